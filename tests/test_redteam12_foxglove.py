"""Red team of the live Foxglove view (docs/ros.md, "Foxglove live view"): a client that
connects, subscribes and then never reads must not keep ``slr foxglove`` from stopping.

The foxglove-sdk's ``WebSocketServer.stop()`` closes each client gracefully: it waits until
the close frame is written to the client's socket. A client that never reads fills its TCP
buffers with data messages, the close frame is never taken, and ``stop()`` waits forever: a
SIGTERM'ed ``slr foxglove`` (or ``slr serve --foxglove``) never exits. Real server process,
real WebSocket clients (one that reads, one that does not)."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from websockets.sync.client import connect

import slr_sql
from test_foxglove import DEADLINE, SUBPROTOCOLS, FoxgloveClient

REPO = Path(__file__).resolve().parent.parent
# enough data that the silent client's socket buffers and the server's backlog fill up
BIG = "x" * 10_000
EVENTS = 3_000


def silent_client(port: int):
    """A client that never reads once subscribed (no keepalive pings either, so its own
    library never closes the connection for it)."""
    return connect(f"ws://127.0.0.1:{port}", subprotocols=SUBPROTOCOLS, open_timeout=DEADLINE,
                   ping_interval=None, max_size=None, close_timeout=1.0)


def subscribe(ws, topic: str) -> None:
    channels: dict[str, int] = {}
    deadline = time.monotonic() + DEADLINE
    while topic not in channels:
        assert time.monotonic() < deadline, f"{topic} never advertised"
        frame = ws.recv(timeout=DEADLINE)
        if isinstance(frame, str):
            op = json.loads(frame)
            if op["op"] == "advertise":
                channels.update({ch["topic"]: ch["id"] for ch in op["channels"]})
    ws.send(json.dumps({"op": "subscribe",
                        "subscriptions": [{"id": 1, "channelId": channels[topic]}]}))


def test_a_client_that_never_reads_does_not_keep_the_view_from_stopping(tmp_path):
    db = tmp_path / "robot.db"
    with slr_sql.open(db, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add_many([("seg", ("cup1", [0.4]), 1.0, 1.0)])
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    process = subprocess.Popen([sys.executable, "-m", "slr_sql", "foxglove", str(db),
                                "--port", "0"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True, env=env)
    try:
        line = process.stdout.readline()
        assert line.startswith("foxglove: ws://127.0.0.1:"), process.stderr.read()
        port = int(line.split(":")[3].split()[0])
        with silent_client(port) as silent, FoxgloveClient(port) as reader:
            subscribe(silent, "/seg/2")
            reader.pump(lambda: "/seg/2" in reader.channels, time.monotonic() + DEADLINE)
            reader.subscribe("/seg/2")
            with slr_sql.open(db, clock=slr_sql.ManualClock(0.0)) as kb:
                kb.add_many([("seg", (BIG, [float(i)]), 2.0, 2.0) for i in range(EVENTS)])
                kb.add_many([("seg", ("last", [0.0]), 3.0, 3.0)])
            # the view has sent everything (to both clients) once the reader has the last one
            reader.pump(lambda: any(m["arg1"] == "last" for _, m in reader.on("/seg/2")),
                        time.monotonic() + DEADLINE)
            process.send_signal(signal.SIGTERM)
            try:
                out, err = process.communicate(timeout=DEADLINE)
            except subprocess.TimeoutExpired:
                raise AssertionError("slr foxglove did not stop while a client did not "
                                     "read") from None
        assert process.returncode == 0, err
        assert "foxglove: stopped after" in out
        assert "did not read" in err        # said once, in words
        assert "Traceback" not in err
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
