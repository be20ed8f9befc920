"""A server that cannot answer now is an :class:`SLRUnavailable` to the client, as a busy or
full store is: nobody listening at the URL, a 503 of the server (beyond ``--max-connections``),
a subscription whose connection broke. Code that catches SLRUnavailable to retry used to miss
them (a ``ServiceError`` of kind ``Unavailable`` only). The error is still a
:class:`ServiceError` with its ``kind`` and ``status``; a refusal a retry would meet again (a
WebSocket handshake refused with 403) is not SLRUnavailable. The error of a 503 carries the
answer's ``Retry-After`` as ``retry_after``, which a following fleet pusher waits. A request
that may change the store, sent in full before the connection broke, is no SLRUnavailable
but a ``ServiceOutcomeUnknown`` (it may have been applied).

The servers here are real ``slr serve`` processes, or real HTTP / TCP servers of the test
on a thread where a test needs an answer slr serve never gives (a proxy's 503 with its own
Retry-After, a server that dies once it has read a request)."""
from __future__ import annotations

import json
import socket
import time

import pytest

import slr_sql
from slr_sql import SLRUnavailable
from slr_sql.service.errors import ServiceError

from service_helpers import ServiceProcess, listener_with_full_queue

DEADLINE = 30.0


def _unavailable(call) -> ServiceError:
    with pytest.raises(SLRUnavailable) as caught:
        call()
    exc = caught.value
    assert isinstance(exc, ServiceError) and exc.kind == "Unavailable", repr(exc)
    return exc


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    # two connections at once: one held by a test and the request's own make a 503
    with ServiceProcess(tmp_path_factory.mktemp("unavailable") / "s.db",
                        "--max-connections", "2") as s:
        yield s


def test_a_server_nobody_listens_for_is_unavailable_to_requests_and_subscriptions():
    # a port nobody listens on: bound, not listening (refused), and held meanwhile so that
    # no other process's server can take it between the close and the requests
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
        with slr_sql.connect(f"http://127.0.0.1:{port}") as kb:
            exc = _unavailable(lambda: kb.query("X = 1"))
            assert exc.status == 0 and "cannot reach slr serve" in str(exc)
            exc = _unavailable(lambda: kb.subscribe("p(X)^T"))
            assert exc.status == 0 and f"cannot subscribe at ws://127.0.0.1:{port}" in str(exc)


def test_a_503_of_the_server_is_unavailable_and_a_retry_succeeds_once_it_passes(server):
    host, port = server.url.rsplit("/", 1)[1].rsplit(":", 1)
    held = socket.create_connection((host, int(port)), timeout=DEADLINE)
    try:
        # answered, and kept alive: the server counts it until it is closed
        held.sendall(f"GET /health HTTP/1.1\r\nHost: {host}\r\n\r\n".encode())
        assert held.recv(4096).startswith(b"HTTP/1.1 200")
        with slr_sql.connect(server.url) as kb:
            exc = _unavailable(lambda: kb.query("X = 1"))
            assert exc.status == 503 and "HTTP 503" in str(exc)
    finally:
        held.close()
    deadline = time.monotonic() + DEADLINE
    with slr_sql.connect(server.url) as kb:
        while True:                            # what a caller retrying on SLRUnavailable does
            try:
                assert kb.query("X = 1") == [{"X": 1}]
                break
            except SLRUnavailable:
                if time.monotonic() > deadline:
                    raise


def test_a_websocket_handshake_the_server_refuses_is_not_unavailable(server):
    """(a URL with a path: no /subscribe there, the handshake is answered 403)"""
    with slr_sql.connect(server.url + "/elsewhere") as kb:
        with pytest.raises(ServiceError) as caught:
            kb.subscribe("p(X)^T")
    assert not isinstance(caught.value, SLRUnavailable)
    assert caught.value.status == 403 and "HTTP 403" in str(caught.value)


def test_a_subscription_whose_server_was_killed_is_unavailable(tmp_path):
    server = ServiceProcess(tmp_path / "s.db")
    try:
        with slr_sql.connect(server.url) as kb:
            sub = kb.subscribe("p(X)^T", since=0)
            kb.add("p(1)^1")
            assert sub.get(timeout=DEADLINE)["X"] == 1
            server.kill()                      # SIGKILL: no close frame
            exc = _unavailable(lambda: sub.get(timeout=DEADLINE))
            assert exc.status == 0 and "connection closed" in str(exc)
            sub.close()
    finally:
        server.stop()


# -- Retry-After ----------------------------------------------------------------------------------

