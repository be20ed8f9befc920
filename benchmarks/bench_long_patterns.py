"""An event rule of many parts on SQLite in memory: the seconds to load it, add its events one
by one (each add detects) and decide what waits for the clock (docs/events.md, "Limits").

The rule is ``c(X) <- a0(X) OP a1(X) OP ... OP a<P-1>(X).`` under a consumption policy; the
events are ``E`` rounds of one event per part, round k with X = k at times after the round
before, so every round completes one match. Run the code of another checkout (the earlier
code, in alternation with this one) with ``--tree``; the figures are absolute, they move
with the machine's load (printed with them).

    python benchmarks/bench_long_patterns.py --parts 30 --events 1
    python benchmarks/bench_long_patterns.py --parts 20 --events 20
    python benchmarks/bench_long_patterns.py --parts 30 --op seq --policy recent
    python benchmarks/bench_long_patterns.py --tree /tmp/before --parts 30 --events 1
"""
from __future__ import annotations

import argparse
import os
import sys
import time


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--parts", type=int, default=30)
    parser.add_argument("--events", type=int, default=1, help="events per part")
    parser.add_argument("--op", default="and")
    parser.add_argument("--policy", default="unrestricted")
    parser.add_argument("--tree", default=os.path.join(os.path.dirname(
        os.path.abspath(__file__)), ".."), help="the checkout whose slr_sql runs")
    args = parser.parse_args()
    sys.path.insert(0, os.path.abspath(args.tree))
    import slr_sql

    kb = slr_sql.open(None, clock=slr_sql.ManualClock(0))
    rule = (f":- consumption({args.policy}).\nc(X) <- "
            + f" {args.op} ".join(f"a{i}(X)" for i in range(args.parts)) + ".")
    started = time.perf_counter()
    outcome = "ok"
    try:
        kb.load(rule)
        loaded = time.perf_counter()
        for k in range(args.events):
            for i in range(args.parts):
                kb.add(f"a{i}({k})^{k * (args.parts + 1) + i + 1}")
        added = time.perf_counter()
        kb.clock.set(float(args.events * (args.parts + 1) + 1))
        decided = time.perf_counter()
        found = kb.query("findall(X, c(X)^[_, _], L), length(L, N)")[0]["N"]
    except slr_sql.SLRError as exc:
        loaded = added = decided = time.perf_counter()
        found, outcome = 0, str(exc).splitlines()[0][-120:]
    print(f"{slr_sql.__file__}: {args.parts} parts ({args.op}, {args.policy}), "
          f"{args.events} event(s) each: load {loaded - started:.2f} s, adds "
          f"{added - loaded:.2f} s, clock {decided - added:.2f} s, total "
          f"{decided - started:.2f} s; {found} complex events; {outcome}; load average "
          f"{os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
