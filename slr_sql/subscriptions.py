"""Subscriptions: deliver each stored event matching a pattern, once, in arrival order, to an
iterator, an async iterator or a callback (docs/subscriptions.md).

``sub = kb.subscribe("face(F, R)^T", where="R > 60", since=0)`` is the event-processing
paper's ``register(ID, s_win(since, until, ⟨face(F, R), R > 60⟩))``.

How it works
------------

* **Journal.** While some subscription (of any process) subscribes to event type p/N, an
  ``AFTER INSERT`` trigger on p/N's table copies every new row into ``slr_subj_<table>``,
  whose ``jid`` (AUTOINCREMENT: never reused) is the arrival order. Events stored by any
  process, by event rules, or by ``INSERT`` statements are journaled in the transaction that
  stores them, so a buffer that prunes an event right after it arrived (``cBuffer(.., 1)``)
  cannot take it away from a subscriber that has not read it yet.
* **Registration** runs in one write transaction: install the trigger, read the type's
  greatest ``seq`` (the history is the stored rows up to it) and the journal's greatest
  ``jid`` (live events are the rows after it). Nothing committed can fall between the two:
  no gap and no duplicate at the seam between history and live.
* **Delivery.** One hub thread per knowledge base reads the journal of each subscribed type
  once for all its subscriptions (woken by ``kb.add`` through ``kb.add_listeners``, and every
  ``poll_interval`` seconds to see rows other processes committed), matches
  each row against each pattern and condition, and appends the answers to each
  subscription's bounded queue. ``add`` never waits for a subscriber.
* **Slow subscribers.** A subscription whose queue is full stops taking answers from the
  shared read and later reads the journal itself, at its own pace: nothing is dropped. One
  that falls more than ``max_lag`` events behind ends with :class:`SubscriptionOverflow`
  after its queued answers (the journal would otherwise grow without bound).
* **Durable** subscriptions (``id=``) keep their definition and position in
  ``slr_subscriptions``; the position moves when the consumer has taken the next answer (or
  the callback returned), so a restart resumes after the last answer handled, at least once.
* **until** ends a subscription once the type's history is complete up to ``until``
  (completeness as for synchronized queries: a pending ``kb.submit`` of
  ``prev(p(_..)^_, until)`` at ``until`` tells when) and everything stored by then was
  delivered.

This module sits beside sync and buffers: it gets the knowledge base as an object and uses
its public methods (``query``, ``submit``, ``add_listeners``; and the synchronizer's
``watch_external``, so that marks other processes write end an ``until``) and the store's.
"""
from __future__ import annotations

import asyncio
import collections
import itertools
import json
import logging
import math
import os
import socket
import threading
import time
import uuid
import warnings
from typing import Any, Callable

from .clocks import DEFAULT_MAX_LEARNED_DELAY, LearnedDelayWarning
from .encoding import decode, encode_json
from .errors import SLRError, SLRSyntaxError, SLRTimeout
from .host import Host
from .parser import parse_term
from .program import split_event_atom
from .store import quote_identifier
from .store.checks import shown
from .terms import Atom, String, Struct, Var, deref, format_atom, make_list, to_python
from .unify import undo, unify

__all__ = ["Subscription", "SubscriptionOverflow", "SubscriptionHub", "attach", "answer_json",
           "journal_table", "DEFAULT_MAX_QUEUE", "DEFAULT_MAX_LAG"]

log = logging.getLogger("slr_sql.subscriptions")

DEFAULT_MAX_QUEUE = 10_000     # answers held in memory per subscription
DEFAULT_MAX_LAG = 1_000_000    # journal rows a subscription may fall behind before it ends
CHUNK = 512                    # rows per read
FEW_HISTORY = 4096             # a history window this small is read by end time
POLL_INTERVAL = 0.05           # s between journal polls (rows other processes committed)
PERSIST_INTERVAL = 0.2         # s between writes of durable positions
LEASE_SECONDS = 30.0           # wall-clock s a process's claim on its subscriptions lasts
CLEANUP_INTERVAL = 1.0         # s between journal trims (when something was delivered)
JOURNAL_PREFIX = "slr_subj_"
TRIGGER_PREFIX = "slr_subt_"

_INF = math.inf
_HISTORY, _LIVE = 0, 1         # phases of a position: (phase, seq or jid)
_H = 2 ** 62                   # queued positions are one int: jid (live) or seq - _H (history)


def _code(phase: int, pos: int) -> int:
    return pos if phase == _LIVE else pos - _H


def _decode_position(code: int) -> tuple[int, int]:
    return (_LIVE, code) if code >= 0 else (_HISTORY, code + _H)


class SubscriptionOverflow(SLRError):
    """A subscription fell more than ``max_lag`` events behind the events it must deliver and
    was ended (after every answer it had queued was taken; nothing was skipped). ``behind``
    is how many journal rows it had not read; a durable subscription resumes where it
    stopped when subscribed again with the same id."""

    def __init__(self, message: str, behind: int, subscription_id: str):
        super().__init__(message)
        self.behind = behind
        self.subscription_id = subscription_id


def journal_table(table: str) -> str:
    """The journal of an event table: ``slr_subj_<table>``.

    >>> journal_table("face")
    'slr_subj_face'
    """
    return JOURNAL_PREFIX + table


def answer_json(answer: dict[str, Any]) -> str:
    """One answer as a JSON object, each value in the store's JSON encoding of terms
    (docs/schema.md): atoms as JSON strings, strings ``{"$string": ..}``, integers and floats
    as JSON numbers (a float always with a ``.`` or an exponent), lists as arrays, compounds
    ``{"f": [..]}``.

    >>> answer_json({"F": Atom("antonio"), "R": 65, "T": 2.0, "S": "hi", "P": [1, 2.5]})
    '{"F":"antonio","R":65,"T":2.0,"S":{"$string":"hi"},"P":[1,2.5]}'
    """
    parts = [json.dumps(str(name)) + ":" + encode_json(_answer_term(value))
             for name, value in answer.items()]
    return "{" + ",".join(parts) + "}"


def _answer_term(value: Any) -> Any:
    """A value of an answer dict back as a term: ``Atom`` stays an atom, a plain ``str`` (how
    answers return strings) is a string."""
    tv = type(value)
    if tv is Atom or tv is int or tv is float:
        return value
    if tv is str or tv is String:
        return String(value)
    if tv is bool:
        return Atom("true" if value else "false")
    if isinstance(value, (list, tuple)):
        return make_list([_answer_term(v) for v in value])
    if tv is Struct:
        return Struct(value.name, tuple(_answer_term(a) for a in value.args))
    if tv is Var:
        raise SLRError("an answer with an unbound variable has no JSON form")
    return value


# ----------------------------------------------------------------------------- patterns

def _pattern_error(text: str, message: str) -> SLRSyntaxError:
    return SLRSyntaxError(message, line=1, column=1, source_line=text.strip(),
                          filename="<pattern>")


