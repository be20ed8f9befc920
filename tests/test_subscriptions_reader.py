"""The subscription hub reads journals on a connection of its own: a lagging subscriber catches
up while a writer holds the store (its transaction, fsync included), and subscribers behind the
shared read are served by one read per chunk, however many they are."""
from __future__ import annotations

import threading
from contextlib import contextmanager

import slr_sql

DEADLINE = 30.0


def opened(path):
    """A store at ``path`` (None: in memory) with a ManualClock: the events here are stamped
    1, 2, ... (not wall-clock times, which would make each type's first event "decades
    late", a LearnedDelayWarning); every subscription here starts at since=0, and the hub's
    housekeeping runs on time.monotonic, not on the store's clock."""
    return slr_sql.open(path, clock=slr_sql.ManualClock(0.0))


def answers_of(sub, count):
    out = []
    while len(out) < count:
        answer = sub.get(timeout=DEADLINE)
        assert answer is not None
        out.append(answer["X"])
    return out


@contextmanager
def store_held_by_another_writer(kb):
    """A thread holds the store's transaction (its lock, as a long commit holds it) for the
    body; yields that thread, released and joined at the end."""
    holding, release = threading.Event(), threading.Event()

    def writer():
        with kb.store.transaction():
            holding.set()
            release.wait(DEADLINE)

    thread = threading.Thread(target=writer)
    thread.start()
    try:
        assert holding.wait(DEADLINE)
        yield thread
    finally:
        release.set()
        thread.join()


@contextmanager
def another_writer_after_the_commit_of(kb, event):
    """``kb.add(event)`` in a thread of its own; right after its commit (the first add
    listener, before the hub's) another thread takes the store's transaction and holds it
    for the body, so the adding thread's later listeners wait for the store. Yields that
    other writer's thread."""
    holding, release = threading.Event(), threading.Event()

    def other_writer():
        with kb.store.transaction():
            holding.set()
            release.wait(DEADLINE)

    thread = threading.Thread(target=other_writer)

    def start_the_other_writer(stored):
        if not thread.is_alive() and not release.is_set():
            thread.start()
            assert holding.wait(DEADLINE)

    kb.add_listeners.insert(0, start_the_other_writer)
    adder = threading.Thread(target=kb.add, args=(event,))
    adder.start()
    try:
        yield thread
    finally:
        release.set()
        adder.join()
        thread.join()


def test_a_lagging_subscriber_catches_up_while_a_writer_holds_the_store(db_path):
    with opened(db_path) as kb:
        hub = kb._subscriptions
        hub.cleanup_interval = 1e9          # no journal trimming (a write) during the test
        sub = kb.subscribe("p(X)^T", since=0, max_queue=10)
        kb.add_many([f"p({i})^{i}" for i in range(1, 101)])
        assert hub.drain(DEADLINE)          # 10 answers queued, the rest left in the journal
        with store_held_by_another_writer(kb) as thread:
            # taking answers makes room; the hub reads on from the journal on its own
            # connection, not waiting for the writer's lock
            assert answers_of(sub, 40) == list(range(1, 41))
            assert thread.is_alive()        # the transaction was held all along
        assert answers_of(sub, 60) == list(range(41, 101))
        sub.close()


def test_subscribers_behind_share_one_read_per_chunk(db_path):
    subscribers = 20
    with opened(db_path) as kb:
        hub = kb._subscriptions
        hub.cleanup_interval = 1e9
        subs = [kb.subscribe("p(X)^T", since=0, max_queue=10) for _ in range(subscribers)]
        kb.add_many([f"p({i})^{i}" for i in range(1, 201)])
        assert hub.drain(DEADLINE)          # every one full (10 answers) and lagging
        gate = threading.Event()
        journal_reads = []
        read = hub._journal_rows

        def counting_read(info, after_jid, limit):
            journal_reads.append((after_jid, limit))
            gate.wait(DEADLINE)             # hold the hub until every consumer made room
            return read(info, after_jid, limit)

        hub._journal_rows = counting_read
        try:
            taken = [answers_of(s, 5) for s in subs]   # each makes room for 5 more
            gate.set()
            assert hub.drain(DEADLINE)
        finally:
            gate.set()
            hub._journal_rows = read
        assert taken == [list(range(1, 6))] * subscribers
        # the first read (whoever made room first) and one read for all the others: not one
        # per subscriber
        assert len(journal_reads) <= 3, journal_reads
        for s in subs:
            assert answers_of(s, 195) == list(range(6, 201))
            s.close()


