"""Reliability benchmark: many writer and reader processes on one store file, and SIGKILLs.

Part 1, throughput: for each N in ``--writers`` (default 1, 2, 4), N writer processes add
events ``w(Writer, Seq)^T`` through ``kb.add_many`` (``--batch`` events a call, one
transaction each, ``synchronous=FULL``) as fast as they can for ``--seconds``, while M
reader processes (``--readers``) ask ``prev(w(W, S)^T, 1e18)`` through ``kb.query``,
``--reader-rate`` times a second each. A writer prints
an acknowledgement once its ``add_many`` has returned. A lock wait longer than the writers'
``busy_timeout`` (``--busy-timeout``) is an ``SLRBusy``: the writer counts it and retries the
same batch. Afterwards every acknowledged event must be in the file (lost = acknowledged but
absent). The baseline, measured in the same run, interleaved: N processes inserting the same
rows with raw ``sqlite3`` into the same schema, one transaction per batch, same pragmas,
SQLite's own busy handler.

Part 2, SIGKILL loop: ``--kills`` rounds; each starts two writers and a reader on one file
(the same file across rounds, so it keeps growing), waits until each writer has
acknowledged a random number of batches, then SIGKILLs every process at that point. Every
acknowledged event must survive, the file must pass ``PRAGMA integrity_check`` and reopen.

Run by hand::

    python benchmarks/bench_reliability.py                # N = 1, 2, 4; 2 readers at 200/s; 50 kills
    python benchmarks/bench_reliability.py --writers 1,2 --seconds 3 --kills 5
"""
from __future__ import annotations

import argparse
import os
import random
import signal
import sqlite3
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

import slr_sql  # noqa: E402
from slr_sql.store import CACHE_SIZE_KIB  # noqa: E402

# argv: path writer_id batch seconds busy_timeout start_seq. With seconds > 0 it writes for
# that long and prints "ack <first> <last>" (every sequence number acknowledged) and
# "busy <count>" at the end; with seconds <= 0 it writes until killed and prints
# "ack <first> <last>" for each batch as soon as its add_many has returned.
WRITER = textwrap.dedent("""
    import sys, time
    sys.path.insert(0, {repo!r})
    import slr_sql
    path, wid, batch, seconds, busy, seq = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), \\
        float(sys.argv[4]), float(sys.argv[5]), int(sys.argv[6])
    kb = slr_sql.open(path, busy_timeout=busy)
    retries = 0
    first = seq
    if seconds > 0:   # a common start: every process is open and waiting
        sys.stdout.write("ready\\n")
        sys.stdout.flush()
        sys.stdin.readline()
    began = time.monotonic()
    end = began + seconds
    slowest = 0.0
    while seconds <= 0 or time.monotonic() < end:
        events = [("w", ("w%d" % wid, seq + k), float(seq + k), float(seq + k))
                  for k in range(batch)]
        t = time.monotonic()
        while True:
            try:
                rejected = kb.add_many(events)
                break
            except slr_sql.SLRBusy:
                retries += 1
        slowest = max(slowest, time.monotonic() - t)
        assert not rejected, rejected
        if seconds <= 0:
            sys.stdout.write("ack %d %d\\n" % (seq, seq + batch - 1))
            sys.stdout.flush()
        seq += batch
    sys.stdout.write("ack %d %d\\nbusy %d\\nelapsed %f\\nslowest %f\\n"
                     % (first, seq - 1, retries, time.monotonic() - began, slowest))
    sys.stdout.flush()
    kb.close()
""")

# The baseline writer: the same rows, raw sqlite3 on the same file (the store's schema and
# pragmas), BEGIN IMMEDIATE / executemany / COMMIT a batch, SQLite's own busy handler.
RAW_WRITER = textwrap.dedent("""
    import sqlite3, sys, time
    path, wid, batch, seconds, busy, seq = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), \\
        float(sys.argv[4]), float(sys.argv[5]), int(sys.argv[6])
    conn = sqlite3.connect(path, isolation_level=None, timeout=busy)
    conn.execute("PRAGMA synchronous=FULL")
    conn.execute("PRAGMA cache_size=-{cache}")
    retries = 0
    first = seq
    sys.stdout.write("ready\\n")
    sys.stdout.flush()
    sys.stdin.readline()
    began = time.monotonic()
    end = began + seconds
    slowest = 0.0
    while time.monotonic() < end:
        rows = [("w%d" % wid, seq + k, float(seq + k), float(seq + k), time.time())
                for k in range(batch)]
        t = time.monotonic()
        while True:
            try:
                conn.execute("BEGIN IMMEDIATE")
                break
            except sqlite3.OperationalError:
                retries += 1
        conn.executemany("INSERT INTO w (arg1, arg2, t_start, t_end, arrival) "
                         "VALUES (?, ?, ?, ?, ?)", rows)
        conn.execute("COMMIT")
        slowest = max(slowest, time.monotonic() - t)
        seq += batch
    sys.stdout.write("ack %d %d\\nbusy %d\\nelapsed %f\\nslowest %f\\n"
                     % (first, seq - 1, retries, time.monotonic() - began, slowest))
    sys.stdout.flush()
""")

