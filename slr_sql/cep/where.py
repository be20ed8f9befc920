"""The ``where`` goals SQL cannot take, run per candidate match as a synchronized query.

A candidate match binds the pattern's variables; the goals then run exactly as the
synchronized query ⟨G, E⟩ would (E: the end of the match's interval), through the compiled
SQL statement when the goal compiles (:mod:`slr_sql.planner`) and in the interpreter
otherwise: first every event type of G's goal set must be complete up to E, then every
prev/next must read a complete history (the interpreter's hooks stop the run at the first one
that does not). When a history is not complete yet, :class:`MustWait` says which and up to
when; the candidate is kept and tried again once it is.

Each solution gives one complex event; an error raised by G (a type error in arithmetic, its
step budget spent) rejects the candidate and is counted on the rule (``kb.event_rules()``).

G's limit is a budget of work, not of time, so that a decision never depends on how fast or
busy the machine is (the same events and program derive the same complex events on every
machine, in every arrival order, on both backends): :data:`WHERE_MAX_STEPS` inference steps
in the interpreter. A compiled SQL statement has :data:`WHERE_SQL_INSTRUCTIONS` virtual
machine instructions on SQLite; a statement that runs out of them (or, on PostgreSQL, which
counts nothing a client could bound, of the backstop's time) decides nothing: the
interpreter then runs G under its step budget and decides. :data:`WHERE_BACKSTOP` seconds of
wall clock stay as a backstop against work no budget counts (one builtin call that loops
inside one step): far beyond what the budgets take, it is the only part that depends on the
machine.
"""
from __future__ import annotations

import time
from typing import Any, Callable, NamedTuple

import orjson

from ..analysis import goal_set
from ..builtins import BuiltinMachine
from ..errors import SLRError, SLRTimeout
from ..store import DatabaseError
from ..encoding import Unencodable, orjson_reads_exactly
from ..sql_functions import compare_terms
from ..terms import Atom, Struct, Var, deref, format_term, is_ground, term_vars
from ..unify import resolve
from ..host import Host
from ..plans import instantiate
from ..robotlib import apply_transforms, pos_multiply_subject, pose_transform

__all__ = ["MustWait", "Residual", "WHERE_MAX_STEPS", "WHERE_SQL_INSTRUCTIONS",
           "WHERE_BACKSTOP"]

# Inference steps of one evaluation of a where goal in the interpreter (counted as
# kb.query's max_steps, checked every 2048 steps): about what 5 s of the interpreter buys
# (benchmarks/bench_where_budget.py, two cores under load 4-5: 1.0-1.7 million steps of a
# recursive loop with arithmetic, 2.0-2.7 million of event goals, 1.9-4.5 million of
# findall/length, 5.6-9.7 million of between/3).
WHERE_MAX_STEPS = 2_000_000
# SQLite virtual machine instructions of each statement of a where goal's compiled SQL: what
# 1.5-2.5 s of plain SQLite work buys and ~10 s of JSON functions on every row, the slowest
# kind (5 s buy, measured likewise: 200-270 million instructions of a recursive CTE, 300-375
# million of a plain join, 44-48 million of JSON functions per row), so that the slowest
# statement spends its budget in about the time the slowest interpreter work spends its own.
WHERE_SQL_INSTRUCTIONS = 100_000_000
# Seconds of wall clock, only against work the budgets do not count (a builtin looping
# inside one step, a Python function called from SQL) and PostgreSQL's statements: the
# slowest work above spends either budget in ~10 s, so a machine ~6 times slower still
# meets the budget first.
WHERE_BACKSTOP = 60.0


class MustWait(Exception):
    """The history of ``key`` is not complete up to ``time`` yet."""

    def __init__(self, key: tuple[str, int], time: float, reason: str):
        super().__init__(f"{key[0]}/{key[1]} up to {time} ({reason})")
        self.key = key
        self.time = time
        self.reason = reason


