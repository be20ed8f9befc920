"""Helpers of the service tests: a real `python -m slr_sql serve` process, and term equality.

The server is started on port 0 (the kernel picks a free port, so parallel runs never
collide) and prints ``slr serve: DB on http://HOST:PORT`` once it listens; the tests read that
line (waiting on a queue, with a deadline), then wait for ``/health`` in a deadline loop.
"""
from __future__ import annotations

import contextlib
import math
import os
import queue
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Iterator

import httpx

from slr_sql import Struct, Var

ROOT = Path(__file__).resolve().parent.parent
START_DEADLINE = 30.0


def slr_env(extra: dict | None = None) -> dict:
    env = dict(os.environ)
    # the current test's id, which a long parametrized id makes longer than the kernel takes
    # for one string of a new program's environment (Argument list too long): a module's
    # server started in the setup of such a test would not start (conftest.server_environment)
    env.pop("PYTEST_CURRENT_TEST", None)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    env.pop("SLR_TOKEN", None)
    env["COLUMNS"] = "200"
    env.setdefault("SLR_HISTORY", os.devnull)
    if extra:
        env.update(extra)
    return env


# The tests' plain-HTTP requests go through one client: httpx.get() and the like build a client
# per call, and each loads the CA bundle for TLS (~70 ms of CPU) that an http:// URL never
# uses. No keep-alive: each request opens its own connection, as those functions do.
HTTP = httpx.Client(verify=False, limits=httpx.Limits(max_keepalive_connections=0))


class ServiceProcess:
    """``with ServiceProcess(db, "--token", "t") as server: server.url``; ``log``: where the
    server's stderr goes (default: beside the file, ``DB.server.log``; give it for a
    PostgreSQL URL)."""

    def __init__(self, db: Path | str, *args: str, env: dict | None = None,
                 log: Path | None = None):
        self.db = str(db)
        self.log = Path(str(db) + ".server.log") if log is None else Path(log)   # log=: for a PostgreSQL URL
        self._log_handle = open(self.log, "wb")
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "slr_sql", "serve", self.db, "--port", "0", *args],
            stdout=subprocess.PIPE, stderr=self._log_handle, stdin=subprocess.DEVNULL,
            env=slr_env(env), cwd=ROOT)
        lines: queue.Queue = queue.Queue()
        threading.Thread(target=lambda: lines.put(self.proc.stdout.readline()),
                         daemon=True).start()
        try:
            first = lines.get(timeout=START_DEADLINE).decode()
        except queue.Empty:
            self.stop()
            raise RuntimeError(f"slr serve did not start: {self.log.read_text()}") from None
        if " on http" not in first:
            self.stop()
            raise RuntimeError(f"slr serve failed: {first!r} {self.log.read_text()}")
        self.first_line = first
        self.url = first.strip().rsplit(" on ", 1)[1]
        self.wait_healthy()

    def wait_healthy(self) -> None:
        deadline = time.monotonic() + START_DEADLINE
        while True:
            try:
                if HTTP.get(self.url + "/health", timeout=5).status_code == 200:
                    return
            except httpx.HTTPError:
                if time.monotonic() > deadline or self.proc.poll() is not None:
                    raise RuntimeError(f"slr serve is not healthy: {self.log.read_text()}")
                time.sleep(0.02)

    def healthy(self) -> bool:
        try:
            return HTTP.get(self.url + "/health", timeout=10).json()["status"] == "ok"
        except httpx.HTTPError:
            return False

    def kill(self) -> None:
        """SIGKILL: no shutdown code runs."""
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(timeout=30)
        self._close()

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=15)
        self._close()

    def _close(self) -> None:
        if self.proc.stdout is not None:
            self.proc.stdout.close()
        self._log_handle.close()

    def __enter__(self) -> "ServiceProcess":
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


def same(a, b, names: dict | None = None) -> bool:
    """Terms equal with their Python types (Atom vs String vs str, 1 vs 1.0, -0.0 vs 0.0,
    NaN equal to NaN), variables by name."""
    names = {} if names is None else names
    if type(a) is not type(b):
        return False
    if type(a) is float:
        return (math.isnan(a) and math.isnan(b)) or (a == b and math.copysign(1, a) == math.copysign(1, b))
    if type(a) is list:
        return len(a) == len(b) and all(same(x, y, names) for x, y in zip(a, b))
    if type(a) is Struct:
        return a.name == b.name and len(a.args) == len(b.args) and \
            all(same(x, y, names) for x, y in zip(a.args, b.args))
    if type(a) is Var:
        return names.setdefault(a.name, b.name) == b.name
    return a == b


