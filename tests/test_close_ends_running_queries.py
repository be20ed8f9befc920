"""A knowledge base closed while a query evaluates in another thread (a server stopping, a
program ending) ends the query at its next check, in words, instead of letting it run to
its timeout while the closing process waits for the thread."""
from __future__ import annotations

import threading
import time

import pytest

import slr_sql


@pytest.mark.parametrize("goal", ["between(1, inf, X), X < 0", "repeat, fail",
                                  "length(L, N), N < 0"])
def test_a_query_running_when_the_knowledge_base_closes_ends_with_an_slr_error(tmp_path, goal):
    kb = slr_sql.open(tmp_path / "robot.db", clock=slr_sql.ManualClock(10.0))
    running = threading.Event()
    kb.define("running", 0, lambda: running.set() or True)
    outcome: list = []

    def ask() -> None:
        try:
            outcome.append(kb.query(f"running, {goal}", timeout=60))
        except slr_sql.SLRError as exc:
            outcome.append(exc)

    asking = threading.Thread(target=ask)
    asking.start()
    assert running.wait(30), "the query did not start"
    started = time.monotonic()
    kb.close()
    asking.join(30)
    assert not asking.is_alive()
    assert time.monotonic() - started < 10          # its timeout was 60 s
    [ended] = outcome
    assert isinstance(ended, slr_sql.SLRError) and \
        "the knowledge base was closed while the query ran" in str(ended), ended


# A compiled query of one statement: 500 ** 3 rows of the cross join, none an answer (about a
# minute of either engine's CPU: far past DEADLINE, so a close that waited for it fails)
EVENTS = 500
SLOW_BODY = "p(X)^_, p(Y)^_, {started}p(Z)^_, X > Y, Y > Z, Z > X"
DEADLINE = 30.0   # seconds a wait may take before the test fails


def _slow_store(where: str, signalled: bool = True
                ) -> tuple[slr_sql.KnowledgeBase, threading.Event | None]:
    """A store of EVENTS p/1 events whose rule ``slow`` compiles to one long statement, and
    (``signalled``) on SQLite the event its statement sets as it runs (a defined predicate
    called from the SQL; on PostgreSQL it would send the rule to the interpreter: None)."""
    kb = slr_sql.open(where, clock=slr_sql.ManualClock(0.0))
    kb.add_many([f"p({i})^{i}" for i in range(EVENTS)])
    started = None
    if signalled and kb.store.python_functions:
        started = threading.Event()
        kb.define("started", 0, lambda: started.set() or True)
    kb.load(f"slow :- {SLOW_BODY.format(started='started, ' if started else '')}.")
    assert "engine: sql" in kb.explain("slow")
    return kb, started


def _next_in_a_thread(answers) -> tuple[list, threading.Event]:
    """Ask ``answers`` for its next answer on a thread of its own: (what it gave or raised,
    once there; set then). A daemon thread: without a working stop the statement runs on
    past the test's wait."""
    outcome: list = []
    ended = threading.Event()

    def ask() -> None:
        try:
            outcome.append(next(answers))
        except BaseException as exc:   # (the caller asserts on it)
            outcome.append(exc)
        ended.set()

    threading.Thread(target=ask, daemon=True).start()
    return outcome, ended


def _store_pid(kb) -> int | None:
    """The server process of the store's connection (None on SQLite); asked before the
    query starts, whose statement holds the connection."""
    if kb.store.python_functions:
        return None
    return kb.sql("SELECT pg_backend_pid()", write=True)[1][0][0]


def _wait_until_running(where: str, pid: int | None, started: threading.Event | None,
                        ended: threading.Event) -> None:
    """Until the query's statement runs: the event its SQL sets (SQLite), or the server
    showing the store's connection ``pid`` active for 100 ms (PostgreSQL, polled up to
    DEADLINE)."""
    if started is not None:
        assert started.wait(DEADLINE), "the statement did not start"
        return
    import psycopg
    running = ("SELECT count(*) FROM pg_stat_activity WHERE pid = %s AND state = 'active' "
               "AND clock_timestamp() - query_start > interval '100 milliseconds'")
    deadline = time.monotonic() + DEADLINE
    with psycopg.connect(where, autocommit=True) as admin:
        while not admin.execute(running, (pid,)).fetchone()[0]:
            assert not ended.is_set() and time.monotonic() < deadline, \
                "the statement did not start"
            ended.wait(0.01)


