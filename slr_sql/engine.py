"""The top-down interpreter: SLDNF resolution with Prolog's order of solutions.

The machine is iterative (no Python recursion per resolution step), so a 100,000-deep
recursion costs heap, not Python stack. State:

* the *continuation*: a linked list of ``(goal, cut_barrier, next)`` tuples still to prove;
* the *choicepoint stack* ``cps``: lists ``[kind, trail_mark, cont, a, b, c]``;
* the *trail*: variables bound since each choicepoint, unbound again on backtracking.

A cut barrier is the height of ``cps`` when the clause (or ``call/N``, or the condition of an
if-then-else) was entered; ``!`` truncates ``cps`` to it. Collecting builtins (findall & co.)
push a COLLECT choicepoint below the goal and gather copies of the template on each solution,
so they need no nested interpreter either.
"""
from __future__ import annotations

import os
import threading
import time
from math import copysign
from typing import Any, Callable, Iterator

from .arith import instantiation_error, iso_error, resource_error, type_error, with_context
from .errors import CLOSED_WHILE_RUNNING, STOPPED_BY_CALLER, SLRError, SLREvaluationError, SLRTimeout
from .program import MAX_RECURSIVE_NEST, Predicate, Program, Slot, Template, build, \
    event_key, split_event_atom
from .terms import (Atom, CheckedBodies, Struct, Var, deref, format_atom, format_term,
                    term_vars)
from .unify import bound_args, copy_term, undo, unify, unify_event_row

__all__ = ["Engine", "Machine", "unify", "copy_term", "PrologThrow"]

# How much one query may grow the process's resident memory, looked at every
# _MEMORY_CHECK_EVERY limit checks (2048 steps each) from its first: beyond is
# resource_error(memory), catchable by catch/3 as in SWI-Prolog, whose 1 GB stacks stop a
# query at a similar size. Without it nth1(100000000, L, x) grew ~40 MB a second until its
# timeout: four such queries over the service (--max-running-queries) held gigabytes for
# 30 s, enough to have a robot's store server killed for memory. The process's resident
# set, not the query's own: a query beside others that grow may meet it first.
MAX_QUERY_GROWTH = 1 << 30
_MEMORY_CHECK_EVERY = 16
_PAGE_SIZE = os.sysconf("SC_PAGE_SIZE") if hasattr(os, "sysconf") else 4096


def resident_bytes() -> int | None:
    """The process's resident memory now, in bytes (Linux's /proc); None where unknown.

    >>> resident_bytes() is None or resident_bytes() > 0
    True
    """
    try:
        with open("/proc/self/statm", "rb") as statm:
            return int(statm.read().split()[1]) * _PAGE_SIZE
    except (OSError, ValueError, IndexError):
        return None


# choicepoint kinds
K_CLAUSES, K_GEN, K_ALT, K_DEAD, K_COLLECT, K_CATCH, K_REACTIVATE, K_OUTPUT = range(8)


class PrologThrow(Exception):
    """A ball thrown by throw/1 (or an ISO error) travelling to the nearest matching catch/3."""

    def __init__(self, ball: Any):
        self.ball = ball


class Special:
    """An internal goal the machine pushes on the continuation (never written by users)."""

    __slots__ = ("op", "data")

    def __init__(self, op: int, data: Any):
        self.op = op
        self.data = data


S_CUT_TO, S_SOFTCUT, S_NAFAIL, S_COLLECT, S_POPCATCH, S_RULES, S_OUTPUT_DONE = range(7)


