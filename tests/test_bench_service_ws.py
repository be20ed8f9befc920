"""benchmarks/bench_service_ws.py's subscribers: the run's checks (every subscriber receives
every event, once, in order) must hold with either WebSocket client, the ``websockets``
library's and the minimal one of ``--client raw``, against a real ``slr serve``. The
figures themselves are the benchmark's business (benchmarks/README.md)."""
from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
SCRIPT = REPO / "benchmarks" / "bench_service_ws.py"
FLOOR = ["--floor-server", "--floor-work-us", "20", "--floor-work-thread"]


@pytest.mark.parametrize("client,server", [("raw", "slr"), ("websockets", "slr"),
                                           ("raw", "floor")])
def test_every_subscriber_gets_every_event_in_order(client, server, tmp_path):
    """Against ``slr serve``, and against the floor server (benchmarks/floor_ws_server.py)
    that speaks the same protocol with no store behind it."""
    run = subprocess.run(
        [sys.executable, str(SCRIPT), "--subscribers", "3", "--minutes", "0.02",
         "--latency-seconds", "0.5", "--sample-seconds", "0.5", "--no-in-process",
         "--client", client] + FLOOR * (server == "floor"),
        capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    found = re.search(r"service    : 3 WebSocket subscribers, (\d+) events .*: (\d+) complete "
                      r"\(min count (\d+), out of order (\d+)\); latency over the first 0.5 s "
                      r"\((\d+) deliveries\)", run.stdout)
    assert found, run.stdout
    sent, complete, min_count, out_of_order, deliveries = map(int, found.groups())
    assert sent >= 1000 and complete == 3 and min_count == sent and out_of_order == 0
    assert deliveries > 0          # the clock of each frame was read
    assert re.search(r"the subscribers' process \d+ µs per event", run.stdout)


def _bench_module():
    spec = importlib.util.spec_from_file_location("bench_service_ws", SCRIPT)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_a_subscriber_that_began_recording_late_is_compared_with_its_own_events():
    """The latency window opens while frames may already arrive: a subscriber whose first
    recorded frame held events 10-19 is compared with when *those* were answered, not with
    events 0-9's answer (which made every one of its latencies a batch period too long); and
    a frame after a lost one is booked as the events it holds."""
    bench = _bench_module()
    answered = [float(i // 10) for i in range(30)]          # batch b answered at b seconds
    requested = [a - 0.5 for a in answered]
    frames = [(list(range(b * 10, b * 10 + 10)), b + 0.001) for b in range(3)]  # 1 ms late
    lat, from_request, firsts, spreads = bench.delivery_latencies(
        [frames, frames[1:], [frames[0], frames[2]]], answered, requested)
    assert max(lat) == pytest.approx(0.001) and len(lat) == 70
    assert max(from_request) == pytest.approx(0.501)
    assert len(firsts) == 10 and max(spreads) == 0.0    # events 20-29: all three have them


def test_bench_ws_frame_path_runs_both_deliveries_to_the_end():
    """bench_ws_frame_path.py: the fan-out (this checkout) against the coroutines (the same
    checkout as --code), every subscriber complete in both (the script asserts it)."""
    out = subprocess.run([sys.executable, str(REPO / "benchmarks" / "bench_ws_frame_path.py"),
                          "--subscribers", "4", "--batches", "20", "--repeat", "1",
                          "--code", str(REPO)],
                         capture_output=True, text=True, timeout=300, cwd=REPO)
    assert out.returncode == 0, out.stderr
    assert "this checkout (fanout): loop thread CPU" in out.stdout
    assert "(coroutines):" in out.stdout and "ratio of the bests" in out.stdout
