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
import math
import socket
import ssl
import threading
import time
from typing import NamedTuple
from urllib.parse import quote, urlencode, urlsplit

__all__ = ["HttpPool", "HttpAnswer", "RequestNotSent", "AnswerLost", "AnswerTimeout",
           "RequestInvalid"]

# `slr serve` closes a keep-alive connection idle for 30 s (uvicorn's timeout_keep_alive);
# one idle for longer than this is closed here instead of raced against the server's close
IDLE_SECONDS = 15.0


class RequestNotSent(OSError):
    """The request did not reach the server whole (no connection, or it failed while the
    request was written): the server carried nothing out."""


class AnswerLost(OSError):
    """The request was sent whole, then the connection failed before a whole answer: the
    server may or may not have carried it out."""


class RequestInvalid(ValueError):
    """The request cannot be written as HTTP (a character a URL cannot carry): nothing was
    sent, and sending it again would fail the same way."""


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
        # (port 0 is a port: connecting to it is refused, as it should be, not port 80)
        self.port = parts.port if parts.port is not None else (443 if self.https else 80)
        # percent-encoded as a browser would (a space, UTF-8 beyond ASCII); what is already
        # encoded stays as it is
        self.prefix = quote(parts.path.rstrip("/"), safe="/%:@!$&'()*+,;=~")
        self.headers = dict(headers)
        self.tls = tls
        self.timeout = timeout
        self.connect_timeout = connect_timeout
        self.max_idle = max_idle
        self._idle: list[tuple[http.client.HTTPConnection, float]] = []
        self._busy: set[http.client.HTTPConnection] = set()   # carrying a request now
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
        now = time.monotonic()
        expired = []
        with self._lock:
            # the newest is reused first: close those idle too long (the server closes them
            # anyway), so that none sits half-closed in the list
            while self._idle and now - self._idle[0][1] >= IDLE_SECONDS:
                expired.append(self._idle.pop(0)[0])
            kept = not self.closed and len(self._idle) < self.max_idle
            if kept:
                self._idle.append((conn, now))
        for old in expired:
            old.close()
        if not kept:
            conn.close()

    # -- requests -------------------------------------------------------------------------------
    def request(self, method: str, path: str, content: bytes | None = None, *,
                params: dict[str, object] | None = None, timeout: float | None = None) -> HttpAnswer:
        """Send one request and read its whole answer (any status). Raises
        :class:`RequestNotSent`, :class:`AnswerLost`, :class:`AnswerTimeout`,
        :class:`RequestInvalid`, or ``RuntimeError`` once the pool is closed."""
        try:
            target = self.prefix + quote(path, safe="/%:@!$&'()*+,;=~") + \
                (f"?{urlencode(params)}" if params else "")
            target.encode("ascii")
        except (UnicodeError, TypeError) as exc:
            raise RequestInvalid(f"the request's path cannot be sent: {exc}") from None
        conn = self._connection()
        with self._lock:
            self._busy.add(conn)
        try:
            return self._exchange(conn, method, target, content, timeout)
        finally:
            with self._lock:
                self._busy.discard(conn)

    def _exchange(self, conn: http.client.HTTPConnection, method: str, target: str,
                  content: bytes | None, timeout: float | None) -> HttpAnswer:
        assert conn.sock is not None
        conn.sock.settimeout(_socket_timeout(self.timeout if timeout is None else timeout))
        headers = self.headers if content is None else \
            {**self.headers, "Content-Length": str(len(content))}
        try:
            conn.request(method, target, body=content, headers=headers)
        except TimeoutError:
            conn.close()
            raise RequestNotSent("the request could not be written in time") from None
        except (http.client.HTTPException, ValueError) as exc:   # (a header it refuses)
            conn.close()
            raise RequestInvalid(f"the request cannot be sent: {exc}") from None
        except OSError as exc:
            # the server may have answered before it closed (a 413 or 401 of a proxy that
            # does not read the body it refuses): that answer, if whole, is the outcome
            answer = _early_answer(conn)
            conn.close()
            if answer is not None:
                return answer
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
        """Close the idle connections, and end those in use: their requests (a long-poll of
        another thread, say) fail at once with :class:`AnswerLost` instead of holding the
        server's place until their answer."""
        with self._lock:
            self.closed = True
            idle, self._idle = self._idle, []
            busy = list(self._busy)
        for conn, _ in idle:
            conn.close()
        for conn in busy:
            sock = conn.sock
            if sock is not None:
                try:      # (wakes the thread reading it; that thread closes the connection)
                    sock.shutdown(socket.SHUT_RDWR)
                except OSError:
                    pass


def _socket_timeout(seconds: float) -> float | None:
    """A socket's timeout for ``seconds``: none for infinity, never 0 (which would make the
    socket non-blocking) nor negative."""
    if math.isinf(seconds) and seconds > 0:
        return None
    if not seconds > 0:      # (0, negative, NaN)
        return 0.001
    return seconds


def _early_answer(conn: http.client.HTTPConnection) -> HttpAnswer | None:
    """The whole answer a server sent before it stopped reading the request, if any."""
    try:
        response = conn.getresponse()
        return HttpAnswer(response.status, response.headers, response.read())
    except (OSError, http.client.HTTPException, ValueError):
        return None


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