# argv: path seconds rate. Asks `rate` queries a second (as a robot's control loop would;
# 0: as fast as it can). Prints "queries <n> errors <n>" at the end.
READER = textwrap.dedent("""
    import sys, time
    sys.path.insert(0, {repo!r})
    import slr_sql
    path, seconds, rate = sys.argv[1], float(sys.argv[2]), float(sys.argv[3])
    kb = slr_sql.open(path)
    queries = errors = 0
    if seconds > 0:
        sys.stdout.write("ready\\n")
        sys.stdout.flush()
        sys.stdin.readline()
    began = time.monotonic()
    end = began + seconds
    while seconds <= 0 or time.monotonic() < end:
        if rate > 0:
            time.sleep(max(0.0, began + queries / rate - time.monotonic()))
        try:
            kb.query("prev(w(W, S)^T, 1e18)")
            queries += 1
        except slr_sql.SLRError as exc:
            errors += 1
            sys.stderr.write("%s\\n" % exc)
    sys.stdout.write("queries %d errors %d\\n" % (queries, errors))
    sys.stdout.flush()
    kb.close()
""")


def spawn(code: str, *args) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", code.format(repo=str(REPO),
                                                               cache=CACHE_SIZE_KIB),
                             *map(str, args)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            text=True)


def start_together(procs: list) -> None:
    """Wait until every process has opened the store, then let them all go."""
    for proc in procs:
        assert proc.stdout.readline().strip() == "ready"
    for proc in procs:
        proc.stdin.write("go\n")
        proc.stdin.flush()


def prepare(path: Path) -> None:
    """Create the store and the event type once, before the writers race for it."""
    with slr_sql.open(path) as kb:
        kb.load(":- event(w/2).")


def stored(path: Path) -> dict[str, set]:
    """Every stored w/2 event, as writer -> set of sequence numbers; checks integrity."""
    conn = sqlite3.connect(path)
    try:
        assert conn.execute("PRAGMA integrity_check").fetchone() == ("ok",)
        out: dict[str, set] = {}
        for writer, seq in conn.execute("SELECT arg1, arg2 FROM w"):
            out.setdefault(writer, set()).add(seq)
        return out
    finally:
        conn.close()


def read_acks(lines: list[str], wid: int, acked: dict) -> dict:
    """Record the acknowledged sequence numbers; returns the writer's closing figures."""
    figures = {}
    for line in lines:
        parts = line.split()
        if parts and parts[0] == "ack":
            acked.setdefault(f"w{wid}", set()).update(range(int(parts[1]), int(parts[2]) + 1))
        elif len(parts) == 2:
            figures[parts[0]] = float(parts[1])
    return figures


def throughput(writer: str, n_writers: int, n_readers: int, reader_rate: float, seconds: float,
               batch: int, busy_timeout: float, folder: Path) -> dict:
    path = folder / f"throughput-{n_writers}-{'raw' if writer is RAW_WRITER else 'store'}.db"
    prepare(path)
    writers = [spawn(writer, path, i, batch, seconds, busy_timeout, 0) for i in range(n_writers)]
    readers = [spawn(READER, path, seconds, reader_rate) for _ in range(n_readers)]
    start_together(writers + readers)
    acked: dict = {}
    busy = 0
    elapsed = slowest = 0.0
    for i, w in enumerate(writers):
        out, _ = w.communicate()
        figures = read_acks(out.splitlines(), i, acked)
        busy += int(figures["busy"])
        elapsed = max(elapsed, figures["elapsed"])
        slowest = max(slowest, figures["slowest"])
    queries = errors = 0
    for r in readers:
        out, _ = r.communicate()
        parts = out.split()
        queries += int(parts[1])
        errors += int(parts[3])
    found = stored(path)
    per_writer = [len(acked.get(f"w{i}", ())) for i in range(n_writers)]
    total = sum(per_writer)
    lost = sum(len(seqs - found.get(w, set())) for w, seqs in acked.items())
    return {"writers": n_writers, "events": total, "events_s": total / elapsed, "busy": busy,
            "lost": lost, "queries_s": queries / seconds, "reader_errors": errors,
            "fairness": min(per_writer) / max(per_writer) if max(per_writer) else 0.0,
            "slowest": slowest}


