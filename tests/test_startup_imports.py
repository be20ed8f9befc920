"""What a process that opens a store and asks one query loads: not asyncio (with ssl, ~40 ms of
CPU of every `slr` command), which only a subscription awaited on an event loop needs."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

PROBE = """
import sys, slr_sql
kb = slr_sql.open(sys.argv[1], clock=slr_sql.ManualClock(0.0))
kb.add("seen(a)^1")
assert kb.query("seen(X)^T") == [{"X": "a", "T": 1.0}]
sub = kb.subscribe("seen(X)^T")       # a subscription read without an event loop
assert sub.get(timeout=5)["X"] == "a"
kb.close()
print(sorted(m for m in ("asyncio", "ssl") if m in sys.modules))
"""


def test_a_store_opened_queried_and_subscribed_without_a_loop_loads_no_asyncio(tmp_path):
    done = subprocess.run([sys.executable, "-c", PROBE, str(tmp_path / "robot.db")],
                          capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]", done.stdout


def test_an_awaited_subscription_still_has_its_loop(tmp_path):
    probe = """
import asyncio, sys, slr_sql
kb = slr_sql.open(sys.argv[1], clock=slr_sql.ManualClock(0.0))
sub = kb.subscribe("seen(X)^T")
kb.add("seen(a)^1")
answers = asyncio.run(asyncio.wait_for(sub.next_answers(10), 30))
print([str(a["X"]) for a in answers])
"""
    done = subprocess.run([sys.executable, "-c", probe, str(tmp_path / "robot.db")],
                          capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "['a']", done.stdout
