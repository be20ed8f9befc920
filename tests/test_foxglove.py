"""slr foxglove DB: a real server process (the foxglove-sdk) and a real WebSocket client
speaking the Foxglove WebSocket protocol — advertise, subscribe, message data — while this
process writes the store through a connection of its own.

The protocol is foxglove.websocket.v1; foxglove-sdk 0.30 names it ``foxglove.sdk.v1`` in the
handshake (the same messages under a new name, Foxglove's discussion #1131) and refuses the
old name, so the client offers both, as current Foxglove does."""
from __future__ import annotations

import json
import os
import struct
import subprocess
import sys
import time
from pathlib import Path

import pytest
from websockets.sync.client import connect

import slr_sql
from slr_sql import Struct

REPO = Path(__file__).resolve().parent.parent
DEADLINE = 30.0
SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]


def pose(x: float, qz: float = 0.0, qw: float = 1.0) -> Struct:
    return Struct("pose", ([x, 0.0, 0.0], [0.0, 0.0, qz, qw]))


class FoxgloveClient:
    """A minimal foxglove.websocket.v1 client: collects advertised channels and message data."""

    def __init__(self, port: int):
        self.ws = connect(f"ws://127.0.0.1:{port}", subprotocols=SUBPROTOCOLS,
                          open_timeout=DEADLINE, max_size=None)
        assert self.ws.subprotocol in SUBPROTOCOLS
        self.channels: dict[str, dict] = {}
        self.by_id: dict[int, dict] = {}
        self.subscriptions: dict[int, str] = {}
        self.messages: list[tuple[str, int, dict]] = []
        self.info = None

    def __enter__(self) -> "FoxgloveClient":
        self.ws.__enter__()
        return self

    def __exit__(self, *exc) -> None:
        self.ws.__exit__(*exc)

    def pump(self, until, deadline: float) -> None:
        """Read frames until ``until()`` holds (or fail at the deadline)."""
        while not until():
            left = deadline - time.monotonic()
            assert left > 0, f"timed out; channels {sorted(self.channels)}, " \
                             f"{len(self.messages)} messages"
            try:
                frame = self.ws.recv(timeout=min(left, 1.0))
            except TimeoutError:
                continue
            if isinstance(frame, str):
                op = json.loads(frame)
                if op["op"] == "serverInfo":
                    self.info = op
                elif op["op"] == "advertise":
                    for ch in op["channels"]:
                        self.channels[ch["topic"]] = ch
                        self.by_id[ch["id"]] = ch
            else:
                assert frame[0] == 0x01, f"unexpected binary opcode {frame[0]}"
                sub, stamp = struct.unpack_from("<IQ", frame, 1)
                self.messages.append((self.subscriptions[sub], stamp, json.loads(frame[13:])))

    def read_for(self, seconds: float) -> None:
        """Read what arrives within ``seconds`` (a deadline, not a pause: frames are read)."""
        end = time.monotonic() + seconds
        try:
            self.pump(lambda: time.monotonic() >= end, end + 1.0)
        except AssertionError:
            pass

    def subscribe(self, *topics: str) -> None:
        subs = []
        for topic in topics:
            sub = len(self.subscriptions) + 1
            self.subscriptions[sub] = topic
            subs.append({"id": sub, "channelId": self.channels[topic]["id"]})
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    def on(self, topic: str) -> list[tuple[int, dict]]:
        return [(stamp, m) for t, stamp, m in self.messages if t == topic]


