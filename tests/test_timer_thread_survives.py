"""Review of the wall clock's timer thread (slr_sql.sync): whatever a round it starts meets,
the thread goes on serving every later timer (it has no caller to raise to)."""
from __future__ import annotations

import logging
import threading

import slr_sql
from slr_sql import WallClock

DEADLINE = 10.0   # seconds a wait may take before the test fails
PROGRAM = (":- consumption(recent).\n:- max_delay(a/1, 1).\n:- max_delay(b/1, 1).\n"
           "c(X) <- a(X) seq b(X).\n")


def test_a_listener_failing_on_the_timer_thread_does_not_end_the_timers(tmp_path, caplog):
    """Decisions wait for the clock (a and b complete 1 s after their times, so not in the
    add's own round): the timer thread makes them and calls the add listeners. One that
    raises there (a user's bug) is logged; the next pair is still decided by the timer, no
    other add needed."""
    derived: list[tuple[str, threading.Event]] = []
    events = [threading.Event(), threading.Event()]

    def listener(batch):
        if any(e[0] == "c" for e in batch):
            derived.append((threading.current_thread().name, events[len(derived)]))
            derived[-1][1].set()
            if len(derived) == 1 and derived[0][0] == "slr-sync-timer":
                raise ValueError("a listener's bug")

    with slr_sql.open(tmp_path / "s.db") as kb, caplog.at_level(logging.WARNING):
        kb.load(PROGRAM)
        kb.add_listeners.append(listener)
        t = WallClock().now()
        kb.add_many([f"a(1)^{t - 0.5}", f"b(1)^{t}"])
        assert events[0].wait(DEADLINE)
        assert derived[0][0] == "slr-sync-timer"
        t = WallClock().now()
        kb.add_many([f"a(2)^{t - 0.5}", f"b(2)^{t}"])
        assert events[1].wait(DEADLINE), "the timer thread ended with the listener's error"
        assert derived[1][0] == "slr-sync-timer"
        assert sorted(r["X"] for r in kb.query("c(X)^[_, _]")) == [1, 2]
    assert any("a listener's bug" in r.getMessage() and r.exc_info is None
               for r in caplog.records)
