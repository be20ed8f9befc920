"""A read-only kb.sql on PostgreSQL runs on a connection of its own (DetachedStatements in
slr_sql/store/postgres.py): a statement the server does not stop at its timeout (LIKE over
long values runs to its end first) neither holds the store for writers nor its caller past
the timeout, and only a few may be left running at once."""
from __future__ import annotations

import threading
import time

import psycopg
import pytest

import slr_sql
from slr_sql import SLRTimeout, SLRUnavailable
from slr_sql.store import postgres as pg_backend

# LIKE over a long text checks statement_timeout only when it ends. Its length is chosen
# (long_like) for 1.5-2 s of this server's CPU: well past the tests' timeout of 0.2 s and the
# caller's grace of 0.5 s, so still running when the caller is back, and short enough to wait
# out. (Fixed at 500,000 characters it took 0.46 s on a faster machine, which ended it --
# stopped at its timeout -- within the grace, and the tests failed.)
LIKE = "SELECT repeat('0', {n}) LIKE ('%' || repeat('0', 1000) || '1') AS tag_{tag}"


def _running(admin_url: str, tag: str) -> bool:
    with psycopg.connect(admin_url, autocommit=True) as conn:
        return bool(conn.execute(
            "SELECT count(*) FROM pg_stat_activity WHERE state = 'active' AND query LIKE %s",
            (f"%AS tag_{tag}%",)).fetchone()[0])


def _wait_until_done(admin_url: str, tag: str, seconds: float = 120.0) -> None:
    """Leave the server idle for the tests after this one (a deadline, polling its state)."""
    deadline = time.monotonic() + seconds
    while _running(admin_url, tag):
        assert time.monotonic() < deadline, "the long statement never ended"
        time.sleep(0.05)


@pytest.fixture(scope="module")
def long_like(postgres_server) -> str:
    """LIKE with a text long enough for about 1.5 s of the server's CPU ({tag} to fill)."""
    n = 500_000
    with psycopg.connect(postgres_server[1], autocommit=True) as conn:
        began = time.monotonic()
        conn.execute(LIKE.format(n=n, tag="calibrate"))
        took = time.monotonic() - began
    n = min(int(n * 1.5 / max(took, 0.05)), 20_000_000)
    return LIKE.replace("{n}", str(n))


@pytest.fixture
def kb(postgres_url):
    with slr_sql.open(postgres_url, clock=slr_sql.ManualClock(10.0)) as store:
        yield store


def test_a_statement_the_server_does_not_stop_leaves_the_store_and_its_caller_free(
        kb, postgres_server, long_like):
    admin = postgres_server[1]
    with pytest.raises(SLRTimeout, match="left to finish on its own connection"):
        kb.sql(long_like.format(tag="a"), timeout=0.2)
    # the caller is back while the server still runs it...
    assert _running(admin, "a")
    # ...and the store's own connection serves writers and readers meanwhile
    kb.add("seg(cup1)^1")
    assert kb.query("seg(X)^T") == [{"X": "cup1", "T": 1.0}]
    assert kb.sql("SELECT arg1 FROM seg")[1] == [("cup1",)]
    _wait_until_done(admin, "a")
    assert kb.sql("SELECT 1 AS one", timeout=5)[1] == [(1,)]


def test_only_a_few_abandoned_statements_may_run_at_once(kb, postgres_server, monkeypatch,
                                                         long_like):
    admin = postgres_server[1]
    monkeypatch.setattr(pg_backend, "MOST_ABANDONED", 1)
    with pytest.raises(SLRTimeout):
        kb.sql(long_like.format(tag="b"), timeout=0.2)
    with pytest.raises(SLRUnavailable, match="still run on the server past their timeouts"):
        kb.sql("SELECT 1 AS one")
    kb.add("seg(cup1)^1")       # writers are not held up
    _wait_until_done(admin, "b")
    # the abandoned statement's thread gave its slot back when the server answered
    deadline = time.monotonic() + 30
    while True:
        try:
            assert kb.sql("SELECT count(*) FROM seg")[1] == [(1,)]
            break
        except SLRUnavailable:
            assert time.monotonic() < deadline
            time.sleep(0.05)


def test_inside_a_transaction_a_statement_sees_the_transactions_own_writes(kb):
    kb.add("seg(cup1)^1")
    with kb.store.transaction():
        kb.store.execute("DELETE FROM seg")
        assert kb.sql("SELECT count(*) FROM seg")[1] == [(0,)]
    assert kb.sql("SELECT count(*) FROM seg")[1] == [(0,)]