@pytest.mark.parametrize("timeout", [None, 120.0], ids=["no timeout", "a timeout far off"])
def test_a_compiled_query_running_when_the_knowledge_base_closes_ends_with_an_slr_error(
        backend, timeout, caplog):
    """A query compiled to one long statement held the store's lock while SQLite or the
    server ran it: the close waited for it to end (a minute here; up to --max-query-time for
    `slr serve`). The close now interrupts (SQLite) or cancels (PostgreSQL) it, and the
    query ends with the interpreter's words; the store is closed, its events unchanged."""
    kb, started = _slow_store(backend)
    outcome: list = []
    ended = threading.Event()

    def ask() -> None:
        try:
            outcome.append(kb.query("slow", timeout=timeout))
        except BaseException as exc:   # (asserted on below)
            outcome.append(exc)
        ended.set()

    pid = _store_pid(kb)
    # (daemon threads: without the fix the statement runs on, and the close waits for it)
    threading.Thread(target=ask, daemon=True).start()
    _wait_until_running(backend, pid, started, ended)
    closed = threading.Event()
    threading.Thread(target=lambda: (kb.close(), closed.set()), daemon=True).start()
    assert ended.wait(DEADLINE), "the query ran on after the close"
    assert closed.wait(DEADLINE), "the close waited"
    [error] = outcome
    assert type(error) is slr_sql.SLRError, repr(error)
    assert str(error) == "the knowledge base was closed while the query ran"
    assert not [r for r in caplog.records if r.levelname in ("ERROR", "CRITICAL")
                or r.exc_info], caplog.text
    with pytest.raises(slr_sql.SLRError, match="^the event store is closed$"):
        kb.query("slow", timeout=timeout)
    with slr_sql.open(backend, clock=slr_sql.ManualClock(0.0)) as again:
        assert again.query("findall(X, p(X)^_, L), length(L, N)")[0]["N"] == EVENTS


