"""PostgreSQL: a server error is classified by what happened, not by psycopg's exception class.

psycopg reports many plain refusals of a statement as ``OperationalError`` (SQLSTATE classes
08, 27, 28, 2F, 38, 39, 3B, 40, 53-58, F0, HV): an invalid savepoint name, a function without
RETURN, too many arguments. Only a connection the server ended is ``SLRServerUnreachable``
(retryable, 503); a lock or serialization conflict, or an object another session uses, is
``SLRBusy``; a lack of resources
(class 53) is ``SLRUnavailable``; the call's own ``timeout=`` is ``SLRTimeout``; anything else
is a plain, non-retryable ``SLRError`` with the server's words, and the store goes on.
"""
from __future__ import annotations

import inspect
import queue
import subprocess
import sys
import threading
import time

import psycopg
import psycopg.errors
import pytest

import slr_sql
from slr_sql import ManualClock
from slr_sql.errors import SLRBusy, SLRError, SLRServerUnreachable, SLRTimeout, SLRUnavailable
from slr_sql.store.postgres import PgReadConnection, PgStatementError, _error

from conftest import drop_postgres_database, postgres_database
from service_helpers import HTTP

DEADLINE = 30.0   # seconds a wait for the other session may take before the test fails


@pytest.fixture(scope="module")
def shared_url(postgres_server):
    """One database for the module's many short cases (each leaves the store as it was)."""
    url = postgres_database(postgres_server[1])
    yield url
    drop_postgres_database(postgres_server[1], url)


@pytest.fixture(scope="module")
def kb(shared_url):
    with slr_sql.open(shared_url, clock=ManualClock(0.0), busy_timeout=0.2) as kb:
        kb.add("p(1)^1")
        yield kb


def _other(url: str) -> psycopg.Connection:
    conn = psycopg.connect(url, autocommit=True)
    conn.execute("SET search_path = slr")
    return conn


def _still_works(kb) -> None:
    """The store took the failure in its stride: a write and a read go through."""
    kb.sql("SELECT 1", write=True)
    assert kb.sql("SELECT count(*) FROM p")[1][0][0] >= 1
    assert {"X": 1} in kb.query("p(X)^_")


def _non_retryable(exc: BaseException) -> bool:
    return type(exc) is SLRError


# Statements that make the server refuse them with an SQLSTATE psycopg maps to
# OperationalError, though the connection is fine: (SQLSTATE, set-up statements, statement,
# words of the server's message).
# (3B001, a RELEASE or ROLLBACK TO of no savepoint, no longer reaches the server: the store
# refuses a hand-written transaction-control statement itself, as a plain SLRError:
# tests/test_sql_transaction_control.py; nor a SET, tests/test_postgres_write_sql_settings.py)
REFUSED = [
    ("55000", ["CREATE SEQUENCE IF NOT EXISTS probe_seq"], "SELECT currval('probe_seq')",
     "currval"),
    ("55P02", [], "SELECT set_config('shared_buffers', '1MB', false)", "shared_buffers"),
    ("54011", [], "CREATE TEMP TABLE wide (" + ", ".join(f"c{i} int" for i in range(1601)) + ")",
     "1600"),
    ("54023", [], "SELECT concat(" + ", ".join(["1"] * 101) + ")", "100 arguments"),
    ("2F005", ["CREATE OR REPLACE FUNCTION no_return() RETURNS int LANGUAGE plpgsql "
               "AS $$ BEGIN END $$"], "SELECT no_return()", "RETURN"),
    ("58P01", [], "SELECT pg_read_file('no_such_file_here')", "no_such_file_here"),
    # 55006 of this very session (a table its own open query reads): no other session to
    # wait for, the same call meets it again
    ("55006", [], "DO $$ DECLARE r record; BEGIN FOR r IN SELECT seq FROM p LOOP "
                  "ALTER TABLE p ADD COLUMN probe int; END LOOP; END $$", "in this session"),
]


@pytest.mark.parametrize("state, setup, statement, says", REFUSED,
                         ids=[f"{r[0]}-{r[2][:24]}" for r in REFUSED])
def test_a_refused_statement_is_a_plain_error_and_the_store_goes_on(kb, state, setup,
                                                                      statement, says):
    for text in setup:
        kb.sql(text, write=True)
    with pytest.raises(SLRError) as caught:
        kb.sql(statement, write=True)
    assert _non_retryable(caught.value), repr(caught.value)
    assert says in str(caught.value)
    _still_works(kb)


