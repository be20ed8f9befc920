"""Point-query latency through the public API, against raw sqlite3 for the same lookup.

    python benchmarks/bench_query.py            # 10k, 100k and 1M stored events
    python benchmarks/bench_query.py --sizes 10000

For each size: N events seg(oK, [x,y,z])^t over 1,000 objects (t = 0.01 * i), then the p50/p99 of
kb.query("prev(seg(O, L)^Z, T)", args={"O": ..., "T": ...}) over random objects and times, and the
p50 of the hand-written sqlite3 lookup returning the same row (same file, same indexes).
"""
from __future__ import annotations

import argparse
import random
import sqlite3
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import slr_sql  # noqa: E402

OBJECTS = 1000


def build(path: Path, n: int) -> None:
    with slr_sql.open(str(path), clock=slr_sql.ManualClock(0.0), synchronous="OFF") as kb:
        batch = []
        for i in range(n):
            batch.append(("seg", (f"o{i % OBJECTS}", [0.1, 0.2, 0.3]), i * 0.01, i * 0.01))
            if len(batch) == 100_000:
                kb.add_many(batch)
                batch = []
        if batch:
            kb.add_many(batch)


def percentile(xs: list[float], p: float) -> float:
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(p * len(xs)))]


def measure(path: Path, n: int, reps: int = 3000) -> dict:
    rng = random.Random(1)
    probes = [(f"o{rng.randrange(OBJECTS)}", rng.uniform(0, n * 0.01)) for _ in range(reps)]
    goal = "prev(seg(O, L)^Z, T)"
    api = []
    with slr_sql.open(str(path)) as kb:
        kb.query(goal, args={"O": "o1", "T": 1.0})  # warm the plan cache
        for obj, t in probes:
            t0 = time.perf_counter()
            kb.query(goal, args={"O": obj, "T": t})
            api.append(time.perf_counter() - t0)
        check = kb.query(goal, args={"O": probes[0][0], "T": probes[0][1]})
    con = sqlite3.connect(str(path))
    sql = ("SELECT arg1, arg2, t_start, t_end FROM seg WHERE arg1 = ? AND t_end = "
           "(SELECT max(t_end) FROM seg WHERE arg1 = ? AND t_end <= ?) ORDER BY t_start, seq")
    raw = []
    for obj, t in probes:
        t0 = time.perf_counter()
        rows = con.execute(sql, (obj, obj, t)).fetchall()
        raw.append(time.perf_counter() - t0)
    raw_check = con.execute(sql, (probes[0][0], probes[0][0], probes[0][1])).fetchall()
    con.close()
    assert len(check) == len(raw_check), (check, raw_check)
    return {"n": n, "api_p50": percentile(api, 0.5) * 1e6, "api_p99": percentile(api, 0.99) * 1e6,
            "raw_p50": percentile(raw, 0.5) * 1e6}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", type=int, nargs="*", default=[10_000, 100_000, 1_000_000])
    args = ap.parse_args()
    print(f"{'events':>10} {'api p50 µs':>11} {'api p99 µs':>11} {'raw p50 µs':>11} {'api/raw':>8}")
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.sizes:
            path = Path(tmp) / f"q{n}.db"
            build(path, n)
            r = measure(path, n)
            results.append(r)
            print(f"{n:>10} {r['api_p50']:>11.1f} {r['api_p99']:>11.1f} {r['raw_p50']:>11.1f} "
                  f"{r['api_p50'] / r['raw_p50']:>8.2f}")
    if len(results) > 1:
        print(f"growth p50 {results[-1]['n']} vs {results[0]['n']}: "
              f"{results[-1]['api_p50'] / results[0]['api_p50']:.2f}x")


if __name__ == "__main__":
    main()
