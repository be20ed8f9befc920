"""close() writes the learned delays not written yet (one that grew by less than 1 ms, or
whose write after an add met a lock): it waits for another session's lock up to the store's
busy_timeout, and when it still cannot write, it says so -- a warning naming the type and
the delay -- instead of dropping the delay silently."""
from __future__ import annotations

import threading
import time
import warnings

import psycopg
import pytest

import slr_sql
from slr_sql import ManualClock
from slr_sql.clocks import LearnedDelayNotWrittenWarning
from store_holders import meta_held


def _stored_delay(kb_location: str) -> float | None:
    with slr_sql.open(kb_location, clock=ManualClock(100.0)) as kb:
        value = kb.store.meta_get("sync/learned/a/1")
    return None if value is None else float(value)


def test_a_delay_close_cannot_write_is_warned_about(backend):
    kb = slr_sql.open(backend, clock=ManualClock(100.0), busy_timeout=0.3)
    kb.add_many(["a(1)^99.5"])                  # learns 0.5 s, written
    kb.add_many(["a(2)^99.4996"])               # 0.5004 s: grew by < 1 ms, left for close
    with meta_held(backend):
        with pytest.warns(LearnedDelayNotWrittenWarning) as caught:
            kb.close()
    [warning] = caught
    text = str(warning.message)
    assert text.startswith("a/1: ") and "(0.5004 s)" in text and "locked by another" in text
    assert warning.filename == __file__   # (where close was called)
    assert kb.store.closed
    assert _stored_delay(backend) == 0.5        # (what the warning says was not written)


def test_a_delay_a_busy_add_left_unwritten_is_warned_about_at_close(postgres_url):
    kb = slr_sql.open(postgres_url, clock=ManualClock(100.0), busy_timeout=0.3)
    kb.add_many(["a(1)^99.5"])
    with meta_held(postgres_url):
        assert kb.add_many(["a(2)^98"]) == []   # learns 2 s: its write fails busy
        with pytest.warns(LearnedDelayNotWrittenWarning, match=r"a/1: .*\(2 s\)"):
            kb.close()
    assert _stored_delay(postgres_url) == 0.5


def test_close_waits_for_the_lock_and_then_writes_the_delay(postgres_url):
    # close waits up to busy_timeout (30 s here): the other session lets go once it sees
    # close's write waiting for its lock (read from the server, within a deadline)
    kb = slr_sql.open(postgres_url, clock=ManualClock(100.0), busy_timeout=30)
    kb.add_many(["a(1)^99.5"])
    kb.add_many(["a(2)^99.4996"])               # left for close
    other = psycopg.connect(postgres_url)
    other.execute("LOCK TABLE slr.slr_meta IN SHARE MODE")
    released = threading.Event()
    close_waited = threading.Event()   # (let go at the deadline otherwise: asserted below)

    def release_once_close_waits():
        deadline = time.monotonic() + 20
        try:
            with psycopg.connect(postgres_url, autocommit=True) as watcher:
                # (each look a round trip to the server, bounded by the deadline)
                while time.monotonic() < deadline:
                    if watcher.execute(
                            "SELECT count(*) FROM pg_locks WHERE NOT granted AND database = "
                            "(SELECT oid FROM pg_database WHERE datname = current_database())"
                            ).fetchone()[0]:
                        close_waited.set()
                        break
        finally:
            other.rollback()
            other.close()
            released.set()
    holder = threading.Thread(target=release_once_close_waits, daemon=True)
    holder.start()
    with warnings.catch_warnings():
        warnings.simplefilter("error", LearnedDelayNotWrittenWarning)
        kb.close()                              # (written: no warning)
    assert released.wait(30)
    holder.join(30)
    assert close_waited.is_set(), "close's write never waited for the other's lock"
    assert _stored_delay(postgres_url) == pytest.approx(0.5004)
