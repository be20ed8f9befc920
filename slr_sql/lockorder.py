"""The order in which a thread may take the locks of a knowledge base, checked in debug mode.

Every lock of slr_sql has a *kind* (``LOCK_ORDER``, outermost first; docs/architecture.md
says what each guards). A thread holding a lock of one kind may take a lock of a later kind,
or take again a lock it holds (the re-entrant ones), never one of an earlier kind: two
threads taking the same two locks in opposite orders can each wait for the other for ever.
Locks of one kind (the stores of two knowledge bases, two subscriptions) are not ordered
among themselves.

In debug mode -- ``SLR_DEBUG_LOCKS=1`` in the environment, or ``python -X dev`` (unless
``SLR_DEBUG_LOCKS=0``) -- :func:`ordered_lock` returns a lock that checks the order on every
blocking acquisition and raises :class:`LockOrderViolation` (also recorded, for threads
whose exceptions nobody sees: :func:`violations`) before it would wait out of order. A
try-lock (``blocking=False``, or a timeout) never waits for ever and is not checked. Without
debug mode it returns a plain ``threading.Lock`` / ``RLock``: no cost.

>>> import os; os.environ["SLR_DEBUG_LOCKS"] = "1"
>>> store, sync = ordered_lock("store", reentrant=True), ordered_lock("sync", reentrant=True)
>>> with sync, store: pass          # sync before store: in order
>>> with store, sync: pass
Traceback (most recent call last):
...
slr_sql.lockorder.LockOrderViolation: took a sync lock while holding a store lock (the order is kb.load, sync, store, buffers, subscriptions.hub, subscription, store.reader, frames, clock.listeners, parser)
>>> del os.environ["SLR_DEBUG_LOCKS"]; clear_violations()
"""
from __future__ import annotations

import os
import sys
import threading
from typing import Any

__all__ = ["LOCK_ORDER", "LockOrderViolation", "OrderedLock", "ordered_lock", "debug_locks",
           "violations", "clear_violations", "observed_nesting", "held_here"]

# outermost first: a thread holding one of these may take only the ones after it
LOCK_ORDER = (
    "kb.load",             # KnowledgeBase: load / unload / re-reading the program
    "sync",                # Synchronizer: waiting queries, timers, completeness (its Condition)
    "store",               # Database / PgDatabase: the store's one connection, transactions
    "buffers",             # BufferManager: buffers installed and removed (in a transaction)
    "subscriptions.hub",   # SubscriptionHub: subscriptions by type, the delivery passes
    "subscription",        # Subscription: its queue and state (its Condition)
    "store.reader",        # ReadConnection / PgReadConnection: a reader's own connection
    "frames",              # FrameTree: the frame tree (the store is read without it)
    "clock.listeners",     # Clock: its listener list (listeners are called without it)
    "parser",              # parser: building the full grammar's parser once
)
_RANK = {name: rank for rank, name in enumerate(LOCK_ORDER)}

_held = threading.local()          # debug mode only: the OrderedLocks this thread holds
_violations: list[str] = []
_edges: set[tuple[str, str]] = set()   # (held kind, kind taken) seen in debug mode
_violations_lock = threading.Lock()


class LockOrderViolation(RuntimeError):
    """A thread took a lock of an earlier kind while holding one of a later kind (debug
    mode): a deadlock waiting for a second thread that takes them the other way round."""


def debug_locks() -> bool:
    """Is the lock order checked for locks made now? ``SLR_DEBUG_LOCKS=1``, or ``-X dev``
    unless ``SLR_DEBUG_LOCKS=0``.

    >>> import os
    >>> from unittest import mock
    >>> with mock.patch.dict(os.environ, SLR_DEBUG_LOCKS="1"): debug_locks()
    True
    >>> with mock.patch.dict(os.environ, SLR_DEBUG_LOCKS="0"): debug_locks()
    False
    """
    flag = os.environ.get("SLR_DEBUG_LOCKS", "")
    if flag:
        return flag not in ("0", "false", "no")
    return bool(sys.flags.dev_mode)


def violations() -> list[str]:
    """The violations seen in this process (debug mode), oldest first.

    >>> import os
    >>> from unittest import mock
    >>> with mock.patch.dict(os.environ, SLR_DEBUG_LOCKS="1"):  # checked locks, as in debug mode
    ...     store, sync = ordered_lock("store", reentrant=True), ordered_lock("sync", reentrant=True)
    >>> clear_violations()
    >>> try:
    ...     with store, sync: pass  # sync after store: out of order
    ... except LockOrderViolation: pass
    >>> violations()
    ['MainThread: took a sync lock while holding a store lock ...']
    >>> clear_violations()
    """
    with _violations_lock:
        return list(_violations)


