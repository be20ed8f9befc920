"""Service subscriptions: 100 WebSocket subscribers on one ``slr serve`` at 1,000 events/s,
against the same fan-out in process (``kb.subscribe``) in the same run; and a memory soak.

* **service** — ``slr serve`` on a temporary file store (a real process). ``--subscribers``
  (100) WebSocket subscriptions to ``e(I)^T`` (``batch`` answers per frame at most) run on
  one asyncio loop in a child process, with the ``websockets`` library's client or
  (``--client raw``) a minimal one (the process's CPU per frame, the kernel's receive
  included: ~22 µs against the library's ~43 µs on the 2-core machine of
  benchmarks/README.md). The producer (this process) sends ``add_many`` over
  HTTP in batches of ``--batch-events`` (10) paced to ``--rate`` (1,000) events/s. Latency of
  one delivery = the time its answer's frame is received minus the time the HTTP
  ``add_many`` holding the event was answered (0 when the frame came first; both read
  ``time.monotonic``, one clock for every process on Linux), and also from when that
  ``add_many`` was made (the HTTP request's hops and the commit included: a server that
  answers ``add_many`` later cannot make its deliveries look sooner), over the first
  ``--latency-seconds`` (20). Every subscriber must receive every event, once, in order
  (counted over the whole run).
* **soak** — the same run lasts ``--minutes`` (10); the server's RSS (``/proc/PID/status``)
  is sampled every ``--sample-seconds`` (5): first, last, max and the least-squares slope.
* **in process** — the same producer pacing (``kb.add_many`` of the same batches) and 100
  ``kb.subscribe`` subscriptions consumed with ``async for`` on one asyncio loop in the same
  process, for ``--latency-seconds``: the baseline of the ratio.

Run by hand::

    python benchmarks/bench_service_ws.py                     # 10-minute soak
    python benchmarks/bench_service_ws.py --minutes 3
    python benchmarks/bench_service_ws.py --minutes 1 --burn 1    # beside a competing CPU load
    python benchmarks/bench_service_ws.py --minutes 1 --server-code /tmp/old   # earlier server
    python benchmarks/bench_service_ws.py --minutes 1 --gc-trace   # the server's collections
    python benchmarks/bench_service_ws.py --minutes 1 --client raw   # lighter subscribers

``--burn N`` starts N processes spinning on a core (``python -c "while 1: pass"``) for the whole
run and stops them at its end; the load averages at start and end are printed with the
figures (the machine may be shared: they say how idle it was).
"""
from __future__ import annotations

import argparse
import asyncio
import gc
import json
import math
import multiprocessing as mp
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


import slr_sql  # noqa: E402


def pct(xs: list[float], p: float) -> float:
    if not xs:
        return float("nan")
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(p / 100 * len(xs)))]


def delivery_latencies(frames: list[list[tuple]], answered: list[float],
                       requested: list[float]) -> tuple[list, ...]:
    """From the frames each subscriber recorded inside the latency window, ``frames[k]``:
    ``(events, when)`` with the event numbers of the frame's answers (recording starts with
    whichever frame first arrives inside the window, not necessarily event 0's): each
    delivery's latency after its ``add_many`` was answered (0 if the frame came first) and
    after it was requested; per event received by every subscriber, its first delivery's
    lateness and the spread from its first to its last.

    >>> delivery_latencies([[([1], 1.5), ([2], 2.5)], [([2], 2.75)]],  # the second began at 2
    ...                    [0.0, 1.0, 2.0], [0.0, 0.5, 1.5])
    ([0.5, 0.5, 0.75], [1.0, 1.0, 1.25], [0.5], [0.25])
    """
    received = [{i: when for events, when in mine for i in events} for mine in frames]
    lat, from_request = [], []
    for got_by in received:
        for i, t in got_by.items():
            if 0 <= i < len(answered):
                lat.append(max(0.0, t - answered[i]))
                from_request.append(t - requested[i])
    firsts_late, spreads = [], []
    for i in range(len(answered)):
        got = [got_by[i] for got_by in received if i in got_by]
        if not got or len(got) < len(frames):
            continue          # not recorded by every subscriber
        firsts_late.append(max(0.0, min(got) - answered[i]))
        spreads.append(max(got) - min(got))
    return lat, from_request, firsts_late, spreads


