"""Point-query latency through the public API, against raw sqlite3 for the same lookup.

    python benchmarks/bench_query.py            # 10k, 100k and 1M stored events
    python benchmarks/bench_query.py --sizes 10000
    python benchmarks/bench_query.py --sizes 100000 --before /tmp/old   # before/after, one run

    python benchmarks/bench_query.py --sizes 100000 --cpu-before /tmp/old      # CPU, paired

``--cpu-before DIR``: process CPU per lookup of kb.query, this code against the checkout
``DIR``, each in a worker process on a file of the same events that it built itself, in
chunks of 2,000 lookups in alternation (A B, B A, ...; ``--rounds`` pairs): the two sides of a
pair ran within a second of each other, so the ratio per pair holds up on a loaded machine
where wall latency does not.

``--before DIR``: a checkout of earlier code (e.g. ``git archive COMMIT | tar -x -C DIR``)
measured in a child process on a file of the same events that it built itself, in alternation
with this code (rounds of
``--rounds``), each side against raw sqlite3 timed in its own process: the ratios of the
two codes come from one run on one machine state.

For each size: N events seg(oK, [x,y,z])^t over 1,000 objects (t = 0.01 * i), then the p50/p99 of
kb.query("prev(seg(O, L)^Z, T)", args={"O": ..., "T": ...}) over random objects and times, and the
p50 of the hand-written sqlite3 lookup returning the same row (same file, same indexes).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import random
import sqlite3
import statistics
import sys
import tempfile
import time
from pathlib import Path

_code = sys.argv[sys.argv.index("--code") + 1] if "--code" in sys.argv else \
    str(Path(__file__).resolve().parent.parent)
sys.path.insert(0, _code)

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
        con.execute(sql, (obj, obj, t)).fetchall()
        raw.append(time.perf_counter() - t0)
    raw_check = con.execute(sql, (probes[0][0], probes[0][0], probes[0][1])).fetchall()
    con.close()
    assert len(check) == len(raw_check), (check, raw_check)
    return {"n": n, "api_p50": percentile(api, 0.5) * 1e6, "api_p99": percentile(api, 0.99) * 1e6,
            "raw_p50": percentile(raw, 0.5) * 1e6}


def measure_before(code: str, path: Path, n: int, reps: int) -> dict:
    """measure() with the code of the checkout ``code``, in a child process."""
    env = dict(os.environ, PYTHONPATH=code)
    out = subprocess.run([sys.executable, __file__, "--code", code, "--measure", str(path),
                          str(n), str(reps)], env=env, capture_output=True, text=True,
                         check=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def compare(args) -> None:
    """This code and the code of ``--before`` in alternation on one file per size."""
    print(f"{'events':>10} | {'before p50':>10} {'raw p50':>8} {'ratio':>6} | "
          f"{'after p50':>10} {'raw p50':>8} {'ratio':>6} | after/before")
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.sizes:
            # each code builds its own file of the same events (a newer schema may be one
            # the earlier code refuses to open)
            path, old_path = Path(tmp) / f"q{n}.db", Path(tmp) / f"q{n}-before.db"
            build(path, n)
            old, new = [], []
            for _ in range(args.rounds):
                old.append(measure_before(args.before, old_path, n, args.reps))
                new.append(measure(path, n, args.reps))
            o = min(old, key=lambda r: r["api_p50"] / r["raw_p50"])
            w = min(new, key=lambda r: r["api_p50"] / r["raw_p50"])
            ro, rw = o["api_p50"] / o["raw_p50"], w["api_p50"] / w["raw_p50"]
            print(f"{n:>10} | {o['api_p50']:>8.1f}µs {o['raw_p50']:>6.1f}µs {ro:>5.2f}x | "
                  f"{w['api_p50']:>8.1f}µs {w['raw_p50']:>6.1f}µs {rw:>5.2f}x | "
                  f"{w['api_p50'] / o['api_p50']:.2f}")
            print("   rounds (api/raw) before: " + ", ".join(
                f"{r['api_p50'] / r['raw_p50']:.2f}" for r in old) + "; after: " + ", ".join(
                f"{r['api_p50'] / r['raw_p50']:.2f}" for r in new), flush=True)


CHUNK = 2000


def cpu_worker(path: Path, n: int) -> None:
    """The worker of --cpu-before: after "ready", one chunk of CHUNK lookups per line read,
    answered with the process CPU per lookup (µs)."""
    if not path.exists():
        build(path, n)
    rng = random.Random(1)
    probes = [(f"o{rng.randrange(OBJECTS)}", rng.uniform(0, n * 0.01)) for _ in range(CHUNK)]
    goal = "prev(seg(O, L)^Z, T)"
    with slr_sql.open(str(path)) as kb:
        query = kb.query
        for obj, t in probes:   # warm: the plan, the page cache
            query(goal, args={"O": obj, "T": t})
        print("ready", flush=True)
        for _ in sys.stdin:
            c0 = time.process_time()
            for obj, t in probes:
                query(goal, args={"O": obj, "T": t})
            print(f"{(time.process_time() - c0) / CHUNK * 1e6:.3f}", flush=True)


def cpu_paired(args) -> None:
    """This code and the code of ``--cpu-before`` in worker processes, chunks in alternation."""
    def start(code: str, path: Path, n: int) -> subprocess.Popen:
        worker = subprocess.Popen(
            [sys.executable, __file__, "--code", code, "--cpu-worker", str(path), str(n)],
            env=dict(os.environ, PYTHONPATH=code), stdin=subprocess.PIPE,
            stdout=subprocess.PIPE, text=True)
        assert worker.stdin is not None and worker.stdout is not None
        if worker.stdout.readline().strip() != "ready":
            raise SystemExit(f"the worker of {code} did not start")
        return worker

    def chunk(worker: subprocess.Popen) -> float:
        assert worker.stdin is not None and worker.stdout is not None
        worker.stdin.write("go\n")
        worker.stdin.flush()
        return float(worker.stdout.readline())

    this = str(Path(__file__).resolve().parent.parent)
    print(f"{'events':>10} | {'before CPU/lookup':>24} | {'after CPU/lookup':>24} | "
          f"after/before per pair")
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.sizes:
            old = start(args.cpu_before, Path(tmp) / f"q{n}-before.db", n)
            new = start(this, Path(tmp) / f"q{n}.db", n)
            before, after = [], []
            for i in range(args.rounds):
                if i % 2:
                    after.append(chunk(new))
                    before.append(chunk(old))
                else:
                    before.append(chunk(old))
                    after.append(chunk(new))
            for worker in (old, new):
                assert worker.stdin is not None
                worker.stdin.close()
                worker.wait()
            ratios = sorted(a / b for a, b in zip(after, before))
            q = len(ratios) // 4
            print(f"{n:>10} | min {min(before):5.1f} median {statistics.median(before):5.1f} µs | "
                  f"min {min(after):5.1f} median {statistics.median(after):5.1f} µs | "
                  f"median {statistics.median(ratios):.3f} "
                  f"(quartiles {ratios[q]:.3f}-{ratios[-1 - q]:.3f})", flush=True)


def main() -> None:
    if "--cpu-worker" in sys.argv:   # a worker process of --cpu-before
        i = sys.argv.index("--cpu-worker")
        cpu_worker(Path(sys.argv[i + 1]), int(sys.argv[i + 2]))
        return
    if "--measure" in sys.argv:   # the child process of --before
        i = sys.argv.index("--measure")
        path, n, reps = Path(sys.argv[i + 1]), int(sys.argv[i + 2]), int(sys.argv[i + 3])
        if not path.exists():
            build(path, n)
        print(json.dumps(measure(path, n, reps)))
        return
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", type=int, nargs="*", default=[10_000, 100_000, 1_000_000])
    ap.add_argument("--before", help="a checkout of earlier code to compare with, same run")
    ap.add_argument("--cpu-before", help="a checkout of earlier code: process CPU per lookup, "
                                         "paired chunks in alternation")
    ap.add_argument("--rounds", type=int, default=3,
                    help="--before: alternations per size; --cpu-before: pairs of chunks")
    ap.add_argument("--reps", type=int, default=3000, help="lookups per measurement")
    ap.add_argument("--code", help="(internal) the checkout to import slr_sql from")
    args = ap.parse_args()
    if args.cpu_before:
        cpu_paired(args)
        return
    if args.before:
        compare(args)
        return
    print(f"{'events':>10} {'api p50 µs':>11} {'api p99 µs':>11} {'raw p50 µs':>11} {'api/raw':>8}")
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.sizes:
            path = Path(tmp) / f"q{n}.db"
            build(path, n)
            r = measure(path, n, args.reps)
            results.append(r)
            print(f"{n:>10} {r['api_p50']:>11.1f} {r['api_p99']:>11.1f} {r['raw_p50']:>11.1f} "
                  f"{r['api_p50'] / r['raw_p50']:>8.2f}")
    if len(results) > 1:
        print(f"growth p50 {results[-1]['n']} vs {results[0]['n']}: "
              f"{results[-1]['api_p50'] / results[0]['api_p50']:.2f}x")


if __name__ == "__main__":
    main()
