"""ROS requests benchmark: a query's round trip through ROS topics against the same query
through ``slr_sql.connect`` on loopback, in one run, on one store file.

* **ROS**: a real ``slr ros bridge DB`` process; a client process (tests/ros_request_client.py,
  an rclpy node) publishes ``{"token", "goal", "args"}`` requests on ``/slr/query`` at
  ``--rate`` per second and notes, with its own clock, when the answer carrying each token
  arrives on ``/slr/answer``.
* **HTTP** (the baseline): a real ``slr serve DB --port 0`` process; this process sends the
  same query with ``slr_sql.connect(url).query(goal, args=...)`` at the same rate and times
  each call.

The goal is the robot's point query ``prev(seg(O, L)^Z, T)`` with ``O`` and ``T`` bound
from ``args`` (new values each request), over 10,000 stored events. The two run in
alternating blocks (so both see the same machine load), after a warm-up each; p50 and p99
of the round trips, and their ratio, are printed. ROS discovery stays on loopback
(ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, a random ROS_DOMAIN_ID).

Run by hand::

    python benchmarks/bench_ros_requests.py                  # 1,000 requests each at 100/s
    python benchmarks/bench_ros_requests.py --requests 300 --rate 100
"""
from __future__ import annotations

import argparse
import json
import os
import queue
import random
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import slr_sql  # noqa: E402

CLIENT = ROOT / "tests" / "ros_request_client.py"
GOAL = "prev(seg(O, L)^Z, T)"
OBJECTS = 100
EVENTS = 10_000
BLOCK = 100        # requests per block; HTTP and ROS blocks alternate
WARMUP = 50        # requests each before measuring


class Lines:
    """The stdout lines of a process, read by a thread."""

    def __init__(self, proc: subprocess.Popen):
        self.proc = proc
        self.queue: queue.Queue = queue.Queue()
        threading.Thread(target=self._pump, daemon=True).start()

    def _pump(self) -> None:
        for line in self.proc.stdout:
            self.queue.put(line.rstrip("\n"))

    def get(self, timeout: float) -> str | None:
        try:
            return self.queue.get(timeout=timeout)
        except queue.Empty:
            if self.proc.poll() is not None:
                raise RuntimeError(f"{self.proc.args[:4]} exited {self.proc.returncode}")
            return None

    def wait_for(self, text: str, timeout: float = 60.0) -> str:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            line = self.get(max(0.0, deadline - time.monotonic()))
            if line is not None and text in line:
                return line
        raise RuntimeError(f"no line with {text!r} within {timeout} s")


def make_store(path: Path) -> None:
    rng = random.Random(7)
    with slr_sql.open(path) as kb:
        kb.add_many([("seg", [f"o{i % OBJECTS}", [rng.random(), rng.random(), rng.random()]],
                      i * 0.01, i * 0.01) for i in range(EVENTS)])


def requests(n: int, seed: int) -> list[dict]:
    rng = random.Random(seed)
    return [{"O": f"o{rng.randrange(OBJECTS)}", "T": rng.uniform(1.0, EVENTS * 0.01)}
            for _ in range(n)]


def start(args: list[str], env: dict, stdin: bool = False) -> tuple[subprocess.Popen, Lines]:
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stdin=subprocess.PIPE if stdin
                            else subprocess.DEVNULL, text=True, env=env, cwd=ROOT)
    return proc, Lines(proc)


def paced(n: int, rate: float, call) -> list[float]:
    """Call ``call(i)`` n times at ``rate`` per second; the round trip of each, in s."""
    samples = []
    began = time.perf_counter()
    for i in range(n):
        due = began + i / rate
        while (now := time.perf_counter()) < due:
            time.sleep(min(0.001, due - now))
        t0 = time.perf_counter()
        call(i)
        samples.append(time.perf_counter() - t0)
    return samples


