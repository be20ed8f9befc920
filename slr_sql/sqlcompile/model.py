"""The shared model of the SQL compiler: what a variable is bound to while a goal is compiled
(:class:`Col`, a value known only when the statement runs), the branches it produces
(:class:`Part`), the walk's mutable state (:class:`State`), the call sites of det builtins
run from SQL (:class:`Site`, :data:`SITES`), and the term walks every part uses.
"""
from __future__ import annotations

import itertools
import weakref
from typing import Any

from ..store.dialect import SQLITE
from ..store.sqltext import joined_balanced
from ..terms import Atom, CheckedBodies, Struct, Var, body_problem, deref, list_items


class Fallback(Exception):
    """The goal cannot be compiled exactly; ``reason`` says why (shown by explain)."""

    def __init__(self, reason: str):
        super().__init__(reason)
        self.reason = reason


class Col:
    """A value known only when the statement runs: an SQL expression and what it can be.

    kinds: ``float`` (REAL: times), ``int`` (INTEGER: counts), ``num`` (INTEGER or REAL:
    arithmetic), ``text`` (encoded JSON text: findall lists), ``any`` (a stored value).

    ``src``: for an element taken out of a stored list or compound, ``(json, path)``: the SQL
    of the JSON text it sits in and the SQL of its JSON path (so a later pattern on it reads
    the element's parts from the same text instead of re-parsing its encoding).
    """

    __slots__ = ("sql", "kind", "src")

    def __init__(self, sql: str, kind: str = "any", src: tuple | None = None):
        self.sql = sql
        self.kind = kind
        self.src = src

    def __repr__(self) -> str:
        return f"Col({self.sql!r}, {self.kind!r})"


NUMERIC = frozenset(("float", "int", "num"))


def quote_ident(name: str) -> str:
    """An SQL identifier quoted (double quotes, an inner one doubled), safe for any name.

    >>> quote_ident("location/2"), quote_ident('a"b')
    ('"location/2"', '"a""b"')
    """
    return '"' + name.replace('"', '""') + '"'


class Site:
    """One call of a det builtin or a ``kb.define`` predicate from SQL (``slr_det``)."""

    __slots__ = ("fn", "python", "args", "cols", "outs", "engine", "last", "__weakref__")

    def __init__(self, fn, python, args, cols, outs, engine):
        self.fn = fn
        self.python = python
        self.args = args      # argument terms with ColRef(i) for the SQL inputs
        self.cols = cols      # number of SQL inputs
        self.outs = outs      # free variables whose values are returned
        self.engine = engine
        self.last = None      # (inputs, result) memo: one call serves all its outputs


SITES: "weakref.WeakValueDictionary[int, Site]" = weakref.WeakValueDictionary()


_site_ids = itertools.count(1)


def next_site_id() -> int:
    """A fresh number for a :class:`Site` (unique in this process, never reused).

    >>> next_site_id() < next_site_id()
    True
    """
    return next(_site_ids)


class ColRef:
    """Position ``i`` of a row (answer recipes) or of a function's inputs (sites)."""

    __slots__ = ("i",)

    def __init__(self, i: int):
        self.i = i


class Part:
    """One branch: a flat SELECT."""

    __slots__ = ("froms", "conds", "keys", "proj", "extra")

    def __init__(self, froms, conds, keys, proj=None, extra=None):
        self.froms = froms    # [(table sql, alias, id column)]
        self.conds = conds    # [sql]
        self.keys = keys      # [sql]
        self.proj = proj      # projected sql expressions
        self.extra = extra    # whatever the emitter attached (answer recipes)

    def from_sql(self) -> str:
        # CROSS JOIN: SQLite keeps the goal order as the join order (the binding order the
        # modes were computed for; each later table is reached through its indexes)
        return " CROSS JOIN ".join(f"{t} AS {a}" for t, a, _ in self.froms)

    def select(self, cols: list[str]) -> str:
        sql = "SELECT " + ", ".join(cols)
        if self.froms:
            sql += " FROM " + self.from_sql()
        if self.conds:
            sql += " WHERE " + joined_balanced(self.conds, "AND")
        return sql