class Engine:
    """Runs goals against a :class:`Program` and an event source (the store).

    ``events`` must offer ``scan``, ``prev_candidates``, ``rows_at_end``, ``next_candidates``
    and ``rows_at_start`` (see :mod:`slr_sql.store`).
    """

    def __init__(self, program: Program, events: Any = None, library: Program | None = None):
        from . import builtins as _b

        self.program = program
        self.library = library or _b.library_program()
        self.events = events
        self.python_preds: dict[tuple[str, int], Callable] = {}
        self.det = _b.DET
        self.nondet = _b.NONDET
        self.out = None  # where write/1 & co. print; None = sys.stdout
        self.err = None  # where print_message/2 and user_error print; None = sys.stderr
        # {(name, arity): callable(machine, args) -> rows or None}: predicates whose calls
        # the SQL compiler answers (slr_sql.planner.CompiledCall); use_sql switches them off
        self.sql_calls: dict = {}
        self.use_sql = True
        self.frames: Any = None  # tf_lookup's frame tree (slr_sql.frames), made on first use
        # set when the knowledge base closes: a query still running (a server stopping, whose
        # process waits for its threads) ends at its next check instead of at its timeout
        self.stopped = False

    def machine(self, at: float | None = None, timeout: float | None = None,
                max_steps: int | None = None) -> "Machine":
        return Machine(self, at=at, timeout=timeout, max_steps=max_steps)


CONTROL = {
    (",", 2), ("true", 0), ("!", 0), (";", 2), ("->", 2), ("*->", 2), ("\\+", 1),
    ("call", 1), ("call", 2), ("call", 3), ("call", 4), ("call", 5), ("call", 6), ("call", 7),
    ("call", 8), ("findall", 3), ("findall", 4), ("findAll", 3), ("forall", 2),
    ("aggregate_all", 3), ("bagof", 3), ("setof", 3), ("catch", 3), ("throw", 1),
    ("fail", 0), ("false", 0), ("^", 2), ("not", 1), ("$with_output_to", 2),
}


# the meta predicates SWI-Prolog names in the context of the errors of the goals they call
_SYSTEM_CATCH = Struct(":", (Atom("system"), Struct("/", (Atom("catch"), 3))))
_SYSTEM_NOT = Struct(":", (Atom("system"), Struct("/", (Atom("not"), 1))))
_SYSTEM_THROW = Struct(":", (Atom("system"), Struct("/", (Atom("throw"), 1))))


