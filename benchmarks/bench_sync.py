"""Synchronized queries: release -> answer latency with 1,000 pending queries, and idle CPU.

Three latency scenarios, each with ``--queries`` (1,000) queries pending while events stream
into a file store; a query's latency is the time from the start of the call that releases it
(``kb.add`` of the arrival or mark, or the clock deadline) to its done-callback:

* ``marks``   — ``prev(s(X)^T, z)`` at 1,000 different z (``max_delay`` 1000 s): events
  ``s(k)^t`` stream in, and every 10th event is followed by ``fullyUpdated(s/1)^t`` which
  releases the queries with z <= t (about 10 at a time);
* ``in_order`` — ``next(r(X)^T, [z, z+100])`` on an in_order type: each query is released by
  the first arrival after its z (the event that arrives is the answer);
* ``clock``   — WallClock, ``findall(X, w(X)^_, L)`` at z spread over 2 s with max_delay 20 ms:
  released by the timer thread when the clock passes z + 20 ms (latency measured from that
  deadline).

Idle CPU: 1,000 queries pending on a WallClock store (waiting for marks / a deadline 1000 s
away), no events for ``--idle`` seconds; ``time.process_time()`` over that interval (every
thread of the process).

Run by hand::

    python benchmarks/bench_sync.py                 # all scenarios, 1,000 queries
    python benchmarks/bench_sync.py --queries 200 --idle 2
"""
from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import slr_sql  # noqa: E402
from percentiles import pct  # noqa: E402  (benchmarks/percentiles.py)


class Latencies:
    """Done-callbacks record perf_counter; `release` holds the release instant per query."""

    def __init__(self) -> None:
        self.release: dict[str, float] = {}
        self.done: dict[str, float] = {}
        self.errors: list[str] = []
        self.lock = threading.Lock()
        self.all_done = threading.Event()
        self.expected = 0

    def callback(self, p) -> None:
        t = time.perf_counter()
        with self.lock:
            self.done[p.id] = t
            if p.exception() is not None:
                self.errors.append(f"{p.id}: {p.exception()}")
            if len(self.done) >= self.expected:
                self.all_done.set()

    def values_ms(self) -> list[float]:
        return [(self.done[i] - self.release[i]) * 1000.0 for i in self.done if i in self.release]


SYNC = "NORMAL"
WORKERS: int | None = None


def open_kb(path: str, clock):
    kb = slr_sql.open(path, clock=clock, synchronous=SYNC)
    if WORKERS is not None:
        kb._sync.workers = WORKERS  # before the first evaluation starts the pool
    return kb


def scenario_marks(n: int, path: str) -> Latencies:
    clock = slr_sql.ManualClock(0.0)
    lat = Latencies()
    lat.expected = n
    with open_kb(path, clock) as kb:
        kb.load(":- max_delay(s/1, 1000).")
        zs = [(i + 1) * 0.01 for i in range(n)]
        for i, z in enumerate(zs):
            kb.submit(f"prev(s(X)^T, {z})", at=z, id=f"m{i}", callback=lat.callback)
        kb._sync.drain()
        assert len(kb.pending()) == n
        k = 0
        t = 0.0
        while len(lat.done) < n:
            k += 1
            t = round(k * 0.001, 6)
            clock.set(t + 0.0005)
            kb.add(f"s({k})^{t}")
            if k % 10 == 0:
                released = [f"m{i}" for i, z in enumerate(zs) if t - 0.01 < z <= t]
                t0 = time.perf_counter()
                kb.add(f"fullyUpdated(s/1)^{t}")
                for qid in released:
                    lat.release[qid] = t0
                kb._sync.drain()
            if k > n * 20:
                break
    return lat


def scenario_in_order(n: int, path: str) -> Latencies:
    clock = slr_sql.ManualClock(0.0)
    lat = Latencies()
    lat.expected = n
    with open_kb(path, clock) as kb:
        kb.load(":- in_order(r/1). :- max_delay(r/1, 1000).")
        zs = [(i + 1) * 0.01 - 0.005 for i in range(n)]
        for i, z in enumerate(zs):
            kb.submit(f"next(r(X)^T, [{z}, {z} + 100])", at=z, id=f"r{i}", callback=lat.callback)
        kb._sync.drain()
        assert len(kb.pending()) == n
        for k in range(1, n + 1):
            t = round(k * 0.01, 6)
            clock.set(t + 0.001)
            t0 = time.perf_counter()
            kb.add(f"r({k})^{t}")
            lat.release[f"r{k - 1}"] = t0
            kb._sync.drain()
    return lat


