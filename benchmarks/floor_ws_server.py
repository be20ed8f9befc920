"""The floor of ``bench_service_ws.py``: a server that does the least any server of its
protocol could, so that a run against it says what the *rest* of the machine (the
subscribers' process, the producer, a competing load) leaves for ``slr serve``.

It speaks what the benchmark uses of ``slr serve``'s protocol and nothing else: ``POST /add``
and ``POST /add_many`` (HTTP/1.1, kept alive; the events are read from the JSON body, nothing
is stored), ``GET /health``, and WebSocket subscriptions on ``/subscribe`` (the upgrade, the
client's subscribe frame answered with ``subscribed``, pings answered). Each ``add_many`` is
answered at once; then, in the same callback of the loop, its answers ``e(I)^T`` (``T`` >
``since``) go to every subscriber as one ``answers`` frame, built once for all of them (the
subscribers of the benchmark are all at the same place). No store, no rules, no hub, no
thread: one asyncio loop, one ``transport.write`` per subscriber per batch.

Not a server of slr_sql: a measuring instrument. Run by ``bench_service_ws.py --floor-server``;
alone::

    python benchmarks/floor_ws_server.py --port 0     # prints "floor: - on http://HOST:PORT"
"""
from __future__ import annotations

import argparse
import asyncio
import base64
import hashlib
import json
import re
import struct
import sys
import time
from pathlib import Path

from orjson import dumps, loads

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from slr_sql.service.fanout import text_frame  # noqa: E402  (slr serve's own framing)

GUID = b"258EAFA5-E914-47DA-95CA-C5AB0DC85B11"
EVENT = re.compile(r"^e\((-?\d+)\)\^(-?[\d.]+)$")


class Hub:
    def __init__(self, work_us: float = 0.0, work_thread: bool = False) -> None:
        self.subscribers: list[Connection] = []
        self.work_us = work_us
        self.work_thread = work_thread   # the work on a thread of its own, as a store's writes

    def work(self, events: int) -> None:
        """Spend ``work_us`` of CPU per event (``--work-us``): a server that costs that much
        more than the floor, to find the cost at which a run's tail crosses its bound."""
        if self.work_us:
            end = time.thread_time() + events * self.work_us / 1e6
            while time.thread_time() < end:
                pass

    def publish(self, events: list) -> None:
        parsed = []
        for text in events:
            m = EVENT.match(text)
            if m is not None:
                parsed.append((int(m.group(1)), float(m.group(2))))
        made: dict[tuple[float, int, int], tuple[list[bytes], int]] = {}
        for sub in self.subscribers:
            key = (sub.since, sub.seq, sub.batch)
            got = made.get(key)
            if got is None:
                # as slr serve: at most `batch` answers a frame, one alone as an "answer"
                answers = [{"I": i, "T": t} for i, t in parsed if t > sub.since]
                frames = []
                for k in range(0, len(answers), sub.batch):
                    part = answers[k:k + sub.batch]
                    frames.append(text_frame(dumps(
                        {"type": "answer", "seq": sub.seq + k + 1, "answer": part[0]}
                        if len(part) == 1 else
                        {"type": "answers", "seq": sub.seq + k + 1, "answers": part})))
                got = made[key] = (frames, len(answers))
            sub.seq += got[1]
            for frame in got[0]:
                sub.transport.write(frame)


