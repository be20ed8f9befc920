"""Writer processes started together: each prints ``ready`` once its store is open, then
waits for a line on its standard input; the test tells them all at once."""
from __future__ import annotations

import subprocess


def start_together(procs: list[subprocess.Popen]) -> None:
    """Wait until every one of ``procs`` said ``ready``, then tell each ``go``."""
    for p in procs:
        assert p.stdout.readline().strip() == "ready"
    for p in procs:
        p.stdin.write("go\n")
        p.stdin.flush()
