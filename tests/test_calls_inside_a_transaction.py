"""Every call of the facade made inside ``with kb.store.transaction():`` keeps the written lock
order (docs/architecture.md, "Locks"): the calls that would take a lock ordered before the
store's -- the program's (load, unload, buffers), the synchronizer's (close) -- are refused
up front with an SLRError naming the call, and change nothing; those that can do without it
(submit, pending, PendingQuery.cancel, subscribe with until) do, and finish their work once
the transaction ended. Checked in debug mode (a lock taken out of order raises before it
could wait, and is recorded), on both backends, and with a second thread taking the locks in
the written order while the first is inside its transaction: nothing waits for ever."""
from __future__ import annotations

import asyncio
import threading

import pytest

import slr_sql
from slr_sql import ManualClock, SLRError
from slr_sql.lockorder import clear_violations, violations

PROGRAM = ":- max_delay(p/1, 0).\nq(X) :- p(X)^_.\n"
DEADLINE = 30.0   # seconds a thread may take; the calls below take milliseconds


@pytest.fixture
def debug_locks(monkeypatch):
    """Debug mode for the locks made during the test (they read it when made)."""
    monkeypatch.setenv("SLR_DEBUG_LOCKS", "1")
    clear_violations()
    yield
    seen = violations()
    clear_violations()
    assert seen == []


@pytest.fixture
def kb(debug_locks, backend, tmp_path):
    """A knowledge base with a program, an event, a runtime buffer and a waiting query."""
    kb = slr_sql.open(backend, clock=ManualClock(10.0))
    kb.load(PROGRAM)
    kb.add("p(0)^0.5")
    kb.add_buffer("p(_)", keep_last=5)
    kb.waiting = kb.submit("p(X)^T", at=100, id="waiting")
    yield kb
    kb.close()


def _state(kb) -> tuple:
    """What a refused call could have changed: programs, buffers, events, waiting queries."""
    return ({name: info.source for name, info in kb.programs().items()},
            [(info.id, info.pattern) for info in kb.buffers()],
            kb.query("findall(X, p(X)^_, L)"),
            sorted(q.id for q in kb.pending()))


def _program_file(tmp_path) -> str:
    path = tmp_path / "more.slr"
    path.write_text("r(1).")
    return str(path)


REFUSED = {
    "kb.close()": lambda kb, tmp_path: kb.close(),
    "kb.__exit__": lambda kb, tmp_path: kb.__exit__(None, None, None),
    "kb.load()": lambda kb, tmp_path: kb.load("r(1).", name="more"),
    "kb.load_file()": lambda kb, tmp_path: kb.load_file(_program_file(tmp_path), name="more"),
    "kb.unload()": lambda kb, tmp_path: kb.unload("main"),
    "kb.add_buffer()": lambda kb, tmp_path: kb.add_buffer("r(_)", keep_last=1),
    "kb.remove_buffer()": lambda kb, tmp_path: kb.remove_buffer(kb.buffers()[0].id),
    "kb.ask()": lambda kb, tmp_path: asyncio.run(kb.ask("p(X)^T", at=0)),
    "PendingQuery.result()": lambda kb, tmp_path: kb.waiting.result(timeout=2),
    "PendingQuery.exception()": lambda kb, tmp_path: kb.waiting.exception(timeout=2),
}
SAID = {"kb.__exit__": "kb.close()"}   # (the end of a with block closes)


@pytest.mark.parametrize("call", sorted(REFUSED))
def test_a_call_taking_a_lock_before_the_stores_is_refused_and_changes_nothing(
        kb, call, tmp_path):
    before = _state(kb)
    with kb.store.transaction():
        kb.add("p(1)^1")
        with pytest.raises(SLRError, match=rf"^{SAID.get(call, call)[:-2]}\(\) inside a "
                                           rf"transaction of the store: "):
            REFUSED[call](kb, tmp_path)
        kb.add("p(2)^2")        # the transaction goes on
    after = _state(kb)
    assert after[2] == [{"L": [0, 1, 2]}]          # its adds were committed
    assert after[:2] + after[3:] == before[:2] + before[3:]
    assert not kb.waiting.done()


def test_a_load_listener_may_still_change_the_buffers_inside_the_load(kb):
    """Inside a load the thread holds the program's lock already: taking it again is no
    step out of order, so a load listener's add_buffer is not refused."""
    made: list = []

    def add_a_buffer_once(kb) -> None:
        if not made:
            made.append(kb.add_buffer("r(_)", keep_last=1))

    kb.load_listeners.append(add_a_buffer_once)
    kb.load("r(1).", name="more")
    assert made and made[0] in [info.id for info in kb.buffers()]


def test_a_rolled_back_transaction_after_a_refused_call_leaves_nothing(kb):
    before = _state(kb)
    with pytest.raises(SLRError, match="kb.load"):
        with kb.store.transaction():
            kb.add("p(1)^1")
            kb.load("r(1).", name="more")
    assert _state(kb) == before


def test_a_query_submitted_inside_is_answered_on_what_the_transaction_committed(kb):
    with kb.store.transaction():
        kb.add("p(1)^1")
        query = kb.submit("findall(X, p(X)^_, L)", at=5)
        kb.mark_complete("p/1", 5)
        assert not query.done()
        assert [p.id for p in kb.pending()] == ["waiting", query.id]
    assert query.result(timeout=DEADLINE) == [{"L": [0, 1]}]


