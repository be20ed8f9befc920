"""Ingest benchmark: kb.add_many (or EventStore.add_events) vs raw sqlite3.executemany, same
schema and pragmas.

Events are ``seg(oN, [x, y, z])^t`` (an atom and a list of three random floats), given as
``(name, args, start, end)`` tuples. The raw baseline inserts rows that were encoded *before*
the clock starts, into a table with the same columns, indexes and pragmas (WAL,
synchronous=FULL, the store's cache_size), in one transaction; a stricter reference inserts
them with multi-row VALUES of 512 rows (reported beside it). The table is made by the
store itself, so it has the ``robot`` column (schema 6) too; neither side names it in its
INSERT (the benchmark's store has no robot name: the column's NULL). The knowledge base
does the same work plus validation and encoding of every event, completeness marks and its add
listeners. Building the Python terms is not timed for either. Target: kb / raw >= 0.80.

Run by hand::

    python benchmarks/bench_ingest.py                       # 1,000,000 events through kb.add_many
    python benchmarks/bench_ingest.py --n 10000 100000 --repeat 5
    python benchmarks/bench_ingest.py --api store --n 100000
    SLR_SQL_NO_SPEEDUPS=1 python benchmarks/bench_ingest.py ...   # without the C loops
"""
from __future__ import annotations

import argparse
import gc
import random
import sqlite3
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import slr_sql  # noqa: E402
from slr_sql import encoding  # noqa: E402
from slr_sql.encoding import encode  # noqa: E402
from slr_sql.store import CACHE_SIZE_KIB, EventStore  # noqa: E402
from slr_sql.terms import Atom, make_list  # noqa: E402


class FixedClock:
    def now(self) -> float:
        return 1000.0


def make_events(n: int, objects: int = 1000, decimals: int | None = None,
                vectors: str = "prolog") -> list[tuple]:
    """``seg(oK, [x,y,z])^t`` events; positions are random floats (17 significant digits,
    the slowest to write as text), or rounded to ``decimals`` places (a sensor's resolution),
    as Prolog lists (``make_list``: what parsed text gives) or Python lists (what decoded
    ROS messages and most robot code give)."""
    rng = random.Random(7)
    names = [Atom(f"o{i}") for i in range(objects)]
    coordinate = rng.random if decimals is None else (lambda: round(rng.random(), decimals))
    events = []
    for i in range(n):
        t = i * 0.01
        position = [coordinate(), coordinate(), coordinate()]
        if vectors == "prolog":
            position = make_list(position)
        events.append(("seg", (names[i % objects], position), t, t))
    return events


def run_store(path: Path, events: list[tuple], synchronous: str) -> tuple[float, float]:
    store = EventStore(path, FixedClock(), synchronous=synchronous)
    store.declare_type("seg", 2)
    began, began_cpu = time.perf_counter(), time.process_time()
    errors = store.add_events(events)
    elapsed = time.perf_counter() - began, time.process_time() - began_cpu
    assert not errors, errors[:3]
    assert store.count("seg", 2) == len(events)
    store.close()
    return elapsed


def run_kb(path: Path, events: list[tuple], synchronous: str) -> tuple[float, float]:
    kb = slr_sql.open(path, clock=slr_sql.ManualClock(1000.0), synchronous=synchronous)
    kb.load(":- event seg/2.")
    began, began_cpu = time.perf_counter(), time.process_time()
    errors = kb.add_many(events)
    elapsed = time.perf_counter() - began, time.process_time() - began_cpu
    assert not errors, errors[:3]
    assert kb.store.count("seg", 2) == len(events)
    kb.close()
    return elapsed


def run_raw(path: Path, events: list[tuple], synchronous: str,
            form: str = "executemany") -> tuple[float, float]:
    # The same schema as the store creates (made by the store itself, robot column included),
    # then plain sqlite3; robot is left to its NULL, as an unnamed store leaves it. ``form``
    # "values": multi-row INSERTs of 512 rows (and one of the rest), the stricter reference
    # (one statement per row spends a third of an insert binding and stepping statements).
    store = EventStore(path, FixedClock(), synchronous=synchronous)
    table = store.declare_type("seg", 2)
    store.close()
    rows = [(encode(args[0]), encode(args[1]), start, end, 1000.0)
            for _name, args, start, end in events]
    conn = sqlite3.connect(path, isolation_level=None)
    conn.execute("PRAGMA journal_mode=WAL")
    conn.execute(f"PRAGMA synchronous={synchronous}")
    conn.execute("PRAGMA foreign_keys=ON")
    conn.execute(f"PRAGMA cache_size=-{CACHE_SIZE_KIB}")
    began, began_cpu = time.perf_counter(), time.process_time()
    conn.execute("BEGIN IMMEDIATE")
    head = f'INSERT INTO "{table}" (arg1, arg2, t_start, t_end, arrival) VALUES '
    if form == "executemany":
        conn.executemany(head + "(?, ?, ?, ?, ?)", rows)
    else:
        for i in range(0, len(rows), 512):
            part = rows[i:i + 512]
            conn.execute(head + ",".join(["(?, ?, ?, ?, ?)"] * len(part)),
                         [v for row in part for v in row])
    conn.execute("COMMIT")
    elapsed = time.perf_counter() - began, time.process_time() - began_cpu
    assert conn.execute(f'SELECT count(*) FROM "{table}"').fetchone()[0] == len(events)
    conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    conn.close()
    return elapsed