def test_a_query_started_once_the_store_stops_its_queries_is_refused_in_words(backend):
    """Between the start of a close and the store's own close (the parts of the knowledge
    base closing first), a query's statement no longer starts; the store's other statements
    (an add's) still run."""
    with slr_sql.open(backend, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.load("r(X) :- p(X)^_.")
        kb.add("p(1)^1")
        kb.store.stop_queries()
        with pytest.raises(slr_sql.SLRError) as caught:
            kb.query("r(X)")
        assert type(caught.value) is slr_sql.SLRError
        assert str(caught.value) == "the knowledge base was closed while the query ran"
        kb.add("p(2)^2")
    with slr_sql.open(backend, clock=slr_sql.ManualClock(0.0)) as again:
        assert again.query("r(X)") == [{"X": 1}, {"X": 2}]


def test_a_stopping_server_ends_a_compiled_query_still_running_after_its_grace(
        backend, tmp_path):
    """`slr serve` stopping (SIGTERM) answers a query still running when its grace ends 503
    and closes the store: a compiled query's statement then ran on to its end (or to
    --max-query-time) while the process waited for its thread. It now ends with the close,
    and nothing of it reaches the log as a traceback."""
    import signal

    import httpx
    from service_helpers import HTTP, ServiceProcess

    _slow_store(backend, signalled=False)[0].close()
    served = ServiceProcess(backend, "--shutdown-grace", "0.5", "--max-query-time", "120",
                            log=tmp_path / "server.log")
    outcome: list = []

    def ask() -> None:
        try:
            answer = HTTP.post(served.url + "/query", timeout=180,
                               json={"goal": "slow", "timeout": 120})
            outcome.append((answer.status_code, answer.json()))
        except httpx.HTTPError as exc:
            outcome.append(type(exc).__name__)

    asking = threading.Thread(target=ask, daemon=True)
    asking.start()
    try:
        deadline = time.monotonic() + DEADLINE
        while HTTP.get(served.url + "/health").json()["queries"]["running"] == 0:
            assert time.monotonic() < deadline, "the query is not counted running"
        started = time.monotonic()
        served.proc.send_signal(signal.SIGTERM)
        assert served.proc.wait(timeout=DEADLINE) == 0
        took = time.monotonic() - started
    finally:
        served.stop()
        asking.join(DEADLINE)
    assert took < 10, took
    [(status, body)] = outcome
    assert status == 503 and "the server stopped before the answer was ready" in \
        body["error"]["message"], body
    log = served.log.read_text()
    assert "Traceback" not in log and "Exception in ASGI" not in log, log
    assert "POST /query was still running when the server stopped; answered 503" in log, log


def test_a_queries_own_deadline_ends_its_long_compiled_statement(backend, tmp_path):
    """The other end of a long statement, on both backends: the query's timeout (a compiled
    goal, a compiled sub-goal the interpreter calls, a synchronized query) and `slr serve`'s
    --max-query-time for a request without one interrupt (SQLite) or cancel (PostgreSQL) it;
    the store is free at once afterwards."""
    from service_helpers import HTTP, ServiceProcess

    kb, _ = _slow_store(backend, signalled=False)
    with kb:
        kb.mark_complete("p/1", 1000.0)
        for ask in (lambda: kb.query("slow", timeout=0.5),
                    lambda: kb.query("findall(x, slow, L)", timeout=0.5),
                    lambda: kb.query("slow", at=600.0, wait=True, timeout=0.5)):
            began = time.monotonic()
            with pytest.raises(slr_sql.SLRTimeout):
                ask()
            assert time.monotonic() - began < DEADLINE
            assert kb.query("p(X)^_, X > 498") == [{"X": 499}]   # (no statement left running)
    with ServiceProcess(backend, "--max-query-time", "0.5", log=tmp_path / "server.log") \
            as served:
        began = time.monotonic()
        answer = HTTP.post(served.url + "/query", json={"goal": "slow"}, timeout=DEADLINE)
        assert answer.status_code == 408 and answer.json()["error"]["kind"] == "SLRTimeout"
        assert time.monotonic() - began < DEADLINE


def _printed_statement(kb) -> str:
    """The statement ``slow`` compiles to, as kb.explain prints it (kb.sql runs it as
    printed: the connection's SQL functions are there)."""
    lines = kb.explain("slow").splitlines()
    return "\n".join(line.strip() for line in lines[lines.index("sql:") + 1:])


@pytest.mark.parametrize("timeout", [None, 120.0], ids=["no timeout", "a timeout far off"])
def test_a_read_only_sql_statement_running_when_the_knowledge_base_closes_ends_in_words(
        backend, timeout, caplog):
    """kb.sql's read-only statement (slr serve's /sql) ends with the close as a compiled
    query's does: on SQLite it held the store's lock, which the close waited for; on
    PostgreSQL it runs on a connection of its own, and its caller waited for its end."""
    kb, started = _slow_store(backend)
    statement = _printed_statement(kb)
    outcome: list = []
    ended = threading.Event()

    def ask() -> None:
        try:
            outcome.append(kb.sql(statement, timeout=timeout))
        except BaseException as exc:   # (asserted on below)
            outcome.append(exc)
        ended.set()

    threading.Thread(target=ask, daemon=True).start()
    if started is not None:
        assert started.wait(DEADLINE), "the statement did not start"
    else:   # (on a connection of its own: the server's view of the database)
        import psycopg
        active = ("SELECT count(*) FROM pg_stat_activity WHERE datname = current_database() "
                  "AND state = 'active' AND left(query, 60) = left(%s, 60)")
        deadline = time.monotonic() + DEADLINE
        with psycopg.connect(backend, autocommit=True) as admin:
            while not admin.execute(active, (statement,)).fetchone()[0]:
                assert not ended.is_set() and time.monotonic() < deadline, \
                    "the statement did not start"
                ended.wait(0.01)
    closed = threading.Event()
    threading.Thread(target=lambda: (kb.close(), closed.set()), daemon=True).start()
    assert ended.wait(DEADLINE), "the statement ran on after the close"
    assert closed.wait(DEADLINE), "the close waited"
    [error] = outcome
    assert type(error) is slr_sql.SLRError, repr(error)
    assert str(error) == "the knowledge base was closed while the query ran"
    assert not [r for r in caplog.records if r.levelname in ("ERROR", "CRITICAL")
                or r.exc_info], caplog.text
    if started is None:   # the server's statement was cancelled, not left to run on
        with psycopg.connect(backend, autocommit=True) as admin:
            while admin.execute(active, (statement,)).fetchone()[0]:
                assert time.monotonic() < deadline + DEADLINE, "the statement runs on"


def test_an_event_rule_deciding_in_its_add_when_the_knowledge_base_closes_decides_as_before(
        backend):
    """A close waits for a transaction, the goals evaluated inside it included: an event
    rule's `where` goal deciding in its add is part of that write. Ended by the close like a
    query, it counted as the rule's error and rejected the match, a decision the close made
    (and stored, since the add then committed)."""
    kb = slr_sql.open(backend, clock=slr_sql.ManualClock(0.0))
    kb.add_many([f"p({i})^{i}" for i in range(300)])
    kb.mark_complete("p/1", 5000.0)
    deciding = threading.Event()
    kb.define("deciding", 0, lambda: deciding.set() or True)
    kb.load("r(X) <- a(X) where (deciding, aggregate_all(count, (p(Y)^_, p(Z)^_, Y > Z), N), "
            "N > X).")
    added = threading.Event()
    # (what the add itself says is not asserted: its stages after the commit may meet the
    # closed store)
    threading.Thread(target=lambda: (_ignore_errors(lambda: kb.add("a(1)^1000")),
                                     added.set()), daemon=True).start()
    assert deciding.wait(DEADLINE), "the where goal was not asked"
    closed = threading.Event()
    threading.Thread(target=lambda: (kb.close(), closed.set()), daemon=True).start()
    assert closed.wait(DEADLINE) and added.wait(DEADLINE)
    with slr_sql.open(backend, clock=slr_sql.ManualClock(0.0)) as again:
        assert again.query("a(X)^T") == [{"X": 1, "T": 1000.0}]
        assert again.query("r(X)^T") == [{"X": 1, "T": 1000.0}]


def _ignore_errors(call) -> None:
    try:
        call()
    except slr_sql.SLRError:
        pass


def test_a_close_cancels_a_querys_statement_never_the_write_after_it(postgres_url,
                                                                      monkeypatch):
    """PostgreSQL: the close's cancel of a query's statement on the store's connection was
    sent after it had looked (under its condition) that the query still ran, without
    holding anything: the query could end meanwhile, and another thread's add -- waiting
    for the store's lock -- take the connection, so that the cancel cut the write (a close
    never does). Here the cancel request is held (psycopg's cancel_safe, for this store's
    connection only) until the query has ended and the add has reached its statement, or
    2 s: the cancel is now sent while the query's thread cannot let go of the connection.
    (Without the fix the add reached its statement within the 2 s and was cancelled.)"""
    import psycopg

    kb, _ = _slow_store(postgres_url, signalled=False)
    with psycopg.connect(postgres_url, autocommit=True) as admin:
        admin.execute("SET search_path = slr")
        admin.execute("CREATE FUNCTION slr_test_slow() RETURNS trigger LANGUAGE plpgsql "
                      "AS $$ BEGIN PERFORM pg_sleep(1); RETURN NEW; END $$")
        admin.execute("CREATE TRIGGER slow BEFORE INSERT ON p "
                      "FOR EACH ROW EXECUTE FUNCTION slr_test_slow()")
        pid = _store_pid(kb)
        store_connection = kb.store._db.conn.raw
        cancel_safe = psycopg.Connection.cancel_safe
        writing = ("SELECT count(*) FROM pg_stat_activity WHERE pid = %s "
                   "AND wait_event = 'PgSleep'")

        def held_cancel(self, *args, **kwargs):
            if self is store_connection:
                # the query ended by another session's cancels, then (if it can) the add
                # runs its statement on the store's connection, then the close's cancel
                deadline = time.monotonic() + 2.0
                while time.monotonic() < deadline and not queried.is_set():
                    admin.execute("SELECT pg_cancel_backend(%s)", (pid,))
                    queried.wait(0.05)
                while time.monotonic() < deadline and \
                        not admin.execute(writing, (pid,)).fetchone()[0]:
                    added.wait(0.01)
            return cancel_safe(self, *args, **kwargs)
        monkeypatch.setattr(psycopg.Connection, "cancel_safe", held_cancel)

        outcome: dict = {}
        queried, added = threading.Event(), threading.Event()

        def ask() -> None:
            try:
                kb.query("slow")
            except BaseException as exc:   # (ended by the cancels)
                outcome["query"] = exc
            queried.set()

        def add() -> None:
            try:
                kb.add("p(1000)^1000")
            except BaseException as exc:   # (asserted on below)
                outcome["add"] = exc
            added.set()

        ended = threading.Event()
        threading.Thread(target=ask, daemon=True).start()
        _wait_until_running(postgres_url, pid, None, ended)
        threading.Thread(target=add, daemon=True).start()
        closed = threading.Event()
        threading.Thread(target=lambda: (kb.close(), closed.set()), daemon=True).start()
        assert queried.wait(DEADLINE) and added.wait(DEADLINE) and closed.wait(DEADLINE)
        # never cut (SLRCancelled); the close may take the store's lock before the add once
        # the query let go of it: then the add is refused in words, and nothing is stored
        error = outcome.get("add")
        assert error is None or (type(error) is slr_sql.SLRError
                                 and str(error) == "the event store is closed"), repr(error)
        assert admin.execute("SELECT count(*) FROM p WHERE arg1 = '1000'").fetchone()[0] == \
            (0 if error else 1)


# -- Solutions.stop(): one query's statement, the knowledge base open ---------------------

STOPPED = "the query was stopped while it looked for its next answer"


@pytest.mark.parametrize("goal", ["slow", "findall(x, slow, L)"],
                         ids=["a compiled goal", "a compiled sub-goal"])
def test_stop_ends_the_compiled_statement_of_its_query_and_the_store_answers_the_next(
        backend, goal, caplog):
    """`solutions(...).stop()` from another thread ended the interpreter's search, but a goal
    compiled to one statement (or a compiled sub-goal the interpreter called) ran on to its
    timeout (120 s here), holding the store's connection. Its statement is now interrupted
    (SQLite) or cancelled (PostgreSQL): the query ends with the interpreter's words, the
    store is unchanged, and its connection answers the next query at once."""
    kb, started = _slow_store(backend)
    with kb:
        pid = _store_pid(kb)
        answers = kb.solutions(goal, timeout=120)
        outcome, ended = _next_in_a_thread(answers)
        _wait_until_running(backend, pid, started, ended)
        answers.stop()
        assert ended.wait(DEADLINE), "the statement ran on after the stop"
        [error] = outcome
        assert type(error) is slr_sql.SLRError and str(error) == STOPPED, repr(error)
        with pytest.raises(slr_sql.SLRError, match=f"^{STOPPED}$"):
            next(answers)
        assert kb.query("p(X)^_, X > 498", timeout=DEADLINE) == [{"X": 499}]
        assert kb.query("findall(X, p(X)^_, L), length(L, N)")[0]["N"] == EVENTS
        assert not [r for r in caplog.records if r.levelname in ("ERROR", "CRITICAL")
                    or r.exc_info], caplog.text


def test_a_served_query_stopped_by_its_client_frees_the_server_at_once(backend, tmp_path):
    """The client's `stop()` of a served query (its WebSocket closed: `slr shell URL`'s
    Ctrl-C, a client that leaves) stopped the server's search, but a compiled statement ran
    on, holding the store, until --max-query-time (120 s here): the server's next query
    waited for it. It now ends with the stop, and the server answers the next query."""
    from service_helpers import HTTP, ServiceProcess

    _slow_store(backend, signalled=False)[0].close()
    with ServiceProcess(backend, "--max-query-time", "120", log=tmp_path / "server.log") \
            as served, slr_sql.connect(served.url) as client:
        answers = client.solutions("slow")
        outcome, ended = _next_in_a_thread(answers)
        deadline = time.monotonic() + DEADLINE
        while HTTP.get(served.url + "/health").json()["queries"]["running"] == 0:
            assert time.monotonic() < deadline, "the query is not counted running"
        answers.stop()
        assert ended.wait(DEADLINE)
        [error] = outcome
        assert type(error) is slr_sql.SLRError and str(error) == STOPPED, repr(error)
        began = time.monotonic()
        answer = HTTP.post(served.url + "/query", json={"goal": "p(X)^_, X > 498"},
                           timeout=DEADLINE)
        assert answer.status_code == 200 and answer.json()["answers"] == [{"X": 499}]
        assert time.monotonic() - began < DEADLINE
        while True:   # (the stopped query's slot is given back on the server's event loop)
            queries = HTTP.get(served.url + "/health").json()["queries"]
            if queries["running"] == 0 and queries["solutions"] == 0:
                break
            assert time.monotonic() < began + DEADLINE, queries
    log = served.log.read_text()
    assert "Traceback" not in log and "Exception in ASGI" not in log, log
