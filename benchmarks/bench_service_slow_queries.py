"""Adds beside slow queries: how long an ``add_many`` of one event takes on ``slr serve`` while
``--queries`` (60) CPU-bound queries of the interpreter (``spin(N)``, ~1.5 s each alone) are
asked at once, against the same add on the idle server in the same run (the ratio).

The server's thread pool has 40 threads; the interpreter holds the GIL while it evaluates. The
figures: the add alone (median of 5), each of ``--adds`` (5) adds made one after the other
1 s after the queries were sent, and what the queries got (200, 408 when they ran out of
``--max-query-time``, 503 when no slot of ``--max-running-queries`` came within it).

Run by hand::

    python benchmarks/bench_service_slow_queries.py
    python benchmarks/bench_service_slow_queries.py --server-code /tmp/before   # earlier server
    python benchmarks/bench_service_slow_queries.py --serve-args "--max-running-queries 1"
"""
from __future__ import annotations

import argparse
import json
import os
import shlex
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import urllib.error
import urllib.request
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SPIN = "spin(0). spin(N) :- N > 0, N1 is N - 1, spin(N1)."


def post(url: str, path: str, body: dict, timeout: float = 600.0) -> tuple[int, dict]:
    req = urllib.request.Request(url + path, json.dumps(body).encode(),
                                 {"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(req, timeout=timeout) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as e:
        return e.code, json.loads(e.read())


def queries_now(url: str) -> dict[str, int]:
    """The server's queries running and waiting for a slot (``GET /health``)."""
    with urllib.request.urlopen(url + "/health", timeout=60) as answer:
        queries = json.loads(answer.read())["queries"]
    return {"running": queries["running"], "waiting": queries["waiting"]}


def timed_add(url: str, i: int) -> float:
    t = time.perf_counter()
    status, _ = post(url, "/add_many", {"events": [f"e({i})^{i}"]})
    assert status == 200, status
    return time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--queries", type=int, default=60)
    ap.add_argument("--loops", type=int, default=300_000, help="spin(N): N")
    ap.add_argument("--adds", type=int, default=5)
    ap.add_argument("--server-code", default=str(ROOT), help="run `slr serve` from this checkout")
    ap.add_argument("--serve-args", default="", help="more `slr serve` options")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ, PYTHONPATH=args.server_code)
        server = subprocess.Popen(
            [sys.executable, "-m", "slr_sql", "serve", f"{tmp}/slow.db", "--port", "0",
             *shlex.split(args.serve_args)],
            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env,
            cwd=args.server_code)
        try:
            assert server.stdout is not None
            url = server.stdout.readline().split(" on ")[1].strip()
            assert post(url, "/load", {"text": SPIN})[0] == 200
            t = time.perf_counter()
            post(url, "/query", {"goal": f"spin({args.loops})", "limit": 1})
            one_query = time.perf_counter() - t
            alone = statistics.median(timed_add(url, 1_000_000 + i) for i in range(5))
            codes: list[int] = []

            def ask() -> None:
                codes.append(post(url, "/query", {"goal": f"spin({args.loops})"})[0])

            threads = [threading.Thread(target=ask) for _ in range(args.queries)]
            for th in threads:
                th.start()
            # the adds are timed once every query runs or waits for a slot (/health counts
            # them): a deadline, not a guess at how long that takes
            deadline = time.monotonic() + 60
            while sum(queries_now(url).values()) < args.queries and time.monotonic() < deadline:
                threading.Event().wait(0.01)
            beside = [timed_add(url, i) for i in range(args.adds)]
            for th in threads:
                th.join()
        finally:
            server.terminate()
            server.wait(30)
    counts = {c: codes.count(c) for c in sorted(set(codes))}
    print(f"one query alone {one_query:.2f} s; an add alone (median of 5) "
          f"{alone * 1000:.1f} ms")
    print(f"adds beside {args.queries} queries: "
          + ", ".join(f"{b * 1000:.0f}" for b in beside) + " ms; median "
          f"{statistics.median(beside) * 1000:.0f} ms = {statistics.median(beside) / alone:.0f}x "
          f"the add alone; the queries got {counts}")


if __name__ == "__main__":
    main()
