"""PostgreSQL: a batch with several completeness marks and a mark of another process at once.

A batch's ``fullyUpdated`` marks are written in the transaction of its events, one after the
other; each write that raises a mark also moves the store's progress counter (one row), and
both rows stay locked until the commit. The batch then holds its first mark's row and the
counter while it writes its second mark; another process marking that second type holds
its row and waits for the counter: each waits for the other, the server breaks the
deadlock after a second and one of them fails busy. Writers of marks must take their locks
in one order.

The test holds the batch just before its second mark's write (a trigger waits on an
advisory lock the test holds), lets the other process write that type's mark, then lets
the batch go on.
"""
from __future__ import annotations

import threading
import time

import psycopg

import slr_sql
from slr_sql import ManualClock

DEADLINE = 30.0
HOLD = 7_771_777   # the advisory lock the trigger waits on

TRIGGER = f"""
CREATE FUNCTION slr.hold_second_mark() RETURNS trigger AS $$
BEGIN
    IF NEW.key = 'sync/mark/b/1' AND CAST(NEW.value AS float8) = 5 THEN
        PERFORM pg_advisory_lock({HOLD});
        PERFORM pg_advisory_unlock({HOLD});
    END IF;
    RETURN NEW;
END $$ LANGUAGE plpgsql;
CREATE TRIGGER hold_second_mark BEFORE INSERT ON slr.slr_meta
    FOR EACH ROW EXECUTE FUNCTION slr.hold_second_mark();
"""


def _wait_until_waiting(test: psycopg.Connection, pid: int) -> None:
    """Until backend ``pid`` waits for a lock (deadline-bounded)."""
    deadline = time.monotonic() + DEADLINE
    while test.execute("SELECT wait_event_type FROM pg_stat_activity WHERE pid = %s",
                       (pid,)).fetchone()[0] != "Lock":
        assert time.monotonic() < deadline, f"backend {pid} never waited for a lock"
        time.sleep(0.01)


def _in_thread(call, errors: list) -> threading.Thread:
    def run():
        try:
            call()
        except Exception as exc:   # (reported by the test's assertion)
            errors.append(exc)
    thread = threading.Thread(target=run)
    thread.start()
    return thread


def test_a_batch_of_two_marks_and_another_process_s_mark_both_go_in(postgres_url):
    with slr_sql.open(postgres_url, clock=ManualClock(0.0), busy_timeout=20) as batch, \
            slr_sql.open(postgres_url, clock=ManualClock(0.0), busy_timeout=20) as other, \
            psycopg.connect(postgres_url, autocommit=True) as test:
        batch.add("a(0)^0")   # (the tables exist: nothing else waits)
        test.execute(TRIGGER)
        batch_pid = batch.store.execute("SELECT pg_backend_pid()")[0][0]
        other_pid = other.store.execute("SELECT pg_backend_pid()")[0][0]
        test.execute("SELECT pg_advisory_lock(%s)", (HOLD,))
        errors: list = []
        adding = _in_thread(lambda: batch.add_many(["fullyUpdated(a/1)^5",
                                                    "fullyUpdated(b/1)^5"]), errors)
        _wait_until_waiting(test, batch_pid)            # before its second mark
        marking = _in_thread(lambda: other.mark_complete("b/1", 6), errors)
        _wait_until_waiting(test, other_pid)
        test.execute("SELECT pg_advisory_unlock(%s)", (HOLD,))
        adding.join(DEADLINE)
        marking.join(DEADLINE)
        assert not adding.is_alive() and not marking.is_alive()
        assert errors == []
        with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as reader:
            assert reader.complete_until("a/1") == 5.0
            assert reader.complete_until("b/1") == 6.0
