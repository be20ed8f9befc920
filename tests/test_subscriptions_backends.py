"""The subscriptions' storage (store/journals.py) on both backends: a durable subscription
reads its history (by seq and by end time), closes, resumes where it stopped, a second one
lags and catches up, journals are trimmed and dropped, rows listed and removed — the same
answers and states on SQLite and PostgreSQL."""
from __future__ import annotations

import pytest

import slr_sql
from slr_sql import ManualClock
from slr_sql import subscriptions
from slr_sql.subscriptions import SubscriptionState, journal_table

DEADLINE = 30.0


def xs(sub, n):
    return [sub.get(timeout=DEADLINE)["X"] for _ in range(n)]


@pytest.mark.parametrize("history", ["by end time", "by seq"])
def test_history_resume_lag_trim_and_drop_alike_on_both_backends(backend, history,
                                                                 monkeypatch):
    if history == "by seq":
        monkeypatch.setattr(subscriptions.hub, "FEW_HISTORY", -1)
    with slr_sql.open(backend, clock=ManualClock(0.0)) as kb:
        hub = kb._subscriptions
        hub.cleanup_interval = 1e9               # trimming only when the test asks
        kb.add_many([f"p({i})^{i}" for i in range(1, 31)])
        sub = kb.subscribe("p(X)^T", since=0, id="d", max_queue=4)
        assert hub.drain(DEADLINE)
        assert sub.state is SubscriptionState.HISTORY
        assert xs(sub, 10) == list(range(1, 11))
        sub.close()                              # the 10th counts as handled
        kb.add_many([f"p({i})^{i}" for i in range(31, 51)])
        assert [(r["id"], r["durable"], r["finished"]) for r in hub.subscriptions()] == \
            [("d", 1, 0)]

        sub = kb.subscribe("p(X)^T", since=0, id="d", max_queue=4)
        assert xs(sub, 40) == list(range(11, 51))
        assert hub.drain(DEADLINE)
        assert sub.state is SubscriptionState.LIVE

        other = kb.subscribe("p(X)^T", since=51, max_queue=2)
        kb.add_many([f"p({i})^{i}" for i in range(51, 61)])
        assert hub.drain(DEADLINE)
        assert other.state is SubscriptionState.LAGGING
        assert xs(other, 10) == list(range(51, 61))
        assert xs(sub, 10) == list(range(51, 61))
        assert hub.drain(DEADLINE)
        assert other.state is SubscriptionState.LIVE

        table = kb.store.table_for("p", 1)
        journal = journal_table(table)
        other.close()
        sub.close()                              # everything taken is handled
        hub.cleanup()
        assert kb.sql(f'SELECT count(*) FROM "{journal}"')[1] == [(0,)]
        kb.unsubscribe("d")
        assert hub.subscriptions() == []
        assert journal not in kb.store.table_names()   # no subscription wants p/1 now
