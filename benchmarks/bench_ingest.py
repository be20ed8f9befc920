"""Ingest benchmark: EventStore.add_events vs raw sqlite3.executemany, same schema and pragmas.

Events are ``seg(oN, [x, y, z])^t`` (an atom and a list of three floats). The raw baseline
inserts rows that were encoded *before* the clock starts, into a table with the same columns,
indexes and pragmas (WAL, synchronous=FULL, the store's cache_size), in one transaction; the store does the same work
plus validation and encoding of every event. Building the Python terms is not timed for
either. Target: store / raw >= 0.70.

Run by hand::

    python benchmarks/bench_ingest.py            # 1,000,000 events
    python benchmarks/bench_ingest.py --n 100000 --repeat 3
"""
from __future__ import annotations

import argparse
import random
import sqlite3
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from slr_sql.encoding import encode  # noqa: E402
from slr_sql.store import CACHE_SIZE_KIB, EventStore  # noqa: E402
from slr_sql.terms import Atom, make_list  # noqa: E402


class FixedClock:
    def now(self) -> float:
        return 1000.0


def make_events(n: int, objects: int = 1000) -> list[tuple]:
    rng = random.Random(7)
    names = [Atom(f"o{i}") for i in range(objects)]
    events = []
    for i in range(n):
        t = i * 0.01
        position = make_list([rng.random(), rng.random(), rng.random()])
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


def run_raw(path: Path, events: list[tuple], synchronous: str) -> tuple[float, float]:
    # The same schema as the store creates (made by the store itself), then plain sqlite3.
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
    conn.executemany(f'INSERT INTO "{table}" (arg1, arg2, t_start, t_end, arrival) '
                     "VALUES (?, ?, ?, ?, ?)", rows)
    conn.execute("COMMIT")
    elapsed = time.perf_counter() - began, time.process_time() - began_cpu
    assert conn.execute(f'SELECT count(*) FROM "{table}"').fetchone()[0] == len(events)
    conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    conn.close()
    return elapsed


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=1_000_000, help="events per run")
    parser.add_argument("--repeat", type=int, default=1, help="runs of each; best is kept")
    parser.add_argument("--synchronous", default="FULL", help="PRAGMA synchronous for both")
    options = parser.parse_args(argv)

    events = make_events(options.n)
    raw_runs, store_runs = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for attempt in range(options.repeat):
            raw_path = Path(tmp) / f"raw{attempt}.db"
            store_path = Path(tmp) / f"store{attempt}.db"
            # alternate which goes first: the second run shares the disk with the first
            # one's writeback, and the machine's load drifts
            if attempt % 2 == 0:
                raw = run_raw(raw_path, events, options.synchronous)
                store = run_store(store_path, events, options.synchronous)
            else:
                store = run_store(store_path, events, options.synchronous)
                raw = run_raw(raw_path, events, options.synchronous)
            print(f"run {attempt + 1}: wall raw {raw[0]:.2f}s store {store[0]:.2f}s "
                  f"(ratio {raw[0] / store[0]:.2f}); cpu raw {raw[1]:.2f}s store {store[1]:.2f}s "
                  f"(ratio {raw[1] / store[1]:.2f})", flush=True)
            raw_runs.append(raw)
            store_runs.append(store)
            raw_path.unlink()
            store_path.unlink()
    n = options.n
    print(f"ingest of {n:,} events seg(oN, [x,y,z])^t, synchronous={options.synchronous}, "
          f"SQLite {sqlite3.sqlite_version}, best of {options.repeat}")
    print(f"{'method':<34}{'wall s':>9}{'events/s':>12}{'cpu s':>9}{'events/cpu-s':>14}")
    for label, runs in (("raw sqlite3.executemany (encoded)", raw_runs),
                        ("EventStore.add_events", store_runs)):
        wall = min(r[0] for r in runs)
        cpu = min(r[1] for r in runs)
        print(f"{label:<34}{wall:>9.2f}{n / wall:>12,.0f}{cpu:>9.2f}{n / cpu:>14,.0f}")
    wall_ratio = min(r[0] for r in raw_runs) / min(r[0] for r in store_runs)
    cpu_ratio = min(r[1] for r in raw_runs) / min(r[1] for r in store_runs)
    print(f"ratio store/raw: wall {wall_ratio:.2f}, cpu {cpu_ratio:.2f} (target >= 0.70; "
          "cpu time is the steadier figure on a shared machine)")


if __name__ == "__main__":
    main()
