"""Timeline plot figures, recorded in benchmarks/README.md under "Plots".

A file store with N events (default 1,000,000) of three types between t=0 and t=1000 s:
60 % `pose_x(X)^T` points carrying a number (drawn as a row and as a --value line), 30 %
`busy(R)^[S, E]` intervals, 10 % `bump(R)^T` points. Measured in the same run:

* baseline: raw sqlite3 reading the same events, `SELECT t_start, t_end FROM <table>` for
  each of the three tables, fetchall (fresh connection, the file already in the page cache);
* plot: `kb.plot(values=["pose_x:1"])` and `savefig` of the 1200-pixel PNG (matplotlib already
  imported), split into reading (SQL aggregation per pixel column) and drawing + saving;
* cli: `python -m slr_sql plot DB --value pose_x:1 -o FILE` as a new process (Python start,
  imports, open, plot, PNG), what a user waits for;
* unbinned (only with --unbinned): the same plot drawing every event (exact_limit above N),
  to show what the aggregation saves.

Run:  python benchmarks/bench_plot.py [--events 1000000] [--repeat 3] [--db PATH] [--unbinned]
"""
from __future__ import annotations

import argparse
import os
import random
import sqlite3
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import slr_sql  # noqa: E402
from slr_sql.plot import collect_timeline, draw_timeline, save_timeline  # noqa: E402

TABLES = ("pose_x", "busy", "bump")
HORIZON = 1000.0


def build(path: str, n: int, seed: int = 5) -> None:
    rng = random.Random(seed)
    n_pose, n_busy = n * 6 // 10, n * 3 // 10
    n_bump = n - n_pose - n_busy
    kb = slr_sql.open(path, synchronous="OFF")
    try:
        batch: list[tuple] = []

        def flush(force: bool = False) -> None:
            if batch and (force or len(batch) >= 50_000):
                kb.add_many(batch)
                batch.clear()

        x = 0.0
        for i in range(n_pose):
            t = HORIZON * i / n_pose
            x += rng.gauss(0.0, 0.01)
            batch.append(("pose_x", [round(x, 4)], t, t))
            flush()
        for i in range(n_busy):
            start = rng.uniform(0.0, HORIZON)
            batch.append(("busy", [f"r{i % 8}"], start, start + rng.expovariate(2.0)))
            flush()
        for i in range(n_bump):
            t = rng.uniform(0.0, HORIZON)
            batch.append(("bump", [f"r{i % 8}"], t, t))
            flush()
        flush(force=True)
    finally:
        kb.close()


def raw_scan(path: str) -> int:
    con = sqlite3.connect(path)
    try:
        return sum(len(con.execute(f'SELECT t_start, t_end FROM "{table}"').fetchall())
                   for table in TABLES)
    finally:
        con.close()


def timed(fn, repeat: int) -> tuple[list[float], object]:
    times, result = [], None
    for _ in range(repeat):
        start = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - start)
    return times, result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--events", type=int, default=1_000_000)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--db", default=None, help="keep (or reuse) the store in this file")
    parser.add_argument("--unbinned", action="store_true")
    args = parser.parse_args()

    scratch = tempfile.TemporaryDirectory()
    path = args.db or os.path.join(scratch.name, "plot.db")
    if not os.path.exists(path):
        t = time.perf_counter()
        build(path, args.events)
        print(f"built {args.events:,} events in {time.perf_counter() - t:.1f} s: {path}")
    out = os.path.join(scratch.name, "plot.png")

    raw_times, rows = timed(lambda: raw_scan(path), args.repeat)
    print(f"baseline raw sqlite3 scan of {rows:,} events: best {min(raw_times):.3f} s, "
          f"median {statistics.median(raw_times):.3f} s")

    kb = slr_sql.open(path)
    try:
        collect_times, draw_times, total_times = [], [], []
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            drawn = collect_timeline(kb, values=["pose_x:1"])
            t1 = time.perf_counter()
            save_timeline(draw_timeline(drawn), out)
            t2 = time.perf_counter()
            collect_times.append(t1 - t0)
            draw_times.append(t2 - t1)
            total_times.append(t2 - t0)
        counted = sum(r.count for r in drawn.rows)
        modes = ", ".join(f"{r.label} {r.mode}" for r in drawn.rows)
        print(f"plot of {counted:,} events ({modes}; value line {drawn.series[0].mode}): "
              f"best {min(total_times):.3f} s = read {min(collect_times):.3f} s + "
              f"draw/save {min(draw_times):.3f} s; median {statistics.median(total_times):.3f} s")
        print(f"ratio plot / raw scan (best): {min(total_times) / min(raw_times):.2f}x")

        if args.unbinned:
            start = time.perf_counter()
            save_timeline(kb.plot(values=["pose_x:1"], exact_limit=args.events + 1), out)
            print(f"unbinned plot (every event drawn): {time.perf_counter() - start:.1f} s")
    finally:
        kb.close()

    cli_times = []
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    for _ in range(args.repeat):
        start = time.perf_counter()
        subprocess.run([sys.executable, "-m", "slr_sql", "plot", path, "--value", "pose_x:1",
                        "-o", out], check=True, capture_output=True, env=env)
        cli_times.append(time.perf_counter() - start)
    print(f"cli `slr plot` process: best {min(cli_times):.3f} s, "
          f"median {statistics.median(cli_times):.3f} s "
          f"(ratio to raw scan {min(cli_times) / min(raw_times):.2f}x)")


if __name__ == "__main__":
    main()
