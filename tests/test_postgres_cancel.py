"""PostgreSQL: a statement the server cancels for another reason than a timeout (another
session's ``pg_cancel_backend``) is an SLRCancelled -- retryable, nothing of the call stored
-- and says so; one it cancels at its own ``statement_timeout`` (an administrator's) is an
SLRStatementTimeout, a timeout a retry would meet again; a call that ran out of its own
``timeout=`` is still "query timed out".
"""
from __future__ import annotations

import threading
import time

import psycopg
import pytest

import slr_sql
from slr_sql import ManualClock
from slr_sql.errors import SLRCancelled, SLRStatementTimeout, SLRTimeout, SLRUnavailable

DEADLINE = 30.0   # seconds a wait for the other session may take before the test fails

# a query compiled to one statement that runs for seconds on 300 events (300 ** 3 rows, none
# an answer)
SLOW_GOAL = "p(X)^_, p(Y)^_, p(Z)^_, X > Y, Y > Z, Z > X"


def _other(url: str) -> psycopg.Connection:
    conn = psycopg.connect(url, autocommit=True)
    conn.execute("SET search_path = slr")
    return conn


def _cancel_until_returned(admin: psycopg.Connection, pid: int,
                           thread: threading.Thread) -> None:
    """Cancel backend ``pid``'s statement once it has run for 100 ms, and again (a pause
    doubling from 50 ms) until ``thread``'s call has returned (deadline-bounded). The server
    shows a statement of the extended protocol active from its Parse message on, and a cancel
    that arrives while the backend waits for the client's next message (wait_event
    ClientRead) is discarded: one cancel sent on the sight of 'active' may be lost, and the
    statement run on (an administrator cancels again)."""
    deadline = time.monotonic() + DEADLINE
    running = ("SELECT count(*) FROM pg_stat_activity WHERE pid = %s AND state = 'active' "
               "AND wait_event IS DISTINCT FROM 'ClientRead' "
               "AND clock_timestamp() - query_start > interval '100 milliseconds'")
    pause = 0.05
    while thread.is_alive():
        assert time.monotonic() < deadline, f"backend {pid}'s statement was never cancelled"
        if admin.execute(running, (pid,)).fetchone()[0]:
            assert admin.execute("SELECT pg_cancel_backend(%s)", (pid,)).fetchone()[0]
            thread.join(pause)
            pause = min(pause * 2, 1.0)
        else:
            thread.join(0.01)


def _cancelled(kb, url: str, call, detached: bool = False) -> BaseException:
    """What ``call()`` raises when another session cancels its statement mid-way: a
    statement of the store's own connection, or (``detached``) a read-only ``kb.sql``, which
    runs on a connection of its own (kept idle for the next one)."""
    pid = kb.sql("SELECT pg_backend_pid()", write=not detached)[1][0][0]
    raised: list[BaseException] = []

    def run() -> None:
        try:
            call()
        except BaseException as exc:   # (the test asserts on it)
            raised.append(exc)
    thread = threading.Thread(target=run)
    thread.start()
    try:
        with _other(url) as admin:
            _cancel_until_returned(admin, pid, thread)
    finally:
        thread.join(DEADLINE)
    assert not thread.is_alive() and len(raised) == 1, raised
    return raised[0]


@pytest.mark.parametrize("timeout", [None, 60.0], ids=["no timeout", "a timeout not reached"])
def test_a_statement_another_session_cancels_is_cancelled_not_timed_out(postgres_url, timeout):
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as kb:
        error = _cancelled(kb, postgres_url,
                           lambda: kb.sql("SELECT pg_sleep(60)", timeout=timeout),
                           detached=True)
        assert type(error) is SLRCancelled and isinstance(error, SLRUnavailable)
        assert str(error).endswith(": the server cancelled the statement (canceling statement "
                                   "due to user request); nothing of the call was stored, and "
                                   "it may be retried")
        assert "timed out" not in str(error)
        assert kb.sql("SELECT 1 AS one") == (["one"], [(1,)])   # the connection goes on


def test_an_add_another_session_cancels_stores_nothing_and_may_be_retried(postgres_url):
    with slr_sql.open(postgres_url, clock=ManualClock(10.0)) as kb:
        kb.add("p(1)^1")
        with _other(postgres_url) as other:
            other.execute("CREATE FUNCTION slr_test_slow() RETURNS trigger LANGUAGE plpgsql "
                          "AS $$ BEGIN PERFORM pg_sleep(60); RETURN NEW; END $$")
            other.execute("CREATE TRIGGER slow BEFORE INSERT ON p "
                          "FOR EACH ROW EXECUTE FUNCTION slr_test_slow()")
            error = _cancelled(kb, postgres_url, lambda: kb.add_many(["p(2)^2", "p(3)^3"]))
            assert type(error) is SLRCancelled, error
            assert "user request" in str(error) and "timed out" not in str(error)
            assert other.execute("SELECT count(*) FROM p").fetchone()[0] == 1
            other.execute("DROP TRIGGER slow ON p")
        kb.add_many(["p(2)^2", "p(3)^3"])   # the same call, retried
        assert [a["X"] for a in kb.query("p(X)^_")] == [1, 2, 3]


