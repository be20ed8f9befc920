"""Buffers benchmark.

1. Ingest rate with a tBuffer and a cBuffer active vs with no buffer, same run, same events:
   ``tBuffer(tf(_,_,_), 10)`` and ``cBuffer(seg(O,_), 5)`` over a 1 kHz stream of tf/3 (a pose
   as a 7-number list, 75%) and seg/2 (50 objects, 25%) events, 1000 events per add_many
   batch (grouped by type inside the batch), on a file store (synchronous=FULL), the
   ManualClock following the stream.
2. Plateau: N events (default 10,000,000) streamed through ``tBuffer(tf(_,_,_), 10)`` at
   1 kHz of stream time (the ManualClock follows the stream); the file size (database + WAL)
   and the process RSS are sampled every 100,000 events, written to
   ``benchmarks/buffers_plateau.csv`` and plotted in ``benchmarks/buffers_plateau.png``.

Run from the repository root::

    python benchmarks/bench_buffers.py                 # both parts
    python benchmarks/bench_buffers.py --skip-plateau  # ingest ratio only
    python benchmarks/bench_buffers.py --plateau 1000000 --skip-ingest
"""
from __future__ import annotations

import argparse
import csv
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import slr_sql  # noqa: E402
from slr_sql import ManualClock  # noqa: E402

HERE = Path(__file__).resolve().parent
BATCH = 1000