def scenario_clock(n: int, path: str, spread: float = 2.0, delay: float = 0.02) -> Latencies:
    clock = slr_sql.WallClock()
    lat = Latencies()
    lat.expected = n
    with open_kb(path, clock) as kb:
        kb.load(f":- max_delay(w/1, {delay}).")
        start = clock.now() + 0.5
        kb.add(f"w(0)^{start - 1}")
        deadline_wall: dict[str, float] = {}
        offset = time.perf_counter() - time.time()
        for i in range(n):
            z = start + spread * i / n
            kb.submit("findall(X, w(X)^_, L)", at=z, id=f"c{i}", callback=lat.callback)
            deadline_wall[f"c{i}"] = z + delay + offset
        lat.release = deadline_wall
        lat.all_done.wait(timeout=spread + 30)
    return lat


def idle_cpu(n: int, seconds: float, path: str) -> tuple[float, int]:
    with slr_sql.open(path) as kb:  # WallClock
        kb.load(":- max_delay(s/1, 1000).")
        now = kb.clock.now()
        for i in range(n):
            kb.submit(f"prev(s(X)^T, {now + i * 0.001})", at=now + i * 0.001, id=f"i{i}")
        kb._sync.drain()
        pending = len(kb.pending())
        threads = threading.active_count()
        c0 = time.process_time()
        time.sleep(seconds)
        c1 = time.process_time()
    return c1 - c0, pending, threads


def service_time(n: int, path: str) -> float:
    """Milliseconds per evaluation of a released query, on one thread, without the pool:
    the synchronizer's own cost (what the latencies are made of when nothing else runs)."""
    clock = slr_sql.ManualClock(0.0)
    with open_kb(path, clock) as kb:
        kb.load(":- max_delay(s/1, 1000).")
        kb.add_many([f"s({k})^{k * 0.001}" for k in range(1, 5000)])
        qs = [kb.submit(f"prev(s(X)^T, {i * 0.005})", at=i * 0.005, id=f"m{i}")
              for i in range(n)]
        sync = kb._sync
        sync.drain()
        with sync.lock:
            sync.tracker.marks[("s", 1)] = 1e9    # complete, without releasing through the pool
        t0 = time.perf_counter()
        for q in qs:
            sync._attempt(q)
        return (time.perf_counter() - t0) / n * 1000.0


def report(name: str, run, *a) -> None:
    lat = run(*a)
    ms = lat.values_ms()
    print(f"{name:9s} answered {len(lat.done):5d}  errors {len(lat.errors)}  "
          f"p50 {statistics.median(ms):7.3f} ms  p99 {pct(ms, 99):7.3f} ms  "
          f"max {max(ms):7.3f} ms")
    for e in lat.errors[:3]:
        print("   ", e)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--queries", type=int, default=1000)
    ap.add_argument("--idle", type=float, default=3.0, help="seconds of idle CPU measurement")
    ap.add_argument("--synchronous", default="NORMAL",
                    help="the store's PRAGMA synchronous: NORMAL (default here: no fsync per "
                         "commit, so the figure is the synchronizer's) or FULL (the library "
                         "default: every add and mark waits for an fsync first)")
    ap.add_argument("--workers", type=int, default=None,
                    help="evaluation threads of the synchronizer (default: the library's)")
    args = ap.parse_args()
    global SYNC, WORKERS
    SYNC = args.synchronous.upper()
    WORKERS = args.workers
    with tempfile.TemporaryDirectory() as d:
        print(f"{args.queries} pending queries per scenario; latency = release -> done-callback; "
              f"synchronous={SYNC}")
        report("marks", scenario_marks, args.queries, f"{d}/marks.db")
        report("in_order", scenario_in_order, args.queries, f"{d}/inorder.db")
        report("clock", scenario_clock, args.queries, f"{d}/clock.db")
        print(f"service   {service_time(args.queries, f'{d}/service.db'):.3f} ms per evaluation "
              f"of a released prev query (one thread, no pool)")
        cpu, pending, threads = idle_cpu(args.queries, args.idle, f"{d}/idle.db")
        print(f"idle      {pending} pending (WallClock), {threads} threads: CPU "
              f"{cpu * 1000:.1f} ms over {args.idle:g} s ({100 * cpu / args.idle:.3f} %)")


if __name__ == "__main__":
    main()