def test_a_query_submitted_inside_a_rolled_back_transaction_is_still_registered(kb):
    with pytest.raises(KeyError):
        with kb.store.transaction():
            query = kb.submit("p(X)^T", at=50, id="kept", timeout=DEADLINE)
            raise KeyError("undo")
    assert "kept" in {p.id for p in kb.pending()}
    kb.mark_complete("p/1", 50)
    assert query.result(timeout=DEADLINE) == [{"X": 0, "T": 0.5}]


def test_an_id_pending_or_taken_inside_the_same_transaction_is_refused_up_front(kb):
    with kb.store.transaction():
        with pytest.raises(SLRError, match="'waiting' is already pending"):
            kb.submit("p(X)^T", at=100, id="waiting")
        kb.submit("p(X)^T", at=100, id="twice")      # (waits: p/1 is complete up to 10)
        with pytest.raises(SLRError, match="'twice' is already pending"):
            kb.submit("p(X)^T", at=100, id="twice")
    assert {"waiting", "twice"} <= {p.id for p in kb.pending()}


def test_pending_inside_lists_the_waiting_queries(kb):
    with kb.store.transaction():
        assert [p.id for p in kb.pending()] == ["waiting"]


def test_a_query_cancelled_inside_leaves_the_pending_queries(kb):
    with kb.store.transaction():
        assert kb.waiting.cancel() is True
        assert kb.waiting.cancelled() and kb.pending() == []
    assert kb.pending() == []
    # its id is free again: the query left the synchronizer's table
    again = kb.submit("p(X)^T", at=5, id="waiting")
    kb.mark_complete("p/1", 5)
    assert again.result(timeout=DEADLINE) == [{"X": 0, "T": 0.5}]


def test_a_subscription_with_until_made_inside_ends_once_the_type_is_complete(kb):
    with kb.store.transaction():
        kb.add("p(1)^1")
        sub = kb.subscribe("p(X)^T", since=0, until=5)
        kb.mark_complete("p/1", 5)
    assert sub.get(timeout=DEADLINE) == {"X": 0, "T": 0.5}
    assert sub.get(timeout=DEADLINE) == {"X": 1, "T": 1.0}
    assert sub.get(timeout=DEADLINE) is None       # until reached: the end
    sub.close()


def test_a_subscription_with_until_closed_inside_cancels_its_watch(kb):
    with kb.store.transaction():
        sub = kb.subscribe("p(X)^T", since=0, until=5)
        sub.close()
    assert [p.id for p in kb.pending()] == ["waiting"]


# -- a second thread taking the locks in the written order ----------------------------------------

def _submit(kb):
    kb.submit("p(X)^T", at=5)


def _cancel(kb):
    kb.waiting.cancel()


def _subscribe_until(kb):
    kb.subscribe("p(X)^T", since=0, until=5)


def _load(kb):
    with pytest.raises(SLRError, match=r"^kb\.load\(\) inside"):
        kb.load("r(1).", name="more")


def _close(kb):
    with pytest.raises(SLRError, match=r"^kb\.close\(\) inside"):
        kb.close()


# (the call inside the transaction, the lock the other thread holds before it takes the store's)
INSIDE = {"submit": (_submit, "sync"), "pending": (lambda kb: kb.pending(), "sync"),
          "cancel": (_cancel, "sync"), "subscribe until": (_subscribe_until, "sync"),
          "close": (_close, "sync"), "load": (_load, "kb.load")}


@pytest.mark.parametrize("name", sorted(INSIDE))
def test_no_deadlock_with_a_thread_taking_the_locks_in_order(backend, name):
    """One thread holds the synchronizer's (or the program's) lock and then asks for the
    store's, as a mark (a load) does; the other, inside its transaction, makes the call.
    Before, the call waited for the first lock while its holder waited for the store."""
    call, first_lock = INSIDE[name]
    kb = slr_sql.open(backend, clock=ManualClock(10.0))
    kb.load(PROGRAM)
    kb.waiting = kb.submit("p(X)^T", at=100, id="waiting")
    lock = kb.synchronizer.lock if first_lock == "sync" else kb.loader.load_lock
    in_transaction, holding = threading.Event(), threading.Event()
    errors: list = []

    def in_order() -> None:       # the first lock, then the store's (a mark, a load)
        try:
            assert in_transaction.wait(DEADLINE)
            with lock:
                holding.set()
                if first_lock == "sync":
                    kb.mark_complete("p/1", 1)
                else:
                    kb.load("s(1).", name="other")
        except BaseException as exc:  # noqa: BLE001 - reported below
            errors.append(exc)

    def inside() -> None:
        try:
            with kb.store.transaction():
                in_transaction.set()
                assert holding.wait(DEADLINE)
                call(kb)
                kb.add("p(1)^1")
        except BaseException as exc:  # noqa: BLE001 - reported below
            errors.append(exc)

    threads = [threading.Thread(target=in_order, daemon=True),
               threading.Thread(target=inside, daemon=True)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(DEADLINE)
    # (deadlocked, the knowledge base is left open: closing it would wait for ever too)
    assert not any(thread.is_alive() for thread in threads), "deadlock"
    try:
        assert errors == []
        assert kb.complete_until("p/1") >= 1
        assert kb.query("findall(X, p(X)^_, L)") == [{"L": [1]}]
        if first_lock == "kb.load":
            assert set(kb.programs()) == {"main", "other"}
    finally:
        kb.close()
