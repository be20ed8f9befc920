"""The service's per-frame path that slr_sql owns, without sockets: 100 subscriptions of one
pattern consumed on one asyncio loop the way ``/subscribe`` consumes them
(``next_answers(256, copy=False)``, then the frame's JSON text by the service's
``_AnswerTexts``), while another thread adds ``--batches`` batches of 10 events (``add_many``,
2 ms apart, so that each batch is a delivery pass and a frame per subscriber of its own). The
figure is the CPU time of the loop's thread per event (``time.thread_time``), which a shared
machine disturbs far less than latency; the WebSocket layers (starlette, uvicorn,
websockets) and the kernel's ``send`` are left out (bench_service_ws.py has them).

``--code DIR`` runs the same measurement with slr_sql from another checkout too, the two in
alternation, ``--repeat`` times each: the ratio is this checkout's over DIR's.

Run by hand::

    python benchmarks/bench_ws_frame_path.py
    python benchmarks/bench_ws_frame_path.py --code /tmp/before --repeat 3
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
n, batches = int(sys.argv[1]), int(sys.argv[2])
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
started = threading.Event()
async def main():
    start = time.thread_time()
    tasks = [asyncio.ensure_future(consume(k)) for k in range(n)]
    asyncio.get_running_loop().call_soon(started.set)   # (after each consumer's first step)
    await asyncio.gather(*tasks)
    cpu[0] = time.thread_time() - start
loop_thread = threading.Thread(target=lambda: asyncio.run(main()))
loop_thread.start()
started.wait(60)
for b in range(batches):
    kb.add_many([f"e({j})^{j + 1}" for j in range(b * 10, b * 10 + 10)])
    time.sleep(0.002)   # (the stream's rate: 10 events every 2 ms, as a live producer)
loop_thread.join(120)
print(json.dumps({"us_per_event": cpu[0] / total * 1e6, "complete": min(counts) == total}))
for sub in subs:
    sub.close()
kb.close()
'''


def measure(code: Path, subscribers: int, batches: int) -> dict:
    env = dict(os.environ, PYTHONPATH=str(code))
    out = subprocess.run([sys.executable, "-c", CHILD, str(subscribers), str(batches)],
                         env=env, capture_output=True, text=True, check=True, cwd=tempfile.gettempdir())
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--subscribers", type=int, default=100)
    ap.add_argument("--batches", type=int, default=400)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--code", help="another checkout, measured in alternation (the baseline)")
    args = ap.parse_args()
    print("load average at start: %.2f %.2f %.2f" % os.getloadavg())
    mine: list[float] = []
    theirs: list[float] = []
    for _ in range(args.repeat):
        r = measure(ROOT, args.subscribers, args.batches)
        assert r["complete"], "a subscriber missed events"
        mine.append(r["us_per_event"])
        if args.code:
            r = measure(Path(args.code), args.subscribers, args.batches)
            assert r["complete"], "a subscriber missed events"
            theirs.append(r["us_per_event"])
    print(f"this checkout: loop thread CPU {', '.join(f'{x:.1f}' for x in mine)} µs per event "
          f"({args.subscribers} subscribers, best {min(mine):.1f})")
    if theirs:
        print(f"{args.code}: {', '.join(f'{x:.1f}' for x in theirs)} µs per event (best "
              f"{min(theirs):.1f}); ratio of the bests {min(mine) / min(theirs):.2f}")
    print("load average at end: %.2f %.2f %.2f" % os.getloadavg())


if __name__ == "__main__":
    main()
