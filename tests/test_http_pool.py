"""slr_sql.service.http_pool: the client's keep-alive connections, against real servers on
real sockets (a threaded ``http.server`` that counts its connections, over plain TCP and TLS,
and raw socket servers that misbehave on purpose)."""
from __future__ import annotations

import http.server
import socket
import ssl
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Iterator

import pytest
import trustme

from service_helpers import listener_with_full_queue

from slr_sql.service import http_pool
from slr_sql.service.http_pool import AnswerLost, AnswerTimeout, HttpPool, RequestNotSent


class Echo(http.server.BaseHTTPRequestHandler):
    """Answers every request with its method, path and body; ``/close`` answers and then
    closes the connection without saying so (as a server restarting would)."""

    protocol_version = "HTTP/1.1"

    def _answer(self) -> None:
        length = int(self.headers.get("Content-Length") or 0)
        body = f"{self.command} {self.path} ".encode() + self.rfile.read(length)
        self.send_response(200)
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)
        self.wfile.flush()
        if self.path.endswith("/close"):
            self.close_connection = True

    do_GET = do_POST = _answer

    def log_message(self, *args: object) -> None:
        pass


class CountingServer(http.server.ThreadingHTTPServer):
    daemon_threads = True

    def __init__(self, tls: ssl.SSLContext | None = None):
        super().__init__(("127.0.0.1", 0), Echo)
        self.tls = tls
        self.connections = 0
        self.closed_one = threading.Event()     # a connection ended on the server's side

    def get_request(self) -> tuple[socket.socket, object]:
        sock, address = super().get_request()
        self.connections += 1
        if self.tls is not None:
            sock = self.tls.wrap_socket(sock, server_side=True)
        return sock, address

    def shutdown_request(self, request: socket.socket) -> None:   # type: ignore[override]
        super().shutdown_request(request)
        self.closed_one.set()


def _serving(server: CountingServer) -> Iterator[CountingServer]:
    thread = threading.Thread(target=server.serve_forever, args=(0.02,), daemon=True)
    thread.start()
    try:
        yield server
    finally:
        server.shutdown()
        server.server_close()


@pytest.fixture
def echo() -> Iterator[CountingServer]:
    yield from _serving(CountingServer())


@pytest.fixture(scope="module")
def ca() -> trustme.CA:
    return trustme.CA()


@pytest.fixture
def tls_echo(ca: trustme.CA) -> Iterator[CountingServer]:
    context = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
    ca.issue_cert("127.0.0.1").configure_cert(context)
    yield from _serving(CountingServer(context))


def url_of(server: CountingServer, scheme: str = "http") -> str:
    return f"{scheme}://127.0.0.1:{server.server_address[1]}"


def test_requests_share_one_kept_alive_connection(echo: CountingServer) -> None:
    pool = HttpPool(url_of(echo) + "/base/", headers={"Content-Type": "application/json"})
    answers = [pool.request("POST", "/add", b'{"n": %d}' % i, params={"wait": i})
               for i in range(20)]
    assert [a.content for a in answers] == \
        [b'POST /base/add?wait=%d {"n": %d}' % (i, i) for i in range(20)]
    assert all(a.status == 200 for a in answers)
    assert echo.connections == 1
    pool.close()


def test_tls_connections_are_kept_alive_too(tls_echo: CountingServer, ca: trustme.CA) -> None:
    # a TLS 1.3 server sends its session tickets after the handshake: read while the
    # connection idles, they must not make it look closed
    context = ssl.create_default_context()
    ca.configure_trust(context)
    pool = HttpPool(url_of(tls_echo, "https"), headers={}, tls=context)
    for i in range(5):
        assert pool.request("GET", f"/{i}").content == f"GET /{i} ".encode()
    assert tls_echo.connections == 1
    pool.close()


def test_a_connection_the_server_closed_while_idle_is_not_reused(echo: CountingServer) -> None:
    pool = HttpPool(url_of(echo), headers={})
    assert pool.request("GET", "/close").status == 200     # closed after its answer, unsaid
    assert echo.closed_one.wait(30)
    assert pool.request("GET", "/next").content == b"GET /next "
    assert echo.connections == 2


def test_a_connection_idle_longer_than_the_server_keeps_one_is_not_reused(
        echo: CountingServer, monkeypatch: pytest.MonkeyPatch) -> None:
    pool = HttpPool(url_of(echo), headers={})
    pool.request("GET", "/a")
    monkeypatch.setattr(http_pool, "IDLE_SECONDS", 0.0)   # every idle connection is too old
    pool.request("GET", "/b")
    assert echo.connections == 2


def test_threads_share_the_pool(echo: CountingServer) -> None:
    pool = HttpPool(url_of(echo), headers={}, max_idle=4)
    with ThreadPoolExecutor(8) as threads:
        bodies = list(threads.map(lambda i: pool.request("POST", "/t", b"%d" % i).content,
                                  range(200)))
    assert bodies == [b"POST /t %d" % i for i in range(200)]
    assert echo.connections <= 200 and len(pool._idle) <= 4
    pool.close()
    assert pool._idle == []
    with pytest.raises(RuntimeError):
        pool.request("GET", "/")


