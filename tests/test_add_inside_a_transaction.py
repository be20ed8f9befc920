"""Adds, marks and clock moves inside ``with kb.store.transaction():`` keep the written lock
order (slr_sql/lockorder.py, docs/architecture.md): stages 1-2 of the event pipeline run in
the caller's transaction (a savepoint per batch), stages 3-6 once it committed. Checked in
debug mode, where a lock taken out of order raises before it could wait, on one thread and
with a second thread adding, marking and moving the clock at the same time."""
from __future__ import annotations

import threading

import pytest

import slr_sql
from slr_sql import EventRejected, ManualClock
from slr_sql.lockorder import clear_violations, violations

RULE = ":- consumption(recent).\n:- max_delay(a/1, 0).\n:- max_delay(b/1, 0).\n" \
       "c(X) <- a(X) seq b(X) cnot e(X).\n:- max_delay(e/1, 1000).\n"
DEADLINE = 60.0


@pytest.fixture
def debug_locks(monkeypatch):
    """Debug mode for the locks made during the test (they read it when made)."""
    monkeypatch.setenv("SLR_DEBUG_LOCKS", "1")
    clear_violations()
    yield
    assert violations() == []
    clear_violations()


def _c(kb) -> list:
    return sorted((a["X"], a["S"], a["E"]) for a in kb.query("c(X)^[S, E]"))


def test_adds_and_a_mark_inside_a_transaction_are_observed_once_it_committed(
        debug_locks, backend):
    with slr_sql.open(backend, clock=ManualClock(10.0)) as kb, \
            slr_sql.open(backend, clock=ManualClock(10.0)) as other:
        kb.load(RULE)
        heard: list = []
        kb.add_listeners.append(lambda batch: heard.append(sorted(e[0] for e in batch)))
        with kb.store.transaction():
            assert kb.add_many(["a(1)^1", "b(1)^2"]) == []
            assert kb.add_many(["a(2)^3", "b(2)^4"]) == []
            kb.mark_complete("e/1", 5)
            assert heard == []                      # (nothing committed yet)
            assert other.store.count("a", 1) == 0
            assert kb.event_rules()[0]["pending"] == 2
        assert heard == [["a", "b"], ["a", "b"], ["c", "c"]]
        assert _c(kb) == _c(other) == [(1, 1.0, 2.0), (2, 3.0, 4.0)]
        assert kb.event_rules()[0]["pending"] == 0


def test_a_transaction_rolled_back_leaves_nothing_to_observe(debug_locks, backend):
    with slr_sql.open(backend, clock=ManualClock(10.0)) as kb:
        kb.load(RULE)
        heard: list = []
        kb.add_listeners.append(heard.append)
        with pytest.raises(KeyError):
            with kb.store.transaction():
                kb.add_many(["a(1)^1", "b(1)^2"])
                kb.mark_complete("e/1", 5)
                raise KeyError("undo")
        assert heard == [] and kb.store.count("a", 1) == 0
        assert kb.complete_until("e/1") < 5
        # a batch that fails inside is taken back alone: the transaction goes on
        with kb.store.transaction():
            kb.add_many(["a(1)^1"])
            with pytest.raises(EventRejected):
                kb.add_many(["b(1)^2", "b(2)^[5, 3]"], atomic=True)   # (ends before it starts)
        assert kb.store.count("a", 1) == 1
        assert len(heard) == 1


def test_two_threads_one_adding_inside_transactions_keep_the_lock_order(debug_locks,
                                                                         backend):
    clock = ManualClock(10.0)
    with slr_sql.open(backend, clock=clock) as kb:
        kb.load(RULE)
        errors: list = []
        start = threading.Barrier(2)

        def grouped():
            try:
                start.wait(DEADLINE)
                for i in range(20):
                    with kb.store.transaction():
                        kb.add_many([f"a({i})^{i + 0.1}", f"b({i})^{i + 0.2}"])
                        kb.mark_complete("e/1", i + 0.3)
            except Exception as exc:  # noqa: BLE001 - reported by the assertion below
                errors.append(exc)

        def alone():
            try:
                start.wait(DEADLINE)
                for i in range(20):
                    kb.add_many([f"a({100 + i})^{i + 0.1}", f"b({100 + i})^{i + 0.2}"])
                    kb.mark_complete("e/1", i + 0.3)
                    clock.advance(0.5)
            except Exception as exc:  # noqa: BLE001 - reported by the assertion below
                errors.append(exc)
        threads = [threading.Thread(target=grouped), threading.Thread(target=alone)]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join(DEADLINE)
        assert not any(thread.is_alive() for thread in threads), "a deadlock"
        assert errors == []
        kb.mark_complete("e/1", 100)
        assert {x for x, _s, _e in _c(kb)} == set(range(20)) | set(range(100, 120))
        assert kb.event_rules()[0]["pending"] == 0
