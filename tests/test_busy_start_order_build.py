"""A start-order build that meets another session's lock (PostgreSQL: its 1 ms
``lock_timeout`` runs out) rolls back only itself: the store's rollback listeners are not
called (the types keep what they knew, the event rules do not read their pending summaries
again), and while the table is busy the build is not tried again at every lookup, only once
the store's clock has moved on by ``START_ORDER_RETRY`` seconds, or ``START_ORDER_RETRY_LOOKUPS``
lookups skipped it (a clock that never moves still gets the build)."""
from __future__ import annotations

import slr_sql
from libpq_trace import traced_messages
from slr_sql import ManualClock
from slr_sql.store.tables import START_ORDER_RETRY, START_ORDER_RETRY_LOOKUPS
from store_holders import table_written

RULE = ":- consumption(unrestricted).\n:- max_delay(a/1, 0).\n:- max_delay(b/1, 0).\n" \
       "c(X) <- a(X) seq b(X).\n"
# the decisions stay pending until e/1 is marked complete
PROGRAM = ":- consumption(unrestricted).\n:- max_delay(a/1, 0).\n:- max_delay(b/1, 0).\n" \
          ":- max_delay(e/1, 100).\n" \
          "c(X) <- a(X) seq b(X) cnot e(X).\n"
EVENTS = ["a(1)^1", "b(1)^2", "a(1)^3", "b(1)^4", "a(2)^5", "b(2)^6"]


def _sent(messages: list[list[str]], text: str) -> int:
    """How many statements the client sent that contain ``text``."""
    return sum(1 for m in messages if m[0] == "F" and m[2] in ("Query", "Parse")
               and text in "\t".join(m[3:]))


def test_a_busy_build_calls_no_rollback_listener_and_waits_for_the_clock(postgres_url):
    with slr_sql.open(postgres_url, clock=ManualClock(10.0), busy_timeout=30) as kb:
        kb.load(RULE)
        kb.add_many(EVENTS)
        expected = sorted(row[:3] for row in kb.store.scan("c", 1))
        heard: list = []
        kb.store.rollback_listeners.append(lambda: heard.append("rolled back"))
        other = table_written(postgres_url)
        try:
            def lookups_and_clock_moves():
                for _ in range(4):
                    rows = kb.store.next_candidates("c", 1, None, 0, 100)
                    assert sorted(row[:3] for row in rows) == expected
                    # a clock move: the event rules look whether a decision is due, reading
                    # their pending summaries again only if something asked them to
                    kb.clock.advance(START_ORDER_RETRY / 10)
            messages = traced_messages(kb, lookups_and_clock_moves)
            # one try of the build (the clock moved less than START_ORDER_RETRY since)
            assert _sent(messages, "CREATE INDEX IF NOT EXISTS") == 1
            assert heard == []
            assert _sent(messages, "FROM slr_cep_pending WHERE rule") == 0
            assert not kb.store.ensure_start_order("c", 1)
            # the clock moved on: the next lookup tries again (still busy: still quiet)
            kb.clock.advance(2 * START_ORDER_RETRY)
            messages = traced_messages(kb, lambda: list(
                kb.store.next_candidates("c", 1, None, 0, 100)))
            assert _sent(messages, "CREATE INDEX IF NOT EXISTS") == 1
            assert heard == []
        finally:
            other.rollback()
            other.close()
        kb.clock.advance(2 * START_ORDER_RETRY)
        assert kb.store.ensure_start_order("c", 1)
        assert {"slr_ix__c__start", "slr_ix__c__a1_start"} <= kb.store.index_names("c")
        assert heard == []


def test_a_busy_build_inside_a_transaction_leaves_the_transaction_and_rules_as_they_were(
        postgres_url):
    # inside a transaction the build is a savepoint: its failure takes back only the build;
    # what the transaction did before it stays, and commits
    with slr_sql.open(postgres_url, clock=ManualClock(10.0), busy_timeout=30) as kb:
        kb.load(PROGRAM)
        kb.add_many(EVENTS)
        assert kb.event_rules()[0]["pending"] > 0
        heard: list = []
        kb.store.rollback_listeners.append(lambda: heard.append("rolled back"))
        other = table_written(postgres_url)
        try:
            def inside():
                with kb.store.transaction():
                    kb.store.add_events([("a", (9,), 8.0, 8.0)])
                    return list(kb.store.next_candidates("c", 1, None, 0, 100))
            messages = traced_messages(kb, inside)
            assert _sent(messages, "CREATE INDEX IF NOT EXISTS") == 1
            assert heard == []
            # the next clock move does not read the summaries again: nothing was undone
            messages = traced_messages(kb, lambda: kb.clock.advance(1))
            assert _sent(messages, "FROM slr_cep_pending WHERE rule") == 0
        finally:
            other.rollback()
            other.close()
        assert kb.store.count("a", 1) == 4
        kb.mark_complete("e/1", 10)
        assert [r["pending"] for r in kb.event_rules()] == [0]
        assert heard == []


def _build_statements(kb, backend: str, call) -> int:
    """How many CREATE INDEX statements ``kb``'s connection ran while ``call()`` ran."""
    if backend.startswith("postgres"):
        return _sent(traced_messages(kb, call), "CREATE INDEX IF NOT EXISTS")
    statements: list[str] = []
    kb.store._db.conn.set_trace_callback(statements.append)
    try:
        call()
    finally:
        kb.store._db.conn.set_trace_callback(None)
    return sum("CREATE INDEX IF NOT EXISTS" in s for s in statements)


def test_a_clock_that_never_moves_still_gets_the_build_after_enough_lookups(backend):
    # a ManualClock that stands still: the build is tried again by the
    # START_ORDER_RETRY_LOOKUPS-th lookup after the busy one, whatever the clock says
    with slr_sql.open(backend, clock=ManualClock(10.0), busy_timeout=30) as kb:
        kb.load(RULE)
        kb.add_many(EVENTS)
        expected = sorted(row[:3] for row in kb.store.scan("c", 1))
        other = table_written(backend)
        try:
            assert sorted(row[:3] for row in kb.store.next_candidates("c", 1, None, 0, 100)) \
                == expected
        finally:
            other.rollback()
            other.close()

        def skipped_lookups():
            for _ in range(START_ORDER_RETRY_LOOKUPS - 1):
                assert not kb.store.ensure_start_order("c", 1)
        # the lookups in between do not try (the lock is free by now: they do not know)
        assert _build_statements(kb, backend, skipped_lookups) == 0
        assert _build_statements(kb, backend, lambda: kb.store.ensure_start_order("c", 1)) > 0
        assert kb.store.ensure_start_order("c", 1)
        assert {"slr_ix__c__start", "slr_ix__c__a1_start"} <= kb.store.index_names("c")
        assert sorted(row[:3] for row in kb.store.next_candidates("c", 1, None, 0, 100)) \
            == expected
