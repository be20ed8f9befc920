"""How an add reaches the PostgreSQL server: the statements and round trips it takes.

A real server (tests/conftest.py). The round trips are counted in libpq's own trace of the
knowledge base's connection (the protocol messages it sent and received), never timed: an
add of a few events with no rules, subscriptions or buffers is one statement that makes
the change check, stores every table's rows (if the check passes) and commits on its own. The rows it defers until
its transaction ends must still reach the server before anything else the transaction
runs, an error in them must store nothing, and their order must be their rows' order.
"""
from __future__ import annotations


import psycopg
import pytest

import slr_sql
from slr_sql import ManualClock
from slr_sql.errors import SLRError

from libpq_trace import traced_messages


def _traced(kb, call) -> list[tuple[str, str]]:
    """``(direction, message type)`` of every protocol message of the knowledge base's
    connection while ``call()`` runs (F: sent by the client, B: sent by the server)."""
    return [(fields[0], fields[2]) for fields in traced_messages(kb, call) if len(fields) > 2]


def _column(url: str, sql: str) -> list:
    with psycopg.connect(url, autocommit=True) as conn:
        conn.execute("SET search_path = slr")
        return [row[0] for row in conn.execute(sql)]


def test_an_add_many_of_two_types_is_one_round_trip(postgres_url):
    """One statement holding the change check and both tables' rows (stored only if the
    check finds the program unchanged), committed by the server on its own (no BEGIN, no
    COMMIT): one wait for the server, not two (the check apart) or three."""
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as kb:
        kb.add_many([("a", ("k",), 0.0, 0.0), ("b", ("k",), 0.0, 0.0)])   # tables exist
        batch = [("a" if i % 2 == 0 else "b", (f"k{i}",), 1.0, 1.0) for i in range(10)]
        messages = _traced(kb, lambda: kb.add_many(batch))
        waits = [m for m in messages if m == ("B", "ReadyForQuery")]
        statements = [m for m in messages if m[0] == "F" and m[1] in ("Execute", "Query")]
        assert len(waits) == 1, messages
        assert len(statements) == 1, messages
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


def test_a_shipped_batch_into_postgresql_is_five_round_trips(postgres_url):
    """A batch of many rows shipped into a PostgreSQL fleet store waits for the server five
    times, whatever its size: the change check, the BEGIN with the robot's position, the
    COPY (its start is answered before the rows go), its end, and the COMMIT that carries
    the robot's count and position. The rows, the count and the position are stored."""
    from slr_sql import shipping
    rows = [(i, f"pallet{i}", "dock", float(i), float(i), 0.5, "r1") for i in range(1, 201)]
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as kb:
        shipping.receive(kb, "r1", [("seen", 2, rows[:100])])   # (the table exists)
        messages = _traced(kb, lambda: shipping.receive(kb, "r1", [("seen", 2, rows[100:])]))
        waits = [m for m in messages
                 if m[0] == "B" and m[1] in ("ReadyForQuery", "CopyInResponse")]
        assert len(waits) == 5, messages
        assert kb.store.fleet_positions("r1") == {("seen", 2): 200}
        assert [(c["robot"], c["shipped"]) for c in kb.store.fleet_contacts()] == [("r1", 200)]
        assert _column(postgres_url, "SELECT arg1 FROM seen ORDER BY seq") == \
            [f"pallet{i}" for i in range(1, 201)]


def test_a_statement_nobody_reads_goes_with_the_next_and_fails_its_transaction(
        postgres_url):
    """``execute_unanswered`` in an open transaction: sent with the next statement, in
    the same wait (which sees its effect), or with the COMMIT; one the server refuses fails
    the transaction as a whole, nothing of it stored, and the connection works after."""
    from slr_sql.store import DatabaseError
    insert = "INSERT INTO slr_meta (key, value) VALUES (?, ?)"
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as kb:
        store, conn = kb.store, kb.store._conn
        with store.transaction():
            store.execute("SELECT 1")          # (the BEGIN went)

            def unanswered_then_read():
                conn.execute_unanswered(insert, ("k1", "1"))
                assert store.execute("SELECT value FROM slr_meta WHERE key = 'k1'") == \
                    [("1",)]
            messages = _traced(kb, unanswered_then_read)
            assert messages.count(("B", "ReadyForQuery")) == 1, messages
            conn.execute_unanswered(insert, ("k2", "2"))      # goes with the COMMIT
        assert _column(postgres_url, "SELECT key FROM slr_meta WHERE key LIKE 'k_' "
                                     "ORDER BY key") == ["k1", "k2"]
        with pytest.raises(DatabaseError, match="duplicate key"), store.transaction():
            store.execute("SELECT 1")
            conn.execute_unanswered(insert, ("k3", "3"))
            conn.execute_unanswered(insert, ("k1", "again"))   # refused at the COMMIT
        assert _column(postgres_url, "SELECT key FROM slr_meta WHERE key LIKE 'k_' "
                                     "ORDER BY key") == ["k1", "k2"]
        conn.execute_unanswered(insert, ("k4", "4"))      # no transaction: at once
        assert _column(postgres_url, "SELECT value FROM slr_meta WHERE key = 'k4'") == ["4"]


