"""How an add reaches the PostgreSQL server: the statements and round trips it takes.

A real server (tests/conftest.py). The round trips are counted in libpq's own trace of the
knowledge base's connection (the protocol messages it sent and received), never timed: an
add of a few events with no rules, subscriptions or buffers is the change check and one
statement that stores every table's rows and commits on its own. The rows it defers until
its transaction ends must still reach the server before anything else the transaction
runs, an error in them must store nothing, and their order must be their rows' order.
"""
from __future__ import annotations

import tempfile

import psycopg
import pytest
from psycopg import pq

import slr_sql
from slr_sql import ManualClock
from slr_sql.errors import SLRError


def _traced(kb, call) -> list[tuple[str, str]]:
    """``(direction, message type)`` of every protocol message of the knowledge base's
    connection while ``call()`` runs (F: sent by the client, B: sent by the server)."""
    raw = kb.store._conn.raw
    with tempfile.TemporaryFile("w+") as out:
        raw.pgconn.trace(out.fileno())
        raw.pgconn.set_trace_flags(pq.Trace.SUPPRESS_TIMESTAMPS | pq.Trace.REGRESS_MODE)
        try:
            call()
        finally:
            raw.pgconn.untrace()
        out.seek(0)
        lines = out.read().splitlines()
    return [(fields[0], fields[2]) for fields in (line.split("\t") for line in lines)
            if len(fields) > 2]


def _column(url: str, sql: str) -> list:
    with psycopg.connect(url, autocommit=True) as conn:
        conn.execute("SET search_path = slr")
        return [row[0] for row in conn.execute(sql)]


def test_an_add_many_of_two_types_is_two_round_trips(postgres_url):
    """The change check, then one statement holding both tables' rows, committed by the
    server on its own (no BEGIN, no COMMIT): two waits for the server, not three."""
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as kb:
        kb.add_many([("a", ("k",), 0.0, 0.0), ("b", ("k",), 0.0, 0.0)])   # tables exist
        batch = [("a" if i % 2 == 0 else "b", (f"k{i}",), 1.0, 1.0) for i in range(10)]
        messages = _traced(kb, lambda: kb.add_many(batch))
        waits = [m for m in messages if m == ("B", "ReadyForQuery")]
        statements = [m for m in messages if m[0] == "F" and m[1] in ("Execute", "Query")]
        assert len(waits) == 2, messages
        assert len(statements) == 2, messages
        # durable and visible to another connection as soon as the add returned, each
        # table's rows in the order they were given
        assert _column(postgres_url, "SELECT arg1 FROM a ORDER BY seq") == \
            ["k", "k0", "k2", "k4", "k6", "k8"]
        assert _column(postgres_url, "SELECT arg1 FROM b ORDER BY seq") == \
            ["k", "k1", "k3", "k5", "k7", "k9"]
        assert [x["X"] for x in kb.query("b(X)^1.0")] == ["k1", "k3", "k5", "k7", "k9"]


def test_a_failing_deferred_insert_stores_nothing_and_the_next_add_works(postgres_url):
    """One table's rows refused by the server (a constraint a user added): the add is an
    SLRError, the other table's rows of the same add are not stored either, and the next
    add on the same connection works."""
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as kb:
        kb.add_many([("a", ("k",), 0.0, 0.0), ("b", ("k",), 0.0, 0.0)])
        with psycopg.connect(postgres_url, autocommit=True) as conn:
            conn.execute("ALTER TABLE slr.b ADD CONSTRAINT b_not_before_zero "
                         "CHECK (t_start >= 0)")
        with pytest.raises(SLRError, match="b_not_before_zero"):
            kb.add_many([("a", ("x",), 1.0, 1.0), ("b", ("x",), -1.0, 1.0),
                         ("a", ("y",), 1.0, 1.0)])
        assert _column(postgres_url, "SELECT arg1 FROM a ORDER BY seq") == ["k"]
        assert _column(postgres_url, "SELECT arg1 FROM b ORDER BY seq") == ["k"]
        kb.add_many([("a", ("z",), 2.0, 2.0), ("b", ("z",), 2.0, 2.0)])
        assert _column(postgres_url, "SELECT arg1 FROM a ORDER BY seq") == ["k", "z"]
        assert _column(postgres_url, "SELECT arg1 FROM b ORDER BY seq") == ["k", "z"]


def test_rows_deferred_in_a_transaction_are_seen_by_its_next_statement(postgres_url):
    """Inserts that open a transaction wait for its end only while nothing else runs: the
    transaction's next statement (here a count, inside the same transaction) sees them;
    a rollback sends nothing."""
    insert = "INSERT INTO p (arg1, t_start, t_end, arrival) VALUES (?, ?, ?, ?)"
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as kb:
        store = kb.store
        store.add_events([("p", (0,), 0.0, 0.0)])
        with store.transaction():
            store.executemany(insert, [("1", 1.0, 1.0, 0.0), ("2", 2.0, 2.0, 0.0)])
            assert store.execute("SELECT count(*) FROM p") == [(3,)]
            store.add_events([("p", (3,), 3.0, 3.0)])   # (a savepoint of its own)
            assert store.count("p", 1) == 4
        assert store.count("p", 1) == 4
        with pytest.raises(RuntimeError), store.transaction():
            store.executemany(insert, [("4", 4.0, 4.0, 0.0)])
            raise RuntimeError("changed my mind")
        assert store.count("p", 1) == 4
        assert _column(postgres_url, "SELECT arg1 FROM p ORDER BY seq") == ["0", "1", "2", "3"]


def test_an_add_wider_than_one_statement_goes_in_parts_in_order(postgres_url):
    """Rows whose parameters would pass the protocol's limit of one statement (65,535;
    here 60 events of 1,100 arguments: 66,180 values) go in several statements, in
    order."""
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as kb:
        wide = [("w", tuple([i] + [0] * 1099), float(i), float(i)) for i in range(60)]
        assert kb.add_many(wide) == []
        assert _column(postgres_url, "SELECT arg1 FROM w ORDER BY seq") == \
            [str(i) for i in range(60)]


def test_subscriptions_of_two_types_see_one_statements_rows(postgres_url):
    """Two tables' rows in one statement (WITH parts): each table's journal trigger runs
    for its own rows, so a subscription to each type gets its events once, in order."""
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as kb:
        kb.add_many([("a", ("k",), 0.0, 0.0), ("b", ("k",), 0.0, 0.0)])
        subs = {name: kb.subscribe(f"{name}(X)^T", since=0.5) for name in "ab"}
        batch = [("a" if i % 2 == 0 else "b", (f"k{i}",), 1.0, 1.0) for i in range(10)]
        kb.add_many(batch)
        for name, first in (("a", 0), ("b", 1)):
            got = [subs[name].get(timeout=30)["X"] for _ in range(5)]
            assert got == [f"k{i}" for i in range(first, 10, 2)]
        with pytest.raises(SLRError):   # (SLRTimeout: nothing more, nothing twice)
            subs["a"].get(timeout=0.3)
