"""An event rule loaded on a store that already holds many events: the seconds (wall clock
and CPU) of the load, of the first add after it and of the adds after that, on a SQLite file
(docs/schema.md, "Start order on first need").

The store holds ``--events`` ``face(F, R, T)^T`` events (20 faces, 10 a second) before the
rule ``r(F) <- (face(F, R1, _) seq face(F, R2, _) seq face(F, R3, _)) within 5 where (R1 >
60, R2 > R1, R3 > R2).`` (bench_events.py's seq3, ``unrestricted``) is loaded; its
statements want face's start-ordered indexes, built over the whole history once: at the
load since this benchmark was written, before that at the first add. The later adds are the
baseline, measured in the same run: the first add's ratio to their median says how much
of the one-time cost is left on the add path. ``--tree`` runs another checkout's code.

    python benchmarks/bench_first_add.py --events 1000000
    python benchmarks/bench_first_add.py --events 1000000 --tree /tmp/before
"""
from __future__ import annotations

import argparse
import os
import random
import shutil
import statistics
import sys
import tempfile
import time

RULE = (":- max_delay(face/3, 0).\nr(F) <- (face(F, R1, _) seq face(F, R2, _) seq "
        "face(F, R3, _)) within 5 where (R1 > 60, R2 > R1, R3 > R2).")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--events", type=int, default=1_000_000)
    parser.add_argument("--adds", type=int, default=20, help="adds timed after the load")
    parser.add_argument("--tree", default=os.path.join(os.path.dirname(
        os.path.abspath(__file__)), ".."), help="the checkout whose slr_sql runs")
    args = parser.parse_args()
    sys.path.insert(0, os.path.abspath(args.tree))
    import slr_sql

    folder = tempfile.mkdtemp(prefix="bench_first_add_")
    try:
        clock = slr_sql.ManualClock(0.0)
        kb = slr_sql.open(os.path.join(folder, "b.db"), clock=clock)
        rng = random.Random(1)
        for i in range(0, args.events, 20_000):
            chunk = [("face", [f"f{j % 20}", rng.randint(50, 100), round(j * 0.1, 6)],
                      round(j * 0.1, 6), round(j * 0.1, 6))
                     for j in range(i, min(args.events, i + 20_000))]
            clock.set(chunk[-1][2] + 0.05)
            kb.add_many(chunk)
        t0, c0 = time.perf_counter(), time.process_time()
        kb.load(RULE)
        load = (time.perf_counter() - t0, time.process_time() - c0)
        t = round(args.events * 0.1 + 10.0, 6)
        times = []
        for k in range(args.adds + 1):
            clock.set(t)
            t0, c0 = time.perf_counter(), time.process_time()
            kb.add_event("face", [f"f{k % 3}", 61 + k, t], t, t)
            times.append((time.perf_counter() - t0, time.process_time() - c0))
            t = round(t + 0.1, 6)
        found = kb.store.count("r", 1)
        kb.close()
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    first, later = times[0], times[1:]
    wall = statistics.median(w for w, _ in later)
    cpu = statistics.median(c for _, c in later)
    print(f"{slr_sql.__file__}: {args.events:,} stored events; load {load[0]:.3f} s "
          f"({load[1]:.3f} s CPU); first add {first[0] * 1000:.1f} ms ({first[1] * 1000:.1f} ms "
          f"CPU) = {first[0] / wall:.0f}x wall, {first[1] / max(cpu, 1e-9):.0f}x CPU of the "
          f"later adds' median {wall * 1000:.2f} ms ({cpu * 1000:.2f} ms CPU); {found} "
          f"complex events; load average {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
