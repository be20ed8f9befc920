"""The client's CPU per request: ``slr_sql.connect(url).add_many`` of 10 events against one
``slr serve``, against the same request made with the standard library's ``http.client`` on
one kept-alive connection (the baseline: the least a Python caller can spend), and with an
``httpx.Client`` (what the client used before its own connection pool), in the same run, in
alternation, ``--repeat`` times. The figure is the caller's CPU time per call
(``time.process_time``), which the server's work does not enter.

Run by hand::

    python benchmarks/bench_client_requests.py
    python benchmarks/bench_client_requests.py --calls 2000 --repeat 5
"""
from __future__ import annotations

import argparse
import http.client
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from urllib.parse import urlsplit

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import httpx  # noqa: E402

import slr_sql  # noqa: E402
from slr_sql.service.encoding import dumps  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--calls", type=int, default=1000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        server = subprocess.Popen([sys.executable, "-m", "slr_sql", "serve", f"{d}/c.db",
                                   "--port", "0"], stdout=subprocess.PIPE,
                                  stderr=subprocess.DEVNULL, cwd=ROOT)
        try:
            url = server.stdout.readline().decode().strip().rsplit(" on ", 1)[1]
            run(url, args)
        finally:
            server.terminate()
            server.wait(30)


def run(url: str, args: argparse.Namespace) -> None:
    kb = slr_sql.connect(url)
    kb.add("e(-1)^0")
    parts = urlsplit(url)
    raw = http.client.HTTPConnection(parts.hostname, parts.port)
    via_httpx = httpx.Client(base_url=url)
    headers = {"Content-Type": "application/json"}
    start = [0]

    def events() -> list[str]:
        start[0] += 10
        return [f"e({j})^{j + 1}" for j in range(start[0], start[0] + 10)]

    def client_call() -> None:
        kb.add_many(events())

    def raw_call() -> None:
        raw.request("POST", "/add_many", body=dumps({"events": events()}), headers=headers)
        answer = raw.getresponse()
        body = answer.read()
        assert answer.status == 200, body

    def httpx_call() -> None:
        answer = via_httpx.post("/add_many", content=dumps({"events": events()}),
                                headers=headers)
        assert answer.status_code == 200, answer.text

    def cpu_per_call(call) -> float:
        t = time.process_time()
        for _ in range(args.calls):
            call()
        return (time.process_time() - t) / args.calls * 1e6

    for f in (client_call, raw_call, httpx_call):   # warm: connections, imports, caches
        f()
    for r in range(args.repeat):
        client, base, old = cpu_per_call(client_call), cpu_per_call(raw_call), \
            cpu_per_call(httpx_call)
        print(f"run {r + 1}: add_many of 10 events, caller's CPU per call: slr_sql client "
              f"{client:.0f} µs, http.client {base:.0f} µs, httpx {old:.0f} µs; client / "
              f"http.client {client / base:.2f}, httpx / http.client {old / base:.2f}",
              flush=True)
    kb.close()
    via_httpx.close()
    raw.close()


if __name__ == "__main__":
    main()
