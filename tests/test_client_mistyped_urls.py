"""Mistyped service URLs and tokens (adversarial review of ``slr_sql.connect`` and the CLI).

A URL whose port is not a number, or an IPv6 address missing its bracket, reached the user as
httpx's ``InvalidURL`` (the CLI called it "a bug in slr_sql"). A token beyond ASCII, which the
server takes (compared as UTF-8), reached the user of the client as a ``UnicodeEncodeError``
and could not be sent by curl either (the server read its UTF-8 bytes as ISO-8859-1); a token
that no header can carry (a line break, a control character) reached the user as "cannot
reach slr serve" -- an Unavailable error, which says retry, for a condition that never
passes -- and a server given one could never be used.
"""
from __future__ import annotations

import subprocess
import sys

import httpx
import pytest
from service_helpers import HTTP, ServiceProcess, slr_env

import slr_sql
from slr_sql import SLRError
from slr_sql.service.errors import ServiceError

DEADLINE = 30.0
BAD_URLS = ["http://127.0.0.1:port", "http://[::1", "http://127.0.0.1:99999999999"]
BAD_TOKENS = ["a\nb", "a\x00b", " padded ", "tab\there", "a\x85b"]


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    with ServiceProcess(tmp_path_factory.mktemp("rt11client") / "s.db", "--token", "s3cret") as s:
        yield s


@pytest.mark.parametrize("url", BAD_URLS)
def test_a_malformed_url_is_an_slr_error_saying_so(url):
    with pytest.raises(SLRError) as caught:
        with slr_sql.connect(url) as kb:
            kb.query("X = 1")
    assert not (isinstance(caught.value, ServiceError) and caught.value.kind == "Unavailable")
    assert "URL" in str(caught.value) and url in str(caught.value)


@pytest.mark.parametrize("url", BAD_URLS)
def test_the_cli_says_what_is_wrong_with_a_malformed_url(url):
    done = subprocess.run([sys.executable, "-m", "slr_sql", "query", url, "X = 1"],
                          capture_output=True, text=True, env=slr_env(), timeout=60)
    assert done.returncode == 1
    assert done.stderr.startswith("error: ") and "URL" in done.stderr
    assert "bug" not in done.stderr and "InvalidURL" not in done.stderr


@pytest.mark.parametrize("token", BAD_TOKENS)
def test_a_token_that_cannot_travel_in_a_header_is_refused_by_the_client(server, token):
    with pytest.raises(SLRError, match="token") as caught:
        with slr_sql.connect(server.url, token=token) as kb:
            kb.query("X = 1")
    assert not isinstance(caught.value, ServiceError) or caught.value.kind != "Unavailable"
    assert server.healthy()
    with slr_sql.connect(server.url, token="s3cret") as kb:   # the right one still works
        assert kb.query("X = 1") == [{"X": 1}]


@pytest.mark.parametrize("token", ["line\nbreak", " padded "])
def test_slr_serve_refuses_a_token_no_client_could_send(tmp_path, token):
    done = subprocess.run([sys.executable, "-m", "slr_sql", "serve", str(tmp_path / "t.db"),
                           "--port", "0", "--token", token],
                          capture_output=True, text=True, env=slr_env(), timeout=60)
    assert done.returncode == 1
    assert done.stderr.startswith("error: ") and "token" in done.stderr
    assert "Traceback" not in done.stderr


def test_a_token_beyond_ascii_works_from_the_client_curl_and_a_websocket(tmp_path):
    token = "clé-ü€"
    with ServiceProcess(tmp_path / "u.db", "--token", token) as served:
        with slr_sql.connect(served.url, token=token) as kb:
            kb.add("seen(a)^1")
            assert kb.query("seen(X)^T") == [{"X": slr_sql.Atom("a"), "T": 1.0}]
            with kb.subscribe("seen(X)^T", since=0) as sub:
                assert next(iter(sub))["X"] == slr_sql.Atom("a")
        with slr_sql.connect(served.url, token="cle-u€") as kb:
            with pytest.raises(ServiceError, match="valid token"):
                kb.query("X = 1")
        # what curl sends for --header "Authorization: Bearer clé-ü€" in a UTF-8 shell
        answer = HTTP.post(served.url + "/query", json={"goal": "X = 1"}, timeout=30,
                           headers={"Authorization": f"Bearer {token}".encode("utf-8")})
        assert answer.json() == {"answers": [{"X": 1}]}


