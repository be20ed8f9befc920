"""Keep-alive HTTP/1.1 connections from a client to one ``slr serve``, on the standard
library's ``http.client``, for any number of threads.

Why not a general HTTP client: a robot's component calls ``add_many`` hundreds of times a
second, and each call through httpx cost ~0.8-1 ms of the caller's CPU against ~0.25 ms for
the same request on ``http.client`` (benchmarks/bench_client_requests.py). The client talks
to one origin with JSON bodies and needs no redirects, cookies or proxies, so the pool is
small: idle connections kept for reuse, a connection that the server closed while idle
(or that idled longer than the server keeps one) never reused, and failures told apart by
what they say about the request — never sent (safe to retry), or sent with its answer lost
(the server may have carried it out).
"""
from __future__ import annotations

import http.client
import socket
import ssl
import threading
import time
from typing import NamedTuple
from urllib.parse import urlencode, urlsplit

__all__ = ["HttpPool", "HttpAnswer", "RequestNotSent", "AnswerLost", "AnswerTimeout"]

# `slr serve` closes a keep-alive connection idle for 30 s (uvicorn's timeout_keep_alive);
# one idle for longer than this is closed here instead of raced against the server's close
IDLE_SECONDS = 15.0


class RequestNotSent(OSError):
    """The request did not reach the server whole (no connection, or it failed while the
    request was written): the server carried nothing out."""


class AnswerLost(OSError):
    """The request was sent whole, then the connection failed before a whole answer: the
    server may or may not have carried it out."""


class AnswerTimeout(OSError):
    """No answer within the timeout (the request was sent, or connecting took too long)."""

    def __init__(self, message: str, sent: bool):
        super().__init__(message)
        self.sent = sent


class HttpAnswer(NamedTuple):
    """An HTTP answer, read whole."""

    status: int
    headers: http.client.HTTPMessage
    content: bytes

    @property
    def text(self) -> str:
        return self.content.decode("utf-8", "replace")


class HttpPool:
    """Requests to the origin of ``url`` (its path a prefix of every request's path) over
    keep-alive connections, at most ``max_idle`` kept idle; thread-safe.

    >>> import threading, http.server
    >>> class Hello(http.server.BaseHTTPRequestHandler):
    ...     protocol_version = "HTTP/1.1"
    ...     def do_GET(self):
    ...         body = b'{"hello": "' + self.path.encode() + b'"}'
    ...         self.send_response(200); self.send_header("Content-Length", str(len(body)))
    ...         self.end_headers(); self.wfile.write(body)
    ...     def log_message(self, *args): pass
    >>> server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Hello)
    >>> threading.Thread(target=server.serve_forever, daemon=True).start()
    >>> pool = HttpPool(f"http://127.0.0.1:{server.server_port}/api", headers={})
    >>> answer = pool.request("GET", "/health", params={"wait": 0}); answer.status, answer.content
    (200, b'{"hello": "/api/health?wait=0"}')
    >>> pool.close(); server.shutdown(); server.server_close()
    """

    def __init__(self, url: str, headers: dict[str, str], *, tls: ssl.SSLContext | None = None,
                 timeout: float = 60.0, connect_timeout: float = 10.0, max_idle: int = 32):
        parts = urlsplit(url)
        self.https = parts.scheme == "https"
        self.host = parts.hostname or ""
        self.port = parts.port or (443 if self.https else 80)
        self.prefix = parts.path.rstrip("/")
        self.headers = dict(headers)
        self.tls = tls
        self.timeout = timeout
        self.connect_timeout = connect_timeout
        self.max_idle = max_idle
        self._idle: list[tuple[http.client.HTTPConnection, float]] = []
        self._lock = threading.Lock()
        self.closed = False

    # -- connections ----------------------------------------------------------------------------
    def _new_connection(self) -> http.client.HTTPConnection:
        conn: http.client.HTTPConnection
        if self.https:
            conn = http.client.HTTPSConnection(self.host, self.port, timeout=self.connect_timeout,
                                               context=self.tls)
        else:
            conn = http.client.HTTPConnection(self.host, self.port, timeout=self.connect_timeout)
        try:
            conn.connect()
        except TimeoutError:
            conn.close()
            raise AnswerTimeout(f"no connection within {self.connect_timeout:g} s",
                                sent=False) from None
        except (OSError, ssl.SSLError) as exc:
            conn.close()
            raise RequestNotSent(str(exc)) from exc
        assert conn.sock is not None
        conn.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        return conn

    def _connection(self) -> http.client.HTTPConnection:
        """An idle connection still open, else a new one."""
        now = time.monotonic()
        while True:
            with self._lock:
                if self.closed:
                    raise RuntimeError("the pool is closed")
                if not self._idle:
                    break
                conn, since = self._idle.pop()
            if now - since < IDLE_SECONDS and not _dropped(conn):
                return conn
            conn.close()     # the server closed it (or will soon): readable means EOF here
        return self._new_connection()

    def _keep(self, conn: http.client.HTTPConnection) -> None:
        with self._lock:
            if not self.closed and len(self._idle) < self.max_idle:
                self._idle.append((conn, time.monotonic()))
                return
        conn.close()

    # -- requests -------------------------------------------------------------------------------
    def request(self, method: str, path: str, content: bytes | None = None, *,
                params: dict[str, object] | None = None, timeout: float | None = None) -> HttpAnswer:
        """Send one request and read its whole answer (any status). Raises
        :class:`RequestNotSent`, :class:`AnswerLost`, :class:`AnswerTimeout`, or
        ``RuntimeError`` once the pool is closed."""
        target = self.prefix + path + (f"?{urlencode(params)}" if params else "")
        conn = self._connection()
        assert conn.sock is not None
        conn.sock.settimeout(self.timeout if timeout is None else timeout)
        headers = self.headers if content is None else \
            {**self.headers, "Content-Length": str(len(content))}
        try:
            conn.request(method, target, body=content, headers=headers)
        except TimeoutError:
            conn.close()
            raise RequestNotSent("the request could not be written in time") from None
        except OSError as exc:
            conn.close()
            raise RequestNotSent(str(exc)) from exc
        try:
            response = conn.getresponse()
            body = response.read()
        except TimeoutError:
            conn.close()
            raise AnswerTimeout(f"no answer within {timeout or self.timeout:g} s",
                                sent=True) from None
        except (OSError, http.client.HTTPException) as exc:
            conn.close()
            raise AnswerLost(str(exc) or type(exc).__name__) from exc
        if response.will_close:
            conn.close()
        else:
            self._keep(conn)
        return HttpAnswer(response.status, response.headers, body)

    def close(self) -> None:
        """Close the idle connections; one in use closes when its request ends."""
        with self._lock:
            self.closed = True
            idle, self._idle = self._idle, []
        for conn, _ in idle:
            conn.close()


def _dropped(conn: http.client.HTTPConnection) -> bool:
    """An idle connection has nothing to read unless its server closed it (EOF) or broke
    the protocol: either way it must not carry another request. (A TLS 1.3 server's session
    tickets arrive after the handshake: reading them is no data, and keeps the connection.)"""
    sock = conn.sock
    if sock is None:
        return True
    sock.setblocking(False)
    try:
        # (a TLS socket takes no flags, and a byte read from it means a dead connection anyway)
        if isinstance(sock, ssl.SSLSocket):
            sock.recv(1)
        else:
            sock.recv(1, socket.MSG_PEEK)
    except (BlockingIOError, ssl.SSLWantReadError):
        return False          # nothing to read: still open
    except OSError:
        return True
    return True               # EOF (b"") or bytes nobody asked for