class _Answering503:
    """A real HTTP server on a thread that answers every request 503 with ``headers`` and
    ``body`` (what a proxy, a load balancer or another version of slr serve may say)."""

    def __init__(self, headers: dict, body: bytes):
        import http.server
        import threading

        outer = self
        self.requests = 0

        class Handler(http.server.BaseHTTPRequestHandler):
            protocol_version = "HTTP/1.1"      # (what a WebSocket handshake's answer needs)

            def _answer(self) -> None:
                self.rfile.read(int(self.headers.get("Content-Length") or 0))
                outer.requests += 1
                self.send_response(503)
                for name, value in headers.items():
                    self.send_header(name, value)
                self.send_header("Content-Length", str(len(body)))
                self.end_headers()
                self.wfile.write(body)

            do_GET = do_POST = _answer

            def log_message(self, *args) -> None:
                pass

        self.server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}"
        self.thread = threading.Thread(target=self.server.serve_forever,
                                       kwargs={"poll_interval": 0.01}, daemon=True)
        self.thread.start()

    def __enter__(self) -> "_Answering503":
        return self

    def __exit__(self, *exc) -> None:
        self.server.shutdown()
        self.server.server_close()
        self.thread.join(DEADLINE)


def _http_date(seconds_from_now: float) -> str:
    from email.utils import formatdate
    return formatdate(time.time() + seconds_from_now, usegmt=True)


_UNAVAILABLE = b'{"error": {"kind": "Unavailable", "status": 503, "message": "try later"}}'
_BUSY = b'{"error": {"kind": "SLRBusy", "status": 503, "message": "robot.db is locked"}}'
_FULL = b'{"error": {"kind": "SLRStoreFull", "status": 503, "message": "the disk is full"}}'


@pytest.mark.parametrize("retry_after, body, cls, expected", [
    ("7", _UNAVAILABLE, "ServiceUnavailable", (7, 7)),
    ("120", b"Service Unavailable", "ServiceUnavailable", (120, 120)),   # not JSON: a proxy
    (lambda: _http_date(100), _UNAVAILABLE, "ServiceUnavailable", (95, 100)),
    ("4", _BUSY, "SLRBusy", (4, 4)),
    ("soon", _UNAVAILABLE, "ServiceUnavailable", (1, 1)),      # garbage: the class default
    (None, _UNAVAILABLE, "ServiceUnavailable", (1, 1)),        # absent: the class default
    ("1.5", _FULL, "SLRStoreFull", (10, 10)),
    ("-3", b"", "ServiceUnavailable", (1, 1)),
], ids=["seconds", "seconds-plain-text", "http-date", "slr-class", "garbage", "absent",
        "garbage-slr-class", "negative-empty-body"])
def test_the_client_error_of_a_503_carries_the_servers_retry_after(retry_after, body, cls,
                                                                   expected):
    """Seconds or an HTTP date; absent or not readable: the class's own default."""
    value = retry_after() if callable(retry_after) else retry_after
    with _Answering503({} if value is None else {"Retry-After": value}, body) as server, \
            slr_sql.connect(server.url) as kb:
        with pytest.raises(SLRUnavailable) as caught:
            kb.add("p(1)^1")
    exc = caught.value
    assert type(exc).__name__ == cls, repr(exc)
    assert expected[0] <= exc.retry_after <= expected[1], exc.retry_after


def test_a_subscription_refused_with_503_carries_the_retry_after_too():
    with _Answering503({"Retry-After": "9"}, _UNAVAILABLE) as server, \
            slr_sql.connect(server.url) as kb:
        exc = _unavailable(lambda: kb.subscribe("p(X)^T"))
    assert exc.status == 503 and exc.retry_after == 9


def test_a_following_fleet_pusher_waits_what_the_fleets_retry_after_says(tmp_path):
    """A fleet that answers 503 with Retry-After: 3 (a backoff would wait 0.1 s first) and
    one asking for an hour (the pusher waits its own most, 5 s)."""
    import threading

    from slr_sql import fleet

    class Stop(threading.Event):
        """The pusher's stop event: records each wait it asks for, and stops at the first."""

        def __init__(self) -> None:
            super().__init__()
            self.waits: list = []

        def wait(self, timeout=None) -> bool:
            self.waits.append(timeout)
            self.set()
            return True

    robot = tmp_path / "r1.db"
    with slr_sql.open(robot, robot="r1", clock=slr_sql.ManualClock(0)) as kb:
        kb.add("seen(pallet7, dock)^1")
    for told, waited in (("3", 3.0), ("3600", fleet.RETRY_MAX)):
        with _Answering503({"Retry-After": told}, _UNAVAILABLE) as server:
            stop, said = Stop(), []
            fleet.push(str(robot), server.url, follow=True, stop=stop, say=said.append)
        assert stop.waits == [waited], (stop.waits, said)
        assert server.requests >= 1 and "unreachable (try later)" in said[0], said


# -- a connection that broke after the request was sent -----------------------------------------