def compares(goal: Struct, values: dict) -> bool:
    """Whether the comparison ``goal`` (``I0 < I1 + 1``: its inputs named ``I0``, ``I1``, ...)
    holds for the ground terms ``values`` (input name -> term), as an event rule's statement
    decides it on SQLite (:func:`~slr_sql.sql_functions.compare_terms`: an error is no
    match).

    >>> from slr_sql.terms import Atom
    >>> below = Struct("<", (Var("I0"), 5))
    >>> compares(below, {"I0": 3}), compares(below, {"I0": Atom("a")})
    (True, False)
    """
    def put(t: Any) -> Any:
        t = deref(t)
        if type(t) is Var:
            return values.get(t.name, t)
        if type(t) is Struct:
            return Struct(t.name, tuple(put(a) for a in t.args))
        return t

    return compare_terms(str(goal.name), put(goal.args[0]), put(goal.args[1]))


class Residual:
    """The residual goals of one alternative: a conjunction whose variables bound by the
    pattern are inputs (``I0``, ``I1``, ...) and whose head variables it binds are outputs
    (``O0``, ...)."""

    def __init__(self, goals: list, inputs: list[Var], outputs: list[Var],
                 quiet: list = ()):
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

        # the comparisons SQLite's statement decides (sqlgen.QUIET) on a server that calls
        # no Python: decided first, as Prolog evaluates them, an error no match (uncounted)
        self.quiet = [rename(g) for g in quiet]
        renamed = [rename(g) for g in goals] or [Atom("true")]
        goal = renamed[-1]
        for g in reversed(renamed[:-1]):
            goal = Struct(",", (g, goal))
        self.goal = goal
        self.only_quiet = not goals
        self.text = format_term(goal)
        present = {v.name for v in term_vars(goal)}
        present.update(v.name for g in self.quiet for v in term_vars(g))
        self.inputs = [(v, f"I{n}") for n, v in enumerate(inputs) if f"I{n}" in present]
        self.outputs = [(v, f"O{n}") for n, v in enumerate(outputs)]
        self._program = None
        self._calls_of: Any = None   # the program _calls was worked out for
        self._calls: list | None = None
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
        if self.quiet and not all(compares(g, values) for g in self.quiet):
            return []   # (as SQLite's statement leaves the candidate out: nothing waits)
        if self.only_quiet:
            return [{}]
        for key in sorted(self.reads - skip):
            if not complete(key, at):
                raise MustWait(key, at, "the where goal's goal set")
        args = {name: values[name] for _, name in self.inputs}
        if not use_sql:
            calls = self.builtin_calls(kb.engine)
            if calls:
                solutions = self._call_builtins(kb.engine, calls, args, at)
                if solutions is not None:
                    self.last_engine = "builtins"
                    return solutions
        plan = kb.plans.plan(self.text, tuple(args))
        if kb.sql_enabled and use_sql:
            rows = self._sql(kb, plan, args, at, complete)
            if rows is not None:
                self.last_engine = "sql"
                return rows
        self.last_engine = "interpreter"
        return self._interpret(kb, plan, args, at, complete)

    def builtin_calls(self, engine: Any) -> list | None:
        """The goal as a conjunction of calls to deterministic builtins (``pos_multiply``,
        ``is``-free arithmetic helpers, ...) that no program or library predicate of the same
        name hides, or None; worked out once per program."""
        program = engine.program
        if self._calls_of is not program:
            from ..engine import CONTROL

            calls: list | None = []
            stack = [self.goal]
            while stack and calls is not None:
                g = deref(stack.pop())
                if type(g) is Struct and g.name == "," and len(g.args) == 2:
                    stack += [g.args[1], g.args[0]]
                    continue
                key = (g.name, len(g.args)) if type(g) is Struct else None
                fn = engine.det.get(key) if key is not None else None
                if fn is None or key in CONTROL or key in program.preds \
                        or key in engine.library.preds:
                    calls = None
                else:
                    calls.append((key, fn, g.args))
            self._calls, self._calls_of = calls, program
        return self._calls

    def plain_function(self, engine: Any) -> tuple[list[str], str, PlainBuiltin] | None:
        """The goal as one builtin with a function of plain values (:data:`PLAIN_BUILTINS`):
        ``(input names, output name, builtin)``, the builtin's readers taking the inputs'
        stored values in that order; None for any other goal."""
        calls = self.builtin_calls(engine)
        if not calls or len(calls) != 1 or calls[0][0] not in PLAIN_BUILTINS:
            return None
        _, _, (items, out) = calls[0]
        names = []
        items = deref(items)
        while type(items) is Struct and items.name == "." and len(items.args) == 2:
            v = deref(items.args[0])
            if type(v) is not Var or not v.name.startswith("I"):
                return None
            names.append(v.name)
            items = deref(items.args[1])
        out = deref(out)
        if items != "[]" or type(out) is not Var or not out.name.startswith("O"):
            return None
        return names, out.name, PLAIN_BUILTINS[calls[0][0]]

    def _call_builtins(self, engine: Any, calls: list, args: dict,
                       at: float) -> list | None:
        """Run :meth:`builtin_calls` straight, as the interpreter would run the conjunction
        (each call once, left to right, no choice point); its one solution, none, or None
        when the interpreter must decide (an exception other than an evaluation error)."""
        from ..engine import PrologThrow

        names: dict = dict(args)

        def put(t: Any) -> Any:
            t = deref(t)
            if type(t) is Var:
                v = names.get(t.name)
                if v is None:
                    v = names[t.name] = Var(t.name)
                return v
            if type(t) is Struct:
                return Struct(t.name, tuple(put(a) for a in t.args))
            return t

        m = BuiltinMachine(engine)
        m.at = at   # (the interpreter runs the goal at the match's end)
        # a builtin's own loop (numlist/3 building millions of cells) counts no steps: the
        # backstop bounds it, as in the interpreter
        m.deadline = time.monotonic() + WHERE_BACKSTOP
        try:
            for _, fn, call_args in calls:
                if not fn(m, tuple(put(a) for a in call_args)):
                    return []
        except (PrologThrow, MemoryError, RecursionError, AttributeError):
            return None
        sol = {}
        for _, name in self.outputs:
            t = names.get(name)
            t = resolve(t) if t is not None else None
            if t is None or not is_ground(t):
                return []
            sol[name] = t
        return [sol]

    def _sql(self, kb: Host, plan: Any, args: dict, at: float,
             complete: Callable) -> list | None:
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
            rows = entry.term_rows(kb, args, at, time.monotonic() + WHERE_BACKSTOP,
                                   WHERE_SQL_INSTRUCTIONS)
        except SLRTimeout:
            # out of its instructions (or, on PostgreSQL, of the backstop's time): how long
            # SQL takes decides nothing, the interpreter's step budget does
            return None
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
        m = kb.engine.machine(at=at, timeout=WHERE_BACKSTOP, max_steps=WHERE_MAX_STEPS)

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