def rss_mb(pid: int) -> float:
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def cpu_seconds(pid: int, thread: int | None = None) -> float:
    """User + system CPU time of a process (or of its ``thread``) so far (/proc/PID/stat)."""
    with open(f"/proc/{pid}/stat" if thread is None else f"/proc/{pid}/task/{thread}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def machine_ticks() -> tuple[int, int]:
    """(busy, total) clock ticks of every core so far (/proc/stat's first line; idle and
    iowait are not busy)."""
    with open("/proc/stat") as f:
        ticks = [int(x) for x in f.readline().split()[1:]]
    return sum(ticks) - ticks[3] - ticks[4], sum(ticks)


def file_mb(db: Path) -> float:
    return sum(os.path.getsize(p) for p in (db, Path(f"{db}-wal")) if p.exists()) / 2 ** 20


def slope_per_min(samples: list[tuple[float, float]]) -> float:
    n = len(samples)
    if n < 2:
        return 0.0
    mt = sum(t for t, _ in samples) / n
    mr = sum(r for _, r in samples) / n
    var = sum((t - mt) ** 2 for t, _ in samples)
    return 60 * sum((t - mt) * (r - mr) for t, r in samples) / var if var else 0.0


def produce(add_many, rate: float, batch: int, seconds: float, answered: list,
            stop_latency_at: float, requested: list | None = None) -> tuple[int, float]:
    """Call ``add_many`` with batches of ``batch`` events ``e(I)^I`` paced to ``rate``
    events/s for ``seconds``; ``answered[I]`` = when the call holding event I returned,
    ``requested[I]`` = when it was made (only up to ``stop_latency_at``). Returns the number
    of events sent and the rate achieved (below ``rate`` when a call takes longer than its
    share of the period)."""
    period = batch / rate
    start = time.monotonic()
    i = 0
    k = 0
    while True:
        due = start + k * period
        now = time.monotonic()
        if due - start >= seconds:
            break
        if due > now:
            time.sleep(due - now)
        events = [f"e({j})^{j + 1}" for j in range(i, i + batch)]
        made = time.monotonic()
        add_many(events)
        done = time.monotonic()
        if done < stop_latency_at:
            answered.extend([done] * batch)
            if requested is not None:
                requested.extend([made] * batch)
        i += batch
        k += 1
    return i, i / (time.monotonic() - start)


# -- the WebSocket subscribers (a child process) -----------------------------------------------

def ws_subscribers(url: str, n: int, batch: int, ready, conn) -> None:
    from orjson import loads
    from websockets.asyncio.client import connect
    from websockets.exceptions import ConnectionClosed

    latency_window = [0.0]                # until when receive times are kept (sent later)
    counts = [0] * n
    bad = [0] * n
    # per subscriber, (the frame's event numbers, when it arrived) of each frame received
    # inside the window: it opens while frames may already arrive
    times: list[list[tuple]] = [[] for _ in range(n)]

    async def one(k: int, started: asyncio.Event, go: list) -> None:
        async with connect(url, max_size=None) as ws:
            await ws.send(json.dumps({"op": "subscribe", "pattern": "e(I)^T", "since": 0.5,
                                      "batch": batch}))
            json.loads(await ws.recv())
            go[0] += 1
            if go[0] == n:
                started.set()
            expect = 0
            mine = times[k]
            while True:
                # the frame's bytes, parsed by orjson: the subscribers' process spends less of
                # the CPU the server needs on a busy machine (the checks are the same)
                try:
                    data = await ws.recv(decode=False)
                except ConnectionClosed:
                    break
                now = time.monotonic()
                msg = loads(data)
                answers = msg["answers"] if msg["type"] == "answers" else [msg["answer"]] \
                    if msg["type"] == "answer" else None
                if answers is None:
                    break
                numbers = [a["I"] for a in answers]
                n_answers = len(numbers)
                if numbers[0] == expect and numbers[-1] == expect + n_answers - 1 and \
                        numbers == list(range(expect, expect + n_answers)):
                    expect += n_answers          # every one in order: the common case
                else:
                    for i in numbers:
                        if i != expect:
                            bad[k] += 1
                        expect = i + 1
                counts[k] += n_answers
                if now < latency_window[0]:
                    mine.append((numbers, now))

    async def main() -> None:
        started = asyncio.Event()
        go = [0]
        tasks = [asyncio.create_task(one(k, started, go)) for k in range(n)]
        await started.wait()
        # the collector as `slr serve` sets it up (its start-up heap frozen, a young collection
        # after 20,000 net allocations): with Python's defaults this process ran ~10 young
        # and a full collection every ~10 s, the full ones up to 60 ms on a busy machine,
        # every subscriber's receive paused meanwhile (--gc-trace's figures are the server's)
        gc.collect()
        gc.freeze()
        gc.set_threshold(20_000, *gc.get_threshold()[1:])
        ready.set()
        latency_window[0] = (await asyncio.get_running_loop().run_in_executor(
            None, conn.recv))[0]
        await asyncio.get_running_loop().run_in_executor(None, conn.poll, None)
        for t in tasks:
            t.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)

    asyncio.run(main())
    conn.recv()                            # the "stop" message
    conn.send((counts, bad, times))


