"""The ``where`` goals SQL cannot take, run per candidate match as a synchronized query.

A candidate match binds the pattern's variables; the goals then run exactly as the
synchronized query ⟨G, E⟩ would (E: the end of the match's interval), through the compiled
SQL statement when the goal compiles (:mod:`slr_sql.planner`) and in the interpreter
otherwise: first every event type of G's goal set must be complete up to E, then every
prev/next must read a complete history (the interpreter's hooks stop the run at the first one
that does not). When a history is not complete yet, :class:`MustWait` says which and up to
when; the candidate is kept and tried again once it is.

Each solution gives one complex event; an error raised by G (a type error in arithmetic, a
time limit) rejects the candidate and is counted on the rule (``kb.event_rules()``).
"""
from __future__ import annotations

import time
from typing import Any, Callable

from ..analysis import goal_set
from ..errors import SLRError
from ..store import DatabaseError
from ..encoding import Unencodable
from ..terms import Struct, Var, deref, format_term, is_ground, term_vars
from ..unify import resolve
from ..host import Host
from ..plans import instantiate

__all__ = ["MustWait", "Residual", "WHERE_TIMEOUT"]

WHERE_TIMEOUT = 5.0   # seconds for one evaluation of a where goal


class MustWait(Exception):
    """The history of ``key`` is not complete up to ``time`` yet."""

    def __init__(self, key: tuple[str, int], time: float, reason: str):
        super().__init__(f"{key[0]}/{key[1]} up to {time} ({reason})")
        self.key = key
        self.time = time
        self.reason = reason


class Residual:
    """The residual goals of one alternative: a conjunction whose variables bound by the
    pattern are inputs (``I0``, ``I1``, ...) and whose head variables it binds are outputs
    (``O0``, ...)."""

    def __init__(self, goals: list, inputs: list[Var], outputs: list[Var]):
        names: dict[int, Var] = {}
        for n, v in enumerate(inputs):
            names[id(v)] = Var(f"I{n}")
        for n, v in enumerate(outputs):
            names.setdefault(id(v), Var(f"O{n}"))
        local = [0]

        def rename(t: Any) -> Any:
            t = deref(t)
            if type(t) is Var:
                v = names.get(id(t))
                if v is None:
                    v = names[id(t)] = Var(f"_L{local[0]}")
                    local[0] += 1
                return v
            if type(t) is Struct:
                return Struct(t.name, tuple(rename(a) for a in t.args))
            return t

        renamed = [rename(g) for g in goals]
        goal = renamed[-1]
        for g in reversed(renamed[:-1]):
            goal = Struct(",", (g, goal))
        self.goal = goal
        self.text = format_term(goal)
        present = {v.name for v in term_vars(goal)}
        self.inputs = [(v, f"I{n}") for n, v in enumerate(inputs) if f"I{n}" in present]
        self.outputs = [(v, f"O{n}") for n, v in enumerate(outputs)]
        self._program = None
        self.reads: frozenset = frozenset()
        self.unknown = False
        self.last_engine = ""

    def analyse(self, program: Any, known: set) -> frozenset:
        """The event types the goals read (goal set, prev/next included); cached per
        program."""
        if self._program is not program:
            gs = goal_set(program, self.goal)
            self.unknown = gs.unknown
            if gs.unknown:
                gs = goal_set(program, self.goal, known_types=known)
            self.reads = frozenset(gs)
            self._program = program
        return self.reads

    def solve(self, kb: Host, values: dict, at: float,
              complete: Callable[[tuple, float], bool], skip: frozenset = frozenset(),
              use_sql: bool = True) -> list[dict]:
        """The solutions (dicts output name -> ground term) for the input ``values``
        (input name -> ground term, as decoded from the store: bound as they are). Raises
        :class:`MustWait`, or SLRError for an error of G.
        ``use_sql=False``: a goal that reads no stored event runs in the interpreter (there
        is nothing for SQL to read; a statement per candidate would only cost)."""
        for key in sorted(self.reads - skip):
            if not complete(key, at):
                raise MustWait(key, at, "the where goal's goal set")
        args = {name: values[name] for _, name in self.inputs}
        plan = kb.plans.plan(self.text, tuple(args))
        deadline = time.monotonic() + WHERE_TIMEOUT
        if kb.sql_enabled and use_sql:
            rows = self._sql(kb, plan, args, at, complete, deadline)
            if rows is not None:
                self.last_engine = "sql"
                return rows
        self.last_engine = "interpreter"
        return self._interpret(kb, plan, args, at, complete)

    def _sql(self, kb: Host, plan: Any, args: dict, at: float, complete: Callable,
             deadline: float) -> list | None:
        from ..planner import SqlPlan, plan_for

        entry = plan_for(kb, plan, True)
        if type(entry) is not SqlPlan:
            return None
        times = entry.history_times(at)
        if times is None:
            return None   # a prev/next time known row by row: the interpreter's hooks check it
        for key, t in times:
            if t is None:
                return None
            if not complete(key, float(t)):
                raise MustWait(key, float(t), "prev/next of the where goal")
        try:
            rows = entry.term_rows(kb, args, at, deadline)
        except (DatabaseError, Unencodable, ValueError, TypeError, KeyError, OverflowError):
            return None   # something only the interpreter does exactly
        out = []
        for row in rows:
            got = dict(row)
            sol = {}
            for _, name in self.outputs:
                t = got.get(name)
                if t is None or not is_ground(t):
                    break
                sol[name] = resolve(t)
            else:
                out.append(sol)
        return out

    def _interpret(self, kb: Host, plan: Any, args: dict, at: float,
                   complete: Callable) -> list:
        term, frame = instantiate(plan, args, terms=True)   # decoded: terms already
        m = kb.engine.machine(at=at, timeout=WHERE_TIMEOUT)

        def on_prev(name: str, n: int, t: float) -> None:
            if not complete((name, n), float(t)):
                raise MustWait((name, n), float(t), f"prev({name}/{n}) in the where goal")

        def on_next(name: str, n: int, lo: float, hi: float, *rest: Any) -> None:
            if not complete((name, n), float(hi)):
                raise MustWait((name, n), float(hi), f"next({name}/{n}) in the where goal")

        m.on_prev = on_prev
        m.on_next = on_next
        slots = dict(plan.names)
        out = []
        solving = m.solve(term)
        try:
            for _ in solving:
                sol = {}
                for _, name in self.outputs:
                    slot = slots.get(name)
                    t = resolve(frame[slot]) if slot is not None and frame[slot] is not None \
                        else None
                    if t is None or not is_ground(t):
                        break
                    sol[name] = t
                else:
                    out.append(sol)
        finally:
            m.abandon(solving)
        return out


def describe_error(exc: BaseException) -> str:
    """A one-line reason for a rejected candidate."""
    if isinstance(exc, SLRError):
        return str(exc).splitlines()[0]
    return f"{type(exc).__name__}: {exc}"