class Connection(asyncio.Protocol):
    def __init__(self, hub: Hub) -> None:
        self.hub = hub
        self.buffer = bytearray()
        self.websocket = False
        self.since = float("-inf")
        self.batch = 256
        self.seq = 0
        self.transport: asyncio.Transport

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport

    def connection_lost(self, exc: BaseException | None) -> None:
        if self in self.hub.subscribers:
            self.hub.subscribers.remove(self)

    def data_received(self, data: bytes) -> None:
        self.buffer += data
        if self.websocket:
            self.frames()
        else:
            self.requests()

    def requests(self) -> None:
        while True:
            end = self.buffer.find(b"\r\n\r\n")
            if end < 0:
                return
            head = bytes(self.buffer[:end]).decode("latin-1").split("\r\n")
            method, path, _ = head[0].split(" ", 2)
            headers = {k.strip().lower(): v.strip() for k, v in
                       (line.split(":", 1) for line in head[1:] if ":" in line)}
            length = int(headers.get("content-length", "0"))
            if len(self.buffer) < end + 4 + length:
                return
            body = bytes(self.buffer[end + 4:end + 4 + length])
            del self.buffer[:end + 4 + length]
            if headers.get("upgrade", "").lower() == "websocket":
                accept = base64.b64encode(hashlib.sha1(
                    headers["sec-websocket-key"].encode() + GUID).digest()).decode()
                self.transport.write((
                    "HTTP/1.1 101 Switching Protocols\r\nUpgrade: websocket\r\n"
                    f"Connection: Upgrade\r\nSec-WebSocket-Accept: {accept}\r\n\r\n").encode())
                self.websocket = True
                self.frames()
                return
            events: list = []
            if method == "POST" and path.startswith("/add_many"):
                events = loads(body)["events"]
                reply = dumps({"accepted": len(events), "rejected": []})
            elif method == "POST" and path.startswith("/add"):
                events = [loads(body)["event"]]
                reply = dumps({"added": 1})
            else:
                reply = dumps({"status": "ok"})
            if self.hub.work_thread and events:
                # as `slr serve`: the work on another thread, the answer and the frames back
                # on the loop's (two hops per add)
                done = asyncio.get_running_loop().run_in_executor(None, self.hub.work,
                                                                   len(events))
                done.add_done_callback(lambda _, reply=reply, events=events:
                                       self.answer(reply, events))
                continue
            self.hub.work(len(events))        # (as a store's commit: before the answer)
            self.answer(reply, events)

    def answer(self, reply: bytes, events: list) -> None:
        self.transport.write(b"HTTP/1.1 200 OK\r\nContent-Type: application/json\r\n"
                             b"Content-Length: %d\r\n\r\n%s" % (len(reply), reply))
        if events:
            self.hub.publish(events)

    def frames(self) -> None:
        buffer = self.buffer
        while len(buffer) >= 2:
            opcode, length = buffer[0] & 0x0F, buffer[1] & 0x7F
            start = 2
            if length == 126:
                length, start = struct.unpack_from("!H", buffer, 2)[0], 4
            elif length == 127:
                length, start = struct.unpack_from("!Q", buffer, 2)[0], 10
            if len(buffer) < start + 4 + length:
                return
            mask = buffer[start:start + 4]
            payload = bytes(b ^ mask[i % 4] for i, b in
                            enumerate(buffer[start + 4:start + 4 + length]))
            del buffer[:start + 4 + length]
            if opcode == 1:
                request = json.loads(payload)
                self.since = float(request.get("since", float("-inf")))
                self.batch = max(1, int(request.get("batch", 256)))
                self.transport.write(text_frame(dumps({"type": "subscribed",
                                                       "id": str(id(self))})))
                self.hub.subscribers.append(self)
            elif opcode == 9:
                self.transport.write(bytes((0x8A, len(payload))) + payload)
            elif opcode == 8:
                self.transport.close()
                return


async def serve(host: str, port: int, work_us: float, work_thread: bool) -> None:
    hub = Hub(work_us, work_thread)
    server = await asyncio.get_running_loop().create_server(lambda: Connection(hub), host, port)
    bound = server.sockets[0].getsockname()[1]
    print(f"floor: - on http://{host}:{bound}", flush=True)
    await server.serve_forever()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--host", default="127.0.0.1")
    ap.add_argument("--port", type=int, default=0)
    ap.add_argument("--work-us", type=float, default=0.0,
                    help="CPU to spend per event (µs) before answering an add: a costlier server")
    ap.add_argument("--work-thread", action="store_true",
                    help="do that work on a worker thread, as a store's writes are")
    args = ap.parse_args()
    try:
        asyncio.run(serve(args.host, args.port, args.work_us, args.work_thread))
    except KeyboardInterrupt:
        pass


if __name__ == "__main__":
    main()