class Machine:
    """One query's execution state. ``solve(goal)`` yields once per solution."""

    def __init__(self, engine: Engine, at: float | None = None, timeout: float | None = None,
                 max_steps: int | None = None):
        self.engine = engine
        self.at = at
        self.trail: list = []
        self.cps: list = []
        self.steps = 0
        self.deadline = time.monotonic() + timeout if timeout is not None else None
        self.max_steps = max_steps
        self.timeout = timeout
        self._memory_base: int | None = None   # resident bytes at its first look
        self._memory_checks = 0                # limit checks until the next look
        # hooks for synchronized queries: called before prev/next read the store
        self.on_prev: Callable | None = None
        self.on_next: Callable | None = None
        # (name, n, t, args): the answer depends on an event matching args, starting at or
        # after t, that has not arrived (tf_lookup beyond an edge's last observation)
        self.on_arrival: Callable | None = None
        self.sql_calls: dict | None = None   # set by solve(): compiled sub-goals, if allowed
        # the robot whose events every event goal, prev and next reads (None: everyone's)
        self.robot: str | None = None
        # set from another thread to end this query at its next check of limits (a served
        # query whose client asked to stop or left: Solutions.stop)
        self.stop: threading.Event | None = None
        # the bodies check_body walked (\+ \+ ... nested N deep walked each nested body
        # again, N²/2 steps)
        self._bodies = CheckedBodies()
        # with_output_to/2's captures, innermost last: (height, choicepoint), each live while
        # its choicepoint is still on the stack at that height (builtins.current_output)
        self.captures: list = []

    # -- helpers used by builtins -------------------------------------------------------
    def unify(self, a: Any, b: Any) -> bool:
        return unify(a, b, self.trail, self.deadline)

    def undo_to(self, mark: int) -> None:
        undo(self.trail, mark)

    def abandon(self, solving: Iterator[None]) -> None:
        """Stop a run of :meth:`solve` before its end: close the generators left on its
        choicepoints (they hold store cursors) now, rather than whenever the garbage
        collector gets to them, then the run itself."""
        for cp in reversed(self.cps):
            if cp[0] == K_GEN:
                try:
                    cp[3].close()
                except Exception:  # noqa: BLE001 - a generator failing to close is done anyway
                    pass
        self.cps.clear()
        solving.close()

    # -- the main loop ------------------------------------------------------------------
    def solve(self, goal: Any) -> Iterator[None]:
        """Prove ``goal``; yields after each solution (bindings readable until resumed)."""
        self.check_body(goal)
        cont = (goal, 0, None)
        engine = self.engine
        preds = engine.program.preds
        library = engine.library.preds
        det = engine.det
        nondet = engine.nondet
        check_every = 2048
        steps_left = check_every
        # compiled sub-goals: not under a step limit (SQL does not count inferences) nor in
        # a synchronized run (its prev/next hooks must see every lookup)
        sql_calls = engine.sql_calls if (engine.use_sql and self.max_steps is None
                                         and self.on_prev is None
                                         and self.on_next is None
                                         and self.robot is None) else None
        self.sql_calls = sql_calls
        while True:
            try:
                # every step counts, backtracking and solutions too: an endless stream of
                # answers (length(L, N), between(1, inf, X)) must also meet the limits
                steps_left -= 1
                if steps_left <= 0:
                    steps_left = check_every
                    self._check_limits(check_every)
                if cont is False:
                    cont = self._backtrack()
                    if cont is False:
                        return
                    continue
                if cont is None:
                    yield None
                    cont = False
                    continue
                goal, cb, nxt = cont
                if type(goal) is Var:
                    while type(goal) is Var:
                        r = goal.ref
                        if r is None:
                            raise instantiation_error()
                        goal = r
                    # a variable goal G is call(G) (ISO 7.6.2): a cut inside it is local
                    cb = len(self.cps)
                    self.check_body(goal)
                tg = type(goal)
                if tg is Struct:
                    args = goal.args
                    key = (goal.name, len(args))
                elif tg is Atom:
                    args = ()
                    key = (goal, 0)
                elif tg is Special:
                    cont = self._special(goal, nxt)
                    continue
                else:
                    raise type_error("callable", goal)

                if key in CONTROL:
                    cont = self._control(key, args, cb, nxt)
                    continue
                pred = preds.get(key)
                if pred is None:
                    pred = library.get(key)
                if pred is not None:
                    if sql_calls:
                        call = sql_calls.get(key)
                        if call is not None:
                            rows = call(self, args)
                            if rows is not None:
                                cont = self.push_solutions(self._sql_answers(rows, args), nxt)
                                continue
                    cont = self._call_pred(pred, args, nxt)
                    continue
                f = det.get(key)
                if f is not None:
                    try:
                        cont = nxt if f(self, args) else False
                    except SLREvaluationError as exc:
                        raise _in_builtin(exc, key, args)
                    continue
                g = nondet.get(key)
                if g is not None:
                    cont = self.push_solutions(g(self, args), nxt, g)
                    continue
                cont = self._other(key, args, nxt)
            except PrologThrow as exc:
                cont = self._handle_throw(exc.ball)
            except SLREvaluationError as exc:
                cont = self._handle_throw(exc.term, exc)
            except MemoryError:
                # a builtin or a Python predicate ran out of memory: an ISO resource error
                # (catchable by catch/3, as in SWI-Prolog), never a raw MemoryError
                err = resource_error("memory")
                cont = self._handle_throw(err.term, err)
            except RecursionError:  # a safety net: term walks are iterative
                err = resource_error("c_stack")
                cont = self._handle_throw(err.term, err)

    def check_deadline(self) -> None:
        """Raise SLRTimeout once the query's time is up: for builtins that loop long inside
        one step (building a list of millions of cells), which the machine's own check
        every 2048 steps would not see in time."""
        if self.stop is not None and self.stop.is_set():
            raise SLRError(STOPPED_BY_CALLER)
        if self.deadline is not None and time.monotonic() > self.deadline:
            raise SLRTimeout(f"query timed out after {self.timeout} s "
                             f"({self.steps} inference steps)")

    def count_steps(self, n: int) -> None:
        """Count ``n`` inference steps a builtin made inside one call (a generator looking
        for its next solution) against the query's limits, as the machine counts its own:
        SLRTimeout once past max_steps or the deadline."""
        self._check_limits(n)

    def _in_own_transaction(self) -> bool:
        """Whether this thread is inside a transaction of the store: a goal evaluated there
        (an event rule's where goal deciding in its add) is part of a write, which a close
        waits for instead of ending it."""
        events = self.engine.events
        return bool(getattr(events, "in_transaction_here", False))

    def _check_limits(self, n: int) -> None:
        self.steps += n
        if self.engine.stopped and not self._in_own_transaction():
            raise SLRError(CLOSED_WHILE_RUNNING)
        if self.stop is not None and self.stop.is_set():
            raise SLRError(STOPPED_BY_CALLER)
        if self.max_steps is not None and self.steps > self.max_steps:
            raise SLRTimeout(f"step limit of {self.max_steps} inference steps exceeded")
        if self.deadline is not None and time.monotonic() > self.deadline:
            raise SLRTimeout(f"query timed out after {self.timeout} s "
                             f"({self.steps} inference steps)")
        self._memory_checks -= 1
        if self._memory_checks <= 0:
            self._memory_checks = _MEMORY_CHECK_EVERY
            now = resident_bytes()
            if now is not None:
                if self._memory_base is None:
                    self._memory_base = now
                elif now - self._memory_base > MAX_QUERY_GROWTH:
                    # (caught, what it built is let go; freed memory stays resident, so the
                    # query may grow as much again from here)
                    self._memory_base = now
                    raise resource_error("memory")

    def _backtrack(self):
        """Resume the newest choicepoint; returns the continuation, or False when none is left."""
        cps = self.cps
        trail = self.trail
        while cps:
            cp = cps[-1]
            mark = cp[1]
            while len(trail) > mark:
                trail.pop().ref = None
            kind = cp[0]
            if kind == K_CLAUSES:
                cont = self._try_clauses(cp, len(cps) - 1)
                if cont is not False:
                    return cont
            elif kind == K_GEN:
                try:
                    next(cp[3])
                except StopIteration:
                    cps.pop()
                    continue
                except SLREvaluationError as exc:
                    if cp[4] is not None:
                        raise _in_nondet_builtin(exc, cp[4])
                    raise
                return cp[2]
            elif kind == K_ALT:
                cps.pop()
                return cp[2]
            elif kind == K_COLLECT:
                cps.pop()
                finish = cp[4]
                cont = finish(self, cp[3], cp[2])
                if cont is not False:
                    return cont
            elif kind == K_REACTIVATE:
                # backtracking into a catch/3 goal that had exited: the catch is active again
                cps.pop()
                cp[3][0] = K_CATCH
            else:  # K_DEAD, K_CATCH, K_OUTPUT: nothing to resume
                cps.pop()
        return False

    # -- user predicates ----------------------------------------------------------------
    def _call_pred(self, pred: Predicate, args: tuple, nxt):
        clauses = pred.candidates(deref(args[0]) if args else None)
        if not clauses:
            return False
        cp = [K_CLAUSES, len(self.trail), nxt, args, clauses, 0]
        self.cps.append(cp)
        return self._try_clauses(cp, len(self.cps) - 1)

    def _try_clauses(self, cp: list, height: int):
        """Try clauses from cp[5] on; pops cp when the last candidate is taken."""
        args = cp[3]
        clauses = cp[4]
        i = cp[5]
        n = len(clauses)
        trail = self.trail
        mark = cp[1]
        cps = self.cps
        while i < n:
            clause = clauses[i]
            i += 1
            frame = [None] * clause.nslots
            if _unify_head(clause.head, args, frame, trail):
                if i >= n:
                    cps.pop()
                else:
                    cp[5] = i
                cont = cp[2]
                body = clause.body
                for g in reversed(body):
                    cont = (build(g, frame), height, cont)
                return cont
            while len(trail) > mark:
                trail.pop().ref = None
        cps.pop()
        return False

    def _sql_answers(self, rows: list, args: tuple) -> Iterator[None]:
        """Bind the call's free arguments to each compiled answer in turn."""
        trail = self.trail
        for row in rows:
            mark = len(trail)
            for i, value in row:
                if not unify(args[i], value, trail):
                    undo(trail, mark)
                    break
            else:
                yield None

    def push_solutions(self, gen: Iterator, nxt, builtin: Callable | None = None):
        """Solve a goal by a generator: each ``next(gen)`` makes the next solution (binding
        on the trail, undone on backtracking) and yields; the machine then continues with
        ``nxt``. Returns ``nxt``, or False when ``gen`` has no solution at all. An error the
        generator of the nondeterministic builtin ``builtin`` (its function, shared: no
        key tuple is kept per choicepoint) raises names it in its context."""
        cp = [K_GEN, len(self.trail), nxt, gen, builtin, None]
        self.cps.append(cp)
        try:
            next(gen)
        except StopIteration:
            self.cps.pop()
            return False
        except SLREvaluationError as exc:
            if builtin is not None:
                raise _in_nondet_builtin(exc, builtin)
            raise
        return nxt

    def _other(self, key, args, nxt):
        fn = self.engine.python_preds.get(key)
        if fn is not None:
            from .builtins import call_python_pred

            return nxt if call_python_pred(self, fn, args) else False
        if key in self.engine.program.dynamic:
            return False
        name, arity = key
        # (a list cell's name is '[|]' in SWI-Prolog 7: call([a], X) is no '.'/3)
        error = iso_error(Struct("existence_error", (
            Atom("procedure"), Struct("/", (Atom("[|]" if name == "." else name), arity)))))
        hint = self._event_hint(name, arity, args)
        if hint:
            error = SLREvaluationError(error.term, f"{error}: {hint}")
        raise error

    def _event_hint(self, name: str, arity: int, args: tuple) -> str:
        """Why an unknown ``p(..)`` may be a slip for the event goal ``p(..)^T``: p/N has
        clauses with a ``^T`` head, or stored events. Empty when neither."""
        if (name, arity) in self.engine.program.temporal:
            what = "is defined with ^T"
        else:
            table_of = getattr(self.engine.events, "event_table_sql", None)
            try:
                known = table_of is not None and table_of(name, arity) is not None
            except Exception:  # only a hint: a store that cannot answer gives none
                known = False
            if not known:
                return ""
            what = "is an event type"
        taken = {v.name for a in args for v in term_vars(a)}
        stamp = "T"
        i = 0
        while stamp in taken:
            i += 1
            stamp = f"T{i}"
        goal = format_atom(name)
        if args:
            goal += "(" + ", ".join(format_term(a, priority=999) for a in args) + ")"
        return f"{format_atom(name)}/{arity} {what}: did you mean {goal}^{stamp}?"

    # -- control constructs -------------------------------------------------------------
    def _control(self, key, args, cb, nxt):
        name = key[0]
        cps = self.cps
        if name == ",":
            return (args[0], cb, (args[1], cb, nxt))
        if name == "true":
            return nxt
        if name == "!":
            del cps[cb:]
            return nxt
        if name == "fail" or name == "false":
            return False
        if name == ";":
            left = deref(args[0])
            if type(left) is Struct and len(left.args) == 2 and left.name in ("->", "*->"):
                height = len(cps)
                cp = [K_ALT, len(self.trail), (args[1], cb, nxt), None, None, None]
                cps.append(cp)
                cond, then = left.args
                if left.name == "->":
                    marker = Special(S_CUT_TO, height)
                else:
                    marker = Special(S_SOFTCUT, cp)
                return (cond, height + 1, (marker, cb, (then, cb, nxt)))
            cps.append([K_ALT, len(self.trail), (args[1], cb, nxt), None, None, None])
            return (args[0], cb, nxt)
        if name == "->":
            height = len(cps)
            return (args[0], height, (Special(S_CUT_TO, height), cb, (args[1], cb, nxt)))
        if name == "*->":
            return (args[0], len(cps), (args[1], cb, nxt))
        if name == "\\+" or name == "not":
            if name == "not":
                self.meta_check(args[0], _SYSTEM_NOT)
            self.check_body(args[0])
            height = len(cps)
            cps.append([K_ALT, len(self.trail), nxt, None, None, None])
            return (args[0], height + 1, (Special(S_NAFAIL, height), cb, None))
        if name == "call":
            goal = deref(args[0])
            if len(args) > 1:
                goal = _add_args(goal, args[1:])
            elif type(goal) is Var:
                raise instantiation_error()
            if type(goal) not in (Struct, Atom):
                raise type_error("callable", goal)
            self.check_body(goal)
            return (goal, len(cps), nxt)
        if name == "^":
            ev = split_event_atom(Struct("^", args))
            if ev is None:
                # V^Goal outside bagof/setof: prove Goal (as SWI does)
                return (args[1], cb, nxt)
            return self._event_goal(ev, nxt)
        if name == "throw":
            ball = deref(args[0])
            if type(ball) is Var:
                raise with_context(instantiation_error(), _SYSTEM_THROW)
            raise PrologThrow(copy_term(ball, deadline=self.deadline))
        if name == "catch":
            height = len(cps)
            cp = [K_CATCH, len(self.trail), nxt, args[1], args[2], cb]
            cps.append(cp)
            # (raised inside the catch: catch/3 catches it)
            self.meta_check(args[0], _SYSTEM_CATCH)
            return (args[0], height + 1, (Special(S_POPCATCH, cp), cb, nxt))
        if name == "$with_output_to":
            # the goal as once/1 with its output captured: the capture is a choicepoint, so
            # it ends with its goal however the goal ends (a failure or an error backtracks
            # past it, and the output goes where it went before)
            from .builtins import capture_sink, output_capture

            sink = capture_sink(self, args)
            height = len(cps)
            cp = [K_OUTPUT, len(self.trail), None, output_capture(sink), None, None]
            cps.append(cp)
            self.captures.append((height, cp))
            return (args[1], height + 1, (Special(S_OUTPUT_DONE, (height, cp, sink)), cb, nxt))
        # collection predicates
        from .builtins import collector

        return collector(self, key, args, nxt)

    def _special(self, goal: Special, nxt):
        op = goal.op
        if op == S_CUT_TO:
            del self.cps[goal.data:]
            return nxt
        if op == S_SOFTCUT:
            goal.data[0] = K_DEAD
            return nxt
        if op == S_NAFAIL:
            del self.cps[goal.data:]
            return False
        if op == S_COLLECT:
            template, results, each = goal.data
            found = copy_term(template, deadline=self.deadline)
            results.append(found)
            if each is not None:
                each(found)
            return False
        if op == S_OUTPUT_DONE:
            # with_output_to/2's goal succeeded: its other solutions cut (once/1), the
            # capture ended, the sink unified with the text
            from .builtins import unify_sink

            height, cp, sink = goal.data
            del self.cps[height:]
            return nxt if unify_sink(self, sink, cp[3]) else False
        if op == S_RULES:
            pred, args = goal.data
            return self._call_pred(pred, args, nxt)
        if op == S_POPCATCH:
            cp = goal.data
            # the catch is only active while its goal runs; leaving it deactivates it
            if self.cps and self.cps[-1] is cp:
                self.cps.pop()
            else:
                # the goal left choicepoints: deactivate the catch, and reactivate it when
                # backtracking re-enters the goal (ISO: catch/3 is transparent to backtracking)
                cp[0] = K_DEAD
                self.cps.append([K_REACTIVATE, len(self.trail), None, cp, None, None])
            return nxt
        raise AssertionError(op)

    def check_body(self, goal: Any) -> None:
        """A term called as a goal is made a body first, as SWI-Prolog's call/1 does (ISO
        7.6.2): every goal inside its control constructs (``,`` ``;`` ``->`` ``*->``
        ``\\+``) must be callable or a variable, else the whole term is
        ``type_error(callable, Goal)`` -- before any of it runs (``call((fail, 1))`` raises,
        it does not fail). A body inside one already found callable is walked again only
        when it must (:class:`CheckedBodies`).

        >>> m = Engine(Program()).machine(); m.check_body(Struct(",", (Atom("fail"), Var())))
        >>> m.check_body(Struct(",", (Atom("fail"), 1)))
        Traceback (most recent call last):
        ...
        slr_sql.errors.SLREvaluationError: error(type_error(callable,(fail,1)),_)
        """
        if self._bodies.problem(goal) is not None:
            raise type_error("callable", deref(goal))

    def meta_check(self, goal: Any, caller: Any) -> None:
        """The errors SWI-Prolog raises as the meta predicate ``caller`` (a predicate
        indicator) calls ``goal``, named in their context: an unbound goal, one that is no
        body (type_error(callable, Goal)), an undefined procedure as the goal itself (one
        inside its control constructs is left to the call, its context unbound)."""
        g = deref(goal)
        try:
            if type(g) is Var:
                raise instantiation_error()
            self.check_body(g)
            if type(g) is Struct:
                key, args = (g.name, len(g.args)), g.args
            elif type(g) is Atom:
                key, args = (g, 0), ()
            else:
                raise type_error("callable", g)
            engine = self.engine
            if not (key in CONTROL or key in engine.program.preds or key in engine.library.preds
                    or key in engine.det or key in engine.nondet or key in engine.python_preds
                    or key in engine.program.dynamic):
                self._other(key, args, None)
        except SLREvaluationError as exc:
            raise with_context(exc, caller)

    def push_collect(self, template: Any, goal: Any, finish: Callable, nxt,
                     each: Callable[[Any], None] | None = None, caller: Any = None):
        """Run ``goal`` to exhaustion collecting copies of ``template``, then ``finish``;
        ``each`` sees every copy as it is found (an error it raises stops the goal there, as
        SWI-Prolog's aggregate_all(max(X), ..) evaluating each solution as it comes).
        ``caller``: the predicate SWI-Prolog names in the context of the goal's own errors
        (:meth:`meta_check`)."""
        if caller is not None:
            self.meta_check(goal, caller)
        self.check_body(goal)
        results: list = []
        height = len(self.cps)
        self.cps.append([K_COLLECT, len(self.trail), nxt, results, finish, None])
        return (goal, height + 1, (Special(S_COLLECT, (template, results, each)), 0, None))

    def _handle_throw(self, ball: Any, original: SLREvaluationError | None = None):
        ball = copy_term(ball, deadline=self.deadline)
        cps = self.cps
        while cps:
            cp = cps.pop()
            undo(self.trail, cp[1])
            if cp[0] == K_CATCH:
                mark = len(self.trail)
                if unify(cp[3], ball, self.trail):
                    return (cp[4], cp[5], cp[2])
                undo(self.trail, mark)
        if original is not None:
            # the copy taken before the bindings were undone: the culprit keeps its values
            original.term = ball
            raise original
        from .terms import MESSAGE_TOKENS, format_term

        raise SLREvaluationError(ball, "unhandled exception: "
                                 + format_term(ball, limit=MESSAGE_TOKENS, deadline=self.deadline))

    # -- events -------------------------------------------------------------------------
    def _event_goal(self, ev, nxt):
        """``p(..)^T``: stored events in store order (stream view), then the temporal rules."""
        atom, s, e = ev
        name, n = event_key(atom)
        args = tuple(atom.args) if type(atom) is Struct else ()
        rules = self.engine.program.temporal.get((name, n))
        events = self.engine.events
        if rules is not None and rules.clauses:
            if self.sql_calls:
                call = self.sql_calls.get(("^", name, n))
                if call is not None:
                    full = args + ((s,) if deref(s) is deref(e) else (s, e))
                    rows = call(self, full)
                    if rows is not None:
                        return self.push_solutions(self._sql_answers(rows, full), nxt)
            rule_goal = Special(S_RULES, (rules, args + (s, e)))
            cps = self.cps
            cps.append([K_ALT, len(self.trail), (rule_goal, 0, nxt), None, None, None])
        if events is None:
            return False
        bound = bound_args(args)
        rows = events.scan(name, n, bound, end_le=self.at, robot=self.robot) \
            if self.robot is not None else events.scan(name, n, bound, end_le=self.at)
        return self.push_solutions(_match_rows(self, args, s, e, rows), nxt)

    def event_source(self):
        return self.engine.events


