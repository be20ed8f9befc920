"""`slr ... | head -1`: the reader of the output leaves after its first line. The next write
of `slr` fails (EPIPE), which was printed as "error: BrokenPipeError: [Errno 32] Broken pipe
(this is a bug in slr_sql; please report it)". Now nothing is said on standard error, and
the exit status is 1, as Python's own recipe and rich's tables (`slr ros info`) have it.
Real `slr` processes whose standard output is a pipe the test closes."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

import slr_sql
from slr_sql import ManualClock

REPO = Path(__file__).resolve().parent.parent
DEADLINE = 60


@pytest.fixture(scope="module")
def many_rows(tmp_path_factory) -> Path:
    """A store whose answers are far more than a pipe holds (64 KiB): the command is still
    writing when the reader leaves."""
    db = tmp_path_factory.mktemp("pipe") / "r.db"
    with slr_sql.open(db, clock=ManualClock(0.0)) as kb:
        kb.add_many([("p", (i, "x" * 100), float(i), float(i)) for i in range(5000)])
    return db


def first_line_then_leave(*args: str) -> tuple[bytes, int, str]:
    """Run `slr ARGS`, read its first line and close the pipe (what `| head -1` does)."""
    proc = subprocess.Popen([sys.executable, "-m", "slr_sql", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, stdin=subprocess.DEVNULL,
                            env={**os.environ, "PYTHONPATH": str(REPO)})
    assert proc.stdout is not None and proc.stderr is not None
    line = proc.stdout.readline()
    proc.stdout.close()
    errors = proc.stderr.read().decode("utf-8", "replace")
    return line, proc.wait(DEADLINE), errors


@pytest.mark.parametrize("args", [
    ["sql", "{db}", "SELECT * FROM p"],
    ["sql", "--json", "{db}", "SELECT * FROM p"],
    ["query", "{db}", "p(X, Y)^T"],
    ["query", "--json", "{db}", "p(X, Y)^T"],
    # (it ended with status 0, as if its --until had been reached)
    ["subscribe", "{db}", "p(X, Y)^T", "--since", "0"],
], ids=lambda args: " ".join(args[:2]))
def test_a_reader_that_leaves_early_is_no_error_of_slr(many_rows, args):
    line, status, errors = first_line_then_leave(*[a.format(db=many_rows) for a in args])
    assert line.strip(), "nothing printed"
    assert status == 1
    assert errors == "", errors       # no "bug", no "Exception ignored", no traceback


def test_a_reader_that_leaves_a_subscription_to_a_server_early_is_no_error_either(tmp_path):
    from service_helpers import ServiceProcess

    db = tmp_path / "served.db"
    with slr_sql.open(db, clock=ManualClock(0.0)) as kb:
        kb.add_many([("p", (i, "x" * 100), float(i), float(i)) for i in range(5000)])
    with ServiceProcess(db) as server:
        line, status, errors = first_line_then_leave("subscribe", server.url, "p(X, Y)^T",
                                                     "--since", "0")
        assert server.healthy()
    assert line.strip(), "nothing printed"
    assert status == 1
    assert errors == "", errors