# The stores written here get a ManualClock: their events are stamped 0.0 to 7.0 (not
# wall-clock times, which would make each type's first event "decades late", a
# LearnedDelayWarning); the views read what is stored, not the writer's clock.
@pytest.fixture
def server(tmp_path):
    db = tmp_path / "robot.db"
    with slr_sql.open(db, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add_many([("seg", ("cup1", [0.4, 0.1, 0.9]), 1.0, 1.0),
                     ("tf_static", ("base", "cam", pose(0.5)), 0.0, 0.0),
                     ("tf", ("map", "base", pose(0.0)), 1.0, 1.0)])
        kb.load("relFace(F) <- face(F, _) seq face(F, _).")
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    process = subprocess.Popen([sys.executable, "-m", "slr_sql", "foxglove", str(db), "--port", "0"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    line = process.stdout.readline()
    assert line.startswith("foxglove: ws://127.0.0.1:"), process.stderr.read()
    port = int(line.split(":")[3].split()[0])
    yield db, port, process
    process.terminate()
    try:
        out, err = process.communicate(timeout=DEADLINE)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 0, err
    assert "Traceback" not in err
    # the SDK's log, in words, on stderr: the start (and each client, see the serve test)
    assert f"foxglove: listening on ws://127.0.0.1:{port}\n" in err, err


def test_channels_are_advertised_with_schemas_from_the_arguments(server):
    db, port, _ = server
    with FoxgloveClient(port) as client:
        check_advertised(client)


def check_advertised(client: FoxgloveClient) -> None:
    deadline = time.monotonic() + DEADLINE
    client.pump(lambda: {"/seg/2", "/tf/3", "/tf", "/tf_static", "/slr/completeness"}
                <= set(client.channels), deadline)
    seg = client.channels["/seg/2"]
    assert (seg["encoding"], seg["schemaName"], seg["schemaEncoding"]) == \
        ("json", "slr.seg/2", "jsonschema")
    schema = json.loads(seg["schema"])
    assert schema["properties"]["arg1"] == {"type": "string"}
    assert schema["properties"]["arg2"] == {"type": "array"}
    assert {"start", "end", "arrival"} <= set(schema["properties"])
    assert client.channels["/tf"]["schemaName"] == "foxglove.FrameTransforms"
    assert "transforms" in json.loads(client.channels["/tf"]["schema"])["properties"]


def test_live_events_from_another_process_reach_a_subscriber(server):
    db, port, _ = server
    with FoxgloveClient(port) as client:
        check_live(client, db)


def check_live(client: FoxgloveClient, db: Path) -> None:
    deadline = time.monotonic() + DEADLINE
    client.pump(lambda: {"/seg/2", "/tf", "/tf_static", "/slr/completeness"} <= set(client.channels),
                deadline)
    client.subscribe("/seg/2", "/tf", "/tf_static", "/slr/completeness")
    # the static frames are sent to a new subscriber of /tf_static (latched, as in ROS)
    client.pump(lambda: client.on("/tf_static"), deadline)
    (_, static), *_ = client.on("/tf_static")
    (frame,) = static["transforms"]
    assert (frame["parent_frame_id"], frame["child_frame_id"], frame["translation"]["x"]) == \
        ("base", "cam", 0.5)
    with slr_sql.open(db, clock=slr_sql.ManualClock(0.0)) as kb:   # a writer of its own (another connection)
        kb.add_many([("seg", ("cup2", [1.0, 2.0, 3.0]), 2.0, 2.5),
                     ("tf", ("map", "base", pose(1.5, 0.6, 0.8)), 3.25, 3.25)])
        kb.mark_complete("seg/2", 2.5)
        kb.add_many([("face", ("ann", 1), 4.0, 4.0), ("face", ("ann", 2), 5.0, 5.0)])
    client.pump(lambda: client.on("/seg/2") and client.on("/tf") and client.on("/slr/completeness")
                and "/relFace/1" in client.channels, deadline)
    (stamp, seg), = client.on("/seg/2")
    assert seg == {"arg1": "cup2", "arg2": [1.0, 2.0, 3.0], "start": 2.0, "end": 2.5,
                   "arrival": seg["arrival"]}
    assert stamp == 2_500_000_000      # the log time is the end time
    (stamp, tf), = client.on("/tf")
    assert stamp == 3_250_000_000
    (t,) = tf["transforms"]
    assert t["timestamp"] == {"sec": 3, "nsec": 250_000_000}
    assert (t["parent_frame_id"], t["child_frame_id"]) == ("map", "base")
    assert t["rotation"] == {"x": 0.0, "y": 0.0, "z": 0.6, "w": 0.8}
    (_, mark), = client.on("/slr/completeness")
    assert (mark["type"], mark["until"]) == ("seg/2", 2.5)
    # a complex event type derived in the writer's transaction is a channel of its own
    rel = client.channels["/relFace/1"]
    assert rel["schemaName"] == "slr.relFace/1"
    client.subscribe("/relFace/1")
    with slr_sql.open(db, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add_many([("face", ("bob", 1), 6.0, 6.0), ("face", ("bob", 2), 7.0, 7.0)])
    client.pump(lambda: client.on("/relFace/1"), deadline)
    assert [m["arg1"] for _, m in client.on("/relFace/1")] == ["bob"]


def test_a_port_in_use_is_a_clear_error(server, tmp_path):
    db, port, _ = server
    out = subprocess.run([sys.executable, "-m", "slr_sql", "foxglove", str(db),
                          "--port", str(port)], capture_output=True, text=True, timeout=DEADLINE,
                         env={**os.environ, "PYTHONPATH": str(REPO)})
    assert out.returncode == 1 and "error:" in out.stderr and "Traceback" not in out.stderr
    missing = subprocess.run([sys.executable, "-m", "slr_sql", "foxglove", str(tmp_path / "no.db")],
                             capture_output=True, text=True, timeout=DEADLINE,
                             env={**os.environ, "PYTHONPATH": str(REPO)})
    assert missing.returncode == 1 and "no such store" in missing.stderr
    assert not (tmp_path / "no.db").exists()


def test_slr_serve_with_foxglove_shows_what_clients_of_the_service_add(tmp_path):
    db = tmp_path / "served.db"
    with slr_sql.open(db, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add("seg(cup1, [0.0, 0.0, 0.0])^1")
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    process = subprocess.Popen([sys.executable, "-m", "slr_sql", "serve", str(db), "--port", "0",
                                "--foxglove", "--foxglove-port", "0"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        fox = process.stdout.readline()
        assert fox.startswith("slr serve: foxglove on ws://127.0.0.1:"), process.stderr.read()
        url = process.stdout.readline().split(" on ")[1].strip()
        with FoxgloveClient(int(fox.rsplit(":", 1)[1])) as client:
            deadline = time.monotonic() + DEADLINE
            client.pump(lambda: "/seg/2" in client.channels, deadline)
            client.subscribe("/seg/2")
            with slr_sql.connect(url) as remote:
                # subscribed before the add: the view sends what is stored from now on
                time_before = time.monotonic()
                while not client.on("/seg/2"):
                    remote.add(f"seg(cup2, [1.0, 2.0, 3.0])^{2 + time.monotonic() - time_before}")
                    client.pump(lambda: client.on("/seg/2") or time.monotonic() > time_before + 1,
                                deadline)
                    time_before = time.monotonic()
            (_, message), *_ = client.on("/seg/2")
            assert message["arg1"] == "cup2" and message["arg2"] == [1.0, 2.0, 3.0]
    finally:
        process.terminate()
        out, err = process.communicate(timeout=DEADLINE)
    assert process.returncode == 0, err


def test_a_postgresql_store_is_followed_too(postgres_url):
    with slr_sql.open(postgres_url, clock=slr_sql.ManualClock(10.0)) as kb:
        kb.add_many([("seg", ("cup1", [0.0, 0.0, 0.0]), 1.0, 1.0)])
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    process = subprocess.Popen([sys.executable, "-m", "slr_sql", "foxglove", postgres_url,
                                "--port", "0"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True, env=env)
    try:
        line = process.stdout.readline()
        assert line.startswith("foxglove: ws://"), process.stderr.read()
        with FoxgloveClient(int(line.split(":")[3].split()[0])) as client:
            deadline = time.monotonic() + DEADLINE
            client.pump(lambda: "/seg/2" in client.channels, deadline)
            client.subscribe("/seg/2")
            # the subscription takes effect at some point: add until a message comes back
            with slr_sql.open(postgres_url, clock=slr_sql.ManualClock(20.0)) as kb:
                n = 0
                while not client.on("/seg/2"):
                    assert time.monotonic() < deadline, "nothing delivered"
                    n += 1
                    kb.add_many([("seg", (f"cup{n + 1}", [1.0, 2.0, 3.0]), 2.0, 2.0)])
                    client.read_for(0.25)
            (_, message), *_ = client.on("/seg/2")
            assert message["arg1"] in {f"cup{i + 1}" for i in range(1, n + 1)}
            assert (message["arg2"], message["arrival"]) == ([1.0, 2.0, 3.0], 20.0)
    finally:
        process.terminate()
        out, err = process.communicate(timeout=DEADLINE)
    assert process.returncode == 0, err


class StderrLines:
    """The lines a process writes on stderr, read on a thread as they come, waited for with
    a deadline."""

    def __init__(self, process: subprocess.Popen):
        import threading

        self.lines: list[str] = []
        self.changed = threading.Condition()
        self.thread = threading.Thread(target=self._read, args=(process.stderr,), daemon=True)
        self.thread.start()

    def _read(self, stream) -> None:
        for line in stream:
            with self.changed:
                self.lines.append(line.rstrip("\n"))
                self.changed.notify_all()

    def wait_for(self, text: str) -> str:
        deadline = time.monotonic() + DEADLINE
        with self.changed:
            while True:
                for line in self.lines:
                    if text in line:
                        return line
                left = deadline - time.monotonic()
                assert left > 0, f"no line with {text!r} in {self.lines}"
                self.changed.wait(left)


def test_slr_serve_logs_the_foxglove_views_start_clients_and_errors_in_words(tmp_path):
    import sqlite3

    db = tmp_path / "served.db"
    with slr_sql.open(db, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add("seg(cup1, [0.0, 0.0, 0.0])^1")
        kb.add("a(1)^1")
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    process = subprocess.Popen([sys.executable, "-m", "slr_sql", "serve", str(db), "--port", "0",
                                "--foxglove", "--foxglove-port", "0"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        err = StderrLines(process)
        fox = process.stdout.readline()
        assert fox.startswith("slr serve: foxglove on ws://127.0.0.1:"), err.lines
        port = int(fox.rsplit(":", 1)[1])
        assert err.wait_for("foxglove: listening on") == \
            f"INFO:     foxglove: listening on ws://127.0.0.1:{port}"
        with FoxgloveClient(port) as client:
            client.pump(lambda: "/seg/2" in client.channels, time.monotonic() + DEADLINE)
            here = "127.0.0.1:%d" % client.ws.local_address[1]
            assert err.wait_for(f"client {here} connected") == \
                f"INFO:     foxglove: client {here} connected"
            # a stranger's bytes quoted in an error stay on their line
            client.ws.send(json.dumps({"op": "bogus\nINFO:     foxglove: forged"}))
            refused = err.wait_for("bogus")
        assert err.wait_for(f"client {here} left") == f"INFO:     foxglove: client {here} left"
        # the view's own trouble: a table dropped by hand, met at the next change
        with sqlite3.connect(db) as conn:
            conn.execute('DROP TABLE "a"')
        conn.close()
        with slr_sql.open(db, clock=slr_sql.ManualClock(0.0)) as kb:
            kb.add("seg(cup2, [0.0, 0.0, 0.0])^2")
        trouble = err.wait_for("a/1")
    finally:
        process.terminate()
        process.wait(timeout=DEADLINE)
        err.thread.join(timeout=DEADLINE)
    assert process.returncode == 0
    assert refused.startswith(f"ERROR:    foxglove: Invalid message from {here}: ")
    assert "bogus\\nINFO:     foxglove: forged" in refused
    assert not any(line.startswith("INFO:     foxglove: forged") for line in err.lines)
    assert trouble.startswith("WARNING:  foxglove: a/1: its rows cannot be read (no such "
                              "table"), trouble
    assert not any("Traceback" in line for line in err.lines), err.lines


def test_static_frames_named_by_equal_numbers_are_sent_apart(tmp_path):
    """Frames are names (docs/language.md, tf_lookup): 1 and 1.0, -0.0 and 0.0 are four
    frames, each with a static edge to base; the view kept the last value of each static
    edge by the raw values, where 1 == 1.0 and -0.0 == 0.0, and sent two of the four."""
    db = tmp_path / "frames.db"
    with slr_sql.open(db, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add_many([("tf_static", ("base", frame, pose(x)), 0.0, 0.0)
                     for frame, x in ((1, 1.0), (1.0, 2.0), (-0.0, 3.0), (0.0, 4.0))])
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    process = subprocess.Popen([sys.executable, "-m", "slr_sql", "foxglove", str(db), "--port",
                                "0"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               env=env)
    try:
        line = process.stdout.readline()
        assert line.startswith("foxglove: ws://127.0.0.1:"), process.stderr.read()
        port = int(line.split(":")[3].split()[0])
        deadline = time.monotonic() + DEADLINE
        with FoxgloveClient(port) as client:
            client.pump(lambda: "/tf_static" in client.channels, deadline)
            client.subscribe("/tf_static")
            client.pump(lambda: client.on("/tf_static"), deadline)
            (_, static), *_ = client.on("/tf_static")
    finally:
        process.terminate()
        process.communicate(timeout=DEADLINE)
    sent = sorted((t["child_frame_id"], t["translation"]["x"]) for t in static["transforms"])
    assert sent == [("-0.0", 3.0), ("0.0", 4.0), ("1", 1.0), ("1.0", 2.0)]