def rss_bytes() -> int:
    """Current resident set size (Linux /proc; falls back to the peak from getrusage)."""
    try:
        with open("/proc/self/statm") as handle:
            return int(handle.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except OSError:
        import resource

        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def file_bytes(path: Path) -> int:
    total = 0
    for suffix in ("", "-wal"):
        try:
            total += os.path.getsize(str(path) + suffix)
        except OSError:
            pass
    return total


def mixed_batches(n: int):
    """tf/3 and seg/2 events at 1 kHz of stream time, in batches of BATCH."""
    t = 0.0
    batch = []
    for i in range(n):
        t += 0.001
        if i % 4:
            batch.append(("tf", ["map", "base", [t, 1.0, 0.5, 0.0, 0.0, 0.0, 1.0]], t, t))
        else:
            batch.append(("seg", [f"obj{i % 50}", [0.4, 0.1, t]], t, t))
        if len(batch) == BATCH:
            yield t, _by_type(batch)
            batch = []
    if batch:
        yield t, _by_type(batch)


def _by_type(batch: list) -> list:
    """One run per event type inside a batch (as a bridge batching per topic would send
    them; the store issues one executemany per run of one type)."""
    return sorted(batch, key=lambda event: event[0])


def ingest_rate(n: int, program: str | None, folder: Path, tag: str) -> float:
    path = folder / f"ingest_{tag}.db"
    for suffix in ("", "-wal", "-shm"):
        try:
            os.remove(str(path) + suffix)
        except OSError:
            pass
    batches = list(mixed_batches(n))  # prepared before timing: measure the store only
    kb = slr_sql.open(path, clock=ManualClock(0.0))
    if program:
        kb.load(program, "bench.slr")
    start = time.perf_counter()
    for t, batch in batches:
        kb.clock.set(t)
        kb.add_many(batch)
    elapsed = time.perf_counter() - start
    kb.close()
    return n / elapsed


def bench_ingest(n: int, rounds: int) -> dict:
    program = "tBuffer(tf(_, _, _), 10).\ncBuffer(seg(O, _), 5).\n"
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        plain, buffered = [], []
        for _ in range(rounds):  # interleaved, best of each: same run, same machine state
            plain.append(ingest_rate(n, None, folder, "plain"))
            buffered.append(ingest_rate(n, program, folder, "buffered"))
    result = {"events": n, "plain": max(plain), "buffered": max(buffered)}
    result["ratio"] = result["buffered"] / result["plain"]
    return result


def bench_plateau(n: int, every: int, out_csv: Path, out_png: Path) -> list[dict]:
    samples: list[dict] = []
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "plateau.db"
        kb = slr_sql.open(path, clock=ManualClock(0.0))
        kb.load("tBuffer(tf(_, _, _), 10).", "plateau.slr")
        per_batch = 10_000
        t = 0.0
        done = 0
        started = time.perf_counter()
        while done < n:
            size = min(per_batch, n - done)
            batch = []
            for _ in range(size):
                t += 0.001
                batch.append(("tf", ["map", "base", [t, 1.0, 0.5, 0.0, 0.0, 0.0, 1.0]], t, t))
            kb.clock.set(t)
            kb.add_many(batch)
            done += size
            if done % every == 0 or done == n:
                sample = {"events": done, "file_bytes": file_bytes(path), "rss_bytes": rss_bytes(),
                          "rows": kb.store.count("tf", 3),
                          "seconds": round(time.perf_counter() - started, 2)}
                samples.append(sample)
                if done % (every * 10) == 0 or done == n:
                    print(f"  {done:>11,} events  file {sample['file_bytes'] / 1e6:8.2f} MB  "
                          f"rss {sample['rss_bytes'] / 1e6:8.1f} MB  rows {sample['rows']:,}  "
                          f"{sample['seconds']:.0f} s", flush=True)
        kb.close()
    with open(out_csv, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(samples[0]))
        writer.writeheader()
        writer.writerows(samples)
    plot(samples, out_png)
    return samples


def plot(samples: list[dict], out_png: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    events = [s["events"] / 1e6 for s in samples]
    fig, ax1 = plt.subplots(figsize=(8, 4.5))
    ax1.plot(events, [s["file_bytes"] / 1e6 for s in samples], color="tab:blue",
             label="file size (db + WAL)")
    ax1.set_xlabel("events streamed (millions)")
    ax1.set_ylabel("file size (MB)", color="tab:blue")
    ax1.set_ylim(0, max(s["file_bytes"] for s in samples) / 1e6 * 1.3)
    ax2 = ax1.twinx()
    ax2.plot(events, [s["rss_bytes"] / 1e6 for s in samples], color="tab:red", label="RSS")
    ax2.set_ylabel("process RSS (MB)", color="tab:red")
    ax2.set_ylim(0, max(s["rss_bytes"] for s in samples) / 1e6 * 1.6)
    ax1.set_title("tBuffer(tf(_,_,_), 10): 1 kHz stream, 10k-event batches")
    lines = ax1.get_lines() + ax2.get_lines()
    ax1.legend(lines, [line.get_label() for line in lines], loc="lower right")
    ax1.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out_png, dpi=120)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ingest", type=int, default=200_000, help="events per ingest run")
    parser.add_argument("--rounds", type=int, default=3, help="ingest runs of each kind")
    parser.add_argument("--plateau", type=int, default=10_000_000, help="events streamed")
    parser.add_argument("--every", type=int, default=100_000, help="sample interval")
    parser.add_argument("--skip-ingest", action="store_true")
    parser.add_argument("--skip-plateau", action="store_true")
    parser.add_argument("--out", type=Path, default=HERE)
    parser.add_argument("--replot", type=Path, help="only redraw the PNG from a samples CSV")
    args = parser.parse_args()
    if args.replot:
        with open(args.replot) as handle:
            samples = [{k: float(v) for k, v in row.items()} for row in csv.DictReader(handle)]
        plot(samples, args.out / "buffers_plateau.png")
        return
    if not args.skip_ingest:
        r = bench_ingest(args.ingest, args.rounds)
        print(f"ingest, {r['events']:,} events, best of {args.rounds}: no buffer "
              f"{r['plain']:,.0f} ev/s; tBuffer + cBuffer {r['buffered']:,.0f} ev/s; "
              f"ratio {r['ratio']:.2f}", flush=True)
    if not args.skip_plateau:
        samples = bench_plateau(args.plateau, args.every, args.out / "buffers_plateau.csv",
                                args.out / "buffers_plateau.png")
        tail = samples[len(samples) // 10:]
        print(f"plateau: file {min(s['file_bytes'] for s in tail) / 1e6:.2f}.."
              f"{max(s['file_bytes'] for s in tail) / 1e6:.2f} MB, rss "
              f"{min(s['rss_bytes'] for s in tail) / 1e6:.1f}.."
              f"{max(s['rss_bytes'] for s in tail) / 1e6:.1f} MB after the first 10%; "
              f"{samples[-1]['events']:,} events in {samples[-1]['seconds']:.0f} s")


if __name__ == "__main__":
    main()