# -- a URL that answers, but is no slr serve ----------------------------------------------------

@pytest.fixture(params=["{}", '{"answers": 5, "programs": [1], "buffers": {"a": 1}, '
                              '"stored": "x", "positions": [[1]], "robots": 3, "columns": 1, '
                              '"rows": 2, "event_rules": 1, "warnings": 1, "explain": 3, '
                              '"id": "x", "handle": 5, "done": true, "time": "x", '
                              '"added": "yes", "accepted": "all", "rejected": 7}'],
                ids=["empty-object", "wrong-types"])
def not_slr_serve(request):
    """Another HTTP service (or a proxy) that answers every request 200 with this JSON."""
    import threading
    from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

    body = request.param.encode()

    class Handler(BaseHTTPRequestHandler):
        def answer(self) -> None:
            self.rfile.read(int(self.headers.get("content-length") or 0))
            self.send_response(200)
            self.send_header("Content-Type", "application/json")
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        do_GET = do_POST = do_DELETE = answer

        def log_message(self, *args) -> None:
            pass

    server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    # serve_forever looks at shutdown() between polls: its default 0.5 s poll made each test's
    # teardown wait ~0.5 s (half of the file's time)
    thread = threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.01},
                              daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{server.server_address[1]}"
    server.shutdown()
    server.server_close()
    thread.join()


CALLS = {
    "add": lambda kb: kb.add("p(1)^1"),
    "add_event": lambda kb: kb.add_event("p", [1], start=1.0),
    "add_many": lambda kb: kb.add_many(["p(1)^1"]),
    "load": lambda kb: kb.load("q(1)."),
    "unload": lambda kb: kb.unload("main"),
    "query": lambda kb: kb.query("X = 1"),
    "programs": lambda kb: kb.programs(),
    "event_rules": lambda kb: kb.event_rules(),
    "buffers": lambda kb: kb.buffers(),
    "add_buffer": lambda kb: kb.add_buffer("p(_)", keep_last=1),
    "explain": lambda kb: kb.explain("X = 1"),
    "goal_warnings": lambda kb: kb.goal_warnings("p(X)"),
    "sql": lambda kb: kb.sql("SELECT 1"),
    "complete_until": lambda kb: kb.complete_until("p/1"),
    "mark_complete": lambda kb: kb.mark_complete("p/1", 5.0),
    "submit": lambda kb: kb.submit("X = 1").result(timeout=10),
    "fleet_positions": lambda kb: kb.fleet_positions("r1"),
    "fleet_receive": lambda kb: kb.fleet_receive("r1", [("p", 1, [(1, "a", 1.0, 1.0, 1.0, None)])]),
    "fleet_status": lambda kb: kb.fleet_status(),
    "fleet_retire": lambda kb: kb.fleet_retire("r1"),
    "fleet_reinstate": lambda kb: kb.fleet_reinstate("r1"),
    "stats": lambda kb: kb.stats(),
    "remove_buffer": lambda kb: kb.remove_buffer(1),
}


@pytest.mark.parametrize("call", sorted(CALLS))
def test_an_answer_that_is_not_slr_serves_is_an_slr_error_never_a_success(not_slr_serve, call):
    with slr_sql.connect(not_slr_serve) as kb:
        with pytest.raises(SLRError, match="not what slr serve answers"):
            CALLS[call](kb)


@pytest.mark.parametrize("first", ["not json", b"\xff\xfe", "[]", '{"type": "answer"}'])
def test_a_websocket_peer_that_is_not_slr_serve_is_an_slr_error(first):
    import threading

    from websockets.sync.server import serve

    def handler(ws) -> None:
        ws.recv()
        ws.send(first)

    with serve(handler, "127.0.0.1", 0) as peer:
        thread = threading.Thread(target=peer.serve_forever, daemon=True)
        thread.start()
        url = f"http://127.0.0.1:{peer.socket.getsockname()[1]}"
        try:
            with slr_sql.connect(url) as kb:
                with pytest.raises(ServiceError, match="server sent|unexpected first"):
                    with kb.subscribe("p(X)^T", since=0) as sub:
                        list(sub)
        finally:
            peer.shutdown()
            thread.join()


