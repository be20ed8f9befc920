"""benchmarks/bench_service_ws.py's subscribers: the run's checks (every subscriber receives
every event, once, in order) must hold with either WebSocket client, the ``websockets``
library's and the minimal one of ``--client raw``, against a real ``slr serve``. The
figures themselves are the benchmark's business (benchmarks/README.md)."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
SCRIPT = REPO / "benchmarks" / "bench_service_ws.py"


@pytest.mark.parametrize("client", ["raw", "websockets"])
def test_every_subscriber_gets_every_event_in_order(client, tmp_path):
    run = subprocess.run(
        [sys.executable, str(SCRIPT), "--subscribers", "3", "--minutes", "0.02",
         "--latency-seconds", "0.5", "--sample-seconds", "0.5", "--no-in-process",
         "--client", client],
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