def complete_only_as_marked(kb, *types: str) -> None:
    """Declare each ``name/arity`` complete only as far as it is marked (a max_delay beyond any
    clock): with a wall-clock server, events stamped 1, 2, 3 ... would otherwise count as
    arrived ~1.8e9 s late, and their types as complete up to now - max_learned_delay."""
    kb.load(" ".join(f":- max_delay({t}, 1e10)." for t in types),
            name="delays-" + "-".join(types))


class DroppingServer:
    """A real TCP server (a thread) standing for an ``slr serve`` that dies once a request
    that writes has reached it: it answers ``GET`` with ``get_body`` (JSON, 200), and reads
    every other request in full (headers and body) and closes the connection without a word
    -- but where ``script`` says ``a`` (one letter per such request, in order: ``a`` answer
    with ``post_body``, ``d`` drop, ``s`` say nothing until the client closes; beyond it,
    drop). ``dropped`` counts those it left unanswered; ``received`` is set at the first."""

    def __init__(self, get_body: bytes = b'{"status": "ok", "limits": {}}',
                 script: str = "", post_body: bytes = b'{}'):
        import socket as socket_module
        self.get_body = get_body
        self.script = list(script)
        self.post_body = post_body
        self.dropped = 0
        self.received = threading.Event()
        self._listener = socket_module.create_server(("127.0.0.1", 0))
        self.url = f"http://127.0.0.1:{self._listener.getsockname()[1]}"
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        while True:
            try:
                conn, _ = self._listener.accept()
            except OSError:          # closed: the test is over
                return
            with conn:
                self._one(conn)

    def _one(self, conn) -> None:
        data = b""
        while b"\r\n\r\n" not in data:
            chunk = conn.recv(65536)
            if not chunk:
                return
            data += chunk
        head, _, body = data.partition(b"\r\n\r\n")
        length = 0
        for line in head.split(b"\r\n")[1:]:
            name, _, value = line.partition(b":")
            if name.strip().lower() == b"content-length":
                length = int(value)
        while len(body) < length:
            chunk = conn.recv(65536)
            if not chunk:
                return
            body += chunk
        if head.startswith(b"GET "):
            answer: bytes | None = self.get_body
        else:
            step = self.script.pop(0) if self.script else "d"
            answer = self.post_body if step == "a" else None
        if answer is not None:
            conn.sendall(b"HTTP/1.1 200 OK\r\nContent-Type: application/json\r\n"
                         b"Connection: close\r\nContent-Length: %d\r\n\r\n%s"
                         % (len(answer), answer))
            return
        self.dropped += 1
        self.received.set()          # (then the connection closes unanswered, or for "s"
        if step == "s":              # stays silent until the client gives up and closes)
            try:
                while conn.recv(65536):
                    pass
            except OSError:
                pass

    def __enter__(self) -> "DroppingServer":
        return self

    def __exit__(self, *exc) -> None:
        import socket as socket_module
        try:
            self._listener.shutdown(socket_module.SHUT_RDWR)   # (wakes the accept)
        except OSError:
            pass
        self._listener.close()
        self._thread.join(START_DEADLINE)


@contextlib.contextmanager
def reserved_port() -> Iterator[int]:
    """A port of 127.0.0.1 held for the test, on which nobody listens until ``slr serve
    --port PORT`` does: bound with SO_REUSEADDR and not listening. Linux refuses a connection
    to it (no listener), gives it to no other socket (``bind`` to port 0 and outgoing
    connections skip a bound port; a bind to it without SO_REUSEADDR is refused), and lets a
    socket with SO_REUSEADDR (the server's, ``listen_on``) bind and listen beside it -- again
    after that server died. A port closed first and served later could be another worker's
    server's meanwhile (``with reserved_port() as port: ServiceProcess(db, "--port",
    str(port))``)."""
    with socket.socket() as placeholder:
        placeholder.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        placeholder.bind(("127.0.0.1", 0))
        yield placeholder.getsockname()[1]


@contextlib.contextmanager
def listener_with_full_queue() -> Iterator[int]:
    """The port of a listening socket whose accept queue is full: the kernel drops the next
    connection attempt, so connecting to it times out (nothing reaches a server)."""
    with socket.socket() as listener:
        listener.bind(("127.0.0.1", 0))
        listener.listen(0)         # one connection queued at most (Linux)
        port = listener.getsockname()[1]
        queued = []
        try:
            while True:
                s = socket.socket()
                queued.append(s)
                s.settimeout(0.3)
                s.connect(("127.0.0.1", port))
        except OSError:
            pass
        try:
            yield port
        finally:
            for s in queued:
                s.close()
