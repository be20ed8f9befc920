"""Stages 3-6 of the adds, marks and clock moves made inside ``kb.store.transaction()`` run
once it committed (EventStore.after_commit): one of them that raises (a listener's error)
does not keep the others from running -- the later adds are still heard, decided and
released -- and the first error is raised once all ran."""
from __future__ import annotations

import pytest

import slr_sql
from slr_sql import ManualClock

RULE = ":- max_delay(a/1, 0).\n:- max_delay(b/1, 0).\n:- max_delay(e/1, 1000).\n" \
       "c(X) <- a(X) seq b(X).\n"


def test_a_callback_that_raises_does_not_keep_the_later_ones_from_running(backend):
    with slr_sql.open(backend, clock=ManualClock(10.0)) as kb:
        kb.load(RULE)
        heard: list = []

        def listener(batch) -> None:
            heard.append(sorted(e[0] for e in batch))
            if len(heard) == 1:
                raise RuntimeError("the first listener call fails")
        kb.add_listeners.append(listener)
        waiting = kb.submit("findall(X, e(X)^_, L)", at=5)
        with pytest.raises(Exception, match="the first listener call fails"):
            with kb.store.transaction():
                kb.add_many(["a(1)^1"])
                kb.add_many(["b(1)^2"])
                kb.add_many(["a(2)^3", "b(2)^4", "e(7)^1"])
                kb.mark_complete("e/1", 5)
        assert heard == [["a"], ["b", "c"], ["a", "b", "c", "e"]]
        assert kb.complete_until("e/1") == 5
        assert waiting.result(timeout=30) == [{"L": [7]}]
        assert kb.store.count("b", 1) == 2


CNOT = ":- consumption(recent).\n:- max_delay(a/1, 0).\n:- max_delay(b/1, 0).\n" \
       "c(X) <- a(X) seq b(X) cnot e(X).\n:- max_delay(e/1, 1000).\n"


def test_a_clock_move_inside_a_transaction_that_rolls_back_still_decides(backend):
    # a rollback takes back the transaction's writes, not the clock's move
    clock = ManualClock(10.0)
    with slr_sql.open(backend, clock=clock) as kb:
        kb.load(CNOT)
        kb.add_many(["a(1)^1", "b(1)^2"])
        assert kb.event_rules()[0]["pending"] == 1
        with pytest.raises(KeyError):
            with kb.store.transaction():
                with kb.store.transaction():
                    clock.set(2000.0)
                raise KeyError("undo")
        assert kb.event_rules()[0]["pending"] == 0
        assert [a["X"] for a in kb.query("c(X)^[S, E]")] == [1]


def test_an_add_in_a_nested_part_is_heard_though_a_later_nested_part_rolled_back(backend):
    """A nested transaction that committed into its enclosing one hands its callbacks to
    it: a later nested part that rolls back takes back its own only, and the add made in
    the first is heard, released and waited for once the whole committed."""
    with slr_sql.open(backend, clock=ManualClock(10.0)) as kb:
        kb.load(RULE)
        heard: list = []
        kb.add_listeners.append(lambda batch: heard.append(sorted(e[0] for e in batch)))
        waiting = kb.submit("findall(X, e(X)^_, L)", at=5)
        with kb.store.transaction():
            with kb.store.transaction():
                kb.add_many(["a(1)^1", "b(1)^2", "e(7)^1"])
                kb.mark_complete("e/1", 5)
            with pytest.raises(ValueError):
                with kb.store.transaction():
                    kb.add_many(["a(9)^3"])
                    raise ValueError("this part only")
        assert heard == [["a", "b", "c", "e"]]
        assert kb.complete_until("e/1") == 5
        assert waiting.result(timeout=30) == [{"L": [7]}]
        assert kb.store.count("a", 1) == 1
