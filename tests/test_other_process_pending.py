"""Decisions another process left pending (it stored them, then stopped) are made here when
only this process's clock moves, or an in-order event of this process completes them: on
SQLite the rules read their pending summaries again when ``PRAGMA data_version`` says that
another connection committed (a check without I/O when nothing changed); on PostgreSQL when
the store's connection heard another session's notification that it changed the pending
rows (a trigger of ``slr_cep_pending``; the check reads what the socket holds, no round
trip)."""
from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import slr_sql
from slr_sql import ManualClock

REPO = Path(__file__).resolve().parent.parent

RULE = ":- consumption(recent).\n:- max_delay(b/1, 0).\n" \
       "c(X) <- a(X) seq b(X).\n"
BY_DELAY = ":- max_delay(a/1, 5).\n" + RULE        # a/1 complete to now - 5
IN_ORDER = ":- in_order(a/1).\n" + RULE             # a/1 complete to its latest end


def _add_in_another_process(path: Path | str, events: list[str]) -> None:
    """Another process opens the store (the program is the stored one), adds ``events``
    with its clock at 0, and exits."""
    code = ("import sys, slr_sql\n"
            "kb = slr_sql.open(sys.argv[1], clock=slr_sql.ManualClock(0.0))\n"
            "assert kb.add_many(sys.argv[2:]) == []\n"
            "assert kb.event_rules()[0]['pending'] == 1, kb.event_rules()\n"
            "kb.close()\n")
    done = subprocess.run([sys.executable, "-c", code, str(path), *events],
                          env=dict(os.environ, PYTHONPATH=str(REPO)),
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr


def _c(kb) -> list:
    return [(a["X"], a["S"], a["E"]) for a in kb.query("c(X)^[S, E]")]


def _heard_of_it(kb, before: int) -> None:
    """Until the store has heard that another connection changed the pending rows (on
    PostgreSQL the notification crosses the server: a deadline, not a pause)."""
    deadline = time.monotonic() + 30
    while kb.store.others_version() == before:
        assert time.monotonic() < deadline, "the other connection's change was never heard"
        time.sleep(0.005)


def test_a_clock_move_decides_what_another_process_left_pending(backend):
    path = backend
    with slr_sql.open(path, clock=ManualClock(0.0)) as kb:
        kb.load(BY_DELAY)
        kb.clock.advance(1)                   # (its rules have looked: nothing pending)
        before = kb.store.others_version()
        _add_in_another_process(path, ["a(1)^1", "b(1)^2"])
        _heard_of_it(kb, before)
        assert _c(kb) == []                   # (its clock at 1: a/1 complete to -4)
        kb.clock.set(8.0)                     # a/1 complete to 3: the decision can be made
        assert _c(kb) == [(1, 1.0, 2.0)]
        assert kb.event_rules()[0]["pending"] == 0


def test_an_in_order_event_decides_what_another_process_left_pending(backend):
    path = backend
    # (the clock here is at 10: b/1 is complete to 10; what a/1 needs is its event at 3)
    with slr_sql.open(path, clock=ManualClock(10.0)) as kb:
        kb.load(IN_ORDER)
        assert kb.add_many(["a(0)^0.5"]) == []
        before = kb.store.others_version()
        _add_in_another_process(path, ["a(1)^1", "b(1)^2"])
        _heard_of_it(kb, before)
        assert _c(kb) == []
        assert kb.add_many(["a(9)^3"]) == []  # a/1 complete before 3
        assert _c(kb) == [(1, 1.0, 2.0)]


def test_a_process_alone_reads_its_summaries_no_more_often(tmp_path):
    # nothing committed by another connection: a clock move reads no summary (the rules'
    # statements, counted by SQLite's own trace of this connection)
    path = tmp_path / "robot.db"
    with slr_sql.open(path, clock=ManualClock(0.0)) as kb:
        kb.load(BY_DELAY)
        kb.add_many(["a(1)^1", "b(1)^2"])
        kb.clock.advance(1)
        statements: list[str] = []
        kb.store._db.conn.set_trace_callback(statements.append)
        try:
            for _ in range(5):
                kb.clock.advance(0.1)
        finally:
            kb.store._db.conn.set_trace_callback(None)
        assert not [s for s in statements if "slr_cep_pending WHERE rule" in s]


def test_a_postgresql_process_alone_reads_its_summaries_no_more_often(postgres_url):
    # its own changes of the pending rows notify too, but it knows them: a clock move reads
    # no summary, and the check sends nothing to the server
    from libpq_trace import traced_messages
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as kb:
        kb.load(BY_DELAY)
        kb.add_many(["a(1)^1", "b(1)^2"])
        kb.clock.advance(1)

        def moves():
            for _ in range(5):
                kb.clock.advance(0.1)
        messages = traced_messages(kb, moves)
        sent = [m for m in messages if m[0] == "F" and m[2] in ("Query", "Parse")]
        assert not [m for m in sent if "slr_cep_pending WHERE rule" in "\t".join(m[3:])]
        kb.add_many(["a(2)^3"])
        version = kb.store.others_version()
        assert traced_messages(kb, kb.store.others_version) == []
        assert kb.store.others_version() == version


def test_another_postgresql_store_in_the_same_database_is_not_heard(postgres_url):
    # the notification names its schema: a store in another schema of the database does not
    # make these rules read their summaries again
    other = postgres_url + ("&" if "?" in postgres_url else "?") + "schema=elsewhere"
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as kb:
        kb.load(BY_DELAY)
        before = kb.store.others_version()
        with slr_sql.open(other, clock=ManualClock(0.0)) as elsewhere:
            elsewhere.load(BY_DELAY)
            elsewhere.add_many(["a(1)^1", "b(1)^2"])
            assert elsewhere.event_rules()[0]["pending"] == 1
        # one notification for this store, sent after the other schema's (the server
        # delivers them in commit order): once it is heard, the others were read too
        import psycopg

        from slr_sql.store.postgres import PENDING_CHANNEL, split_url
        with psycopg.connect(split_url(postgres_url)[0], autocommit=True) as conn:
            conn.execute("SELECT pg_notify(%s, %s)", (PENDING_CHANNEL, kb.store._db.schema))
        _heard_of_it(kb, before)
        assert kb.store.others_version() == before + 1
