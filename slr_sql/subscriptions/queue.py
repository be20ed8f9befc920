"""One subscription: its queue of answers, its position, and its state
(:class:`SubscriptionState`), whose changes are checked against :data:`TRANSITIONS`.

The consumer (an iterator, an async iterator, a callback thread, the network service) takes
answers with the methods of :class:`Subscription`; the hub (:mod:`.hub`) queues them with
its hub-side methods (:meth:`Subscription.offer_batch`, :meth:`Subscription.end`, ...). Both
sides change the queue and the state under the subscription's lock only.

States::

    HISTORY ──> LIVE <──> LAGGING        (running: the hub queues answers)
       │         │           │
       └─────────┴───────────┴──> ENDED ──> FINISHED    (an end queued; the consumer took it)
       any state but CLOSED ──────────────────────────> CLOSED
"""
from __future__ import annotations

import collections
import enum
import logging
import threading
import time
from typing import Any, Callable, Protocol

from ..arguments import check_flag, wait_seconds
from ..errors import SLRError, SLRTimeout
from ..lockorder import ordered_lock
from .matching import Matcher

__all__ = ["Subscription", "SubscriptionState", "TRANSITIONS", "IllegalTransition",
           "SubscriptionOverflow", "HISTORY_PHASE", "LIVE_PHASE"]

log = logging.getLogger("slr_sql.subscriptions")

HISTORY_PHASE, LIVE_PHASE = 0, 1   # phases of a position: (phase, seq or jid)
_H = 2 ** 62                       # queued positions are one int: jid (live) or seq - _H


def _code(phase: int, pos: int) -> int:
    return pos if phase == LIVE_PHASE else pos - _H


def _decode_position(code: int) -> tuple[int, int]:
    return (LIVE_PHASE, code) if code >= 0 else (HISTORY_PHASE, code + _H)


class SubscriptionState(enum.Enum):
    """Where a subscription is in its life.

    >>> SubscriptionState.LAGGING in TRANSITIONS[SubscriptionState.LIVE]
    True
    """

    HISTORY = "history"    # the hub reads stored events (seq <= the top at registration)
    LIVE = "live"          # in the hub's shared read of the journal
    LAGGING = "lagging"    # its queue was full: it reads the journal at its own pace
    ENDED = "ended"        # an end is queued after its answers (until, overflow, error)
    FINISHED = "finished"  # the consumer took the end
    CLOSED = "closed"      # close(): nothing more is queued or taken

    # a member is equal only to itself, so its identity is its hash: Enum's own hash (of its
    # name, in Python) made each test of a state against a set, done by the hub and the
    # consumer for every batch of every subscription, a function call
    __hash__ = object.__hash__

    @property
    def running(self) -> bool:
        """The hub still queues answers for it."""
        return self in _RUNNING


_RUNNING = frozenset({SubscriptionState.HISTORY, SubscriptionState.LIVE,
                      SubscriptionState.LAGGING})

S = SubscriptionState
TRANSITIONS: dict[SubscriptionState, frozenset[SubscriptionState]] = {
    S.HISTORY: frozenset({S.LIVE, S.ENDED, S.CLOSED}),
    S.LIVE: frozenset({S.LAGGING, S.ENDED, S.CLOSED}),
    S.LAGGING: frozenset({S.LIVE, S.ENDED, S.CLOSED}),
    S.ENDED: frozenset({S.FINISHED, S.CLOSED}),
    S.FINISHED: frozenset({S.CLOSED}),
    S.CLOSED: frozenset(),
}
"""The allowed changes of state: ``TRANSITIONS[old]`` is the set of states ``old`` may become."""


class IllegalTransition(SLRError):
    """A subscription was asked to change from a state to one :data:`TRANSITIONS` does not
    allow (a bug in the caller: the change is refused and the state kept)."""

    def __init__(self, old: SubscriptionState, new: SubscriptionState):
        super().__init__(f"a subscription cannot go from {old.value} to {new.value}")
        self.old = old
        self.new = new