class RosClient:
    def __init__(self, env: dict):
        self.proc, self.lines = start([sys.executable, str(CLIENT)], env, stdin=True)
        self.lines.wait_for('"ready"')
        self.send({"listen": "/slr/answer"})
        self.count = 0

    def send(self, command: dict) -> None:
        self.proc.stdin.write(json.dumps(command) + "\n")
        self.proc.stdin.flush()

    def handshake(self, timeout: float = 60.0) -> None:
        """Ask until the bridge answers: both directions have matched."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            token = f"hello{self.count}"
            self.count += 1
            self.send({"pub": "/slr/query", "type": "String",
                       "data": json.dumps({"token": token, "goal": "true"})})
            retry = time.monotonic() + 0.25
            while time.monotonic() < retry:
                line = self.lines.get(0.05)
                if line is not None and token in line:
                    return
        raise RuntimeError("the bridge never answered")

    def block(self, bindings: list[dict], rate: float) -> list[float]:
        texts = []
        for b in bindings:
            texts.append(json.dumps({"token": f"q{self.count}", "goal": GOAL,
                                     "args": {"O": b["O"], "T": b["T"]}}))
            self.count += 1
        self.send({"rate": "/slr/query", "hz": rate, "texts": texts})
        self.lines.wait_for('"sent"', timeout=len(texts) / rate + 60)
        tokens = [json.loads(t)["token"] for t in texts]
        deadline = time.monotonic() + 30
        while True:
            self.send({"times": True})
            times = json.loads(self.lines.wait_for('"received"'))
            if all(t in times["received"] for t in tokens) or time.monotonic() > deadline:
                break
            time.sleep(0.05)
        missing = [t for t in tokens if t not in times["received"]]
        if missing:
            raise RuntimeError(f"{len(missing)} of {len(tokens)} answers never arrived")
        return [times["received"][t] - times["sent"][t] for t in tokens]


def percentile(samples: list[float], q: float) -> float:
    return statistics.quantiles(samples, n=100, method="inclusive")[q - 1] if q < 100 \
        else max(samples)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--requests", type=int, default=1000, help="requests each (ROS, HTTP)")
    parser.add_argument("--rate", type=float, default=100.0, help="requests per second")
    opts = parser.parse_args()

    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"   # discovery never leaves the machine
    env["ROS_DOMAIN_ID"] = str(random.SystemRandom().randint(1, 200))
    env.pop("ROS_LOCALHOST_ONLY", None)

    with tempfile.TemporaryDirectory() as tmp:
        db = Path(tmp) / "bench.db"
        make_store(db)
        serve, serve_lines = start([sys.executable, "-m", "slr_sql", "serve", str(db),
                                    "--port", "0"], env)
        bridge, bridge_lines = start([sys.executable, "-m", "slr_sql", "ros", "bridge",
                                      str(db)], env)
        client = None
        try:
            url = serve_lines.wait_for("slr serve:").strip().rsplit(" on ", 1)[1]
            bridge_lines.wait_for("bridge ready")
            client = RosClient(env)
            client.handshake()
            http = slr_sql.connect(url)
            expected = http.query(GOAL, args={"O": "o1", "T": 50.0})
            assert expected, "the benchmark query has no answer"

            def http_call(bindings: list[dict]):
                return lambda i: http.query(GOAL, args=bindings[i])

            warm = requests(WARMUP, 1)
            paced(WARMUP, opts.rate, http_call(warm))
            client.block(warm, opts.rate)
            ros_rtt: list[float] = []
            http_rtt: list[float] = []
            for start_at in range(0, opts.requests, BLOCK):
                n = min(BLOCK, opts.requests - start_at)
                bindings = requests(n, 100 + start_at)
                http_rtt += paced(n, opts.rate, http_call(bindings))
                ros_rtt += client.block(bindings, opts.rate)
            http.close()
        finally:
            if client is not None:
                client.send({"exit": True})
                client.proc.wait(timeout=30)
            for proc in (bridge, serve):
                proc.terminate()
                proc.wait(timeout=30)
    load = os.getloadavg()[0]
    print(f"query round trip, {opts.requests} requests each at {opts.rate:g}/s "
          f"(load average {load:.1f}):")
    rows = [("ROS topics (slr ros bridge)", ros_rtt), ("HTTP (slr serve, connect)", http_rtt)]
    for name, samples in rows:
        print(f"  {name:28s} p50 {percentile(samples, 50) * 1e3:7.2f} ms   "
              f"p99 {percentile(samples, 99) * 1e3:7.2f} ms   max {max(samples) * 1e3:7.2f} ms")
    print(f"  ROS / HTTP: p50 {percentile(ros_rtt, 50) / percentile(http_rtt, 50):.2f}x, "
          f"p99 {percentile(ros_rtt, 99) / percentile(http_rtt, 99):.2f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
