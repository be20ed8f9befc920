"""Answer frames written as framed once (service/fanout.py, service/ws_protocol.py): the
frame format against the ``websockets`` reader; the ``slr.websocket.frames`` extension of
``slr serve``'s WebSocket protocol on a real uvicorn server (offered without compression
only); and a subscriber that stops reading until the server's socket buffer is full, then
reads on, over a real ``slr serve`` with the frame channel and, with ``--ws-compression``,
through ASGI sends."""
from __future__ import annotations

import asyncio
import json
import socket
import subprocess
import sys
import threading
import time

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from websockets.frames import Frame, Opcode
from websockets.streams import StreamReader

import slr_sql
from slr_sql.service.fanout import FRAMES_EXTENSION, text_frame
from service_helpers import ServiceProcess, complete_only_as_marked, slr_env

DEADLINE = 30.0


def _read_frame(data: bytes) -> Frame:
    reader = StreamReader()
    reader.feed_data(data)
    reader.feed_eof()
    parser = Frame.parse(reader.read_exact, mask=False)
    try:
        next(parser)
    except StopIteration as stop:
        return stop.value
    raise AssertionError("the frame is incomplete")


@settings(max_examples=50, deadline=None)
@given(st.one_of(st.text(max_size=200),
                 st.integers(0, 70_000).map(lambda n: "é" * (n // 2) + "x" * (n % 2)),
                 st.sampled_from([125, 126, 127, 65535, 65536, 65537]).map(lambda n: "a" * n)))
def test_a_text_frame_reads_back_as_its_text(text):
    frame = _read_frame(text_frame(text.encode()))
    assert frame.opcode is Opcode.TEXT and frame.fin
    assert frame.data.decode() == text


# -- the extension on a real uvicorn server -------------------------------------------------------

def _serve(app, deflate: bool):
    """A real uvicorn server with slr serve's WebSocket protocol, on a thread; (url, stop)."""
    import uvicorn

    from slr_sql.service.ws_protocol import SubscriberWebSocketProtocol

    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    config = uvicorn.Config(app, ws=SubscriberWebSocketProtocol, lifespan="off",
                            log_level="warning", ws_per_message_deflate=deflate)
    server = uvicorn.Server(config)
    thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True)
    thread.start()

    def stop() -> None:
        server.should_exit = True
        thread.join(DEADLINE)
        sock.close()
    return f"ws://127.0.0.1:{sock.getsockname()[1]}/", stop, server


@pytest.mark.parametrize("deflate, asked, offered", [
    (False, False, True), (True, True, False), (True, False, True)])
def test_the_frame_channel_is_offered_without_compression_and_writes_whole_frames(
        deflate, asked, offered):
    """Offered unless the connection negotiated compression (the server allows it and the
    client asked for it): then each connection compresses its own frames."""
    seen: dict = {}

    async def app(scope, receive, send):
        assert scope["type"] == "websocket"
        await receive()
        await send({"type": "websocket.accept"})
        offered = scope["extensions"].get(FRAMES_EXTENSION)
        seen["offered"] = offered is not None
        if offered is not None:
            channel = offered["channel"]
            seen["open"], seen["paused"] = channel.open, channel.paused
            assert channel.write(text_frame('{"n":1}'.encode()))
            write = channel.writer()         # the fan-out's one call per frame
            write(text_frame(("y" * 70_000).encode()))
            protocol = channel._protocol()   # (what the transport calls above its mark)
            protocol.pause_writing()
            seen["writer_paused"], seen["paused_then"] = channel.writer(), channel.paused
            protocol.resume_writing()
        else:
            await send({"type": "websocket.send", "text": '{"n":1}'})
            await send({"type": "websocket.send", "text": "y" * 70_000})
        await send({"type": "websocket.close", "code": 1000})
        if offered is not None:
            seen["open_after_close"] = offered["channel"].open
            seen["written_after_close"] = offered["channel"].write(text_frame(b"{}"))
            seen["writer_after_close"] = offered["channel"].writer()

    url, stop, server = _serve(app, deflate)
    try:
        from websockets.sync.client import connect

        assert _started(server)
        with connect(url, compression="deflate" if asked else None) as ws:
            assert ws.recv(DEADLINE) == '{"n":1}'
            assert ws.recv(DEADLINE) == "y" * 70_000
    finally:
        stop()
    assert seen["offered"] is offered
    if offered:
        assert seen["open"] and not seen["paused"]
        assert not seen["open_after_close"] and not seen["written_after_close"]
        assert seen["writer_paused"] is None and seen["paused_then"]
        assert seen["writer_after_close"] is False


def _started(server) -> bool:
    """Wait (until the deadline) for the server thread to listen."""
    ready = threading.Event()
    deadline = time.monotonic() + DEADLINE
    while not server.started and time.monotonic() < deadline:
        ready.wait(0.01)
    return bool(server.started)


# -- a subscriber that stalls, then reads on ----------------------------------------------------

STALLING_CLIENT = r"""
import json, sys
from websockets.sync.client import connect
url, pattern, until, compression = sys.argv[1], sys.argv[2], float(sys.argv[3]), sys.argv[4]
with connect(url, compression=compression or None, max_queue=4) as ws:
    ws.send(json.dumps({"op": "subscribe", "pattern": pattern, "since": 0, "until": until}))
    print(json.loads(ws.recv())["type"], flush=True)
    sys.stdin.readline()             # stalled until the test has added everything
    got, seq = [], 1
    while True:
        frame = json.loads(ws.recv(60))
        if frame["type"] == "end":
            break
        answers = frame["answers"] if frame["type"] == "answers" else [frame["answer"]]
        assert frame["seq"] == seq, (frame["seq"], seq)
        seq += len(answers)
        got.extend(a["I"] for a in answers)
    print(json.dumps(got), flush=True)
"""


@pytest.mark.parametrize("compression", ["", "deflate"])
def test_a_subscriber_that_stalls_until_the_socket_is_full_then_reads_gets_everything(
        tmp_path, compression):
    """The server's socket buffer fills (6 MB of answers the client does not read): its
    frames wait for the drain, its queue overflows into the store, and once it reads it
    gets every answer once, in order, numbered without a gap, then its end. Without
    compression the frames go through the frame channel, with it through ASGI sends."""
    args = ("--ws-compression",) if compression else ()
    with ServiceProcess(tmp_path / "stall.db", *args) as server:
        with slr_sql.connect(server.url) as remote:
            complete_only_as_marked(remote, "big/2")
            client = subprocess.Popen(
                [sys.executable, "-c", STALLING_CLIENT, server.url.replace("http", "ws") +
                 "/subscribe", "big(I, S)^T", "3000", compression],
                stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=slr_env())
            try:
                assert client.stdout.readline().strip() == b"subscribed"
                payload = "x" * 2000
                for start in range(0, 3000, 100):
                    remote.add_many([f'big({i}, "{payload}")^{i}' for i in
                                     range(start, start + 100)])
                remote.mark_complete("big/2", 3000)
                with slr_sql.connect(server.url) as other:    # the others are served meanwhile
                    assert other.query("big(2999, _)^T") == [{"T": 2999.0}]
                client.stdin.write(b"go\n")
                client.stdin.flush()
                out, _ = client.communicate(timeout=120)
                assert client.returncode == 0
                assert json.loads(out.splitlines()[-1]) == list(range(3000))
            finally:
                client.kill()
                client.wait(DEADLINE)
    log = server.log.read_text()
    assert "Traceback" not in log, log



# -- one callback for the loop's subscribers -------------------------------------------------------

class _Socket:
    """The frames a connection was given (the socket side of a FrameChannel, in memory)."""

    def __init__(self, broken: bool = False):
        self.frames: list[bytes] = []
        self.broken = broken
        self.on_drain = None
        self.paused = False
        self.open = True

    def write(self, frame: bytes) -> bool:
        if self.broken:
            raise RuntimeError("the transport refused the write")
        self.frames.append(frame)
        return True

    def writer(self):
        return False if not self.open else None if self.paused else self.write


def _run_until(loop, done, what: str) -> None:
    async def wait() -> None:
        deadline = loop.time() + DEADLINE
        while not done():
            assert loop.time() < deadline, what
            await asyncio.sleep(0.005)
    loop.run_until_complete(wait())


def test_a_delivery_that_fails_ends_alone_and_the_others_of_its_callback_go_on():
    """Two subscribers woken by one pass: the first one's write raises; it ends with that
    error (its coroutine sends it), and the second still gets its frame in the same round."""
    from slr_sql.service.fanout import FanOut

    kb = slr_sql.open(clock=slr_sql.ManualClock(0))
    loop = asyncio.new_event_loop()
    try:
        fanout = FanOut(loop, lambda seq, answers: json.dumps(
            {"seq": seq, "I": [a["I"] for a in answers]}))
        broken, good = _Socket(broken=True), _Socket()
        first = fanout.start(kb.subscribe("p(I)^T", since=0), broken, 10)
        second = fanout.start(kb.subscribe("p(I)^T", since=0), good, 10)
        _run_until(loop, lambda: True, "started")
        kb.add_many(["p(1)^1", "p(2)^2"])
        _run_until(loop, lambda: good.frames and first.finished.done(), "delivered")
        with pytest.raises(RuntimeError, match="refused"):
            first.finished.result()
        assert [json.loads(_read_frame(f).data) for f in good.frames] == [
            {"seq": 1, "I": [1, 2]}]
        kb.add("p(3)^3")
        _run_until(loop, lambda: len(good.frames) == 2, "the next pass")
        assert json.loads(_read_frame(good.frames[1]).data) == {"seq": 3, "I": [3]}
        assert not second.finished.done()
        second.sub.close()
        _run_until(loop, second.finished.done, "ended")
        assert second.finished.result() is None
    finally:
        loop.close()
        kb.close()


class _Interrupted(_Socket):
    """A connection whose first write is interrupted (Ctrl-C while the frame is written)."""

    interrupted = False

    def write(self, frame: bytes) -> bool:
        if not self.interrupted:
            self.interrupted = True
            raise KeyboardInterrupt
        return super().write(frame)


def test_a_base_exception_in_one_delivery_leaves_the_others_of_its_callback_delivered():
    """Three subscribers woken by one pass; the second one's write is interrupted by a
    KeyboardInterrupt, which stops the loop. The third was marked for the same callback:
    it is delivered once the loop runs again (it stayed marked, and no later wake would
    have queued it again), and so are the next answers of all three."""
    from slr_sql.service.fanout import FanOut

    kb = slr_sql.open(clock=slr_sql.ManualClock(0))
    loop = asyncio.new_event_loop()
    try:
        fanout = FanOut(loop, lambda seq, answers: json.dumps(
            {"seq": seq, "I": [a["I"] for a in answers]}))
        sockets = [_Socket(), _Interrupted(), _Socket()]
        deliveries = [fanout.start(kb.subscribe("p(I)^T", since=0), s, 10) for s in sockets]
        _run_until(loop, lambda: True, "started")
        kb.add_many(["p(1)^1", "p(2)^2"])
        assert kb._subscriptions.drain(DEADLINE)   # all three woken before the loop runs
        with pytest.raises(KeyboardInterrupt):
            _run_until(loop, lambda: False, "interrupted")
        first, interrupted, third = sockets
        _run_until(loop, lambda: third.frames, "the third delivered after the interrupt")
        assert [json.loads(_read_frame(f).data) for f in first.frames + third.frames] == [
            {"seq": 1, "I": [1, 2]}] * 2
        kb.add("p(3)^3")
        _run_until(loop, lambda: len(first.frames) == len(third.frames) == 2, "the next pass")
        assert json.loads(_read_frame(third.frames[1]).data) == {"seq": 3, "I": [3]}
        for delivery in deliveries:
            delivery.sub.close()
        _run_until(loop, lambda: all(d.finished.done() for d in deliveries), "ended")
    finally:
        loop.close()
        kb.close()


def test_a_finished_delivery_leaves_nothing_for_the_cyclic_collector(tmp_path):
    """With the collector off, subscribers delivered through the frame channel, then gone
    (a close message, a dropped connection): their connections, deliveries and
    subscriptions are freed by reference counting, as on the coroutine path — at 100
    subscribers coming and going, what the collector would otherwise walk in one pause."""
    import gc

    from websockets.sync.client import connect

    from slr_sql.service.app import create_app
    from slr_sql.service.fanout import Delivery
    from slr_sql.service.ws_protocol import SubscriberWebSocketProtocol
    from slr_sql.subscriptions.queue import Subscription

    kb = slr_sql.open(tmp_path / "garbage.db", clock=slr_sql.ManualClock(0))
    url, stop, server = _serve(create_app(kb), deflate=False)

    hub = kb._subscriptions
    fanouts: set[int] = set()   # (ids of this server's fan-outs, as its deliveries show)

    def alive() -> dict:
        # (this server's connections and this knowledge base's deliveries and subscriptions
        # only: in a worker of the whole suite, another test's server stopping in threads of
        # its own may free its own later, and a connection of another server lives until its
        # close handshake or its 10 s close timeout: the wait below waited for those too)
        counts = {"connections": 0, "deliveries": 0, "subscriptions": 0}
        for o in gc.get_objects():
            if type(o) is SubscriberWebSocketProtocol:
                counts["connections"] += o.connections is server.server_state.connections
            elif type(o) is Delivery:
                if getattr(o.sub, "_hub", None) is hub:
                    fanouts.add(id(o._fanout))
                counts["deliveries"] += id(o._fanout) in fanouts
            elif type(o) is Subscription:
                counts["subscriptions"] += o._hub is hub
        return counts

    try:
        assert _started(server)
        gc.collect()
        gc.disable()
        for round, leave in enumerate(("close message", "dropped")):
            with connect(url + "subscribe") as ws:
                pattern = f"p{round}(X)^T"
                ws.send(json.dumps({"op": "subscribe", "pattern": pattern, "since": 0}))
                assert json.loads(ws.recv(DEADLINE))["type"] == "subscribed"
                kb.add_many([f"p{round}(1)^1", f"p{round}(2)^2"])
                got: list = []
                while len(got) < 2:
                    frame = json.loads(ws.recv(DEADLINE))
                    assert frame["seq"] == len(got) + 1
                    got += frame["answers"] if frame["type"] == "answers" else [frame["answer"]]
                assert [a["X"] for a in got] == [1, 2]
                assert alive()["deliveries"] == 1      # (delivered by the frame channel)
                if leave == "close message":
                    ws.send('{"op": "close"}')
            ready = threading.Event()
            deadline = time.monotonic() + DEADLINE
            while alive() != {"connections": 0, "deliveries": 0, "subscriptions": 0} and \
                    time.monotonic() < deadline:
                ready.wait(0.02)
            assert alive() == {"connections": 0, "deliveries": 0, "subscriptions": 0}, leave
    finally:
        gc.enable()
        stop()
        kb.close()
