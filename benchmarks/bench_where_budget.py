"""What a where goal's budgets are worth in time on this machine (slr_sql/cep/where.py).

A where goal is limited by work, not time: ``WHERE_MAX_STEPS`` inference steps in the
interpreter, ``WHERE_SQL_INSTRUCTIONS`` SQLite instructions per compiled statement, and a
``WHERE_BACKSTOP`` of wall clock only against work the budgets do not count. The budgets were
chosen as about what 5 s bought; this measures, per kind of work, how many steps (through
``kb.query(timeout=)``, whose SLRTimeout says how many steps ran) and how many SQLite
instructions (counted by a progress handler on a plain ``sqlite3`` connection) ``--seconds``
buy, and how long each budget then takes at that rate: the backstop must stay far beyond the
slowest. Absolute figures: they move with the machine's load (printed with them).

    python benchmarks/bench_where_budget.py              # 5 s per kind of work
    python benchmarks/bench_where_budget.py --seconds 1  # a quick look
"""
from __future__ import annotations

import argparse
import os
import re
import sqlite3
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import slr_sql  # noqa: E402
from slr_sql import ManualClock  # noqa: E402
from slr_sql.cep.where import (WHERE_BACKSTOP, WHERE_MAX_STEPS,  # noqa: E402
                               WHERE_SQL_INSTRUCTIONS)
from slr_sql.errors import SLRTimeout  # noqa: E402

PROGRAM = """
loop(N) :- N1 is N + 1, loop(N1).
lists(N) :- findall(X, between(1, 1000, X), L), length(L, _), N1 is N + 1, lists(N1).
scan :- between(1, inf, _), a(X)^_, X < 0.
"""
GOALS = {
    "recursion with arithmetic": "loop(0)",
    "event goals": "scan",
    "findall/length": "lists(0)",
    "between/3": "between(1, inf, X), X < 0",
}
STATEMENTS = {
    "recursive CTE": "WITH RECURSIVE r(n) AS (SELECT 1 UNION ALL SELECT n + 1 FROM r) "
                     "SELECT count(*) FROM r WHERE n < 0",
    "plain join": "SELECT count(*) FROM t a, t b WHERE a.x + b.x = -1",
    "JSON functions per row": "SELECT count(*) FROM t a, t b "
                              "WHERE json_extract(json_array(a.x, b.y), '$[0]') < 0",
}


def steps_bought(seconds: float) -> list[tuple[str, int, float]]:
    with slr_sql.open(None, clock=ManualClock(0.0)) as kb:
        kb.load(PROGRAM)
        kb.add_many([f"a({i})^{i}" for i in range(1, 20001)])
        out = []
        for name, goal in GOALS.items():
            start = time.monotonic()
            try:
                kb.query(goal, timeout=seconds)
            except SLRTimeout as exc:
                found = re.search(r"\((\d+) inference steps\)", str(exc))
                if found is None:
                    raise
                out.append((name, int(found.group(1)), time.monotonic() - start))
        return out


def instructions_bought(seconds: float) -> list[tuple[str, int, float]]:
    conn = sqlite3.connect(":memory:")
    conn.execute("CREATE TABLE t (x, y)")
    conn.executemany("INSERT INTO t VALUES (?, ?)", [(i, str(i)) for i in range(100_000)])
    out = []
    every = 1000
    for name, sql in STATEMENTS.items():
        calls = [0]
        start = time.monotonic()

        def progress() -> int:
            calls[0] += 1
            return 1 if time.monotonic() - start > seconds else 0

        conn.set_progress_handler(progress, every)
        try:
            conn.execute(sql).fetchall()
        except sqlite3.OperationalError:
            pass   # interrupted: the time is up
        out.append((name, calls[0] * every, time.monotonic() - start))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=5.0, help="per kind of work (5)")
    args = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.1f}, {os.cpu_count()} cores; "
          f"{args.seconds:g} s per kind of work")
    print(f"\ninterpreter: WHERE_MAX_STEPS = {WHERE_MAX_STEPS:,}")
    print("| work | steps per s | budget takes |")
    print("|---|---:|---:|")
    slowest = 0.0
    for name, steps, took in steps_bought(args.seconds):
        rate = steps / took
        slowest = max(slowest, WHERE_MAX_STEPS / rate)
        print(f"| {name} | {rate:,.0f} | {WHERE_MAX_STEPS / rate:.1f} s |")
    print(f"\nSQLite: WHERE_SQL_INSTRUCTIONS = {WHERE_SQL_INSTRUCTIONS:,}")
    print("| work | instructions per s | budget takes |")
    print("|---|---:|---:|")
    for name, count, took in instructions_bought(args.seconds):
        rate = count / took
        slowest = max(slowest, WHERE_SQL_INSTRUCTIONS / rate)
        print(f"| {name} | {rate:,.0f} | {WHERE_SQL_INSTRUCTIONS / rate:.1f} s |")
    print(f"\nslowest budget: {slowest:.1f} s; WHERE_BACKSTOP = {WHERE_BACKSTOP:g} s "
          f"({WHERE_BACKSTOP / slowest:.1f}x beyond)")


if __name__ == "__main__":
    main()
