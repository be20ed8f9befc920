"""PostgreSQL: savepoints sent with the next statement, and what waits with them.

A nested transaction's SAVEPOINT, the statements nobody reads (``execute_unanswered``) and
the writer groups' locks wait for the transaction's next statement. Two nested transactions
one after the other at the same depth queue the same savepoint name twice; a rollback of
the second must drop what followed *its* SAVEPOINT only, not what the first one (released)
left waiting.
"""
from __future__ import annotations

import psycopg
import pytest

import slr_sql
from slr_sql import ManualClock

INSERT = "INSERT INTO slr_meta (key, value) VALUES (?, ?)"


def _keys(url: str) -> list:
    with psycopg.connect(url, autocommit=True) as conn:
        conn.execute("SET search_path = slr")
        return [r[0] for r in conn.execute(
            "SELECT key FROM slr_meta WHERE key LIKE 'k_' ORDER BY key")]


def test_a_rolled_back_savepoint_keeps_what_an_earlier_one_of_its_name_left_waiting(
        postgres_url):
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as kb:
        store, conn = kb.store, kb.store._conn
        with store.transaction():
            store.execute("SELECT 1")          # (the BEGIN went)
            with store.transaction():
                conn.execute_unanswered(INSERT, ("k1", "1"))   # waits, released
            with pytest.raises(RuntimeError), store.transaction():
                raise RuntimeError("nothing sent inside")
            with store.transaction():
                conn.execute_unanswered(INSERT, ("k2", "2"))
            with pytest.raises(RuntimeError), store.transaction():
                conn.execute_unanswered(INSERT, ("k3", "3"))
                raise RuntimeError("after a statement that waits")
        assert _keys(postgres_url) == ["k1", "k2"]


def test_a_writer_groups_lock_asked_in_a_released_savepoint_survives_a_later_rollback(
        postgres_url):
    """The lock ``lock_for_write`` asks for inside a nested transaction that sent nothing
    waits; a later nested transaction at the same depth that fails must not drop it: the
    transaction's next statement takes it."""
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as kb, \
            psycopg.connect(postgres_url, autocommit=True) as other:
        store = kb.store
        store.set_write_groups([[("a", 1)]])
        pid = store.execute("SELECT pg_backend_pid()")[0][0]
        with store.transaction():
            store.execute("SELECT 1")
            with store.transaction():
                store.lock_for_write([("a", 1)])
            with pytest.raises(RuntimeError), store.transaction():
                raise RuntimeError("nothing sent inside")
            store.execute("SELECT 1")
            held = other.execute("SELECT count(*) FROM pg_locks WHERE locktype = 'advisory' "
                                 "AND pid = %s AND granted", (pid,)).fetchone()[0]
            assert held == 1
