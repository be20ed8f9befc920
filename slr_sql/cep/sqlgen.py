"""SQL for one alternative of an event rule (docs/events.md, "How a rule runs as SQL").

Every positive event atom of the alternative is a row of its type's table, aliased ``e0``,
``e1``, ... by position. The pattern becomes conditions between those rows:

* the atoms' own arguments: a constant is compared with its stored encoding (and SQL type,
  so that ``1`` does not match ``1.0``); a variable met again is an equality with its first
  occurrence (same SQL type for data arguments; by value for times);
* ``^T`` (a point event: start = end = T) and ``^[S, E]`` bind the times;
* each binary operator's relation between the intervals of its operands (``seq``: end of the
  left < start of the right, ...), ``within D`` (end − start ≤ D, plus the per-row bounds
  ``t_end``/``t_start`` within D of each other row, which let the indexes bound the search);
* comparisons and equalities in ``where`` whose operands are bound by the atoms (``R2 > R1``,
  ``F \\== G``): pushed into the statement, exactly (a non-number falls back to the SQL function
  ``slr_cep_cmp``, which evaluates as Prolog does); so is a call of a predicate made of ground
  facts with its arguments bound (``softDrink(O)``: EXISTS a row of its fact table);
* ``cnot c``: ``NOT EXISTS`` a row of c strictly inside the interval, once c's history is
  complete up to the interval's end (the completeness condition is SQL too, its inputs bound
  as parameters).

A *delta* statement finds the matches in which position i is one of the rows that are new in
this round (``e_i.seq > :w_i``) and every earlier position with new rows is an old row
(``e_j.seq <= :w_j``): each new combination is found once, by exactly one statement. The new
row is the outer loop (``CROSS JOIN`` fixes the order), so a statement's cost depends on the
new rows and on what the indexes reach from them, not on the size of the history.

The templates use ``{eN}`` for the alias of position N (``str.format_map``), because the
``recent`` policy nests the same conditions inside correlated sub-queries with other aliases.
Values only ever appear as named parameters.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable

from ..encoding import Unencodable, encode
from ..store import quote_identifier
from ..store.dialect import SQLITE, short_text
from ..store.sqltext import joined_balanced
from ..terms import Struct, Var, deref, format_term, is_ground, term_vars
from .rules import Alternative, Expr, Leaf

__all__ = ["Ref", "AltSQL", "anchor_index", "index_name", "render"]

_CMP = {"<": "<", ">": ">", "=<": "<=", ">=": ">=", "=:=": "=", "=\\=": "<>"}
_EQ = {"==": True, "=": True, "\\==": False, "\\=": False}
# what _push gives for a comparison SQLite decides in its statement, a value it cannot
# compare exactly by the Python functions slr_cep_cmp and slr_cep_arith (an error there is
# no match, never counted), on a server that calls no Python: the Python side decides it
# before the other where goals, as Prolog evaluates it, an error no match too (AltSQL.quiet)
QUIET = object()
_INT64 = 1 << 63
_NUMERIC = "IN ('integer', 'real')"
# Arithmetic pushed into SQL (``T3 - T1 =< 5``): + and - over bound variables and numbers,
# computed by SQL only where it gives Prolog's value -- integers small enough that no sum
# of _MAX_LEAVES of them leaves the exact range of a double, finite floats far from
# overflow; any other value is evaluated by the Python function ``slr_cep_arith``.
_INT_BOUND = 2 ** 48
_REAL_BOUND = 1e300
_MAX_LEAVES = 16
# From this many equalities of data arguments between two rows on, the dialect may write
# them as one condition (:meth:`AltSQL._folded`); fewer plan in a few milliseconds.
_FOLD_FROM = 6


@dataclass(frozen=True)
class Ref:
    """Where a variable's value is: an SQL expression (a template over the aliases) and
    whether it is a data argument (any encoded term) or a time (always a REAL)."""

    sql: str
    kind: str          # "data" | "time"
    positions: frozenset


def render(template: str, aliases: dict[str, str]) -> str:
    """Put the aliases into a template (``{e0}`` -> ``e0`` or a sub-query's alias).

    >>> render("{e0}.t_end < {e1}.t_start", {"e0": "q0_e0", "e1": "e1"})
    'q0_e0.t_end < e1.t_start'
    """
    return template.format_map(aliases)


def index_name(table: str, column: str, first: str) -> str:
    """The name of the index a rule adds on ``table`` (``column``, then ``t_<first>`` and
    the other time).

    >>> index_name("face", "arg3", "end")
    'slr_cep_ix__face__arg3_end'
    """
    return f"slr_cep_ix__{table}__{column}_{first}"


def anchor_index(table: str, key: str | None, column: str) -> tuple[str, list[str]]:
    """The name and columns of the index an anchor (:meth:`AltSQL.anchored`) searches:
    the key column first when the position has one.

    >>> anchor_index("face", "arg1", "arg3")
    ('slr_cep_ix__face__arg1_arg3', ['arg1', 'arg3', 't_end'])
    """
    columns = ([key] if key and key != column else []) + [column, "t_end"]
    return f"slr_cep_ix__{table}__{'_'.join(columns[:-1])}", columns


def _expr(e: Expr, dialect: Any = SQLITE) -> str:
    """A time expression as SQL: a chain of one scalar (the ``min`` of a long ``and``'s
    starts) is printed as one call of many arguments, not nested calls, which SQLite's
    parser refused beyond ~30 parts ("parser stack overflow") once the rule was decided.

    >>> _expr(("min", ("min", ("s", 0), ("s", 1)), ("s", 2)))
    'min({e0}.t_start, {e1}.t_start, {e2}.t_start)'
    """
    if e[0] == "s":
        return f"{{e{e[1]}}}.t_start"
    if e[0] == "e":
        return f"{{e{e[1]}}}.t_end"
    operands: list = []
    pending = [e[2], e[1]]
    while pending:   # the operands of the chain, left to right
        part = pending.pop()
        if part[0] == e[0]:
            pending += [part[2], part[1]]
        else:
            operands.append(part)
    return f"{dialect.scalar(e[0])}({', '.join(_expr(o, dialect) for o in operands)})"


def _arg_number(column: str) -> int:
    """The place of a data argument's column in its row (``{e3}.arg12`` -> 12).

    >>> _arg_number("{e3}.arg12")
    12
    """
    return int(column.rsplit(".arg", 1)[1])


def _single(positions: frozenset) -> int | None:
    """The position of a column of one position's row (None: of no position)."""
    return next(iter(positions)) if len(positions) == 1 else None


def _expr_positions(e: Expr) -> frozenset:
    if e[0] in ("s", "e"):
        return frozenset((e[1],))
    return _expr_positions(e[1]) | _expr_positions(e[2])


@dataclass
class _Cond:
    positions: frozenset
    sql: str
    # an equality between two occurrences of a variable (group ("eq", id of the variable),
    # ends: the (column, position) of each) or a window's bound of one row by another
    # (group ("window", n), ends: ((None, bounding position), (None, bounded position))):
    # a statement needs only some of each group (:meth:`AltSQL.cond_sql`)
    group: tuple | None = None
    ends: tuple = ()


@dataclass
class _Neg:
    key: tuple[str, int]
    positions: frozenset
    sql: str | None          # NOT EXISTS (...) or None: the type has no table yet (holds)
    end: str                 # the interval end the completeness condition is about


class _Statements(dict):
    """An alternative's statements by what they are for; each new one is shown to
    ``on_statement`` once, as it is stored."""

    def __init__(self, on_statement: Callable[[str], None] | None) -> None:
        super().__init__()
        self.on_statement = on_statement

    def __setitem__(self, key: Any, sql: str) -> None:
        if self.on_statement is not None:
            self.on_statement(sql)
        super().__setitem__(key, sql)


@dataclass
class AltSQL:
    """The SQL pieces of one alternative, and the statements built from them.

    ``tables[p]`` is the quoted table of position p (None: the type has no table yet, so the
    alternative cannot match now); ``neg_tables`` likewise for the negations.
    """

    alt: Alternative
    index: int
    tables: list
    neg_tables: list
    head_args: tuple
    policy: str
    # (type, end expression, through) -> SQL: the type is complete up to the end -- through
    # it, or only before it (every event ending earlier is in; docs/events.md)
    complete_sql: Callable[[tuple, str, bool], str]
    used_table: str | None = None
    prov_table: str = ""
    fact_table: Callable[[tuple], str | None] | None = None  # planner's slr_facts_* tables
    table_names: list = field(default_factory=list)   # unquoted, for the used-rows table
    params: dict = field(default_factory=dict)
    refs: dict = field(default_factory=dict)
    conds: list = field(default_factory=list)
    negs: list = field(default_factory=list)
    residual: list = field(default_factory=list)
    pushed: list = field(default_factory=list)
    quiet: list = field(default_factory=list)      # comparisons decided first in Python (QUIET)
    head_sql: list | None = None
    dialect: Any = SQLITE     # the SQL printed: store/dialect.py
    # position -> (column, positions bounding it): a pushed ``X - Y =< C`` gives the row of
    # Y a lower bound on its data column once X's row is chosen (an index range)
    anchors: dict = field(default_factory=dict)
    # the types a terminator's decision waits for, each with whether through its end
    # (:meth:`EventRule.decision_inputs`); empty: the alternative's own, before its end
    decision: dict = field(default_factory=dict)
    # called with each statement the first time it is built, before it runs (the store
    # builds the start-ordered indexes its plan would use)
    on_statement: Callable[[str], None] | None = None

    def __post_init__(self) -> None:
        alt = self.alt
        self._table_names: dict = {}
        self._cache: dict = _Statements(self.on_statement)
        self._others: dict = {}   # variable -> its later occurrences in positive atoms
        self.k = len(alt.leaves)
        self.S = _expr(alt.interval[0], self.dialect)
        self.E = _expr(alt.interval[1], self.dialect)
        for pos, leaf in enumerate(alt.leaves):
            self._leaf(leaf, f"{{e{pos}}}", frozenset((pos,)))
        for i in range(self.k):
            for j in range(i + 1, self.k):
                if alt.leaves[i].key == alt.leaves[j].key:
                    self.conds.append(_Cond(frozenset((i, j)), f"{{e{i}}}.seq <> {{e{j}}}.seq"))
        for op, left, right in alt.relations:
            for a, cmp, b in self._relation(op, left, right):
                self.conds.append(_Cond(_expr_positions(a) | _expr_positions(b),
                                        f"{_expr(a, self.dialect)} {cmp} {_expr(b, self.dialect)}"))
        for interval, seconds, positions in alt.windows:
            self._window(interval, seconds, positions)
        for goal in alt.goals:
            sql = self._push(goal)
            if sql is None:
                self.residual.append(goal)
            elif sql is QUIET:
                self.quiet.append(goal)
            else:
                self.pushed.append(goal)
                self.conds.append(sql)
        for n, (interval, leaf) in enumerate(alt.negations):
            self._negation(n, interval, leaf)
        self._index_conditions()
        self.head_sql = self._head()
        if self.used_table is not None:   # chronological: the tables' names as parameters
            for p in range(self.k):
                self._table_names[p] = self._param(self.table_names[p])
        # the variables whose values the Python side needs (residual goals, head)
        needed = []
        seen = set()
        for t in list(self.quiet) + list(self.residual) + list(self.head_args):
            for v in term_vars(t):
                if id(v) in self.refs and id(v) not in seen:
                    seen.add(id(v))
                    needed.append(v)
        self.value_vars = needed

    # ---------------------------------------------------------------- building blocks
    def _param(self, value: Any) -> str:
        name = f"c{self.index}_{len(self.params)}"
        self.params[name] = value
        return f":{name}"

    def _const_cond(self, ref: Ref, value: Any) -> str | None:
        """The condition ``ref`` equals the constant term ``value`` (None: always false)."""
        value = deref(value)
        if ref.kind == "time":
            if type(value) in (int, float):
                return f"{ref.sql} = {self._param(float(value))}"
            return None
        try:
            encoded = encode(value)
        except Unencodable:
            return None
        typeof = self.dialect.typeof
        stored = self._stored(encoded)
        p = self._param(stored)
        # (an argument's indexes hold the dialect's key of it: key_equal lets them serve)
        equal = self.dialect.key_equal(ref.sql, p, p if short_text(stored) is not None
                                       else "NULL")
        if type(value) is int and type(encoded) is int:
            return f"({equal} AND {typeof(ref.sql)} = 'integer')"
        if type(value) is float:
            # (-0.0 and 0.0 are two terms; SQLite's = takes one for the other)
            sign = None if value else self.dialect.zero_sign(ref.sql, math.copysign(1.0, value) < 0)
            return f"({equal} AND {typeof(ref.sql)} = 'real'" + \
                (f" AND {sign})" if sign else ")")
        return equal if equal == f"{ref.sql} = {p}" else f"({equal})"

    def _stored(self, encoded: Any) -> Any:
        """An encoded value as the store's columns hold it."""
        to_column = self.dialect.to_column
        return encoded if to_column is None else to_column(encoded)

    def _eq(self, a: Ref, b: Ref) -> str:
        typeof = self.dialect.typeof
        if a.kind == "time" and b.kind == "time":
            return f"{a.sql} = {b.sql}"
        if a.kind == "data" and b.kind == "data":
            sign = self.dialect.same_zero_sign(a.sql, b.sql)
            return f"({self.dialect.key_equal(a.sql, b.sql)} AND {typeof(a.sql)} = {typeof(b.sql)}" + \
                (f" AND {sign})" if sign else ")")
        d, t = (a, b) if a.kind == "data" else (b, a)
        # times match by value (a time 5.0 and a data argument 5 are the same instant),
        # exactly: 2**53 + 1 is no time (the query printers' time_equal)
        return self.dialect.time_equal(d.sql, t.sql)

    def _bind(self, term: Any, ref: Ref, refs: dict, out: list) -> None:
        """Constrain the column ``ref`` by the pattern term at that place."""
        term = deref(term)
        if type(term) is Var:
            if term.name == "_":
                return
            first = refs.get(id(term))
            if first is None:
                refs[id(term)] = ref
            else:
                # an equality with every earlier occurrence, not only the first: any two
                # positions sharing the variable are tied without the others (the recent
                # policy's sub-queries pick positions one at a time)
                for other in [first] + self._others.get(id(term), []):
                    out.append(_Cond(other.positions | ref.positions, self._eq(other, ref),
                                     ("eq", id(term)), ((other.sql, _single(other.positions),
                                                         other.kind),
                                                        (ref.sql, _single(ref.positions),
                                                         ref.kind))))
                if ref.positions:
                    self._others.setdefault(id(term), []).append(ref)
            return
        sql = self._const_cond(ref, term)
        out.append(_Cond(ref.positions, sql if sql is not None else self.dialect.false))

    def _leaf(self, leaf: Leaf, alias: str, positions: frozenset,
              refs: dict | None = None, out: list | None = None) -> None:
        refs = self.refs if refs is None else refs
        out = self.conds if out is None else out
        for j, arg in enumerate(leaf.args):
            self._bind(arg, Ref(f"{alias}.arg{j + 1}", "data", positions), refs, out)
        if leaf.point:
            out.append(_Cond(positions, f"{alias}.t_start = {alias}.t_end"))
        if leaf.start is not None:
            self._bind(leaf.start, Ref(f"{alias}.t_start", "time", positions), refs, out)
        if leaf.end is not None and not leaf.point:
            self._bind(leaf.end, Ref(f"{alias}.t_end", "time", positions), refs, out)

    @staticmethod
    def _relation(op: str, left: tuple, right: tuple) -> list[tuple]:
        """The comparisons (expression, operator, expression) an operator requires between
        its operands' intervals (each kept apart: it involves fewer positions)."""
        (s1, e1), (s2, e2) = left, right
        if op == "seq":
            return [(e1, "<", s2)]
        if op == "par":
            return [(s1, "<=", e2), (s2, "<=", e1)]
        if op == "equals":
            return [(s1, "=", s2), (e1, "=", e2)]
        if op == "meets":
            return [(e1, "=", s2)]
        if op == "during":
            return [(s2, "<=", s1), (e1, "<=", e2)]
        if op == "starts":
            return [(s1, "=", s2)]
        if op == "finishes":
            return [(e1, "=", e2)]
        return []  # and: both occurred, in any order

    def _window(self, interval: tuple, seconds: float, within: tuple) -> None:
        s, e = _expr(interval[0], self.dialect), _expr(interval[1], self.dialect)
        positions = _expr_positions(interval[0]) | _expr_positions(interval[1])
        d = self._param(float(seconds))
        self.conds.append(_Cond(positions, f"{e} - {s} <= {d}"))
        positions = frozenset(within)
        # Implied bounds between every two rows of the window, widened by a margin far above
        # the rounding of the subtraction: pure pre-filters that the indexes can use.
        loose = self._param(float(seconds) * (1 + 1e-9) + 1e-9)
        for i in sorted(positions):
            for j in sorted(positions):
                if i == j:
                    continue
                ei, si, ej, sj = (f"{{e{i}}}.t_end", f"{{e{i}}}.t_start", f"{{e{j}}}.t_end",
                                  f"{{e{j}}}.t_start")
                slack = f"abs({ei}) * 1e-12"
                self.conds.append(_Cond(frozenset((i, j)),
                                        f"{ej} >= {ei} - {loose} - {slack} AND "
                                        f"{sj} <= {si} + {loose} + {slack}",
                                        ("window", d),
                                        ((None, i, "time"), (None, j, "time"))))

    def _side(self, t: Any) -> tuple[str, str] | None:
        """An operand of a pushed comparison: (SQL, kind) with kind data/time/num."""
        t = deref(t)
        if type(t) is Var:
            ref = self.refs.get(id(t))
            return None if ref is None else (ref.sql, ref.kind)
        if type(t) in (int, float) and t == t:
            try:
                stored = encode(t)
            except Unencodable:
                return None
            if type(t) is int and not -_INT64 <= t < _INT64:
                # an integer beyond 64 bits is no SQL number (SQLite refused the parameter:
                # every add the rule decided failed): a stored value, which the comparison
                # hands to slr_cep_cmp, as Prolog evaluates it
                return self._param(self._stored(stored)), "data"
            return self._param(t), "num"
        return None

    def _push(self, goal: Any) -> _Cond | None:
        """A where goal that SQL can decide exactly, as a condition; None otherwise."""
        g = deref(goal)
        if type(g) is not Struct:
            return None
        positions = frozenset()
        for v in term_vars(g):
            ref = self.refs.get(id(v))
            if ref is None:
                return None
            positions |= ref.positions
        if self.fact_table is not None:
            table = self.fact_table((str(g.name), len(g.args)))
            if table is not None:
                return self._fact(g, table, positions)
        if len(g.args) != 2:
            return None
        if g.name in _CMP and any(type(deref(a)) is Struct for a in g.args):
            return self._push_arith(g, positions)
        if g.name in _CMP:
            a, b = self._side(g.args[0]), self._side(g.args[1])
            if a is None or b is None:
                return None
            number = self.dialect.number
            core = (f"{number(a[0]) if a[1] == 'data' else a[0]} {_CMP[g.name]} "
                    f"{number(b[0]) if b[1] == 'data' else b[0]}")
            guards = [f"{self.dialect.typeof(x)} {_NUMERIC}" for x, kind in (a, b)
                      if kind == "data"]
            if not guards:
                return _Cond(positions, core)
            if not self.dialect.python_functions:
                return QUIET  # slr_cep_cmp is Python: the Python side decides it as it would
            op = self._param(str(g.name))
            return _Cond(positions, f"(CASE WHEN {' AND '.join(guards)} THEN {core} ELSE "
                                    f"slr_cep_cmp({op}, {a[0]}, {b[0]}) END)")
        if g.name in _EQ:
            if not all(is_ground(a) or type(deref(a)) is Var for a in g.args):
                return None
            sides = []
            for a in g.args:
                a = deref(a)
                if type(a) is Var:
                    sides.append(self.refs[id(a)])
                else:
                    sides.append(a)
            x, y = sides
            if isinstance(x, Ref) and isinstance(y, Ref):
                if x.kind != y.kind:
                    d, t = (x, y) if x.kind == "data" else (y, x)
                    sql = (f"({self.dialect.typeof(d.sql)} = 'real' AND "
                           f"{self.dialect.number(d.sql)} = {t.sql})")
                else:
                    sql = self._eq(x, y)
            elif isinstance(x, Ref) or isinstance(y, Ref):
                ref, value = (x, y) if isinstance(x, Ref) else (y, x)
                if ref.kind == "time":
                    sql = (f"{ref.sql} = {self._param(value)}" if type(value) is float
                           else self.dialect.false)
                else:
                    sql = self._const_cond(ref, value) or self.dialect.false
            else:
                return None  # two constants: the interpreter's business
            return _Cond(positions, sql if _EQ[g.name] else f"NOT ({sql})")
        return None

    def _arith(self, t: Any, leaves: list, names: dict) -> tuple[str, Any] | None:
        """An arithmetic expression of + and - over bound variables and numbers: its SQL
        and the same term with each variable renamed ``V<n>`` (n: its place in ``leaves``,
        the refs the fallback receives); None if it is anything else."""
        t = deref(t)
        if type(t) is not Struct:
            names[None] = names.get(None, 0) + 1   # leaves met (variables and numbers)
            if names[None] > _MAX_LEAVES:
                return None
        if type(t) is Var:
            ref = self.refs.get(id(t))
            if ref is None:
                return None
            n = names.get(id(t))
            if n is None:
                n = names[id(t)] = len(leaves)
                leaves.append(ref)
            return (self.dialect.number(ref.sql) if ref.kind == "data" else ref.sql,
                    Var(f"V{n}"))
        if type(t) is int:
            return (self._param(t), t) if abs(t) <= _INT_BOUND else None
        if type(t) is float:
            return (self._param(t), t) if abs(t) <= _REAL_BOUND else None   # (NaN: no)
        if type(t) is Struct and t.name in ("+", "-") and len(t.args) == 2:
            a = self._arith(t.args[0], leaves, names)
            b = self._arith(t.args[1], leaves, names) if a is not None else None
            if b is None:
                return None
            return f"({a[0]} {t.name} {b[0]})", Struct(t.name, (a[1], b[1]))
        if type(t) is Struct and t.name == "-" and len(t.args) == 1:
            a = self._arith(t.args[0], leaves, names)
            return None if a is None else (f"(- {a[0]})", Struct("-", (a[1],)))
        return None

    def _push_arith(self, g: Struct, positions: frozenset) -> _Cond | None:
        """A comparison with an arithmetic expression on either side, in SQL where its
        operands are in the exact range (see _INT_BOUND), ``slr_cep_arith`` otherwise."""
        leaves: list = []
        names: dict = {}
        a = self._arith(g.args[0], leaves, names)
        b = self._arith(g.args[1], leaves, names) if a is not None else None
        if b is None:
            return None
        typeof = self.dialect.typeof
        guards = []
        # (a range, not abs(): SQLite's abs() of the smallest 64-bit integer is an overflow
        # error, which failed the whole statement and so the add that decided it)
        for ref in leaves:
            if ref.kind == "data":
                guards.append(f"(({typeof(ref.sql)} = 'integer' AND {ref.sql} BETWEEN "
                              f"-{_INT_BOUND} AND {_INT_BOUND}) OR ({typeof(ref.sql)} = 'real' "
                              f"AND {ref.sql} BETWEEN -{_REAL_BOUND!r} AND {_REAL_BOUND!r}))")
            else:
                guards.append(f"{ref.sql} BETWEEN -{_REAL_BOUND!r} AND {_REAL_BOUND!r}")
        if guards and not self.dialect.python_functions:
            # no fallback for the values out of range: the Python side decides it as
            # slr_cep_arith would
            return QUIET
        text = self._param(format_term(Struct(g.name, (a[1], b[1]))))
        values = ", ".join(ref.sql for ref in leaves)
        fallback = f"slr_cep_arith({text}{', ' if values else ''}{values})"
        core = f"{a[0]} {_CMP[g.name]} {b[0]}"
        self._anchor(g)
        if not guards:
            return _Cond(positions, core)
        return _Cond(positions, f"(CASE WHEN {' AND '.join(guards)} THEN {core} ELSE "
                                f"{fallback} END)")

    def _anchor(self, g: Struct) -> None:
        """``X - Y =< C`` (or ``<``, or ``C >= X - Y``, ``C > X - Y``), Y a data argument of
        another position than X, C a number: also the loose lower bound ``Y >= X - C -
        slack`` (a pre-filter the index on Y's column can use; the exact comparison stays).
        The bound is -inf when X is not a number (its value is Prolog's business), and a
        stored Y that is not a number is greater than every number in SQLite: it passes."""
        op, lhs, rhs = g.name, deref(g.args[0]), deref(g.args[1])
        if op in (">=", ">"):
            op, lhs, rhs = ("=<" if op == ">=" else "<"), rhs, lhs
        if op not in ("=<", "<") or type(lhs) is not Struct or lhs.name != "-" \
                or len(lhs.args) != 2 or type(rhs) not in (int, float):
            return
        if not (abs(rhs) <= _INT_BOUND if type(rhs) is int else abs(rhs) <= _REAL_BOUND):
            return
        x, y = deref(lhs.args[0]), deref(lhs.args[1])
        if type(x) is not Var or type(y) is not Var:
            return
        rx, ry = self.refs.get(id(x)), self.refs.get(id(y))
        if rx is None or ry is None or ry.kind != "data" or len(ry.positions) != 1 \
                or ry.positions & rx.positions or not rx.positions:
            return
        if self.dialect.typeof(ry.sql) != f"typeof({ry.sql})":
            return   # (SQLite's order of values: text after numbers)
        x_num = (f"{self.dialect.typeof(rx.sql)} {_NUMERIC}" if rx.kind == "data"
                 else self.dialect.true)
        c = self._param(float(rhs))
        # (X as a float before abs(): abs() of the smallest 64-bit integer is an overflow
        # error in SQLite; the bound is a loose one anyway)
        bound = (f"(CASE WHEN {x_num} AND {rx.sql} BETWEEN -{_REAL_BOUND!r} AND "
                 f"{_REAL_BOUND!r} THEN {rx.sql} - {c} - (abs({rx.sql} + 0.0) + abs({c})) "
                 f"* 1e-9 - 1e-9 ELSE "
                 f"{self.dialect.infinity(True)} END)")
        (pos,) = ry.positions
        self.conds.append(_Cond(ry.positions | rx.positions, f"{ry.sql} >= {bound}"))
        column = ry.sql.rsplit(".", 1)[1]
        self.anchors.setdefault(pos, []).append((column, rx.positions))

    def anchored(self, pos: int, chosen: set) -> bool:
        """Position ``pos`` has a lower bound given the rows of ``chosen``: a window over
        both, or an anchor (:meth:`_anchor`)."""
        for _, _, within in self.alt.windows:
            if pos in within and chosen & set(within):
                return True
        return any(bounding <= chosen for _, bounding in self.anchors.get(pos, ()))

    def _anchor_hint(self, pos: int, chosen: set) -> str:
        """`` INDEXED BY`` the index of an anchor of ``pos`` (SQLite's planner, without
        statistics, takes the (key, time) index instead, which reaches the whole history)."""
        if not self.dialect.index_hints or pos >= len(self.table_names):
            return ""
        for column, bounding in self.anchors.get(pos, ()):
            if bounding <= chosen and self.table_names[pos] is not None:
                name = anchor_index(self.table_names[pos], self.key_column(pos), column)[0]
                return f" INDEXED BY {quote_identifier(name)}"
        return ""

    def key_column(self, pos: int) -> str | None:
        """``arg1`` when position pos's first argument is tied to another position's or a
        constant (an equality the anchor's index can use first), else None."""
        leaf = self.alt.leaves[pos]
        if not leaf.args:
            return None
        a = deref(leaf.args[0])
        if type(a) is not Var:
            return "arg1"
        ref = self.refs.get(id(a))
        if ref is not None and ref.positions != frozenset((pos,)):
            return "arg1"
        return "arg1" if self._others.get(id(a)) else None

    def _fact(self, g: Struct, table: str, positions: frozenset) -> _Cond:
        """``p(A..)`` over a predicate made of ground facts, its arguments bound: a row of
        its fact table with the same values (and SQL types) exists."""
        alias = f"f{len(self.conds)}"
        conds = []
        for j, a in enumerate(g.args):
            column = Ref(f"{alias}.arg{j + 1}", "data", frozenset())
            a = deref(a)
            if type(a) is Var:
                ref = self.refs[id(a)]
                if ref.kind == "time":   # a time is a float: a fact's 5 is not 5.0
                    conds.append(_Cond(frozenset(), (
                        f"({self.dialect.typeof(column.sql)} = 'real' AND "
                        f"{self.dialect.number(column.sql)} = {ref.sql})")))
                else:
                    conds.append(_Cond(frozenset(), self._eq(column, ref), ("eq", id(a)),
                                       ((column.sql, None, "data"), (ref.sql, None, "data"))))
            else:
                conds.append(_Cond(frozenset(), self._const_cond(column, a)
                                   or self.dialect.false))
        where = joined_balanced(self._folded(conds), "AND") or self.dialect.true
        return _Cond(positions, f"EXISTS (SELECT 1 FROM {table} AS {alias} WHERE {where})")

    def _negation(self, n: int, interval: tuple, leaf: Leaf) -> None:
        s, e = _expr(interval[0], self.dialect), _expr(interval[1], self.dialect)
        positions = _expr_positions(interval[0]) | _expr_positions(interval[1])
        table = self.neg_tables[n]
        if table is None:
            self.negs.append(_Neg(leaf.key, positions, None, e))
            return
        alias = f"n{n}"
        local = dict(self.refs)   # shared variables: equalities; new ones are local
        conds: list = []
        self._leaf(leaf, alias, frozenset(), local, conds)
        for c in conds:
            positions |= c.positions
        where = [f"{alias}.t_start > {s}", f"{alias}.t_end < {e}"] + self._folded(conds)
        # the index on (t_end, t_start) bounds the scan to the interval
        sql = (f"NOT EXISTS (SELECT 1 FROM {table} AS {alias} WHERE "
               f"{joined_balanced(where, 'AND')})")
        self.negs.append(_Neg(leaf.key, positions, sql, e))

    def _head(self) -> list | None:
        """SQL of each head argument, or None when one needs the Python side (a residual
        goal binds it, or it is a compound term with variables)."""
        out = []
        for a in self.head_args:
            a = deref(a)
            if type(a) is Var:
                ref = self.refs.get(id(a))
                if ref is None:
                    return None
                out.append(ref.sql)
            elif is_ground(a):
                try:
                    out.append(self._param(self._stored(encode(a))))
                except Unencodable:
                    return None
            else:
                return None
        return out

    # ---------------------------------------------------------------- properties
    @property
    def runnable(self) -> bool:
        """False while a positive atom's type has no table (nothing can match yet)."""
        return all(t is not None for t in self.tables)

    @property
    def pure(self) -> bool:
        """Everything in SQL: no residual goal (nor comparison left to Python), head
        computable in SQL."""
        return not self.residual and not self.quiet and self.head_sql is not None

    def aliases(self, prefix: str = "") -> dict[str, str]:
        return {f"e{p}": f"{prefix}e{p}" for p in range(self.k)}

    def _where(self, conds: list[str]) -> str:
        """The conditions joined by AND, a long list as a balanced tree of parenthesized
        halves (:func:`joined_balanced`): SQLite refuses an expression deeper than 1000, and
        a long pattern has hundreds (``e_i.seq <> e_j.seq`` for rows of one type).

        >>> from slr_sql.cep.rules import compile_rule
        >>> from slr_sql.parser import parse_program
        >>> alt = compile_rule(parse_program("c <- a.")[0]).alternatives[0]
        >>> sql = AltSQL(alt, 0, ['"a"'], [], (), "unrestricted", lambda *a: "1")
        >>> sql._where([f"x{i} = 1" for i in range(65)]).count("(")
        2
        """
        return joined_balanced([c for c in conds if c], "AND") or self.dialect.true

    def _from(self, order: list[int], aliases: dict[str, str]) -> str:
        return " CROSS JOIN ".join(f"{self.tables[p]} AS {aliases[f'e{p}']}" for p in order)

    def _order_from(self, first: int) -> list[int]:
        """The join order: the given position first, then outwards by distance -- except
        that a position an anchor bounds by those already joined comes before the others
        (its few rows then bound the search of the positions between)."""
        outwards = [first]
        for d in range(1, self.k):
            for p in (first - d, first + d):
                if 0 <= p < self.k:
                    outwards.append(p)
        if not self.anchors:
            return outwards
        order, rest = [first], outwards[1:]

        def bounded(q: int, placed: set) -> bool:
            return any(b <= placed for _, b in self.anchors.get(q, ()))

        while rest:
            placed = set(order)
            p = next((q for q in rest if bounded(q, placed)), None)
            if p is None:   # the position whose row bounds another one, first
                p = next((q for q in rest if any(bounded(r, placed | {q})
                                                 for r in rest if r != q)), rest[0])
            order.append(p)
            rest.remove(p)
        return order

    def neg_complete(self, aliases: dict[str, str]) -> str:
        """Every negated type complete up to the end of its interval."""
        # a negated event lies strictly inside: the events ending before the end suffice
        parts = [self.complete_sql(n.key, render(n.end, aliases), False) for n in self.negs]
        return " AND ".join(f"({p})" for p in parts) or self.dialect.true

    def neg_ok(self, aliases: dict[str, str]) -> str:
        parts = [render(n.sql, aliases) for n in self.negs if n.sql is not None]
        return joined_balanced(parts, "AND") or self.dialect.true

    def inputs_complete(self, end: str) -> str:
        """Every type a terminator's decision reads complete up to ``end`` (its end): through
        it or before it, as :attr:`decision` says."""
        decision = self.decision or {
            leaf.key: False for leaf in self.alt.leaves + [n for _, n in self.alt.negations]}
        return " AND ".join(f"({self.complete_sql(k, end, through)})"
                            for k, through in decision.items()) or self.dialect.true

    def cond_sql(self, aliases: dict[str, str], within: set | None = None,
                 exclude: set | None = None, order: list[int] | None = None) -> list[str]:
        """The conditions (rendered) whose positions all lie in ``within`` (all if None),
        except those entirely inside ``exclude`` (rows the enclosing query has chosen, its
        conditions between them checked there), the rows of the rest joined in ``order``
        (default: by position).

        Of a variable's equalities (one between every two of its occurrences) only as many
        as tie its occurrences together are kept: each occurrence equal to the first one
        joined (a chosen row first); the others follow, as equal values of equal SQL types
        are an equivalence. Of a window's bounds (one per two rows), each row keeps the
        bound by the first row joined before it (they only narrow index searches). With
        all of them a pattern of n parts had n(n-1)/2 equalities per shared variable:
        SQLite's planner took seconds per statement of 20-30 parts, and from ~60 parts
        refused the statement (an expression deeper than 1000)."""
        chosen = exclude or set()
        placed = list(order if order is not None else range(self.k))
        rank = {p: n for n, p in enumerate(placed)}
        for p in chosen:
            rank.setdefault(p, -1)
        last = len(rank)

        def inside(p: int | None) -> bool:
            return within is None or p in within

        kept = [n for n in self._plain_conds
                if (within is None or self.conds[n].positions <= within)
                and not (exclude is not None and self.conds[n].positions <= exclude)]
        for group, nodes in self._occurrences.items():
            nodes = [node for node in nodes if inside(node[1])]
            if group[0] == "eq":
                if len(nodes) < 2:
                    continue
                first = min(range(len(nodes)), key=lambda i: (rank.get(nodes[i][1], last), i))
                for i, node in enumerate(nodes):
                    if i != first and node[1] not in chosen:
                        kept.append(self._pairs[(group, nodes[first][0], node[0])])
                continue
            for j in nodes:    # a window: ("", position) nodes
                before = [i for i in nodes if rank.get(i[1], last) < rank.get(j[1], last)]
                if before and j[1] not in chosen:
                    i = min(before, key=lambda i: (rank.get(i[1], last), i[1]))
                    kept.append(self._pairs[(group, i[0], j[0])])
        return [render(sql, aliases) for sql in self._folded([self.conds[n]
                                                              for n in sorted(kept)])]

    def _folded(self, conds: list[_Cond]) -> list[str]:
        """The templates of ``conds``, where the dialect can (PostgreSQL) the many
        equalities of data arguments between two rows as one condition
        (:meth:`~slr_sql.store.dialect.PostgresDialect.values_equal`): with one per
        argument, planning a statement over two events of n shared arguments took time
        growing as n cubed (seconds from n = 200). Of each row's side the equality of its
        first argument stays apart: it is the one an index over the row's table serves
        (the type's index on ``arg1``, or the rule's on its first argument tied to another
        row, :meth:`RuleRuntime.indexes`)."""
        by_rows: dict[tuple[str, str], list[tuple[int, str, str]]] = {}
        for n, c in enumerate(conds):
            if c.group is None or c.group[0] != "eq" or len(c.ends) != 2:
                continue
            (a, _, a_kind), (b, _, b_kind) = c.ends
            if a_kind != "data" or b_kind != "data":
                continue
            row_a, row_b = a.rsplit(".arg", 1)[0], b.rsplit(".arg", 1)[0]
            if row_a == row_b:
                continue
            by_rows.setdefault((row_a, row_b) if row_a < row_b else (row_b, row_a), []).append(
                (n, a, b) if row_a < row_b else (n, b, a))
        folded: dict[int, str] = {}
        dropped: set[int] = set()
        for pairs in by_rows.values():
            if len(pairs) < _FOLD_FROM:
                continue
            apart = {min(pairs, key=lambda e: _arg_number(e[1]))[0],
                     min(pairs, key=lambda e: _arg_number(e[2]))[0]}
            rest = [e for e in pairs if e[0] not in apart]
            sql = self.dialect.values_equal([a for _, a, _ in rest], [b for _, _, b in rest])
            if sql is None:
                continue
            folded[rest[0][0]] = sql
            dropped.update(e[0] for e in rest[1:])
        return [folded.get(n) or c.sql for n, c in enumerate(conds) if n not in dropped]

    def _index_conditions(self) -> None:
        """The groups of conditions :meth:`cond_sql` thins out: each group's occurrences
        (column or position, position) and the condition between two of them."""
        kinds: dict = {}
        for c in self.conds:
            if c.group is not None:
                kinds.setdefault(c.group, set()).update(end[2] for end in c.ends)
        # a variable that is a data argument somewhere and a time elsewhere: its equalities
        # are no equivalence (a time 5.0 equals the data 5 and the data 5.0, which are two
        # terms), so every one of them stays
        mixed = {g for g, k in kinds.items() if len(k) > 1}
        self._plain_conds: list[int] = []
        self._occurrences: dict[tuple, list[tuple]] = {}
        self._pairs: dict[tuple, int] = {}
        for n, c in enumerate(self.conds):
            if c.group is None or c.group in mixed:
                self._plain_conds.append(n)
                continue
            nodes = self._occurrences.setdefault(c.group, [])
            ends = [(str(col) if col is not None else str(p), p) for col, p, _ in c.ends]
            for node in ends:
                if node not in nodes:
                    nodes.append(node)
            self._pairs[(c.group, ends[0][0], ends[1][0])] = n
            if c.group[0] == "eq":
                self._pairs[(c.group, ends[1][0], ends[0][0])] = n
        for group, nodes in self._occurrences.items():
            nodes.sort(key=lambda node: (node[1], node[0]) if group[0] == "window" else 0)

    def value_columns(self, aliases: dict[str, str]) -> list[str]:
        """seq of every position, start, end, then the values of ``value_vars``."""
        cols = [f"{aliases[f'e{p}']}.seq" for p in range(self.k)]
        cols += [render(self.S, aliases), render(self.E, aliases)]
        cols += [render(self.refs[id(v)].sql, aliases) for v in self.value_vars]
        return cols

    def _prov_insert(self) -> str:
        cols = ["alt"] + [f"r{p + 1}" for p in range(self.k)] + ["t_start", "t_end"] \
            + [f"h{i + 1}" for i in range(len(self.head_args))] + ["detected"]
        return f"INSERT INTO {self.prov_table} ({', '.join(cols)}) "

    def _prov_values(self, aliases: dict[str, str]) -> list[str]:
        return ([f"{self.index}"] + [f"{aliases[f'e{p}']}.seq" for p in range(self.k)]
                + [render(self.S, aliases), render(self.E, aliases)]
                + [render(h, aliases) for h in self.head_sql] + [":now"])

    def _match_order(self, aliases: dict[str, str]) -> str:
        """ORDER BY of a statement that finds several matches at once: the store order of
        the events at each position, left to right -- the order Prolog's nested loops over
        the events in store order give. The matches of one round are stored (and their
        complex events arrive) in this order, whatever plan the database chose: without it,
        PostgreSQL and SQLite stored two complex events of the same interval in other
        orders, and queries listed them so. The unary plus keeps the order from choosing the
        plan: SQLite would rather scan a whole table by an index in that order than sort the
        few new matches of a round."""
        return " ORDER BY " + ", ".join(
            f"+{aliases[f'e{p}']}.t_end, +{aliases[f'e{p}']}.t_start, +{aliases[f'e{p}']}.seq"
            for p in range(self.k))

    def _delta_conds(self, pos: int, dirty: set, aliases: dict[str, str]) -> list[str]:
        conds = [f"{aliases[f'e{pos}']}.seq > :w{pos}"]
        for j in range(pos):
            if self.alt.leaves[j].key in dirty:
                conds.append(f"{aliases[f'e{j}']}.seq <= :w{j}")
        return conds

    # ---------------------------------------------------------------- statements
    def forget_statements(self) -> None:
        """Build every statement again when next asked for (and show it to
        ``on_statement`` again): after a rollback, which may have taken back an index."""
        self._cache.clear()

    def delta_insert(self, pos: int, dirty: set) -> str:
        key = ("delta_insert", pos, tuple(self.alt.leaves[j].key in dirty for j in range(pos)))
        sql = self._cache.get(key)
        if sql is None:
            sql = self._cache[key] = self._delta_insert(pos, dirty)
        return sql

    def _delta_insert(self, pos: int, dirty: set) -> str:
        """unrestricted, pure: the new matches with position ``pos`` new, straight into the
        provenance table (only those whose negations can be decided now)."""
        a = self.aliases()
        conds = self._delta_conds(pos, dirty, a) + self.cond_sql(a, order=self._order_from(pos))
        if self.negs:
            conds += [self.neg_complete(a), self.neg_ok(a)]
        return (self._prov_insert() + f"SELECT {', '.join(self._prov_values(a))} FROM "
                f"{self._from(self._order_from(pos), a)} WHERE {self._where(conds)}"
                + self._match_order(a))

    def delta_pending(self, pos: int, dirty: set) -> str:
        key = ("delta_pending", pos, tuple(self.alt.leaves[j].key in dirty for j in range(pos)))
        sql = self._cache.get(key)
        if sql is None:
            sql = self._cache[key] = self._delta_pending(pos, dirty)
        return sql

    def _delta_pending(self, pos: int, dirty: set) -> str:
        """The new matches whose negated types are not complete yet: kept as pending."""
        a = self.aliases()
        conds = self._delta_conds(pos, dirty, a) + self.cond_sql(a, order=self._order_from(pos)) \
            + [f"NOT ({self.neg_complete(a)})"]
        seqs = ", ".join(f"e{p}.seq" for p in range(self.k))
        return ("INSERT INTO slr_cep_pending (rule, alt, kind, pos, rowids, t_start, t_end, "
                "created_at) "
                f"SELECT :rule, {self.index}, 'match', NULL, {self.dialect.json_array(seqs)}, "
                f"{render(self.S, a)}, {render(self.E, a)}, :now FROM "
                f"{self._from(self._order_from(pos), a)} WHERE {self._where(conds)}"
                + self._match_order(a))

    def delta_select(self, pos: int, dirty: set) -> str:
        key = ("delta_select", pos, tuple(self.alt.leaves[j].key in dirty for j in range(pos)))
        sql = self._cache.get(key)
        if sql is None:
            sql = self._cache[key] = self._delta_select(pos, dirty)
        return sql

    def _delta_select(self, pos: int, dirty: set) -> str:
        """The new matches with position ``pos`` new, for the Python side: value columns,
        then (with negations) 'complete' and 'ok' flags."""
        a = self.aliases()
        cols = self.value_columns(a)
        if self.negs:
            cols += [f"({self.neg_complete(a)})", f"({self.neg_ok(a)})"]
        conds = self._delta_conds(pos, dirty, a) + self.cond_sql(a, order=self._order_from(pos))
        return (f"SELECT {', '.join(cols)} FROM {self._from(self._order_from(pos), a)} "
                f"WHERE {self._where(conds)}" + self._match_order(a))

    def match_select(self) -> str:
        key = ("match_select", )
        sql = self._cache.get(key)
        if sql is None:
            sql = self._cache[key] = self._match_select()
        return sql

    def _match_select(self) -> str:
        """One pending match by its rowids (:r0, :r1, ...): values and negation flags."""
        a = self.aliases()
        cols = self.value_columns(a)
        cols += [f"({self.neg_complete(a)})", f"({self.neg_ok(a)})"]
        conds = [f"e{p}.seq = :r{p}" for p in range(self.k)]
        return (f"SELECT {', '.join(cols)} FROM {self._from(list(range(self.k)), a)} "
                f"WHERE {self._where(conds)}")

    # -- policies ---------------------------------------------------------------------
    def _terminator_conds(self, pos: int, aliases: dict[str, str]) -> list[str]:
        """Position ``pos`` holds the match's last event: every other row ends (then
        starts) no later, strictly so for rows to its right (ties go to the rightmost)."""
        t = aliases[f"e{pos}"]
        out = []
        for j in range(self.k):
            if j == pos:
                continue
            x = aliases[f"e{j}"]
            cmp = "<=" if j < pos else "<"
            out.append(f"{x}.t_end <= {t}.t_end AND ({x}.t_end, {x}.t_start) {cmp} "
                       f"({t}.t_end, {t}.t_start)")
        return out

    def _key_order(self, p: int, alias: str, descending: bool,
                   fixed: frozenset[int] = frozenset()) -> list[str]:
        d = " DESC" if descending else ""
        leaf = self.alt.leaves[p]
        # by occurrence, then by the stored values (and their SQL type: 1 before 1.0), so
        # that only identical events are told apart by their arrival (seq). An argument the
        # query's conditions fix (``fixed``) orders nothing: left out, the order is the
        # (key, end, start) index's own and needs no sort
        keys = [f"{alias}.t_end{d}", f"{alias}.t_start{d}"]
        for j in range(leaf.arity):
            if j not in fixed:
                keys += [f"{k}{d}" for k in self.dialect.value_order(f"{alias}.arg{j + 1}")]
        return keys + [f"{alias}.seq{d}"]

    def _fixed_args(self, p: int, chosen: set) -> frozenset[int]:
        """The arguments of position ``p`` whose value and SQL type the conditions of a
        query that has the rows of ``chosen`` fix: a constant (:meth:`_const_cond`), or a
        variable that is also a data argument of a chosen row (:meth:`_eq`: the same value
        and type; equal to a time, only the number is fixed)."""
        fixed = set()
        for j, arg in enumerate(self.alt.leaves[p].args):
            a = deref(arg)
            if type(a) is not Var:
                if not term_vars(a):
                    fixed.add(j)
                continue
            if a.name == "_":
                continue
            occurrences = [self.refs.get(id(a))] + self._others.get(id(a), [])
            if any(r is not None and r.kind == "data" and r.positions
                   and p not in r.positions and r.positions <= chosen for r in occurrences):
                fixed.add(j)
        return frozenset(fixed)

    def partner_order(self, pos: int) -> list[int]:
        """The order in which the other positions are chosen: right to left under
        ``recent`` (the closest to the end first), left to right under ``chronological``."""
        others = [p for p in range(self.k) if p != pos]
        return list(reversed(others)) if self.policy == "recent" else others

    def _unused(self, p: int, alias: str) -> str:
        """chronological: the row at position p was used by no earlier match of the rule
        (``slr_cep_u_<key>`` lists the rows used, by table name and seq)."""
        name = self._table_names.get(p)
        if name is None:
            name = self._table_names[p] = self._param(self.table_names[p])
        return (f"NOT EXISTS (SELECT 1 FROM {self.used_table} AS u WHERE u.tbl = {name} "
                f"AND u.seq = {alias}.seq)")

    def term_select(self, pos: int, limit: bool) -> str:
        key = ("term_select", pos, limit)
        sql = self._cache.get(key)
        if sql is None:
            sql = self._cache[key] = self._term_select(pos, limit)
        return sql

    def term_select_many(self, pos: int) -> str:
        """:meth:`term_select` (all matches) for several terminator rows at once: their seqs
        in the JSON array :ts; the rows come grouped by terminator (its seq, column ``pos``
        of each row), each group in :meth:`term_select`'s order."""
        key = ("term_select_many", pos)
        sql = self._cache.get(key)
        if sql is None:
            sql = self._cache[key] = self._term_select(pos, False, many=True)
        return sql

    def _term_select(self, pos: int, limit: bool, many: bool = False) -> str:
        """The matches that end with the terminator row :t at ``pos``, best first under the
        policy (recent: newest partners; chronological: oldest unused partners)."""
        a = self.aliases()
        order = [pos] + self.partner_order(pos)
        first = (f"e{pos}.seq IN ({self.dialect.json_integers(':ts')})" if many
                 else f"e{pos}.seq = :t")
        conds = [first] + self.cond_sql(a, order=order) + self._terminator_conds(pos, a)
        if self.negs:
            conds.append(self.neg_ok(a))
        if self.policy == "chronological":
            conds += [self._unused(p, f"e{p}") for p in range(self.k)]
        keys = [f"e{pos}.seq"] if many else []
        # a partner's arguments that the terminator's and the earlier partners' rows fix
        # order nothing (the rows tied on the keys before have those rows): left out, a
        # rule over two wide events sorted by no argument instead of four keys each
        chosen = {pos}
        for p in self.partner_order(pos):
            keys += self._key_order(p, f"e{p}", self.policy == "recent",
                                    self._fixed_args(p, chosen))
            chosen.add(p)
        sql = (f"SELECT {', '.join(self.value_columns(a))} FROM {self._from(order, a)} "
               f"WHERE {self._where(conds)}")
        if keys:
            sql += " ORDER BY " + ", ".join(keys)
        if limit:
            sql += " LIMIT 1"
        return sql

    def recent_insert(self, pos: int) -> str:
        key = ("recent_insert", pos)
        sql = self._cache.get(key)
        if sql is None:
            sql = self._cache[key] = self._recent_insert(pos)
        return sql

    def pending_recent_insert(self, pos: int) -> str:
        """:meth:`recent_insert` for the terminators kept in slr_cep_pending whose inputs
        are complete now (decided together, in one statement)."""
        key = ("pending_recent_insert", pos)
        sql = self._cache.get(key)
        if sql is None:
            sql = self._cache[key] = self._recent_insert(pos, pending=True)
        return sql

    def term_span(self, pos: int) -> str:
        """The new rows at terminator position ``pos``, none complete yet, kept as one
        pending span: ``rowids`` their first and last seq and their count, ``t_start``
        their latest end, ``t_end`` their earliest (the time the first of them can be
        decided). A span holds no row of another transaction: the writers of a rule's
        types take turns (SQLite's one writer; PostgreSQL's lock of their write group),
        and the span is kept only when the type's new rows (all of them, whatever the
        position's own conditions) are one run of seqs -- checked in this statement, so on
        what it sees. A write that takes no turn (another client's insert, or
        ``kb.sql(..., write=True)``, on PostgreSQL) may draw a seq while the add runs and
        commit after this statement: the seq is then missing here, and the rows are kept
        one by one instead, as :meth:`term_pending` keeps them, never to decide a row no
        add stored."""
        key = ("term_span", pos)
        sql = self._cache.get(key)
        if sql is None:
            a = self.aliases()
            t = a[f"e{pos}"]
            own = [c for c in self.cond_sql(a, within={pos}) if c]

            def kept(expr: str) -> str:   # (the position's own conditions, if any)
                return f"CASE WHEN {self._where(own)} THEN {expr} END" if own else expr
            # one pass over the type's new rows (all of them: whether their seqs are one
            # run; and those of the position: the span), read by both branches
            new_rows = (f"WITH s AS (SELECT count(*) AS total, min({t}.seq) AS lowest, "
                        f"max({t}.seq) AS highest, min({kept(f'{t}.seq')}) AS first_seq, "
                        f"max({kept(f'{t}.seq')}) AS last_seq, count({kept('1')}) AS n, "
                        f"max({kept(f'{t}.t_end')}) AS latest, "
                        f"min({kept(f'{t}.t_end')}) AS earliest "
                        f"FROM {self.tables[pos]} AS {t} WHERE {t}.seq > :w{pos}) ")
            run = "s.total = s.highest - s.lowest + 1"
            sql = self._cache[key] = (
                "INSERT INTO slr_cep_pending (rule, alt, kind, pos, rowids, t_start, t_end, "
                f"created_at) {new_rows}SELECT :rule, {self.index}, 'span', {pos}, "
                f"{self.dialect.json_array('s.first_seq, s.last_seq, s.n')}, s.latest, s.earliest, "
                f":now FROM s WHERE s.n > 0 AND {run} UNION ALL "
                f"SELECT :rule, {self.index}, 'term', {pos}, "
                f"{self.dialect.json_array(f'{t}.seq')}, {t}.t_start, {t}.t_end, :now "
                f"FROM s CROSS JOIN {self.tables[pos]} AS {t} WHERE NOT ({run}) AND "
                f"{self._where([f'{t}.seq > :w{pos}'] + own)}")
        return sql

    def _span_join(self, pos: int) -> str:
        """FROM the pending spans at ``pos`` joined with their terminators."""
        t = f"e{pos}"
        d = self.dialect
        return (f"slr_cep_pending AS p JOIN {self.tables[pos]} AS {t} ON {t}.seq BETWEEN "
                f"{d.json_integer('p.rowids', 0)} AND {d.json_integer('p.rowids', 1)}")

    def span_recent_insert(self, pos: int) -> str:
        """:meth:`recent_insert` for the terminators of the pending spans at ``pos`` whose
        inputs are complete now (one statement for all of them)."""
        key = ("span_recent_insert", pos)
        sql = self._cache.get(key)
        if sql is None:
            sql = self._cache[key] = self._recent_insert(pos, span=True)
        return sql

    def span_split(self, pos: int) -> str:
        """The terminators that must still wait, of the spans at ``pos`` decided now in
        part (their earliest end complete, their latest not), as pending terminators of
        their own."""
        key = ("span_split", pos)
        sql = self._cache.get(key)
        if sql is None:
            a = self.aliases()
            t = a[f"e{pos}"]
            conds = (self._span_conditions(pos)
                     + [f"NOT ({self.inputs_complete('p.t_start')})",
                        f"NOT ({self.inputs_complete(f'{t}.t_end')})"]
                     + self.cond_sql(a, within={pos}))
            sql = self._cache[key] = (
                "INSERT INTO slr_cep_pending (rule, alt, kind, pos, rowids, t_start, t_end, "
                f"created_at) SELECT :rule, {self.index}, 'term', {pos}, "
                f"{self.dialect.json_array(f'{t}.seq')}, {t}.t_start, {t}.t_end, :now FROM "
                f"{self._span_join(pos)} WHERE {self._where(conds)}")
        return sql

    def span_terms(self, pos: int) -> str:
        """The terminators of one pending span at ``pos`` (its first and last seq
        ``:first``, ``:last``): their seq, start and end, in decision order -- a span
        decided one terminator at a time (its alternative no longer all SQL)."""
        key = ("span_terms", pos)
        sql = self._cache.get(key)
        if sql is None:
            a = self.aliases()
            t = a[f"e{pos}"]
            conds = [f"{t}.seq BETWEEN :first AND :last"] + self.cond_sql(a, within={pos})
            sql = self._cache[key] = (
                f"SELECT {t}.seq, {t}.t_start, {t}.t_end FROM {self.tables[pos]} AS {t} "
                f"WHERE {self._where(conds)} ORDER BY {t}.t_end, {t}.t_start, {t}.seq")
        return sql

    def _span_conditions(self, pos: int) -> list[str]:
        """The pending spans at ``pos`` whose earliest terminator can be decided now."""
        return ["p.rule = :rule", f"p.alt = {self.index}", "p.kind = 'span'", f"p.pos = {pos}",
                self.inputs_complete("p.t_end")]

    def span_delete(self, pos: int) -> str:
        """Delete the spans at ``pos`` decided now (whole, or the rest split off)."""
        return ("DELETE FROM slr_cep_pending WHERE rule = :rule AND alt = "
                f"{self.index} AND kind = 'span' AND pos = {pos} AND "
                f"{self.inputs_complete('slr_cep_pending.t_end')}")

    def pending_term_delete(self, pos: int) -> str:
        """Delete the pending terminators at ``pos`` whose inputs are complete now."""
        return ("DELETE FROM slr_cep_pending WHERE rule = :rule AND alt = "
                f"{self.index} AND kind = 'term' AND pos = {pos} AND wait_type IS NULL AND "
                f"{self.inputs_complete('slr_cep_pending.t_end')}")

    def _pending_join(self, aliases: dict[str, str]) -> str:
        """FROM the pending matches of this alternative, joined with their events."""
        joins = " ".join(f"JOIN {self.tables[p]} AS {aliases[f'e{p}']} ON "
                         f"{aliases[f'e{p}']}.seq = {self.dialect.json_integer('p.rowids', p)}"
                         for p in range(self.k))
        return (f"slr_cep_pending AS p {joins} WHERE p.rule = :rule AND p.alt = {self.index} "
                f"AND p.kind = 'match' AND p.wait_type IS NULL")

    def pending_match_insert(self) -> str:
        """unrestricted, pure, with negations: the pending matches whose negated types are
        complete now and hold, into the provenance table (one statement)."""
        a = self.aliases()
        return (self._prov_insert() + f"SELECT {', '.join(self._prov_values(a))} FROM "
                f"{self._pending_join(a)} AND {self.neg_complete(a)} AND {self.neg_ok(a)}"
                + self._match_order(a))

    def pending_match_delete(self) -> str:
        """Delete the pending matches that can be decided now (made, or refuted)."""
        a = self.aliases()
        return (f"DELETE FROM slr_cep_pending WHERE id IN (SELECT p.id FROM "
                f"{self._pending_join(a)} AND {self.neg_complete(a)})")

    def partners_linked(self, pos: int) -> dict[int, int]:
        """The partners of terminator position ``pos`` by the group of partners whose rows
        constrain each other once the terminator's row is chosen (position -> the group's
        first position): two partners are in one group when a condition reads both (a
        relation, a ``where``, rows of one type told apart, a variable they share that the
        terminator does not have), and all are in one when the pattern has a ``cnot`` (its
        condition reads the whole interval).

        Under ``recent`` a partner's row is the newest for which rows of the partners after
        it exist (:meth:`_choose`); the rows of another group do not depend on its choice
        and exist or not whatever it is, so only its own group's partners are asked for.
        An ``and`` of n atoms sharing a variable with the terminator is n - 1 groups of one:
        n - 1 small sub-queries instead of an EXISTS over up to n - 2 tables in each, which
        SQLite took ~0.1 s per statement to plan at 30 parts (a first decision of every
        position, 3.5-15 s). A variable the terminator has ties each partner to the
        terminator's row: equal values of equal SQL types are an equivalence.

        >>> from slr_sql.cep.rules import compile_rule
        >>> from slr_sql.parser import parse_program
        >>> def linked(text, pos):
        ...     alt = compile_rule(parse_program(text)[0]).alternatives[0]
        ...     k = len(alt.leaves)
        ...     sql = AltSQL(alt, 0, ['"t"'] * k, [], (), "recent", lambda *a: "1")
        ...     return sql.partners_linked(pos)
        >>> linked("c(X) <- a(X) and b(X) and d(X).", 2)
        {0: 0, 1: 1}
        >>> linked("c(X) <- a(X) and b(X, Y) and d(Y).", 0)
        {1: 1, 2: 1}
        >>> linked("c(X) <- a(X) seq b(X) seq d(X).", 2)
        {0: 0, 1: 0}
        """
        group = {p: p for p in range(self.k) if p != pos}

        def find(p: int) -> int:
            while group[p] != p:
                p = group[p]
            return p

        def join(positions: Any) -> None:
            found = sorted(find(p) for p in positions if p is not None and p != pos)
            for p in found[1:]:
                group[p] = found[0]

        if self.negs:
            join(group)
        for n in self._plain_conds:
            join(self.conds[n].positions)
        for key, nodes in self._occurrences.items():
            positions = {node[1] for node in nodes}
            # (a shared variable of the terminator: each occurrence is tied to a chosen row)
            if key[0] != "eq" or pos not in positions or None in positions:
                join(positions)
        return {p: find(p) for p in sorted(group)}

    def _recent_insert(self, pos: int, pending: bool = False, span: bool = False) -> str:
        """recent, pure: for every new terminator at ``pos`` whose inputs are complete up to
        its end, the match with the newest partners, chosen by nested correlated
        sub-queries (each partner: the newest for which the remaining partners exist).
        ``pending``: the terminators kept in slr_cep_pending instead of the new rows;
        ``span``: those of the spans kept there."""
        t = "e%d" % pos
        top = self.aliases()
        chosen = {pos}
        joins = []
        partners = self.partner_order(pos)
        linked = self.partners_linked(pos)
        for level, p in enumerate(partners):
            # (only the partners whose choice depends on p's: see partners_linked)
            rest = [r for r in partners[level + 1:] if linked[r] == linked[p]]
            sub = self._choose(pos, p, chosen, rest, top, level)
            joins.append(f"JOIN {self.tables[p]} AS e{p} ON e{p}.seq = ({sub})")
            chosen = chosen | {p}
        own = self.cond_sql(top, within={pos})
        conds = [self.inputs_complete(f"{t}.t_end")] + own
        if not partners and self.negs:
            # the partners' sub-queries check the negations; a one-atom pattern has none
            conds.append(self.neg_ok(top))
        if span:
            source = self._span_join(pos)
            conds = self._span_conditions(pos) + conds
        elif pending:
            source = (f"slr_cep_pending AS p JOIN {self.tables[pos]} AS {t} ON {t}.seq = "
                      f"{self.dialect.json_integer('p.rowids', 0)}")
            conds = ["p.rule = :rule", f"p.alt = {self.index}", "p.kind = 'term'",
                     f"p.pos = {pos}", "p.wait_type IS NULL"] + conds
        else:
            source = f"{self.tables[pos]} AS {t}"
            conds = [f"{t}.seq > :w{pos}"] + conds
        return (self._prov_insert() + f"SELECT {', '.join(self._prov_values(top))} FROM "
                f"{source} {' '.join(joins)} WHERE {self._where(conds)}")

    def _choose(self, pos: int, p: int, chosen: set, rest: list, top: dict,
                level: int) -> str:
        """SELECT the seq of the newest row for position p given the chosen rows (aliases
        of ``top``) such that rows for ``rest`` exist."""
        q = f"q{level}_"
        aliases = dict(top)
        aliases[f"e{p}"] = f"{q}e{p}"
        for r in rest:
            aliases[f"e{r}"] = f"{q}e{r}"
        have = chosen | {p}
        conds = self.cond_sql(aliases, within=have, exclude=chosen, order=[p])
        conds += self._terminator_one(pos, p, aliases)
        if rest:
            inner_have = have | set(rest)
            from_rest = not self.anchored(p, chosen) and all(self.anchored(r, chosen)
                                                             for r in rest)
            # (searched from the rest, p is joined after them)
            inner = self.cond_sql(aliases, within=inner_have, exclude=have,
                                  order=rest + [p] if from_rest else rest)
            for r in rest:
                inner += self._terminator_one(pos, r, aliases)
            if self.negs:
                inner.append(self.neg_ok(aliases))
            if from_rest:
                # p's history has no bound but the rest's has (seq with a where over the
                # times): search from the few rows of the rest, the newest p among their
                # partners (the same row as the EXISTS form, found from the other side)
                keys = self._key_order(p, aliases[f"e{p}"], True,
                                       self._fixed_args(p, chosen))
                froms = " CROSS JOIN ".join(f"{self.tables[r]} AS {aliases[f'e{r}']}"
                                            f"{self._anchor_hint(r, chosen)}"
                                            for r in rest + [p])
                # (implied: p ends no later than the terminator, and starts before it
                # ends; the (key, start) index then reaches only the rows in between)
                implied = [f"{aliases[f'e{p}']}.t_start <= {aliases[f'e{pos}']}.t_end"]
                return (f"SELECT {aliases[f'e{p}']}.seq FROM {froms} WHERE "
                        f"{self._where(conds + inner + implied)} ORDER BY {', '.join(keys)} "
                        f"LIMIT 1")
            froms = ", ".join(f"{self.tables[r]} AS {aliases[f'e{r}']}" for r in rest)
            conds.append(f"EXISTS (SELECT 1 FROM {froms} WHERE {self._where(inner)})")
        elif self.negs:
            conds.append(self.neg_ok(aliases))
        keys = self._key_order(p, aliases[f"e{p}"], True, self._fixed_args(p, chosen))
        return (f"SELECT {aliases[f'e{p}']}.seq FROM {self.tables[p]} AS {aliases[f'e{p}']} "
                f"WHERE {self._where(conds)} ORDER BY {', '.join(keys)} LIMIT 1")

    def _terminator_one(self, pos: int, j: int, aliases: dict[str, str]) -> list[str]:
        t, x = aliases[f"e{pos}"], aliases[f"e{j}"]
        cmp = "<=" if j < pos else "<"
        return [f"{x}.t_end <= {t}.t_end AND ({x}.t_end, {x}.t_start) {cmp} "
                f"({t}.t_end, {t}.t_start)"]

    def term_ready(self, pos: int) -> str:
        key = ("term_ready", pos)
        sql = self._cache.get(key)
        if sql is None:
            sql = self._cache[key] = self._term_ready(pos)
        return sql

    def _term_ready(self, pos: int) -> str:
        """New rows at terminator position ``pos`` whose inputs are complete up to their end
        (decided at once): their seq and end."""
        a = self.aliases()
        t = a[f"e{pos}"]
        conds = [f"{t}.seq > :w{pos}"] + self.cond_sql(a, within={pos}) \
            + [self.inputs_complete(f"{t}.t_end")]
        return (f"SELECT {t}.seq, {t}.t_end FROM {self.tables[pos]} AS {t} "
                f"WHERE {self._where(conds)} ORDER BY {t}.t_end, {t}.t_start, {t}.seq")

    def term_pending(self, pos: int, only_incomplete: bool) -> str:
        key = ("term_pending", pos, only_incomplete)
        sql = self._cache.get(key)
        if sql is None:
            sql = self._cache[key] = self._term_pending(pos, only_incomplete)
        return sql

    def _term_pending(self, pos: int, only_incomplete: bool) -> str:
        """New rows at terminator position ``pos`` kept as pending decisions (all of them,
        or only those whose inputs are not complete up to their end yet)."""
        a = self.aliases()
        t = a[f"e{pos}"]
        conds = [f"{t}.seq > :w{pos}"] + self.cond_sql(a, within={pos})
        if only_incomplete:
            conds.append(f"NOT ({self.inputs_complete(f'{t}.t_end')})")
        return ("INSERT INTO slr_cep_pending (rule, alt, kind, pos, rowids, t_start, t_end, "
                "created_at) "
                f"SELECT :rule, {self.index}, 'term', {pos}, {self.dialect.json_array(f'{t}.seq')}, "
                f"{t}.t_start, {t}.t_end, :now FROM {self.tables[pos]} AS {t} "
                f"WHERE {self._where(conds)}")

    def used_insert(self) -> str:
        return self.dialect.insert_ignore(self.used_table, "tbl, seq", "?, ?")


# ---------------------------------------------------------------------------- the runtime's
# The statements of the rule runtime around the delta statements (slr_sql/cep/runtime.py):
# provenance rows, pending decisions, the copy of matches into the complex event type's
# table, the catalog of installed rules. Values are named parameters; tables come quoted.

_PENDING_COLUMNS = ("rule", "alt", "kind", "pos", "rowids", "t_start", "t_end", "wait_type",
                    "wait_arity", "wait_time", "wait_reason", "created_at")
_PENDING_READ = ("SELECT id, alt, kind, pos, rowids, t_start, t_end, wait_type, wait_arity, "
                 "wait_time FROM slr_cep_pending WHERE rule = :rule")


def create_index(name: str, table: str, columns: list[str], dialect: Any = SQLITE) -> list[str]:
    """The indexes a rule's statements search (created once, kept with the table): over
    its data arguments as the ``dialect``'s key indexes (any length on PostgreSQL).

    >>> create_index("slr_cep_ix__a__arg2_end", "a", ["arg2", "t_end", "t_start"])
    ['CREATE INDEX IF NOT EXISTS "slr_cep_ix__a__arg2_end" ON "a" (arg2, t_end, t_start)']
    >>> from slr_sql.store.dialect import POSTGRES
    >>> create_index("slr_cep_ix__a__arg2_end", "a", ["arg2", "t_end"], POSTGRES)[1]
    'CREATE INDEX IF NOT EXISTS "slr_cep_ix__a__arg2_end_k" ON "a" (slr_key(arg2), t_end)'
    """
    keys = [c for c in columns if c.startswith("arg")]
    rest = [c for c in columns if not c.startswith("arg")]
    return [f"CREATE INDEX IF NOT EXISTS {quote_identifier(name + suffix)} ON "
            f"{quote_identifier(table)} {indexed}"
            for suffix, indexed in dialect.key_indexes(keys, rest)]


def max_id(table: str) -> str:
    """The greatest ``id`` of a (quoted) provenance table, 0 when empty.

    >>> max_id('"slr_cep_m_x"')
    'SELECT coalesce(max(id), 0) FROM "slr_cep_m_x"'
    """
    return f"SELECT coalesce(max(id), 0) FROM {table}"


def max_seq(table: str) -> str:
    """The greatest ``seq`` of a (quoted) event table, 0 when empty.

    >>> max_seq('"a"')
    'SELECT coalesce(max(seq), 0) FROM "a"'
    """
    return f"SELECT coalesce(max(seq), 0) FROM {table}"


def watermarks(event_tables: list[str], prov_tables: list[str]) -> str:
    """In one row: the greatest ``seq`` of each (quoted) event table, then the greatest
    ``id`` of each provenance table (0 when empty).

    >>> watermarks(['"a"'], ['"slr_cep_m_x"'])
    'SELECT (SELECT coalesce(max(seq), 0) FROM "a"), (SELECT coalesce(max(id), 0) FROM "slr_cep_m_x")'
    """
    return "SELECT " + ", ".join([f"({max_seq(t)})" for t in event_tables]
                                 + [f"({max_id(t)})" for t in prov_tables])


def pending_insert() -> str:
    """One pending decision; its values as the parameters named after the columns.

    >>> pending_insert().split(" VALUES ")[1][:18]
    '(:rule, :alt, :kin'
    """
    return (f"INSERT INTO slr_cep_pending ({', '.join(_PENDING_COLUMNS)}) VALUES "
            f"({', '.join(':' + c for c in _PENDING_COLUMNS)})")


def pending_row(values: tuple) -> dict:
    """The parameters of :func:`pending_insert` for ``values`` in the columns' order.

    >>> pending_row(("k", 0, "term", 1, "[7]", 1.0, 2.0, None, None, None, None, 3.0))["rowids"]
    '[7]'
    """
    return dict(zip(_PENDING_COLUMNS, values))


def provenance_columns(width: int, arity: int) -> list[str]:
    """The columns a provenance row is written with (:func:`provenance_insert`).

    >>> provenance_columns(2, 1)
    ['alt', 'r1', 'r2', 't_start', 't_end', 'h1', 'detected']
    """
    return (["alt"] + [f"r{p + 1}" for p in range(width)] + ["t_start", "t_end"]
            + [f"h{i + 1}" for i in range(arity)] + ["detected"])


def provenance_insert(prov: str, width: int, arity: int) -> str:
    """One match found on the Python side into the provenance table; positional
    parameters in :func:`provenance_columns` order (a match is a tuple of those values:
    no dict per match).

    >>> provenance_insert('"m"', 1, 0)
    'INSERT INTO "m" (alt, r1, t_start, t_end, detected) VALUES (?, ?, ?, ?, ?)'
    """
    cols = provenance_columns(width, arity)
    return f"INSERT INTO {prov} ({', '.join(cols)}) VALUES ({', '.join('?' * len(cols))})"


def pending_of_rule(order: bool) -> str:
    """The pending decisions of rule ``:rule`` (in decision order when ``order``).

    >>> pending_of_rule(True).endswith("WHERE rule = :rule ORDER BY t_end, t_start, id")
    True
    """
    return _PENDING_READ + (" ORDER BY t_end, t_start, id" if order else "")


def pending_of_group(waiting: bool) -> str:
    """The pending decisions of one group: rule ``:rule``, alternative ``:alt``, kind
    ``:kind``, waiting on nothing or on the type ``:wait_type``/``:wait_arity``.

    >>> "wait_type IS NULL" in pending_of_group(False), "wait_type = :wait_type" in pending_of_group(True)
    (True, True)
    """
    if not waiting:
        return (_PENDING_READ + " AND alt = :alt AND kind = :kind AND wait_type IS NULL "
                "ORDER BY t_end, t_start, id")
    return (_PENDING_READ + " AND alt = :alt AND kind = :kind AND wait_type = :wait_type "
            "AND wait_arity = :wait_arity ORDER BY wait_time, t_end, id")


def rows_by_seq(table: str, arity: int, count: int) -> str:
    """seq and arguments of the rows of a (quoted) event table whose seq is one of
    ``:s0`` .. ``:s<count-1>``.

    >>> rows_by_seq('"a"', 1, 2)
    'SELECT seq, arg1 FROM "a" WHERE seq IN (:s0, :s1)'
    """
    cols = ", ".join(["seq"] + [f"arg{j + 1}" for j in range(arity)])
    return (f"SELECT {cols} FROM {table} WHERE seq IN "
            f"({', '.join(f':s{i}' for i in range(count))})")


def pending_wait() -> str:
    """Record what pending decision ``:id`` waits for (all NULL: nothing).

    >>> pending_wait().endswith("WHERE id = :id")
    True
    """
    return ("UPDATE slr_cep_pending SET wait_type = :wait_type, wait_arity = :wait_arity, "
            "wait_time = :wait_time, wait_reason = :wait_reason WHERE id = :id")


def pending_delete(count: int) -> str:
    """Delete the pending decisions ``:d0`` .. ``:d<count-1>``.

    >>> pending_delete(2)
    'DELETE FROM slr_cep_pending WHERE id IN (:d0, :d1)'
    """
    return (f"DELETE FROM slr_cep_pending WHERE id IN "
            f"({', '.join(f':d{i}' for i in range(count))})")


def pending_delete_listed(dialect: Any) -> str:
    """Delete the pending decisions whose ids are in the JSON array ``:ids``.

    >>> from slr_sql.store.dialect import SQLITE
    >>> pending_delete_listed(SQLITE)
    'DELETE FROM slr_cep_pending WHERE id IN (SELECT value FROM json_each(:ids))'
    """
    return f"DELETE FROM slr_cep_pending WHERE id IN ({dialect.json_integers(':ids')})"


def pending_summary(dialect: Any) -> str:
    """Per group of rule ``:rule``'s pending decisions: the earliest time it waits for, the
    earliest end and the count of decisions (a span counts its terminators).

    >>> from slr_sql.store.dialect import SQLITE
    >>> pending_summary(SQLITE).endswith("GROUP BY alt, kind, wait_type, wait_arity")
    True
    """
    return ("SELECT alt, kind, wait_type, wait_arity, min(coalesce(wait_time, t_end)), "
            "min(t_end), sum(CASE WHEN kind = 'span' THEN "
            f"{dialect.json_integer('rowids', 2)} ELSE 1 END) FROM slr_cep_pending "
            "WHERE rule = :rule GROUP BY alt, kind, wait_type, wait_arity")


def complex_copy(table: str, prov: str, arity: int, returning: bool) -> str:
    """Copy the matches after provenance id ``:before`` into the complex event type's
    (quoted) table, arrival ``:now``, robot ``:robot``; ``returning``: the rows stored (a
    buffer's trigger may refuse some).

    >>> complex_copy('"c"', '"m"', 1, False)
    'INSERT INTO "c" (arg1, t_start, t_end, arrival, robot) SELECT h1, t_start, t_end, :now, :robot FROM "m" WHERE id > :before ORDER BY id'
    """
    values = [f"h{i + 1}" for i in range(arity)] + ["t_start", "t_end"]
    cols = [f"arg{i + 1}" for i in range(arity)] + ["t_start", "t_end"]
    sql = (f"INSERT INTO {table} ({', '.join(cols)}, arrival, robot) "
           f"SELECT {', '.join(values)}, :now, :robot FROM {prov} WHERE id > :before "
           f"ORDER BY id")
    return sql + f" RETURNING {', '.join(cols)}" if returning else sql


def complex_read(prov: str, arity: int) -> str:
    """The head values and times of the matches after provenance id ``:before``.

    >>> complex_read('"m"', 1)
    'SELECT h1, t_start, t_end FROM "m" WHERE id > :before ORDER BY id'
    """
    values = [f"h{i + 1}" for i in range(arity)] + ["t_start", "t_end"]
    return f"SELECT {', '.join(values)} FROM {prov} WHERE id > :before ORDER BY id"


def rule_record() -> str:
    """Record an installed rule in the catalog (once per key).

    >>> rule_record().endswith("ON CONFLICT(key) DO NOTHING")
    True
    """
    return ("INSERT INTO slr_cep_rules (key, head, rule, policy, source, prov_table, "
            "installed_at) VALUES (:key, :head, :rule, :policy, :source, :prov_table, "
            ":installed_at) ON CONFLICT(key) DO NOTHING")


def query_plan(sql: str) -> str:
    """The statement asking SQLite how it runs ``sql`` (explain).

    >>> query_plan("SELECT 1")
    'EXPLAIN QUERY PLAN SELECT 1'
    """
    return "EXPLAIN QUERY PLAN " + sql
