"""A completeness mark whose write was busy: retryable, and stored when retried.

``kb.mark_complete`` stores the mark (``slr_meta``) for the other processes, whose
decisions wait for it; another connection holding the store makes that write SLRBusy. The
same call once the store is free must store it -- the failed one must not leave the mark in
this process's memory only, where the retry took it as already made and stored nothing.
"""
from __future__ import annotations

import pytest

import slr_sql
from slr_sql import ManualClock
from slr_sql.errors import SLRBusy
from store_holders import meta_held


def test_a_busy_mark_is_stored_when_retried(backend):
    with slr_sql.open(backend, clock=ManualClock(0.0), busy_timeout=0.3) as kb:
        kb.load(":- consumption(recent).\nc(X) <- a(X) seq b(X).\n")
        kb.add_many(["a(1)^1", "b(1)^2"])
        with meta_held(backend), pytest.raises(SLRBusy):
            kb.mark_complete("a/1", 10)
        kb.mark_complete("a/1", 10)
        with slr_sql.open(backend, clock=ManualClock(0.0)) as other:
            assert other.complete_until("a/1") == 10.0