def key_columns(parts: list[Part], dialect: Any) -> list[list[str]]:
    """Each branch's order keys as the columns ``k0..`` of a UNION ALL: a branch with fewer
    keys pads them with the ``dialect``'s NULL for the kind of keys at that place (a
    robot's name is text, the other keys numbers), which raises Unprintable where the
    dialect's columns cannot hold the kinds met there.

    >>> from slr_sql.store.dialect import SQLITE
    >>> key_columns([Part([], [], ["0", "t0.robot"]), Part([], [], ["1"])], SQLITE)
    [['0 AS k0', 't0.robot AS k1'], ['1 AS k0', 'NULL AS k1']]
    """
    width = max((len(p.keys) for p in parts), default=0)
    kinds = [frozenset("text" if k.endswith(".robot") else "number"
                       for p in parts if i < len(p.keys) for k in (p.keys[i],))
             for i in range(width)]
    padding = [dialect.key_padding(k) for k in kinds]
    return [[f"{k} AS k{i}" for i, k in enumerate(p.keys)]
            + [f"{padding[i]} AS k{i}" for i in range(len(p.keys), width)] for p in parts]


class _Conds(list):
    """The WHERE conditions of a branch; one that calls an slr_ function (which may raise
    an error Prolog would raise) is also recorded with its prefix (see Compiler.guards)."""

    __slots__ = ("st",)

    def append(self, cond: str) -> None:
        if self.st.may_raise(cond):
            self.st.raised(cond, len(self), True)
        list.append(self, cond)


class State:
    __slots__ = ("froms", "conds", "keys", "trail", "checks", "raising", "nested", "branches",
                 "live", "first", "may_raise")

    def __init__(self, may_raise: Any = SQLITE.may_raise):
        # which conditions may raise: a call of a function of the dialect's that can fail
        self.may_raise = may_raise
        self.froms: list = []
        self.conds: _Conds = _Conds()
        self.conds.st = self
        # (expr, froms prefix, conds prefix, is a condition, inside \+ or ->) of every goal
        # that may raise, in goal order; never undone (a branch that fails later still
        # evaluated it)
        self.raising: list = []
        self.nested = 0       # > 0 while a prev/next pattern is matched on its subquery alias
        # (froms, conds, live) of every branch emitted, subquery branches (findall, \+, ...)
        # included with the tables and conditions of the goals before them
        self.branches: list = []
        self.live: list = []  # indexes into raising of the goals on the current path
        self.first = 0        # > 0 inside a subquery SQLite stops at its first row (\+, ->)
        self.keys: list = []
        self.trail: list = []
        # values that may raise (arithmetic through slr_ functions, findall/aggregate_all
        # subqueries): SQLite computes a value only where the statement uses it, Prolog
        # computes it when the goal runs, so an unused one still gets a condition
        self.checks: list = []

    def raised(self, expr: str, nc: int, is_cond: bool) -> None:
        if not self.nested:
            self.live.append(len(self.raising))
            self.raising.append((expr, list(self.froms), list(self.conds[:nc]), is_cond,
                                 self.first > 0))

    def mark(self) -> tuple:
        return (len(self.froms), len(self.conds), len(self.keys), len(self.trail),
                len(self.checks), len(self.live))

    def restore(self, m: tuple) -> None:
        del self.froms[m[0]:]
        del self.conds[m[1]:]
        del self.keys[m[2]:]
        del self.checks[m[4]:]
        del self.live[m[5]:]
        trail = self.trail
        while len(trail) > m[3]:
            trail.pop().ref = None


def resolve(t: Any) -> Any:
    """The term with bound variables replaced by their values (Cols and free Vars kept).

    >>> X, Y = Var("X"), Var("Y"); X.ref = 1
    >>> resolve(Struct("f", (X, Y, Col("t0.arg1", "any"))))
    Struct('f', (1, Var('Y'), Col('t0.arg1', 'any')))
    """
    t = deref(t)
    if type(t) is Struct:
        if t.name == "." and len(t.args) == 2:
            items, tail = list_items(t)
            out = resolve(tail)
            for x in reversed(items):
                out = Struct(".", (resolve(x), out))
            return out
        return Struct(t.name, tuple(resolve(a) for a in t.args))
    return t