def test_read_only_statements_in_many_threads_answer_alike(kb):
    kb.add_many([("seg", [f"cup{i}"], float(i), float(i)) for i in range(50)])
    answers: list = []

    def read() -> None:
        for _ in range(10):
            answers.append(kb.sql("SELECT count(*) FROM seg WHERE arg1 LIKE 'cup%'",
                                  timeout=10)[1])

    threads = [threading.Thread(target=read) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert answers == [[(50,)]] * 40


def test_a_write_through_read_only_sql_is_still_refused(kb):
    with pytest.raises(slr_sql.SLRError, match="read-only"):
        kb.sql("DELETE FROM slr_meta")


def test_a_statement_that_finds_every_connection_busy_is_slr_busy_not_a_timeout(
        kb, postgres_server, postgres_url):
    """Every connection of read-only SQL runs a statement (here each waits for a lock another
    session holds): one more waits its timeout for a connection and did not start, a
    condition that passes (SLRBusy: the service answers 503 with Retry-After), not the
    SLRTimeout of a statement that ran too long."""
    kb.add("seen(cup1)^1")
    with psycopg.connect(postgres_url) as holder:
        holder.execute("LOCK TABLE slr.slr_meta IN ACCESS EXCLUSIVE MODE")   # (every store's)
        answers: list = []
        waiting = [threading.Thread(target=lambda: answers.append(
            kb.sql("SELECT count(*) AS tag_locked FROM slr.slr_meta", timeout=120)))
            for _ in range(pg_backend.MOST_RUNNING)]
        for t in waiting:
            t.start()
        deadline = time.monotonic() + 60
        while not _count_waiting_for_lock(postgres_server[1]) == pg_backend.MOST_RUNNING:
            assert time.monotonic() < deadline, "the statements never waited for the lock"
            time.sleep(0.02)   # polling the server's sessions; the deadline bounds the wait
        with pytest.raises(slr_sql.SLRBusy) as caught:
            kb.sql("SELECT 1", timeout=0.3)
        assert "did not start" in str(caught.value) and "try again" in str(caught.value)
        holder.rollback()                            # (the lock goes: they all answer)
    for t in waiting:
        t.join(60)
    assert len(answers) == pg_backend.MOST_RUNNING
    assert kb.sql("SELECT 1 AS one", timeout=60)[1] == [(1,)]


def _count_waiting_for_lock(admin_url: str) -> int:
    with psycopg.connect(admin_url, autocommit=True) as conn:
        return conn.execute(
            "SELECT count(*) FROM pg_stat_activity WHERE wait_event_type = 'Lock' "
            "AND query LIKE %s", ("%AS tag_locked%",)).fetchone()[0]


def test_a_statement_still_connecting_when_the_store_closes_is_never_sent(
        postgres_url, postgres_server):
    """A statement whose thread still connects when the store closes (its stop): the caller
    has the close's error at once, and once connected the thread sends nothing -- no cancel
    could reach a connection it did not have yet, so the statement ran anyway (and the
    close's cancels went on at it). Its connection is held in a login event trigger that
    waits for an advisory lock the test holds; the statement calls a function whose calls
    the server counts."""
    from psycopg import sql

    from slr_sql.errors import CLOSED_WHILE_RUNNING

    kb = slr_sql.open(postgres_url, clock=slr_sql.ManualClock(10.0))
    # (connected before the trigger exists: the trigger holds only the connections after)
    holder = psycopg.connect(postgres_url, autocommit=True)
    try:
        holder.execute("SELECT pg_advisory_lock(4711)")
        holder.execute("CREATE FUNCTION public.slr_test_probe() RETURNS int LANGUAGE plpgsql "
                       "AS $$ BEGIN RETURN 1; END $$")
        holder.execute("CREATE FUNCTION public.slr_test_held_login() RETURNS event_trigger "
                       "LANGUAGE plpgsql AS $$ BEGIN PERFORM pg_advisory_xact_lock_shared(4711);"
                       " END $$")
        database = holder.execute("SELECT current_database()").fetchone()[0]
        holder.execute(sql.SQL("ALTER DATABASE {} SET track_functions = 'all'").format(
            sql.Identifier(database)))
        holder.execute("CREATE EVENT TRIGGER slr_test_held_login ON login "
                       "EXECUTE FUNCTION public.slr_test_held_login()")
        outcome: dict = {}

        def ask() -> None:
            try:
                outcome["answer"] = kb.sql("SELECT public.slr_test_probe() AS probe")
            except BaseException as exc:   # (asserted below)
                outcome["error"] = exc
        asking = threading.Thread(target=ask)
        asking.start()
        with psycopg.connect(postgres_server[1], autocommit=True) as watcher:
            deadline = time.monotonic() + 60
            while not (held := watcher.execute(
                    "SELECT pid FROM pg_locks WHERE locktype = 'advisory' AND objid = 4711 "
                    "AND NOT granted").fetchall()):
                assert asking.is_alive(), outcome
                assert time.monotonic() < deadline, "the statement's connection never waited"
                asking.join(0.02)   # (polling the server's sessions: the deadline bounds it)
            ((connecting,),) = held
            kb.close()                                   # its thread still connects
            asking.join(60)
            assert not asking.is_alive()
            error = outcome.get("error")
            assert type(error) is slr_sql.SLRError and str(error) == CLOSED_WHILE_RUNNING, outcome
            holder.execute("SELECT pg_advisory_unlock(4711)")   # it connects now
            while watcher.execute("SELECT count(*) FROM pg_stat_activity WHERE pid = %s",
                                  (connecting,)).fetchone()[0]:
                assert time.monotonic() < deadline, "the statement's session never ended"
                threading.Event().wait(0.02)   # (a pause between two looks, as above)
        # (a session's counts reach the server's statistics before it leaves pg_stat_activity)
        calls = holder.execute("SELECT coalesce(sum(calls), 0) FROM pg_stat_user_functions "
                               "WHERE funcname = 'slr_test_probe'").fetchone()[0]
        assert calls == 0, "the statement was sent after the store had closed"
    finally:
        holder.execute("DROP EVENT TRIGGER IF EXISTS slr_test_held_login")
        holder.close()
        kb.close()
