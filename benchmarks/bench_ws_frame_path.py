"""The service's per-frame path that slr_sql owns, without sockets: 100 subscriptions of one
pattern delivered on one asyncio loop the way ``/subscribe`` delivers them, while another
thread adds ``--batches`` batches of 10 events (``add_many``, 2 ms apart, so that each batch is
a delivery pass and a frame per subscriber of its own). ``--path fanout`` (the default):
``slr serve``'s way, the loop's one callback (service/fanout.py) taking each subscriber's
batch and framing it once, written to a frame channel without a socket; ``--path
coroutines``: a coroutine per subscriber, ``next_answers(256, copy=False)`` then the frame's
JSON text by the service's ``_AnswerTexts`` (the way for clients that acknowledge, with
``--ws-compression``, and of the code before the fan-out). The figure is the CPU time of the
loop's thread per event (``time.thread_time``; the hub thread's is printed too), which a shared machine disturbs far less than
latency; the kernel's ``send`` is left out, and for the coroutines the WebSocket layers
(starlette, uvicorn, websockets) too (bench_service_ws.py and bench_ws_paired.py have them).

``--code DIR`` runs the same measurement with slr_sql from another checkout too (its delivery
``--code-path``, coroutines unless told), the two in alternation, ``--repeat`` times each: the
ratio is this checkout's over DIR's.

Run by hand::

    python benchmarks/bench_ws_frame_path.py
    python benchmarks/bench_ws_frame_path.py --code /tmp/before --repeat 3
    python benchmarks/bench_ws_frame_path.py --code . --repeat 3     # fan-out / coroutines
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

CHILD = r'''
import asyncio, json, os, sys, tempfile, threading, time
import slr_sql
from slr_sql.service.app import _AnswerTexts
n, batches, path = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
kb = slr_sql.open(os.path.join(tempfile.mkdtemp(), "frames.db"), clock=slr_sql.ManualClock(0))
kb.add("e(-1)^0")
subs = [kb.subscribe("e(I)^T", since=0.5) for _ in range(n)]
texts = _AnswerTexts()
counts = [0] * n
total = batches * 10
cpu = [0.0]
async def consume(k):
    sub, seq = subs[k], 0
    while counts[k] < total:
        answers = await sub.next_answers(256, copy=False)
        if not answers:
            break
        texts.frame(seq + 1, answers)
        seq += len(answers)
        counts[k] += len(answers)
class Sink:
    """A connection's frame channel without its socket: takes every frame."""
    on_drain = None
    paused = False
    open = True
    def write(self, frame):
        return True
    def writer(self):
        return self.write
started = threading.Event()
async def main():
    start = time.thread_time()
    if path == "fanout":
        from slr_sql.service.fanout import FanOut
        loop = asyncio.get_running_loop()
        fanout = FanOut(loop, texts.frame)
        deliveries = [fanout.start(sub, Sink(), 256) for sub in subs]
        loop.call_soon(started.set)
        while min(d.seq for d in deliveries) < total:
            await asyncio.sleep(0.01)   # (100 looks a second: well under 1% of the figure)
        for k, d in enumerate(deliveries):
            counts[k] = d.seq
    else:
        tasks = [asyncio.ensure_future(consume(k)) for k in range(n)]
        asyncio.get_running_loop().call_soon(started.set)   # (after each consumer's first step)
        await asyncio.gather(*tasks)
    cpu[0] = time.thread_time() - start
loop_thread = threading.Thread(target=lambda: asyncio.run(main()))
loop_thread.start()
started.wait(60)
hub = next(t for t in threading.enumerate() if t.name == "slr-subscriptions")
hub_clock = time.pthread_getcpuclockid(hub.ident)
hub_start = time.clock_gettime(hub_clock)
for b in range(batches):
    kb.add_many([f"e({j})^{j + 1}" for j in range(b * 10, b * 10 + 10)])
    time.sleep(0.002)   # (the stream's rate: 10 events every 2 ms, as a live producer)
loop_thread.join(120)
hub_cpu = time.clock_gettime(hub_clock) - hub_start
print(json.dumps({"us_per_event": cpu[0] / total * 1e6, "complete": min(counts) == total,
                  "hub_us_per_event": hub_cpu / total * 1e6}))
for sub in subs:
    sub.close()
kb.close()
'''


def measure(code: Path, subscribers: int, batches: int, path: str) -> dict:
    env = dict(os.environ, PYTHONPATH=str(code))
    out = subprocess.run([sys.executable, "-c", CHILD, str(subscribers), str(batches), path],
                         env=env, capture_output=True, text=True, check=True, cwd=tempfile.gettempdir())
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--subscribers", type=int, default=100)
    ap.add_argument("--batches", type=int, default=400)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--code", help="another checkout, measured in alternation (the baseline)")
    ap.add_argument("--path", choices=("fanout", "coroutines"), default="fanout",
                    help="this checkout's delivery: the loop's one callback writing to each "
                         "connection's frame channel (slr serve's), or a coroutine per "
                         "subscriber (acks, --ws-compression, another ASGI server)")
    ap.add_argument("--code-path", choices=("fanout", "coroutines"), default="coroutines",
                    help="the other checkout's delivery (coroutines: what code before the "
                         "fan-out had)")
    args = ap.parse_args()
    print("load average at start: %.2f %.2f %.2f" % os.getloadavg())
    mine: list[float] = []
    theirs: list[float] = []
    hubs: dict[str, list[float]] = {"mine": [], "theirs": []}
    for _ in range(args.repeat):
        r = measure(ROOT, args.subscribers, args.batches, args.path)
        assert r["complete"], "a subscriber missed events"
        mine.append(r["us_per_event"])
        hubs["mine"].append(r["hub_us_per_event"])
        if args.code:
            r = measure(Path(args.code), args.subscribers, args.batches, args.code_path)
            assert r["complete"], "a subscriber missed events"
            theirs.append(r["us_per_event"])
            hubs["theirs"].append(r["hub_us_per_event"])
    print(f"this checkout ({args.path}): loop thread CPU {', '.join(f'{x:.1f}' for x in mine)} µs per event "
          f"({args.subscribers} subscribers, best {min(mine):.1f})")
    if theirs:
        print(f"{args.code} ({args.code_path}): {', '.join(f'{x:.1f}' for x in theirs)} µs per event (best "
              f"{min(theirs):.1f}); ratio of the bests {min(mine) / min(theirs):.2f}")
    print("the hub thread's CPU (its delivery passes): this checkout "
          + ", ".join(f"{x:.1f}" for x in hubs["mine"]) + " µs per event"
          + ("; " + args.code + " " + ", ".join(f"{x:.1f}" for x in hubs["theirs"])
             if hubs["theirs"] else ""))
    print("load average at end: %.2f %.2f %.2f" % os.getloadavg())


if __name__ == "__main__":
    main()