def test_sigterm_stops_a_server_whose_synchronized_query_still_waits(tmp_path):
    """A synchronized query that waits (for an hour: max_wait) held slr serve's graceful
    shutdown for as long: SIGTERM did not stop it. Requests in flight now get a grace period
    (``--shutdown-grace``, 10 s by default; 0.5 s here), then the server stops and closes the
    store."""
    import signal
    import threading

    grace = 0.5
    served = ServiceProcess(tmp_path / "w.db", "--shutdown-grace", str(grace))
    outcome: list = []

    def wait_long() -> None:
        try:
            outcome.append(HTTP.post(served.url + "/query", timeout=120, json={
                "goal": "zz(X)^T", "at": 1e15, "wait": True, "timeout": 3000}).status_code)
        except httpx.HTTPError as exc:
            outcome.append(type(exc).__name__)

    waiter = threading.Thread(target=wait_long)
    waiter.start()
    try:
        for _ in range(3):      # the waiting request is read and dispatched before these
            assert served.healthy()
        served.proc.send_signal(signal.SIGTERM)
        assert served.proc.wait(timeout=grace + 30) == 0
    finally:
        served.stop()
        waiter.join(timeout=60)
    assert outcome and outcome[0] != 200, outcome


def test_a_client_that_leaves_a_synchronized_query_frees_its_place(tmp_path):
    """A client that leaves while its synchronized query (/query wait=true) waits: the
    server kept waiting for it (up to max_wait, an hour), holding a place of
    --max-connections, so that a few such clients made it answer 503 to everyone. The query
    is now cancelled when its client leaves."""
    import time

    with ServiceProcess(tmp_path / "l.db", "--max-connections", "2") as served:
        for _ in range(3):
            try:                                     # the client gives up and leaves
                refused = HTTP.post(served.url + "/query", timeout=0.5, json={
                    "goal": "zz(X)^T", "at": 1e15, "wait": True, "timeout": 3000})
            except httpx.HTTPError:
                continue
            assert refused.status_code == 503        # (both places taken already)
        deadline = time.monotonic() + 30
        while True:
            answer = HTTP.post(served.url + "/query", json={"goal": "X = 1"}, timeout=30)
            if answer.status_code == 200:
                break
            assert answer.status_code == 503
            assert time.monotonic() < deadline, "the waits of clients gone hold the server"
            time.sleep(0.05)
        assert answer.json() == {"answers": [{"X": 1}]}


@pytest.mark.parametrize("url", ["http://user:pw@127.0.0.1:8765", "https://me@robot:8443"])
def test_a_user_or_password_in_the_url_is_refused_not_dropped(url):
    with pytest.raises(SLRError, match="user or password in the URL is not sent") as caught:
        slr_sql.connect(url)
    assert "pw" not in str(caught.value)          # (the password is not shown either)


@pytest.mark.parametrize("timeout", [0, -1, float("nan"), float("inf"), "soon"])
def test_a_timeout_that_is_no_positive_number_is_refused(server, timeout):
    with pytest.raises(SLRError, match="timeout must be a positive number"):
        slr_sql.connect(server.url, token="s3cret", timeout=timeout)


def test_a_prefix_beyond_ascii_and_a_parameter_no_url_carries_are_slr_errors(server):
    with slr_sql.connect(server.url + "/é kb", token="s3cret") as kb:
        with pytest.raises(ServiceError) as caught:     # (slr serve has no such prefix)
            kb.health()
        assert caught.value.status == 404
    with slr_sql.connect(server.url, token="s3cret") as kb:
        with pytest.raises(ServiceError) as caught:
            kb.fleet_positions("r\ud800")
        assert caught.value.kind == "BadRequest" and caught.value.status == 0
        # (an event type the store cannot hold is refused before any URL, as locally)
        with pytest.raises(slr_sql.SLRError, match="cannot be stored: text with a lone"):
            kb.complete_until("p\ud800/1")


