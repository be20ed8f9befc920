"""Subscriptions: 100 subscribers at 1,000 events/s in one process, and what they cost `add`.

* **latency** — ``--subscribers`` (100) subscriptions to ``p(I, V)^T`` on a file store, each
  consumed by a callback (one delivery thread per subscription), an async iterator (all on
  one asyncio loop) or a blocking iterator (one thread each). One producer thread calls
  ``kb.add`` at ``--rate`` (1,000) events/s for ``--seconds`` (5) s. Latency of one delivery =
  the time the answer is received minus the time ``kb.add`` of its event returned (0 when the
  answer arrived before ``add`` returned). Checks that every subscriber received every event,
  once, in order.
* **baseline** — the same producer pacing and consumers, with each event handed to the
  subscribers by a bare in-memory fan-out (a deque and a Condition per subscriber, or one
  ``call_soon_threadsafe`` per event for async): no store, no matching. It shows what the
  machine and the interpreter allow at that moment (the machine is shared).
* **throughput** — ``kb.add`` of ``--events`` single events as fast as possible on a fresh
  store with no subscriber, and with the same subscribers consuming (callback mode): events/s
  and the ratio. Run order alternates; best of ``--repeat``.

Run by hand::

    python benchmarks/bench_subscriptions.py                  # everything
    python benchmarks/bench_subscriptions.py --modes async --seconds 3
"""
from __future__ import annotations

import argparse
import asyncio
import collections
import os
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import slr_sql  # noqa: E402
from percentiles import pct  # noqa: E402  (benchmarks/percentiles.py)


class Receiver:
    """What one subscriber received: event indexes and perf_counter at receipt, in two lists
    of numbers (numbers are not tracked by the garbage collector: recording 500,000 receipts
    must not itself cause the collector pauses the run measures)."""

    __slots__ = ("indexes", "times", "done", "expected")

    def __init__(self, expected: int):
        self.indexes: list[int] = []
        self.times: list[float] = []
        self.done = threading.Event()
        self.expected = expected

    def receive(self, answer: dict) -> None:
        self.times.append(time.perf_counter())
        self.indexes.append(answer["I"])
        if len(self.indexes) >= self.expected:
            self.done.set()

    @property
    def got(self) -> list[tuple[int, float]]:
        return list(zip(self.indexes, self.times))


def produce(kb, n: int, rate: float, added_at: list) -> float:
    """Add n events at ``rate`` per second (paced on perf_counter); returns the wall time."""
    t0 = time.perf_counter()
    for i in range(n):
        target = t0 + i / rate
        now = time.perf_counter()
        if target > now:
            time.sleep(target - now)
        kb.add_event("p", [i, 0.5], float(i))
        added_at[i] = time.perf_counter()
    return time.perf_counter() - t0


def run_latency(mode: str, subscribers: int, rate: float, seconds: float, synchronous: str,
                folder: Path) -> dict:
    n = int(rate * seconds)
    path = folder / f"latency-{mode}.db"
    receivers = [Receiver(n) for _ in range(subscribers)]
    added_at = [0.0] * n
    cpu0 = time.process_time()
    with slr_sql.open(path, synchronous=synchronous, clock=slr_sql.ManualClock(0.0)) as kb:
        subs = []
        consumers: list[threading.Thread] = []
        loop_thread = None
        if mode == "callback":
            subs = [kb.subscribe("p(I, V)^T", callback=r.receive, since=0) for r in receivers]
        elif mode == "iterator":
            subs = [kb.subscribe("p(I, V)^T", since=0) for _ in receivers]

            def iterate(sub, r):
                for answer in sub:
                    r.receive(answer)
                    if r.done.is_set():
                        return

            consumers = [threading.Thread(target=iterate, args=(s, r), daemon=True)
                         for s, r in zip(subs, receivers)]
            for c in consumers:
                c.start()
        elif mode == "async":
            subs = [kb.subscribe("p(I, V)^T", since=0) for _ in receivers]

            async def consume(sub, r):
                async for answer in sub:
                    r.receive(answer)
                    if r.done.is_set():
                        return

            async def main():
                await asyncio.gather(*(consume(s, r) for s, r in zip(subs, receivers)))

            loop_thread = threading.Thread(target=lambda: asyncio.run(main()), daemon=True)
            loop_thread.start()
        else:
            raise SystemExit(f"unknown mode {mode}")
        wall = produce(kb, n, rate, added_at)
        deadline = time.monotonic() + 60
        for r in receivers:
            r.done.wait(max(deadline - time.monotonic(), 0.0))
        cpu = time.process_time() - cpu0
        for s in subs:
            s.close()
        if loop_thread is not None:
            loop_thread.join(10)
    complete = all([i for i, _ in r.got] == list(range(n)) for r in receivers)
    lat = [max(0.0, t - added_at[i]) * 1e3 for r in receivers for i, t in r.got]
    return {"mode": mode, "events": n, "deliveries": len(lat), "complete": complete,
            "rate": n / wall, "p50": pct(lat, 50), "p99": pct(lat, 99), "max": max(lat),
            "cpu": cpu / wall}


class _RawSubscriber:
    """Baseline: a bare Python fan-out queue (deque + Condition), no store, no matching."""

    def __init__(self) -> None:
        self.queue: collections.deque = collections.deque()
        self.cond = threading.Condition()
        self.waiting = False
        self.future = None


