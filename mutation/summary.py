"""Summarize cosmic-ray sessions: per session the mutants, those skipped (annotation-only,
not sampled), run, killed, survived, and the diff of every survivor.

Usage: python mutation/summary.py SESSION.sqlite [...] [--diffs]
"""
from __future__ import annotations

import argparse
import sys
from collections import Counter

from cosmic_ray.work_db import WorkDB, use_db
from cosmic_ray.work_item import TestOutcome, WorkerOutcome


def summarize(path: str, diffs: bool) -> None:
    with use_db(path, WorkDB.Mode.open) as db:
        items = {i.job_id: i for i in db.work_items}
        counts: Counter = Counter()
        survivors = []
        for job_id, result in db.results:
            if result.worker_outcome == WorkerOutcome.SKIPPED:
                counts["skipped: " + (result.output or "filter")] += 1
                continue
            counts["run"] += 1
            if result.test_outcome == TestOutcome.SURVIVED:
                counts["survived"] += 1
                survivors.append((items[job_id], result))
            else:
                counts["killed"] += 1
                if result.worker_outcome == WorkerOutcome.ABNORMAL:
                    counts["killed by the timeout"] += 1
        counts["pending"] = len(items) - sum(1 for _ in db.results)
        print(f"{path}: {len(items)} mutants; " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))
        for item, result in survivors:
            m = item.mutations[0]
            print(f"  SURVIVED {m.module_path}:{m.start_pos[0]} {m.operator_name} #{m.occurrence}")
            if diffs and result.diff:
                print("    " + "\n    ".join(result.diff.splitlines()[2:]))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sessions", nargs="+")
    parser.add_argument("--diffs", action="store_true")
    args = parser.parse_args(argv)
    for s in args.sessions:
        summarize(s, args.diffs)
    return 0


if __name__ == "__main__":
    sys.exit(main())
