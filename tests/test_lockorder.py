"""The lock order (slr_sql/lockorder.py, docs/architecture.md): in debug mode every lock of a
knowledge base checks it; a representative workload keeps it, an acquisition out of order
is caught before it can wait."""
from __future__ import annotations

import inspect
import re
import threading
from contextlib import nullcontext
from pathlib import Path

import pytest

import slr_sql
from slr_sql import ManualClock
from slr_sql.lockorder import (LOCK_ORDER, LockOrderViolation, OrderedLock, clear_violations,
                               observed_nesting, ordered_lock, violations)

import test_add_joins_the_round
import test_after_commit_stages
import test_close_during_add


@pytest.fixture
def debug_locks(monkeypatch):
    """Debug mode for the locks made during the test (they read it when made)."""
    monkeypatch.setenv("SLR_DEBUG_LOCKS", "1")
    clear_violations()
    yield
    clear_violations()


def _rank(kind: str) -> int:
    return LOCK_ORDER.index(kind)


def test_an_acquisition_out_of_order_is_caught_before_it_waits(debug_locks):
    store, sync = ordered_lock("store", reentrant=True), ordered_lock("sync", reentrant=True)
    with sync, store, store:      # in order, and the store's lock taken again
        pass
    with store:
        with pytest.raises(LockOrderViolation, match="took a sync lock while holding a "
                                                      "store lock"):
            sync.acquire()
        assert sync.acquire(blocking=False)   # a try-lock never waits: not checked
        sync.release()
    assert violations() == [f"{threading.current_thread().name}: took a sync lock while "
                            f"holding a store lock (the order is {', '.join(LOCK_ORDER)})"]
    taken = []    # the failed acquisition left the lock free for another thread
    worker = threading.Thread(target=lambda: taken.append(sync.acquire(timeout=5)))
    worker.start()
    worker.join()
    assert taken == [True]


def test_a_violation_on_a_thread_nobody_joins_is_recorded(debug_locks):
    hub, store = ordered_lock("subscriptions.hub"), ordered_lock("store", reentrant=True)

    def wrong_way():
        with hub:
            try:
                store.acquire()
            except LockOrderViolation:
                pass

    thread = threading.Thread(target=wrong_way, name="delivery")
    thread.start()
    thread.join()
    assert len(violations()) == 1
    assert violations()[0].startswith("delivery: took a store lock while holding a "
                                      "subscriptions.hub lock")


def test_a_lock_that_is_not_reentrant_taken_twice_is_caught(debug_locks):
    lock = ordered_lock("subscription")
    with lock:
        with pytest.raises(LockOrderViolation, match="already holds"):
            lock.acquire()


def test_conditions_wait_on_ordered_locks(debug_locks):
    lock = OrderedLock("sync", reentrant=True)
    cond = threading.Condition(lock)
    ready = []

    def notify():
        with cond:
            ready.append(True)
            cond.notify_all()

    with lock, cond:              # held twice: wait lets go of both and takes both back
        threading.Thread(target=notify).start()
        assert cond.wait_for(lambda: ready, timeout=10)
        assert lock.held_by_me()
    assert not lock.held_by_me()
    assert violations() == []


def test_without_debug_mode_the_locks_are_plain(monkeypatch):
    monkeypatch.setenv("SLR_DEBUG_LOCKS", "0")
    with slr_sql.open() as kb:
        assert type(kb.store.lock) is type(threading.RLock())
    with pytest.raises(ValueError, match="add it to LOCK_ORDER"):
        ordered_lock("somewhere")


def test_a_representative_workload_keeps_the_order(debug_locks, tmp_path):
    """Event rules deciding on marks and the clock, buffers, a synchronized query, a
    subscription delivering through its callback, frames, concurrent writers and a second
    knowledge base on the file: no lock is ever taken out of order."""
    clock = ManualClock(0.0)
    path = tmp_path / "kb.db"
    kb = slr_sql.open(path, clock=clock)
    try:
        assert isinstance(kb.store.lock, OrderedLock)   # debug mode is on
        kb.load("""
            :- max_delay(c/1, 1).
            pair(X) <- a(X) seq b(X).
            quiet(X) <- (a(X) seq b(X)) cnot c(X).
            cBuffer(a(_), 50).
            tBuffer(b(_), 100).
            near(X) :- pair(X)^[_, _].
        """)
        got: list = []
        sub = kb.subscribe("pair(X)^[S, E]", since=0, callback=got.append)
        waiting = kb.submit("findall(X, pair(X)^[_, _], L)", at=30)
        buffer_id = kb.add_buffer("c(_)", keep_last=10)
        kb.add("c(3)^3.2")                   # inside a(3) seq b(3): no quiet(3)

        def writer(k: int) -> None:
            for i in range(10):
                n = 10 * k + i
                kb.add_many([f"a({n})^{n}", f"b({n})^{n + 0.5}"])

        threads = [threading.Thread(target=writer, args=(k,)) for k in range(3)]
        for thread in threads:
            thread.start()
        for t in (5.0, 10.0, 20.0):          # the clock moves while they write
            clock.set(t)
        for thread in threads:
            thread.join()
        kb.add_many(["fullyUpdated(a/1)^40", "fullyUpdated(b/1)^40"])
        kb.mark_complete("c/1", 40)
        clock.set(50.0)
        assert waiting.result(timeout=30) == [{"L": list(range(30))}]
        assert sorted(a["X"] for a in kb.query("quiet(X)^[_, _]")) == \
            [n for n in range(30) if n != 3]
        assert len(kb.query("near(X)")) == 30
        kb.add("tf(map, base, pose([1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]))^1")
        assert kb.query("tf_lookup(map, base, 1, pose(P, _))") == [{"P": [1.0, 0.0, 0.0]}]
        kb._subscriptions.drain(timeout=30)
        assert sorted(a["X"] for a in got) == list(range(30))   # (before 60)
        kb.add_many(["a(60)^60", "b(60)^61"])           # quiet(60): a decision pending
        with slr_sql.open(path, clock=clock) as other:   # rules restored, timers asked for
            other.add("a(99)^45")
            assert other.query("pair(X)^[_, _]", args={"X": 99}) == []
            clock.set(70.0)
            assert other.query("quiet(60)^[S, E]") == [{"S": 60.0, "E": 61.0}]
        kb.remove_buffer(buffer_id)
        kb.unload("main")
        sub.close()
    finally:
        kb.close()
    assert violations() == []
    seen = observed_nesting()
    assert {("sync", "store"), ("store", "buffers"), ("kb.load", "store")} <= seen
    assert all(_rank(held) < _rank(taken) for held, taken in seen)


