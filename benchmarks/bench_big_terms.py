"""Big terms and the cost of stopping: what the tests check for correctness only, here as
ratios to a baseline measured in the same run (benchmarks/README.md, "Big terms").

1. Parsing and printing a list of 1,000,000 integers (``parse_term`` then ``format_term``)
   against ``json.loads`` then ``json.dumps`` of the same text (a C parser: the floor).
2. The interpreter over a list of 1,000,000 elements (numlist, length, last, sum_list,
   msort, nth1, max_list in one query) against the same operations on a Python list.
3. How long ``kb.query("loop", timeout=T)`` takes to give up, as a ratio to ``T`` (1.0 is
   exact; the overshoot is the deadline check's granularity).

Run:  python benchmarks/bench_big_terms.py [--n 1000000] [--repeat 3]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import slr_sql
from slr_sql.parser import parse_term
from slr_sql.terms import format_term


def best(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def parse_and_print(n: int, repeat: int) -> tuple[float, float]:
    text = "[" + ",".join(map(str, range(n))) + "]"

    def ours() -> None:
        term, _ = parse_term(text)
        assert format_term(term) == text

    def baseline() -> None:
        assert json.dumps(json.loads(text), separators=(",", ":")) == text

    return best(ours, repeat), best(baseline, repeat)


def interpreter_lists(n: int, repeat: int) -> tuple[float, float]:
    goal = (f"numlist(1, {n}, _L), length(_L, N), last(_L, X), sum_list(_L, S), "
            f"msort(_L, _M), nth1(1, _M, F), max_list(_L, Max)")
    expected = [{"N": n, "X": n, "S": n * (n + 1) // 2, "F": 1, "Max": n}]
    kb = slr_sql.open()

    def ours() -> None:
        assert kb.query(goal) == expected

    def baseline() -> None:
        items = list(range(1, n + 1))
        assert [{"N": len(items), "X": items[-1], "S": sum(items), "F": min(items),
                 "Max": max(items)}] == expected

    try:
        return best(ours, repeat), best(baseline, repeat)
    finally:
        kb.close()


def timeout_overshoot(timeout: float, repeat: int) -> float:
    kb = slr_sql.open()
    kb.load("loop :- loop.")
    worst = 0.0
    try:
        for _ in range(repeat):
            t0 = time.perf_counter()
            try:
                kb.query("loop", timeout=timeout)
            except slr_sql.SLRTimeout:
                pass
            else:
                raise AssertionError("an endless loop answered")
            worst = max(worst, (time.perf_counter() - t0) / timeout)
    finally:
        kb.close()
    return worst


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    ours, base = parse_and_print(args.n, args.repeat)
    print(f"parse+print {args.n:,} integers: {ours:.2f} s vs json {base:.3f} s: "
          f"{ours / base:.0f}x")
    ours, base = interpreter_lists(args.n, args.repeat)
    print(f"interpreter over a {args.n:,}-element list: {ours:.2f} s vs Python {base:.3f} s: "
          f"{ours / base:.0f}x")
    for timeout in (0.1, 0.5):
        print(f"timeout={timeout}: gives up after {timeout_overshoot(timeout, args.repeat):.2f}x "
              f"the timeout (worst of {args.repeat})")


if __name__ == "__main__":
    main()
