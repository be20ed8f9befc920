"""A knowledge base closed while a query evaluates in another thread (a server stopping, a
program ending) ends the query at its next check, in words, instead of letting it run to
its timeout while the closing process waits for the thread."""
from __future__ import annotations

import threading
import time

import pytest

import slr_sql


@pytest.mark.parametrize("goal", ["between(1, inf, X), X < 0", "repeat, fail",
                                  "length(L, N), N < 0"])
def test_a_query_running_when_the_knowledge_base_closes_ends_with_an_slr_error(tmp_path, goal):
    kb = slr_sql.open(tmp_path / "robot.db", clock=slr_sql.ManualClock(10.0))
    running = threading.Event()
    kb.define("running", 0, lambda: running.set() or True)
    outcome: list = []

    def ask() -> None:
        try:
            outcome.append(kb.query(f"running, {goal}", timeout=60))
        except slr_sql.SLRError as exc:
            outcome.append(exc)

    asking = threading.Thread(target=ask)
    asking.start()
    assert running.wait(30), "the query did not start"
    started = time.monotonic()
    kb.close()
    asking.join(30)
    assert not asking.is_alive()
    assert time.monotonic() - started < 10          # its timeout was 60 s
    [ended] = outcome
    assert isinstance(ended, slr_sql.SLRError) and \
        "the knowledge base was closed while the query ran" in str(ended), ended
