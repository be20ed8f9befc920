"""What the store sets for one part of the caller's transaction on PostgreSQL (``SET LOCAL``,
which lasts to the end of the transaction, savepoints released or not) is put back to what
it was before for the rest of it:

* a compiled query with a timeout sets its own ``statement_timeout`` for its statement
  only: the caller's later statements run under the setting they ran under before (an
  administrator's, the session's, or the transaction's own), never with the limit off;
* a nested transaction that does not wait for locks (``wait=False``: ``lock_timeout`` 1 ms)
  leaves the enclosing one's ``lock_timeout`` as it was: 1 ms in one that does not wait
  either, the transaction's own setting, else ``busy_timeout``."""
from __future__ import annotations

import time

import psycopg
import pytest

import slr_sql
from slr_sql import ManualClock, SLRError, SLRTimeout
from slr_sql.planner import plan_for

GOAL = "p(X)^_, X > 1"
SLOW_GOAL = "s(X)^_, s(Y)^_, s(Z)^_, X > Y, Y > Z, Z > X"


def _setting(kb, name: str = "statement_timeout") -> str:
    return kb.store.execute(f"SHOW {name}")[0][0]


def test_a_compiled_query_with_a_deadline_leaves_the_transactions_statement_timeout(
        postgres_url):
    with psycopg.connect(postgres_url, autocommit=True) as admin:
        database = admin.execute("SELECT current_database()").fetchone()[0]
        admin.execute(f'ALTER DATABASE "{database}" SET statement_timeout = 7000')
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as kb:
        kb.add_many(["p(1)^1", "p(2)^2", "p(3)^3"])
        assert not hasattr(plan_for(kb, kb.plans.plan(GOAL, ()), False), "reason")
        assert _setting(kb) == "7s"                    # the administrator's
        with kb.store.transaction():
            assert kb.query(GOAL, timeout=30) == [{"X": 2}, {"X": 3}]
            assert _setting(kb) == "7s"
            rows = kb.store.run_compiled("SELECT 1", {}, deadline=time.monotonic() + 30)
            assert rows == [(1,)] and _setting(kb) == "7s"
            kb.add_many([f"s({i})^{i}" for i in range(300)])
            with pytest.raises(SLRTimeout):            # cancelled: rolled back to its savepoint
                kb.query(SLOW_GOAL, timeout=0.2)
            assert _setting(kb) == "7s"
            kb.add("p(4)^4")                           # the transaction goes on
        kb.store.execute("SET statement_timeout = '9s'")   # the session's own
        with kb.store.transaction():
            kb.store.run_compiled("SELECT 1", {}, deadline=time.monotonic() + 30)
            assert _setting(kb) == "9s"
            kb.store.execute("SET LOCAL statement_timeout = '3s'")   # the transaction's
            assert kb.query(GOAL, timeout=30) == [{"X": 2}, {"X": 3}, {"X": 4}]
            assert _setting(kb) == "3s"
        assert _setting(kb) == "9s"
        assert kb.store.count("p", 1) == 4


def test_a_nested_transaction_that_does_not_wait_leaves_the_enclosing_lock_timeout(
        postgres_url):
    with slr_sql.open(postgres_url, clock=ManualClock(0.0), busy_timeout=4.0) as kb:
        store = kb.store
        assert _setting(kb, "lock_timeout") == "4s"
        with store.transaction(wait=False):
            assert _setting(kb, "lock_timeout") == "1ms"
            with store.transaction(wait=False):
                assert _setting(kb, "lock_timeout") == "1ms"
            assert _setting(kb, "lock_timeout") == "1ms"   # still not waiting
            with store.transaction():
                pass
            assert _setting(kb, "lock_timeout") == "1ms"
        with store.transaction():
            store.execute("SET LOCAL lock_timeout = '2s'")
            with store.transaction(wait=False):
                assert _setting(kb, "lock_timeout") == "1ms"
            assert _setting(kb, "lock_timeout") == "2s"
            with pytest.raises(SLRError):
                with store.transaction(wait=False):
                    raise SLRError("rolled back")
            assert _setting(kb, "lock_timeout") == "2s"
        with store.transaction():
            with store.transaction(wait=False):
                pass
            assert _setting(kb, "lock_timeout") == "4s"
        assert _setting(kb, "lock_timeout") == "4s"
