"""The cost of noticing a store file deleted or replaced while open (``Database.check_identity``,
run before every commit): per add, the same single-event adds with the check and with it
replaced by a no-op, in alternating rounds of one run; for ``synchronous=OFF`` (the cheapest
commit, where the check weighs most) and ``FULL`` (the default). Also the check itself against
one ``os.stat`` of the same file (it makes two).

Run from the repository root::

    python benchmarks/bench_store_checks.py            # 6 rounds of 1,500 adds per setting
    python benchmarks/bench_store_checks.py --adds 300 --rounds 4
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import slr_sql  # noqa: E402
from slr_sql.store.connection import Database  # noqa: E402


def per_call(fn, n: int) -> float:
    start = time.perf_counter()
    for _ in range(n):
        fn()
    return (time.perf_counter() - start) / n * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--adds", type=int, default=1500)
    parser.add_argument("--rounds", type=int, default=6)
    options = parser.parse_args()
    real = Database.check_identity
    for synchronous in ("OFF", "FULL"):
        folder = tempfile.mkdtemp()
        path = os.path.join(folder, "robot.db")
        kb = slr_sql.open(path, synchronous=synchronous, clock=slr_sql.ManualClock(0.0))
        kb.add("p(0)^0")
        counter = iter(range(10 ** 9))
        add = lambda: kb.add_event("p", [next(counter)], 1.0)  # noqa: E731
        checked, unchecked = [], []
        try:
            for _ in range(options.rounds):
                Database.check_identity = real
                checked.append(per_call(add, options.adds))
                Database.check_identity = lambda self: None
                unchecked.append(per_call(add, options.adds))
        finally:
            Database.check_identity = real
        a, b = statistics.median(checked), statistics.median(unchecked)
        print(f"synchronous={synchronous}: {a:.1f} us per add with the check, {b:.1f} us "
              f"without: ratio {a / b:.3f}")
        db = kb.store._db
        check = per_call(db.check_identity, 20000)
        one_stat = per_call(lambda: os.stat(path), 20000)
        print(f"  check_identity {check:.2f} us = {check / one_stat:.2f} x one os.stat "
              f"({one_stat:.2f} us) = {check / b:.4f} of an add")
        kb.close()


if __name__ == "__main__":
    main()