def _match_rows(m: Machine, args: tuple, s: Any, e: Any, rows) -> Iterator[None]:
    """Bind the event goal to each stored row it matches: data by unification, the stored
    float times by value (``seen(X)^5`` finds ``seen(x)^5.0``)."""
    trail = m.trail
    for row in rows:
        mark = len(trail)
        if unify_event_row(args, s, e, row[0], row[1], row[2], trail):
            yield None
        undo(trail, mark)


def _unify_head(head: tuple, args: tuple, frame: list, trail: list) -> bool:
    for p, a in zip(head, args):
        tp = type(p)
        if tp is Slot:
            cur = frame[p.index]
            if cur is None:
                frame[p.index] = a
            elif not unify(cur, a, trail):
                return False
        elif tp is Template:
            if not _unify_pattern(p, a, frame, trail):
                return False
        else:
            # a constant: compare without the general unifier when the goal argument is bound
            while type(a) is Var:
                r = a.ref
                if r is None:
                    a.ref = p
                    trail.append(a)
                    break
                a = r
            else:
                if type(a) is not tp or (a != p if tp is not Struct else not unify(p, a, trail)):
                    return False
                if tp is float and not p and copysign(1.0, a) != copysign(1.0, p):
                    return False  # -0.0 and 0.0: equal numbers, two terms
    return True


