"""The server's CPU per WebSocket frame, two (or more) checkouts side by side in the same
time window: one ``slr serve`` per checkout, ``--subscribers`` WebSocket subscribers to
``e(I)^T`` on each (all in one subscribers process), and a producer that adds batches of 10
events by HTTP ``add_many`` to each server in turn, each time waiting until every subscriber
of that server has the batch (lockstep: one frame per subscriber per batch, whatever the
load). The figure is each server's CPU per frame delivered (its event loop's thread and the
whole process), the HTTP request of each batch included.

On a shared machine the CPU time of a thread depends on what the other core runs (a 2-core
VM's cores are often one core's two hyperthreads): runs made one after the other differ by
20% and more for the same code. Here the servers take turns batch by batch, so whatever
disturbs one disturbs the others alike, and the difference between them is what their code
makes (the same checkout twice agrees within ~3%).

Run by hand::

    python benchmarks/bench_ws_paired.py /tmp/before,.            # before, this checkout
    python benchmarks/bench_ws_paired.py /tmp/before,. --batches 400 --repeat 3
"""
from __future__ import annotations

import argparse
import asyncio
import json
import multiprocessing as mp
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
WARM_UP = 50            # batches before the measurement starts


def cpu_seconds(pid: int, thread: int | None = None) -> float:
    path = f"/proc/{pid}/task/{thread}/stat" if thread else f"/proc/{pid}/stat"
    with open(path) as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def subscribers(urls: list[str], n: int, batches: int, ready, done) -> None:
    """``n`` subscribers per URL; ``done.put((server, events))`` when all ``n`` of a server
    have received its first ``events`` events."""
    from orjson import loads
    from websockets.asyncio.client import connect

    connected = [0]

    async def group(index: int, url: str) -> None:
        target = [10]
        reached = [0]

        async def one() -> None:
            got = 0
            async with connect(url, max_size=None) as ws:
                await ws.send(json.dumps({"op": "subscribe", "pattern": "e(I)^T",
                                          "since": 0.5, "batch": 256}))
                await ws.recv()
                connected[0] += 1
                if connected[0] == n * len(urls):
                    ready.set()
                while got < batches * 10:
                    msg = loads(await ws.recv(decode=False))
                    if msg["type"] == "answers":
                        got += len(msg["answers"])
                    elif msg["type"] == "answer":
                        got += 1
                    else:
                        raise RuntimeError(f"unexpected message {msg}")
                    if got >= target[0]:
                        reached[0] += 1
                        if reached[0] == n:
                            reached[0] = 0
                            done.put((index, target[0]))
                            target[0] += 10
        await asyncio.gather(*[one() for _ in range(n)])

    async def main() -> None:
        await asyncio.gather(*[group(i, url) for i, url in enumerate(urls)])
    asyncio.run(main())


def run(codes: list[str], n: int, batches: int) -> list[tuple[float, float]]:
    """(loop thread, process) µs of CPU per frame of each checkout's server."""
    import slr_sql

    procs: list[subprocess.Popen] = []
    clients = []
    urls = []
    sub_proc = None
    try:
        for code in codes:
            tmp = Path(tempfile.mkdtemp())
            # cwd: `python -m` puts the working directory first on sys.path, ahead of PYTHONPATH
            proc = subprocess.Popen([sys.executable, "-m", "slr_sql", "serve",
                                     str(tmp / "ws.db"), "--port", "0"],
                                    stdout=subprocess.PIPE, stderr=open(tmp / "server.log", "wb"),
                                    env=dict(os.environ, PYTHONPATH=str(Path(code).resolve())),
                                    cwd=tmp)
            procs.append(proc)
            url = proc.stdout.readline().decode().strip().rsplit(" on ", 1)[1]
            urls.append(url.replace("http", "ws") + "/subscribe")
            client = slr_sql.connect(url)
            client.add("e(-1)^0")
            clients.append(client)
        ctx = mp.get_context("spawn")
        ready, done = ctx.Event(), ctx.Queue()
        sub_proc = ctx.Process(target=subscribers, args=(urls, n, batches, ready, done))
        sub_proc.start()
        if not ready.wait(120):
            raise RuntimeError("the subscribers did not connect")
        start: list[tuple[float, float]] = []
        for b in range(batches):
            if b == WARM_UP:
                start = [(cpu_seconds(p.pid, p.pid), cpu_seconds(p.pid)) for p in procs]
            events = [f"e({j})^{j + 1}" for j in range(b * 10, b * 10 + 10)]
            order = range(len(procs)) if b % 2 == 0 else reversed(range(len(procs)))
            for i in order:               # (each first as often as last)
                clients[i].add_many(events)
                if done.get(timeout=60) != (i, (b + 1) * 10):
                    raise RuntimeError("a subscriber missed events")
        end = [(cpu_seconds(p.pid, p.pid), cpu_seconds(p.pid)) for p in procs]
        frames = (batches - WARM_UP) * n
        return [((e[0] - s[0]) / frames * 1e6, (e[1] - s[1]) / frames * 1e6)
                for s, e in zip(start, end)]
    finally:
        if sub_proc is not None:
            sub_proc.join(30)
            if sub_proc.is_alive():
                sub_proc.terminate()
        for client in clients:
            client.close()
        for proc in procs:
            proc.terminate()
            proc.wait(30)
            proc.stdout.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("codes", help="checkouts, comma-separated (each a folder holding slr_sql "
                                  "and its _slr_sql_speedups module)")
    ap.add_argument("--subscribers", type=int, default=100, help="per server")
    ap.add_argument("--batches", type=int, default=400)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    codes = args.codes.split(",")
    print("load average at start: %.2f %.2f %.2f" % os.getloadavg())
    for r in range(args.repeat):
        figures = run(codes, args.subscribers, args.batches)
        for code, (loop_us, process_us) in zip(codes, figures):
            print(f"run {r + 1}: {code}: loop thread {loop_us:.1f} µs per frame, process "
                  f"{process_us:.1f} µs per frame", flush=True)
        if len(codes) > 1:
            print(f"run {r + 1}: loop thread ratio {figures[-1][0] / figures[0][0]:.2f}, "
                  f"process ratio {figures[-1][1] / figures[0][1]:.2f} (last over first)")
    print("load average at end: %.2f %.2f %.2f" % os.getloadavg())


if __name__ == "__main__":
    main()
