"""CPU of a fresh store's first ``add_many`` that brings N new event types, with a program
whose views read them (each new type is one the views wait for).

    PYTHONPATH=. python benchmarks/bench_views_batch.py --types 1 5 20 --repeat 20

Prints one line per (types, store): the median process CPU of the add_many, in ms.
Run it alternately against two checkouts (A/B) for a comparison.
"""
from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time

import slr_sql


def program(n: int) -> str:
    rules = [f"r{i}(X) :- e{i}(X)^_." for i in range(n)]
    rules.append("both(X) :- " + ", ".join(f"e{i}(X)^_" for i in range(min(n, 3))) + ".")
    rules.append("f(a). f(b).")
    return "\n".join(rules)


def one(n: int, path: str | None) -> float:
    kb = slr_sql.open(path, clock=slr_sql.ManualClock(0.0))
    try:
        kb.load(program(n))
        events = [(f"e{i}", ("a",), 1.0, 1.0) for i in range(n)]
        t0 = time.process_time()
        kb.add_many(events)
        return time.process_time() - t0
    finally:
        kb.close()


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--types", type=int, nargs="+", default=[1, 5, 20])
    parser.add_argument("--repeat", type=int, default=20)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.types:
            for kind in ("memory", "file"):
                times = []
                for r in range(args.repeat):
                    path = None if kind == "memory" else os.path.join(tmp, f"s{n}_{r}.db")
                    times.append(one(n, path))
                print(f"types={n:3d} {kind:6s} add_many CPU median {1000 * statistics.median(times):7.2f} ms "
                      f"(min {1000 * min(times):.2f}, n={args.repeat})")


if __name__ == "__main__":
    main()