class PlainBuiltin(NamedTuple):
    """A deterministic builtin with a function of plain values (numbers, lists of numbers,
    compounds of lists of numbers) that gives the builtin's very result for them (the same
    floats: the builtin runs the same function on the terms' numbers).

    ``readers(n)``: for a call with ``n`` inputs, a reader per input that turns the stored
    column value (SQLite's) into what ``apply`` takes, or None when the terms' path must
    decide; None for a call the function does not take. ``apply(read values)``: the result,
    or None when the builtin must decide (and raise its error) on the terms. A reader is a
    pure function of the stored value, so its readings may be remembered
    (:func:`remembering`)."""
    readers: Callable[[int], "list[Callable[[Any], Any]] | None"]
    apply: Callable[[list], Any]


def _read_subject(value: Any) -> Any:
    """pos_multiply's first input (a point or a pose) from a stored value."""
    v = plain_value(value)
    return None if v is None else pos_multiply_subject(v)


def _read_transform(value: Any) -> Any:
    """A transform of pos_multiply's list from a stored value: the
    :func:`~slr_sql.robotlib.pose_transform` of the pose :func:`plain_value` reads (read
    without making the compound)."""
    data = _plain_json(value)
    if type(data) is dict and len(data) == 1:
        args = data.get("pose")
        if type(args) is list and len(args) == 2:
            return pose_transform(args[0], args[1])
    return None