# Every SQLSTATE psycopg maps to OperationalError, raised by the server (a DO block) on a
# connection that stays up: what the call raises.
OPERATIONAL = sorted(c.sqlstate for c in vars(psycopg.errors).values()
                     if inspect.isclass(c) and issubclass(c, psycopg.OperationalError)
                     and getattr(c, "sqlstate", None))


def _expected(state: str) -> type:
    if state in ("40001", "40P01", "55P03", "55006"):
        return SLRBusy
    if state == "57014":
        return slr_sql.SLRCancelled
    if state.startswith("53"):
        return SLRUnavailable
    return SLRError


def test_the_survey_covers_the_classes_psycopg_maps_to_operational_error():
    assert {s[:2] for s in OPERATIONAL} >= {"08", "27", "28", "2F", "38", "39", "3B", "40",
                                            "53", "54", "55", "57", "58", "F0", "HV"}


@pytest.mark.parametrize("state", OPERATIONAL)
def test_every_operational_sqlstate_on_a_live_connection(kb, state):
    with pytest.raises(SLRError) as caught:
        kb.sql(f"DO $$ BEGIN RAISE EXCEPTION 'probe {state}' USING ERRCODE = '{state}'; "
               f"END $$", write=True)
    assert type(caught.value) is _expected(state), (state, repr(caught.value))
    assert not isinstance(caught.value, SLRServerUnreachable)
    assert f"probe {state}" in str(caught.value)
    _still_works(kb)


def test_a_refused_read_only_statement_is_a_plain_error(kb):
    """The read-only path (its own connection, kept for the next statement)."""
    with pytest.raises(SLRError) as caught:
        kb.sql("SELECT concat(" + ", ".join(["1"] * 101) + ")")
    assert _non_retryable(caught.value), repr(caught.value)
    assert kb.sql("SELECT 41 + 1")[1] == [(42,)]
    _still_works(kb)


# ------------------------------------------------------------------ the real conditions

def test_a_lock_held_by_another_session_is_busy_for_sql_add_and_query(kb, shared_url):
    with _other(shared_url) as other:
        other.execute("BEGIN")
        other.execute("LOCK TABLE p IN ACCESS EXCLUSIVE MODE")
        try:
            with pytest.raises(SLRBusy):           # 55P03 at once
                kb.sql("LOCK TABLE p IN ACCESS EXCLUSIVE MODE NOWAIT", write=True)
            with pytest.raises(SLRBusy):           # 55P03 after lock_timeout
                kb.sql("UPDATE p SET robot = NULL WHERE false OR seq = 0", write=True)
            with pytest.raises(SLRBusy):
                kb.add("p(3)^3")
            with pytest.raises(SLRBusy):             # reads wait for the lock too
                kb.query("p(X)^_", timeout=20)
            with pytest.raises(SLRBusy):
                kb.sql("LOCK TABLE p IN SHARE MODE", write=True)
        finally:
            other.execute("ROLLBACK")
    assert {"X": 3} not in kb.query("p(X)^_")
    _still_works(kb)


def test_an_object_another_session_uses_is_busy_until_it_lets_go(kb, postgres_server):
    """55006 (object_in_use): here a database another session is connected to, which
    cannot be renamed meanwhile. A condition that passes when the other session goes: the
    same call, retried then, succeeds."""
    scratch = postgres_database(postgres_server[1])
    name = psycopg.conninfo.conninfo_to_dict(scratch)["dbname"]
    rename = f'ALTER DATABASE "{name}" RENAME TO "{name}_moved"'
    try:
        with psycopg.connect(scratch, autocommit=True):
            with pytest.raises(SLRBusy) as caught:
                kb.sql(rename, write=True)
            assert "in use by another session; retry" in str(caught.value)
            assert "being accessed by other users" in str(caught.value)
            _still_works(kb)
        kb.sql(rename, write=True)
        moved = kb.sql("SELECT datname FROM pg_database WHERE datname LIKE ?",
                       [name + "%"])[1]
        assert moved == [(name + "_moved",)]
    finally:
        with psycopg.connect(postgres_server[1], autocommit=True) as admin:
            for db in (name, name + "_moved"):
                admin.execute(f'DROP DATABASE IF EXISTS "{db}" WITH (FORCE)')


