"""A mark decides the pending decisions another connection stored.

Two knowledge bases on one store (two connections, as two processes): one adds a
terminator that must wait for its partner type's completeness; the other then marks that
type complete. The store is the truth: the mark's process makes the decision, though the
pending row is not its own -- it must not wait until the first one happens to call again.
"""
from __future__ import annotations

import pytest

import slr_sql
from slr_sql import ManualClock


@pytest.mark.parametrize("policy", ["recent", "chronological", "unrestricted"])
def test_a_mark_decides_what_another_connection_left_pending(backend, policy):
    rule = "c(X) <- a(X) seq b(X)" + (" cnot e(X)" if policy == "unrestricted" else "")
    waits_for = "e/1" if policy == "unrestricted" else "a/1"
    with slr_sql.open(backend, clock=ManualClock(0.0)) as marker, \
            slr_sql.open(backend, clock=ManualClock(0.0)) as writer:
        marker.load(f":- consumption({policy}).\n:- max_delay(b/1, 0).\n{rule}.\n")
        marker.mark_complete("b/1", 10)
        assert writer.add_many(["a(1)^1", "b(1)^2", "e(9)^9"]) == []
        assert writer.query("c(X)^[S, E]") == []   # (waits for the mark)
        other = "a/1" if waits_for == "e/1" else "e/1"
        marker.mark_complete(other, 10)
        assert marker.query("c(X)^[S, E]") == []
        marker.mark_complete(waits_for, 10)
        assert marker.query("c(X)^[S, E]") == [{"X": 1, "S": 1.0, "E": 2.0}]
        assert writer.query("c(X)^[S, E]") == [{"X": 1, "S": 1.0, "E": 2.0}]



def test_a_process_that_only_marks_decides_with_rules_loaded_elsewhere(backend):
    """The marking process opened the store before another one loaded the rules and never
    added an event: its marks still run the rules' decisions (it follows the stored
    program, as every call does)."""
    with slr_sql.open(backend, clock=ManualClock(0.0)) as marker, \
            slr_sql.open(backend, clock=ManualClock(0.0)) as writer:
        assert marker.query("c(X)^[S, E]") == []
        writer.load(":- consumption(recent).\nc(X) <- a(X) seq b(X).\n")
        assert writer.add_many(["a(1)^1", "b(1)^2"]) == []
        marker.mark_complete("a/1", 10)
        marker.mark_complete("b/1", 10)
        assert marker.query("c(X)^[S, E]") == [{"X": 1, "S": 1.0, "E": 2.0}]


def test_two_marks_at_once_each_before_the_others_commit_still_decide(backend):
    """Two connections mark the two types a decision waits for at the same time: each read
    the store's marks when its call began, before the other's mark was committed. Whichever
    commits last must see both marks and decide (here the second mark runs its stage
    straight after the first committed, with the view it had before)."""
    with slr_sql.open(backend, clock=ManualClock(0.0)) as first, \
            slr_sql.open(backend, clock=ManualClock(0.0)) as second:
        first.load(":- consumption(recent).\nc(X) <- a(X) seq b(X).\n")
        assert first.add_many(["a(1)^1", "b(1)^2"]) == []
        assert second.query("c(X)^[S, E]") == []    # (its view of the marks: none yet)
        first.mark_complete("a/1", 10)
        # the second call's own start was before that commit: its stage runs as it would
        second._pipeline.mark("b/1", 10)
        assert second.query("c(X)^[S, E]") == [{"X": 1, "S": 1.0, "E": 2.0}]
