"""Ctrl-C (SIGINT) in a Python program while a query's compiled SQL statement runs: the
KeyboardInterrupt reaches the program at once, the store is unchanged and the knowledge
base answers the next query. On SQLite the KeyboardInterrupt, raised inside the statement's
progress handler, was cleared by sqlite3: the statement ended "interrupted" and the goal went
on in the interpreter for minutes, where only a second Ctrl-C landed.

Each test runs a real Python process over a real store and sends it SIGINT once its
statement runs."""
from __future__ import annotations

import os
import signal
import sys
import threading
from pathlib import Path

import pexpect
import pytest

import slr_sql

from test_close_ends_running_queries import DEADLINE, EVENTS, SLOW_BODY, _slow_store
from test_shell import _wait_until_its_statement_runs

ROOT = Path(__file__).resolve().parent.parent

# Goals of one long statement each (a minute or more of either engine's work): `slow` calls
# a Python function of one argument (slr_num) row by row, where Python most often runs the
# signal's handler on SQLite; `counted(N)` calls none (there the handler runs in the
# statement's progress handler); `differing` calls one of several arguments (slr_det; on
# SQLite only: PostgreSQL runs it in the interpreter)
PROGRAM = (f"slow :- {SLOW_BODY.format(started='')}. "
           "counted(N) :- aggregate_all(count, (p(_)^_, p(_)^_, p(_)^_), N). "
           "differing :- p(X)^_, p(Y)^_, p(Z)^_, X \\== Y, Y \\== Z, X == Z, X == -1. "
           "summed(S) :- aggregate_all(sum(T), (p(_)^T, p(_)^_, p(_)^_), S).")

# The program: asks GOAL the way HOW says, reports how the ask ended and how long it took,
# then asks again and counts the events
CHILD = r"""
import signal, sys, time
import slr_sql

# (Python's own Ctrl-C handler, as a program started from a terminal has it: a program that a
# background job starts, a CI run's, inherits SIGINT ignored, and Python then keeps it so)
signal.signal(signal.SIGINT, signal.default_int_handler)

where, goal, how = sys.argv[1:]
kb = slr_sql.open(where, clock=slr_sql.ManualClock(0.0))
assert "engine: sql" in kb.explain(goal)
print("asking", flush=True)
began = time.monotonic()
try:
    if how == "query":
        kb.query(goal)
    elif how == "query with a timeout":
        kb.query(goal, timeout=600)
    elif how == "solutions":
        for answer in kb.solutions(goal):
            pass
    elif how == "sub-goal":   # a compiled sub-goal the interpreter calls
        kb.query("member(A, [1]), " + goal)
    elif how == "synchronized":   # evaluated on a worker thread of the knowledge base
        kb.query(goal, at=600, wait=True)
    print("answered", flush=True)
except KeyboardInterrupt:
    print(f"KeyboardInterrupt after {time.monotonic() - began:.1f} s", flush=True)
print("next:", kb.query("p(X)^_, X > %d") , flush=True)
print("events:", kb.query("findall(X, p(X)^_, L), length(L, N)")[0]["N"], flush=True)
kb.close()
print("closed", flush=True)
""" % (EVENTS - 2)


def _interrupted_program(where: str, goal: str, how: str, **environment: str) -> None:
    """Run CHILD over a store at ``where`` (EVENTS p/1 events, PROGRAM), send it SIGINT once
    its statement runs, and check what it says: the KeyboardInterrupt well before the
    statement would end, the next query answered, the events all there; and the store
    holds them when opened again."""
    kb = _slow_store(where, signalled=False)[0]
    kb.load(PROGRAM)
    kb.mark_complete("p/1", 1000)   # (the synchronized query's history is complete)
    kb.close()
    env = dict(os.environ, PYTHONPATH=str(ROOT), **environment)
    child = pexpect.spawn(sys.executable, ["-c", CHILD, where, goal, how], env=env,
                          cwd=str(ROOT), encoding="utf-8", timeout=DEADLINE)
    try:
        child.expect("asking\r\n")
        _wait_until_its_statement_runs(child, where)
        child.kill(signal.SIGINT)
        # (the statement alone runs a minute or more: an answer or a wait past DEADLINE
        # means the Ctrl-C did not stop it)
        child.expect(r"(answered|KeyboardInterrupt after ([0-9.]+) s)\r\n")
        assert child.match.group(1).startswith("KeyboardInterrupt"), child.before
        assert float(child.match.group(2)) < DEADLINE
        child.expect(r"next: ([^\r\n]*)\r\n")
        assert child.match.group(1) == "[{'X': %d}]" % (EVENTS - 1)
        child.expect(r"events: (\d+)\r\n")
        assert int(child.match.group(1)) == EVENTS
        child.expect("closed\r\n")
        child.expect(pexpect.EOF)
    finally:
        child.close(force=True)
    assert child.exitstatus == 0, child.before
    with slr_sql.open(where) as again:
        assert again.query("findall(X, p(X)^_, L), length(L, N)")[0]["N"] == EVENTS


