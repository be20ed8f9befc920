"""Service benchmark: the network service against the same work in process, in one run.

* **Batch ingest**: N events ``seg(oK, [x, y, z])^t`` in batches of 5,000, through
  ``slr_sql.connect(url).add_many`` to a real ``slr serve`` process, against
  ``kb.add_many`` in this process on a file of its own (both ``synchronous=FULL``: every batch
  is fsynced before it is answered). Once as SLR text, once as ``(name, args, start, end)``
  tuples. Target: HTTP throughput >= 0.5x in process.
* **Query round trip**: ``prev(seg(O, L)^Z, T)`` with ``args`` bound (the robot's point
  query), p50 over many calls through the client, against (the same query in process + one
  empty request, ``GET /health``, to the same server through the same client).
  Target: HTTP p50 <= 3x that sum.

Run by hand::

    python benchmarks/bench_service.py                 # 100,000 events, 3,000 queries
    python benchmarks/bench_service.py --n 20000 --queries 1000
"""
from __future__ import annotations

import argparse
import os
import queue
import random
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import slr_sql  # noqa: E402

BATCH = 5000


def make_events(n: int, objects: int = 1000) -> tuple[list[str], list[tuple]]:
    rng = random.Random(7)
    texts, tuples = [], []
    for i in range(n):
        t = i * 0.01
        x, y, z = rng.random(), rng.random(), rng.random()
        texts.append(f"seg(o{i % objects}, [{x!r}, {y!r}, {z!r}])^{t!r}")
        tuples.append(("seg", [f"o{i % objects}", [x, y, z]], t, t))
    return texts, tuples


def start_server(db: Path) -> tuple[subprocess.Popen, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    proc = subprocess.Popen([sys.executable, "-m", "slr_sql", "serve", str(db), "--port", "0"],
                            stdout=subprocess.PIPE, env=env)
    lines: queue.Queue = queue.Queue()
    threading.Thread(target=lambda: lines.put(proc.stdout.readline()), daemon=True).start()
    first = lines.get(timeout=60).decode()
    url = first.strip().rsplit(" on ", 1)[1]
    with slr_sql.connect(url) as kb:   # wait until it answers
        deadline = time.monotonic() + 60
        while True:
            try:
                kb.health()
                break
            except slr_sql.SLRError:
                if time.monotonic() > deadline:
                    raise
    return proc, url


def ingest(kb, events: list, timer=time.perf_counter) -> float:
    began = timer()
    for i in range(0, len(events), BATCH):
        rejected = kb.add_many(events[i:i + BATCH])
        assert not rejected, rejected[:3]
    return timer() - began


def p50_us(samples: list[float]) -> float:
    return statistics.median(samples) * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=100_000, help="events to ingest")
    parser.add_argument("--queries", type=int, default=3000, help="query round trips")
    args = parser.parse_args()

    texts, tuples = make_events(args.n)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        proc, url = start_server(tmp / "served.db")
        try:
            with slr_sql.connect(url) as remote, slr_sql.open(tmp / "local.db") as local:
                print(f"{args.n:,} events in batches of {BATCH:,}; server {url}")
                rows = []
                for label, events in (("SLR text", texts), ("tuples", tuples)):
                    local_s = ingest(local, events)
                    remote_s = ingest(remote, events)
                    rows.append((label, args.n / local_s, args.n / remote_s))
                print("| events as | in process | over HTTP | HTTP / in process |")
                print("|---|---:|---:|---:|")
                for label, a, b in rows:
                    print(f"| {label} | {a:,.0f} ev/s | {b:,.0f} ev/s | {b / a:.2f}x |")

                rng = random.Random(11)
                goal = "prev(seg(O, L)^Z, T)"
                calls = [{"O": f"o{rng.randrange(1000)}", "T": rng.uniform(0, args.n * 0.01)}
                         for _ in range(args.queries)]
                for c in calls[:200]:                # warm both plan caches and connections
                    assert local.query(goal, args=c) == remote.query(goal, args=c)
                    remote.health()
                in_process, over_http, empty = [], [], []
                for c in calls:                      # interleaved: the same load on all three
                    t0 = time.perf_counter()
                    local.query(goal, args=c)
                    t1 = time.perf_counter()
                    remote.query(goal, args=c)
                    t2 = time.perf_counter()
                    remote.health()
                    t3 = time.perf_counter()
                    in_process.append(t1 - t0)
                    over_http.append(t2 - t1)
                    empty.append(t3 - t2)
                base = p50_us(in_process) + p50_us(empty)
                print()
                print("| query | p50 | p99 |")
                print("|---|---:|---:|")
                for label, s in (("in process", in_process), ("empty request (GET /health)", empty),
                                 ("over HTTP", over_http)):
                    p99 = sorted(s)[int(len(s) * 0.99)] * 1e6
                    print(f"| {label} | {p50_us(s):,.0f} µs | {p99:,.0f} µs |")
                print(f"\nHTTP p50 / (in-process p50 + empty-request p50) = "
                      f"{p50_us(over_http):,.0f} / {base:,.0f} = {p50_us(over_http) / base:.2f}x "
                      f"(target <= 3x)")
        finally:
            proc.terminate()
            proc.wait(timeout=30)


if __name__ == "__main__":
    main()
