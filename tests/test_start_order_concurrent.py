"""Review of the start-ordered indexes built on first need (store/tables.py): a reader in
start order while another connection writes, and the build inside a transaction."""
from __future__ import annotations

import os
import re
import threading

import psycopg

import slr_sql
from libpq_trace import traced_messages
from store_holders import table_written
from slr_sql import ManualClock

RULE = ":- consumption(unrestricted).\n:- max_delay(a/1, 0).\n:- max_delay(b/1, 0).\n" \
       "c(X) <- a(X) seq b(X).\n"
EVENTS = ["a(1)^1", "b(1)^2", "a(1)^3", "b(1)^4", "a(2)^5", "b(2)^6"]


def _opened(location: str, **options) -> slr_sql.KnowledgeBase:
    kb = slr_sql.open(location, clock=ManualClock(100.0), **options)
    kb.load(RULE)
    kb.add_many(EVENTS)
    return kb


def _within(deadline: float, call) -> tuple[bool, object]:
    """Whether ``call`` returned on another thread before ``deadline`` seconds passed (an
    event, not a pause), and what it returned."""
    done = threading.Event()
    out: list = []

    def run():
        try:
            out.append(call())
        finally:
            done.set()
    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return done.wait(deadline), (out[0] if out else None)


def test_a_reader_in_start_order_does_not_wait_for_a_writer(backend):
    # a writer holding its transaction for long (a bulk import) must not make every next
    # wait the busy timeout (30 s here) to answer: readers never waited for writers
    with _opened(backend, busy_timeout=30) as kb:
        expected = len(list(kb.store.scan("c", 1)))
        other = table_written(backend)
        try:
            answered, rows = _within(10, lambda: list(
                kb.store.next_candidates("c", 1, None, 0, 100)))
            assert answered, "a next lookup waited for another connection's write lock"
            assert rows is not None and len(rows) == expected
            answered, answers = _within(10, lambda: kb.query("next(c(X)^[S, E], [0, 10])"))
            assert answered and answers
        finally:
            other.rollback()
            other.close()
        assert kb.query("next(c(X)^[S, E], [0, 10])") == answers
        # the lock gone, the next reader once the clock moved on builds them
        kb.clock.advance(1)
        assert kb.store.ensure_start_order("c", 1)
        assert {"slr_ix__c__start", "slr_ix__c__a1_start"} <= kb.store.index_names("c")


def test_a_build_inside_a_transaction_does_not_wait_and_leaves_its_lock_wait_as_it_was(
        backend):
    # a builder inside its own transaction does not wait for another writer either (on a
    # server, a wait there could deadlock with that writer); the transaction goes on
    with _opened(backend, busy_timeout=30) as kb:
        other = table_written(backend)
        try:
            def inside():
                with kb.store.transaction():
                    rows = list(kb.store.next_candidates("c", 1, None, 0, 100))
                    kb.store.add_events([("a", (9,), 50.0, 50.0)])
                    shown = kb.sql("SHOW lock_timeout")[1][0][0] \
                        if backend.startswith("postgresql") else None
                return rows, shown
            if backend.startswith("postgresql"):
                answered, out = _within(10, inside)
                assert answered, "a build inside a transaction waited for another writer"
                rows, shown = out
                assert len(rows) == len(list(kb.store.scan("c", 1)))
                assert shown == "30s"   # (the build's 1 ms does not outlive it)
        finally:
            other.rollback()
            other.close()
        if not backend.startswith("postgresql"):
            # SQLite: the transaction itself waits for the writer, then holds the lock
            rows, _ = inside()
            assert len(rows) == len(list(kb.store.scan("c", 1)))
        assert kb.store.count("a", 1) == 4
        kb.clock.advance(1)   # (a busy build is tried again once the clock moved on)
        assert kb.store.ensure_start_order("c", 1)


ROLE = f"r11_writer_{os.getpid()}"   # (roles are the server's, not one database's)


def _non_owner(url: str) -> str:
    """The URL of a new role that may read and write the store's tables but owns none of
    them (PostgreSQL: only a table's owner may index it)."""
    database = url.split("/")[3].split("?")[0]
    with psycopg.connect(url, autocommit=True) as admin:
        admin.execute(f"CREATE ROLE {ROLE} LOGIN")
        admin.execute(f"GRANT ALL ON DATABASE {database} TO {ROLE}")
        admin.execute(f"GRANT USAGE, CREATE ON SCHEMA slr TO {ROLE}")
        admin.execute(f"GRANT SELECT, INSERT, UPDATE, DELETE ON ALL TABLES IN SCHEMA slr "
                      f"TO {ROLE}")
        admin.execute(f"GRANT USAGE, SELECT, UPDATE ON ALL SEQUENCES IN SCHEMA slr TO {ROLE}")
    return re.sub(r"://[^@]*@", f"://{ROLE}@", url)


def test_a_role_that_may_not_index_the_table_tries_once(postgres_url):
    # a build refused for good (not the table's owner; on SQLite a read-only file) is not
    # tried again by every lookup, each a failed transaction (a round trip); its rollback
    # calls no rollback listener; the owner's build is still found in the catalog
    with _opened(postgres_url) as owner:
        expected = [row[:3] for row in owner.store.scan("c", 1)]
        url = _non_owner(postgres_url)
        try:
            with slr_sql.open(url, clock=ManualClock(100.0)) as kb:
                rollbacks: list = []
                kb.store.rollback_listeners.append(lambda: rollbacks.append(1))
                def lookups():
                    for _ in range(3):
                        kb.clock.advance(1)   # (a refusal is not retried even then)
                        rows = [row[:3] for row in
                                kb.store.next_candidates("c", 1, None, 0, 100)]
                        assert sorted(rows) == sorted(expected)
                sent = [m for m in traced_messages(kb, lookups) if m[0] == "F"
                        and "CREATE INDEX IF NOT EXISTS" in "\t".join(m[3:])]
                assert len(sent) == 1       # the one refused build
                assert rollbacks == []     # (it took back only itself)
                assert not kb.store.ensure_start_order("c", 1)
                assert owner.store.ensure_start_order("c", 1)
                assert kb.store.ensure_start_order("c", 1)   # found in the catalog
                assert rollbacks == []
        finally:
            with psycopg.connect(postgres_url, autocommit=True) as admin:
                admin.execute(f"DROP OWNED BY {ROLE}")
                admin.execute(f"DROP ROLE {ROLE}")
