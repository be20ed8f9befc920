"""PostgreSQL: ``busy_timeout`` becomes ``lock_timeout`` on every connection of the store,
at least 1 ms: ``busy_timeout=0`` means no wait, never the server's ``lock_timeout = 0``
(no limit at all). A value that is no number of seconds >= 0 is refused at open with the
words SQLite stores get, not a raw OverflowError or ValueError.

The lock is real: another psycopg session holds a table in a transaction left open; every
wait has a deadline, and the lock is let go in a ``finally``."""
from __future__ import annotations

import psycopg
import pytest

import slr_sql
from slr_sql.store import quote_identifier  # (an identifier cannot be bound)
from slr_sql import ManualClock
from slr_sql.errors import SLRBusy, SLRError
from test_postgres_reader_busy import _in_a_thread

DEADLINE = 30.0


def _outcome_within_deadline(url: str, table: str, mode: str, call) -> dict:
    """Run ``call`` in a thread while another session holds ``table`` in ``mode``; the
    outcome (``value`` or ``error``), asserting the call ended within the deadline."""
    other = psycopg.connect(url)
    thread = None
    try:
        other.execute("SET search_path = slr")
        other.execute(f"LOCK TABLE {quote_identifier(table)} IN {mode} MODE")
        thread, box = _in_a_thread(call)
        thread.join(DEADLINE)
        assert not thread.is_alive(), "the call waited for the lock past its deadline"
    finally:
        other.rollback()
        other.close()
        if thread is not None:
            thread.join(DEADLINE)
    return box


def test_busy_timeout_0_makes_an_add_meeting_a_lock_busy_at_once(postgres_url):
    with slr_sql.open(postgres_url, clock=ManualClock(0.0), busy_timeout=0) as kb:
        kb.add("p(1)^1")
        table = kb.store.table_for("p", 1)
        box = _outcome_within_deadline(postgres_url, table, "SHARE",
                                       lambda: kb.add("p(2)^2"))
        assert isinstance(box.get("error"), SLRBusy), repr(box)
        kb.add("p(2)^2")   # the lock gone: stored
        assert sorted(a["X"] for a in kb.query("p(X)^T")) == [1, 2]


def test_busy_timeout_0_makes_a_read_meeting_a_lock_busy_at_once(postgres_url):
    with slr_sql.open(postgres_url, clock=ManualClock(0.0), busy_timeout=0) as kb:
        kb.add("p(1)^1")
        table = kb.store.table_for("p", 1)
        box = _outcome_within_deadline(postgres_url, table, "ACCESS EXCLUSIVE",
                                       lambda: kb.sql(f"SELECT count(*) FROM {quote_identifier(table)}"))
        assert isinstance(box.get("error"), SLRBusy), repr(box)
        assert kb.sql(f"SELECT count(*) FROM {quote_identifier(table)}")[1] == [(1,)]


@pytest.mark.parametrize("value", [float("inf"), float("nan"), -1, "5", True],
                         ids=["inf", "nan", "negative", "text", "bool"])
def test_a_busy_timeout_that_is_no_seconds_is_refused_on_both_backends(backend, value):
    with pytest.raises(SLRError, match=r"^busy_timeout must be a number of seconds >= 0, "
                                       r"not ") as caught:
        slr_sql.open(backend, busy_timeout=value)
    assert caught.value.__context__ is None or caught.value.__suppress_context__


def test_a_huge_busy_timeout_opens_on_both_backends(backend):
    """(``lock_timeout`` is an int of milliseconds: about 24 days at most.)"""
    with slr_sql.open(backend, clock=ManualClock(0.0), busy_timeout=1e30) as kb:
        kb.add("p(1)^1")
        assert [a["X"] for a in kb.query("p(X)^T")] == [1]
