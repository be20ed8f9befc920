"""A store with event rules LISTENs to channel ``slr_pending`` (other sessions' pending rows,
migration pg_0011). The server keeps each notification in its queue until every listener
has read it, and a listening session sends what it reads to its client's socket: a store
whose process makes no call while others keep writing would, once the socket's buffers
were full, hold every later notification in the queue (a full queue fails the notifying
commits). The store's connection is drained on its own while the store is idle (a daemon
thread, docs/postgres.md): the queue is freed without any call of the store, and what it
read still counts for ``others_version``."""
from __future__ import annotations

import threading
import time

import psycopg
import pytest

import slr_sql
from slr_sql import ManualClock
from slr_sql.store.postgres import PENDING_CHANNEL, split_url

BY_DELAY = ":- max_delay(a/1, 5).\n:- consumption(recent).\n:- max_delay(b/1, 0).\n" \
           "c(X) <- a(X) seq b(X).\n"
# more than the socket buffers between the server and the store hold (notifications of
# ~40 bytes: a few MB)
FLOOD = 200_000


def _queue_pages(other) -> float:
    """The pages of the server's notification queue in use (8 kB each)."""
    usage, pages = other.execute(
        "SELECT pg_notification_queue_usage(), "
        "coalesce(current_setting('max_notify_queue_pages', true)::bigint, 1048576)"
    ).fetchone()
    return usage * pages


@pytest.fixture
def other(postgres_url):
    """Another session of the database, as another process writing would be."""
    with psycopg.connect(split_url(postgres_url)[0], autocommit=True) as conn:
        yield conn


def test_an_idle_store_with_event_rules_does_not_hold_the_notification_queue(
        postgres_url, other):
    threads = _drainers()   # (other tests' stores not closed yet may have theirs)
    with slr_sql.open(postgres_url, clock=ManualClock(10.0)) as kb:
        kb.load(BY_DELAY)
        kb.add_many(["a(1)^1"])                   # its rules look: it listens from now on
        schema = split_url(postgres_url)[1]
        version = kb.store.others_version()
        other.execute(f"SELECT pg_notify('{PENDING_CHANNEL}', 'flood' || i) "
                      f"FROM generate_series(1, {FLOOD}) AS i")
        other.execute("SELECT pg_notify(%s, %s)", (PENDING_CHANNEL, schema))
        flooded = _queue_pages(other)
        assert flooded > 100                      # (the flood is in the queue)
        # the store makes no call; the server frees the queue's pages once every listener
        # read them (it looks when a notifying commit passes a few pages: a nudge of ~5)
        deadline = time.monotonic() + 30
        while (held := _queue_pages(other)) > 10 and time.monotonic() < deadline:
            other.execute(f"SELECT pg_notify('{PENDING_CHANNEL}', 'nudge' || i) "
                          f"FROM generate_series(1, 1000) AS i")
            time.sleep(0.1)   # (a deadline, not a pause: the next look comes at once)
        assert held <= 10, f"the idle store still holds {held:.0f} of {flooded:.0f} pages"
        # what it read while idle is heard: the one notification for its schema
        assert kb.store.others_version() == version + 1
        kb.clock.advance(1)                       # and it goes on as before
        assert kb.add_many(["b(1)^12"]) == []
        assert _drainers() == threads + 1
    deadline = time.monotonic() + 10              # closed: its thread ends
    while _drainers() > threads and time.monotonic() < deadline:
        time.sleep(0.01)
    assert _drainers() <= threads


def _drainers() -> int:
    return sum(t.name == "slr-pg-drain" for t in threading.enumerate())


def test_a_store_without_event_rules_starts_no_thread(postgres_url):
    threads = _drainers()
    with slr_sql.open(postgres_url, clock=ManualClock(10.0)) as kb:
        kb.add_many(["a(1)^1"])
        assert kb.query("a(X)^_") == [{"X": 1}]
        assert _drainers() <= threads