class _Matcher:
    """A pattern and condition, compiled: ``match(args, start, end)`` gives the answer dict or
    None. One matcher serves every subscription with the same texts (the hub thread only)."""

    def __init__(self, kb: Host, pattern: str, where: str | None):
        self.kb = kb
        self.pattern = pattern
        self.where = where
        term, varnames = parse_term(pattern, "<pattern>")
        ev = split_event_atom(term)
        if ev is None:
            raise _pattern_error(pattern, "a subscription pattern is an event atom "
                                          "p(...)^T or p(...)^[S,E]")
        atom, s, e = ev
        for stamp in (s, e):
            d = deref(stamp)
            if type(d) is not Var and type(d) not in (int, float):
                raise _pattern_error(pattern, "the time of a subscription pattern must be a "
                                              "variable or a number")
        atom = deref(atom)
        if type(atom) is Struct:
            self.name, self.args = str(atom.name), tuple(atom.args)
        else:
            self.name, self.args = str(atom), ()
        self.arity = len(self.args)
        self.key = (self.name, self.arity)
        self.point = s is e
        self.start, self.end = s, e
        self.vars = [(n, v) for n, v in varnames.items()]
        self.answer_vars = [(n, v) for n, v in self.vars if not n.startswith("_")]
        self.where_bind: list[tuple[str, Var]] = []
        if where is not None:
            _, where_vars = parse_term(where, "<where>")
            pattern_vars = dict(self.vars)
            self.where_bind = [(n, pattern_vars[n]) for n in where_vars if n in pattern_vars]

    def match(self, args: tuple, start: float, end: float) -> dict | None:
        trail: list = []
        try:
            for p, v in zip(self.args, args):
                if not unify(p, v, trail):
                    return None
            stamps = ((self.end, end),) if self.point else ((self.start, start), (self.end, end))
            for stamp, value in stamps:
                d = deref(stamp)
                if type(d) is Var:
                    d.ref = value
                    trail.append(d)
                elif type(d) is int or type(d) is float:
                    if d != value:       # times match by value: 5 == 5.0
                        return None
                else:
                    return None
            answer = {name: to_python(var) for name, var in self.answer_vars}
            if self.where is not None:
                bound = {name: deref(var) for name, var in self.where_bind}
                rows = self.kb.query(self.where, args=bound or None, limit=1)
                if not rows:
                    return None
                for name, value in rows[0].items():
                    if name not in answer and not name.startswith("_"):
                        answer[name] = value
            return answer
        finally:
            undo(trail, 0)