# The interpreter unifies without occurs check (as Prolog does) and can build X = f(X);
# the compiler's walks over bound terms would not terminate on one, so it leaves such goals
# to the interpreter.
CYCLIC = "a unification can build a cyclic term (no occurs check)"


def occurs_in(v: Var, t: Any) -> bool:
    """True if the variable ``v`` occurs in the term ``t`` (the occurs check).

    >>> X = Var("X"); occurs_in(X, Struct("f", (X,))), occurs_in(X, Atom("a"))
    (True, False)
    """
    stack = [t]
    while stack:
        x = deref(stack.pop())
        if x is v:
            return True
        if type(x) is Struct:
            stack.extend(x.args)
    return False


def _contains(t: Any, kind: type) -> bool:
    stack = [t]
    while stack:
        x = deref(stack.pop())
        if type(x) is kind:
            return True
        if type(x) is Struct:
            stack.extend(x.args)
    return False


def has_var(t: Any) -> bool:
    """True when the term (after dereferencing) still contains an unbound variable.

    >>> X = Var("X"); has_var(Struct("f", (X,))), has_var(Struct("f", (Col("t0.arg1", "any"),)))
    (True, False)
    >>> X.ref = 1; has_var(Struct("f", (X,)))
    False
    """
    return _contains(t, Var)


def has_float(t: Any) -> bool:
    """True if a float occurs in ``t`` (SQL's 1 = 1.0 is not a Prolog match).

    >>> has_float(Struct("f", (1, 2.0))), has_float(Struct("f", (1,)))
    (True, False)
    """
    return _contains(t, float)


def has_col(t: Any) -> bool:
    """True when the term contains a :class:`Col`, a value known only when the statement runs.

    >>> has_col(Struct("f", (Col("t0.arg1", "any"),))), has_col(Struct("f", (1,)))
    (True, False)
    """
    return _contains(t, Col)


def term_free_vars(t: Any) -> list:
    """The unbound variables of a term, each once, in left-to-right order.

    >>> X, Y = Var("X"), Var("Y")
    >>> term_free_vars(Struct("f", (Y, Struct("g", (X, Y)), 1)))
    [Var('Y'), Var('X')]
    """
    out, seen, stack = [], set(), [t]
    while stack:
        x = deref(stack.pop())
        if type(x) is Var:
            if id(x) not in seen:
                seen.add(id(x))
                out.append(x)
        elif type(x) is Struct:
            stack.extend(reversed(x.args))
    return out




def check_called_body(goal: Any, bodies: CheckedBodies | None = None) -> None:
    """A term called as a goal (a query, call/1, \\+, findall, aggregate_all, forall) is a
    body for the interpreter, which raises type_error(callable, Goal) before running it when
    a goal inside its control constructs is no callable term (engine.check_body): such a
    body, or one with a goal known only at run time there, runs in the interpreter.

    >>> check_called_body(Struct(",", (Atom("fail"), 1)))
    Traceback (most recent call last):
    ...
    slr_sql.sqlcompile.model.Fallback: fail,1 is not callable (type error at run time)
    """
    problem = body_problem(goal, unknown=Col) if bodies is None else bodies.problem(goal)
    if problem == "unknown":
        raise Fallback("a goal only known at run time inside a called body")
    if problem == "uncallable":
        raise Fallback(f"{format_for_message(deref(goal))} is not callable (type error at run "
                       f"time)")


def format_for_message(t: Any) -> str:
    """A term as Prolog text for a fallback reason; never raises (``repr`` otherwise).

    >>> format_for_message(Struct("f", (Atom("a"), 1)))
    'f(a,1)'
    """
    from ..terms import format_term

    try:
        return format_term(t)
    except Exception:
        return repr(t)


def shown_in_message(t: Any) -> Any:
    """A term for messages, stored values (:class:`Col`) shown as ``<stored value>``.

    >>> shown_in_message(Struct("f", (Atom("a"),)))
    Struct('f', (Atom('a'),))
    """
    t = deref(t)
    if type(t) is Col:
        return Atom("<stored value>")
    if type(t) is Struct:
        return Struct(t.name, tuple(shown_in_message(a) for a in t.args))
    return t