def test_an_add_whose_connection_broke_after_it_was_sent_has_an_unknown_outcome():
    """The server read the whole add and closed without answering (it died): it may have
    stored it, so the error is no SLRUnavailable (which would tell a caller to send it
    again) but a ServiceOutcomeUnknown saying so. A query that met the same fate changed
    nothing: that one is a ServiceUnavailable, safe to retry."""
    from slr_sql.service.errors import ServiceOutcomeUnknown
    from service_helpers import DroppingServer

    with DroppingServer() as server, slr_sql.connect(server.url) as kb:
        for write in (lambda: kb.add("p(1)^1"), lambda: kb.add_many(["p(1)^1", "p(2)^2"]),
                      lambda: kb.mark_complete("p/1", 5), lambda: kb.load("q(1).")):
            with pytest.raises(ServiceOutcomeUnknown) as caught:
                write()
            exc = caught.value
            assert not isinstance(exc, SLRUnavailable), repr(exc)
            assert exc.kind == "OutcomeUnknown" and exc.status == 0
            assert "may or may not have applied it" in str(exc), str(exc)
        assert server.dropped == 4
        exc = _unavailable(lambda: kb.query("p(X)^T"))
        assert exc.status == 0 and server.dropped == 5


def test_an_add_the_server_never_answered_in_time_has_an_unknown_outcome_a_query_a_timeout():
    """The server read the whole request and said nothing within the client's timeout: an
    add may be under way there (ServiceOutcomeUnknown, no SLRUnavailable); a query that
    timed out changed nothing (a RequestTimeout)."""
    from slr_sql.service.errors import ServiceOutcomeUnknown
    from service_helpers import DroppingServer

    with DroppingServer(script="ss") as server, \
            slr_sql.connect(server.url, timeout=0.3) as kb:
        with pytest.raises(ServiceOutcomeUnknown) as caught:
            kb.add("p(1)^1")
        assert not isinstance(caught.value, SLRUnavailable)
        assert "no answer" in str(caught.value) and "within 0.3 s" in str(caught.value) and \
            "may or may not have applied it" in str(caught.value), str(caught.value)
        with pytest.raises(ServiceError) as caught:
            kb.query("p(X)^T")
        assert caught.value.kind == "RequestTimeout" and caught.value.status == 0
        assert not isinstance(caught.value, (ServiceOutcomeUnknown, SLRUnavailable))
        assert server.dropped == 2


def test_an_add_many_split_in_requests_says_which_events_no_request_carried():
    """Above the server's body limit add_many sends several requests: the first is
    answered, the second one's connection breaks, so its events may be stored, those of
    the first are, and the later ones were never sent."""
    from slr_sql.service.errors import ServiceOutcomeUnknown
    from service_helpers import DroppingServer

    with DroppingServer(b'{"status": "ok", "limits": {"max_body": 2048}}', script="a",
                        post_body=b'{"accepted": 5, "rejected": []}') as server, \
            slr_sql.connect(server.url) as kb:
        with pytest.raises(ServiceOutcomeUnknown) as caught:
            kb.add_many([f"p({'x' * 100}, {i})^{i}" for i in range(40)])
    assert server.dropped == 1
    first, end = caught.value.carried
    assert 0 < first < end < 40, caught.value.carried


# -- the server's 503s: one SLRUnavailable class each, its status and Retry-After from it ---------

MAX_PENDING_SERVER = r"""
import sys
from slr_sql.service.app import Limits
from slr_sql.service.cli import run_server
run_server(sys.argv[1], port=0, limits=Limits(max_pending=1))
"""


def test_a_submit_beyond_max_pending_is_503_unavailable_with_retry_after(tmp_path):
    import subprocess
    import sys

    from service_helpers import HTTP, slr_env
    from slr_sql.service.errors import ServiceUnavailable

    proc = subprocess.Popen([sys.executable, "-c", MAX_PENDING_SERVER,
                             str(tmp_path / "pending.db")], stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, env=slr_env())
    try:
        url = proc.stdout.readline().decode().strip().rsplit(" on ", 1)[1]
        first = HTTP.post(url + "/submit", json={"goal": "p(X)^T", "at": 1e11}, timeout=30)
        assert first.status_code == 202, first.text           # waits: the one allowed
        second = HTTP.post(url + "/submit", json={"goal": "q(X)^T", "at": 1e11}, timeout=30)
        assert second.status_code == 503 and second.headers["Retry-After"] == "1"
        assert second.json()["error"]["kind"] == "Unavailable"
        with slr_sql.connect(url) as kb:
            with pytest.raises(ServiceUnavailable) as caught:
                kb.submit("q(X)^T", at=1e11)
        assert caught.value.status == 503 and caught.value.retry_after == 1
        assert "1 submitted queries are pending already" in str(caught.value)
    finally:
        proc.terminate()
        proc.wait(DEADLINE)
        proc.stdout.close()