def test_a_deadlock_the_server_breaks_is_busy(kb, shared_url):
    """A real deadlock (40P01): the store's statement holds lock B and waits for A, held by
    another session that waits for B. The store's session checks for deadlocks first (its
    deadlock_timeout is 10 ms, the other's the default second), so its statement is the
    one the server gives up."""
    got_b = "SELECT count(*) FROM pg_locks WHERE locktype = 'advisory' AND classid = 4242 " \
            "AND objid = 2 AND objsubid = 2 AND granted"
    with _other(shared_url) as other, _other(shared_url) as watcher:
        other.execute("BEGIN")
        other.execute("SELECT pg_advisory_xact_lock(4242, 1)")
        waited: list[BaseException] = []

        def take_b_when_held() -> None:
            deadline = time.monotonic() + DEADLINE
            while not watcher.execute(got_b).fetchone()[0]:
                if time.monotonic() > deadline:   # (failed by the assertion below)
                    waited.append(AssertionError("the store's session never held lock B"))
                    return
                time.sleep(0.005)
            try:
                other.execute("SELECT pg_advisory_xact_lock(4242, 2)")
            except psycopg.Error as exc:   # (the test asserts it did not happen)
                waited.append(exc)
        thread = threading.Thread(target=take_b_when_held)
        thread.start()
        try:
            with pytest.raises(SLRBusy) as caught:
                kb.sql(f"""DO $$ DECLARE deadline timestamptz := clock_timestamp()
                                                  + interval '{DEADLINE} seconds';
                BEGIN
                  PERFORM set_config('deadlock_timeout', '10ms', true);
                  PERFORM pg_advisory_xact_lock(4242, 2);
                  WHILE NOT EXISTS (SELECT 1 FROM pg_locks WHERE locktype = 'advisory'
                                    AND classid = 4242 AND objid = 2 AND objsubid = 2
                                    AND NOT granted) LOOP
                    IF clock_timestamp() > deadline THEN RAISE 'the other never waited'; END IF;
                    PERFORM pg_sleep(0.005);
                  END LOOP;
                  PERFORM pg_advisory_xact_lock(4242, 1);
                END $$""", write=True)
            assert "waited for each other" in str(caught.value)
        finally:
            thread.join(DEADLINE)
            other.execute("ROLLBACK")
        assert not waited
    _still_works(kb)


def test_a_statement_past_a_configured_limit_is_unavailable(kb):
    """Class 53 (here 53400: a sort's temporary file past ``temp_file_limit``): the
    server's resources or limits, a condition that may pass."""
    with pytest.raises(SLRUnavailable) as caught:
        kb.sql("""DO $$ BEGIN
                 PERFORM set_config('work_mem', '64kB', true);
                 PERFORM set_config('temp_file_limit', '64kB', true);
                 PERFORM count(*) FROM (SELECT md5(g::text) FROM generate_series(1, 100000) g
                                        ORDER BY 1 OFFSET 0) s;
               END $$""", write=True)
    assert type(caught.value) is SLRUnavailable and "temp_file_limit" in str(caught.value)
    _still_works(kb)


def test_a_trigger_of_another_tool_that_fails_makes_add_a_plain_error(postgres_url):
    """A trigger another tool put on an event table ends without RETURN (2F005): the add
    is refused with the server's words, not a lost server to retry forever."""
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as kb:
        kb.add("p(1)^1")
        with _other(postgres_url) as other:
            other.execute("CREATE FUNCTION no_return() RETURNS trigger LANGUAGE plpgsql "
                          "AS $$ BEGIN IF NEW.arg1 = '2' THEN NULL; END IF; END $$")
            other.execute("CREATE TRIGGER probe BEFORE INSERT ON p FOR EACH ROW "
                          "EXECUTE FUNCTION no_return()")
        with pytest.raises(SLRError) as caught:
            kb.add("p(2)^2")
        assert _non_retryable(caught.value), repr(caught.value)
        assert "RETURN" in str(caught.value)
        with _other(postgres_url) as other:
            other.execute("DROP TRIGGER probe ON p")
        kb.add("p(3)^3")
        assert [a["X"] for a in kb.query("p(X)^_")] == [1, 3]


def test_the_calls_own_statement_timeout_is_a_timeout(kb):
    with pytest.raises(SLRTimeout):
        kb.sql("SELECT pg_sleep(5)", write=True, timeout=0.05)
    with pytest.raises(SLRTimeout):
        kb.sql("SELECT pg_sleep(5)", timeout=0.05)
    _still_works(kb)


def test_a_connection_the_server_ends_is_unreachable_then_works_again(postgres_url):
    """57P01 (administrator's termination): the connection is gone, the call may be
    retried, and the next call opens a new one."""
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as kb:
        kb.add("p(1)^1")
        pid = kb.sql("SELECT pg_backend_pid()", write=True)[1][0][0]
        with _other(postgres_url) as admin:
            admin.execute("SELECT pg_terminate_backend(%s, 10000)", (pid,))
        with pytest.raises(SLRServerUnreachable):
            kb.sql("SELECT 1", write=True)
        _still_works(kb)


