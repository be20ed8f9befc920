"""What a process pays before its first answer: opening a store, and one ``slr`` command.

    python benchmarks/bench_startup.py
    python benchmarks/bench_startup.py --opens 200 --spawns 10
    python benchmarks/bench_startup.py --code /tmp/old     # an earlier checkout, same run

Every test that opens a store and every CLI command (the test suite runs ~700) pays these;
all figures are CPU time (user + system), the best of the repeats, against baselines measured
in the same run:

* **open** -- ``slr_sql.open()`` of an in-memory store then ``close()`` (the migrations, the
  program analysis of the library, the parts attached), against raw sqlite3 creating the same
  schema (a new store's tables, indexes and triggers, as one script on a fresh in-memory
  connection);
* **command** -- a whole ``python -m slr_sql query DB "X = 1"`` process on a small file store,
  against ``python -c "import sqlite3; ..."`` running the same kind of read on the same file
  (the interpreter's own start-up is in both).

``--code DIR`` runs the same figures for another checkout (``PYTHONPATH=DIR``) in the same run,
alternated with this one, for a before/after.
"""
from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

OPEN_CHILD = r"""
import sqlite3, sys, time
import slr_sql
n, made = int(sys.argv[1]), sys.argv[2]
slr_sql.open().close()                      # what a process does once (imports, the library)
best_ours = best_raw = float("inf")
with sqlite3.connect(made) as schema:       # the schema a new store has, as one script
    script = ";\n".join(row[0] for row in schema.execute(
        "SELECT sql FROM sqlite_master WHERE sql IS NOT NULL "
        "AND name NOT LIKE 'sqlite_%' ORDER BY rowid"))
for _ in range(5):
    t = time.process_time()
    for _ in range(n):
        slr_sql.open().close()
    best_ours = min(best_ours, (time.process_time() - t) / n)
    t = time.process_time()
    for _ in range(n):
        conn = sqlite3.connect(":memory:")
        conn.executescript(script)
        conn.close()
    best_raw = min(best_raw, (time.process_time() - t) / n)
print(best_ours, best_raw)
"""

RAW_COMMAND = ("import sqlite3, sys; conn = sqlite3.connect(sys.argv[1]); "
               "print(conn.execute('SELECT count(*) FROM sqlite_master').fetchone()[0])")


def child_cpu(args: list[str], env: dict) -> float:
    """CPU seconds (user + system) of one child process running ``args``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    done = subprocess.run(args, env=env, capture_output=True, text=True, timeout=120)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise SystemExit(f"{args} failed: {done.stderr[-2000:]}")
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def figures(code: Path, db: str, opens: int, spawns: int) -> dict[str, float]:
    env = dict(os.environ, PYTHONPATH=str(code))
    out = subprocess.run([sys.executable, "-c", OPEN_CHILD, str(opens), db], env=env,
                         capture_output=True, text=True, timeout=600, cwd=code)
    if out.returncode != 0:
        raise SystemExit(out.stderr[-2000:])
    ours_open, raw_open = map(float, out.stdout.split())
    ours_cmd = min(child_cpu([sys.executable, "-m", "slr_sql", "query", db, "X = 1"], env)
                   for _ in range(spawns))
    raw_cmd = min(child_cpu([sys.executable, "-c", RAW_COMMAND, db], env)
                  for _ in range(spawns))
    return {"open_ms": ours_open * 1e3, "open_raw_ms": raw_open * 1e3,
            "command_ms": ours_cmd * 1e3, "command_raw_ms": raw_cmd * 1e3}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--opens", type=int, default=100, help="opens per repeat (5 repeats)")
    ap.add_argument("--spawns", type=int, default=8, help="command processes per figure")
    ap.add_argument("--code", type=Path, help="another checkout, measured in the same run")
    ap.add_argument("--rounds", type=int, default=2, help="alternations with --code")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        db = str(Path(tmp) / "startup.db")
        made = subprocess.run([sys.executable, "-m", "slr_sql", "add", db, "p(1)^1"],
                              env=dict(os.environ, PYTHONPATH=str(ROOT)), capture_output=True,
                              text=True, timeout=120)
        if made.returncode != 0:
            raise SystemExit(made.stderr)
        codes = [ROOT] if args.code is None else [args.code, ROOT]
        for _ in range(1 if args.code is None else args.rounds):
            for code in codes:
                f = figures(code, db, args.opens, args.spawns)
                print(f"{str(code):30s} open {f['open_ms']:6.2f} ms CPU "
                      f"(raw schema {f['open_raw_ms']:5.2f} ms: "
                      f"{f['open_ms'] / f['open_raw_ms']:4.1f}x)   "
                      f"command {f['command_ms']:5.0f} ms CPU "
                      f"(raw {f['command_raw_ms']:4.0f} ms: "
                      f"{f['command_ms'] / f['command_raw_ms']:4.1f}x)", flush=True)


if __name__ == "__main__":
    main()
