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

import pytest
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


def view_port(process: subprocess.Popen) -> int:
    """The port `slr foxglove` says it listens on, from its first line."""
    line = process.stdout.readline()
    assert line.startswith("foxglove: ws://127.0.0.1:"), process.stderr.read()
    return int(line.split(":")[3].split()[0])


def stop_view(process: subprocess.Popen) -> str:
    """SIGTERM to a view's process, and its stderr once it ended."""
    process.send_signal(signal.SIGTERM)
    return process.communicate(timeout=DEADLINE)[1]


def kill_if_running(process: subprocess.Popen) -> None:
    """(A test that failed before it stopped the view leaves no process behind.)"""
    if process.poll() is None:
        process.kill()
        process.communicate()


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
    process = subprocess.Popen([sys.executable, "-m", "slr_sql", "foxglove", str(db),
                                "--port", "0"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True, env={**os.environ, "PYTHONPATH": str(REPO)})
    try:
        port = view_port(process)
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


def test_a_client_subscribing_to_tf_static_again_and_again_reads_no_history(tmp_path):
    """The latched /tf_static message (the last pose of each static edge) was made by reading
    every stored tf_static row, at each subscription to /tf_static and every 5 s: a store
    whose /tf_static was published at 10 Hz for a day has 864,000 of them (seconds a read),
    and any client could make the view do it in a loop. Now the view keeps the last row of
    each edge as rows arrive: a subscription reads nothing (the view's own connection is
    traced: no statement on tf_static runs), and the message is the same."""
    from slr_sql.viz.foxglove_live import FoxgloveView
    from test_foxglove import pose

    db = tmp_path / "robot.db"
    with slr_sql.open(db, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add_many([("tf_static", ("base", f"cam{i % 3}", pose(float(i))), float(i), float(i))
                     for i in range(3000)])
    view_kb = slr_sql.open(db, clock=slr_sql.ManualClock(0.0))
    statements: list[str] = []
    view = FoxgloveView(view_kb.store, port=0, static_every=3600.0)
    view_kb.store._db.conn.set_trace_callback(
        lambda sql: statements.append(sql) if "tf_static" in sql else None)
    view.start()
    try:
        with FoxgloveClient(view.port) as client:
            deadline = time.monotonic() + DEADLINE
            client.pump(lambda: "/tf_static" in client.channels, deadline)
            channel = client.channels["/tf_static"]["id"]
            for n in range(1, 6):
                client.subscriptions[n] = "/tf_static"
                client.ws.send(json.dumps({"op": "subscribe",
                                           "subscriptions": [{"id": n, "channelId": channel}]}))
                client.pump(lambda: len(client.on("/tf_static")) >= n, deadline)
                client.ws.send(json.dumps({"op": "unsubscribe", "subscriptionIds": [n]}))
            last = client.on("/tf_static")[-1][1]
        # a static edge stored later still reaches the next subscriber
        with slr_sql.open(db, clock=slr_sql.ManualClock(0.0)) as kb:
            kb.add_many([("tf_static", ("base", "cam1", pose(-1.0)), 5000.0, 5000.0)])
        with FoxgloveClient(view.port) as late:
            deadline = time.monotonic() + DEADLINE
            late.pump(lambda: "/tf_static" in late.channels, deadline)

            def has_new_cam1() -> bool:
                return any(t["child_frame_id"] == "cam1" and t["translation"]["x"] == -1.0
                           for _, m in late.on("/tf_static") for t in m["transforms"])

            while not has_new_cam1():
                assert time.monotonic() < deadline, late.on("/tf_static")
                late.messages.clear()
                n = len(late.subscriptions) + 1
                late.subscriptions[n] = "/tf_static"
                late.ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                    {"id": n, "channelId": late.channels["/tf_static"]["id"]}]}))
                late.pump(lambda: bool(late.on("/tf_static")), deadline)
                late.ws.send(json.dumps({"op": "unsubscribe", "subscriptionIds": [n]}))
            final = [m for _, m in late.on("/tf_static")][-1]
    finally:
        view.close()
        view_kb.close()
    assert sorted((t["child_frame_id"], t["translation"]["x"]) for t in last["transforms"]) \
        == [("cam0", 2997.0), ("cam1", 2998.0), ("cam2", 2999.0)]
    assert sorted((t["child_frame_id"], t["translation"]["x"]) for t in final["transforms"]) \
        == [("cam0", 2997.0), ("cam1", -1.0), ("cam2", 2999.0)]
    full_reads = [s for s in statements if "seq >" not in s and "seq>" not in s]
    assert full_reads == [], full_reads