def test_a_reading_connection_the_server_does_not_take_is_unreachable(postgres_server,
                                                                     postgres_url):
    """The subscription hub's reads open a connection of their own: one the server does not
    take (the database closed to new connections) or that nobody answers (a port nobody
    listens on) is SLRServerUnreachable, as the store's own connection opened again is."""
    name = psycopg.conninfo.conninfo_to_dict(postgres_url)["dbname"]
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as kb, \
            psycopg.connect(postgres_server[1], autocommit=True) as admin:
        admin.execute(f'ALTER DATABASE "{name}" ALLOW_CONNECTIONS false')
        try:
            with pytest.raises(SLRServerUnreachable, match="cannot open a reading connection: "
                                                           "the server is not reachable"):
                kb.store.journal_reader(own_connection=True)
        finally:
            admin.execute(f'ALTER DATABASE "{name}" ALLOW_CONNECTIONS true')
        kb.store.journal_reader(own_connection=True).close()   # taken again
    with pytest.raises(SLRServerUnreachable, match="cannot open a reading connection"):
        PgReadConnection("postgresql://nobody@127.0.0.1:1/none?connect_timeout=2", "slr",
                         "127.0.0.1:1", 1.0)


# ------------------------------------------------------------------ the service

def test_the_service_answers_a_refused_statement_with_400_not_503(postgres_url):
    from service_helpers import ROOT, slr_env
    proc = subprocess.Popen([sys.executable, "-m", "slr_sql", "serve", postgres_url, "--port",
                             "0"], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                            stdin=subprocess.DEVNULL, env=slr_env(), cwd=ROOT)
    try:
        lines: queue.Queue = queue.Queue()
        threading.Thread(target=lambda: lines.put(proc.stdout.readline()), daemon=True).start()
        first = lines.get(timeout=60).decode()
        assert " on http" in first, first
        url = first.strip().rsplit(" on ", 1)[1]
        refused = HTTP.post(url + "/sql", json={
            "query": "SELECT concat(" + ", ".join(["1"] * 101) + ")", "params": []},
            timeout=30)
        assert refused.status_code == 400, refused.text
        assert "retry-after" not in refused.headers
        assert refused.json()["error"]["kind"] == "SLRError"   # as kb.sql raises locally
        assert "100 arguments" in refused.json()["error"]["message"]
        assert HTTP.post(url + "/sql", json={"query": "SELECT 1", "params": []},
                         timeout=30).status_code == 200
    finally:
        proc.terminate()
        proc.wait(timeout=30)
        proc.stdout.close()


# ------------------------------------------------------------------ when the connection is not known

@pytest.mark.parametrize("error, connected, kind", [
    (psycopg.errors.AdminShutdown("terminating connection"), None, SLRServerUnreachable),
    (psycopg.errors.ConnectionFailure("connection failure"), None, SLRServerUnreachable),
    (psycopg.OperationalError("server closed the connection unexpectedly"), None,
     SLRServerUnreachable),
    (psycopg.errors.InvalidSavepointSpecification("savepoint x does not exist"), None,
     PgStatementError),
    (psycopg.errors.InvalidPassword("password authentication failed"), False, SLRError),
    (psycopg.errors.CannotConnectNow("the database system is starting up"), False,
     SLRServerUnreachable),
    (psycopg.errors.TooManyConnections("too many clients already"), False, SLRUnavailable),
    (psycopg.errors.UndefinedTable("relation x does not exist"), False, SLRServerUnreachable),
    # (FATAL: the server ends the session; psycopg's class is InternalError)
    (psycopg.errors.IdleInTransactionSessionTimeout("terminating connection due to "
                                                    "idle-in-transaction timeout"), False,
     SLRServerUnreachable),
    (psycopg.errors.ProgrammingError("the query has 1 placeholder but 2 parameters were "
                                     "passed"), None, PgStatementError),
])
def test_what_an_error_is_when_the_connection_is_or_is_not_known(error, connected, kind):
    """A connect that fails for good (a wrong password) is no server to wait for; one whose
    server is starting, or short of connections, may pass; an error with the server's
    SQLSTATE (not one it ends a session with) came from a live connection."""
    assert type(_error(error, "postgresql://db", 5.0, connected)) is kind