def measure(n: int, repeat: int, synchronous: str, api: str,
            decimals: int | None = None, vectors: str = "prolog") -> tuple[float, float]:
    """Print the runs and the best of each for ``n`` events; returns (wall, cpu) ratios."""
    events = make_events(n, decimals=decimals, vectors=vectors)
    run_api = run_kb if api == "kb" else run_store
    label = "kb.add_many" if api == "kb" else "EventStore.add_events"
    raw_runs, api_runs, values_runs = [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        for attempt in range(repeat):
            raw_path = Path(tmp) / f"raw{attempt}.db"
            api_path = Path(tmp) / f"api{attempt}.db"
            values_path = Path(tmp) / f"values{attempt}.db"
            gc.collect()
            # alternate which goes first: the second run shares the disk with the first
            # one's writeback, and the machine's load drifts
            if attempt % 2 == 0:
                raw = run_raw(raw_path, events, synchronous)
                api_run = run_api(api_path, events, synchronous)
            else:
                api_run = run_api(api_path, events, synchronous)
                raw = run_raw(raw_path, events, synchronous)
            values = run_raw(values_path, events, synchronous, form="values")
            print(f"  run {attempt + 1}: wall raw {raw[0]:.3f}s {api} {api_run[0]:.3f}s "
                  f"(ratio {raw[0] / api_run[0]:.2f}); cpu raw {raw[1]:.3f}s {api} "
                  f"{api_run[1]:.3f}s (ratio {raw[1] / api_run[1]:.2f})", flush=True)
            raw_runs.append(raw)
            api_runs.append(api_run)
            values_runs.append(values)
            for used in (raw_path, api_path, values_path):
                used.unlink()
    digits = "random floats" if decimals is None else f"floats rounded to {decimals} decimals"
    loops = "C loops" if encoding._speedups is not None else "Python only"
    print(f"ingest of {n:,} events seg(oN, [x,y,z])^t ({digits}, {vectors} lists), "
          f"synchronous={synchronous}, "
          f"SQLite {sqlite3.sqlite_version}, column encoder: {loops}, best of {repeat}")
    print(f"{'method':<34}{'wall s':>9}{'events/s':>12}{'cpu s':>9}{'events/cpu-s':>14}")
    for name, runs in (("raw sqlite3.executemany (encoded)", raw_runs),
                       ("raw multi-row VALUES (encoded)", values_runs), (label, api_runs)):
        wall = min(r[0] for r in runs)
        cpu = min(r[1] for r in runs)
        print(f"{name:<34}{wall:>9.3f}{n / wall:>12,.0f}{cpu:>9.3f}{n / cpu:>14,.0f}")
    wall_ratio = min(r[0] for r in raw_runs) / min(r[0] for r in api_runs)
    cpu_ratio = min(r[1] for r in raw_runs) / min(r[1] for r in api_runs)
    print(f"ratio {api}/raw: wall {wall_ratio:.2f}, cpu {cpu_ratio:.2f} (target >= 0.80)")
    # each run's ratio compares two runs made one right after the other, under the same
    # load: their median moves less than the ratio of two bests taken minutes apart
    paired = sorted(raw[1] / mine[1] for raw, mine in zip(raw_runs, api_runs))
    print(f"ratio {api}/raw, cpu, median of the runs' own ratios: "
          f"{statistics.median(paired):.2f} ({paired[0]:.2f}–{paired[-1]:.2f}, {len(paired)} runs)")
    print(f"ratio {api}/raw multi-row VALUES: wall "
          f"{min(r[0] for r in values_runs) / min(r[0] for r in api_runs):.2f}, cpu "
          f"{min(r[1] for r in values_runs) / min(r[1] for r in api_runs):.2f} (reported)\n",
          flush=True)
    return wall_ratio, cpu_ratio


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, nargs="+", default=[1_000_000], help="events per run")
    parser.add_argument("--repeat", type=int, default=1, help="runs of each; best is kept")
    parser.add_argument("--synchronous", default="FULL", help="PRAGMA synchronous for both")
    parser.add_argument("--api", choices=("kb", "store"), default="kb",
                        help="kb.add_many (default) or the store's add_events")
    parser.add_argument("--decimals", type=int, default=None,
                        help="round the coordinates to this many decimals (default: not)")
    parser.add_argument("--vectors", choices=("prolog", "python"), default="prolog",
                        help="positions as Prolog lists (make_list, default) or Python lists")
    options = parser.parse_args(argv)
    for n in options.n:
        measure(n, options.repeat, options.synchronous, options.api, options.decimals,
                options.vectors)


if __name__ == "__main__":
    main()
