"""The synchronizer's timer thread meets a store it cannot read while it polls for what
other processes wrote (``watch_external``): it logs one line and polls on, so the pending
queries are released once the store reads again — the thread serves every later timer and
timeout, and ending it would leave them all waiting."""
from __future__ import annotations

import logging
import sqlite3
import threading
import time

import slr_sql

DEADLINE = 30.0


def test_the_timer_thread_outlives_a_store_it_cannot_read_and_releases_later(tmp_path, caplog):
    path = tmp_path / "shared.db"
    kb = slr_sql.open(path, clock=slr_sql.ManualClock(0))
    other = slr_sql.open(path, clock=slr_sql.ManualClock(0))
    try:
        kb.load(":- max_delay(p/1, 1e10).")
        kb.add("p(1)^1")
        pending = kb.submit("p(X)^T", at=5)
        kb.synchronizer.watch_external(0.01)
        raw = sqlite3.connect(path)
        with caplog.at_level(logging.WARNING, logger="slr_sql.sync"):
            # another process renames the table the marks are read from, and commits
            raw.execute("ALTER TABLE slr_meta RENAME TO slr_meta_away")
            raw.commit()
            poll = threading.Event()
            deadline = time.monotonic() + DEADLINE
            while "re-reading what other processes wrote" not in caplog.text and \
                    time.monotonic() < deadline:
                poll.wait(0.01)
            assert "re-reading what other processes wrote" in caplog.text
            raw.execute("ALTER TABLE slr_meta_away RENAME TO slr_meta")
            raw.commit()
            raw.close()
            other.mark_complete("p/1", 10)          # another process's mark: the query goes
            assert [a["X"] for a in pending.result(DEADLINE)] == [1]
        assert "Traceback" not in caplog.text
    finally:
        other.close()
        kb.close()
