"""benchmarks/bench_startup.py runs against this checkout and prints its two ratios."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_the_startup_benchmark_prints_both_ratios():
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_startup.py"),
                           "--opens", "3", "--spawns", "1"],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    line = re.search(r"open +([\d.]+) ms CPU \(raw schema +([\d.]+) ms: +([\d.]+)x\) +"
                     r"command +(\d+) ms CPU \(raw +(\d+) ms: +([\d.]+)x\)", done.stdout)
    assert line, done.stdout
    ours_open, raw_open, _, ours_cmd, raw_cmd, _ = map(float, line.groups())
    assert min(ours_open, raw_open, ours_cmd, raw_cmd) > 0   # figures, not a time limit
