"""A server that cannot answer now is an :class:`SLRUnavailable` to the client, as a busy or
full store is: nobody listening at the URL, a 503 of the server (beyond ``--max-connections``),
a subscription whose connection broke. Code that catches SLRUnavailable to retry used to miss
them (a ``ServiceError`` of kind ``Unavailable`` only). The error is still a
:class:`ServiceError` with its ``kind`` and ``status``; a refusal a retry would meet again (a
WebSocket handshake refused with 403) is not SLRUnavailable.

Every server here is a real ``slr serve`` process."""
from __future__ import annotations

import socket
import time

import pytest

import slr_sql
from slr_sql import SLRUnavailable
from slr_sql.service.errors import ServiceError

from service_helpers import ServiceProcess

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
    with socket.socket() as s:                 # a port nobody listens on
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
