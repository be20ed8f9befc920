"""A wall clock's decision round that fails busy is tried again by a timer.

With a wall clock no clock listener calls the pipeline when time passes: a timer of the
synchronizer does, at the times pending decisions wait for. A decision round that fails
busy (another session holds a table it writes) -- after an add, whose events are committed,
or on that timer's thread -- leaves its decisions pending; a retry timer (a backoff from
50 ms, at most 1 s) makes them once the table is free, without another add, mark or timer.
PostgreSQL: its table locks let another session block a round's writes and not the add's.
"""
from __future__ import annotations

import threading
import time

import psycopg

import slr_sql
from slr_sql import WallClock

# seconds a wait may take before the test fails (a bound, not a pause: a 10 s one was met
# on a machine loaded to 18 runnable processes, where the timer's round itself came late)
DEADLINE = 60.0


def _other(url: str) -> psycopg.Connection:
    conn = psycopg.connect(url)
    conn.execute("SET search_path = slr")
    return conn


def _derived_seen(kb) -> threading.Event:
    """Set once a batch holding a complex event ``c`` reaches the add listeners."""
    seen = threading.Event()
    kb.add_listeners.append(lambda batch: any(e[0] == "c" for e in batch) and seen.set())
    return seen


def _until_failed(other: psycopg.Connection, pid: int) -> None:
    """Until backend ``pid`` has waited for a lock and given up (its lock_timeout): the
    round failed busy (deadline-bounded)."""
    deadline = time.monotonic() + DEADLINE
    for waiting in (True, False):
        while (other.execute("SELECT wait_event_type FROM pg_stat_activity WHERE pid = %s",
                             (pid,)).fetchone()[0] == "Lock") is not waiting:
            assert time.monotonic() < deadline, f"backend {pid}: waiting is never {waiting}"
            time.sleep(0.005)


def test_a_round_an_add_made_possible_that_fails_busy_is_retried(postgres_url):
    """The history of a and b is complete only by marks (their delays are long); an add of
    the marks makes the decision possible, its round meets the pending table locked and
    fails busy, the add returns. Once the lock is gone, a retry derives c: no other add."""
    program = (":- consumption(recent).\n:- max_delay(a/1, 100).\n:- max_delay(b/1, 100).\n"
               "c(X) <- a(X) seq b(X).\n")
    t = WallClock().now() - 1.0
    with slr_sql.open(postgres_url, busy_timeout=0.2) as kb:
        kb.load(program)
        kb.add_many([f"a(1)^{t}", f"b(1)^{t + 0.5}"])
        seen = _derived_seen(kb)
        with _other(postgres_url) as other:
            other.execute("LOCK TABLE slr_cep_pending IN SHARE MODE")
            assert kb.add_many([f"fullyUpdated(a/1)^{t + 1}", f"fullyUpdated(b/1)^{t + 1}"]) \
                == []
            assert kb.query("c(X)^_") == []   # (the add's round failed busy)
            other.rollback()
        assert seen.wait(DEADLINE), "the pending decision was never made"
        assert [(r["X"], r["S"], r["E"]) for r in kb.query("c(X)^[S, E]")] == \
            [(1, t, t + 0.5)]


def test_a_round_the_timer_starts_that_fails_busy_is_retried(postgres_url):
    """The decision waits for the clock (a and b complete 2 s after their times): the
    synchronizer's timer starts its round, which meets the pending table locked and fails
    busy on the timer's thread. Once the lock is gone, a retry derives c."""
    # (2 s: the lock below must come before the timer's round even on a loaded machine)
    program = (":- consumption(recent).\n:- max_delay(a/1, 2).\n:- max_delay(b/1, 2).\n"
               "c(X) <- a(X) seq b(X).\n")
    with slr_sql.open(postgres_url, busy_timeout=0.2) as kb:
        kb.load(program)
        seen = _derived_seen(kb)
        # the store's own connection (a read-only kb.sql runs on one of its own)
        pid = kb.sql("SELECT pg_backend_pid()", write=True)[1][0][0]
        with _other(postgres_url) as other:
            # (the times are taken once the store is open: opening a PostgreSQL store,
            # which creates its schema, took 2.6-3.4 s on a loaded machine, past the 1.9 s
            # the events left the lock)
            t = WallClock().now() - 0.1
            kb.add_many([f"a(1)^{t - 0.5}", f"b(1)^{t}"])
            other.execute("LOCK TABLE slr_cep_pending IN SHARE MODE")
            assert kb.query("c(X)^_") == []   # (the lock came before the timer's round)
            with _other(postgres_url) as watcher:
                _until_failed(watcher, pid)
            other.rollback()
        assert seen.wait(DEADLINE), "the pending decision was never made"
        assert [(r["X"], r["S"], r["E"]) for r in kb.query("c(X)^[S, E]")] == \
            [(1, t - 0.5, t)]