@pytest.mark.parametrize("callback", [False, True], ids=["pulled", "callback"])
def test_a_close_with_a_subscription_waiting_for_its_until_keeps_the_order(
        debug_locks, tmp_path, callback):
    # the close records every position in one transaction (the store's lock); a subscription
    # still waiting for its history to be complete up to `until` had its wait cancelled
    # inside it, which takes the synchronizer's lock: the synchronizer's timer thread takes
    # the two the other way round, and the close then deadlocked against it now and again
    clock = ManualClock(0.0)
    kb = slr_sql.open(tmp_path / "kb.db", clock=clock)
    try:
        kb.add_many(["p(1)^1", "p(2)^2"])
        kb.subscribe("p(X)^T", since=0, until=10, id="durable")
        kb.subscribe("p(X)^T", since=0, until=10,
                     **({"callback": lambda answer: None} if callback else {}))
    finally:
        kb.close()
    assert violations() == []


@pytest.mark.parametrize("ending", ["commit", "rollback"])
def test_a_clock_moved_inside_a_transaction_fires_the_timers_once_it_ended(
        debug_locks, tmp_path, ending):
    # the synchronizer's clock listener takes its lock, which comes before the store's (a
    # mark takes the two in that order): inside a transaction it waits for the end
    clock = ManualClock(0.0)
    with slr_sql.open(tmp_path / "kb.db", clock=clock) as kb:
        kb.load(":- max_delay(p/1, 1).")
        kb.add("p(1)^1")
        waiting = kb.submit("findall(X, p(X)^_, L)", at=5)
        with pytest.raises(KeyError) if ending == "rollback" else nullcontext():
            with kb.store.transaction():
                clock.set(10.0)               # p/1 complete up to 9: the query may run
                assert not waiting.done()
                if ending == "rollback":
                    raise KeyError("undo")
        assert waiting.result(timeout=30) == [{"L": [1]}]
    assert violations() == []


def test_a_transform_looked_up_inside_a_transaction_keeps_the_order(debug_locks, tmp_path):
    # the lookup takes the frame tree's lock, and another thread's lookup read the store
    # while holding it: with the store's lock held here, the two waited for each other
    with slr_sql.open(tmp_path / "kb.db", clock=ManualClock(0.0)) as kb:
        kb.add("tf(map, odom, pose([1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]))^1")
        assert kb.query("tf_lookup(map, odom, 1, pose(P, _))") == [{"P": [1.0, 0.0, 0.0]}]
        with kb.store.transaction():
            kb.add("tf(odom, base, pose([0.0, 2.0, 0.0], [0.0, 0.0, 0.0, 1.0]))^1")
            assert kb.query("tf_lookup(map, base, 1, pose(P, _))") == \
                [{"P": [1.0, 2.0, 0.0]}]
    assert violations() == []


# Tests of the suite that make threads meet (transactions, clock moves and adds, a close
# during adds, callbacks of the event pipeline), run again here in debug mode on SQLite
# (the rest of the suite runs without it): a lock taken out of order on any of their
# threads fails them. A few seconds; the whole suite can be run so with SLR_DEBUG_LOCKS=1.
RUN_AGAIN_IN_DEBUG_MODE = [
    (test_after_commit_stages.test_a_callback_that_raises_does_not_keep_the_later_ones_from_running,
     {}),
    (test_after_commit_stages.test_a_clock_move_inside_a_transaction_that_rolls_back_still_decides,
     {}),
    (test_after_commit_stages
     .test_an_add_in_a_nested_part_is_heard_though_a_later_nested_part_rolled_back, {}),
    (test_add_joins_the_round.test_a_failed_add_inside_a_callers_transaction_takes_back_only_itself,
     {}),
    (test_close_during_add.test_an_add_that_raised_stored_nothing_and_one_that_returned_stored_all,
     {"trial": 3}),
    (test_close_during_add.test_an_add_that_raised_stored_nothing_and_one_that_returned_stored_all,
     {"trial": 17}),
]


@pytest.mark.parametrize("test, arguments", RUN_AGAIN_IN_DEBUG_MODE,
                         ids=[f"{test.__module__}.{test.__name__}{arguments or ''}"
                              for test, arguments in RUN_AGAIN_IN_DEBUG_MODE])
def test_the_suites_concurrency_tests_keep_the_order(debug_locks, tmp_path, test, arguments):
    parameters = inspect.signature(test).parameters
    given = {"tmp_path": tmp_path, "backend": str(tmp_path / "robot.db"), **arguments}
    test(**{name: given[name] for name in parameters})
    assert violations() == []


def test_the_order_is_written_in_the_architecture_document():
    text = (Path(__file__).resolve().parent.parent / "docs" / "architecture.md").read_text()
    section = text[text.index("## Locks"):]
    written = re.findall(r"^\d+\. `([a-z.]+)`", section, flags=re.M)
    assert written == list(LOCK_ORDER)
