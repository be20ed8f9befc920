"""tf_lookup over a 10-frame chain against the SLR paper's hand-written two-edge rule.

    python benchmarks/bench_tf.py                    # 1,000 observations per edge
    python benchmarks/bench_tf.py --per-edge 10000 --reps 2000

The store holds a chain f0 -> f1 -> ... -> f9 (9 edges, every third stored child->parent so
that the lookup inverts it), each edge observed at 10 Hz, plus the two edges the paper's rule
reads (cam -> base, base -> world, as many observations). Both are asked through the public
API (``kb.query`` with the time bound), at the same random times:

* the baseline, the paper's rule (interpolation of each edge with prev/next, then
  ``pos_multiply``), written for exactly two edges:
  ``position(T, P) :- itf(base, cam, A)^T, itf(world, base, B)^T, pos_multiply([..., A, B], P)``;
* ``tf_lookup(f0, f9, T, P)``: the frame tree, 9 edges, each interpolated.

The figure is the ratio of the p50 latencies, measured in the same run (target: <= 3).
"""
from __future__ import annotations

import argparse
import random
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import slr_sql  # noqa: E402
from slr_sql import Struct  # noqa: E402

RULES = """
itf(P, C, TF)^T :- prev(tf(P, C, TF1)^T1, T), next(tf(P, C, TF2)^T2, [T, inf]),
                   interpolate([TF, T], [TF1, T1], [TF2, T2]).
position(T, P) :- itf(base, cam, A)^T, itf(world, base, B)^T,
                  pos_multiply([pose([0,0,0],[0,0,0,1]), A, B], P).
"""


def pose(i: int, k: int) -> Struct:
    a = 0.001 * i + 0.1 * k
    return Struct("pose", ([0.1 * k + 0.001 * i, 0.2, 0.3], [0.0, 0.0, 0.1 * a, 1.0]))


def build(path: Path, per_edge: int) -> None:
    with slr_sql.open(str(path), clock=slr_sql.ManualClock(0.0), synchronous="OFF") as kb:
        kb.load(RULES)
        events = []
        for i in range(per_edge):
            t = i * 0.1
            for k in range(9):
                parent, child = f"f{k}", f"f{k + 1}"
                if k % 3 == 2:
                    parent, child = child, parent
                events.append(("tf", (parent, child, pose(i, k)), t, t))
            events.append(("tf", ("base", "cam", pose(i, 1)), t, t))
            events.append(("tf", ("world", "base", pose(i, 2)), t, t))
            if len(events) > 50_000:
                kb.add_many(events)
                events = []
        kb.add_many(events)


def measure(path: Path, per_edge: int, reps: int) -> dict:
    rng = random.Random(7)
    times = [rng.uniform(0.0, (per_edge - 1) * 0.1) for _ in range(reps)]
    out = {}
    with slr_sql.open(str(path)) as kb:
        goals = {"two-edge rule": "position(T, P)", "tf_lookup 10 frames": "tf_lookup(f0, f9, T, P)"}
        for goal in goals.values():   # warm plans and caches
            assert len(kb.query(goal, args={"T": times[0]})) == 1
        for name, goal in goals.items():
            lat = []
            for t in times:
                t0 = time.perf_counter()
                kb.query(goal, args={"T": t})
                lat.append(time.perf_counter() - t0)
            lat.sort()
            out[name] = (statistics.median(lat), lat[int(0.99 * (len(lat) - 1))])
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--per-edge", type=int, default=1000)
    parser.add_argument("--reps", type=int, default=1000)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "tf.db"
        build(path, args.per_edge)
        result = measure(path, args.per_edge, args.reps)
    for name, (p50, p99) in result.items():
        print(f"{name:22s} p50 {p50 * 1e6:8.1f} us   p99 {p99 * 1e6:8.1f} us")
    ratio = result["tf_lookup 10 frames"][0] / result["two-edge rule"][0]
    print(f"ratio tf_lookup(10 frames) / two-edge rule (p50): {ratio:.2f}  (target <= 3)")


if __name__ == "__main__":
    main()
