"""What a lagging subscriber costs the writer: CPU per event of ``kb.add_many`` (batches of
``--batch`` events, like the service's producer) on a file store with no subscriber, with one
subscriber that keeps up, and with one that lags (a full queue nobody takes from, so it
falls further behind with every event), in one run, alternating, best of ``--repeat``.

Figures are CPU times (``time.thread_time`` of the writer thread, ``time.process_time`` of
the whole process: writer, hub thread and consumer), which a shared machine disturbs much
less than wall time; the ratios are against the no-subscriber run of the same round. Lag
independence: the lagging run's CPU per event in its last quarter (lag 3/4 N .. N) against
its first quarter (lag 0 .. N/4).

Run by hand::

    python benchmarks/bench_subscriptions_lag.py                 # 20,000 events, best of 3
    python benchmarks/bench_subscriptions_lag.py --events 5000 --repeat 1
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import slr_sql  # noqa: E402


def run(mode: str, events: int, batch: int) -> dict[str, float]:
    """One writer run; per-event CPU (µs) overall and in its first and last quarter."""
    path = os.path.join(tempfile.mkdtemp(prefix="slr-lag-"), "lag.db")
    with slr_sql.open(path, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add("e(0)^0")                     # the table exists before the measured part
        consumer = None
        sub = None
        if mode == "keeps up":
            sub = kb.subscribe("e(I)^T", since=1, max_lag=None)

            def consume() -> None:
                for answer in sub:
                    if answer["I"] == events:
                        return

            consumer = threading.Thread(target=consume, daemon=True)
            consumer.start()
        elif mode == "lags":
            sub = kb.subscribe("e(I)^T", since=1, max_queue=100, max_lag=None)
        quarters = []
        t0, p0 = time.thread_time(), time.process_time()
        mark = (t0, p0)
        for i in range(1, events + 1, batch):
            kb.add_many([("e", (j,), float(j), float(j))
                         for j in range(i, min(i + batch, events + 1))])
            if (i + batch - 1) % (events // 4) < batch:
                now = (time.thread_time(), time.process_time())
                quarters.append((now[0] - mark[0], now[1] - mark[1]))
                mark = now
        assert kb._subscriptions.drain(60.0) or sub is None
        if consumer is not None:
            consumer.join(60.0)
            assert not consumer.is_alive(), "the consumer did not get every event"
        t1, p1 = time.thread_time(), time.process_time()
        if sub is not None:
            if mode == "lags":
                assert sub.lagging, sub.state
            sub.close()
    per = 1e6 / events
    q = 4e6 / events
    return {"writer": (t1 - t0) * per, "process": (p1 - p0) * per,
            "process_first_q": quarters[0][1] * q if quarters else float("nan"),
            "process_last_q": quarters[-1][1] * q if quarters else float("nan")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--events", type=int, default=20_000)
    ap.add_argument("--batch", type=int, default=10)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    modes = ["none", "keeps up", "lags"]
    best: dict[str, dict[str, float]] = {}
    print(f"load average at start: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    for r in range(args.repeat):
        order = modes if r % 2 == 0 else modes[::-1]
        for mode in order:
            got = run(mode, args.events, args.batch)
            old = best.get(mode)
            if old is None or got["process"] < old["process"]:
                best[mode] = got
    base = best["none"]
    print(f"{args.events} events in add_many batches of {args.batch}, best of {args.repeat} "
          f"(CPU µs per event; ratio to no subscriber)")
    for mode in modes:
        b = best[mode]
        print(f"  {mode:9s}: writer thread {b['writer']:7.1f} ({b['writer'] / base['writer']:.2f}x)"
              f"   process {b['process']:7.1f} ({b['process'] / base['process']:.2f}x)"
              f"   last/first quarter {b['process_last_q'] / b['process_first_q']:.2f}")
    print(f"load average at end: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