class RawServer:
    """One connection at a time: reads a whole request (head and Content-Length body), then
    does what ``behave`` says: "hang up" (closes without an answer), "silent" (keeps the
    connection open, never answers), "half" (half an answer, then closes)."""

    def __init__(self, behave: str):
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.behave = behave
        self.received = threading.Event()
        self.release = threading.Event()
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.sock.getsockname()[1]}"

    def _serve(self) -> None:
        conn, _ = self.sock.accept()
        with conn:
            data = b""
            while b"\r\n\r\n" not in data:
                data += conn.recv(65536)
            head, _, body = data.partition(b"\r\n\r\n")
            length = next((int(line.split(b":")[1]) for line in head.split(b"\r\n")
                           if line.lower().startswith(b"content-length:")), 0)
            while len(body) < length:
                body += conn.recv(65536)
            self.received.set()
            if self.behave == "half":
                conn.sendall(b"HTTP/1.1 200 OK\r\nContent-Length: 100\r\n\r\n{\"accep")
            elif self.behave == "silent":
                self.release.wait(30)

    def close(self) -> None:
        self.release.set()
        self.thread.join(30)
        self.sock.close()


@pytest.mark.parametrize("behave", ["hang up", "half"])
def test_a_request_sent_whose_answer_never_came_whole_is_an_answer_lost(behave: str) -> None:
    server = RawServer(behave)
    try:
        with pytest.raises(AnswerLost):
            HttpPool(server.url, headers={}).request("POST", "/add_many", b'{"events": []}')
        assert server.received.is_set()     # the server had the whole request
    finally:
        server.close()


def test_no_answer_within_the_timeout_is_an_answer_timeout_after_sending() -> None:
    server = RawServer("silent")
    try:
        with pytest.raises(AnswerTimeout) as raised:
            HttpPool(server.url, headers={}).request("GET", "/health", timeout=0.2)
        assert raised.value.sent and server.received.is_set()
    finally:
        server.close()


def test_nobody_listening_is_a_request_not_sent() -> None:
    # a port bound and not listening (refused), held meanwhile: closed first, it could be
    # another process's server's by the time the request connects
    with socket.socket() as placeholder:
        placeholder.bind(("127.0.0.1", 0))
        port = placeholder.getsockname()[1]
        with pytest.raises(RequestNotSent, match="refused"):
            HttpPool(f"http://127.0.0.1:{port}", headers={}).request("GET", "/health")


def test_no_connection_within_the_connect_timeout_is_an_answer_timeout_before_sending() -> None:
    with listener_with_full_queue() as port:
        with pytest.raises(AnswerTimeout) as raised:
            HttpPool(f"http://127.0.0.1:{port}", headers={}, connect_timeout=0.3).request(
                "GET", "/health")
        assert not raised.value.sent


def test_a_prefix_with_spaces_or_beyond_ascii_is_percent_encoded(echo: CountingServer) -> None:
    pool = HttpPool(url_of(echo) + "/my kb/é/already%20encoded", headers={})
    assert pool.request("GET", "/health").content == \
        b"GET /my%20kb/%C3%A9/already%20encoded/health "
    with pytest.raises(http_pool.RequestInvalid):      # nothing sent, and no retry helps
        pool.request("GET", "/x", params={"type": "p\ud800/1"})
    pool.close()


def test_port_0_is_port_0_not_the_schemes_default() -> None:
    assert HttpPool("http://127.0.0.1:0", headers={}).port == 0
    assert HttpPool("https://127.0.0.1:0/x", headers={}).port == 0
    with pytest.raises(RequestNotSent):
        HttpPool("http://127.0.0.1:0", headers={}).request("GET", "/health")


def test_an_answer_sent_before_the_server_stopped_reading_the_body_is_the_outcome() -> None:
    # a proxy refusing a body too large: it answers after the head and closes unread
    with socket.create_server(("127.0.0.1", 0)) as listener:
        def refuse() -> None:
            conn, _ = listener.accept()
            with conn:
                data = b""
                while b"\r\n\r\n" not in data:
                    data += conn.recv(65536)
                conn.sendall(b"HTTP/1.1 413 Payload Too Large\r\nContent-Length: 8\r\n"
                             b"Connection: close\r\n\r\ntoo big!")
        thread = threading.Thread(target=refuse, daemon=True)
        thread.start()
        pool = HttpPool(f"http://127.0.0.1:{listener.getsockname()[1]}", headers={})
        answer = pool.request("POST", "/add_many", b"x" * (16 << 20))
        thread.join(30)
    assert (answer.status, answer.content) == (413, b"too big!")


def test_connections_idle_too_long_are_closed_when_another_is_kept(
        echo: CountingServer, monkeypatch: pytest.MonkeyPatch) -> None:
    pool = HttpPool(url_of(echo), headers={})
    first, second = pool._connection(), pool._connection()
    pool._keep(first)
    monkeypatch.setattr(http_pool, "IDLE_SECONDS", 0.0)
    pool._keep(second)            # first has idled "too long": closed now, not left half-open
    assert [conn for conn, _ in pool._idle] == [second] and first.sock is None
    pool.close()


@pytest.mark.parametrize("seconds, socket_timeout", [
    (5.0, 5.0), (float("inf"), None), (0.0, 0.001), (-60.0, 0.001), (float("nan"), 0.001)])
def test_a_timeout_never_makes_the_socket_non_blocking(seconds: float,
                                                       socket_timeout: float | None) -> None:
    assert http_pool._socket_timeout(seconds) == socket_timeout
