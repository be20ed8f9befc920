"""PostgreSQL: the read connection of a store (``PgReadConnection``, the subscription hub's
journal reads) waits for another session's lock at most ``busy_timeout``, then SLRBusy --
retryable, like every other call of the store -- instead of as long as the lock is held.

The lock is real: another psycopg session holds ``LOCK TABLE ... IN ACCESS EXCLUSIVE
MODE`` (what an ``ALTER TABLE`` takes) in a transaction left open. Every wait has a
deadline; the lock is let go in a ``finally``, so a reader that would wait for it ends."""
from __future__ import annotations

import logging
import threading

import psycopg
import pytest

import slr_sql
from slr_sql.store import quote_identifier  # (an identifier cannot be bound)
from slr_sql import ManualClock
from slr_sql.errors import SLRBusy

from hub_helpers import hub_with_one_delivery

DEADLINE = 30.0


class _Locked:
    """Another session holding ``table`` in ACCESS EXCLUSIVE mode until ``release``."""

    def __init__(self, url: str, table: str):
        self.conn = psycopg.connect(url)
        self.conn.execute("SET search_path = slr")
        self.conn.execute(f"LOCK TABLE {quote_identifier(table)} IN ACCESS EXCLUSIVE MODE")

    def release(self) -> None:
        self.conn.rollback()
        self.conn.close()


def _in_a_thread(call):
    """Run ``call`` in a thread; returns the thread and the box of its outcome."""
    box: dict = {}

    def run():
        try:
            box["value"] = call()
        except BaseException as exc:   # noqa: BLE001 - handed to the test
            box["error"] = exc

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread, box


@pytest.mark.parametrize("busy_timeout", [0.3, 0])
def test_a_journal_read_meeting_another_sessions_lock_is_busy(postgres_url, busy_timeout):
    """(``busy_timeout=0``: no wait, not the server's lock_timeout 0, which is no limit.)"""
    with slr_sql.open(postgres_url, clock=ManualClock(0.0), busy_timeout=busy_timeout) as kb:
        sub = kb.subscribe("p(X)^T", since=0)
        kb.add("p(1)^1")
        assert sub.get(timeout=DEADLINE)["X"] == 1
        journal = f"slr_subj_{kb.store.table_for('p', 1)}"
        reads = kb.store.journal_reader(own_connection=True)
        try:
            locked = _Locked(postgres_url, journal)
            try:
                thread, box = _in_a_thread(lambda: reads.journal_rows(journal, 1, 0, 10))
                thread.join(DEADLINE)
                assert not thread.is_alive(), "the read waited for the lock past its deadline"
            finally:
                locked.release()
                thread.join(DEADLINE)
            error = box.get("error")
            assert isinstance(error, SLRBusy), repr(box)
            assert f"locked by another writer for more than {busy_timeout:g} s" in str(error)
            assert not isinstance(error, psycopg.Error)
            # the same read, the lock gone: the connection works
            assert [row[0] for row in reads.journal_rows(journal, 1, 0, 10)] == [1]
        finally:
            reads.close()
        sub.close()


def test_the_hub_meeting_a_locked_journal_logs_busy_and_delivers_once_it_is_free(
        postgres_url, caplog):
    with hub_with_one_delivery(postgres_url, caplog, busy_timeout=0.3) as (kb, hub, sub):
        assert hub.drain(DEADLINE)
        journal = f"slr_subj_{kb.store.table_for('p', 1)}"
        locked = _Locked(postgres_url, journal)
        try:
            thread, box = _in_a_thread(lambda: hub.drain(10.0))
            thread.join(DEADLINE)
            assert not thread.is_alive() and box.get("value") is True, \
                "the hub's pass waited for the lock past its deadline"
        finally:
            locked.release()
            thread.join(DEADLINE)
        records = [r for r in caplog.records if "delivery pass failed" in r.getMessage()]
        assert len(records) == 1, caplog.text
        [record] = records
        assert record.levelno == logging.WARNING and record.exc_info is None
        assert "SLRBusy" in record.getMessage() and "retrying" in record.getMessage()
        # the lock gone: the hub goes on
        kb.add("p(2)^2")
        assert sub.get(timeout=DEADLINE)["X"] == 2
        sub.close()
