"""A batch rolled back after its rule round leaves no trace in what completeness reads.

The rule round of an add runs inside the add's transaction, after its events went in: a
first read there of an in-order type's newest end (the synchronizer remembers it) sees the
batch's own events. A batch that then rolls back -- its completeness mark refused busy (the
marks are stored in the same transaction), or an atomic batch cut into rounds whose later
round has a bad event -- must take the newest end remembered from inside it along. Kept, it
calls the in-order type complete up to an end no stored event has, and a terminator is
decided before the partner that belongs to it arrives.
"""
from __future__ import annotations

import psycopg
import pytest

import slr_sql
from slr_sql import SLRError
from slr_sql import ManualClock
from slr_sql.errors import SLRBusy

PROGRAM = (":- consumption(recent).\n:- in_order(a/1).\n:- max_delay(a/1, 1000).\n"
           ":- max_delay(b/1, 0).\n"
           "c(X) <- a(X) seq b(X).\n")
REFUSED = ["a(9)^10", "fullyUpdated(b/1)^1"]     # the mark's write is refused busy
AFTER = [["a(1)^1", "b(1)^5"], ["a(1)^3"]]      # then b(1)^5 waits for a up to 5


def _answers(kb) -> list:
    for batch in AFTER:
        kb.add_many(batch)
    kb.mark_complete("a/1", 5)
    return sorted((r["X"], r["S"], r["E"]) for r in kb.query("c(X)^[S, E]"))


def test_a_batch_refused_busy_leaves_the_answers_as_if_it_never_came(postgres_url, tmp_path):
    with slr_sql.open(tmp_path / "clean.db", clock=ManualClock(100.0)) as clean:
        clean.load(PROGRAM)
        expected = _answers(clean)
    assert expected == [(1, 3.0, 5.0)]   # the most recent a(1) before b(1)^5
    with slr_sql.open(postgres_url, clock=ManualClock(100.0), busy_timeout=0.3) as kb:
        kb.load(PROGRAM)
        with psycopg.connect(postgres_url) as other:
            other.execute("LOCK TABLE slr.slr_meta IN SHARE MODE")
            with pytest.raises(SLRBusy):
                kb.add_many(REFUSED)
            other.rollback()
        assert kb.store.count("a", 1) == 0
        assert _answers(kb) == expected


def test_an_atomic_batch_refused_in_a_later_round_leaves_the_answers_as_if_it_never_came(
        tmp_path):
    program = PROGRAM + "cBuffer(a(_), 10).\n"   # (a batch is cut before each a)
    with slr_sql.open(tmp_path / "clean.db", clock=ManualClock(100.0)) as clean:
        clean.load(program)
        expected = _answers(clean)
    with slr_sql.open(tmp_path / "kb.db", clock=ManualClock(100.0)) as kb:
        kb.load(program)
        with pytest.raises(SLRError):   # (the second a ends before it starts)
            kb.add_many([("a", (9,), 10.0, 10.0), ("a", (1,), 12.0, 11.0)], atomic=True)
        assert kb.store.count("a", 1) == 0
        assert _answers(kb) == expected