class SubscriptionOverflow(SLRError):
    """A subscription fell more than ``max_lag`` events behind the events it must deliver and
    was ended (after every answer it had queued was taken; nothing was skipped). ``behind``
    is how many journal rows it had not read; a durable subscription resumes where it
    stopped when subscribed again with the same id."""

    def __init__(self, message: str, behind: int, subscription_id: str):
        super().__init__(message)
        self.behind = behind
        self.subscription_id = subscription_id


class QueueOwner(Protocol):
    """What a subscription needs from its hub."""

    def notify(self, through_store: bool = False) -> None: ...

    def taken_end(self, sub: "Subscription") -> None: ...

    def release(self, sub: "Subscription", forget: bool) -> None: ...


class _End:
    """Queue marker: no more answers (``error`` None) or the subscription failed."""

    __slots__ = ("error",)

    def __init__(self, error: BaseException | None = None):
        self.error = error


def resolve_threadsafe(loop: Any, futures: list) -> None:
    """Resolve asyncio ``futures`` of ``loop`` from another thread (nothing if it closed).

    >>> import asyncio, threading
    >>> loop = asyncio.new_event_loop(); waiting = loop.create_future()
    >>> worker = threading.Thread(target=resolve_threadsafe, args=(loop, [waiting]))
    >>> worker.start(); worker.join()
    >>> loop.run_until_complete(waiting), waiting.done()
    (None, True)
    >>> loop.close(); resolve_threadsafe(loop, [loop.create_future()])  # closed: nothing happens
    """
    try:
        loop.call_soon_threadsafe(_resolve, futures)
    except RuntimeError:  # the loop is closed: nobody waits any more
        pass


def _resolve(futures: list) -> None:
    for f in futures:
        if not f.done():
            f.set_result(None)


