"""An add with event rules stores its events in the round's transaction (the pipeline's) with
no savepoint of its own: every error of the add leaves through that transaction, which takes
the whole back, so a savepoint would only make SQLite keep the pages the inserts change for
a rollback that never comes (~5% of seq2 recent's CPU). Inside a caller's transaction the
pipeline's level is still a savepoint, so a failed add takes back only itself."""
from __future__ import annotations

import pytest

import slr_sql
from slr_sql import ManualClock
from slr_sql.errors import SLRError

RULE = ":- consumption(recent).\n:- max_delay(a/1, 0).\n:- max_delay(b/1, 0).\n" \
       "c(X) <- a(X) seq b(X).\n"


def _statements(kb) -> list[str]:
    heard: list[str] = []
    kb.store._db.conn.set_trace_callback(heard.append)
    return heard


def _c(kb) -> list:
    return sorted((a["X"], a["S"], a["E"]) for a in kb.query("c(X)^[S, E]"))


def test_an_add_with_rules_opens_one_transaction_and_no_savepoint(tmp_path):
    with slr_sql.open(str(tmp_path / "r.db"), clock=ManualClock(10.0)) as kb:
        kb.load(RULE)
        kb.add_many(["a(1)^1", "b(1)^2"])      # (the tables exist: no first-add work)
        heard = _statements(kb)
        kb.add_many(["a(2)^3", "b(2)^4"])
        kb.store._db.conn.set_trace_callback(None)
        assert not [s for s in heard if s.startswith("SAVEPOINT")], heard
        assert sum(s.startswith("BEGIN") for s in heard) == 1
        assert _c(kb) == [(1, 1.0, 2.0), (2, 3.0, 4.0)]


def test_the_store_alone_still_takes_a_savepoint_inside_a_callers_transaction(tmp_path):
    with slr_sql.open(str(tmp_path / "r.db"), clock=ManualClock(10.0)) as kb:
        kb.load(RULE)
        kb.add_many(["a(1)^1"])
        heard = _statements(kb)
        with kb.store.transaction():
            kb.store.add_events([("a", (2,), 3.0, 3.0)])
        kb.store._db.conn.set_trace_callback(None)
        assert any(s.startswith("SAVEPOINT") for s in heard), heard


def test_a_failed_add_inside_a_callers_transaction_takes_back_only_itself(backend):
    with slr_sql.open(backend, clock=ManualClock(10.0)) as kb:
        kb.load(RULE)
        with kb.store.transaction():
            kb.add_many(["a(1)^1", "b(1)^2"])
            with pytest.raises(SLRError):
                kb.add_many(["a(2)^3", "b(2)^4", "b(x)^[5, 4]"], atomic=True)
            kb.add_many(["a(3)^6", "b(3)^7"])
        assert _c(kb) == [(1, 1.0, 2.0), (3, 6.0, 7.0)]
        assert sorted(a["X"] for a in kb.query("a(X)^T")) == [1, 3]