def run_baseline(mode: str, subscribers: int, rate: float, seconds: float) -> dict:
    """The same producer pacing and consumers with the events handed over by a plain in-memory
    fan-out: what this machine and Python allow, measured in the same run."""
    n = int(rate * seconds)
    receivers = [Receiver(n) for _ in range(subscribers)]
    raws = [_RawSubscriber() for _ in range(subscribers)]
    added_at = [0.0] * n
    cpu0 = time.process_time()
    loop = asyncio.new_event_loop() if mode == "async" else None
    if mode == "async":
        async def consume(raw, r):
            while len(r.indexes) < r.expected:
                while not raw.queue:
                    raw.future = loop.create_future()
                    await raw.future
                    raw.future = None
                r.receive(raw.queue.popleft())

        def wake():
            for raw in raws:
                if raw.future is not None and not raw.future.done():
                    raw.future.set_result(None)

        async def main():
            await asyncio.gather(*(consume(raw, r) for raw, r in zip(raws, receivers)))

        thread = threading.Thread(target=lambda: loop.run_until_complete(main()), daemon=True)
    else:
        def consume_thread(raw, r):
            while len(r.indexes) < r.expected:
                with raw.cond:
                    while not raw.queue:
                        raw.waiting = True
                        raw.cond.wait()
                        raw.waiting = False
                    items = list(raw.queue)
                    raw.queue.clear()
                for answer in items:
                    r.receive(answer)

        thread = None
        for raw, r in zip(raws, receivers):
            threading.Thread(target=consume_thread, args=(raw, r), daemon=True).start()
    if thread is not None:
        thread.start()
    t0 = time.perf_counter()
    for i in range(n):
        target = t0 + i / rate
        now = time.perf_counter()
        if target > now:
            time.sleep(target - now)
        added_at[i] = time.perf_counter()
        answer = {"I": i, "V": 0.5, "T": float(i)}
        for raw in raws:
            with raw.cond:
                raw.queue.append(dict(answer))
                if raw.waiting:
                    raw.cond.notify()
        if loop is not None:
            loop.call_soon_threadsafe(wake)
    wall = time.perf_counter() - t0
    deadline = time.monotonic() + 60
    for r in receivers:
        r.done.wait(max(deadline - time.monotonic(), 0.0))
    cpu = time.process_time() - cpu0
    if thread is not None:
        thread.join(10)
    complete = all([i for i, _ in r.got] == list(range(n)) for r in receivers)
    lat = [max(0.0, t - added_at[i]) * 1e3 for r in receivers for i, t in r.got]
    return {"mode": f"baseline {mode}", "events": n, "deliveries": len(lat),
            "complete": complete, "rate": n / wall, "p50": pct(lat, 50), "p99": pct(lat, 99),
            "max": max(lat), "cpu": cpu / wall}


def add_rate(subscribers: int, events: int, synchronous: str, path: Path) -> float:
    with slr_sql.open(path, synchronous=synchronous, clock=slr_sql.ManualClock(0.0)) as kb:
        receivers = [Receiver(events) for _ in range(subscribers)]
        subs = [kb.subscribe("p(I, V)^T", callback=r.receive, since=0) for r in receivers]
        t0 = time.perf_counter()
        for i in range(events):
            kb.add_event("p", [i, 0.5], float(i))
        elapsed = time.perf_counter() - t0
        for r in receivers:
            r.done.wait(120)
        assert all(len(r.indexes) == events for r in receivers), "a subscriber missed events"
        for s in subs:
            s.close()
    return events / elapsed


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--subscribers", type=int, default=100)
    ap.add_argument("--rate", type=float, default=1000.0)
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--modes", default="baseline-callback,callback,baseline-async,async,"
                                       "iterator")
    ap.add_argument("--events", type=int, default=5000, help="throughput run: events added")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--synchronous", default="NORMAL",
                    help="PRAGMA synchronous of the store (the library default is FULL)")
    ap.add_argument("--skip-throughput", action="store_true")
    args = ap.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="bench-subs-"))
    print(f"{args.subscribers} subscribers, {args.rate:g} events/s for {args.seconds:g} s, "
          f"synchronous={args.synchronous}, load average {os.getloadavg()[0]:.1f}")
    print("| mode | events | deliveries | all delivered in order | achieved rate | p50 | p99 "
          "| max | CPU (s/s) |")
    print("|---|---:|---:|---|---:|---:|---:|---:|---:|")
    for mode in args.modes.split(","):
        if mode.startswith("baseline-"):
            r = run_baseline(mode.split("-", 1)[1], args.subscribers, args.rate, args.seconds)
        else:
            r = run_latency(mode, args.subscribers, args.rate, args.seconds, args.synchronous,
                            folder)
        print(f"| {r['mode']} | {r['events']:,} | {r['deliveries']:,} | "
              f"{'yes' if r['complete'] else 'NO'} | {r['rate']:,.0f}/s | {r['p50']:.2f} ms | "
              f"{r['p99']:.2f} ms | {r['max']:.1f} ms | {r['cpu']:.2f} |", flush=True)
    if args.skip_throughput:
        return
    print()
    print(f"add throughput, {args.events:,} single kb.add calls:")
    print("| run | no subscriber | "
          f"{args.subscribers} subscribers | ratio |")
    print("|---|---:|---:|---:|")
    best = [0.0, 0.0]
    for run in range(args.repeat):
        order = [0, args.subscribers] if run % 2 == 0 else [args.subscribers, 0]
        rates = {}
        for subs in order:
            rates[subs] = add_rate(subs, args.events, args.synchronous,
                                   folder / f"tp-{run}-{subs}.db")
        best = [max(best[0], rates[0]), max(best[1], rates[args.subscribers])]
        print(f"| {run + 1} | {rates[0]:,.0f}/s | {rates[args.subscribers]:,.0f}/s | "
              f"{rates[args.subscribers] / rates[0]:.2f} |", flush=True)
    print(f"| best | {best[0]:,.0f}/s | {best[1]:,.0f}/s | {best[1] / best[0]:.2f} |")


if __name__ == "__main__":
    main()