def _pos_multiply_readers(n: int) -> list | None:
    return [_read_subject] + [_read_transform] * (n - 1) if n else None


def _pos_multiply_apply(values: list) -> Any:
    return apply_transforms(values[0], values[1:])


# The builtins an event rule's where goal runs on stored values, without terms.
PLAIN_BUILTINS: dict[tuple[str, int], PlainBuiltin] = {
    ("pos_multiply", 2): PlainBuiltin(_pos_multiply_readers, _pos_multiply_apply),
}

_UNREAD = object()

# the longest text whose reading is remembered: a pose's text is ~150 characters
REMEMBERED_TEXT_CHARS = 1024


def remembering(read: Callable[[Any], Any], size: int = 64) -> Callable[[Any], Any]:
    """``read`` (a pure function of a stored value), remembering its readings of up to
    ``size`` texts: a value that comes again and again (a fixed camera's pose) is read once.
    Numbers are read each time (``1``, ``1.0`` and ``True`` are one key to a dict), and so
    are texts longer than :data:`REMEMBERED_TEXT_CHARS` (kept, a few large values of a
    column would stay in memory as long as the rule).

    >>> calls = []
    >>> read = remembering(lambda v: calls.append(v) or len(v))
    >>> read("[1,2]"), read("[1,2]"), calls
    (5, 5, ['[1,2]'])
    """
    memo: dict = {}

    def read_text(value: Any) -> Any:
        if type(value) is not str or len(value) > REMEMBERED_TEXT_CHARS:
            return read(value)
        got = memo.get(value, _UNREAD)
        if got is _UNREAD:
            if len(memo) >= size:
                memo.clear()
            got = memo[value] = read(value)
        return got

    return read_text


def _numbers(x: Any) -> bool:
    if type(x) is not list:
        return False
    for v in x:
        if type(v) is not float and type(v) is not int:
            return False
    return True


def _plain_json(value: Any) -> Any:
    """A stored text that is a JSON array or object, parsed; None for anything else and for
    text orjson would not read exactly (the terms' path decides)."""
    if type(value) is not str or not value or value[0] not in "[{":
        return None
    if not orjson_reads_exactly(value):
        return None   # maybe an integer orjson would read as a float
    try:
        # (orjson refuses what the store never writes plainly -- NaN, infinities -- and
        # those go to the terms' path; its floats are Python's)
        return orjson.loads(value)
    except ValueError:
        return None


def plain_value(value: Any) -> Any:
    """A stored value (SQLite's column) as a plain value: a number, a list of numbers, or
    a compound whose arguments are lists of numbers (``pose([..], [..])``, its arguments
    Python lists); None for anything else (the terms' path decides).

    >>> plain_value('{"pose":[[0.1,0.0,1.2],[0,0,0,1]]}')
    Struct('pose', ([0.1, 0.0, 1.2], [0, 0, 0, 1]))
    >>> plain_value("[1.5,2]"), plain_value("cup"), plain_value('{"$atom":"1"}')
    ([1.5, 2], None, None)
    """
    tv = type(value)
    if tv is int or tv is float:
        return value
    data = _plain_json(value)
    if type(data) is list:
        return data if _numbers(data) else None
    if type(data) is dict and len(data) == 1:
        (name, args), = data.items()
        if name.startswith("$") or type(args) is not list or not args:
            return None
        for a in args:
            if not _numbers(a):
                return None
        return Struct(name, tuple(args))
    return None


def describe_error(exc: BaseException) -> str:
    """A one-line reason for a rejected candidate.

    >>> describe_error(SLRError("X is not a number")), describe_error(ValueError("bad"))
    ('X is not a number', 'ValueError: bad')
    """
    if isinstance(exc, SLRError):
        return str(exc).splitlines()[0]
    return f"{type(exc).__name__}: {exc}"
