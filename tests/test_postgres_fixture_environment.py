"""The suite's PostgreSQL servers start and stop whatever the current test's id: pytest keeps
it in the environment (``PYTEST_CURRENT_TEST``), and a string of a program's environment
longer than 128 KiB fails its start ("Argument list too long"). The session's server is
started in the set-up of the first test that needs it and stopped in the teardown of the
last test of the session, whichever they are."""
from __future__ import annotations

import os

import psycopg

from conftest import start_throwaway_postgres, stop_throwaway_postgres


def test_a_server_starts_and_stops_under_a_test_id_too_long_for_an_environment(
        monkeypatch):
    long_id = "tests/test_x.py::test_y[" + "--\\n" * 50_000 + "] (teardown)"
    monkeypatch.setenv("PYTEST_CURRENT_TEST", long_id)
    server, folder = start_throwaway_postgres("slr-pg-long-id-", tuned=False)
    try:
        with psycopg.connect(server.get_uri(), autocommit=True) as conn:
            assert conn.execute("SELECT 1").fetchone() == (1,)
    finally:
        stop_throwaway_postgres(server, folder)
    assert not os.path.exists(folder)
    assert os.environ["PYTEST_CURRENT_TEST"] == long_id   # pytest's own, left as it was
