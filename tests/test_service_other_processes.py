"""Several `slr serve` processes on one store (a file, or a PostgreSQL database): what one
writes releases the synchronized queries waiting on another, without a further request to
it. Real processes."""
from __future__ import annotations

import time

from service_helpers import HTTP, ServiceProcess

DEADLINE = 30.0  # seconds; each wait ends as soon as its condition holds


def test_a_mark_written_through_another_server_answers_a_waiting_long_poll(backend, tmp_path):
    """A query submitted to server A waits for p/1 to be complete up to 5; server B, another
    process on the same store, stores the event and the mark. A's long-poll is answered
    within its wait (A saw the other process's commit only at its next store call: the
    long-poll answered 202 until the query's timeout, unless some other request happened
    to reach A)."""
    with ServiceProcess(backend, log=tmp_path / "a.log") as a, \
            ServiceProcess(backend, log=tmp_path / "b.log") as b:
        assert HTTP.post(a.url + "/load", json={"text": ":- max_delay(p/1, 1e10).",
                                                "name": "delays"}, timeout=30).status_code == 200
        submitted = HTTP.post(a.url + "/submit", json={"goal": "p(X)^T", "at": 5},
                              timeout=30).json()
        assert submitted["done"] is False
        assert HTTP.post(b.url + "/add", json={"event": "p(a)^1"}, timeout=30).status_code == 200
        assert HTTP.post(b.url + "/mark_complete", json={"type": "p/1", "time": 6},
                         timeout=30).status_code == 200
        deadline = time.monotonic() + DEADLINE
        while True:   # (one long-poll answers it; a 202 is a poll that ran out first)
            polled = HTTP.get(f"{a.url}/submit/{submitted['handle']}?wait=10", timeout=30)
            if polled.json()["done"] or time.monotonic() > deadline:
                break
        assert polled.status_code == 200, polled.text
        assert polled.json()["answers"] == [{"X": "a", "T": 1.0}]


def test_event_rules_another_server_loaded_are_listed(backend, tmp_path):
    """Server B (another process on the same store) loads an event rule, then unloads it:
    server A's /event_rules lists it, then no longer, as A's /programs does (A listed the
    rules of the program it had read last, until some other request read the store)."""
    with ServiceProcess(backend, log=tmp_path / "a.log") as a, \
            ServiceProcess(backend, log=tmp_path / "b.log") as b:
        def heads() -> list:
            listed = HTTP.get(a.url + "/event_rules", timeout=30)
            assert listed.status_code == 200, listed.text
            return [rule["head"] for rule in listed.json()["event_rules"]]

        assert heads() == []
        loaded = HTTP.post(b.url + "/load", json={"text": "c(X) <- p(X) seq q(X).",
                                                  "name": "rules"}, timeout=30)
        assert loaded.status_code == 200, loaded.text
        assert heads() == ["c/1"]
        assert HTTP.post(b.url + "/unload", json={"name": "rules"}, timeout=30).status_code == 200
        assert heads() == []