def test_an_in_memory_store_has_no_second_connection_and_still_delivers():
    with opened(None) as kb:
        sub = kb.subscribe("p(X)^T", since=0, max_queue=4)
        kb.add_many([f"p({i})^{i}" for i in range(1, 21)])
        assert answers_of(sub, 20) == list(range(1, 21))
        sub.close()


def test_events_added_while_another_thread_holds_a_transaction_are_read_on_the_hubs_connection(
        db_path):
    """The add path wakes the hub while another thread (here a stand-in for the hub's own
    housekeeping or a second writer) is inside a transaction: the rows are committed, so the
    hub reads them on its own connection and delivers them without waiting for that
    transaction."""
    with opened(db_path) as kb:
        hub = kb._subscriptions
        hub.cleanup_interval = 1e9
        sub = kb.subscribe("p(X)^T", since=0)
        kb.add("p(0)^0")                      # the type's table exists: steady state
        assert answers_of(sub, 1) == [0]
        with another_writer_after_the_commit_of(kb, "p(1)^1") as thread:
            assert answers_of(sub, 1) == [1]
            assert thread.is_alive()          # delivered while the other transaction is open
        kb.add("p(2)^2")
        assert answers_of(sub, 1) == [2]
        sub.close()


def test_a_subscription_to_a_type_without_events_does_not_hold_up_the_others(db_path):
    """Every pass looks up the table of a type that has none yet (it may appear from another
    process): on the hub's connection, so that lookup never waits for a writer's transaction
    while an event of another type waits to be delivered."""
    with opened(db_path) as kb:
        hub = kb._subscriptions
        hub.cleanup_interval = 1e9
        nothing = kb.subscribe("nothing(X)^T", since=0)   # served first in every pass
        sub = kb.subscribe("p(X)^T", since=0)
        kb.add("p(0)^0")
        assert answers_of(sub, 1) == [0]
        with another_writer_after_the_commit_of(kb, "p(1)^1") as thread:
            assert answers_of(sub, 1) == [1]
            assert thread.is_alive()
        kb.add("nothing(a)^2")               # the type appears: delivered as usual
        assert nothing.get(timeout=DEADLINE)["X"] == "a"
        sub.close()
        nothing.close()


def test_housekeeping_waits_for_a_busy_store_after_the_deliveries_not_before(db_path):
    """Writing positions waits while a writer holds the store: delivery passes go on
    meanwhile (they used to queue behind that transaction), and the positions are written
    once the store is free."""
    with opened(db_path) as kb:
        hub = kb._subscriptions
        sub = kb.subscribe("p(X)^T", since=0, id="log")
        kb.add_many([f"p({i})^{i}" for i in range(1, 4)])
        assert answers_of(sub, 3) == [1, 2, 3]
        with store_held_by_another_writer(kb) as thread:
            hub._last_persist = 0.0           # positions due now
            for _ in range(3):                # whole passes, none waiting for the writer
                assert hub.drain(DEADLINE / 4)
            assert thread.is_alive()
        hub._last_persist = 0.0
        assert hub.housekeeping_round(DEADLINE)   # the store is free: written now
        rows = {r["id"]: r for r in hub.subscriptions()}
        assert rows["log"]["live_pos"] == 2   # up to the answer before the one in hand
        sub.close()


def test_housekeeping_that_must_wait_for_a_writer_delays_no_delivery(db_path):
    """Housekeeping runs on a thread of its own: when its writes are due and must wait for
    a writer's transaction (here at once: a lease so short that nothing may be put off), a
    lagging subscriber still catches up meanwhile. On the hub thread, the pass after the
    first refill waited for the writer, and the deliveries with it."""
    with opened(db_path) as kb:
        hub = kb._subscriptions
        hub.cleanup_interval = 1e9
        sub = kb.subscribe("p(X)^T", since=0, id="log", max_queue=10)
        kb.add_many([f"p({i})^{i}" for i in range(1, 101)])
        assert hub.drain(DEADLINE)          # 10 answers queued, the rest left in the journal
        with store_held_by_another_writer(kb) as thread:
            hub.lease_seconds = 1e-6          # claims to renew now, nothing put off
            hub._last_persist = 0.0           # positions due now
            assert answers_of(sub, 40) == list(range(1, 41))
            assert thread.is_alive()          # the transaction was held all along
        hub.lease_seconds = 60.0
        hub._last_persist = hub._last_lease = 0.0
        assert hub.housekeeping_round(DEADLINE)   # written once the store is free
        rows = {r["id"]: r for r in hub.subscriptions()}
        assert rows["log"]["live_pos"] >= 39
        assert answers_of(sub, 60) == list(range(41, 101))
        sub.close()
