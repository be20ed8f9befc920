"""A client that opens connections to `slr serve` and never finishes a request's headers (a
"slowloris"): uvicorn arms no timer before the headers are complete, so each such connection
was held for as long as the client liked, and --max-connections of them (1000 by default,
from one client) left every other client a 503 for as long as they stayed. Now a request's
headers have --request-timeout seconds (as its body has), from the connection's opening or
from the first byte of a later request on it; a connection that sends nothing is closed
after it. A WebSocket subscription, whose headers were complete, is not. A real `slr serve`."""
from __future__ import annotations

import socket
import time

import slr_sql
from service_helpers import HTTP, ServiceProcess

DEADLINE = 30.0


def closed_by_the_server(conn: socket.socket) -> bool:
    """Wait (until DEADLINE) for the server to close ``conn``, reading what it still sends
    (the rest of an earlier answer); True if it did."""
    end = time.monotonic() + DEADLINE
    try:
        while time.monotonic() < end:
            conn.settimeout(max(0.01, end - time.monotonic()))
            if conn.recv(4096) == b"":
                return True
    except socket.timeout:
        return False
    except ConnectionResetError:
        return True
    return False


def test_connections_that_never_finish_their_headers_are_closed(tmp_path):
    db = tmp_path / "robot.db"
    with slr_sql.open(db, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add("p(1)^1")
    with ServiceProcess(db, "--max-connections", "6", "--request-timeout", "0.5") as server, \
            slr_sql.connect(server.url) as client:
        sub = client.subscribe("p(X)^T", since=0)
        assert sub.get(timeout=DEADLINE)["X"] == 1
        host, port = server.url.split("//")[1].rsplit(":", 1)
        address = (host, int(port))
        slow = []
        for first in (b"POST /add HTTP/1.1\r\nHost: x\r\n", b"GET /hea", b""):
            conn = socket.create_connection(address)
            conn.sendall(first)
            slow.append(conn)
        kept_alive = socket.create_connection(address)   # a second request that stalls
        kept_alive.sendall(b"GET /health HTTP/1.1\r\nHost: x\r\n\r\n")
        kept_alive.settimeout(DEADLINE)
        assert kept_alive.recv(4096).startswith(b"HTTP/1.1 200")
        kept_alive.sendall(b"GET /health HTTP/1.1\r\n")
        slow.append(kept_alive)
        started = time.monotonic()
        try:
            assert all(closed_by_the_server(conn) for conn in slow)
        finally:
            for conn in slow:
                conn.close()
        assert time.monotonic() - started < DEADLINE
        assert HTTP.get(server.url + "/health", timeout=DEADLINE).status_code == 200
        # the subscription outlived the timeout: its connection's headers were complete
        client.add("p(2)^2")
        assert sub.get(timeout=DEADLINE)["X"] == 2
        sub.close()
