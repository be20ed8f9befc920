"""A subscription's state machine (slr_sql/subscriptions/queue.py): every state is reached by
real use of a store (history, live, lagging, ended, finished, closed), a change that
TRANSITIONS does not allow raises IllegalTransition and keeps the state, and the table
itself is connected (every state reachable from the start, CLOSED the only dead end)."""
from __future__ import annotations

import pytest

import slr_sql
from slr_sql import ManualClock
from slr_sql.subscriptions import TRANSITIONS, IllegalTransition, SubscriptionOverflow, \
    SubscriptionState

S = SubscriptionState
DEADLINE = 20.0


@pytest.fixture
def kb():
    k = slr_sql.open(clock=ManualClock(0.0))
    yield k
    k.close()


def drain(kb):
    assert kb._subscriptions.drain(DEADLINE)


def in_history(kb):
    kb.add_many([f"p({i})^{i}" for i in range(1, 51)])
    sub = kb.subscribe("p(X)^T", since=0, max_queue=4)
    drain(kb)                        # 4 of 50 stored answers queued: the rest still to read
    return sub


def live(kb):
    sub = kb.subscribe("p(X)^T", since=0)
    drain(kb)
    return sub


def lagging(kb):
    sub = kb.subscribe("p(X)^T", since=0, max_queue=2)
    kb.add_many([f"p({i})^{i}" for i in range(1, 11)])
    drain(kb)                        # 2 of 10 queued: it reads the rest at its own pace
    return sub


def ended(kb):
    sub = kb.subscribe("p(X)^T", since=0, max_queue=1, max_lag=3)
    kb.add_many([f"p({i})^{i}" for i in range(1, 21)])
    drain(kb)                        # 19 behind > max_lag: the end is queued after p(1)
    return sub


def finished(kb):
    sub = ended(kb)
    # the consumer takes the end: FINISHED, and the hub closes it right away
    assert sub.get(timeout=DEADLINE)["X"] == 1
    with pytest.raises(SubscriptionOverflow):
        sub.get(timeout=DEADLINE)
    return sub


def closed(kb):
    sub = live(kb)
    sub.close()
    return sub


REACH = {S.HISTORY: in_history, S.LIVE: live, S.LAGGING: lagging, S.ENDED: ended,
         S.CLOSED: closed}


@pytest.mark.parametrize("state", list(REACH), ids=lambda s: s.value)
def test_each_state_is_reached_by_use(kb, state):
    sub = REACH[state](kb)
    assert sub.state is state
    assert sub.lagging is (state is S.LAGGING)
    assert sub.is_over is (state in (S.ENDED, S.FINISHED, S.CLOSED))
    sub.close()


def test_finished_is_reached_when_the_consumer_takes_the_end(kb):
    sub = finished(kb)
    assert sub.state is S.CLOSED and sub.closed_from is S.FINISHED
    assert sub.closed


def test_until_reached_records_a_durable_subscription_finished(tmp_path):
    with slr_sql.open(tmp_path / "f.db", clock=ManualClock(0.0)) as kb:
        sub = kb.subscribe("p(X)^T", since=0, until=5, id="f")
        kb.add("p(a)^2")
        assert sub.get(timeout=DEADLINE)["X"] == "a"
        kb.mark_complete("p/1", 5)
        assert sub.get(timeout=DEADLINE) is None
        assert sub.closed_from is S.FINISHED and sub.completed
        assert kb.sql("SELECT finished FROM slr_subscriptions WHERE id = 'f'")[1] == [(1,)]


def test_a_lagging_subscription_goes_live_again_when_its_consumer_catches_up(kb):
    sub = lagging(kb)
    assert [sub.get(timeout=DEADLINE)["X"] for _ in range(10)] == list(range(1, 11))
    drain(kb)
    assert sub.state is S.LIVE and sub.overflows == 1
    kb.add("p(11)^11")
    assert sub.get(timeout=DEADLINE)["X"] == 11
    sub.close()


def test_history_goes_live_after_the_stored_events(kb):
    sub = in_history(kb)
    assert [sub.get(timeout=DEADLINE)["X"] for _ in range(50)] == list(range(1, 51))
    drain(kb)
    assert sub.state is S.LIVE and sub.phase == 1
    sub.close()


@pytest.mark.parametrize("state", list(REACH), ids=lambda s: s.value)
def test_a_change_not_in_the_table_raises_and_keeps_the_state(kb, state):
    sub = REACH[state](kb)
    refused = [new for new in S if new not in TRANSITIONS[state]]
    assert refused                     # every state refuses something (itself at least)
    for new in refused:
        with pytest.raises(IllegalTransition) as info, sub._lock:
            sub._to(new)
        assert sub.state is state
        assert info.value.old is state and info.value.new is new
        assert f"from {state.value} to {new.value}" in str(info.value)
    sub.close()


def test_finished_refuses_everything_but_closed(kb):
    sub = ended(kb)
    with sub._lock:                     # as the consumer does when it takes the end
        sub._to(S.FINISHED)
    for new in S:
        if new is not S.CLOSED:
            with pytest.raises(IllegalTransition), sub._lock:
                sub._to(new)
    sub.close()                         # FINISHED to CLOSED: allowed
    assert sub.state is S.CLOSED and sub.closed_from is S.FINISHED


def test_the_table_is_connected_and_closed_is_its_only_dead_end():
    seen, todo = {S.HISTORY}, [S.HISTORY]
    while todo:
        for new in TRANSITIONS[todo.pop()]:
            if new not in seen:
                seen.add(new)
                todo.append(new)
    assert seen == set(S)
    assert [s for s in S if not TRANSITIONS[s]] == [S.CLOSED]
    assert all(S.CLOSED in TRANSITIONS[s] for s in S if s is not S.CLOSED)
    assert all(s not in TRANSITIONS[s] for s in S)     # no change to itself
