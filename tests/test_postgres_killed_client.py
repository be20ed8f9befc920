"""A process killed while its statement runs on a PostgreSQL store (SIGKILL, a crash, the
kill of a timeout): the server ends the statement within about a second
(client_connection_check_interval, slr_sql/store/postgres.py). It ran on to its end before --
an add's event-rule detection holding its writer's locks of the types for as long as the
join took, minutes for one the planner does badly -- since the server only notices a closed
socket when it next sends. Real processes: ``python -m slr_sql`` and the suite's server."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import psycopg
import pytest

REPO = Path(__file__).resolve().parent.parent
DEADLINE = 30.0   # seconds; each wait ends as soon as its condition holds
pytestmark = pytest.mark.skipif(sys.platform != "linux",
                                reason="the server's check of a gone client needs Linux")


def _backends(url: str, text: str) -> list[int]:
    """The server processes of the database running a statement that holds ``text``."""
    with psycopg.connect(url, autocommit=True) as conn:
        return [pid for (pid,) in conn.execute(
            "SELECT pid FROM pg_stat_activity WHERE datname = current_database() "
            "AND state = 'active' AND pid <> pg_backend_pid() AND query LIKE %s",
            (f"%{text}%",))]


def _wait_for(condition, what: str) -> None:
    deadline = time.monotonic() + DEADLINE
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"not within {DEADLINE:g} s: {what}")
        time.sleep(0.05)


@pytest.mark.parametrize("write", [False, True], ids=["read", "write"])
def test_the_statement_of_a_killed_client_ends_with_it(postgres_url, write):
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    assert subprocess.run([sys.executable, "-m", "slr_sql", "add", postgres_url, "p(1)^1"],
                          env=env, capture_output=True, timeout=120).returncode == 0
    marker = f"slr_killed_client_{int(write)}"
    statement = f"SELECT pg_sleep(300) AS {marker}"
    client = subprocess.Popen([sys.executable, "-m", "slr_sql", "sql", postgres_url, statement]
                              + (["--write"] if write else []), env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        _wait_for(lambda: _backends(postgres_url, marker), "the statement runs")
        os.kill(client.pid, signal.SIGKILL)
        client.wait(timeout=DEADLINE)
        # (ran on for its 300 s: the test's deadline is a tenth of that)
        _wait_for(lambda: not _backends(postgres_url, marker),
                  "the server ends the statement of the killed client")
    finally:
        if client.poll() is None:
            client.kill()
            client.wait()
        with psycopg.connect(postgres_url, autocommit=True) as conn:
            for pid in _backends(postgres_url, marker):
                conn.execute("SELECT pg_terminate_backend(%s)", (pid,))