def ws_subscribers_raw(url: str, n: int, batch: int, ready, conn) -> None:
    """``--client raw``: the same subscribers, checks and clock as :func:`ws_subscribers`, with
    a minimal WebSocket client (RFC 6455: the upgrade request, masked client frames, unmasked
    server frames, pings answered) on ``asyncio.Protocol`` instead of the ``websockets``
    library's. The subscribers' process then costs ~22 µs per frame (the kernel's receive
    included) instead of ~43 µs: at 100 subscribers × 100 frames/s, ~0.2 of a core less of
    the two the run shares with the server, where beside a competing load the subscribers'
    own CPU shows up as the server's latency. The frame reading is the benchmark's only:
    slr_sql's own client (slr_sql.connect) keeps the library."""
    import base64
    import struct
    from urllib.parse import urlsplit
    from orjson import loads

    parts = urlsplit(url)
    latency_window = [0.0]
    counts = [0] * n
    bad = [0] * n
    times: list[list[tuple]] = [[] for _ in range(n)]     # as in ws_subscribers

    def client_frame(opcode: int, payload: bytes) -> bytes:
        mask = os.urandom(4)
        length = len(payload)
        head = bytes([0x80 | opcode])
        if length < 126:
            head += bytes([0x80 | length])
        elif length < 65536:
            head += bytes([0x80 | 126]) + struct.pack("!H", length)
        else:
            head += bytes([0x80 | 127]) + struct.pack("!Q", length)
        masked = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
        return head + mask + masked

    class Subscriber(asyncio.Protocol):
        def __init__(self, k: int, subscribed: asyncio.Future, ended: asyncio.Future) -> None:
            self.k = k
            self.buffer = bytearray()
            self.upgraded = False
            self.subscribed = subscribed
            self.ended = ended
            self.expect = 0
            self.transport: asyncio.Transport | None = None

        def connection_made(self, transport) -> None:
            self.transport = transport
            key = base64.b64encode(os.urandom(16)).decode()
            transport.write((f"GET {parts.path} HTTP/1.1\r\nHost: {parts.netloc}\r\n"
                             f"Upgrade: websocket\r\nConnection: Upgrade\r\n"
                             f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n")
                            .encode())

        def data_received(self, data: bytes) -> None:
            now = time.monotonic()
            buffer = self.buffer
            buffer += data
            if not self.upgraded:
                end = buffer.find(b"\r\n\r\n")
                if end < 0:
                    return
                if not buffer.startswith(b"HTTP/1.1 101"):
                    raise RuntimeError(f"the server refused the upgrade: {bytes(buffer[:80])!r}")
                del buffer[:end + 4]
                self.upgraded = True
                self.transport.write(client_frame(1, json.dumps(
                    {"op": "subscribe", "pattern": "e(I)^T", "since": 0.5,
                     "batch": batch}).encode()))
            position = 0
            size = len(buffer)
            while size - position >= 2:
                opcode = buffer[position] & 0x0F
                length = buffer[position + 1] & 0x7F
                start = position + 2
                if length == 126:
                    if size - start < 2:
                        break
                    length = struct.unpack_from("!H", buffer, start)[0]
                    start += 2
                elif length == 127:
                    if size - start < 8:
                        break
                    length = struct.unpack_from("!Q", buffer, start)[0]
                    start += 8
                if size - start < length:
                    break
                payload = bytes(buffer[start:start + length])
                position = start + length
                if opcode == 9:                       # ping: pong with the same payload
                    self.transport.write(client_frame(10, payload))
                elif opcode == 1:
                    self.message(loads(payload), now)
                elif opcode == 8:
                    self.finish()
            del buffer[:position]

        def message(self, msg: dict, now: float) -> None:
            if not self.subscribed.done():
                self.subscribed.set_result(None)       # the "subscribed" message
                return
            kind = msg["type"]
            answers = msg["answers"] if kind == "answers" else [msg["answer"]] \
                if kind == "answer" else None
            if answers is None:
                self.finish()
                return
            k = self.k
            numbers = [a["I"] for a in answers]
            n_answers = len(numbers)
            expect = self.expect
            if numbers[0] == expect and numbers[-1] == expect + n_answers - 1 and \
                    numbers == list(range(expect, expect + n_answers)):
                self.expect = expect + n_answers
            else:
                for i in numbers:
                    if i != self.expect:
                        bad[k] += 1
                    self.expect = i + 1
            counts[k] += n_answers
            if now < latency_window[0]:
                times[k].append((numbers, now))

        def finish(self) -> None:
            if not self.ended.done():
                self.ended.set_result(None)

        def connection_lost(self, exc) -> None:
            self.finish()

    async def main() -> None:
        loop = asyncio.get_running_loop()
        subscribed = [loop.create_future() for _ in range(n)]
        ended = [loop.create_future() for _ in range(n)]
        transports = []
        for k in range(n):
            transport, _ = await loop.create_connection(
                lambda k=k: Subscriber(k, subscribed[k], ended[k]), parts.hostname, parts.port)
            transports.append(transport)
        await asyncio.gather(*subscribed)
        gc.collect()                     # the collector as in ws_subscribers (and `slr serve`)
        gc.freeze()
        gc.set_threshold(20_000, *gc.get_threshold()[1:])
        ready.set()
        latency_window[0] = (await loop.run_in_executor(None, conn.recv))[0]
        await loop.run_in_executor(None, conn.poll, None)
        for transport in transports:
            transport.close()

    asyncio.run(main())
    conn.recv()                            # the "stop" message
    conn.send((counts, bad, times))


# ``--gc-trace``: `slr serve` started through this prelude, which records each collection of
# the cyclic garbage collector (gc.callbacks: generation, wall time, objects collected) and
# writes them out when the server exits (it exits normally on SIGTERM)
GC_TRACE_PRELUDE = r"""
import atexit, gc, json, runpy, sys, time
_out, _rec, _start = sys.argv.pop(1), [], [0.0]
def _collection(phase, info):
    if phase == "start":
        _start[0] = time.perf_counter()
    else:
        _rec.append((time.monotonic(), info["generation"], time.perf_counter() - _start[0],
                     info["collected"]))
gc.callbacks.append(_collection)
def _write():
    with open(_out, "w") as f:
        json.dump(_rec, f)
atexit.register(_write)
sys.argv[0] = "slr"
runpy.run_module("slr_sql", run_name="__main__", alter_sys=True)
"""


def gc_summary(records: list, start: float, end: float) -> str:
    """The server's collections between ``start`` and ``end`` (monotonic), per generation:
    how many, objects collected, total and longest pause (wall time)."""
    parts = []
    for gen in (0, 1, 2):
        mine = [r for r in records if start <= r[0] <= end and r[1] == gen]
        pauses = [r[2] for r in mine]
        parts.append(f"gen{gen} {len(mine)} ({sum(r[3] for r in mine)} objects collected, "
                     f"{1000 * sum(pauses):.1f} ms, longest {1000 * max(pauses, default=0):.2f} ms)")
    return ", ".join(parts)


def run_service(args, tmp: Path) -> dict:
    db = tmp / "ws.db"
    env = dict(os.environ, PYTHONPATH=str(args.server_code or ROOT))
    command = [sys.executable, "-m", "slr_sql", "serve", str(db), "--port", "0"]
    if args.floor_server:       # the least any server could do: what the rest leaves
        command = [sys.executable, str(ROOT / "benchmarks" / "floor_ws_server.py"), "--port", "0",
                   "--work-us", str(args.floor_work_us)] + \
            (["--work-thread"] if args.floor_work_thread else [])
    gc_log = tmp / "gc.json"
    if args.gc_trace:
        command[1:3] = ["-c", GC_TRACE_PRELUDE, str(gc_log)]
    if args.cache_kib:     # the same server with another SQLite page cache bound
        command += ["--cache-mib", str(args.cache_kib / 1024)]
    # cwd: `python -m` puts the working directory first on sys.path, ahead of PYTHONPATH; run
    # from a checkout, the server would import that checkout's slr_sql, not --server-code's
    proc = subprocess.Popen(command, stdout=subprocess.PIPE,
                            stderr=open(tmp / "server.log", "wb"), env=env, cwd=tmp)
    url = proc.stdout.readline().decode().strip().rsplit(" on ", 1)[1]
    try:
        client = slr_sql.connect(url)
        client.add("e(-1)^0")
        ctx = mp.get_context("spawn")
        ready = ctx.Event()
        parent, child = ctx.Pipe()
        sub_proc = ctx.Process(target=ws_subscribers_raw if args.client == "raw" else ws_subscribers,
                               args=(url.replace("http", "ws") + "/subscribe",
                                     args.subscribers, args.frame_batch, ready, child))
        sub_proc.start()
        seconds = args.minutes * 60
        answered: list[float] = []
        samples: list[tuple[float, float]] = []
        sizes: list[float] = []        # MB of the store file and its WAL, with each sample
        if not ready.wait(60):
            raise RuntimeError("the subscribers did not connect")
        t0 = time.monotonic()
        latency_end = t0 + args.latency_seconds
        parent.send([latency_end])
        stop = threading.Event()

        def sample() -> None:
            while not stop.wait(args.sample_seconds):
                samples.append((time.monotonic() - t0, rss_mb(proc.pid)))
                sizes.append(file_mb(db))
                if args.trace:
                    print(f"  {samples[-1][0]:6.0f} s  RSS {samples[-1][1]:6.1f} MB  file "
                          f"{sizes[-1]:6.1f} MB", flush=True)
        sampler = threading.Thread(target=sample, daemon=True)
        samples.append((0.0, rss_mb(proc.pid)))
        sizes.append(file_mb(db))
        sampler.start()
        load_start = os.getloadavg()
        # the server's main thread runs the event loop: every frame's send, every request
        loop_start = cpu_seconds(proc.pid, proc.pid)
        cpu_start, cpu_t0 = cpu_seconds(proc.pid), time.monotonic()
        subscribers_start = cpu_seconds(sub_proc.pid)
        producer_start = time.process_time()
        burn_start = sum(cpu_seconds(pid) for pid in args.burn_pids)
        machine_start = machine_ticks()
        requested: list[float] = []
        sent, achieved = produce(client.add_many, args.rate, args.batch_events, seconds, answered,
                                 latency_end, requested)
        produced_at = time.monotonic()
        server_cpu = (cpu_seconds(proc.pid) - cpu_start) / (produced_at - cpu_t0)
        loop_cpu = (cpu_seconds(proc.pid, proc.pid) - loop_start) / (produced_at - cpu_t0)
        subscribers_cpu = (cpu_seconds(sub_proc.pid) - subscribers_start) / (produced_at - cpu_t0)
        producer_cpu = (time.process_time() - producer_start) / (produced_at - cpu_t0)
        burn_cpu = (sum(cpu_seconds(pid) for pid in args.burn_pids) - burn_start) / \
            (produced_at - cpu_t0)
        machine_end = machine_ticks()
        # the cores' busy share while producing: near 1, every runnable thread queues
        machine_busy = (machine_end[0] - machine_start[0]) / max(1, machine_end[1] -
                                                                  machine_start[1])
        # every event must arrive: wait (bounded) for the stragglers
        time.sleep(2.0)
        stop.set()
        sampler.join()
        samples.append((time.monotonic() - t0, rss_mb(proc.pid)))
        sizes.append(file_mb(db))
        parent.send("stop")
        counts, bad, times = parent.recv()
        sub_proc.join(30)
        lat, from_request, firsts_late, spreads = delivery_latencies(times, answered,
                                                                     requested)
        rss = [r for _, r in samples]
        client.close()
        result = {"sent": sent, "achieved": achieved, "complete": sum(c == sent for c in counts),
                  "min_count": min(counts), "out_of_order": sum(bad),
                  "p50_ms": 1000 * pct(lat, 50), "p99_ms": 1000 * pct(lat, 99),
                  "max_ms": 1000 * max(lat) if lat else float("nan"), "latencies": len(lat),
                  "request_p50_ms": 1000 * pct(from_request, 50),
                  "request_p99_ms": 1000 * pct(from_request, 99),
                  "first_p99_ms": 1000 * pct(firsts_late, 99), "spread_p50_ms": 1000 * pct(spreads, 50),
                  "spread_p99_ms": 1000 * pct(spreads, 99),
                  "rss_first": rss[0], "rss_last": rss[-1], "rss_max": max(rss),
                  "rss_slope_mb_per_min": slope_per_min(samples[len(samples) // 10:]),
                  "rss_samples": len(samples), "load_start": load_start,
                  "file_first": sizes[0], "file_last": sizes[-1], "server_cpu": server_cpu,
                  "loop_cpu": loop_cpu, "subscribers_cpu": subscribers_cpu,
                  "producer_cpu": producer_cpu, "burn_cpu": burn_cpu,
                  "machine_busy": machine_busy,
                  "load_end": os.getloadavg()}
    finally:
        proc.terminate()
        proc.wait(30)
    if args.gc_trace:
        records = json.loads(gc_log.read_text()) if gc_log.exists() else []
        result["gc"] = gc_summary(records, cpu_t0, produced_at)
    return result


# -- the same fan-out in process -------------------------------------------------------------

def run_in_process(args, tmp: Path) -> dict:
    kb = slr_sql.open(tmp / "inproc.db")
    kb.add("e(-1)^0")
    n = args.subscribers
    counts = [0] * n
    times: list[list[float]] = [[] for _ in range(n)]
    answered: list[float] = []
    seconds = args.latency_seconds
    loop = asyncio.new_event_loop()
    subs = [kb.subscribe("e(I)^T", since=0.5) for _ in range(n)]

    async def one(k: int) -> None:
        mine = times[k]
        async for a in subs[k]:
            mine.append(time.monotonic())
            counts[k] += 1

    def run_loop() -> None:
        asyncio.set_event_loop(loop)
        loop.run_until_complete(asyncio.gather(*[one(k) for k in range(n)],
                                               return_exceptions=True))
    thread = threading.Thread(target=run_loop, daemon=True)
    thread.start()
    sent, achieved = produce(kb.add_many, args.rate, args.batch_events, seconds, answered, float("inf"))
    deadline = time.monotonic() + 10
    while min(counts) < sent and time.monotonic() < deadline:
        time.sleep(0.05)
    for s in subs:
        s.close()
    thread.join(10)
    kb.close()
    lat = [max(0.0, t - answered[i]) for mine in times for i, t in enumerate(mine)
           if i < len(answered)]
    return {"sent": sent, "achieved": achieved, "complete": sum(c == sent for c in counts),
            "p50_ms": 1000 * pct(lat, 50), "p99_ms": 1000 * pct(lat, 99)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--subscribers", type=int, default=100)
    ap.add_argument("--rate", type=float, default=1000.0)
    ap.add_argument("--batch-events", type=int, default=10)
    ap.add_argument("--frame-batch", type=int, default=256)
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--latency-seconds", type=float, default=20.0)
    ap.add_argument("--sample-seconds", type=float, default=5.0)
    ap.add_argument("--cache-kib", type=int, default=0,
                    help="run the server with this SQLite page cache (KiB; default: the "
                         "store's own, 64 MiB)")
    ap.add_argument("--trace", action="store_true", help="print each RSS sample")
    ap.add_argument("--gc-trace", action="store_true",
                    help="record the server's garbage collections (gc.callbacks) while producing")
    ap.add_argument("--burn", type=int, default=0,
                    help="processes spinning on a core beside the run (a competing CPU load)")
    ap.add_argument("--client", choices=("websockets", "raw"), default="websockets",
                    help="the subscribers' WebSocket client: the websockets library's, or a "
                         "minimal one (a few µs per frame)")
    ap.add_argument("--floor-server", action="store_true",
                    help="serve with benchmarks/floor_ws_server.py (no store: one loop writing "
                         "each batch's frame to every subscriber), not `slr serve`: the floor "
                         "the rest of the machine leaves for any server")
    ap.add_argument("--floor-work-us", type=float, default=0.0,
                    help="with --floor-server: CPU it spends per event (µs), a costlier server")
    ap.add_argument("--floor-work-thread", action="store_true",
                    help="with --floor-work-us: spend it on a worker thread (two hops per add)")
    ap.add_argument("--server-code", help="run `slr serve` from this checkout (before/after)")
    ap.add_argument("--no-in-process", action="store_true",
                    help="skip the in-process baseline (a soak of the server alone)")
    args = ap.parse_args()
    if args.floor_server and (args.gc_trace or args.cache_kib or args.server_code):
        ap.error("--floor-server is no slr serve: --gc-trace, --cache-kib and --server-code "
                 "do not apply to it")
    if (args.floor_work_us or args.floor_work_thread) and not args.floor_server:
        ap.error("--floor-work-us and --floor-work-thread go with --floor-server")
    burners = [subprocess.Popen([sys.executable, "-c", "while 1: pass"])
               for _ in range(args.burn)]
    args.burn_pids = [burner.pid for burner in burners]
    try:
        run(args)
    finally:
        for burner in burners:
            burner.kill()
            burner.wait()


def run(args) -> None:
    if args.burn:
        print(f"competing load: {args.burn} process(es) spinning on a core", flush=True)
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        local = {"sent": 0, "achieved": 0, "complete": 0, "p50_ms": math.nan,
                 "p99_ms": math.nan} if args.no_in_process else run_in_process(args, tmp)
        print(f"in process : {args.subscribers} subscribers, {local['sent']} events: "
              f"{local['complete']} complete (achieved {local['achieved']:.0f} events/s); p50 {local['p50_ms']:.2f} ms, "
              f"p99 {local['p99_ms']:.2f} ms", flush=True)
        remote = run_service(args, tmp)
        print(f"service    : {args.subscribers} WebSocket subscribers, {remote['sent']} events "
              f"over HTTP add_many x{args.batch_events} at {args.rate:g}/s for "
              f"{args.minutes:g} min worth (achieved {remote['achieved']:.0f} events/s): {remote['complete']} complete (min count "
              f"{remote['min_count']}, out of order {remote['out_of_order']}); latency over the "
              f"first {args.latency_seconds:g} s ({remote['latencies']} deliveries): p50 "
              f"{remote['p50_ms']:.2f} ms, p99 {remote['p99_ms']:.2f} ms, max "
              f"{remote['max_ms']:.1f} ms; from the add_many request made: p50 "
              f"{remote['request_p50_ms']:.2f} ms, p99 {remote['request_p99_ms']:.2f} ms",
              flush=True)
        print(f"tail: an event's first delivery p99 {remote['first_p99_ms']:.2f} ms after its "
              f"answer; from its first to its last subscriber p50 {remote['spread_p50_ms']:.2f} "
              f"ms, p99 {remote['spread_p99_ms']:.2f} ms", flush=True)
        print(f"server CPU while producing: {remote['server_cpu']:.2f} s per second "
              f"({remote['server_cpu'] / remote['achieved'] * 1e6:.0f} µs per event, "
              f"{remote['server_cpu'] / remote['achieved'] / args.subscribers * 1e6:.2f} µs "
              f"per delivery); its event loop thread {remote['loop_cpu'] / remote['achieved'] * 1e6:.0f} "
              f"µs per event; the subscribers' process {remote['subscribers_cpu'] / remote['achieved'] * 1e6:.0f} "
              f"µs per event, the producer {remote['producer_cpu'] / remote['achieved'] * 1e6:.0f} µs per event")
        print(f"the cores while producing: {100 * remote['machine_busy']:.0f}% busy of "
              f"{os.cpu_count()}" + (f"; the competing load took {remote['burn_cpu']:.2f} of a "
                                    f"core" if args.burn else ""))
        print(f"p99 ratio service / in process: {remote['p99_ms'] / local['p99_ms']:.1f}x")
        print(f"server RSS: first {remote['rss_first']:.1f} MB, last {remote['rss_last']:.1f} "
              f"MB, max {remote['rss_max']:.1f} MB, slope {remote['rss_slope_mb_per_min']:+.2f} "
              f"MB/min ({remote['rss_samples']} samples, first 10% left out of the slope); "
              f"store file + WAL {remote['file_first']:.1f} -> {remote['file_last']:.1f} MB"
              + (f" (page cache bound {args.cache_kib} KiB)" if args.cache_kib else ""))
        if "gc" in remote:
            print(f"server garbage collections while producing: {remote['gc']}")
        print("load average (1, 5, 15 min): start %.2f %.2f %.2f, end %.2f %.2f %.2f"
              % (*remote["load_start"], *remote["load_end"]))


if __name__ == "__main__":
    main()