def _statement_timeout(error: BaseException) -> None:
    """``error`` is the server's statement_timeout: a timeout (408 over the service), no
    condition to retry, naming the setting and quoting the server's words."""
    assert type(error) is SLRStatementTimeout, repr(error)
    assert isinstance(error, SLRTimeout) and not isinstance(error, SLRUnavailable)
    assert ": the server cancelled the statement at its statement_timeout setting (canceling " \
           "statement due to statement timeout)" in str(error), str(error)
    assert "a retry meets it again" in str(error) and "query timed out" not in str(error)
    assert error.reason == "canceling statement due to statement timeout"


def test_the_statement_timeout_of_an_administrator_is_not_the_calls_timeout(postgres_url):
    """The database's statement_timeout cancels the statement: a retry would run as long
    and meet it again, so the call fails with SLRStatementTimeout (not the retryable
    SLRCancelled), on every path -- a read-only and a writing kb.sql, a compiled query, an
    add -- and a call's own timeout= replaces it for that call."""
    with _other(postgres_url) as admin:
        database = admin.execute("SELECT current_database()").fetchone()[0]
        admin.execute(f'ALTER DATABASE "{database}" SET statement_timeout = 200')
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as kb:
        for write in (False, True):
            with pytest.raises(SLRStatementTimeout) as caught:
                kb.sql("SELECT pg_sleep(5)", write=write)
            _statement_timeout(caught.value)
        kb.add_many([f"p({i})^{i}" for i in range(300)])
        with pytest.raises(SLRStatementTimeout) as caught:
            kb.query(SLOW_GOAL)
        _statement_timeout(caught.value)
        # the call's own timeout= (longer than the administrator's) is the statement's
        slept = "SELECT 1 AS slept FROM pg_sleep(0.4)"
        assert kb.sql(slept, timeout=30) == (["slept"], [(1,)])
        assert kb.sql(slept, write=True, timeout=30) == (["slept"], [(1,)])
        with _other(postgres_url) as other:
            other.execute("CREATE FUNCTION slr_test_slow() RETURNS trigger LANGUAGE plpgsql "
                          "AS $$ BEGIN PERFORM pg_sleep(5); RETURN NEW; END $$")
            other.execute("CREATE TRIGGER slow BEFORE INSERT ON p "
                          "FOR EACH ROW EXECUTE FUNCTION slr_test_slow()")
            with pytest.raises(SLRStatementTimeout) as caught:
                kb.add("p(1000)^1000")
            _statement_timeout(caught.value)
            assert other.execute("SELECT count(*) FROM p").fetchone()[0] == 300
            other.execute("DROP TRIGGER slow ON p")
        kb.add("p(1000)^1000")
        assert kb.query("p(X)^_, X > 299") == [{"X": 1000}]


def test_the_server_statement_timeout_crosses_the_service_as_itself():
    from slr_sql.service.errors import error_body, error_from_body, retry_after
    error = SLRStatementTimeout("postgresql://db: the server cancelled the statement at its "
                                "statement_timeout setting")
    body = error_body(error)
    assert body["error"]["kind"] == "SLRStatementTimeout"
    assert body["error"]["status"] == 408 and retry_after(error) is None
    again = error_from_body(body, 408)
    assert type(again) is SLRStatementTimeout and str(again) == str(error)


def test_a_compiled_query_another_session_cancels_is_cancelled(postgres_url):
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as kb:
        kb.add_many([f"p({i})^{i}" for i in range(300)])
        for timeout in (None, 60.0):
            error = _cancelled(kb, postgres_url, lambda: kb.query(SLOW_GOAL, timeout=timeout))
            assert type(error) is SLRCancelled, error
            assert "user request" in str(error) and "timed out" not in str(error)
        assert kb.query("p(X)^_, X > 298") == [{"X": 299}]


def test_the_calls_own_timeout_still_reads_timed_out(postgres_url):
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as kb:
        with pytest.raises(SLRTimeout, match=r"^query timed out \(canceling statement due "
                           r"to statement timeout\)$"):
            kb.sql("SELECT pg_sleep(5)", timeout=0.2)
        kb.add_many([f"p({i})^{i}" for i in range(300)])
        with pytest.raises(SLRTimeout, match=r"^query timed out \(canceling statement due "
                           r"to statement timeout\)$"):
            kb.query(SLOW_GOAL, timeout=0.2)