def test_the_client_goes_straight_to_the_url_whatever_the_proxy_variables_say(
        server, monkeypatch):
    for name in ("HTTP_PROXY", "http_proxy", "HTTPS_PROXY", "https_proxy", "ALL_PROXY",
                 "all_proxy"):
        monkeypatch.setenv(name, "http://127.0.0.1:9")       # nobody listens there
    monkeypatch.delenv("NO_PROXY", raising=False)
    monkeypatch.delenv("no_proxy", raising=False)
    with slr_sql.connect(server.url, token="s3cret") as kb:
        kb.add("proxied(a)^1")
        assert kb.query("proxied(X)^T") == [{"X": slr_sql.Atom("a"), "T": 1.0}]
        with kb.subscribe("proxied(X)^T", since=0) as sub:
            assert sub.get(timeout=DEADLINE)["X"] == slr_sql.Atom("a")


def _stop_while_asked(served, path: str, body: dict, counter: str) -> tuple[float, tuple]:
    """Ask ``body`` of ``path`` from a thread, SIGTERM the server once its /health counts the
    request (``queries[counter]``), and return the seconds the stop took and the answer."""
    import signal
    import threading
    import time

    outcome: list = []

    def ask() -> None:
        try:
            answer = HTTP.post(served.url + path, timeout=120, json=body)
            outcome.append((answer.status_code, answer.json()))
        except httpx.HTTPError as exc:
            outcome.append(type(exc).__name__)

    asking = threading.Thread(target=ask)
    asking.start()
    try:
        deadline = time.monotonic() + 30
        while HTTP.get(served.url + "/health").json()["queries"][counter] == 0:
            assert time.monotonic() < deadline, f"the request is not counted {counter}"
        started = time.monotonic()
        served.proc.send_signal(signal.SIGTERM)
        assert served.proc.wait(timeout=60) == 0
        took = time.monotonic() - started
    finally:
        served.stop()
        asking.join(timeout=60)
    [answered] = outcome
    return took, answered


@pytest.mark.parametrize("request_body, path", [
    ({"goal": "zz(X)^T", "at": 1e15, "wait": True, "timeout": 3000}, "/query"),
    ({"goal": "zz(X)^T", "at": 1e15, "wait": 60, "timeout": 3000}, "/submit"),
], ids=["synchronized-query", "long-poll"])
def test_a_stopping_server_ends_its_waiting_requests_at_once(tmp_path, request_body, path):
    """A synchronized query waiting for its answer (or a long-poll of a submitted one) held
    the stop for the whole grace (10 s), then was cancelled, with uvicorn's traceback in the
    log. A stopping server now ends them at once: the query is answered 503 (ask again,
    of the next server), the poll with the state as it is (not done)."""
    served = ServiceProcess(tmp_path / "w.db")
    took, (status, body) = _stop_while_asked(served, path, request_body, "held")
    assert took < 5, took          # the grace is 10 s
    log = served.log.read_text()
    assert "Traceback" not in log and "Exception in ASGI" not in log, log
    if path == "/query":
        assert status == 503 and "the server is stopping" in body["error"]["message"], body
    else:
        assert status == 202 and body["done"] is False, body   # (202: not answered yet)


def test_a_request_still_running_when_the_grace_ends_is_answered_503_without_a_traceback(
        tmp_path):
    """A query still evaluating when the stop's grace ended was cancelled by uvicorn, which
    logged it with a traceback (a line any client could cause), and its thread ran on to the
    query's timeout. It is now answered 503 (ask again) and logged on one line, and it ends
    when the server closes the knowledge base."""
    served = ServiceProcess(tmp_path / "w.db", "--shutdown-grace", "0.5")
    took, (status, body) = _stop_while_asked(
        served, "/query", {"goal": "between(1, inf, X), X < 0", "timeout": 30}, "running")
    # the query's thread ends as the store closes: the process waited for it to reach its
    # own timeout (--max-query-time, 30 s) as it exited
    assert took < 10, took
    log = served.log.read_text()
    assert "Traceback" not in log and "Exception in ASGI" not in log, log
    assert "POST /query was still running when the server stopped; answered 503" in log, log
    assert status == 503 and "the server stopped before the answer was ready" in \
        body["error"]["message"], body
