"""PostgreSQL: the SLRBusy of a deadlock or a serialization conflict says what happened.

Both are retryable like a lock wait that ran out, but neither waited out ``busy_timeout``:
the server broke a deadlock (after its ``deadlock_timeout``, a second) or refused a
conflicting change at once. "locked by another writer for more than 20 s" sent a user
looking for a long-running writer that does not exist.
"""
from __future__ import annotations

import psycopg
import pytest

from slr_sql.errors import SLRBusy
from slr_sql.store.postgres import _error


@pytest.mark.parametrize("error, says", [
    (psycopg.errors.DeadlockDetected("deadlock detected"), "waited for each other"),
    (psycopg.errors.SerializationFailure("could not serialize access"), "conflicting change"),
])
def test_a_busy_that_did_not_wait_out_the_timeout_does_not_say_it_did(error, says):
    busy = _error(error, "postgresql://db", busy_timeout=20.0)
    assert isinstance(busy, SLRBusy)
    assert "20 s" not in str(busy) and says in str(busy)


def test_a_lock_wait_that_ran_out_says_how_long_it_waited():
    busy = _error(psycopg.errors.LockNotAvailable("canceling statement due to lock timeout"),
                  "postgresql://db", busy_timeout=20.0)
    assert isinstance(busy, SLRBusy) and "for more than 20 s" in str(busy)
