"""An event rule of many parts on SQLite in memory: the seconds to load it, add its events one
by one (each add detects) and decide what waits for the clock (docs/events.md, "Limits").

The rule is ``c(X) <- a0(X) OP a1(X) OP ... OP a<P-1>(X).`` under a consumption policy; the
events are ``E`` rounds of one event per part, round k with X = k at times after the round
before, so every round completes one match. Run the code of another checkout (the earlier
code, in alternation with this one) with ``--tree``; the figures are absolute, they move
with the machine's load (printed with them).

``--rows`` runs the table of benchmarks/README.md instead, each row in a process of its
own (a new connection: a statement's first plan is in its figure): per number of parts, the
``and`` under ``unrestricted`` (the baseline, measured in the same run), then the ``and``
and the ``seq`` under ``recent``, each as seconds and as a ratio to the baseline's total.

    python benchmarks/bench_long_patterns.py --parts 30 --events 1
    python benchmarks/bench_long_patterns.py --parts 20 --events 20
    python benchmarks/bench_long_patterns.py --parts 30 --op seq --policy recent
    python benchmarks/bench_long_patterns.py --tree /tmp/before --parts 30 --events 1
    python benchmarks/bench_long_patterns.py --rows --row-parts 10 20 30 --events 2
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

# (op, policy) of the table's rows: the first is the baseline
ROWS = [("and", "unrestricted"), ("and", "recent"), ("seq", "recent")]


def measure(args: argparse.Namespace) -> dict:
    """One rule's run: seconds to load, add and decide, complex events found."""
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
    return {"file": slr_sql.__file__, "load": loaded - started, "adds": added - loaded,
            "clock": decided - added, "total": decided - started, "found": found,
            "outcome": outcome, "cpu": time.process_time()}


def rows(args: argparse.Namespace) -> None:
    """The table: each row a process of its own, the baseline first for each size."""
    print(f"tree {os.path.abspath(args.tree)}, {args.events} event(s) per part; "
          f"load average {os.getloadavg()[0]:.1f}")
    print("| parts | rule | load s | adds s | clock s | total s | / baseline | complex events |")
    print("|---|---|---|---|---|---|---|---|")
    for parts in args.row_parts:
        baseline = None
        for op, policy in ROWS:
            done = subprocess.run(
                [sys.executable, os.path.abspath(__file__), "--json", "--tree", args.tree,
                 "--parts", str(parts), "--events", str(args.events), "--op", op,
                 "--policy", policy], capture_output=True, text=True, check=True)
            r = json.loads(done.stdout.strip().splitlines()[-1])
            if baseline is None:
                baseline = r["total"]
            print(f"| {parts} | {op} {policy} | {r['load']:.2f} | {r['adds']:.2f} | "
                  f"{r['clock']:.2f} | {r['total']:.2f} | {r['total'] / baseline:.2f}x | "
                  f"{r['found']}{'' if r['outcome'] == 'ok' else ' ' + r['outcome']} |",
                  flush=True)
    print(f"load average {os.getloadavg()[0]:.1f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--parts", type=int, default=30)
    parser.add_argument("--events", type=int, default=1, help="events per part")
    parser.add_argument("--op", default="and")
    parser.add_argument("--policy", default="unrestricted")
    parser.add_argument("--tree", default=os.path.join(os.path.dirname(
        os.path.abspath(__file__)), ".."), help="the checkout whose slr_sql runs")
    parser.add_argument("--rows", action="store_true", help="the README's table")
    parser.add_argument("--row-parts", type=int, nargs="+", default=[10, 20, 30])
    parser.add_argument("--json", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.rows:
        rows(args)
        return
    r = measure(args)
    if args.json:
        print(json.dumps(r))
        return
    print(f"{r['file']}: {args.parts} parts ({args.op}, {args.policy}), "
          f"{args.events} event(s) each: load {r['load']:.2f} s, adds {r['adds']:.2f} s, "
          f"clock {r['clock']:.2f} s, total {r['total']:.2f} s; {r['found']} complex events; "
          f"{r['outcome']}; load average {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