def _unify_pattern(p: Any, t: Any, frame: list, trail: list) -> bool:
    tp = type(p)
    if tp is Slot:
        cur = frame[p.index]
        if cur is None:
            frame[p.index] = t
            return True
        return unify(cur, t, trail)
    if tp is Template:
        if p.nest > MAX_RECURSIVE_NEST:  # a deeply nested head argument: no recursion
            return unify(build(p, frame), t, trail)
        while type(t) is Var:
            r = t.ref
            if r is None:
                t.ref = build(p, frame)
                trail.append(t)
                return True
            t = r
        if type(t) is not Struct or t.name != p.name or len(t.args) != len(p.args):
            return False
        # iterate along list spines instead of recursing on the tail
        while True:
            pa = p.args
            ta = t.args
            last = len(pa) - 1
            for i in range(last):
                if not _unify_pattern(pa[i], ta[i], frame, trail):
                    return False
            p = pa[last]
            t = ta[last]
            if type(p) is not Template:
                return _unify_pattern(p, t, frame, trail)
            while type(t) is Var:
                r = t.ref
                if r is None:
                    t.ref = build(p, frame)
                    trail.append(t)
                    return True
                t = r
            if type(t) is not Struct or t.name != p.name or len(t.args) != len(p.args):
                return False
    return unify(p, t, trail)




def _in_builtin(exc: SLREvaluationError, key: tuple, args: tuple = ()) -> SLREvaluationError:
    """``exc`` raised by the builtin ``key``, its context filled as SWI-Prolog's."""
    from .builtins import in_builtin as fill

    return fill(exc, key, args)


def _in_nondet_builtin(exc: SLREvaluationError, fn: Callable) -> SLREvaluationError:
    """``exc`` raised by the nondeterministic builtin whose function is ``fn``."""
    from .builtins import NONDET

    for key, f in NONDET.items():
        if f is fn:
            return _in_builtin(exc, key)
    return exc


def _add_args(goal: Any, extra: tuple) -> Any:
    goal = deref(goal)
    if type(goal) is Atom:
        return Struct(goal, tuple(extra))
    if type(goal) is Struct:
        return Struct(goal.name, goal.args + tuple(extra))
    if type(goal) is Var:
        raise instantiation_error()
    raise type_error("callable", goal)
