"""What reading a store's text costs against raw sqlite3: ``kb.sql`` and ``kb.query`` over
every row of an event type with three short text arguments, beside a raw ``fetchall`` of the
same statement on the same file (no ``text_factory``: sqlite3 decodes in C) and the same
fetch with a ``text_factory`` (what every store connection had before its reads went through
``store/stored_text.py``'s ``fetch_rows``: a bytes object and a call per text cell).

Run from the repository root::

    python benchmarks/bench_text_read.py --rows 100000
    python benchmarks/bench_text_read.py --rows 100000 --before /tmp/old --rounds 5

``--before DIR``: a checkout of earlier code (``git archive COMMIT | tar -x -C DIR``); each
round runs that code and this code in child processes of their own, one after the other,
each on its own file of the same events, and each measures its own raw sqlite3 baseline.
Every figure is the reading thread's CPU time, the best of ``--reps`` runs in its process;
the table gives the best round.
"""
from __future__ import annotations

import argparse
import functools
import json
import os
import sqlite3
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent
STATEMENT = "SELECT arg1, arg2, arg3 FROM obj"


def _slr_sql():
    import slr_sql
    return slr_sql


def build(path: Path, rows: int) -> None:
    """``rows`` obj(cupN, cup, red) events (three short texts each)."""
    slr_sql = _slr_sql()
    with slr_sql.open(str(path), clock=slr_sql.ManualClock(float(rows))) as kb:
        for start in range(0, rows, 50_000):
            kb.add_many([("obj", (f"cup{i}", "cup", "red"), float(i), float(i))
                         for i in range(start, min(rows, start + 50_000))])


def timed(fn) -> float:
    """CPU seconds of this thread (the one sqlite3 reads on) that ``fn()`` took: the
    machine is shared, and the wall clock swings with its load."""
    start = time.thread_time()
    fn()
    return time.thread_time() - start


def measure(path: Path, rows: int, reps: int) -> dict:
    """The best time of each read, in this process, in alternation."""
    slr_sql = _slr_sql()
    if not path.exists():
        build(path, rows)
    raw = sqlite3.connect(str(path))
    with_factory = sqlite3.connect(str(path))
    with_factory.text_factory = functools.partial(str, encoding="utf-8", errors="replace")
    out: dict[str, list[float]] = {"raw": [], "raw_factory": [], "sql": [], "query": []}
    with slr_sql.open(str(path), clock=slr_sql.ManualClock(float(rows))) as kb:
        assert len(kb.sql(STATEMENT)[1]) == rows == len(raw.execute(STATEMENT).fetchall())
        for _ in range(reps):
            out["raw"].append(timed(lambda: raw.execute(STATEMENT).fetchall()))
            out["raw_factory"].append(timed(lambda: with_factory.execute(STATEMENT).fetchall()))
            out["sql"].append(timed(lambda: kb.sql(STATEMENT)))
            out["query"].append(timed(lambda: kb.query("obj(O, K, C)^_")))
        factory = kb.store._db.conn.text_factory   # (the code measured: str since fetch_rows)
    raw.close()
    with_factory.close()
    return {**{name: min(times) for name, times in out.items()},
            "code": slr_sql.__file__, "factory": getattr(factory, "__name__", repr(factory))}


def run_child(code: Path, path: Path, rows: int, reps: int) -> dict:
    env = dict(os.environ, PYTHONPATH=str(code))
    out = subprocess.run([sys.executable, __file__, "--measure", str(path), str(rows), str(reps)],
                         env=env, capture_output=True, text=True, check=True, cwd=str(code)).stdout
    return json.loads(out.strip().splitlines()[-1])


def show(label: str, r: dict, cells: int) -> None:
    ms = {k: v * 1e3 for k, v in r.items()}
    print(f"{label:>7} | raw {ms['raw']:7.1f} ms | raw with a text_factory {ms['raw_factory']:7.1f}"
          f" ms ({r['raw_factory'] / r['raw']:.2f}x) | kb.sql {ms['sql']:7.1f} ms "
          f"({r['sql'] / r['raw']:.2f}x raw) | kb.query {ms['query']:7.1f} ms "
          f"({r['query'] / r['raw']:.2f}x raw) | {cells:,} text cells", flush=True)


def main() -> None:
    if "--measure" in sys.argv:   # a child process: the code on its PYTHONPATH
        i = sys.argv.index("--measure")
        path, rows, reps = Path(sys.argv[i + 1]), int(sys.argv[i + 2]), int(sys.argv[i + 3])
        print(json.dumps(measure(path, rows, reps)))
        return
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=100_000)
    ap.add_argument("--reps", type=int, default=3, help="runs of each read per process")
    ap.add_argument("--rounds", type=int, default=3, help="--before: alternations")
    ap.add_argument("--before", help="a checkout of earlier code to compare with, same run")
    args = ap.parse_args()
    cells = 3 * args.rows
    print(f"load average {os.getloadavg()[0]:.1f}; {args.rows:,} rows of 3 short texts")
    with tempfile.TemporaryDirectory() as tmp:
        after_path = Path(tmp) / "after.db"
        if not args.before:
            show("this", run_child(HERE, after_path, args.rows, args.reps), cells)
            return
        before_path = Path(tmp) / "before.db"
        before, after = [], []
        for _ in range(args.rounds):
            before.append(run_child(Path(args.before), before_path, args.rows, args.reps))
            after.append(run_child(HERE, after_path, args.rows, args.reps))
        for label, rounds in (("before", before), ("after", after)):
            print(f"{label}: {rounds[0]['code']}, the store connection's text_factory "
                  f"{rounds[0]['factory']}")
        for label, rounds in (("before", before), ("after", after)):
            show(label, {k: min(r[k] for r in rounds) for k in ("raw", "raw_factory", "sql",
                                                               "query")}, cells)
        print("rounds, kb.sql / raw: before " + ", ".join(
            f"{r['sql'] / r['raw']:.2f}" for r in before) + "; after " + ", ".join(
            f"{r['sql'] / r['raw']:.2f}" for r in after))
        print("rounds, kb.query / raw: before " + ", ".join(
            f"{r['query'] / r['raw']:.2f}" for r in before) + "; after " + ", ".join(
            f"{r['query'] / r['raw']:.2f}" for r in after))
        print(f"load average {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
