"""The compiler's walk: :class:`Compiler` solves a goal depth-first as the interpreter does,
dispatching each goal to its handler (``<kind>_sql``, defined by the mixins of the other
modules of this package), and hands every branch it completes to the caller's ``emit``.
"""
from __future__ import annotations

import itertools
import math
from typing import Any, Callable

from ..program import event_key, split_event_atom
from ..store.dialect import SQLITE
from ..terms import Atom, CheckedBodies, Struct, Var, deref
from .aggregates import AggregateGoals
from .builtin_goals import BuiltinGoals
from .control import ControlGoals, IfThenMarker
from .events import EventGoals
from .guards import unused_checks
from .model import (Col, Fallback, Part, Site, State, check_called_body, format_for_message,
                    has_var)
from .rules import RuleGoals
from .unify import Unification


CONTROL_FALLBACK = {
    ("!", 0): "cut (!)",
    ("*->", 2): "soft-cut (*->)",
    ("catch", 3): "catch/3",
    ("throw", 1): "throw/1",
    ("findall", 4): "findall/4 (difference list)",
    ("bagof", 3): "bagof/3 (free-variable grouping)",
    ("setof", 3): "setof/3 (free-variable grouping)",
}


class Compiler(Unification, BuiltinGoals, ControlGoals, RuleGoals, EventGoals, AggregateGoals):
    """Compiles goals for one knowledge base (``ctx`` gives the program, store, builtins).

    ``ctx`` needs: ``program``, ``library``, ``det``, ``nondet``, ``python_preds``,
    ``event_table(name, n)`` -> quoted table or None, ``fact_table(name, n)`` -> quoted table
    or None, ``engine``.
    """

    MAX_BRANCHES = 512

    def __init__(self, ctx: Any, has_at: bool, literal: bool = False, robot: bool = False):
        self.ctx = ctx
        # how the engine spells what differs (typeof, JSON, functions): the store's dialect
        self.dialect = getattr(ctx, "dialect", SQLITE)
        # every event row read must belong to each of these robots (terms unified with the
        # row's robot column): the query's robot (the parameter :robot), when it has one
        self.robot_terms: list[Any] = [Col(":robot", "any")] if robot else []
        self.program = ctx.program
        self.has_at = has_at
        self.literal = literal        # views: constants as literals, no parameters
        self.params: dict[str, Any] = {}
        # (argument parameter, its equality with a first argument for a short text, for a
        # long one): the statement has the first; a run with a long text, the second
        self.key_forms: list[tuple[str, str, str]] = []
        self._const: dict[tuple, str] = {}
        self._alias = itertools.count()
        self.missing: set = set()     # event types without a table when compiled
        self.sites: list[Site] = []
        self.uses_udf = False
        self.modes: list[str] = []
        self._modes_seen: set = set()
        self.branches = 0
        # the called bodies checked so far: a body inside one checked is not walked again
        # (\+ \+ ... nested N deep walked each nested body, N²/2 steps)
        self._bodies = CheckedBodies(unknown=Col)
        # ((name, n), upper time SQL) of every prev/next: a synchronized query may run the
        # statement once each history is complete up to its time (slr_sql.sync)
        self.time_sites: list[tuple[tuple[str, int], str]] = []
        # the event types the statement reads in start order (next's subquery): their
        # start-ordered indexes are made sure of before it runs (a complex type's are built
        # on first need, slr_sql.store.tables)
        self.start_ordered: set[tuple[str, int]] = set()
        self.read_types: set[tuple[str, int]] = set()   # the event types whose tables it reads
        # a prev/next time computed by SQL's own float arithmetic -> it checked for overflow
        self.finite_checks: dict[str, str] = {}

    # ------------------------------------------------------------------ helpers
    def alias(self, prefix: str = "t") -> str:
        return f"{prefix}{next(self._alias)}"

    def const(self, value: Any) -> str:
        """A bound parameter (or, for views, a literal) holding an SQL value."""
        key: tuple = (type(value), value)
        if type(value) is float:
            if value != value:
                raise Fallback("NaN constant")
            # -0.0 == 0.0 (and hashes alike): the sign keeps the two parameters apart
            key = (float, value, math.copysign(1.0, value))
        name = self._const.get(key)
        if name is not None:
            return name
        if self.literal:
            from ..store import sql_literal

            name = sql_literal(value)
        else:
            name = f":c{len(self._const)}"
            self.params[name[1:]] = value
        self._const[key] = name
        return name

    def stored(self, value: Any) -> str:
        """A bound parameter holding an encoded value as the engine's columns hold it."""
        to_column = self.dialect.to_column
        return self.const(value if to_column is None else to_column(value))

    def udf(self, sql: str) -> str:
        self.uses_udf = True
        return sql

    def record_mode(self, goal: Any) -> None:
        if len(self.modes) >= 60:
            return
        g = deref(goal)
        try:
            text = _mode_text(g)
        except Exception:
            return
        if text not in self._modes_seen:
            self._modes_seen.add(text)
            self.modes.append(text)

    def check_called_body(self, goal: Any) -> None:
        """:func:`check_called_body` with this compilation's bodies checked so far."""
        check_called_body(goal, self._bodies)

    # ------------------------------------------------------------------ driver
    def compile(self, goal: Any, emit: Callable[[State], None]) -> None:
        st = self.state = State(self.dialect.may_raise)
        self.check_called_body(goal)
        self.solve((goal, (), None), st, emit)

    def solve(self, cont, st: State, emit) -> None:
        if cont is None:
            self.branches += 1
            if self.branches > self.MAX_BRANCHES:
                raise Fallback(f"more than {self.MAX_BRANCHES} alternative paths")
            emit(st)
            return
        goal, ctx, nxt = cont
        self.goal_sql(goal, ctx, nxt, st, emit)

    def sub_parts(self, goal: Any, ctx: tuple, st: State,
                  project: Callable[[State], list] | None = None,
                  first: bool = False) -> list[Part]:
        """The branches of ``goal`` as a subquery of the current state (bindings undone)."""
        parts: list[Part] = []
        m = st.mark()

        def emit(s: State) -> None:
            # a subquery's branch is a path of its own goals only: the goals before it go
            # on with the goal after the subquery (which may never be reached)
            s.branches.append((list(s.froms), list(s.conds), frozenset(s.live[m[5]:])))
            proj = project(s) if project is not None else None
            conds = list(s.conds[m[1]:])
            keys = list(s.keys[m[2]:])
            conds += unused_checks(s.checks[m[4]:], conds + keys + (proj or []))
            parts.append(Part(list(s.froms[m[0]:]), conds, keys, proj))

        st.first += first
        try:
            self.solve((goal, ctx, None), st, emit)
        finally:
            st.first -= first
        st.restore(m)
        return parts

    # ------------------------------------------------------------------ dispatch
    def goal_sql(self, goal, ctx, nxt, st, emit) -> None:
        g = deref(goal)
        tg = type(g)
        if tg is Var:
            raise Fallback("a goal that is an unbound variable (call/N on an unknown goal)")
        if type(goal) is Var:
            self.check_called_body(g)    # a variable goal G is call(G)
        if tg is Col:
            raise Fallback("a goal only known at run time (call/N on an unknown goal)")
        if tg is IfThenMarker:
            return self.marker_sql(g, ctx, nxt, st, emit)
        if tg is Struct:
            name, args = str(g.name), g.args
        elif tg is Atom:
            name, args = str(g), ()
        else:
            raise Fallback(f"{format_for_message(g)} is not callable (type error at run time)")
        key = (name, len(args))
        ctl = CONTROL_SQL.get(key)
        if ctl is not None:
            return ctl(self, g, args, ctx, nxt, st, emit)
        if key in CONTROL_FALLBACK:
            raise Fallback(CONTROL_FALLBACK[key])
        pred = self.program.preds.get(key)
        if pred is not None:
            return self.call_sql(pred, ("pred", name, len(args)), args, ctx, nxt, st, emit)
        lib = self.ctx.library.preds.get(key)
        if lib is not None:
            return self.library_sql(key, args, ctx, nxt, st, emit)
        if key in self.ctx.det:
            return self.builtin_sql(key, args, ctx, nxt, st, emit)
        if key in (("prev", 2), ("next", 2), ("next", 3)):
            self.record_mode(g)
            return (self.prev_sql if name == "prev" else self.next_sql)(args, ctx, nxt, st, emit)
        if key == ("origin", 2):
            self.record_mode(g)
            return self.origin_sql(args, ctx, nxt, st, emit)
        if key == ("reverse", 2):
            return self.reverse_sql(args, nxt, st, emit)
        if key in self.ctx.nondet:
            raise Fallback(f"the builtin {name}/{len(args)} has no SQL form")
        fn = self.ctx.python_preds.get(key)
        if fn is not None:
            return self.det_sql(key, fn, True, args, nxt, st, emit)
        if key in self.program.dynamic:
            return  # fails
        if key in self.program.temporal:
            raise Fallback(f"{name}/{len(args)} is only defined with ^T: a plain call is an "
                           f"existence error at run time")
        raise Fallback(f"unknown predicate {name}/{len(args)} (existence error at run time)")