@pytest.mark.parametrize("how", ["query", "query with a timeout", "solutions", "sub-goal",
                                 "synchronized"])
@pytest.mark.parametrize("goal", ["slow", "counted(N)"])
def test_ctrl_c_during_a_compiled_statement_raises_keyboard_interrupt_at_once(backend, goal,
                                                                               how):
    """The program gets the KeyboardInterrupt well before the statement would end, the next
    query answers, and the store holds its events; on both backends, for a query, a query
    with a timeout (PostgreSQL's statement_timeout in a transaction of its own), the
    answers one at a time, a compiled sub-goal the interpreter calls, and a synchronized
    query (its statement runs on a worker thread: the KeyboardInterrupt came at once, but
    the statement ran on, and the next query waited for the store's connection)."""
    _interrupted_program(backend, goal, how)


@pytest.mark.parametrize("how", ["query", "sub-goal"])
def test_ctrl_c_met_in_a_function_of_several_arguments_raises_keyboard_interrupt(tmp_path,
                                                                                 how):
    """SQLite: a statement calling slr_det (\\==, ==) row by row, where Python most often
    runs the signal's handler; sqlite3 cleared its KeyboardInterrupt there (and again in the
    compiled sub-goal the interpreter then called: only a third Ctrl-C landed). PostgreSQL
    runs such a goal in the interpreter. Kept by the C speedups' signal_safe (built wherever
    a C compiler is: tests/test_speedups.py), used even in a run without them."""
    _interrupted_program(str(tmp_path / "robot.db"), "differing", how, SLR_SQL_NO_SPEEDUPS="")


@pytest.mark.parametrize("speedups", ["", "1"], ids=["with the C speedups", "without"])
def test_ctrl_c_met_in_an_aggregates_step_raises_keyboard_interrupt(tmp_path, speedups):
    """SQLite: a statement whose one Python call per row is an aggregate's step (slr_sum's),
    where Python then runs the signal's handler; sqlite3 cleared its KeyboardInterrupt there
    ("'step' method raised error"), and the goal went on in the interpreter until its end.
    Kept by the C speedups' signal_safe around the aggregate's calls, and without them by
    the step's own wrapper (the statement's progress handler then ends it)."""
    _interrupted_program(str(tmp_path / "robot.db"), "summed(S)", "query",
                         SLR_SQL_NO_SPEEDUPS=speedups)


@pytest.mark.parametrize("goal", ["slow", "counted(N)"])
def test_ctrl_c_without_the_c_speedups_raises_keyboard_interrupt(tmp_path, goal):
    """SQLite without the C speedups (SLR_SQL_NO_SPEEDUPS=1): the progress handler and the
    functions of one argument (slr_num) keep the KeyboardInterrupt in Python."""
    _interrupted_program(str(tmp_path / "robot.db"), goal, "query", SLR_SQL_NO_SPEEDUPS="1")


COUNTING = ("WITH RECURSIVE r(n) AS (SELECT 1 UNION ALL SELECT n + 1 FROM r WHERE n < 200000) "
            "SELECT count(*) FROM r")


class _SignalledWhileChecked(threading.Event):
    """A query's stop that sends this process SIGUSR1 the first time the statement's
    progress handler looks at it (run_compiled looks once before): Python then runs the
    signal's handler there, inside the progress handler, as it does for a signal that comes
    while SQLite runs no function."""

    def __init__(self) -> None:
        super().__init__()
        self.looks = 0

    def is_set(self) -> bool:
        self.looks += 1
        if self.looks == 2:
            os.kill(os.getpid(), signal.SIGUSR1)
        return super().is_set()


def test_a_signal_handler_querying_the_store_inside_the_progress_handler():
    """A signal's handler that queries the store (a status report on SIGUSR1) as it runs
    inside a compiled statement's progress handler: its statement is answered and the
    statement it interrupted goes on to its answer. The progress handler, a generator, could
    not be resumed by the handler's statement (which keeps the handler of the statement it
    runs inside): SQLite ended that statement, which raised KeyboardInterrupt though no
    Ctrl-C came, and so did the statement it interrupted."""
    from slr_sql.store import EventStore

    store = EventStore(None)
    reports = []
    previous = signal.signal(signal.SIGUSR1,
                             lambda signum, frame: reports.append(store.sql(COUNTING)))
    try:
        stop = _SignalledWhileChecked()
        try:
            rows = store.run_compiled(COUNTING, {}, may_fall_back=True, stop=stop)
        except KeyboardInterrupt:
            pytest.fail("a KeyboardInterrupt, though no Ctrl-C came")
        assert rows == [(200000,)]
    finally:
        signal.signal(signal.SIGUSR1, previous)
    assert stop.looks > 2 and reports == [(["count(*)"], [(200000,)])]
    store.close()