def kill_loop(kills: int, batch: int, busy_timeout: float, folder: Path,
              rng: random.Random) -> dict:
    path = folder / "killed.db"
    prepare(path)
    acked: dict = {}
    for round_ in range(kills):
        # sequence numbers of their own for each writer and round: an event in flight when
        # its writer was killed (stored or not) is never confused with a later one
        writers = {i: spawn(WRITER, path, i, batch, 0, busy_timeout,
                            1_000_000_000 * i + 1_000_000 * round_) for i in (0, 1)}
        reader = spawn(READER, path, 0, 0)
        for i, w in writers.items():
            for _ in range(rng.randint(1, 60)):
                line = w.stdout.readline()
                if not line:
                    raise RuntimeError("a writer died before it was killed")
                read_acks([line], i, acked)
        time.sleep(rng.random() * 0.02)   # a random point of the writers' next transaction
        for proc in list(writers.values()) + [reader]:
            os.kill(proc.pid, signal.SIGKILL)
        for i, w in writers.items():
            w.wait()
            read_acks(w.stdout.read().splitlines(), i, acked)   # acknowledged before the kill
            w.stdout.close()
        reader.wait()
        reader.stdout.close()
    found = stored(path)
    with slr_sql.open(path) as kb:   # and it reopens as a knowledge base
        kb.query("prev(w(W, S)^T, 1e18)")
    total = sum(len(v) for v in acked.values())
    lost = sum(len(seqs - found.get(w, set())) for w, seqs in acked.items())
    return {"kills": kills, "acknowledged": total, "stored": sum(len(v) for v in found.values()),
            "lost": lost}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--writers", default="1,2,4")
    parser.add_argument("--readers", type=int, default=2)
    parser.add_argument("--reader-rate", type=float, default=200.0,
                        help="queries a second per reader (0: as fast as it can)")
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--batch", type=int, default=10)
    parser.add_argument("--busy-timeout", type=float, default=slr_sql.store.DEFAULT_BUSY_TIMEOUT)
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--kills", type=int, default=50)
    parser.add_argument("--seed", type=int, default=7)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        print(f"{args.readers} readers, {args.reader_rate:g} queries/s each; "
              f"{args.batch} events an add; best of {args.repeat} interleaved runs")
        print("| writers | raw sqlite3 events/s | store events/s | store / raw | slowest add "
              "(raw, store) | fewest/most per writer | SLRBusy retries | lost |")
        print("|---:|---:|---:|---:|---:|---:|---:|---:|")
        for n in (int(x) for x in args.writers.split(",")):
            best: dict = {}
            for _ in range(args.repeat):
                for kind, code in (("raw", RAW_WRITER), ("store", WRITER)):
                    r = throughput(code, n, args.readers, args.reader_rate, args.seconds,
                                   args.batch, args.busy_timeout, folder)
                    assert r["lost"] == 0 and r["reader_errors"] == 0, r
                    if kind not in best or r["events_s"] > best[kind]["events_s"]:
                        best[kind] = r
            raw, store = best["raw"], best["store"]
            print(f"| {n} | {raw['events_s']:,.0f} | {store['events_s']:,.0f} | "
                  f"{store['events_s'] / raw['events_s']:.2f} | {raw['slowest'] * 1000:,.0f} ms, "
                  f"{store['slowest'] * 1000:,.0f} ms | {store['fairness']:.2f} | "
                  f"{store['busy']} | {store['lost']} |", flush=True)
        if args.kills:
            k = kill_loop(args.kills, args.batch, args.busy_timeout, folder,
                          random.Random(args.seed))
            print(f"SIGKILL loop: {k['kills']} rounds of 2 writers + 1 reader killed; "
                  f"{k['acknowledged']:,} events acknowledged, {k['stored']:,} stored, "
                  f"lost {k['lost']}")
            assert k["lost"] == 0, k


if __name__ == "__main__":
    main()
