"""Foxglove delivery latency: events written by one process at 1,000 events/s, seen by one
Foxglove WebSocket client of ``slr foxglove`` (a third process).

    python benchmarks/bench_foxglove.py                 # 3 s at 1,000 events/s
    python benchmarks/bench_foxglove.py --rate 2000 --seconds 5

The writer adds ``ping(I)^T`` one event per transaction (``synchronous=NORMAL``, as the ROS
bridge writes) on a fixed schedule; each event's arrival time is the store's wall clock when
it was stored. The client subscribes to ``/ping/1`` and takes, for every message, its
receive time minus the event's arrival time: the time from the commit to the client. The
figures are the p50 and p99 of that delay (target: p99 <= 20 ms), and how many events
arrived. The same run measures the baseline the view adds to: the foxglove-sdk server alone
logging the same messages from its own process at the same rate (no store, no polling).
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

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import slr_sql  # noqa: E402
from percentiles import pct  # noqa: E402

WRITER = r"""
import sys, time
import slr_sql
db, rate, seconds = sys.argv[1], float(sys.argv[2]), float(sys.argv[3])
with slr_sql.open(db, synchronous="NORMAL") as kb:
    print("ready", flush=True)
    sys.stdin.readline()
    start = time.perf_counter()
    n = int(rate * seconds)
    for i in range(n):
        wait = start + i / rate - time.perf_counter()
        if wait > 0:
            time.sleep(wait)
        kb.add_many([("ping", (i,), time.time(), time.time())])
print("done", flush=True)
"""


def client_delays(port: int, topic: str, expected: int, started: threading.Event,
                  deadline: float) -> list[float]:
    from websockets.sync.client import connect

    delays: list[float] = []
    with connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1", "foxglove.websocket.v1"],
                 max_size=None) as ws:
        channel = None
        while channel is None:
            frame = ws.recv(timeout=30)
            if isinstance(frame, str):
                op = json.loads(frame)
                if op["op"] == "advertise":
                    channel = next((c["id"] for c in op["channels"] if c["topic"] == topic), None)
        ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": channel}]}))
        time.sleep(0.5)   # the subscription is in effect before the writer starts
        started.set()
        while len(delays) < expected and time.monotonic() < deadline:
            try:
                frame = ws.recv(timeout=1.0)
            except TimeoutError:
                continue
            now = time.time()
            if isinstance(frame, bytes) and frame[0] == 1:
                delays.append(now - json.loads(frame[13:])["arrival"])
    return delays


def view_run(rate: float, seconds: float) -> list[float]:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    with tempfile.TemporaryDirectory() as tmp:
        db = Path(tmp) / "live.db"
        with slr_sql.open(db) as kb:
            kb.add_many([("ping", (-1,), 0.0, 0.0)])
        server = subprocess.Popen([sys.executable, "-m", "slr_sql", "foxglove", str(db), "--port",
                                   "0"], stdout=subprocess.PIPE, text=True, env=env)
        writer = subprocess.Popen([sys.executable, "-c", WRITER, str(db), str(rate), str(seconds)],
                                  stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env)
        try:
            port = int(server.stdout.readline().split(":")[3].split()[0])
            assert writer.stdout.readline().strip() == "ready"
            started = threading.Event()
            result: list = []
            n = int(rate * seconds)
            reader = threading.Thread(target=lambda: result.extend(client_delays(
                port, "/ping/1", n, started, time.monotonic() + seconds + 60)))
            reader.start()
            started.wait(60)
            writer.stdin.write("go\n")
            writer.stdin.flush()
            reader.join()
            return result
        finally:
            for p in (writer, server):
                p.terminate()
                p.wait(timeout=30)


def sdk_alone(rate: float, seconds: float) -> list[float]:
    import foxglove

    context = foxglove.Context()
    channel = foxglove.Channel("/ping/1", schema={"type": "object"}, context=context)
    server = foxglove.start_server(port=0, context=context)
    try:
        started = threading.Event()
        result: list = []
        n = int(rate * seconds)
        reader = threading.Thread(target=lambda: result.extend(client_delays(
            server.port, "/ping/1", n, started, time.monotonic() + seconds + 60)))
        reader.start()
        started.wait(60)
        start = time.perf_counter()
        for i in range(n):
            wait = start + i / rate - time.perf_counter()
            if wait > 0:
                time.sleep(wait)   # not a busy loop: the client thread needs the GIL
            channel.log({"arg1": i, "start": 0.0, "end": 0.0, "arrival": time.time()})
        reader.join()
        return result
    finally:
        server.stop()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rate", type=float, default=1000.0)
    parser.add_argument("--seconds", type=float, default=3.0)
    args = parser.parse_args()
    n = int(args.rate * args.seconds)
    for name, run in (("slr foxglove (store -> client)", view_run),
                      ("foxglove-sdk alone (log -> client)", sdk_alone)):
        delays = run(args.rate, args.seconds)
        ms = [d * 1e3 for d in delays]
        print(f"{name:36s} {len(ms)}/{n} events  p50 {pct(ms, 50):6.2f} ms  "
              f"p99 {pct(ms, 99):6.2f} ms  max {max(ms):6.2f} ms")


if __name__ == "__main__":
    main()
