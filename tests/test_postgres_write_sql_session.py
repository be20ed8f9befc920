"""PostgreSQL: what a statement handed to ``kb.sql(..., write=True)`` leaves in the store's
own connection's session. A temporary table it made does not hide the store's table of the
same name (the store's search_path names ``pg_temp`` last: unnamed, the session's temporary
schema is searched first), and a session advisory lock it took is let go after it (refused or
failed too; in a caller's transaction it failed in, at that transaction's end), as after a
read-only statement (docs/sql.md, "What a statement may call")."""
from __future__ import annotations

import psycopg
import pytest

import slr_sql
from slr_sql.store import DatabaseError


@pytest.fixture
def kb(postgres_url):
    with slr_sql.open(postgres_url, clock=slr_sql.ManualClock(10.0)) as kb:
        kb.add("p(0)^0")
        yield kb


def events(kb) -> list:
    return sorted(a["X"] for a in kb.query("p(X)^_"))


@pytest.mark.parametrize("in_transaction", [False, True])
def test_a_temporary_table_does_not_hide_the_stores_table(kb, postgres_url, in_transaction):
    # (q: a type the store has no table of yet)
    statements = ["CREATE TEMP TABLE p (x int)", "CREATE TEMPORARY TABLE slr_event_types (x int)",
                  "CREATE TEMP TABLE q (x int)", "INSERT INTO pg_temp.p VALUES (7)"]
    if in_transaction:
        with kb.store.transaction():
            for statement in statements:
                kb.sql(statement, write=True)
            kb.add("p(1)^1")
    else:
        for statement in statements:
            kb.sql(statement, write=True)
        kb.add("p(1)^1")
    kb.add("p(2)^2")
    kb.add("q(5)^3")   # (a new type: slr_event_types is the store's)
    assert events(kb) == [0, 1, 2]
    assert [a["X"] for a in kb.query("q(X)^_")] == [5]
    # the temporary table is there all the same, named by its schema
    assert kb.sql("SELECT x FROM pg_temp.p", write=True)[1] == [(7,)]
    with slr_sql.open(postgres_url, clock=slr_sql.ManualClock(10.0)) as other:
        assert events(other) == [0, 1, 2]
        other.add("p(3)^4")
    assert events(kb) == [0, 1, 2, 3]


def lock_is_free(postgres_url, key: int = 42) -> bool:
    """Whether another session can take the session advisory lock ``key`` (and lets it go)."""
    with psycopg.connect(postgres_url, autocommit=True) as other:
        taken = other.execute("SELECT pg_try_advisory_lock(%s)", (key,)).fetchone()[0]
        if taken:
            other.execute("SELECT pg_advisory_unlock(%s)", (key,))
        return taken


def test_a_session_advisory_lock_of_a_written_statement_is_let_go(kb, postgres_url):
    kb.sql("SELECT pg_advisory_lock(42)", write=True)
    assert lock_is_free(postgres_url)
    kb.sql("SELECT pg_advisory_lock(42), pg_advisory_lock(42)", write=True, timeout=30)
    assert lock_is_free(postgres_url)
    # refused for the setting it changed, and failed
    with pytest.raises(slr_sql.SLRError, match="changed search_path of the session"):
        kb.sql("SELECT pg_advisory_lock(42), set_config('search_path', 'public', false)",
               write=True)
    assert lock_is_free(postgres_url)
    with pytest.raises(slr_sql.SLRError, match="no, after the lock"):
        kb.sql("DO $$ BEGIN PERFORM pg_advisory_lock(42); RAISE 'no, after the lock'; END $$",
               write=True)
    assert lock_is_free(postgres_url)
    assert events(kb) == [0]


def test_in_a_transaction_the_lock_is_let_go_too(kb, postgres_url):
    with kb.store.transaction():
        kb.sql("SELECT pg_advisory_lock(42)", write=True)
        assert lock_is_free(postgres_url)
        kb.add("p(1)^1")
    assert events(kb) == [0, 1]
    # a failed statement leaves the caller's transaction aborted: let go at its end
    with pytest.raises(slr_sql.SLRError, match="no, after the lock"):
        with kb.store.transaction():
            kb.add("p(2)^2")
            kb.sql("DO $$ BEGIN PERFORM pg_advisory_lock(42); RAISE 'no, after the lock'; "
                   "END $$", write=True)
    assert lock_is_free(postgres_url)
    kb.add("p(3)^3")
    assert events(kb) == [0, 1, 3]


def test_on_the_stores_own_path_too(kb, postgres_url):
    """The store's ``sql(..., write=True)`` outside a transaction (its own transaction:
    ``kb.sql`` wraps it in one of the store's)."""
    kb.store.sql("SELECT pg_advisory_lock(42)", write=True)
    assert lock_is_free(postgres_url)
    with pytest.raises(DatabaseError, match="no, after the lock"):
        kb.store.sql("DO $$ BEGIN PERFORM pg_advisory_lock(42); RAISE 'no, after the lock'; "
                     "END $$", write=True)
    assert lock_is_free(postgres_url)
    with pytest.raises(slr_sql.SLRError, match="changed search_path of the session"):
        kb.store.sql("SELECT pg_advisory_lock(42), set_config('search_path', 'public', false)",
                     write=True)
    assert lock_is_free(postgres_url)
    assert events(kb) == [0]
