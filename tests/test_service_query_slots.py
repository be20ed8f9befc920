"""Queries take one of ``--max-running-queries`` slots; adds never wait for one. More slow
queries than the server has threads leave an add answered at once, and a query that cannot get
a slot within its time is answered 503 (retryable), on a real ``slr serve``."""
from __future__ import annotations

import threading
import time

import httpx
import pytest

from service_helpers import HTTP, ServiceProcess

DEADLINE = 60.0
SPIN = "spin(0). spin(N) :- N > 0, N1 is N - 1, spin(N1)."
ENDLESS = "spin(1000000000)"      # far longer than any test: ends when the server does


def health(url: str) -> dict:
    return HTTP.get(url + "/health", timeout=DEADLINE).json()


def until_queries(url: str, running: int, waiting: int) -> None:
    """Wait (deadline) until the server reports these counts of queries."""
    end = time.monotonic() + DEADLINE
    while True:
        queries = health(url)["queries"]
        if queries == {"running": running, "waiting": waiting, "held": 0, "solutions": 0}:
            return
        assert time.monotonic() < end, f"the server reports {queries}"
        threading.Event().wait(0.01)   # (polling another process: a deadline, not a pause)


def endless_queries(url: str, n: int) -> list[threading.Thread]:
    """``n`` threads each asking for an endless query (answered when the server stops)."""
    def ask() -> None:
        try:
            httpx.post(url + "/query", json={"goal": ENDLESS, "timeout": 600}, timeout=600)
        except httpx.HTTPError:
            pass                       # the server was stopped under it
    threads = [threading.Thread(target=ask, daemon=True) for _ in range(n)]
    for t in threads:
        t.start()
    return threads


@pytest.fixture
def one_slot_server(tmp_path):
    with ServiceProcess(tmp_path / "slots.db", "--max-running-queries", "1",
                        "--max-query-time", "600") as server:
        assert HTTP.post(server.url + "/load", json={"text": SPIN}).status_code == 200
        yield server


def test_an_add_is_answered_while_more_slow_queries_than_threads_run(one_slot_server):
    url = one_slot_server.url
    queries = endless_queries(url, 41)           # the thread pool holds 40
    until_queries(url, running=1, waiting=40)
    r = httpx.post(url + "/add_many", json={"events": ["e(1)^1"]}, timeout=DEADLINE)
    assert r.status_code == 200 and r.json()["accepted"] == 1
    r = httpx.post(url + "/query", json={"goal": "e(X)^T", "timeout": 0.5}, timeout=DEADLINE)
    assert r.status_code == 503                  # (no slot for it)
    assert all(t.is_alive() for t in queries)    # none of them was answered meanwhile
    one_slot_server.kill()
    for t in queries:
        t.join(DEADLINE)


def test_a_query_without_a_slot_within_its_time_is_answered_503_to_retry(one_slot_server):
    url = one_slot_server.url
    endless = endless_queries(url, 1)
    until_queries(url, running=1, waiting=0)
    for path, body in (("/query", {"goal": "spin(3)", "timeout": 0.2}),
                       ("/sql", {"query": "SELECT 1", "timeout": 0.2})):
        r = HTTP.post(url + path, json=body, timeout=DEADLINE)
        assert r.status_code == 503, (path, r.text)
        assert r.json()["error"]["kind"] == "Unavailable"
        assert "max_running_queries" in r.json()["error"]["message"]
        assert int(r.headers["Retry-After"]) >= 1
    assert health(url)["queries"] == {"running": 1, "waiting": 0, "held": 0, "solutions": 0}
    one_slot_server.kill()
    endless[0].join(DEADLINE)


def test_health_reports_the_limit_and_no_query_when_idle(tmp_path):
    with ServiceProcess(tmp_path / "idle.db") as server:
        h = health(server.url)
        assert h["limits"]["max_running_queries"] == 4
        assert h["queries"] == {"running": 0, "waiting": 0, "held": 0, "solutions": 0}
        r = HTTP.post(server.url + "/query", json={"goal": "X = 1"})
        assert r.json()["answers"] == [{"X": 1}]
        assert health(server.url)["queries"] == {"running": 0, "waiting": 0, "held": 0, "solutions": 0}
