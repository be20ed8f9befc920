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


def test_the_cli_startup_benchmark_prints_every_command_and_the_import():
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_cli_startup.py"),
                           "--runs", "1"], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    for command in ("--help", "query rule", "sql plain", "stats plain"):
        assert re.search(rf"^{re.escape(command)} +\| +\d+ \| +\d+$", done.stdout, re.M), \
            done.stdout
    assert re.search(r"import slr_sql.cli \(.*\): [\d.]+ ms .* \d+ modules added", done.stdout)
