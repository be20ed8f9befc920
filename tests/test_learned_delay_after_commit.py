"""A learned delay is persisted after the add's events committed: when that write meets
another session's lock and times out busy, the add has still stored its events, so it
returns (a retry would store them twice); the delay stays learned in memory and is written
by the next add of any type (another process, or this one after a crash, must not judge
the type complete earlier than the delay learned here allows), or by close.
"""
from __future__ import annotations

import threading

import psycopg

import slr_sql
from slr_sql import ManualClock


def _other(url: str) -> psycopg.Connection:
    conn = psycopg.connect(url)
    conn.execute("SET search_path = slr")
    return conn


def _stored_delay(url: str) -> float | None:
    with psycopg.connect(url, autocommit=True) as conn:
        conn.execute("SET search_path = slr")
        row = conn.execute("SELECT value FROM slr_meta WHERE key = 'sync/learned/a/1'").fetchone()
    return None if row is None else float(row[0])


def test_a_learned_delay_whose_write_is_busy_does_not_fail_the_committed_add(postgres_url):
    clock = ManualClock(100.0)
    with slr_sql.open(postgres_url, clock=clock, busy_timeout=0.3) as kb:
        kb.add_many(["a(1)^99.5"])                       # learns 0.5 s
        assert _stored_delay(postgres_url) == 0.5
        with _other(postgres_url) as other:
            other.execute("LOCK TABLE slr_meta IN SHARE MODE")   # (reads go on, writes wait)
            assert kb.add_many(["a(2)^98"]) == []        # learns 2 s: its write waits, busy
            assert kb.store.count("a", 1) == 2           # the events are stored, once
            assert kb.complete_until("a/1") == 98.0      # (now - the delay learned)
            assert _stored_delay(postgres_url) == 0.5
            other.rollback()
        assert kb.add_many(["a(3)^99.9"]) == []          # learns nothing new: writes it (the write failed before)
        assert kb.store.count("a", 1) == 3
    assert _stored_delay(postgres_url) == 2.0


def test_a_delay_whose_write_failed_is_written_by_the_next_add(postgres_url):
    clock = ManualClock(100.0)
    with slr_sql.open(postgres_url, clock=clock, busy_timeout=0.3) as kb:
        kb.add_many(["a(1)^99.5"])                       # learns 0.5 s
        with psycopg.connect(postgres_url) as other:
            other.execute("SET search_path = slr")
            other.execute("LOCK TABLE slr_meta IN SHARE MODE")   # (reads go on, writes wait)
            assert kb.add_many(["a(2)^98"]) == []        # learns 2 s: its write fails busy
            other.rollback()
        assert _stored_delay(postgres_url) == 0.5
        # an add of another type, learning nothing of a: the unwritten delay goes with it
        assert kb.add_many(["b(1)^99.9"]) == []
        assert _stored_delay(postgres_url) == 2.0
        # another process opening the store now judges a/1 as this one does
        with slr_sql.open(postgres_url, clock=clock) as again:
            assert again.complete_until("a/1") == kb.complete_until("a/1") == 98.0


def test_the_write_tried_again_does_not_hold_up_an_add_that_learned_nothing(postgres_url):
    # while the lock stays, an add that learns nothing new tries the unwritten delay again
    # without waiting for the lock: it returns at once (here the session waits 30 s for a
    # lock otherwise); the delay is written once the lock is gone
    clock = ManualClock(100.0)
    with slr_sql.open(postgres_url, clock=clock, busy_timeout=0.3) as kb:
        kb.add_many(["a(1)^99.5"])
        with psycopg.connect(postgres_url) as other:
            other.execute("SET search_path = slr")
            other.execute("LOCK TABLE slr_meta IN SHARE MODE")
            assert kb.add_many(["a(2)^98"]) == []        # learns 2 s: its write fails busy
            kb.store.execute("SET lock_timeout = 30000")   # (the session: not kb.sql's to set)
            done = threading.Event()

            def add():
                kb.add_many(["a(3)^100"])                # (a delay of 0: nothing learned)
                done.set()
            threading.Thread(target=add, daemon=True).start()
            assert done.wait(10), "an add waited for the lock to write an older delay"
            assert _stored_delay(postgres_url) == 0.5
            other.rollback()
        assert kb.add_many(["a(4)^100"]) == []
        assert _stored_delay(postgres_url) == 2.0
        assert kb.store.count("a", 1) == 4