def clear_violations() -> None:
    """Forget the violations and the nesting seen so far.

    >>> import os
    >>> from unittest import mock
    >>> with mock.patch.dict(os.environ, SLR_DEBUG_LOCKS="1"):  # checked locks, as in debug mode
    ...     store, sync = ordered_lock("store", reentrant=True), ordered_lock("sync", reentrant=True)
    >>> try:
    ...     with store, sync: pass  # out of order
    ... except LockOrderViolation: pass
    >>> len(violations()) > 0
    True
    >>> clear_violations(); violations()
    []
    """
    with _violations_lock:
        _violations.clear()
        _edges.clear()


def observed_nesting() -> set[tuple[str, str]]:
    """The (held, taken) pairs of lock kinds seen in this process (debug mode): what the
    order must allow.

    >>> all(a in LOCK_ORDER and b in LOCK_ORDER for a, b in observed_nesting())
    True
    """
    return set(_edges)


def _stack() -> list[OrderedLock]:
    stack: list[OrderedLock] | None = getattr(_held, "stack", None)
    if stack is None:
        stack = _held.stack = []
    return stack


class OrderedLock:
    """A lock of one kind that checks, before each blocking acquisition, that this thread
    holds no lock of a later kind (debug mode; see :func:`ordered_lock`). Works with
    ``threading.Condition``.

    >>> lock = OrderedLock("sync", reentrant=True)
    >>> with lock, lock: lock.held_by_me()
    True
    """

    def __init__(self, kind: str, reentrant: bool = False):
        if kind not in _RANK:
            raise ValueError(f"unknown lock kind {kind!r}: add it to LOCK_ORDER")
        self.kind = kind
        self.rank = _RANK[kind]
        self.reentrant = reentrant
        self._inner: Any = threading.RLock() if reentrant else threading.Lock()
        self.raises = os.environ.get("SLR_DEBUG_LOCKS") != "record"

    def __repr__(self) -> str:
        return f"<OrderedLock {self.kind}>"

    def held_by_me(self) -> bool:
        return any(entry is self for entry in _stack())

    def _check(self, stack: list[OrderedLock]) -> None:
        if any(entry is self for entry in stack):
            if self.reentrant:
                return
            problem = f"took a {self.kind} lock it already holds (not re-entrant)"
        else:
            with _violations_lock:
                _edges.update((entry.kind, self.kind) for entry in stack
                              if entry.kind != self.kind)
            later = [entry for entry in stack if entry.rank > self.rank]
            if not later:
                return
            problem = f"took a {self.kind} lock while holding a {later[-1].kind} lock"
        message = f"{problem} (the order is {', '.join(LOCK_ORDER)})"
        with _violations_lock:
            _violations.append(f"{threading.current_thread().name}: {message}")
        if self.raises:
            raise LockOrderViolation(message)

    def acquire(self, blocking: bool = True, timeout: float = -1) -> bool:
        stack = _stack()
        if blocking and timeout < 0:
            self._check(stack)
        if self._inner.acquire(blocking, timeout):
            stack.append(self)
            return True
        return False

    def release(self) -> None:
        self._inner.release()
        stack = _stack()
        for i in range(len(stack) - 1, -1, -1):
            if stack[i] is self:
                del stack[i]
                break

    def __enter__(self) -> bool:
        return self.acquire()

    def __exit__(self, *exc: Any) -> None:
        self.release()

    # what threading.Condition uses to wait (release fully, re-take as before)
    def _is_owned(self) -> bool:
        return self.held_by_me()

    def _release_save(self) -> Any:
        stack = _stack()
        count = sum(1 for entry in stack if entry is self)
        stack[:] = [entry for entry in stack if entry is not self]
        if self.reentrant:
            return self._inner._release_save(), count
        self._inner.release()
        return None, count

    def _acquire_restore(self, saved: Any) -> None:
        state, count = saved
        if self.reentrant:
            self._inner._acquire_restore(state)
        else:
            self._inner.acquire()
        _stack().extend([self] * count)


def held_here(lock: Any) -> bool:
    """Does the calling thread hold ``lock`` (an ``RLock`` or an :class:`OrderedLock`)?

    >>> lock = ordered_lock("store", reentrant=True)
    >>> with lock: held_here(lock)
    True
    >>> held_here(lock)
    False
    """
    return bool(lock._is_owned())


def ordered_lock(kind: str, reentrant: bool = False) -> Any:
    """A lock of ``kind`` (one of ``LOCK_ORDER``): an :class:`OrderedLock` in debug mode,
    else a plain ``threading.RLock`` (``reentrant``) or ``threading.Lock``.

    >>> type(ordered_lock("store", reentrant=True)).__name__ in ("RLock", "OrderedLock")
    True
    """
    if kind not in _RANK:
        raise ValueError(f"unknown lock kind {kind!r}: add it to LOCK_ORDER")
    if debug_locks():
        return OrderedLock(kind, reentrant)
    return threading.RLock() if reentrant else threading.Lock()
