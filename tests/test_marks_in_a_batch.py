"""A completeness mark added in a batch (``fullyUpdated(p/N)^t`` among the events of one
``add_many``) is stored in the transaction of the batch's events: a write of the mark that
is busy leaves neither stored, so the add is retryable as a whole (retried, it stores each
event once); a mark stored with them is seen by another process.

On PostgreSQL the meta table alone is held, so only a mark written apart from the events
could fail after them: that half fails without the change. On SQLite the holder blocks the
whole file, so that half checks the same outcome without telling the two designs apart.
"""
from __future__ import annotations

import pytest

import slr_sql
from slr_sql import ManualClock
from slr_sql.errors import SLRBusy
from store_holders import meta_held

BATCH = ["a(1)^1", "a(2)^2", "fullyUpdated(a/1)^5"]


def _stored(kb) -> list:
    return sorted((args[0], end) for args, _start, end, _seq in kb.store.scan("a", 1))


@pytest.mark.parametrize("rules", ["", "c(X) <- a(X) seq b(X)."])
def test_a_batch_whose_mark_is_busy_stores_nothing_and_its_retry_stores_once(backend, rules):
    with slr_sql.open(backend, clock=ManualClock(0.0), busy_timeout=0.3) as kb:
        kb.load(f":- max_delay(a/1, 100). :- max_delay(b/1, 100).\n{rules}\n")
        kb.add("b(0)^0.5")
        with meta_held(backend), pytest.raises(SLRBusy):
            kb.add_many(BATCH)
        assert _stored(kb) == []
        assert kb.complete_until("a/1") < 5.0
        kb.add_many(BATCH)
        assert _stored(kb) == [(1, 1.0), (2, 2.0)]
        with slr_sql.open(backend, clock=ManualClock(0.0)) as other:
            assert other.complete_until("a/1") == 5.0