class Subscription:
    """One subscription (made by :meth:`slr_sql.KnowledgeBase.subscribe`).

    Consume it with ``for answer in sub``, ``async for answer in sub``, ``sub.get(timeout)``,
    or give ``callback=`` to ``subscribe``. ``close()`` unregisters it (a durable one keeps its
    position; ``close(forget=True)`` removes it). Attributes: ``id``, ``pattern``, ``where``,
    ``since``, ``until``, ``durable``, ``max_queue``, ``max_lag``, ``delivered`` (answers
    taken), ``overflows`` (times its queue was full, so that it fell back to reading the
    store), ``lagging`` (reading the store at its own pace now), ``state``
    (:class:`SubscriptionState`), ``error`` (what ended it, if anything).

    >>> import slr_sql
    >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0)); sub = kb.subscribe("p(X)^T", since=0)
    >>> kb.add("p(a)^1"); sub.get(timeout=5)
    {'X': Atom('a'), 'T': 1.0}
    >>> sub.close(); kb.close()
    """

    def __init__(self, hub: QueueOwner, matcher: Matcher, sub_id: str, durable: bool,
                 since: float, until: float | None, max_queue: int, max_lag: int | None,
                 callback: Callable[[dict], Any] | None):
        self._hub = hub
        self.matcher = matcher
        self.id = sub_id
        self.pattern = matcher.pattern
        self.where = matcher.where
        self.key = matcher.key
        self.durable = durable
        self.since = since
        self.until = until
        self.max_queue = max_queue
        self.max_lag = max_lag
        self.callback = callback
        self.delivered = 0
        self.overflows = 0
        self.error: BaseException | None = None
        self._lock = ordered_lock("subscription")
        self._cond = threading.Condition(self._lock)
        self._state = SubscriptionState.HISTORY
        self._closed_from: SubscriptionState | None = None
        self._completed = False      # the end queued was `until` reached (not an error)
        # pairs: a position code (int; None before the end marker), then the answer dict (the
        # same object for every subscription with the same answers: copied when taken) or _End.
        # Ints are not tracked by the garbage collector and the dicts are shared, so queued
        # answers cost the collector (whose full passes are latency spikes) next to nothing.
        self._queue: collections.deque = collections.deque()
        self._in_flight: int | None = None        # position code of the answer taken last
        # position codes of the answers taken with handled=False and not acknowledged yet, in
        # order (the network service's clients acknowledge what they handled)
        self._unacked: collections.deque = collections.deque()
        self._thread_waiting = 0
        self._async_waiter: tuple[Any, Any] | None = None
        # the waiter registered by the batch that emptied the queue, for next_answers' next
        # call to wait on (it is no longer the one when another wait replaced it)
        self._next_waiter: tuple[Any, Any] | None = None
        self._final_position: tuple[int, int] | None = None   # set by close()
        self._thread: threading.Thread | None = None
        # positions (the hub thread moves them, under the lock together with the queue)
        self.phase = HISTORY_PHASE
        self.history_top = 0
        self.history_pos = 0
        self.live_start = 0
        self.scanned = 0             # last journal jid passed (phase LIVE_PHASE)
        # the hub's bookkeeping of this subscription
        self.until_reached = False   # set by the synchronizer's answer: the end may come
        self.end_jid: int | None = None    # the journal's head when until was reached
        self.pending: Any = None     # the kb.submit PendingQuery that waits for `until`
        self.persisted: tuple | None = None   # the position written last
        self.history_by_end: bool | None = None   # how its history is read (None: not yet)
        self.cohort_key: tuple = (matcher, since, until)   # same key, same answers

    def __repr__(self) -> str:
        state = self._state
        shown = "ended" if state is S.FINISHED else state.value
        return (f"<Subscription {self.id!r} {self.pattern!r}"
                f"{' where ' + repr(self.where) if self.where else ''}: {shown}, "
                f"{self.delivered} delivered>")

    # -- state ----------------------------------------------------------------------------------
    @property
    def state(self) -> SubscriptionState:
        """Its :class:`SubscriptionState`."""
        return self._state

    def _to(self, new: SubscriptionState) -> None:
        """Change the state (the lock held); raises :class:`IllegalTransition` for a change
        :data:`TRANSITIONS` does not allow."""
        if new not in TRANSITIONS[self._state]:
            raise IllegalTransition(self._state, new)
        self._state = new

    @property
    def closed_from(self) -> SubscriptionState | None:
        """The state it was in when it was closed (None while it is not closed)."""
        return self._closed_from

    @property
    def closed(self) -> bool:
        """True once closed or ended (until reached, overflow, error) and taken."""
        return self._state is S.CLOSED or self._state is S.FINISHED

    @property
    def lagging(self) -> bool:
        """Reading the store at its own pace (its queue was full)."""
        return self._state is S.LAGGING

    @property
    def is_over(self) -> bool:
        """The hub is done with it: ended (an end queued), finished or closed."""
        return self._state not in _RUNNING

    @property
    def completed(self) -> bool:
        """Everything up to ``until`` was delivered and the consumer took the end: a durable
        subscription is recorded as finished."""
        return self._completed and S.FINISHED in (self._state, self._closed_from)

    @property
    def queued(self) -> int:
        """Answers waiting in memory for the consumer (at most ``max_queue``)."""
        with self._lock:
            return sum(1 for item in self._queue if type(item) is dict)

    def position(self) -> tuple[int, int]:
        """``(phase, n)``: every event up to it was handled (phase 0: history, n a ``seq`` of the
        type's table; phase 1: live, n a ``jid`` of its journal). What a durable subscription
        persists."""
        with self._lock:
            return self._position_locked()

    @property
    def unacknowledged(self) -> int:
        """Answers taken with ``next_answers(handled=False)`` and not acknowledged yet."""
        with self._lock:
            return len(self._unacked)

    def _position_locked(self) -> tuple[int, int]:
        if self._final_position is not None:
            return self._final_position
        if self._unacked:                    # codes grow: the first unhandled answer is the
            first = self._unacked[0]         # smaller of the two
            if self._in_flight is not None and self._in_flight < first:
                first = self._in_flight
            return _decode_position(first - 1)
        if self._in_flight is not None:
            return _decode_position(self._in_flight - 1)
        queue = self._queue
        if queue and queue[0] is not None:
            return _decode_position(queue[0] - 1)
        if self.phase == HISTORY_PHASE:
            return HISTORY_PHASE, self.history_pos
        return LIVE_PHASE, self.scanned

    def _refills(self) -> bool:
        return self._state is S.LAGGING or self._state is S.HISTORY

    # -- consuming ------------------------------------------------------------------------------
    def _take(self, timeout: float | None, block: bool = True) -> Any:
        """The next answer (a dict of its own), or an _End; None when nothing came within
        ``timeout``. Taking it marks the previous one handled."""
        with self._lock:
            self._in_flight = None           # the consumer is back: the previous one is done
            queue = self._queue
            if not queue and block and self._state is not S.CLOSED:
                deadline = None if timeout is None else time.monotonic() + timeout
                while not queue and self._state is not S.CLOSED:
                    left = None if deadline is None else deadline - time.monotonic()
                    if left is not None and left <= 0:
                        break
                    self._thread_waiting += 1
                    try:
                        self._cond.wait(left)
                    finally:
                        self._thread_waiting -= 1
            if not queue:
                return _End(self.error) if self._state is S.CLOSED else None
            code = queue.popleft()
            item = queue.popleft()
            if code is None:
                self._to(S.FINISHED)
            else:
                self._in_flight = code
                self.delivered += 1
                refill = len(queue) >> 1 == self.max_queue >> 1 and self._refills()
        if code is None:
            self._hub.taken_end(self)
            return item
        if refill:                           # room again: the hub reads on from the store
            self._hub.notify()
        return dict(item)

    def get(self, timeout: float | None = None) -> dict | None:
        """The next answer; None once the subscription has ended (``until`` reached or
        closed). Raises SLRTimeout when none came within ``timeout`` seconds, and the error
        that ended the subscription (e.g. :class:`SubscriptionOverflow`) after the answers
        queued before it. ``timeout``: seconds >= 0, None or ``inf`` for ever (anything
        else is an SLRError).

        >>> import slr_sql
        >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0)); sub = kb.subscribe("p(X)^T")
        >>> sub.get(timeout=float("nan"))
        Traceback (most recent call last):
        ...
        slr_sql.errors.SLRError: get: timeout must be a number of seconds >= 0, not nan
        >>> sub.close(); kb.close()
        """
        wait = wait_seconds("get: timeout", timeout)
        self._check_pull()
        item = self._take(wait)
        if item is None:
            raise SLRTimeout(f"subscription {self.id!r}: no event within {timeout:g} s")
        if type(item) is _End:
            if item.error is not None:
                raise item.error
            return None
        return item

    def _check_pull(self) -> None:
        if self.callback is not None:
            raise SLRError(f"subscription {self.id!r} delivers to its callback; it cannot also "
                           f"be iterated")

    def __iter__(self) -> "Subscription":
        self._check_pull()
        return self

    def __next__(self) -> dict:
        item = self._take(None)
        if type(item) is _End:
            if item.error is not None:
                raise item.error
            raise StopIteration
        return item

    def __aiter__(self) -> "Subscription":
        self._check_pull()
        return self

    async def __anext__(self) -> dict:
        while True:
            item = self._take(None, block=False)
            if item is not None:
                if type(item) is _End:
                    if item.error is not None:
                        raise item.error
                    raise StopAsyncIteration
                return item
            await self._wait_async()

    async def _wait_async(self, acks: bool = False) -> None:
        """Wait on the running loop until something is queued or the subscription closed (the
        hub resolves the future through ``call_soon_threadsafe``, once per loop per pass);
        ``acks``: until every answer taken was acknowledged, or closed."""
        import asyncio   # (here: a process that never awaits a subscription need not load it)

        loop = asyncio.get_running_loop()
        future = loop.create_future()
        with self._lock:
            if (not self._unacked if acks else self._queue) or self._state is S.CLOSED:
                return
            self._async_waiter = waiter = (loop, future)
        try:
            await future
        finally:
            self._forget_waiter(waiter)

    def _forget_waiter(self, waiter: tuple | None) -> None:
        """After an async wait: take back ``waiter`` (this wait's own) if nothing woke it (a
        cancelled wait). Only this wait ever sets it and every other change replaces or clears
        it, so once it is seen gone (the common case: the hub's wake took it) it stays gone:
        no lock then."""
        if waiter is None or self._async_waiter is not waiter:
            return
        with self._lock:
            if self._async_waiter is waiter:
                self._async_waiter = None

    async def next_answers(self, limit: int, copy: bool = True,
                           handled: bool = True) -> list[dict]:
        """Wait (on the running asyncio loop) for the next answer, then return it with the
        answers queued behind it, ``limit`` at most, in order; ``[]`` once the subscription
        has ended; raises the error that ended it after the answers queued before it. Taking
        a batch marks the previous batch handled (the position of a durable subscription moves
        past it), as taking one answer does. ``copy=False`` returns the queued answer dicts
        themselves, shared with every subscription that has the same answers: the caller must
        not change them (what the service does to encode each answer once for all its
        WebSocket subscribers).

        ``handled=False``: taking a batch marks nothing handled; the answers taken stay
        unhandled until :meth:`acknowledge` says so (what the service does for clients that
        acknowledge). The end of the subscription then comes only once every answer taken
        was acknowledged (it waits for that), so a durable subscription is recorded as
        finished only when its consumer handled everything.

        >>> import asyncio, slr_sql
        >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0)); sub = kb.subscribe("p(X)^T", since=0)
        >>> rejected = kb.add_many(["p(a)^1", "p(b)^2"])
        >>> asyncio.run(sub.next_answers(10))
        [{'X': Atom('a'), 'T': 1.0}, {'X': Atom('b'), 'T': 2.0}]
        >>> sub.close(); kb.close()
        """
        self._check_pull()
        import asyncio   # (see _wait_async)

        loop = asyncio.get_running_loop()
        waiter, self._next_waiter = self._next_waiter, None
        if waiter is not None and waiter is self._async_waiter and waiter[0] is loop and \
                not self._queue:
            # registered by the last call's batch, which emptied the queue, and still nobody
            # else's: what is queued from then on resolves it, so this wait takes no lock
            # (one lock per frame of the service: taking the batch)
            try:
                await waiter[1]
            finally:
                self._forget_waiter(waiter)
        while True:
            waiter = (loop, loop.create_future())
            got = self._take_batch(limit, handled, waiter)
            if type(got) is _End:
                if got.error is not None:
                    raise got.error
                return []
            if got:
                return [dict(a) for a in got] if copy else got
            if got is None:
                await self._wait_async(acks=True)
            else:
                # registered by _take_batch under the lock that found the queue empty: one
                # lock for looking and waiting
                try:
                    await waiter[1]
                finally:
                    self._forget_waiter(waiter)

    def take_answers(self, limit: int, waker: tuple[Any, Any]) -> list[dict] | None:
        """The answers queued now, ``limit`` at most, in order, never waiting: the shared
        dicts, as ``next_answers(copy=False)`` returns them (the caller must not change
        them); ``None`` once the subscription has ended; raises the error that ended it after
        the answers queued before it. Taking a batch marks the previous one handled.

        ``waker`` is ``(loop, obj)``: when ``[]`` is returned or the batch taken empties the
        queue, it is registered, and the hub calls ``obj.set_result(None)`` on ``loop``
        (unless ``obj.done()``) once something more is queued or the subscription ends; when
        :meth:`waits_with` then says it is not registered, something is queued behind the
        batch (answers beyond ``limit``, or the end): take again. This is how the service
        delivers every caught-up WebSocket subscriber of a pass in one callback of its loop
        instead of resuming one coroutine each.

        >>> import asyncio, slr_sql
        >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0)); sub = kb.subscribe("p(X)^T", since=0)
        >>> loop = asyncio.new_event_loop(); waker = (loop, loop.create_future())
        >>> sub.take_answers(10, waker), sub.waits_with(waker)     # nothing queued yet
        ([], True)
        >>> rejected = kb.add_many(["p(a)^1"])
        >>> loop.run_until_complete(waker[1])     # the hub queued the answer and woke it
        >>> waker = (loop, loop.create_future())
        >>> sub.take_answers(10, waker), sub.waits_with(waker)
        ([{'X': Atom('a'), 'T': 1.0}], True)
        >>> sub.close(); loop.close(); kb.close()
        """
        self._check_pull()
        got = self._take_batch(limit, True, waker, remember=False)
        if type(got) is _End:
            if got.error is not None:
                raise got.error
            return None
        return got

    def waits_with(self, waker: tuple[Any, Any]) -> bool:
        """``waker`` (given to the last :meth:`take_answers`) is registered and nothing has
        woken it yet: the queue was empty after that take, and what is queued next wakes it.
        False: the take left something queued (take again), or the hub or ``close()`` has
        woken the waker since (it runs on its loop, and a take then finds what woke it).

        >>> import asyncio, slr_sql
        >>> kb = slr_sql.open(); sub = kb.subscribe("p(X)^T")
        >>> loop = asyncio.new_event_loop(); waker = (loop, loop.create_future())
        >>> sub.waits_with(waker), sub.take_answers(10, waker), sub.waits_with(waker)
        (False, [], True)
        >>> sub.close(); loop.close(); kb.close()
        """
        return self._async_waiter is waker

    def acknowledge(self, count: int) -> None:
        """Mark the first ``count`` answers taken with ``next_answers(handled=False)`` and
        not acknowledged yet handled, in order: the position of a durable subscription moves
        past the last of them (written as usual, every 0.2 s and at close). Answers never
        acknowledged stay unhandled, also when the subscription is closed: a durable
        subscription delivers them again. Callable from any thread.

        >>> import asyncio, slr_sql
        >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0)); sub = kb.subscribe("p(X)^T", since=0)
        >>> rejected = kb.add_many(["p(a)^1", "p(b)^2"])
        >>> len(asyncio.run(sub.next_answers(10, handled=False))), sub.unacknowledged
        (2, 2)
        >>> sub.acknowledge(1); sub.unacknowledged
        1
        >>> sub.close(); kb.close()
        """
        if type(count) is not int or count < 0:
            raise SLRError(f"subscription {self.id!r}: acknowledge() takes a count >= 0, "
                           f"not {count!r}")
        with self._lock:
            unacked = self._unacked
            if count > len(unacked):
                raise SLRError(f"subscription {self.id!r}: {count} answers acknowledged, but "
                               f"only {len(unacked)} were taken and not acknowledged")
            if self._final_position is not None:     # closed: its position is written
                return
            for _ in range(count):
                unacked.popleft()
            waiter = None
            if not unacked and self._async_waiter is not None:
                waiter, self._async_waiter = self._async_waiter, None
        if waiter is not None:               # an end waits for the acknowledgements
            resolve_threadsafe(waiter[0], [waiter[1]])

    def _take_batch(self, limit: int, handled: bool = True,
                    waiter: tuple | None = None, remember: bool = True) -> Any:
        """Up to ``limit`` queued answers (the shared dicts), never waiting: ``[]`` when none is
        queued, the _End when it is next (never after answers taken in the same call, so
        those are handled before the end closes the subscription). One lock for the batch.
        ``handled=False``: the batch goes to the unacknowledged answers (the previous one
        is not marked handled), and an end waits for them to be acknowledged (None then).
        ``waiter`` ``(loop, future)``: registered, when ``[]`` is returned or the batch taken
        empties the queue, as the waiter the hub resolves once something is queued
        (``remember``: also as the one the next ``next_answers`` awaits)."""
        with self._lock:
            if handled:
                self._in_flight = None       # the consumer is back: the previous batch is done
            queue = self._queue
            if not queue:
                if self._state is S.CLOSED:
                    return _End(self.error)
                if waiter is not None:
                    self._async_waiter = waiter
                return []
            if queue[0] is None and not handled and self._unacked:
                return None                  # the end after the acknowledgements
            if queue[0] is None:              # the end marker
                queue.popleft()
                end = queue.popleft()
                self._to(S.FINISHED)
                taken = None
            else:
                before = len(queue) >> 1
                if before <= limit and queue[-2] is not None:
                    # all of it and no end (an end is always the last pair: nothing is queued
                    # after it): taken in one go, as a frame of the service typically is
                    items = list(queue)
                    queue.clear()
                    taken = items[1::2]
                    if waiter is not None:       # what comes next wakes the next call
                        self._async_waiter = waiter
                        if remember:             # (next_answers awaits it next time)
                            self._next_waiter = waiter
                    if handled:
                        self._in_flight = items[0]   # the batch is in the consumer's hands
                    else:
                        self._unacked.extend(items[0::2])
                elif handled:
                    taken = []
                    self._in_flight = queue[0]   # the batch is in the consumer's hands
                    while queue and len(taken) < limit and queue[0] is not None:
                        queue.popleft()
                        taken.append(queue.popleft())
                else:
                    taken = []
                    unacked = self._unacked
                    while queue and len(taken) < limit and queue[0] is not None:
                        unacked.append(queue.popleft())
                        taken.append(queue.popleft())
                self.delivered += len(taken)
                half = self.max_queue >> 1
                refill = before > half >= len(queue) >> 1 and self._refills()
        if taken is None:
            self._hub.taken_end(self)
            return end
        if refill:                           # room again: the hub reads on from the store
            self._hub.notify()
        return taken

    def wait(self, timeout: float | None = None) -> bool:
        """Wait until a callback subscription has ended (``until`` reached, closed, or failed);
        True if it has, False on timeout (seconds >= 0, None or ``inf`` for ever). Raises
        the error that ended it."""
        timeout = wait_seconds("wait: timeout", timeout)
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout)
            if self._thread.is_alive():
                return False
        else:
            deadline = None if timeout is None else time.monotonic() + timeout
            with self._cond:
                while self._state in _RUNNING:
                    left = None if deadline is None else deadline - time.monotonic()
                    if left is not None and left <= 0:
                        return False
                    self._thread_waiting += 1
                    try:
                        self._cond.wait(left)
                    finally:
                        self._thread_waiting -= 1
        if self.error is not None:
            raise self.error
        return True

    def start_callback(self) -> None:
        """Deliver to ``callback`` on a thread of its own (until the end or a failure)."""
        self._thread = threading.Thread(target=self._run_callback, daemon=True,
                                        name=f"slr-subscription-{self.id}")
        self._thread.start()

    def _run_callback(self) -> None:
        fn = self.callback
        assert fn is not None
        while True:
            item = self._take(None)
            if type(item) is _End:
                if item.error is not None:
                    log.warning("subscription %r ended: %s", self.id, item.error)
                return
            try:
                fn(item)
            except BaseException as exc:  # the callback's failure ends its subscription
                log.exception("subscription %r: the callback raised; the subscription ends",
                              self.id)
                self.error = exc
                self.close(ack=False)
                return

    # -- closing --------------------------------------------------------------------------------
    def close(self, forget: bool = False, ack: bool = True, join: bool = True) -> None:
        """Unregister. A durable subscription keeps its position (the last answer taken counts
        as handled unless ``ack=False``); ``forget=True`` removes its record too. Answers still
        queued are dropped here and delivered again when a durable subscription resumes.
        Each flag is True or False, else an :class:`SLRError` (before anything is closed).

        >>> import slr_sql; kb = slr_sql.open(clock=slr_sql.ManualClock(10))
        >>> sub = kb.subscribe("p(X)^T"); sub.close(ack="no")
        Traceback (most recent call last):
        ...
        slr_sql.errors.SLRError: close: ack must be True or False, not 'no'
        >>> sub.close(); sub.closed
        True
        >>> kb.close()
        """
        check_flag("close: forget", forget)
        check_flag("close: ack", ack)
        check_flag("close: join", join)
        with self._cond:
            if self._state is S.CLOSED and not forget:
                return
            if self._state is not S.CLOSED:
                if ack:
                    self._in_flight = None
                self._final_position = self._position_locked()
                self._queue.clear()
                self._closed_from = self._state
                self._to(S.CLOSED)
            self._cond.notify_all()
            waiter, self._async_waiter = self._async_waiter, None
            self._next_waiter = None     # (it may hold its consumer, which holds this)
        if waiter is not None:
            resolve_threadsafe(waiter[0], [waiter[1]])
        self._hub.release(self, forget)
        if join:
            self.join_callback()

    def join_callback(self, timeout: float = 5.0) -> None:
        """Wait (``timeout`` s at most) for the callback thread, unless called from it."""
        thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout=timeout)

    def __enter__(self) -> "Subscription":
        return self

    def __exit__(self, exc_type: Any, *rest: Any) -> None:
        self.close(ack=exc_type is None)

    # -- hub side (the hub thread) --------------------------------------------------------------
    def start_at(self, phase: int, history_top: int, history_pos: int, live_start: int,
                 scanned: int) -> None:
        """Registration: where delivery starts (a new subscription, or a durable one
        resuming); a live phase makes it LIVE."""
        with self._lock:
            self.history_top, self.history_pos = history_top, history_pos
            self.live_start, self.scanned = live_start, scanned
            if phase == LIVE_PHASE:
                self.phase = LIVE_PHASE
                if self._state is S.HISTORY:
                    self._to(S.LIVE)

    def room(self) -> int:
        """How many more answers its queue takes now (read without the lock: a hint)."""
        return self.max_queue - (len(self._queue) >> 1)

    def offer_all(self, flat: list, count: int, last_jid: int, loops: dict | None = None) -> bool:
        """Queue ``count`` answers (``flat``: ``[jid, answer, ...]``) and pass the journal up to
        ``last_jid``, if all of them fit and it is running; False (nothing done) otherwise.
        ``loops``: when answers were queued, an async consumer waiting for them is handed
        over there (its future appended to ``loops[its loop]``, for the caller to resolve as
        :meth:`wake` would have collected it): one lock for queueing and waking."""
        with self._lock:
            queue = self._queue
            if self._state not in _RUNNING or (len(queue) >> 1) + count > self.max_queue:
                return False
            queue.extend(flat)
            self.scanned = last_jid
            waiter = self._async_waiter
            if waiter is not None and count and loops is not None:
                self._async_waiter = None
                loops.setdefault(waiter[0], []).append(waiter[1])
            return True

    def offer_batch(self, phase: int, batch: list, end_pos: int) -> bool:
        """Queue ``batch`` ``[(pos, answer)]`` (in order) and pass every row up to ``end_pos``.
        When the queue cannot take all of it, queue what fits, pass the rows before the first
        answer left out, and return False (the hub reads the rest from the store later)."""
        with self._lock:
            if self._state not in _RUNNING:
                return True
            queue = self._queue
            room = self.max_queue - (len(queue) >> 1)
            taken = batch if len(batch) <= room else batch[:max(room, 0)]
            for pos, answer in taken:
                queue.append(_code(phase, pos))
                queue.append(answer)
            if len(taken) < len(batch):
                end_pos = batch[len(taken)][0] - 1
            if phase == LIVE_PHASE:
                if end_pos > self.scanned:
                    self.scanned = end_pos
            elif end_pos > self.history_pos:
                self.history_pos = end_pos
            return len(taken) == len(batch)

    def end(self, error: BaseException | None = None, completed: bool = False) -> None:
        """Queue the end after the answers queued (``error``: what ended it; ``completed``:
        everything up to ``until`` was delivered). Nothing if it is over already."""
        with self._lock:
            if self._state not in _RUNNING:
                return
            self._to(S.ENDED)
            self._completed = completed
            if error is not None and self.error is None:
                self.error = error
            self._queue.append(None)
            self._queue.append(_End(error))

    def go_live(self) -> None:
        """Its history was delivered: read the journal from ``live_start`` on."""
        with self._lock:
            self.phase = LIVE_PHASE
            self.scanned = max(self.scanned, self.live_start)
            if self._state is S.HISTORY:
                self._to(S.LIVE)

    def fall_behind(self) -> None:
        """Its queue is full: it leaves the shared read (LIVE to LAGGING)."""
        with self._lock:
            if self._state is S.LIVE:
                self._to(S.LAGGING)

    def catch_up(self) -> None:
        """It has room again and is read with the others (LAGGING to LIVE)."""
        with self._lock:
            if self._state is S.LAGGING:
                self._to(S.LIVE)

    def wake(self, loops: dict) -> None:
        """Wake a consumer waiting on this subscription (async ones are collected per loop).
        Called after the answers were queued under the lock: a consumer registers as waiting
        under the same lock only after seeing an empty queue, so the flags read here without
        the lock cannot miss one that waits for these answers."""
        if not self._thread_waiting and self._async_waiter is None:
            return
        with self._lock:
            if self._thread_waiting:
                self._cond.notify_all()
            if self._async_waiter is not None:
                loop, future = self._async_waiter
                self._async_waiter = None
                loops.setdefault(loop, []).append(future)