HELD_ANSWERS_SERVER = r"""
import sys
from slr_sql.service.app import Limits
from slr_sql.service.cli import run_server
run_server(sys.argv[1], port=0, limits=Limits(max_held_answer_bytes=2000))
"""


def test_a_submit_beyond_the_bytes_of_answers_kept_is_503_until_one_is_deleted(tmp_path):
    """A finished submitted query's answers are kept for its client (result_ttl, 600 s):
    a client repeating a submission of a large answer filled the server's memory (~50 MB a
    `length(L, 300000)`). Once the kept answers' JSON reaches max_held_answer_bytes a new
    submission is 503 (retryable); deleting a finished one makes room."""
    import subprocess
    import sys

    from service_helpers import HTTP, slr_env

    proc = subprocess.Popen([sys.executable, "-c", HELD_ANSWERS_SERVER,
                             str(tmp_path / "held.db")], stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, env=slr_env())
    try:
        url = proc.stdout.readline().decode().strip().rsplit(" on ", 1)[1]
        big = {"goal": "numlist(1, 1000, L)", "wait": DEADLINE}
        first = HTTP.post(url + "/submit", json=big, timeout=DEADLINE)
        assert first.status_code == 200 and first.json()["done"], first.text
        assert len(first.json()["answers"][0]["L"]) == 1000
        second = HTTP.post(url + "/submit", json=big, timeout=DEADLINE)
        assert second.status_code == 503 and second.headers["Retry-After"] == "1"
        assert second.json()["error"]["kind"] == "Unavailable"
        assert "at most 2000" in second.json()["error"]["message"], second.text
        # the answer kept is still there for its client, then deleted
        handle = first.json()["handle"]
        kept = HTTP.get(f"{url}/submit/{handle}", timeout=DEADLINE)
        assert kept.status_code == 200 and kept.json()["answers"] == first.json()["answers"]
        assert HTTP.delete(f"{url}/submit/{handle}", timeout=DEADLINE).status_code == 200
        third = HTTP.post(url + "/submit", json=big, timeout=DEADLINE)
        assert third.status_code == 200 and third.json()["done"], third.text
    finally:
        proc.terminate()
        proc.wait(DEADLINE)
        proc.stdout.close()


def _real_sqlite_error(tmp_path, kind: str):
    """The error SQLite itself raises: a write lock another connection holds, or a file at
    its page limit."""
    import sqlite3

    db = str(tmp_path / f"{kind}.db")
    holder = sqlite3.connect(db, isolation_level=None)
    holder.execute("CREATE TABLE t (x)")
    other = sqlite3.connect(db, isolation_level=None, timeout=0)
    try:
        if kind == "locked":
            holder.execute("BEGIN IMMEDIATE")
            other.execute("BEGIN IMMEDIATE")
        else:
            other.execute("PRAGMA max_page_count = 2")
            other.execute("INSERT INTO t VALUES (zeroblob(100000))")
    except sqlite3.OperationalError as exc:
        return exc
    finally:
        other.close()
        holder.close()
    raise AssertionError("SQLite raised nothing")


@pytest.mark.parametrize("kind, cls, wait", [("locked", "SLRBusy", "1"),
                                             ("full", "SLRStoreFull", "10")])
def test_a_raw_sqlite_busy_or_full_error_is_answered_as_the_stores_own_class(tmp_path, kind,
                                                                             cls, wait):
    """What the server answers for a SQLite error no layer turned into an SLRError (the
    store does for its own calls): the class the store raises for the same condition, with
    its status and Retry-After, and the client raises that class."""
    from slr_sql.service.app import _classify, _error_response

    response = _error_response(_classify(_real_sqlite_error(tmp_path, kind)))
    assert response.status_code == 503 and response.headers["Retry-After"] == wait
    body = json.loads(response.body)
    assert body["error"]["kind"] == cls and body["error"]["status"] == 503
    with _Answering503({"Retry-After": response.headers["Retry-After"]},
                       response.body) as server, slr_sql.connect(server.url) as kb:
        with pytest.raises(SLRUnavailable) as caught:
            kb.add("p(1)^1")
    assert type(caught.value).__name__ == cls and caught.value.retry_after == int(wait)


def test_a_server_that_accepts_no_connection_in_time_is_unavailable():
    # connecting times out and nothing reached the server: a retry is safe
    with listener_with_full_queue() as port:
        kb = slr_sql.connect(f"http://127.0.0.1:{port}", timeout=0.3)
        exc = _unavailable(lambda: kb.add("p(a)^1"))
        assert exc.status == 0 and "no connection within 0.3 s" in str(exc)
        kb.close()