def _time_arg(value: Any, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SLRError(f"subscribe: {what} must be a number of seconds, not {shown(value)}")
    try:
        value = float(value)
    except OverflowError:
        raise SLRError(f"subscribe: {what} is out of range (an integer of "
                       f"{value.bit_length()} bits; a time is a float)") from None
    if math.isnan(value):
        raise SLRError(f"subscribe: {what} must be a number, not NaN")
    return value


# ----------------------------------------------------------------------------- subscriptions

class _End:
    """Queue marker: no more answers (``error`` None) or the subscription failed."""

    __slots__ = ("error",)

    def __init__(self, error: BaseException | None = None):
        self.error = error


class Subscription:
    """One subscription (made by :meth:`slr_sql.KnowledgeBase.subscribe`).

    Consume it with ``for answer in sub``, ``async for answer in sub``, ``sub.get(timeout)``,
    or give ``callback=`` to ``subscribe``. ``close()`` unregisters it (a durable one keeps its
    position; ``close(forget=True)`` removes it). Attributes: ``id``, ``pattern``, ``where``,
    ``since``, ``until``, ``durable``, ``max_queue``, ``max_lag``, ``delivered`` (answers
    taken), ``overflows`` (times its queue was full, so that it fell back to reading the
    store), ``lagging`` (reading the store at its own pace now), ``error`` (what ended it, if
    anything).

    >>> import slr_sql
    >>> kb = slr_sql.open(); sub = kb.subscribe("p(X)^T", since=0)
    >>> kb.add("p(a)^1"); sub.get(timeout=5)
    {'X': Atom('a'), 'T': 1.0}
    >>> sub.close(); kb.close()
    """

    def __init__(self, hub: "SubscriptionHub", matcher: _Matcher, sub_id: str, durable: bool,
                 since: float, until: float | None, max_queue: int, max_lag: int | None,
                 callback: Callable[[dict], Any] | None):
        self._hub = hub
        self._matcher = matcher
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
        self._lock = threading.Lock()
        self._cond = threading.Condition(self._lock)
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
        self._ended = False          # an _End was queued: the hub is done with it
        self._finished = False       # the consumer took the _End
        self._closed = False
        # positions (the hub thread writes them; matching answers under _lock with the queue)
        self.phase = _HISTORY
        self.history_top = 0
        self.history_pos = 0
        self.live_start = 0
        self.scanned = 0             # last journal jid passed (phase _LIVE)
        self.lagging = False
        self._until_reached = False
        self._end_jid: int | None = None
        self._pending: Any = None     # the kb.submit PendingQuery that waits for `until`
        self._thread: threading.Thread | None = None
        self._final_position: tuple[int, int] | None = None   # set by close()
        self._completed = False      # ended because everything up to `until` was delivered
        self._persisted: tuple | None = None                  # last position written
        self._history_sql: str | None = None   # how to read its history (by seq or end time)
        self._cohort_key: tuple = (matcher, since, until)

    def __repr__(self) -> str:
        state = "closed" if self._closed else "ended" if self._ended else (
            "lagging" if self.lagging else "history" if self.phase == _HISTORY else "live")
        return (f"<Subscription {self.id!r} {self.pattern!r}"
                f"{' where ' + repr(self.where) if self.where else ''}: {state}, "
                f"{self.delivered} delivered>")

    # -- state ----------------------------------------------------------------------------------
    @property
    def closed(self) -> bool:
        """True once closed or ended (until reached, overflow, error) and taken."""
        return self._closed or self._finished

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
        if self.phase == _HISTORY:
            return _HISTORY, self.history_pos
        return _LIVE, self.scanned

    # -- consuming ------------------------------------------------------------------------------
    def _take(self, timeout: float | None, block: bool = True) -> Any:
        """The next answer (a dict of its own), or an _End; None when nothing came within
        ``timeout``. Taking it marks the previous one handled."""
        with self._lock:
            self._in_flight = None           # the consumer is back: the previous one is done
            queue = self._queue
            if not queue and block and not self._closed:
                deadline = None if timeout is None else time.monotonic() + timeout
                while not queue and not self._closed:
                    left = None if deadline is None else deadline - time.monotonic()
                    if left is not None and left <= 0:
                        break
                    self._thread_waiting += 1
                    try:
                        self._cond.wait(left)
                    finally:
                        self._thread_waiting -= 1
            if not queue:
                return _End(self.error) if self._closed else None
            code = queue.popleft()
            item = queue.popleft()
            if code is None:
                self._finished = True
            else:
                self._in_flight = code
                self.delivered += 1
                refill = len(queue) >> 1 == self.max_queue >> 1 and (
                    self.lagging or self.phase == _HISTORY)
        if code is None:
            self._hub._taken_end(self)
            return item
        if refill:                           # room again: the hub reads on from the store
            self._hub.notify()
        return dict(item)

    def get(self, timeout: float | None = None) -> dict | None:
        """The next answer; None once the subscription has ended (``until`` reached or
        closed). Raises SLRTimeout when none came within ``timeout`` seconds, and the error
        that ended the subscription (e.g. :class:`SubscriptionOverflow`) after the answers
        queued before it."""
        self._check_pull()
        item = self._take(timeout)
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
        loop = asyncio.get_running_loop()
        future = loop.create_future()
        with self._lock:
            if (not self._unacked if acks else self._queue) or self._closed:
                return
            self._async_waiter = (loop, future)
        try:
            await future
        finally:
            with self._lock:
                if self._async_waiter is not None and self._async_waiter[1] is future:
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
        >>> kb = slr_sql.open(); sub = kb.subscribe("p(X)^T", since=0)
        >>> rejected = kb.add_many(["p(a)^1", "p(b)^2"])
        >>> asyncio.run(sub.next_answers(10))
        [{'X': Atom('a'), 'T': 1.0}, {'X': Atom('b'), 'T': 2.0}]
        >>> sub.close(); kb.close()
        """
        self._check_pull()
        while True:
            got = self._take_batch(limit, handled)
            if type(got) is _End:
                if got.error is not None:
                    raise got.error
                return []
            if got:
                return [dict(a) for a in got] if copy else got
            await self._wait_async(acks=got is None)

    def acknowledge(self, count: int) -> None:
        """Mark the first ``count`` answers taken with ``next_answers(handled=False)`` and
        not acknowledged yet handled, in order: the position of a durable subscription moves
        past the last of them (written as usual, every 0.2 s and at close). Answers never
        acknowledged stay unhandled, also when the subscription is closed: a durable
        subscription delivers them again. Callable from any thread.

        >>> import asyncio, slr_sql
        >>> kb = slr_sql.open(); sub = kb.subscribe("p(X)^T", since=0)
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
            _resolve_threadsafe(waiter[0], [waiter[1]])

    def _take_batch(self, limit: int, handled: bool = True) -> Any:
        """Up to ``limit`` queued answers (the shared dicts), never waiting: ``[]`` when none is
        queued, the _End when it is next (never after answers taken in the same call, so
        those are handled before the end closes the subscription). One lock for the batch.
        ``handled=False``: the batch goes to the unacknowledged answers (the previous one
        is not marked handled), and an end waits for them to be acknowledged (None then)."""
        with self._lock:
            if handled:
                self._in_flight = None       # the consumer is back: the previous batch is done
            queue = self._queue
            if not queue:
                return _End(self.error) if self._closed else []
            if queue[0] is None and not handled and self._unacked:
                return None                  # the end after the acknowledgements
            if queue[0] is None:              # the end marker
                queue.popleft()
                end = queue.popleft()
                self._finished = True
                taken = None
            else:
                before = len(queue) >> 1
                taken = []
                if handled:
                    self._in_flight = queue[0]   # the batch is in the consumer's hands
                    while queue and len(taken) < limit and queue[0] is not None:
                        queue.popleft()
                        taken.append(queue.popleft())
                else:
                    unacked = self._unacked
                    while queue and len(taken) < limit and queue[0] is not None:
                        unacked.append(queue.popleft())
                        taken.append(queue.popleft())
                self.delivered += len(taken)
                half = self.max_queue >> 1
                refill = before > half >= len(queue) >> 1 and (
                    self.lagging or self.phase == _HISTORY)
        if taken is None:
            self._hub._taken_end(self)
            return end
        if refill:                           # room again: the hub reads on from the store
            self._hub.notify()
        return taken

    def wait(self, timeout: float | None = None) -> bool:
        """Wait until a callback subscription has ended (``until`` reached, closed, or failed);
        True if it has, False on timeout. Raises the error that ended it."""
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout)
            if self._thread.is_alive():
                return False
        else:
            deadline = None if timeout is None else time.monotonic() + timeout
            with self._cond:
                while not (self._ended or self._closed):
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

    def _run_callback(self) -> None:
        fn = self.callback
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
        queued are dropped here and delivered again when a durable subscription resumes."""
        with self._cond:
            if self._closed and not forget:
                return
            if not self._closed:
                if ack:
                    self._in_flight = None
                self._final_position = self._position_locked()
                self._queue.clear()
                self._closed = True
            self._cond.notify_all()
            waiter, self._async_waiter = self._async_waiter, None
        if waiter is not None:
            _resolve_threadsafe(waiter[0], [waiter[1]])
        self._hub._close(self, forget)
        if join:
            self._join()

    def _join(self) -> None:
        thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout=5.0)

    def __enter__(self) -> "Subscription":
        return self

    def __exit__(self, exc_type: Any, *rest: Any) -> None:
        self.close(ack=exc_type is None)

    # -- hub side (hub thread) ------------------------------------------------------------------
    def _offer_batch(self, phase: int, batch: list, end_pos: int) -> bool:
        """Queue ``batch`` ``[(pos, answer)]`` (in order) and pass every row up to ``end_pos``.
        When the queue cannot take all of it, queue what fits, pass the rows before the first
        answer left out, and return False (the hub reads the rest from the store later)."""
        with self._lock:
            if self._closed or self._ended:
                return True
            queue = self._queue
            room = self.max_queue - (len(queue) >> 1)
            taken = batch if len(batch) <= room else batch[:max(room, 0)]
            for pos, answer in taken:
                queue.append(_code(phase, pos))
                queue.append(answer)
            if len(taken) < len(batch):
                end_pos = batch[len(taken)][0] - 1
            if phase == _LIVE:
                if end_pos > self.scanned:
                    self.scanned = end_pos
            elif end_pos > self.history_pos:
                self.history_pos = end_pos
            return len(taken) == len(batch)

    def _end(self, error: BaseException | None = None, completed: bool = False) -> None:
        with self._lock:
            if self._ended or self._closed:
                return
            self._ended = True
            self._completed = completed
            if error is not None and self.error is None:
                self.error = error
            self._queue.append(None)
            self._queue.append(_End(error))

    def _go_live(self) -> None:
        with self._lock:
            self.phase = _LIVE
            self.scanned = max(self.scanned, self.live_start)

    def _wake(self, loops: dict) -> None:
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


def _resolve(futures: list) -> None:
    for f in futures:
        if not f.done():
            f.set_result(None)


def _resolve_threadsafe(loop: Any, futures: list) -> None:
    try:
        loop.call_soon_threadsafe(_resolve, futures)
    except RuntimeError:  # the loop is closed: nobody waits any more
        pass


# ----------------------------------------------------------------------------- the hub

def _owner_alive(owner: str | None, lease_until: float | None, now_wall: float, me: str) -> bool:
    """Does another process hold a claim on a subscription row?"""
    if not owner or owner == me:
        return False
    if lease_until is None or lease_until < now_wall:
        return False
    host, _, rest = owner.partition(":")
    pid_text = rest.partition(":")[0]
    if host == socket.gethostname() and pid_text.isdigit():
        try:
            os.kill(int(pid_text), 0)
        except ProcessLookupError:
            return False        # the owner died (SIGKILL, crash): its claim is void
        except (PermissionError, OSError):
            return True
    return True


class _TypeInfo:
    __slots__ = ("table", "journal", "columns", "history_sql", "history_by_end_sql",
                 "window_count_sql", "journal_sql", "max_sql")

    def __init__(self, table: str, arity: int):
        self.table = table
        self.journal = journal_table(table)
        t, j = quote_identifier(table), quote_identifier(self.journal)
        cols = "".join(f", arg{i}" for i in range(1, arity + 1))
        tcols = "".join(f", t.arg{i}" for i in range(1, arity + 1))
        self.columns = cols
        self.history_sql = (
            f"SELECT t.seq{tcols}, t.t_start, t.t_end FROM {t} AS t "
            f"WHERE t.seq > ? AND t.seq <= ? AND t.t_end >= ? AND t.t_end <= ? "
            f"AND NOT EXISTS (SELECT 1 FROM {j} AS j WHERE j.seq = t.seq AND j.jid > ?) "
            f"ORDER BY t.seq LIMIT ?")
        # few events in [since, until] (e.g. since="now" on a long history): read them through
        # the end-time index and sort them, rather than walking every row by seq
        self.history_by_end_sql = self.history_sql.replace(
            "WHERE t.seq > ? AND t.seq <= ?", "WHERE +t.seq > ? AND +t.seq <= ?")
        self.window_count_sql = (f"SELECT count(*) FROM (SELECT 1 FROM {t} WHERE t_end >= ? "
                                 f"AND t_end <= ? LIMIT {FEW_HISTORY + 1})")
        self.journal_sql = (f"SELECT jid, seq{cols}, t_start, t_end FROM {j} WHERE jid > ? "
                            f"ORDER BY jid LIMIT ?")
        self.max_sql = f"SELECT max(jid) FROM {j}"


class SubscriptionHub:
    """The subscriptions of one knowledge base and the thread that delivers them (created by
    :func:`attach`; ``kb.subscribe`` / ``kb.unsubscribe`` delegate here)."""

    def __init__(self, kb: Host):
        self.kb = kb
        self.store = kb.store
        # the store's columns: encoded terms as they are (SQLite) or as a server holds them
        from_column = self.store.dialect.from_column
        self._decode: Any = decode if from_column is None else \
            (lambda v: decode(from_column(v)))
        self.clock = kb.clock
        self.lock = threading.Lock()
        self.cond = threading.Condition(self.lock)
        self.owner = f"{socket.gethostname()}:{os.getpid()}:{uuid.uuid4().hex[:12]}"
        self.poll_interval = POLL_INTERVAL
        self.persist_interval = PERSIST_INTERVAL
        self.lease_seconds = LEASE_SECONDS
        self.cleanup_interval = CLEANUP_INTERVAL
        self._subs: dict[str, Subscription] = {}
        self._by_type: dict[tuple[str, int], list[Subscription]] = {}
        self._type_pos: dict[tuple[str, int], int] = {}
        self._types: dict[tuple[str, int], _TypeInfo] = {}
        self._matchers: dict[tuple[str, str | None], _Matcher] = {}
        self._ids = itertools.count(1)
        self._dirty = False
        self._closed = False
        self._thread: threading.Thread | None = None
        self._last_persist = 0.0
        self._last_lease = time.monotonic()   # registration writes a fresh lease
        self._last_cleanup = 0.0
        self._subscribed_types: set[tuple[str, int]] = set()   # ever, in this process
        self._journaled: set[tuple[str, int]] = set()   # types whose trigger was seen
        self._last_failure = ""
        self._passes_started = 0
        self._passes_done = 0
        self._cleaned_at_pass = -1
        # the hub thread's own connection for its journal and history reads (None: in memory,
        # or not started): they never wait for the store's lock, which a writer holds through
        # its commit, and a lagging subscriber's reads never delay the writers
        self._reader: Any = None
        self._max_jids: dict[str, int] = {}   # per type and pass: max(jid) of each journal
        # woken from inside a transaction (not committed yet): the next pass reads through the
        # store's connection, which waits for the commit, as every read did before
        self._through_store = False
        self._pass_through_store = False

    # -- wiring -------------------------------------------------------------------------------
    def notify(self, through_store: bool = False) -> None:
        """Something may be new: wake the hub thread (never waits on delivery).
        ``through_store``: called inside a transaction, so the next pass must read through
        the store's connection (which waits for its commit)."""
        with self.cond:
            self._dirty = True
            self._through_store = self._through_store or through_store
            self.cond.notify()

    def on_add(self, stored: list) -> None:
        """``kb.add_listeners`` entry: events of subscribed types were stored."""
        if not self._by_type or not stored:
            return
        keys = self._by_type
        for ev in stored:
            try:
                if (ev[0], len(ev[1])) in keys:
                    self.notify(through_store=self.store.in_transaction)
                    return
            except (TypeError, IndexError):
                continue

    def on_table_created(self, name: str, arity: int, table: str) -> None:
        """Store hook, inside the transaction creating an event table: journal it from its
        first row if some subscription (of any process) wants that type."""
        rows = self.store.execute(
            "SELECT 1 FROM slr_subscriptions WHERE type_name = ? AND type_arity = ? "
            "AND finished = 0 LIMIT 1", (name, arity))
        if rows:
            self._ensure_journal(name, arity, table)

    # -- subscribe / unsubscribe ----------------------------------------------------------------
    def subscribe(self, pattern: str, where: str | None = None, since: Any = "now",
                  until: Any = None, id: str | None = None,
                  callback: Callable[[dict], Any] | None = None,
                  max_queue: int = DEFAULT_MAX_QUEUE,
                  max_lag: int | None = DEFAULT_MAX_LAG) -> Subscription:
        """Register a subscription (see :meth:`slr_sql.KnowledgeBase.subscribe`): validate,
        register in one write transaction, start delivering.

        >>> import slr_sql
        >>> kb = slr_sql.open(); sub = kb._subscriptions.subscribe("p(X)^T", since=0)
        >>> sub.durable, sub.since
        (False, 0.0)
        >>> kb.close()
        """
        if self._closed:
            raise SLRError("the knowledge base is closed")
        if not isinstance(pattern, str):
            raise SLRError(f"subscribe: the pattern must be text such as 'face(F, R)^T', "
                           f"not {shown(pattern)}")
        if where is not None and not isinstance(where, str):
            raise SLRError(f"subscribe: where must be a goal as text, not {shown(where)}")
        if where is not None and not where.strip():
            where = None
        if isinstance(since, str) and since.strip() == "now":
            since_value = float(self.clock.now())
        else:
            since_value = _time_arg(since, "since")
        until_value = None if until is None else _time_arg(until, "until")
        if until_value == _INF:
            until_value = None
        if until_value is not None and until_value < since_value:
            raise SLRError(f"subscribe: until ({until_value:g}) is before since "
                           f"({since_value:g})")
        if id is not None and (not isinstance(id, str) or not id):
            raise SLRError(f"subscribe: id must be a non-empty string, not {shown(id)}")
        if callback is not None and not callable(callback):
            raise SLRError("subscribe: callback must be callable")
        if isinstance(max_queue, bool) or not isinstance(max_queue, int) or max_queue < 1:
            raise SLRError(f"subscribe: max_queue must be a positive integer, not {shown(max_queue)}")
        if max_lag is not None and (isinstance(max_lag, bool) or not isinstance(max_lag, int)
                                    or max_lag < 1):
            raise SLRError(f"subscribe: max_lag must be a positive integer or None, "
                           f"not {shown(max_lag)}")
        pattern = pattern.strip()
        matcher = _Matcher(self.kb, pattern, where)   # SLRSyntaxError for bad texts
        if isinstance(since, str):
            self._warn_if_stamped_long_before(matcher.key, since_value)
        durable = id is not None
        with self.lock:
            if durable and id in self._subs:
                raise SLRError(f"subscription {id!r} is already open in this process")
            sub_id = id if durable else f"~{self.owner}:{next(self._ids)}"
        sub = Subscription(self, matcher, sub_id, durable, since_value, until_value,
                           max_queue, max_lag, callback)
        self._register(sub)
        with self.lock:
            if durable and id in self._subs:   # a concurrent subscribe with the same id
                self._unclaim(sub)
                raise SLRError(f"subscription {id!r} is already open in this process")
            key = (matcher.pattern, matcher.where)
            sub._matcher = self._matchers.setdefault(key, matcher)
            sub._cohort_key = (sub._matcher, sub.since, sub.until)   # shared answers
            self._subs[sub.id] = sub
            self._by_type.setdefault(sub.key, []).append(sub)
            self._subscribed_types.add(sub.key)
            self._dirty = True
            if self._thread is None:
                self._thread = threading.Thread(target=self._loop, name="slr-subscriptions",
                                                daemon=True)
                self._thread.start()
                # a server tells when other processes stored events of journaled types
                self._stop_listening = self.store.listen(self.notify)
            self.cond.notify()
        if sub.until is not None and not sub._ended:
            try:
                self._watch_until(sub)
            except BaseException:
                sub.close(ack=False)
                raise
        if callback is not None:
            sub._thread = threading.Thread(target=sub._run_callback, daemon=True,
                                           name=f"slr-subscription-{sub.id}")
            sub._thread.start()
        return sub

    def _warn_if_stamped_long_before(self, key: tuple[str, int], now: float) -> None:
        """``since="now"`` on a type whose events end long before the clock's now (robot or
        recorded times on a store with a wall clock): the new events will most likely be
        stamped the same way, end before ``since`` and never be delivered. Say so."""
        latest = self.store.max_end(*key)
        gap = getattr(self.kb, "max_learned_delay", None) or DEFAULT_MAX_LEARNED_DELAY
        if latest is None or now - latest <= gap:
            return
        name = f"{key[0]}/{key[1]}"
        warnings.warn(LearnedDelayWarning(
            f"subscribe(since=\"now\") on {name}: its latest event ends at {latest:g}, "
            f"{now - latest:.6g} s before the clock's now ({type(self.clock).__name__}); "
            f"events stamped like it end before since and are not delivered. Subscribe "
            f"since=0 (history first, then live), or give the store a ManualClock or a "
            f"StreamClock for simulated or recorded times"), stacklevel=3)

    def unsubscribe(self, sub_id: str) -> None:
        """Remove the subscription ``sub_id`` (closing it if it is open here).

        >>> import slr_sql
        >>> kb = slr_sql.open(); sub = kb.subscribe("p(X)^T", id="log"); sub.close()
        >>> kb.unsubscribe("log"); kb._subscriptions.subscriptions()
        []
        >>> kb.close()
        """
        with self.lock:
            sub = self._subs.get(sub_id)
        if sub is not None:
            sub.close(forget=True)
            return
        with self.store.transaction():
            rows = self.store.execute("SELECT type_name FROM slr_subscriptions WHERE id = ?",
                                      (sub_id,))
            if not rows:
                raise SLRError(f"no subscription with id {shown(sub_id)}")
            self.store.execute("DELETE FROM slr_subscriptions WHERE id = ?", (sub_id,))
        self._cleanup()

    def subscriptions(self) -> list[dict[str, Any]]:
        """Every registered subscription of the store (all processes), as dicts.

        >>> import slr_sql
        >>> kb = slr_sql.open(); sub = kb.subscribe("p(X)^T", id="log")
        >>> [(r["id"], r["pattern"], r["durable"]) for r in kb._subscriptions.subscriptions()]
        [('log', 'p(X)^T', 1)]
        >>> kb.close()
        """
        columns = ["id", "durable", "pattern", "where_goal", "since", "until", "type_name",
                   "type_arity", "history_done", "live_pos", "finished", "owner",
                   "lease_until"]
        rows = self.store.execute(f"SELECT {', '.join(columns)} FROM slr_subscriptions "
                                  f"ORDER BY id")
        return [dict(zip(columns, row)) for row in rows]

    # -- registration (a write transaction) -----------------------------------------------------
    def _type_info(self, key: tuple[str, int]) -> _TypeInfo | None:
        info = self._types.get(key)
        if info is None:
            table = self.store.table_for(*key)
            if table is None:
                return None
            info = self._types[key] = _TypeInfo(table, key[1])
        return info

    def _ensure_journal(self, name: str, arity: int, table: str) -> None:
        """Create the journal of ``table`` and its trigger (inside the caller's transaction)."""
        self.store.create_journal(table, arity, journal_table(table), TRIGGER_PREFIX + table)

    def _register(self, sub: Subscription) -> None:
        store = self.store
        name, arity = sub.key
        now_wall = time.time()
        with store.transaction():
            row = None
            if sub.durable:
                found = store.execute(
                    "SELECT pattern, where_goal, since, until, history_top, history_pos, "
                    "history_done, live_start, live_pos, finished, owner, lease_until "
                    "FROM slr_subscriptions WHERE id = ?", (sub.id,))
                row = found[0] if found else None
            table = store.table_for(name, arity)
            if table is not None:
                self._ensure_journal(name, arity, table)
                self._types.setdefault(sub.key, _TypeInfo(table, arity))
            if row is not None:
                (pattern, where, since, until, top, hpos, hdone, lstart, lpos, finished,
                 owner, lease) = row
                if pattern != sub.pattern or where != sub.where or until != sub.until:
                    raise SLRError(
                        f"subscription {sub.id!r} exists with pattern {pattern!r}"
                        f"{', where ' + repr(where) if where else ''}"
                        f"{', until ' + format(until, 'g') if until is not None else ''}; "
                        f"resume it with the same definition, or kb.unsubscribe({sub.id!r}) "
                        f"first")
                if _owner_alive(owner, lease, now_wall, self.owner):
                    raise SLRError(f"subscription {sub.id!r} is being delivered by another "
                                   f"process ({owner})")
                sub.since = since
                sub.history_top, sub.history_pos = top, hpos
                sub.live_start = lstart
                sub.scanned = lpos
                sub.phase = _LIVE if hdone else _HISTORY
                store.execute("UPDATE slr_subscriptions SET owner = ?, lease_until = ? "
                              "WHERE id = ?", (self.owner, now_wall + self.lease_seconds,
                                               sub.id))
                if finished:
                    sub._end()
                return
            top = 0
            start = 0
            if table is not None:
                top = store.execute(f"SELECT coalesce(max(seq), 0) FROM "
                                    f"{quote_identifier(table)}")[0][0]
                start = store.execute(f"SELECT coalesce(max(jid), 0) FROM "
                                      f"{quote_identifier(journal_table(table))}")[0][0]
            sub.history_top = top
            sub.history_pos = 0
            sub.live_start = start
            sub.scanned = start
            sub.phase = _HISTORY if top > 0 else _LIVE
            store.execute(
                "INSERT INTO slr_subscriptions (id, durable, pattern, where_goal, since, "
                "until, type_name, type_arity, history_top, history_pos, history_done, "
                "live_start, live_pos, finished, owner, lease_until, created_at) "
                "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, 0, ?, ?, ?, 0, ?, ?, ?)",
                (sub.id, int(sub.durable), sub.pattern, sub.where, sub.since, sub.until,
                 name, arity, top, int(top == 0), start, start, self.owner,
                 now_wall + self.lease_seconds, float(self.clock.now())))

    def _unclaim(self, sub: Subscription, forget: bool = False) -> None:
        """Write ``sub``'s final position and release (or remove) its row."""
        if self.store.closed:
            return
        try:
            with self.store.transaction():
                if forget:
                    self.store.execute("DELETE FROM slr_subscriptions WHERE id = ?", (sub.id,))
                elif not sub.durable:
                    self.store.execute("DELETE FROM slr_subscriptions WHERE id = ? AND "
                                       "owner = ?", (sub.id, self.owner))
                else:
                    self._write_position(sub, release=True)
        except SLRError as exc:
            log.warning("subscription %r: could not record its position: %s", sub.id, exc)

    def _write_position(self, sub: Subscription, release: bool = False) -> None:
        phase, pos = sub.position()
        finished = int(sub._finished and sub._completed)
        if phase == _HISTORY:
            hdone, hpos, lpos = 0, pos, sub.live_start
        else:
            hdone, hpos, lpos = 1, sub.history_top, pos
        self.store.execute(
            "UPDATE slr_subscriptions SET history_done = ?, history_pos = ?, live_pos = ?, "
            "finished = CASE WHEN ? = 1 THEN 1 ELSE finished END, lease_until = ?, owner = ? "
            "WHERE id = ? AND owner = ? AND (history_done < ? OR (history_done = ? AND "
            "history_pos <= ? AND live_pos <= ?))",
            (hdone, hpos, lpos, finished,
             None if release else time.time() + self.lease_seconds,
             None if release else self.owner,
             sub.id, self.owner, hdone, hdone, hpos, lpos))

    def _watch_until(self, sub: Subscription) -> None:
        """Ask the synchronizer to tell when the type is complete up to ``until``."""
        name, arity = sub.key
        atom = format_atom(name) + (f"({', '.join('_' * arity)})" if arity else "")
        sync = getattr(self.kb, "_sync", None)
        if self.store.path is not None and sync is not None and \
                getattr(sync, "external_poll", 1) is None:
            sync.watch_external(self.poll_interval)   # marks written by other processes
        pending = self.kb.submit(f"prev({atom}^_, U)", at=sub.until, args={"U": sub.until},
                                 id=f"subscription {sub.id} until {sub.until:g}")
        sub._pending = pending

        def reached(future: Any) -> None:
            if future.cancelled() or self._closed:
                return
            error = future.exception()
            if error is not None:
                if not sub._closed:
                    sub._end(SLRError(f"subscription {sub.id!r}: waiting for its history to be "
                                      f"complete up to until={sub.until:g} failed: {error}"))
                    self._wake({sub})
                return
            sub._until_reached = True
            self.notify()

        pending.add_done_callback(reached)

    # -- closing ------------------------------------------------------------------------------------
    def _close(self, sub: Subscription, forget: bool) -> None:
        with self.lock:
            registered = self._subs.get(sub.id) is sub
            if registered:
                del self._subs[sub.id]
                subs = self._by_type.get(sub.key, [])
                if sub in subs:
                    subs.remove(sub)
                if not subs:
                    self._by_type.pop(sub.key, None)
                    self._type_pos.pop(sub.key, None)
                key = (sub._matcher.pattern, sub._matcher.where)
                if self._matchers.get(key) is sub._matcher and not any(
                        s._matcher is sub._matcher for s in subs):
                    del self._matchers[key]      # kept only while some subscription uses it
        pending = sub._pending
        if pending is not None and not pending.done():
            pending.cancel()
        if registered or forget:
            self._unclaim(sub, forget)
            if (forget or not sub.durable) and sub.key not in self._by_type:
                try:                    # the last one of its type here: drop what is unused
                    self._cleanup()
                except SLRError as exc:
                    log.warning("subscriptions: journal cleanup failed: %s", exc)

    def _taken_end(self, sub: Subscription) -> None:
        """The consumer took the end of ``sub``: record it as finished, unregister."""
        if not sub._closed:
            sub.close(forget=False)

    def close(self) -> None:
        """Close every subscription (durable ones keep their position) and stop the thread."""
        with self.cond:
            if self._closed:
                return
            subs = list(self._subs.values())
        if subs and not self.store.closed:
            try:
                with self.store.transaction():   # one commit for every position
                    for sub in subs:
                        sub.close(join=False)
            except SLRError as exc:
                log.warning("subscriptions: could not record positions at close: %s", exc)
        for sub in subs:
            sub.close(join=False)                # (if the transaction above failed)
            sub._join()                          # callback threads, outside the transaction
        with self.cond:
            self._closed = True
            self.cond.notify_all()
        stop = getattr(self, "_stop_listening", None)
        if stop is not None:
            stop()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=10.0)
        if self._subscribed_types and not self.store.closed:
            try:
                self._cleanup()
            except SLRError:
                pass

    # -- the hub thread ------------------------------------------------------------------------
    def _read(self, sql: str, params: tuple = ()) -> list[tuple]:
        """A reading statement of the hub thread, on its own connection when it has one."""
        reader = self._reader
        if reader is None or self._pass_through_store:
            return self.store.execute(sql, params)
        return reader.execute(sql, params)

    def _loop(self) -> None:
        """Run a delivery pass whenever ``kb.add`` (or a consumer making room, or ``until``)
        wakes the hub, and at least every ``poll_interval`` seconds: the pass compares each
        journal's greatest jid with what was read, which is how events stored by other
        connections (processes) or by statements on this one are seen."""
        try:
            self._reader = self.store.open_reader()
        except SLRError as exc:   # (too many open files, ...): read on the store's connection
            log.warning("subscriptions: no connection of their own (%s); reading on the "
                        "store's", exc)
        try:
            self._run_passes()
        finally:
            reader, self._reader = self._reader, None
            if reader is not None:
                reader.close()

    def _run_passes(self) -> None:
        while True:
            with self.cond:
                if not self._dirty and not self._closed:
                    self.cond.wait(self.poll_interval if self._subs else None)
                if self._closed:
                    return
                self._dirty = False
                self._pass_through_store, self._through_store = self._through_store, False
                if not self._subs:
                    continue
                self._passes_started += 1
                number = self._passes_started
            try:
                self._pass()
                self._housekeeping()
            except Exception as exc:  # a busy store, a closing kb: try again on the next tick
                if self._closed or self.store.closed:
                    return
                if str(exc) != self._last_failure:   # once per distinct failure, not per tick
                    self._last_failure = str(exc)
                    log.warning("subscriptions: a delivery pass failed (%s: %s); retrying",
                                type(exc).__name__, exc, exc_info=True)
            finally:
                with self.cond:
                    self._passes_done = number
                    self.cond.notify_all()

    def drain(self, timeout: float | None = None) -> bool:
        """Wait until a whole delivery pass has run after this call (tests, benchmarks): every
        event stored before the call has then been matched and queued, or left for a lagging
        subscription to read later. True if it did within ``timeout`` seconds."""
        end = None if timeout is None else time.monotonic() + timeout
        with self.cond:
            if not self._subs or self._thread is None:
                return True
            want = self._passes_started + 1
            self._dirty = True
            self.cond.notify_all()
            while self._passes_done < want and not self._closed:
                left = None if end is None else end - time.monotonic()
                if left is not None and left <= 0:
                    return False
                self.cond.wait(left)
        return True

    def _snapshot(self) -> dict[tuple[str, int], list[Subscription]]:
        with self.lock:
            return {key: list(subs) for key, subs in self._by_type.items()}

    def _pass(self) -> None:
        for key, subs in self._snapshot().items():
            try:
                self._serve_type(key, subs)
            except Exception:
                if any(not s._closed for s in subs):
                    raise
                # every subscription of the type closed meanwhile (its journal may be gone)

    def _serve_type(self, key: tuple[str, int], subs: list[Subscription]) -> None:
        """One round for the subscriptions of one event type: the shared read of the journal
        for those that keep up, then each one that reads at its own pace (history, lagging),
        then the ends (``until`` reached, too far behind)."""
        info = self._type_info(key)
        touched: set = set()
        self._max_jids.clear()
        if info is None:   # no event of this type yet: nothing to read; until may still end it
            ending = [s for s in subs if s._until_reached and not s._ended]
            # looked up again after reading the flags: events stored (creating the table) before
            # `until` was reached must be delivered first, by the reading below
            if ending and self._type_info(key) is None:
                for s in ending:
                    s._go_live()
                    s._end(completed=True)
                    touched.add(s)
                self._wake(touched)
                return
            info = self._type_info(key)
            if info is None:
                return
        self._check_journal(key, info)
        for s in subs:
            if s._until_reached and s._end_jid is None:
                s._end_jid = self._max_jid(info)
        pos = self._type_pos.get(key)
        group = [s for s in subs if s.phase == _LIVE and not s.lagging and not s._ended
                 and not s._closed and (pos is None or s.scanned >= pos)]
        if group:
            if pos is None:
                pos = min(s.scanned for s in group)
            while True:
                rows = self._read(info.journal_sql, (pos, CHUNK))
                if not rows:
                    break
                self._deliver_rows(key, rows, group, touched)
                pos = rows[-1][0]
                self._type_pos[key] = pos
                if len(rows) < CHUNK:
                    break
                group = [s for s in group if not s.lagging and not s._ended]
                self._wake(touched)     # a long backlog: let consumers start
                touched = set()
        rest = []
        behind = []
        for s in subs:
            if s._ended or s._closed or (s.phase == _LIVE and not s.lagging and pos is not None
                                         and s.scanned >= pos and not s._until_reached):
                continue                 # served by the shared read: nothing else to do
            rest.append(s)
            if s.phase == _HISTORY:
                self._serve_history(info, s, touched)
            if s.phase == _LIVE and (s.lagging or pos is None or s.scanned < pos):
                behind.append(s)         # not (yet) in the shared read
        if behind:
            self._serve_behind(key, info, behind, touched)
        for s in rest:
            self._check_end(key, info, s, touched)
        self._wake(touched)

    def _deliver_rows(self, key: tuple[str, int], rows: list, group: list[Subscription],
                      touched: set, own_pace: bool = False) -> None:
        """Match journal rows ``(jid, seq, args.., start, end)`` for ``group``: the answers of
        each distinct (pattern, condition, since, until) are computed once, then given to each
        subscription in one batch; one whose queue fills up is marked lagging at the first
        answer it cannot take."""
        arity = key[1]
        events = [(row[0], tuple([self._decode(v) for v in row[2:2 + arity]]), row[2 + arity],
                   row[3 + arity]) for row in rows]
        first_jid, last_jid = events[0][0], events[-1][0]
        cohorts: dict = {}
        for s in group:
            scanned = s.scanned
            if scanned >= last_jid or s.lagging or s._ended or s._closed:
                continue
            cohort = cohorts.get(s._cohort_key)
            if cohort is None:
                cohort = cohorts[s._cohort_key] = self._cohort(s, events)
            items, error, error_jid, flat = cohort
            if scanned < first_jid and error is None:
                # the common case, inline: every answer of the batch, if they all fit
                with s._lock:
                    queue = s._queue
                    fits = not (s._closed or s._ended) and \
                        (len(queue) >> 1) + len(items) <= s.max_queue
                    if fits:
                        queue.extend(flat)
                        s.scanned = last_jid
                if fits:
                    if items:
                        touched.add(s)
                    continue
            if scanned >= first_jid:
                items = [item for item in items if item[0] > scanned]
                if error is not None and error_jid <= scanned:
                    error = None
            if error is None:
                end_pos = last_jid
            else:
                end_pos = items[-1][0] if items else scanned
            if s._offer_batch(_LIVE, items, end_pos):
                if error is not None:
                    s._end(error)
                if items or error is not None:
                    touched.add(s)
            else:
                s.lagging = True
                touched.add(s)
                if not own_pace:
                    s.overflows += 1

    def _cohort(self, s: Subscription, events: list) -> tuple[list, Any, int, list]:
        """``s``'s answers among ``events``: ([(jid, answer)], the first error, its jid, and
        the answers as queue entries ``[jid, answer, ...]``)."""
        m = s._matcher
        since = s.since
        until = _INF if s.until is None else s.until
        items = []
        for jid, args, start, end in events:
            if end < since or end > until:
                continue
            answer = self._match(m, args, start, end)
            if answer is None:
                continue
            if type(answer) is not dict:
                return items, answer, jid, []
            items.append((jid, answer))
        return items, None, 0, [x for item in items for x in item]

    @staticmethod
    def _match(m: _Matcher, args: tuple, start: float, end: float) -> Any:
        try:
            return m.match(args, start, end)
        except SLRError as exc:
            return exc

    def _serve_history(self, info: _TypeInfo, s: Subscription, touched: set) -> None:
        """Deliver stored events (seq <= history_top, end in [since, until]) in seq order, as
        far as ``s``'s queue has room; then switch ``s`` to the journal."""
        arity = s.key[1]
        m = s._matcher
        until = _INF if s.until is None else s.until
        if s._history_sql is None:
            few = self._read(info.window_count_sql, (s.since, until))[0][0]
            s._history_sql = info.history_by_end_sql if few <= FEW_HISTORY else info.history_sql
        while s.phase == _HISTORY and not s._ended and not s._closed:
            room = s.max_queue - (len(s._queue) >> 1)
            if room <= 0:
                return
            limit = max(min(room, CHUNK), 16)
            rows = self._read(s._history_sql, (s.history_pos, s.history_top, s.since, until,
                                               s.live_start, limit))
            batch = []
            error = None
            for row in rows:
                answer = self._match(m, tuple([self._decode(v) for v in row[1:1 + arity]]),
                                     row[1 + arity], row[2 + arity])
                if answer is None:
                    continue
                if type(answer) is not dict:
                    error = answer
                    break
                batch.append((row[0], answer))
            done = error is None and len(rows) < limit
            if error is None:
                end_pos = s.history_top if done else (rows[-1][0] if rows else s.history_pos)
            else:
                end_pos = batch[-1][0] if batch else s.history_pos
            if batch or error is not None:
                touched.add(s)
            if not s._offer_batch(_HISTORY, batch, end_pos):
                return
            if error is not None:
                s._end(error)
                return
            if done:
                s._go_live()

    def _serve_behind(self, key: tuple[str, int], info: _TypeInfo, behind: list[Subscription],
                      touched: set) -> None:
        """Read the journal for the live subscriptions behind the shared read (lagging ones,
        new ones) together, from the earliest position among them: each chunk is read,
        decoded and matched once for all of them (once per distinct pattern, condition and
        window, as in the shared read), and each takes the answers after its own position
        that its queue has room for. One whose queue is full stays lagging until its consumer
        makes room. So the work per event does not grow with the number of subscriptions
        behind, nor with how far behind they are."""
        active = behind
        while True:
            room = 0
            going = []
            for s in active:
                if s._ended or s._closed:
                    continue
                free = s.max_queue - (len(s._queue) >> 1)
                if free <= 0:
                    s.lagging = True
                    continue
                going.append(s)
                room = max(room, free)
            if not going:
                return
            limit = max(min(room, CHUNK), 16)
            rows = self._read(info.journal_sql, (min(s.scanned for s in going), limit))
            for s in going:
                s.lagging = False
            if rows:
                self._deliver_rows(key, rows, going, touched, own_pace=True)
            if len(rows) < limit:
                return                   # the end of the journal: all caught up
            active = [s for s in going if not s.lagging]

    def _serve_lagging(self, key: tuple[str, int], info: _TypeInfo, s: Subscription,
                       touched: set) -> None:
        """Read the journal after ``s.scanned`` at ``s``'s own pace, until its queue is full or
        it reaches the end of the journal (and so rejoins the shared read)."""
        while not s._ended and not s._closed:
            room = s.max_queue - (len(s._queue) >> 1)
            if room <= 0:
                s.lagging = True
                return
            limit = max(min(room, CHUNK), 16)
            rows = self._read(info.journal_sql, (s.scanned, limit))
            s.lagging = False
            if rows:
                self._deliver_rows(key, rows, [s], touched, own_pace=True)
            if s.lagging or len(rows) < limit:
                return

    def _check_end(self, key: tuple[str, int], info: _TypeInfo, s: Subscription,
                   touched: set) -> None:
        if s._ended or s._closed:
            return
        if s.max_lag is not None and (s.lagging or s.phase == _HISTORY):
            base = s.scanned if s.phase == _LIVE else s.live_start
            behind = self._max_jid(info) - base
            if behind > s.max_lag:
                s._end(SubscriptionOverflow(
                    f"subscription {s.id!r} ({s.pattern}) fell {behind} events behind "
                    f"(max_lag {s.max_lag}): its consumer is slower than the events arrive; "
                    f"it was ended after its last queued answer"
                    + (f"; subscribe again with id={s.id!r} to resume there" if s.durable
                       else ""), behind, s.id))
                touched.add(s)
                return
        if s._until_reached and s.phase == _LIVE and s._end_jid is not None:
            if s.scanned < s._end_jid and not s.lagging:
                self._serve_lagging(key, info, s, touched)   # read up to the end
            if s.scanned >= s._end_jid and not s.lagging:
                s._end(completed=True)
                touched.add(s)

    def _max_jid(self, info: _TypeInfo) -> int:
        """The journal's greatest jid, read once per type and pass (every lagging subscription
        of the type compares its position with it)."""
        value = self._max_jids.get(info.journal)
        if value is None:
            value = self._read(info.max_sql)[0][0] or 0
            self._max_jids[info.journal] = value
        return value

    def _check_journal(self, key: tuple[str, int], info: _TypeInfo) -> None:
        """A table created by a program without this module (raw SQL) has no journal yet."""
        if key in self._journaled:
            return
        if TRIGGER_PREFIX + info.table not in self.store.triggers(info.table):
            with self.store.transaction():
                self._ensure_journal(key[0], key[1], info.table)
        self._journaled.add(key)

    def _wake(self, touched: set) -> None:
        if not touched:
            return
        loops: dict = {}
        for s in touched:
            s._wake(loops)
        for loop, futures in loops.items():
            _resolve_threadsafe(loop, futures)

    # -- housekeeping: durable positions, leases, journal trimming --------------------------------
    def _housekeeping(self) -> None:
        """Write the positions of durable subscriptions that moved (every persist_interval),
        renew this process's claims (every lease/3), trim journals (every cleanup_interval,
        when something was delivered). Each is one short write transaction."""
        now = time.monotonic()
        if now - self._last_persist >= self.persist_interval:
            self._last_persist = now
            with self.lock:
                subs = list(self._subs.values())
            renew = now - self._last_lease >= self.lease_seconds / 3
            todo = []
            for s in subs:
                position = s.position()
                if position != s._persisted and (s.durable or renew):
                    todo.append((s, position))
            if todo or renew:
                with self.store.transaction():
                    for s, position in todo:
                        if not s._closed:
                            self._write_position(s)
                            s._persisted = position
                    if renew:
                        self.store.execute("UPDATE slr_subscriptions SET lease_until = ? "
                                           "WHERE owner = ?",
                                           (time.time() + self.lease_seconds, self.owner))
                        mine = {r[0] for r in self.store.execute(
                            "SELECT id FROM slr_subscriptions WHERE owner = ?", (self.owner,))}
                if renew:
                    self._last_lease = now
                    for s in subs:
                        if s.id not in mine and not s._closed and not s._ended:
                            s._end(SLRError(
                                f"subscription {s.id!r} was removed from the store "
                                f"(kb.unsubscribe elsewhere, or this process did not renew "
                                f"its claim for {self.lease_seconds:g} s); events after its "
                                f"position may be missing"))
                            self._wake({s})
        if now - self._last_cleanup >= self.cleanup_interval and \
                self._passes_done != self._cleaned_at_pass:
            self._last_cleanup = now
            self._cleaned_at_pass = self._passes_done
            self._cleanup()

    def _local_positions(self) -> dict[str, int]:
        """The journal position each open subscription of this process still needs (in memory:
        never behind what it wrote to the store)."""
        with self.lock:
            subs = list(self._subs.values())
        out = {}
        for s in subs:
            phase, pos = s.position()
            out[s.id] = pos if phase == _LIVE else s.live_start
        return out

    def _cleanup(self) -> None:
        """Remove expired claims, trim each journal to what some subscription still needs (this
        process's from memory, the others' as written), and drop the journal and trigger of
        types no subscription wants any more."""
        store = self.store
        if store.closed:
            return
        journals = sorted(name for name in store.table_names()
                          if name.startswith(JOURNAL_PREFIX))
        tables = {table: key for key, table in store.event_types().items()}
        with self.lock:
            local = set(self._by_type)
        positions = self._local_positions()
        with store.transaction():
            store.execute("DELETE FROM slr_subscriptions WHERE durable = 0 AND "
                          "lease_until < ?", (time.time(),))
            for journal in journals:
                table = journal[len(JOURNAL_PREFIX):]
                key = tables.get(table)
                if key is None:
                    continue
                rows = store.execute(
                    "SELECT id, owner, live_pos FROM slr_subscriptions WHERE "
                    "type_name = ? AND type_arity = ? AND finished = 0", key)
                if not rows and key not in local:
                    store.drop_journal(table, journal, TRIGGER_PREFIX + table)
                    self._types.pop(key, None)
                    self._journaled.discard(key)
                    self._type_pos.pop(key, None)
                elif rows:
                    low = min(positions.get(sid, pos) if owner == self.owner else pos
                              for sid, owner, pos in rows)
                    store.execute(f"DELETE FROM {quote_identifier(journal)} WHERE jid <= ?",
                                  (low,))


def attach(kb: Host) -> SubscriptionHub:
    """Create the subscription hub of ``kb`` and hook it into its add path and store."""
    hub = SubscriptionHub(kb)
    kb.add_listeners.append(hub.on_add)
    kb.store.table_created_hooks.append(hub.on_table_created)
    return hub
