"""The synchronizer's timer thread meets a store it cannot read while it polls for what
other processes wrote (``watch_external``): it logs one line and polls on, so the pending
queries are released once the store reads again — the thread serves every later timer and
timeout, and ending it would leave them all waiting."""
from __future__ import annotations

import logging
import sqlite3
import threading
import time

import pytest

import slr_sql

DEADLINE = 30.0


@pytest.fixture
def shared(tmp_path):
    """The store's path, and two knowledge bases on it (one process's, another's)."""
    path = tmp_path / "shared.db"
    kb = slr_sql.open(path, clock=slr_sql.ManualClock(0))
    other = slr_sql.open(path, clock=slr_sql.ManualClock(0))
    try:
        yield path, kb, other
    finally:
        other.close()
        kb.close()


def _wait_for(condition, what: str) -> None:
    poll = threading.Event()
    deadline = time.monotonic() + DEADLINE
    while not condition():
        assert time.monotonic() < deadline, what
        poll.wait(0.01)


def test_the_timer_thread_outlives_a_store_it_cannot_read_and_releases_later(shared, caplog):
    path, kb, other = shared
    kb.load(":- max_delay(p/1, 1e10).")
    kb.add("p(1)^1")
    pending = kb.submit("p(X)^T", at=5)
    kb.synchronizer.watch_external(0.01)
    raw = sqlite3.connect(path)
    failed = "re-reading what other processes wrote to the store failed"
    with caplog.at_level(logging.WARNING, logger="slr_sql.sync"):
        # another process renames the table the marks are read from, and commits
        raw.execute("ALTER TABLE slr_meta RENAME TO slr_meta_away")
        raw.commit()
        _wait_for(lambda: failed in caplog.text, "the failure logged")
        raw.execute("ALTER TABLE slr_meta_away RENAME TO slr_meta")
        raw.commit()
        raw.close()
        other.mark_complete("p/1", 10)          # another process's mark: the query goes
        assert [a["X"] for a in pending.result(DEADLINE)] == [1]
    assert "Traceback" not in caplog.text


def test_a_re_read_failing_half_way_lets_the_queries_it_released_go_and_says_so_once(
        shared, caplog):
    """The re-read releases the queries of each parked type in turn; the read of a later type
    fails (its table renamed by another process): the queries already released are
    answered, not dropped, the failure is logged once however many polls meet it, and
    once the store reads again, that is said too."""
    path, kb, other = shared
    kb.load(":- max_delay(a/1, 1e10).\n:- max_delay(b/1, 1e10).\n:- in_order(b/1).\n")
    kb.add("a(1)^1")
    kb.add("b(1)^1")
    first = kb.submit("a(X)^T", at=5)       # parked on a/1, before b/1
    kb.submit("b(X)^T", at=5)               # on b/1: in order, its latest end is read
    second = kb.submit("a(X)^T", at=10.5)
    kb.synchronizer.watch_external(0.01)
    raw = sqlite3.connect(path)
    table = dict(raw.execute("SELECT name, table_name FROM slr_event_types"))["b"]
    failed = "re-reading what other processes wrote to the store failed"
    with caplog.at_level(logging.WARNING, logger="slr_sql.sync"):
        raw.execute(f'ALTER TABLE "{table}" RENAME TO b_away')
        raw.commit()
        other.mark_complete("a/1", 10)
        assert [a["X"] for a in first.result(DEADLINE)] == [1]
        _wait_for(lambda: failed in caplog.text, "the failure logged")
        other.mark_complete("a/1", 11)      # another poll, failing at b/1 again
        assert [a["X"] for a in second.result(DEADLINE)] == [1]
        assert caplog.text.count(failed) == 1
        raw.execute(f'ALTER TABLE b_away RENAME TO "{table}"')
        raw.commit()
        other.mark_complete("a/1", 12)
        _wait_for(lambda: "works again" in caplog.text, "the recovery logged")
    raw.close()
    assert caplog.text.count(failed) == 1 and "Traceback" not in caplog.text
