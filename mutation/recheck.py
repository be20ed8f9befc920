"""Re-run the survivors of a session against the tests of this checkout.

For each surviving mutant of the session NAME (run by run.sh), a fresh copy of this
checkout (``$MUTATION_WORKDIR/NAME-recheck-PID``, never the session's own copy, where a run
may be going on, nor another recheck's) gets the mutant applied and runs the test command (the session's, or
``--tests "pytest ..."`` to run only new tests); prints KILLED or SURVIVED per mutant.

Usage: python mutation/recheck.py NAME [--tests COMMAND] [--only FILE:LINE ...]
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

from cosmic_ray.config import load_config
from cosmic_ray.work_db import WorkDB, use_db
from cosmic_ray.work_item import TestOutcome, WorkerOutcome

ROOT = Path(__file__).resolve().parent.parent


def fresh_copy(work: Path) -> None:
    shutil.rmtree(work, ignore_errors=True)
    shutil.copytree(ROOT, work, ignore=shutil.ignore_patterns(
        ".git", "__pycache__", ".hypothesis"))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("name")
    parser.add_argument("--tests", default=None)
    parser.add_argument("--only", nargs="*", default=None)
    args = parser.parse_args(argv)
    base = Path(os.environ.get("MUTATION_WORKDIR", "/tmp/slr-mutation"))
    work = base / f"{args.name}-recheck-{os.getpid()}"
    fresh_copy(work)
    command = args.tests or load_config(str(ROOT / "mutation" / f"{args.name}.toml")).test_command
    with use_db(str(base / args.name / f"{args.name}.sqlite"), WorkDB.Mode.open) as db:
        items = {i.job_id: i for i in db.work_items}
        survivors = [items[j] for j, r in db.results
                     if r.worker_outcome != WorkerOutcome.SKIPPED
                     and r.test_outcome == TestOutcome.SURVIVED]
    for item in survivors:
        m = item.mutations[0]
        where = f"{m.module_path}:{m.start_pos[0]}"
        if args.only is not None and where not in args.only:
            continue
        out = subprocess.run(["cosmic-ray", "mutate-and-test", str(m.module_path),
                              m.operator_name, str(m.occurrence), command],
                             cwd=work, capture_output=True, text=True)
        try:
            outcome = json.loads(out.stdout.strip().splitlines()[-1]).get("test_outcome")
        except (ValueError, IndexError):
            outcome = f"? {out.stdout[-300:]} {out.stderr[-300:]}"
        print(f"{'KILLED' if outcome == 'killed' else outcome.upper()} {where} "
              f"{m.operator_name} #{m.occurrence}", flush=True)
    shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
