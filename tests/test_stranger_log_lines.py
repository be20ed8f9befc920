r"""Log lines a stranger can make happen (slr_sql/log_throttle.py, docs/printed_text.md).

A client of `slr serve` or of the Foxglove view, or a publisher on a bridged ROS topic, can
make the process log a line per connection or message: bytes that are no HTTP, a WebSocket
text frame that is no UTF-8 (uvicorn logged it with a traceback), a client connecting and
leaving, a message that does not map. Each such line is one line (a line break in the
stranger's text escaped, not a new line), at most LOG_TEXT_LIMIT characters of its text,
without traceback, and at most BURST lines of a kind a minute, the next one let through
saying how many were left out. Real server processes where the suite starts them; the
throttle's time from a ManualClock.
"""
from __future__ import annotations

import base64
import io
import json
import logging
import os
import socket
import subprocess
import sys

import pytest
from service_helpers import ServiceProcess, slr_env

import slr_sql
from slr_sql.clocks import ManualClock
from slr_sql.log_throttle import BURST, ThrottledLog, ThrottledLogFilter
from slr_sql.printable import LOG_TEXT_LIMIT

DEADLINE = 30.0


def lines_with(log_text: str, words: str) -> list[str]:
    return [line for line in log_text.splitlines() if words in line]


@pytest.fixture
def served(tmp_path):
    db = tmp_path / "served.db"
    with slr_sql.open(db, clock=ManualClock(0.0)) as kb:
        kb.add("seen(a)^1")
    with ServiceProcess(db) as server:
        yield server


def _port(server) -> int:
    return int(server.url.rsplit(":", 1)[1])


def test_bytes_that_are_no_http_are_logged_at_most_burst_times(served):
    for _ in range(3 * BURST):
        with socket.create_connection(("127.0.0.1", _port(served)), timeout=DEADLINE) as s:
            s.sendall(b"NOT HTTP\x1b]0;owned\x07\r\n\r\n")
            assert s.recv(100).startswith(b"HTTP/1.1 400")   # (said in the log before it)
    assert served.healthy()
    said = lines_with(served.log.read_text(), "Invalid HTTP request received.")
    assert len(said) == BURST, said


def test_a_websocket_text_frame_that_is_no_utf8_is_one_line_without_traceback(served):
    key = base64.b64encode(os.urandom(16)).decode()
    with socket.create_connection(("127.0.0.1", _port(served)), timeout=DEADLINE) as s:
        s.sendall(f"GET /subscribe HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\n"
                  f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
                  f"Sec-WebSocket-Version: 13\r\n\r\n".encode())
        assert s.recv(1000).startswith(b"HTTP/1.1 101")
        payload = b"\xff\xfe"
        s.sendall(bytes([0x81, 0x80 | len(payload)]) + b"\0\0\0\0" + payload)   # text, masked
        assert s.recv(100)[:1] == b"\x88"          # the server's close frame (1007)
    log = served.log.read_text()
    assert "Traceback" not in log, log
    said = lines_with(log, "Invalid UTF-8 sequence received from client.")
    assert len(said) == 1 and "(UnicodeDecodeError: " in said[0], log


def test_foxglove_clients_connecting_and_leaving_in_a_loop_are_logged_at_most_burst_times(
        tmp_path):
    from test_foxglove import FoxgloveClient, StderrLines
    from websockets.sync.client import connect

    db = tmp_path / "robot.db"
    with slr_sql.open(db, clock=ManualClock(0.0)) as kb:
        kb.add("seen(a)^1")
    process = subprocess.Popen([sys.executable, "-m", "slr_sql", "foxglove", str(db), "--port", "0"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               env=slr_env())
    try:
        err = StderrLines(process)
        port = int(process.stdout.readline().split(":")[3].split()[0])
        for _ in range(3 * BURST):
            with FoxgloveClient(port):
                pass
        # the last client's bad message: a line after every earlier client's
        with connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1",
                                                             "foxglove.websocket.v1"],
                     open_timeout=DEADLINE) as last:
            last.send(json.dumps({"op": "bogus\nforged line"}))
            refused = err.wait_for("bogus")
    finally:
        process.terminate()
        process.wait(timeout=DEADLINE)
        err.thread.join(timeout=DEADLINE)
    assert "bogus\\nforged line" in refused
    connected = [line for line in err.lines if line.endswith(" connected")]
    assert len(connected) == BURST, err.lines
    assert not any(line.startswith("forged line") for line in err.lines)


def test_input_the_service_refused_is_one_bounded_line():
    from slr_sql.service.app import _classify

    out = io.StringIO()
    log = logging.getLogger("slr_sql.service")
    handler = logging.StreamHandler(out)
    log.addHandler(handler)
    try:
        _classify(ValueError("bad\nWARNING: forged\x1b]0;owned\x07" + "x" * 10_000))
    finally:
        log.removeHandler(handler)
    line = out.getvalue()
    assert line.count("\n") == 1 and "\x1b" not in line, line
    assert "bad\\nWARNING: forged\\x1B\\]0;owned\\a" in line
    assert len(line) < LOG_TEXT_LIMIT + 100 and "more characters)" in line


def test_the_filter_counts_the_lines_it_left_out_and_says_so_when_the_minute_is_over():
    clock = ManualClock(0.0)
    out = io.StringIO()
    log = logging.getLogger("slr_sql.test.throttled")
    log.propagate = False
    handler = logging.StreamHandler(out)
    log.addHandler(handler)
    log.addFilter(ThrottledLogFilter(clock, burst=3, period=60.0))
    try:
        for n in range(10):
            log.warning("client %s: bad bytes", n)
        clock.advance(59.0)
        log.warning("client %s: bad bytes", "late")      # the same minute: left out too
        log.warning("another kind of line")              # its own budget
        clock.advance(1.0)
        log.warning("client %s: bad bytes", "next\nforged")
    finally:
        log.removeHandler(handler)
    assert out.getvalue().splitlines() == [
        "client 0: bad bytes", "client 1: bad bytes", "client 2: bad bytes",
        "another kind of line",
        "client next\\nforged: bad bytes (8 lines like it left out before)"]


def test_a_client_s_traceback_is_left_out_and_a_bug_s_kept():
    out = io.StringIO()
    log = logging.getLogger("slr_sql.test.tracebacks")
    log.propagate = False
    handler = logging.StreamHandler(out)
    log.addHandler(handler)
    log.addFilter(ThrottledLogFilter(ManualClock(0.0)))
    try:
        for message in ("Invalid UTF-8 sequence received from client.", "internal error"):
            try:
                b"\xff".decode()
            except UnicodeDecodeError:
                log.exception(message)
    finally:
        log.removeHandler(handler)
    text = out.getvalue()
    assert text.startswith("Invalid UTF-8 sequence received from client. (UnicodeDecodeError: "
                           "'utf-8' codec can't decode byte 0xff in position 0: invalid start "
                           "byte)\ninternal error\nTraceback (most recent call last):\n"), text


def test_throttled_log_of_a_function_bounds_and_escapes_each_line():
    clock = ManualClock(0.0)
    lines: list[str] = []
    say = ThrottledLog(lines.append, clock, burst=2)
    for n in range(5):
        say(f"warning: /pose: message rejected: frame {n}\x1b]0;owned\x07\n" + "x" * 1000)
    assert len(lines) == 2
    assert all("\n" not in line and "\x1b" not in line and len(line) < LOG_TEXT_LIMIT + 40
               for line in lines), lines
