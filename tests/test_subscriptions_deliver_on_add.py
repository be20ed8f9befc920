"""The thread whose add committed delivers the events to the subscriptions that keep up
(the shared read), when no other delivery pass is under way: the answers are queued before
``kb.add`` returns, without waiting for the hub thread to be scheduled (on a busy machine,
that wait was the tail of the delivery latency). What the shared read leaves -- a history, a
lagging subscription -- is still the hub thread's, and passes never overlap."""
from __future__ import annotations

import threading

import pytest

import slr_sql

DEADLINE = 30.0


def opened(path):
    """A store with a ManualClock (events stamped 1, 2, ...; subscriptions since=0)."""
    return slr_sql.open(path, clock=slr_sql.ManualClock(0.0))


def parked(hub):
    """Let the hub thread finish what it was woken for, then keep it from polling: after
    this it runs a pass only when something notifies it."""
    hub.poll_interval = 3600.0
    assert hub.drain(DEADLINE)


def add_on_a_thread(kb, events):
    """``kb.add_many(events)`` on a thread of its own; returns the thread and an Event set
    once the call returned."""
    returned = threading.Event()

    def add():
        kb.add_many(events)
        returned.set()

    thread = threading.Thread(target=add)
    thread.start()
    return thread, returned


@pytest.mark.parametrize("in_file", [True, False])
def test_the_adding_thread_queues_the_answers_while_the_hub_thread_cannot_run(tmp_path,
                                                                               in_file):
    kb = opened(tmp_path / "s.db" if in_file else None)
    try:
        subs = [kb.subscribe("p(X)^T", since=0) for _ in range(3)]
        kb.add("p(0)^1")
        hub = kb._subscriptions
        parked(hub)
        for sub in subs:
            assert sub.get(timeout=DEADLINE)["X"] == 0
        # the hub thread is held at its lock (as a thread the machine does not schedule
        # is): only the adding thread can deliver meanwhile
        with hub.cond:
            thread, returned = add_on_a_thread(kb, ["p(1)^2", "p(2)^3"])
            assert returned.wait(DEADLINE), "the add waited for the hub thread"
            for sub in subs:
                assert [sub.get(timeout=0)["X"] for _ in range(2)] == [1, 2]
        thread.join()
        kb.add("p(3)^4")                      # and again: nothing was left half done
        for sub in subs:
            assert sub.get(timeout=DEADLINE)["X"] == 3
    finally:
        kb.close()


def test_a_lagging_subscription_is_still_served_by_the_hub_thread(tmp_path):
    """The shared read leaves a subscription whose queue was full: the adding thread
    delivers to the others and wakes the hub thread, which serves it once there is room,
    every answer once and in order."""
    kb = opened(tmp_path / "s.db")
    try:
        keeps_up = kb.subscribe("p(X)^T", since=0)
        small = kb.subscribe("p(X)^T", since=0, max_queue=2)
        kb.add_many([f"p({i})^{i + 1}" for i in range(5)])   # small: 2 queued, lagging
        assert kb._subscriptions.drain(DEADLINE)
        assert small.lagging
        kb.add_many([f"p({i})^{i + 1}" for i in range(5, 8)])
        assert [keeps_up.get(timeout=DEADLINE)["X"] for _ in range(8)] == list(range(8))
        assert [small.get(timeout=DEADLINE)["X"] for _ in range(8)] == list(range(8))
    finally:
        kb.close()


def test_adds_from_many_threads_reach_every_subscriber_once_in_order(tmp_path):
    """Passes of adding threads and of the hub thread never overlap: four threads adding at
    once, three subscribers, each gets every event once, in the order of the journal."""
    kb = opened(tmp_path / "s.db")
    try:
        subs = [kb.subscribe("p(W, I)^T", since=0) for _ in range(3)]
        start = threading.Barrier(4)

        def writer(w):
            start.wait(DEADLINE)
            for i in range(25):
                kb.add_many([f"p({w}, {i})^{1 + w * 100 + i}"])

        threads = [threading.Thread(target=writer, args=(w,)) for w in range(4)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        journal_order = [(a["W"], a["I"]) for a in
                         kb.query("p(W, I)^T")]   # every event, once
        assert len(journal_order) == 100
        got = []
        for sub in subs:
            mine = [(a["W"], a["I"]) for a in (sub.get(timeout=DEADLINE) for _ in range(100))]
            got.append(mine)
            for w in range(4):                 # each writer's events in its order
                assert [i for ww, i in mine if ww == w] == list(range(25))
        assert got[0] == got[1] == got[2]       # one order for every subscriber
        assert sorted(got[0]) == sorted(journal_order)
    finally:
        kb.close()