def test_one_type_that_cannot_be_read_does_not_stop_the_view_of_the_others(tmp_path):
    """The view reads the types one after the other in one pass; a type whose rows could
    not be read (its table dropped by hand: "no such table") ended every pass there, so the
    types after it were never sent again, and the failure was logged at every change of the
    store. Now the other types go on and the failure is said once."""
    import sqlite3

    from slr_sql.viz.foxglove_live import FoxgloveView

    db = tmp_path / "robot.db"
    with slr_sql.open(db, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add_many([("a", (1,), 1.0, 1.0), ("z", (1,), 1.0, 1.0)])
    view_kb = slr_sql.open(db, clock=slr_sql.ManualClock(0.0))
    lines: list[str] = []
    view = FoxgloveView(view_kb.store, port=0, log=lines.append).start()
    try:
        with FoxgloveClient(view.port) as client:
            deadline = time.monotonic() + DEADLINE
            client.pump(lambda: "/z/1" in client.channels, deadline)
            client.subscribe("/z/1")
            with sqlite3.connect(db) as conn:
                conn.execute('DROP TABLE "a"')
            with slr_sql.open(db, clock=slr_sql.ManualClock(0.0)) as kb:
                for i in range(2, 7):
                    kb.add_many([("z", (i,), float(i), float(i))])
            client.pump(lambda: [m["arg1"] for _, m in client.on("/z/1")] == [2, 3, 4, 5, 6],
                        deadline)
            # rows written by hand that are no events (a NULL argument) are left out, the
            # rows around them are sent
            with sqlite3.connect(db) as conn:
                conn.execute('INSERT INTO "z" (arg1, t_start, t_end, arrival) VALUES '
                             '(NULL, 7.0, 7.0, 0.0), (8, 8.0, 8.0, 0.0), (NULL, 9.0, 9.0, 0.0)')
            client.pump(lambda: [m["arg1"] for _, m in client.on("/z/1")][-1:] == [8],
                        deadline)
    finally:
        view.close()
        view_kb.close()
    about_a = [line for line in lines if "a/1" in line]
    assert len(about_a) == 1, lines
    assert "no such table" in about_a[0] and "OperationalError" not in about_a[0]
    about_z = [line for line in lines if "z/1" in line]
    assert about_z == ["foxglove: z/1: rows that are not events are left out (NULL is not a "
                       "stored term)"], lines


def test_a_port_in_use_or_a_host_that_does_not_resolve_is_said_in_words(tmp_path):
    """The foxglove-sdk raises RuntimeError (not OSError) when it cannot bind: the command
    printed "RuntimeError: FoxgloveError: Failed to bind port ... (this is a bug in
    slr_sql ...)"."""
    import socket

    db = tmp_path / "robot.db"
    with slr_sql.open(db, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add_many([("p", (1,), 1.0, 1.0)])
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        for args, said in (
                (["--port", str(port)],
                 f"error: cannot listen on 127.0.0.1:{port}: Failed to bind port: Address "
                 f"already in use"),
                (["--host", "no-such-host.invalid", "--port", "0"],
                 "error: cannot listen on no-such-host.invalid:0: Failed to bind port")):
            result = subprocess.run([sys.executable, "-m", "slr_sql", "foxglove", str(db), *args],
                                    capture_output=True, text=True, env=env, timeout=DEADLINE)
            assert result.returncode == 1, result
            assert said in result.stderr, result.stderr
            assert "bug" not in result.stderr and "RuntimeError" not in result.stderr


def test_a_client_subscribing_to_tf_static_in_a_loop_does_not_flood_the_others(tmp_path):
    """Each subscription to /tf_static made the view send the latched message (every static
    edge) to every subscriber of /tf_static at its next pass: one client subscribing and
    unsubscribing in a loop kept the view's thread busy building it, sent the others one
    every few milliseconds (here ~250 in 1.6 s; with 2,000 edges, messages of 200 KB) and made
    their live events late (60 ms instead of 3). Now it is sent at most every STATIC_GAP
    seconds when asked, whoever asks; a late subscriber still gets it."""
    from slr_sql.viz import foxglove_live
    from slr_sql.viz.foxglove_live import FoxgloveView
    from test_foxglove import pose

    gap = 0.25   # (foxglove_live.STATIC_GAP, checked last)
    db = tmp_path / "robot.db"
    with slr_sql.open(db, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add_many([("tf_static", ("base", f"cam{i}", pose(float(i))), 0.0, 0.0)
                     for i in range(50)] + [("seg", ("a", 1), 0.0, 0.0)])
    view_kb = slr_sql.open(db, clock=slr_sql.ManualClock(0.0))
    view = FoxgloveView(view_kb.store, port=0, static_every=3600.0).start()
    try:
        with FoxgloveClient(view.port) as victim, FoxgloveClient(view.port) as hammer:
            deadline = time.monotonic() + DEADLINE
            for client in (victim, hammer):
                client.pump(lambda c=client: "/tf_static" in c.channels
                            and "/seg/2" in c.channels, deadline)
            victim.subscribe("/tf_static", "/seg/2")
            victim.pump(lambda: bool(victim.on("/tf_static")), deadline)
            began = time.monotonic()
            channel = hammer.channels["/tf_static"]["id"]
            # one second of subscribing and unsubscribing, as fast as this client can
            hammering = began + 1.0
            n = 0
            while time.monotonic() < hammering:
                n += 1
                hammer.subscriptions[n] = "/tf_static"
                hammer.ws.send(json.dumps({"op": "subscribe",
                                           "subscriptions": [{"id": n, "channelId": channel}]}))
                hammer.ws.send(json.dumps({"op": "unsubscribe", "subscriptionIds": [n]}))
            # an event stored after the last subscription: once the victim has it, the view
            # has passed over every subscription
            with slr_sql.open(db, clock=slr_sql.ManualClock(1.0)) as kb:
                kb.add_many([("seg", ("b", 2), 1.0, 1.0)])
            victim.pump(lambda: len(victim.on("/seg/2")) >= 1, deadline)
            victim.read_for(gap * 2)   # (a send asked for in the last gap)
            elapsed = time.monotonic() - began
            static = len(victim.on("/tf_static")) - 1
            # a late subscriber still gets the latched message
            hammer.subscriptions[n + 1] = "/tf_static"
            hammer.ws.send(json.dumps({"op": "subscribe",
                                       "subscriptions": [{"id": n + 1, "channelId": channel}]}))
            hammer.messages.clear()
            hammer.pump(lambda: bool(hammer.on("/tf_static")), deadline)
    finally:
        view.close()
        view_kb.close()
    assert 1 <= static <= elapsed / gap + 2, (static, elapsed)
    assert len(hammer.on("/tf_static")[-1][1]["transforms"]) == 50
    assert foxglove_live.STATIC_GAP == gap


MESSAGE_MAX = 64 * 1024   # (foxglove_live.MESSAGE_MAX_BYTES, checked last)
BACKLOG = 1024 * MESSAGE_MAX


def test_a_slow_client_of_large_messages_holds_at_most_the_backlog_bytes(tmp_path):
    """The foxglove-sdk queues up to 1,024 messages per client that does not keep up,
    whatever their size: a client subscribed to a type with megabyte arguments (a camera
    topic imported with `slr ros import --all`) that did not read held a megabyte per
    message, here 100 MB, up to a gigabyte per client. Now no message larger than 64 KiB
    is sent (said once on the log, per topic), so a slow client holds at most 64 MiB. What
    the server held for the client is what the client receives once it reads: its queue
    and the sockets' buffers."""
    from slr_sql.viz import foxglove_live

    db = tmp_path / "robot.db"
    with slr_sql.open(db, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add_many([("camera", ("x",), 1.0, 1.0)])
    process = subprocess.Popen([sys.executable, "-m", "slr_sql", "foxglove", str(db),
                                "--port", "0"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True, env={**os.environ, "PYTHONPATH": str(REPO)})
    try:
        port = view_port(process)
        with silent_client(port) as silent, FoxgloveClient(port) as reader:
            subscribe(silent, "/camera/1")
            reader.pump(lambda: "/camera/1" in reader.channels, time.monotonic() + DEADLINE)
            reader.subscribe("/camera/1")
            # both subscriptions are in place once both clients have an event stored now
            with slr_sql.open(db, clock=slr_sql.ManualClock(0.0)) as kb:
                kb.add_many([("camera", ("probe",), 1.5, 1.5)])
            reader.pump(lambda: bool(reader.on("/camera/1")), time.monotonic() + DEADLINE)
            reader.messages.clear()
            while not isinstance(frame := silent.recv(timeout=DEADLINE), bytes):
                pass
            assert json.loads(frame[13:])["arg1"] == "probe"
            with slr_sql.open(db, clock=slr_sql.ManualClock(0.0)) as kb:
                for i in range(100):
                    kb.add_many([("camera", (f"{i:03d}" + "p" * 1_000_000,), 2.0, 2.0)])
                # messages up to the limit still go
                kb.add_many([("camera", (f"{i}" + "s" * 60_000,), 3.0, 3.0) for i in range(5)])
            # the view has logged every message (to both clients at once) when the reader has
            # the last
            reader.pump(lambda: any(m["arg1"].startswith("4s") for _, m in reader.on("/camera/1")),
                        time.monotonic() + DEADLINE)
            read = sorted(len(m["arg1"]) for _, m in reader.on("/camera/1"))
            # what the server held for the silent client, read now, up to its newest message
            held, newest = 0, None
            deadline = time.monotonic() + DEADLINE
            while newest != "4" + "s" * 60_000:
                frame = silent.recv(timeout=max(0.0, deadline - time.monotonic()))
                if isinstance(frame, bytes):
                    held += len(frame)
                    newest = json.loads(frame[13:])["arg1"]
        err = stop_view(process)
    finally:
        kill_if_running(process)
    assert held < BACKLOG, f"{held / 2 ** 20:.0f} MiB held for one client"
    assert read == [60_001] * 5
    assert process.returncode == 0, err
    too_large = [line for line in err.splitlines() if "larger than" in line]
    assert too_large == ["foxglove: /camera/1: messages larger than 65,536 bytes are left out "
                         "(the view's limit, so that a slow client holds at most 64 MiB)"], err
    assert (foxglove_live.MESSAGE_MAX_BYTES, foxglove_live.BACKLOG_BYTES) == (MESSAGE_MAX,
                                                                             BACKLOG)


def test_static_frames_too_many_for_one_message_come_in_several(tmp_path):
    """The latched /tf_static message holds every static edge: 600 edges with long frame
    names made one message of 190 KB. It comes in messages of at most 64 KiB now, every
    edge in one of them."""
    from slr_sql.viz.foxglove_live import FoxgloveView
    from test_foxglove import pose

    db = tmp_path / "robot.db"
    children = {f"camera_{i:03d}_" + "c" * 150 for i in range(600)}
    with slr_sql.open(db, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add_many([("tf_static", ("base", child, pose(1.0)), 0.0, 0.0) for child in children])
    view_kb = slr_sql.open(db, clock=slr_sql.ManualClock(0.0))
    view = FoxgloveView(view_kb.store, port=0, static_every=3600.0).start()
    sizes: list[int] = []
    try:
        with FoxgloveClient(view.port) as client:
            deadline = time.monotonic() + DEADLINE
            client.pump(lambda: "/tf_static" in client.channels, deadline)
            client.subscribe("/tf_static")
            client.pump(lambda: {t["child_frame_id"] for _, m in client.on("/tf_static")
                                 for t in m["transforms"]} == children, deadline)
            sizes = [len(json.dumps(m, separators=(",", ":")))
                     for _, m in client.on("/tf_static")]
    finally:
        view.close()
        view_kb.close()
    assert len(sizes) >= 3 and max(sizes) <= MESSAGE_MAX, sizes


def test_a_burst_of_more_than_two_pages_is_sent_without_waiting_for_another_change(tmp_path):
    """The view reads 10,000 rows of a type per pass, and passed again only at a change of
    the store (and once 50 ms after one): of 25,000 events stored at once it sent 20,000,
    and the last 5,000 waited for the store's next change, for ever on a store that no
    longer changes. Now a full page makes another pass."""
    from slr_sql.viz import foxglove_live
    from slr_sql.viz.foxglove_live import FoxgloveView

    db = tmp_path / "robot.db"
    with slr_sql.open(db, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add_many([("p", (0,), 0.0, 0.0)])
    view_kb = slr_sql.open(db, clock=slr_sql.ManualClock(0.0))
    view = FoxgloveView(view_kb.store, port=0).start()
    try:
        with FoxgloveClient(view.port) as client:
            deadline = time.monotonic() + DEADLINE
            client.pump(lambda: "/p/1" in client.channels, deadline)
            client.subscribe("/p/1")
            probe = 0
            while not client.on("/p/1"):   # (until the subscription is in place)
                assert time.monotonic() < deadline, "the subscription never took effect"
                probe -= 1
                with slr_sql.open(db, clock=slr_sql.ManualClock(0.0)) as kb:
                    kb.add_many([("p", (probe,), 0.5, 0.5)])
                client.read_for(0.2)
            with slr_sql.open(db, clock=slr_sql.ManualClock(0.0)) as kb:
                kb.add_many([("p", (i,), 1.0, 1.0) for i in range(1, 25_001)])
            # (a client slower than the view may lose older ones, never the newest, which
            # comes last)
            client.pump(lambda: client.messages[-1][2]["arg1"] == 25_000, deadline)
    finally:
        view.close()
        view_kb.close()
    assert foxglove_live.PAGE_ROWS == 10_000


@pytest.mark.parametrize("command", [
    ["foxglove", "--port", "0", "--message-max"],
    ["serve", "--port", "0", "--foxglove", "--foxglove-port", "0", "--foxglove-message-max"]])
def test_a_raised_message_cap_sends_larger_messages_and_queues_fewer(tmp_path, command):
    """`slr foxglove --message-max` and `slr serve --foxglove-message-max`: a camera topic's
    100 KB messages, left out at the default 64 KiB, reach a client at a cap of 256 KiB; the
    SDK then queues 256 of them per slow client, so it still holds at most 64 MiB."""
    from slr_sql.viz import foxglove_live

    db = tmp_path / "robot.db"
    with slr_sql.open(db, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add_many([("camera", ("x",), 1.0, 1.0)])
    process = subprocess.Popen([sys.executable, "-m", "slr_sql", command[0], str(db),
                                *command[1:], str(256 * 1024)],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               env={**os.environ, "PYTHONPATH": str(REPO)})
    try:
        line = process.stdout.readline()      # (either says where the view listens first)
        assert "foxglove" in line and "ws://127.0.0.1:" in line, process.stderr.read()
        port = int(line.split("ws://127.0.0.1:")[1].split()[0])
        with FoxgloveClient(port) as reader:
            reader.pump(lambda: "/camera/1" in reader.channels, time.monotonic() + DEADLINE)
            reader.subscribe("/camera/1")
            with slr_sql.open(db, clock=slr_sql.ManualClock(0.0)) as kb:
                kb.add_many([("camera", ("big" + "b" * 100_000,), 2.0, 2.0)])
                kb.add_many([("camera", ("huge" + "h" * 300_000,), 3.0, 3.0)])
                kb.add_many([("camera", ("last",), 4.0, 4.0)])
            reader.pump(lambda: any(m["arg1"] == "last" for _, m in reader.on("/camera/1")),
                        time.monotonic() + DEADLINE)
            got = [m["arg1"][:4] for _, m in reader.on("/camera/1")]
        err = stop_view(process)
    finally:
        kill_if_running(process)
    assert "bigb" in got and "huge" not in got and got[-1] == "last", got
    [said] = [line for line in err.splitlines() if "larger than" in line]
    assert said.endswith("foxglove: /camera/1: messages larger than 262,144 bytes are left out "
                         "(the view's limit, so that a slow client holds at most 64 MiB)"), err
    assert foxglove_live.backlog_messages(256 * 1024) == 256


@pytest.mark.parametrize("cap", [100, 1023, True, 2.5e5, "65536"])
def test_a_message_cap_that_is_no_integer_of_1024_at_least_is_refused_in_words(tmp_path, cap):
    from slr_sql.viz.foxglove_live import FoxgloveView

    with slr_sql.open(tmp_path / "r.db") as kb:
        with pytest.raises(slr_sql.SLRError, match="message_max_bytes must be an integer"):
            FoxgloveView(kb.store, port=0, message_max_bytes=cap)