def _other(url: str):
    return slr_sql.open(url, clock=ManualClock(0.0))


def test_an_add_sees_a_rule_another_connection_loaded_after_its_last_call(postgres_url):
    """The change check travels in the add's statement: when it finds the program changed
    (another connection loaded an event rule since this one last looked), the statement
    stores nothing and the add is made again on the new program, which derives the
    complex event; every event is stored once."""
    with _other(postgres_url) as kb, _other(postgres_url) as loader:
        kb.add_many([("x", ("k",), 1.0, 1.0), ("y", ("k",), 0.0, 0.0)])   # tables exist
        loader.load("xy(K) <- x(K) seq y(K).")
        kb.add_many([("y", ("k",), 2.0, 2.0), ("z", ("k",), 2.0, 2.0)])
        assert kb.query("xy(K)^[S, E]") == [{"K": "k", "S": 1.0, "E": 2.0}]
        assert loader.query("xy(K)^[S, E]") == [{"K": "k", "S": 1.0, "E": 2.0}]
        assert _column(postgres_url, "SELECT t_end FROM y ORDER BY seq") == [0.0, 2.0]
        assert _column(postgres_url, "SELECT t_end FROM z ORDER BY seq") == [2.0]
        assert _column(postgres_url, "SELECT t_end FROM x ORDER BY seq") == [1.0]
        # and the next add of this connection is one round trip again
        messages = _traced(kb, lambda: kb.add_many([("z", ("k",), 3.0, 3.0)]))
        assert messages.count(("B", "ReadyForQuery")) == 1, messages


def test_an_add_records_the_clock_for_a_tbuffer_another_connection_added(postgres_url):
    """A server's add records the clock only while a tBuffer is active: a tBuffer another
    connection added since this one last looked is found by the add's own check, and the
    add is made again recording the clock first, so the buffer judges the add's events
    (and prunes the stored ones) at this connection's time."""
    with slr_sql.open(postgres_url, clock=ManualClock(20.0)) as kb, \
            _other(postgres_url) as other:
        kb.add_many([("p", ("a",), 0.0, 0.0), ("q", ("a",), 0.0, 0.0)])
        assert kb.store._db.tbuffers_active is False
        other.add_buffer("p(_)", keep_seconds=5)   # (judged at the other's time, 0)
        assert _column(postgres_url, "SELECT t_end FROM p") == [0.0]
        kb.add_many([("p", ("b",), 1.0, 1.0), ("q", ("b",), 1.0, 1.0)])
        assert _column(postgres_url, "SELECT t_end FROM p") == []
        assert _column(postgres_url, "SELECT t_end FROM q ORDER BY seq") == [0.0, 1.0]
        assert [(b.pruned, b.dropped) for b in kb.buffers()] == [(1, 1)]


def test_marks_another_connection_wrote_are_heard_with_the_add(postgres_url):
    """What the check reads of the progress (completeness marks another connection raised)
    reaches the synchronizer right after the add's statement: a synchronized query waiting
    for such a mark is answered at this connection's next add, without another read."""
    with _other(postgres_url) as kb, _other(postgres_url) as other:
        kb.add_many([("p", ("a",), 1.0, 1.0), ("q", ("a",), 0.0, 0.0)])
        waiting = kb.submit("p(X)^T", at=5.0)
        assert not waiting.done()
        other.mark_complete("p/1", 5.0)
        messages = _traced(kb, lambda: kb.add_many([("q", ("b",), 1.0, 1.0)]))
        assert waiting.result(timeout=10) == [{"X": "a", "T": 1.0}]
        assert messages.count(("B", "ReadyForQuery")) >= 1


def test_an_add_with_a_rule_sees_a_rule_another_connection_loaded_after_its_last_call(
        postgres_url):
    """With an event rule the add opens a transaction (the rule's writer lock): the change
    check goes ahead of its BEGIN, in the same round trip, and when it finds the program
    changed the transaction is rolled back with what it ran and the add is made again on
    the new program: both rules derive, every event is stored once."""
    with _other(postgres_url) as kb, _other(postgres_url) as loader:
        kb.load("xy(K) <- x(K) seq y(K).")
        kb.add_many([("x", ("k",), 1.0, 1.0), ("z", ("k",), 0.0, 0.0)])
        loader.load("yz(K) <- y(K) seq z(K).", name="other")
        kb.add_many([("y", ("k",), 2.0, 2.0), ("z", ("k",), 3.0, 3.0)])
        assert kb.query("xy(K)^[S, E]") == [{"K": "k", "S": 1.0, "E": 2.0}]
        assert kb.query("yz(K)^[S, E]") == [{"K": "k", "S": 2.0, "E": 3.0}]
        assert _column(postgres_url, "SELECT t_end FROM y ORDER BY seq") == [2.0]
        assert _column(postgres_url, "SELECT t_end FROM z ORDER BY seq") == [0.0, 3.0]
        assert _column(postgres_url, "SELECT count(*) FROM xy") == [1]