def _mode_text(g: Any) -> str:
    """``obj(-,+,-)^-``: + bound (known when the goal is reached), - free."""
    def m(t):
        t = deref(t)
        if type(t) is Var:
            return "-"
        if type(t) is Col or not has_var(t):
            return "+"
        return "?"
    ev = split_event_atom(g)
    if ev is not None:
        atom, s, e = ev
        atom = deref(atom)
        name, n = event_key(atom)
        args = atom.args if type(atom) is Struct else ()
        stamp = m(s) if deref(s) is deref(e) else f"[{m(s)},{m(e)}]"
        return f"{name}({','.join(m(a) for a in args)})^{stamp}" if args else f"{name}^{stamp}"
    if type(g) is Struct:
        if g.name in ("prev", "next"):
            inner = _mode_text(deref(g.args[0]))
            return f"{g.name}({inner}, {','.join(m(a) for a in g.args[1:])})"
        if g.name in ("findall", "aggregate_all", "\\+"):
            return f"{g.name}/{len(g.args)}"
        return f"{g.name}({','.join(m(a) for a in g.args)})"
    return str(g)


CONTROL_SQL = {
    (",", 2): Compiler.conj_sql,
    ("true", 0): Compiler.true_sql,
    ("fail", 0): Compiler.fail_sql,
    ("false", 0): Compiler.fail_sql,
    (";", 2): Compiler.disj_sql,
    ("->", 2): Compiler.ifthen_sql,
    ("\\+", 1): Compiler.neg_sql,
    ("not", 1): Compiler.neg_sql,
    ("^", 2): Compiler.caret_sql,
    ("forall", 2): Compiler.forall_sql,
    ("findall", 3): Compiler.findall_sql,
    ("findAll", 3): Compiler.findall_sql,
    ("aggregate_all", 3): Compiler.aggregate_sql,
}
for _n in range(1, 9):
    CONTROL_SQL[("call", _n)] = Compiler.call_n_sql
