"""Synchronized queries over asynchronous events (the SLR paper, "Synchronizing
Queries over Asynchronous Events"). See docs/synchronization.md.

Three parts:

* :class:`Completeness` — per event type p/N: the max delay (declared with
  ``:- max_delay(p/N, D)``, else learned: the largest ``arrival − end`` seen, persisted),
  completeness marks (``fullyUpdated(p/N)^t`` / ``fullyUpdated(p)^t`` events and
  ``kb.mark_complete``, persisted), and for ``:- in_order(p/N)`` types the latest end time
  received. The history of p/N is complete up to z when ``z + max_delay < now`` (the clock has
  *passed* z + max_delay), or a mark t ≥ z exists, or (in_order) an event with end > z arrived.
* :class:`PendingQuery` — a :class:`concurrent.futures.Future` with an id, the goal, its time
  ``at``, what it waits for now (``waiting_for``) and what it waited for (``waits``).
* :class:`Synchronizer` — runs pending queries: first the static goal-set condition (every
  event type reachable from the goal complete up to z, :func:`slr_sql.analysis.goal_set`), then
  an evaluation with the machine hooks ``on_prev``/``on_next`` that stop it with
  :class:`_MustWait` at the first prev/next whose history is not complete yet. A stopped query
  is *parked* on that one condition (type, time) and re-evaluated from scratch when it holds.

Wake-ups: parked queries are indexed per event type in a heap ordered by the time they need;
an arrival (in_order types) or a mark pops exactly the entries it completes. Time-driven
completeness (z + max_delay) goes through one heap of deadlines: with a ManualClock or
StreamClock the clock's move listener serves it synchronously; with a WallClock one timer
thread sleeps on a Condition until the earliest deadline (or a query timeout). Nothing polls.
Evaluations run on a small thread pool; a query occupies a worker only while it is evaluated,
never while it waits, so one waiting query never delays another.
"""
from __future__ import annotations

import heapq
import itertools
import logging
import math
import threading
import time
import warnings
from concurrent.futures import Future, InvalidStateError, ThreadPoolExecutor
from operator import itemgetter
from typing import Any, Callable, Iterable, NamedTuple

from .analysis import GoalSet, goal_set
from .answers import answer_bindings
from .arguments import check_callable, wait_seconds
from .clocks import (DEFAULT_MAX_LEARNED_DELAY, LearnedDelayNotWrittenWarning,
                     LearnedDelayWarning, ManualClock, StreamClock)
from .errors import EventRejected, SLRError, SLRTimeout, SLRUnavailable, log_failure
from .lockorder import ordered_lock
from .host import Host
from .parser import parse_indicator
from .plans import instantiate
from .store import DatabaseError, store_error
from .store.checks import BadEvent, check_times
from .terms import Atom, Struct, Var, deref, format_atom

_first, _second, _fourth = itemgetter(0), itemgetter(1), itemgetter(3)

__all__ = ["Completeness", "PendingQuery", "Wait", "Synchronizer", "attach", "parse_type"]

log = logging.getLogger("slr_sql.sync")

_INF = math.inf
MARK_NAME = "fullyUpdated"
_first_item = itemgetter(0)


def _end_spans(events: list) -> dict:
    """``{(name, arity): (earliest end, latest end)}`` of ``(name, args, start, end)`` events;
    a batch of one type (a recording) column-wise, with no loop in Python.

    >>> _end_spans([("p", (1,), 1.0, 2.0), ("q", (), 0.0, 0.5), ("p", (2,), 3.0, 3.0)])
    {('p', 1): (2.0, 3.0), ('q', 0): (0.5, 0.5)}
    """
    names = set(map(_first, events))
    if len(names) == 1:
        arities = set(map(len, map(_second, events)))
        if len(arities) == 1:
            ends = list(map(_fourth, events))
            return {(names.pop(), arities.pop()): (min(ends), max(ends))}
    spans: dict = {}
    for ev in events:
        key = (ev[0], len(ev[1]))
        end = ev[3]
        span = spans.get(key)
        if span is None:
            spans[key] = (end, end)
        elif end < span[0]:
            spans[key] = (end, span[1])
        elif end > span[1]:
            spans[key] = (span[0], end)
    return spans


def _fmt(t: float, decimals: int = 6) -> str:
    """A time for messages: ``14``, ``10.55``, ``1795281441.94`` (no exponent, no noise)."""
    if t == _INF:
        return "inf"
    if t == -_INF:
        return "-inf"
    text = f"{t:.{decimals}f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def _dur(d: float) -> str:
    return _fmt(d, 3)


def type_text(key: tuple[str, int]) -> str:
    """An event type key as Prolog writes its indicator, for messages.

    >>> type_text(("location", 2))
    'location/2'
    """
    return f"{key[0]}/{key[1]}"


def quoted_type_text(key: tuple[str, int]) -> str:
    """An event type key as Prolog writes its indicator with the name quoted where it must
    be (``writeq``): the form a warning, a log line, shows. A name any client can send
    (``add_event`` takes any string) then stays on its line: a line break or a NUL in it is
    an escape, never a line of the log of its own, and the text reads back as the type.

    >>> quoted_type_text(("location", 2)), quoted_type_text(("p q", 1))
    ('location/2', "'p q'/1")
    >>> print(quoted_type_text(("a\\nINFO: forged", 0)))
    'a\\nINFO: forged'/0
    """
    return f"{format_atom(key[0])}/{key[1]}"


def parse_type(spec: Any) -> tuple[str, int | None]:
    """``"seg/2"`` -> ("seg", 2); ``"seg"`` -> ("seg", None) (every arity); also ``(name, n)``
    tuples and the terms ``seg/2`` / ``seg``. A text whose name is quoted is read as Prolog
    reads it (:func:`slr_sql.parser.parse_indicator`): ``"'x/seen'/2"`` is the type
    ``x/seen`` of two arguments, as ``"x/seen/2"`` is.

    >>> parse_type("seg/2"), parse_type("seg"), parse_type(("tf", 3))
    (('seg', 2), ('seg', None), ('tf', 3))
    >>> parse_type("'x/seen'/2"), parse_type("x/seen/2"), parse_type("'it''s'")
    (('x/seen', 2), ('x/seen', 2), ("it's", None))
    """
    if isinstance(spec, tuple) and len(spec) == 2:
        return str(spec[0]), (None if spec[1] is None else int(spec[1]))
    t = deref(spec)
    if type(t) is Struct and t.name == "/" and len(t.args) == 2:
        name, n = deref(t.args[0]), deref(t.args[1])
        if type(name) is Atom and type(n) is int and n >= 0:
            return str(name), n
    elif isinstance(t, str) and type(t) is not Var:
        text = str(t)
        if type(t) is str and text.startswith("'"):
            # (text given as Prolog writes the indicator; an atom of a term is read already)
            return parse_indicator(text)
        name, sep, n = text.rpartition("/")
        if sep and name and n.isascii() and n.isdigit():
            return name, int(n)
        if text and "/" not in text:
            return text, None
    raise SLRError(f"expected an event type p/N or p, not {spec}")


class _MustWait(Exception):
    """Raised by the machine hooks: the history of ``key`` is not complete up to ``time``."""

    def __init__(self, key: tuple[str, int], time: float, reason: str, kind: str = "complete",
                 seen: int = 0):
        self.key = key
        self.time = time
        self.reason = reason
        self.kind = kind    # "complete", or "arrival": in_order next, any new event may do
        self.seen = seen    # the type's arrival counter when the store was checked


class Wait:
    """One condition a query waited for: event type ``type`` complete up to ``time``."""

    __slots__ = ("key", "time", "reason", "kind", "since", "since_wall", "released_at",
                 "released_wall", "released_by", "seen")

    def __init__(self, key: tuple[str, int], time: float, reason: str, since: float,
                 kind: str = "complete"):
        self.key = key
        self.time = time
        self.reason = reason
        self.kind = kind
        self.since = since                 # clock time when the wait began
        self.since_wall = _time_mono()      # time.monotonic() then
        self.released_at: float | None = None
        self.released_wall: float | None = None
        self.released_by: str | None = None
        self.seen = 0                      # kind "arrival": the type's arrival counter then

    @property
    def type(self) -> str:
        return type_text(self.key)

    def same(self, other: "Wait") -> bool:
        return (self.key, self.time, self.reason) == (other.key, other.time, other.reason)

    def waited(self) -> float:
        """Seconds of clock time waited (until now if still waiting)."""
        return (self.released_at if self.released_at is not None else _now_of(self)) - self.since

    def __str__(self) -> str:
        what = f"{self.type} complete up to {_fmt(self.time)}"
        if self.kind == "arrival":
            what += " (or a matching in-order event)"
        return f"{what} ({self.reason})"

    def __repr__(self) -> str:
        return f"Wait({self.type}, {_fmt(self.time)}, {self.reason!r})"


def _time_mono() -> float:
    return time.monotonic()


def _now_of(w: Wait) -> float:  # pragma: no cover - only for a still-waiting Wait
    return w.since + (time.monotonic() - w.since_wall)


class PendingQuery(Future):
    """A synchronized query ⟨goal, at⟩: a Future whose result is the answer list (as
    ``kb.query`` gives it) once the query is answerable.

    ``id``, ``goal``, ``at``; ``waiting_for`` — the conditions it waits for now (empty while it
    runs or once done); ``waits`` — every condition it waited for, with when and why it was
    released; ``goal_set`` — the event types of the static condition; ``evaluations`` — how
    many times it was (re-)evaluated; ``engine`` — what answered it: ``"sql"`` (the compiled
    statement, once every prev/next in it reads a complete history) or ``"interpreter"``;
    ``explain()`` — all that as text.
    """

    def __init__(self, sync: "Synchronizer", id: str, goal: str, at: float,
                 args: dict | None):
        super().__init__()
        self.id = id
        self.goal = goal
        self.at = at
        self.args = args
        self.robot: str | None = None    # every event goal, prev and next restricted to it
        self.goal_set: GoalSet | None = None
        self.waiting_for: list[Wait] = []
        self.waits: list[Wait] = []
        self.evaluations = 0
        self.engine: str | None = None
        self.submitted_at = sync.clock.now()
        self.submitted_wall = time.monotonic()
        self.answered_at: float | None = None
        self.answered_wall: float | None = None
        self._sync = sync
        self._gen = 0
        self._plan: Any = None
        self._deadline: float | None = None   # monotonic deadline of timeout=
        self._timeout: float | None = None
        self._released_at: float | None = None  # clock time of the latest release
        self._gs_program: Any = None             # the Program goal_set was computed for
        self._gs_sorted: list = []
        # set by cancel(): an evaluation under way (on a worker) ends, its compiled
        # statement included (the store interrupts or cancels it)
        self._stop = threading.Event()

    def cancel(self) -> bool:
        """Cancel the query (Future's ``cancel``): it stops waiting, and an evaluation of
        it under way ends too -- the interpreter at its next check, a compiled statement
        at once (SQLite's progress handler interrupts it, PostgreSQL's server is sent a
        cancel) -- so that the store's connection is free for the next query. False once
        the query was answered (or failed).

        >>> import slr_sql
        >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0)); q = kb.submit("p(X)^T", at=5)
        >>> q.cancel(), q.cancelled(), kb.pending()
        (True, True, [])
        >>> kb.close()
        """
        cancelled = super().cancel()
        if cancelled:
            self._stop.set()
            self._sync.store.stop_query(self._stop)
        return cancelled

    def __repr__(self) -> str:
        state = "answered" if self.done() else (
            "waiting for " + ", ".join(str(w) for w in self.waiting_for) if self.waiting_for
            else "running")
        return f"<PendingQuery {self.id!r} {self.goal!r} at={_fmt(self.at)}: {state}>"

    def explain(self) -> str:
        """What the query waited for, how long (clock seconds) and what released it.

        One line per condition, e.g. ``waited 0.7 s for seg/2 complete up to 14 (goal set);
        released by fullyUpdated(seg/2)^14``.
        """
        lines = []
        for w in self.waits:
            if w.released_at is None:
                lines.append(f"waiting {self._sync._clock_span(w)} for {w}")
            else:
                lines.append(f"waited {_dur(w.released_at - w.since)} s for {w}; released by "
                             f"{w.released_by}")
        if not lines:
            lines.append(f"no wait: every event type it needs was complete up to "
                         f"{_fmt(self.at)} when it was submitted")
        if self.answered_at is not None:
            lines.append(f"answered at clock {_fmt(self.answered_at)} "
                         f"({_dur(self.answered_at - self.submitted_at)} s after submission, "
                         f"{self.evaluations} evaluation{'s' if self.evaluations != 1 else ''}"
                         f"{', by ' + self.engine if self.engine else ''})")
        return "\n".join(lines)

    def result(self, timeout: float | None = None) -> list[dict[str, Any]]:
        """The answer list, waiting up to ``timeout`` seconds (None or ``inf``: for ever).
        When the wait runs out first: :class:`~slr_sql.SLRTimeout` saying what the query
        waits for (it goes on waiting: call ``result`` again, or ``cancel()``). A timeout
        that is no number of seconds >= 0 is an :class:`SLRError`.

        >>> import slr_sql
        >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0)); p = kb.submit("p(X)^T", at=5)
        >>> p.result(timeout="soon")
        Traceback (most recent call last):
        ...
        slr_sql.errors.SLRError: result: timeout must be a number of seconds, not 'soon'
        >>> kb.close()
        """
        wait = wait_seconds("result: timeout", timeout)
        self._refuse_wait_inside_transaction("result")
        try:
            return super().result(wait)
        except TimeoutError:
            if self.done():      # answered (or failed with its own SLRTimeout) meanwhile
                return super().result(0)
            raise SLRTimeout(self.timeout_message(timeout) + "; it is still waiting "
                             "(call result() again, or cancel())") from None

    def exception(self, timeout: float | None = None) -> BaseException | None:
        """The query's error (None when it was answered), waiting up to ``timeout``
        seconds as :meth:`result` does (its SLRTimeout included).

        >>> import slr_sql
        >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0))
        >>> kb.submit("X is 1 / 0", at=0).exception(timeout=5)
        SLREvaluationError('error(evaluation_error(zero_divisor),context((/)/2,_))')
        >>> kb.close()
        """
        wait = wait_seconds("exception: timeout", timeout)
        self._refuse_wait_inside_transaction("exception")
        try:
            return super().exception(wait)
        except TimeoutError:
            if self.done():
                return super().exception(0)
            raise SLRTimeout(self.timeout_message(timeout) + "; it is still waiting "
                             "(call exception() again, or cancel())") from None

    def _refuse_wait_inside_transaction(self, method: str) -> None:
        """Waiting for an answer inside a transaction of the store the calling thread holds
        would wait for itself: the query is evaluated on another thread, with the store's
        lock, and a query submitted or marked complete inside the transaction is registered
        once it ended. Answered already, there is nothing to wait for.

        >>> import slr_sql
        >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0)); p = kb.submit("p(X)^T", at=5)
        >>> with kb.store.transaction():
        ...     p.result(timeout=5)
        Traceback (most recent call last):
        ...
        slr_sql.errors.SLRError: PendingQuery.result() inside a transaction of the store: ...
        >>> kb.close()
        """
        if not self.done() and self._sync.store.in_transaction_here:
            raise SLRError(f"PendingQuery.{method}() inside a transaction of the store: the "
                           f"query is answered on another thread once the transaction ended "
                           f"(it needs the store, and what the transaction adds and marks); "
                           f"call {method}() after the transaction")

    def add_done_callback(self, fn: Callable[[Any], Any]) -> None:
        """Call ``fn(pending)`` once the query is answered, failed or cancelled (at once
        if it is already); ``fn`` that is not callable is an :class:`SLRError` here, not
        a logged TypeError later.

        >>> import slr_sql
        >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0)); p = kb.submit("p(X)^T", at=5)
        >>> p.add_done_callback(5)
        Traceback (most recent call last):
        ...
        slr_sql.errors.SLRError: add_done_callback: fn must be callable (a function), not 5
        >>> kb.close()
        """
        super().add_done_callback(check_callable("add_done_callback: fn", fn))

    def timeout_message(self, timeout: float | None) -> str:
        """The SLRTimeout text: which types were not complete, and their horizons."""
        sync = self._sync
        now = sync.clock.now()
        waits = self.waiting_for or [w for w in self.waits if w.released_at is None]
        parts = []
        for w in waits:
            parts.append(f"{w.type} ({w.reason}) would require its history up to "
                         f"{_fmt(w.time)}, but it is complete only up to "
                         f"{_fmt(sync.tracker.horizon(w.key, now))} "
                         f"({sync.tracker.describe(w.key, now)})")
        what = "; ".join(parts) if parts else "it was still being evaluated"
        after = f" within {timeout:g} s" if timeout is not None else ""
        return (f"synchronized query {self.id!r} ({self.goal} at {_fmt(self.at)}) was not "
                f"answerable{after}: {what}")


def _delay_warning(key: tuple[str, int], observed: float, cap: float, clock: Any) -> str:
    name = quoted_type_text(key)
    return (f"{name}: an event arrived {_fmt(observed, 1)} s after its end time on a store "
            f"whose clock is a {type(clock).__name__} (now {_fmt(clock.now(), 1)}): the "
            f"events' times are probably not the clock's time. The learned delay of {name} "
            f"is capped at {_fmt(cap)} s (max_learned_delay). For simulated or recorded "
            f"times give the store a ManualClock or a StreamClock (slr_sql.open(path, "
            f"clock=slr_sql.StreamClock())), or declare the delay (:- max_delay({name}, D).); "
            f"note that subscribe(since=\"now\") delivers only events that end after the "
            f"clock's now, so it does not deliver these")


class WrittenMarks(NamedTuple):
    """Marks :meth:`Synchronizer.store_marks` wrote, for :meth:`Synchronizer.apply_marks`
    once their transaction committed."""
    marks: list          # (key, time, source, (stored time, its source) or None)
    seen: dict[str, Any]  # the store's sync/ entries, read once they were written


class Completeness:
    """Per event type: max delay (declared or learned), marks, in-order latest end.

    State persisted in ``slr_meta``: ``sync/learned/<name>/<n>`` (seconds),
    ``sync/mark/<name>/<n>`` and ``sync/mark/<name>`` (time; the latter for
    ``fullyUpdated(p)`` = every arity of p), each mark with its source in ``sync/marksrc/...``.
    Delays and marks only grow: they are written with the store's ``meta_raise`` (the larger
    of the stored and the new value is kept, compared inside SQLite) and read back.
    """

    def __init__(self, store: Any, clock: Any, decls: Callable[[], Any],
                 max_learned: float | None = DEFAULT_MAX_LEARNED_DELAY):
        self.store = store
        self.clock = clock
        self._decls = decls
        self.max_learned = max_learned     # None: learned delays grow without a cap
        self.warned: set[tuple[str, int]] = set()   # types whose delay hit the cap
        self.learned: dict[tuple[str, int], float] = {}
        self.marks: dict[tuple[str, int], float] = {}
        self.name_marks: dict[str, float] = {}
        self.mark_src: dict[Any, str] = {}
        self.max_end: dict[tuple[str, int], float] = {}
        # a newest end first read inside a transaction that then rolled back may be of its
        # own events (the store's connection sees them): read again from what is stored
        store.rollback_listeners.append(self.max_end.clear)
        self.arrivals: dict[tuple[str, int], int] = {}
        self._persisted: dict[tuple[str, int], float] = {}   # learned delays as stored
        # learned delays whose write after an add failed (busy): the next add writes them
        self._unwritten: set[tuple[str, int]] = set()
        # event rules (slr_sql.cep): the completeness of complex event types, which follows
        # from the types their rules read; an object with ``types``, ``complete``,
        # ``horizon``, ``deadline``, ``why`` and ``describe`` (None: no event rules)
        self.derived: Any = None
        self.load()

    def _capped(self, key: tuple[str, int], observed: float, cap: float) -> None:
        """An event of ``key`` arrived ``observed`` s after its end, beyond the cap: say so,
        once per type, where it happens (a Python warning and the log)."""
        if key in self.warned:
            return
        self.warned.add(key)
        derived = self.derived
        if derived is not None and key in derived.types:
            # a complex event type: its completeness follows from the types its rules read,
            # whose own lateness is warned of; no delay of its own to declare
            return
        d = self._decls().max_delay.get(key)
        if d is not None and d != "learn":
            return                          # a declared delay: nothing is learned
        warnings.warn(LearnedDelayWarning(_delay_warning(key, observed, cap, self.clock)),
                      stacklevel=2)

    def flush(self, learned: dict | None = None, wait: bool = True) -> None:
        """Persist learned delays (all that grew since the last write by default). The
        store keeps the larger of its value and ours (another process may have learned a
        larger one meanwhile): we take the stored value back. ``wait=False``: SLRBusy at
        once when another connection holds a lock the write needs."""
        if learned is None:
            learned = {k: d for k, d in self.learned.items() if d > self._persisted.get(k, 0.0)}
        if not learned:
            return
        stored = {}
        with self.store.transaction(wait):
            for key, d in learned.items():
                stored[key] = self.store.meta_raise(f"sync/learned/{key[0]}/{key[1]}", d)
        for key, d in stored.items():
            self._persisted[key] = max(self._persisted.get(key, 0.0), d)
            self.learned[key] = max(self.learned.get(key, 0.0), d)

    def flush_at_close(self) -> None:
        """Write the learned delays not written yet (grown by less than 1 ms, or whose
        write after an add met a lock), waiting for another session's lock up to the
        store's busy timeout; those it still cannot write are named in a
        :class:`~slr_sql.clocks.LearnedDelayNotWrittenWarning`, not dropped in silence."""
        if self.store.closed:
            return
        unwritten = {k: d for k, d in self.learned.items() if d > self._persisted.get(k, 0.0)}
        try:
            self.flush(unwritten)
            self._unwritten.clear()
        except SLRError as exc:
            if self.store.closed:
                return
            for key, d in sorted(unwritten.items()):
                name = quoted_type_text(key)
                warnings.warn(LearnedDelayNotWrittenWarning(
                    f"{name}: the delay learned here ({_fmt(d)} s) was not written when the "
                    f"knowledge base closed ({exc}); the store keeps "
                    f"{_fmt(self._persisted.get(key, 0.0))} s, so another process may judge "
                    f"{name} complete earlier (:- max_delay({name}, {_fmt(d)}). declares "
                    f"it for good)"), stacklevel=5)

    def load(self) -> None:
        """(Re)read learned delays and marks from the store."""
        self.merge(self.store.meta_items("sync/"))

    def merge(self, items: dict[str, Any]) -> None:
        """Take the learned delays and marks of the store's ``sync/`` entries (read by
        :meth:`load`, or inside the transaction that wrote marks) where they are later."""
        for k, v in items.items():
            parts = k.split("/")
            try:
                if parts[1] == "learned" and len(parts) >= 4:
                    key = ("/".join(parts[2:-1]), int(parts[-1]))
                    self.learned[key] = max(self.learned.get(key, 0.0), float(v))
                    self._persisted[key] = max(self._persisted.get(key, 0.0), float(v))
                elif parts[1] == "mark":
                    key = self._key_of(parts[2:])
                    if isinstance(key, tuple):
                        self.marks[key] = max(self.marks.get(key, -_INF), float(v))
                    else:
                        self.name_marks[key] = max(self.name_marks.get(key, -_INF), float(v))
                elif parts[1] == "marksrc":
                    self.mark_src[self._key_of(parts[2:])] = str(v)
            except (ValueError, IndexError):
                continue

    @staticmethod
    def _key_of(parts: list[str]) -> Any:
        # sync/mark/<name>/<n> (name may contain '/': the last part is the arity) or sync/mark/<name>!
        if parts and parts[-1] == "*":
            return "/".join(parts[:-1])
        return ("/".join(parts[:-1]), int(parts[-1]))

    # -- reading -----------------------------------------------------------------------------
    def declared_delay(self, key: tuple[str, int]) -> float | None:
        d = self._decls().max_delay.get(key)
        if d is None or d == "learn":
            return None
        return float(d)

    def delay(self, key: tuple[str, int]) -> float:
        """The max delay used for ``key``: declared, else learned (0 before any event)."""
        d = self._decls().max_delay.get(key)
        if d is not None and d != "learn":
            return float(d)
        learned = self.learned.get(key, 0.0)
        cap = self.max_learned
        return learned if cap is None or learned <= cap else cap

    def mark(self, key: tuple[str, int]) -> float:
        return max(self.marks.get(key, -_INF), self.name_marks.get(key[0], -_INF))

    def in_order(self, key: tuple[str, int]) -> bool:
        return key in self._decls().in_order

    def latest_end(self, key: tuple[str, int]) -> float:
        e = self.max_end.get(key)
        if e is None:
            e = self.store.max_end(*key)
            e = self.max_end[key] = -_INF if e is None else float(e)
        return e

    def complete(self, key: tuple[str, int], z: float, now: float | None = None) -> bool:
        """Is the history of ``key`` complete up to ``z``?"""
        if self.derived is not None and key in self.derived.types:
            return self.derived.complete(key, z, now)
        if z <= self.mark(key):
            return True
        if now is None:
            now = self.clock.now()
        if z + self.delay(key) < now:
            return True
        return self.in_order(key) and z < self.latest_end(key)

    def horizon(self, key: tuple[str, int], now: float | None = None) -> float:
        """The time up to which ``key`` is complete now: max(now − max_delay, latest mark,
        and for in_order types the latest end received) — strictly below it for the first
        and last, up to and including it for a mark."""
        if self.derived is not None and key in self.derived.types:
            return self.derived.horizon(key, now)
        if now is None:
            now = self.clock.now()
        h = max(now - self.delay(key), self.mark(key))
        if self.in_order(key):
            h = max(h, self.latest_end(key))
        return h

    def deadline(self, key: tuple[str, int], z: float) -> float:
        """The clock time the clock must pass for ``key`` to be complete up to ``z``."""
        if self.derived is not None and key in self.derived.types:
            return self.derived.deadline(key, z)
        return z + self.delay(key)

    def describe(self, key: tuple[str, int], now: float | None = None) -> str:
        if self.derived is not None and key in self.derived.types:
            return self.derived.describe(key, now)
        if now is None:
            now = self.clock.now()
        dd = self.declared_delay(key)
        delay = (f"max_delay {_fmt(dd)} s declared" if dd is not None
                 else f"max_delay {_fmt(self.learned.get(key, 0.0))} s learned")
        m = self.mark(key)
        mark = (f"latest mark {_fmt(m)} from {self.mark_src.get(key) or self.mark_src.get(key[0], 'a mark')}"
                if m > -_INF else f"no {MARK_NAME}({type_text(key)}) mark yet")
        parts = [f"now {_fmt(now)}", delay, mark]
        if self.in_order(key):
            e = self.latest_end(key)
            parts.append(f"in order, latest end {_fmt(e)}" if e > -_INF else "in order, no event yet")
        return "; ".join(parts)

    def why(self, key: tuple[str, int], z: float, now: float) -> str:
        """Why ``key`` is complete up to ``z`` (for explanations)."""
        if self.derived is not None and key in self.derived.types:
            return self.derived.why(key, z, now)
        if z <= self.mark(key):
            src = self.mark_src.get(key) if self.marks.get(key, -_INF) >= z else None
            return src or self.mark_src.get(key[0]) or f"a mark >= {_fmt(z)}"
        if z + self.delay(key) < now:
            return (f"the clock passing {_fmt(z)} + max_delay {_fmt(self.delay(key))} "
                    f"(now {_fmt(now)})")
        if self.in_order(key) and z < self.latest_end(key):
            return f"an in-order {type_text(key)} event at {_fmt(self.latest_end(key))} > {_fmt(z)}"
        return "?"

    # -- updating (the Synchronizer holds its lock) ------------------------------------------
    def store_mark(self, key: Any, t: float, source: str) -> tuple[float, str] | None:
        """Write a mark to the store, in the caller's transaction if one is open; returns
        the mark stored and its source (another process's, when it stored a larger one), or
        None when this process knows one at least as late. Memory is left to
        :meth:`remember_mark`, once the write is committed: a write that failed, busy, is
        made again by the same mark retried. A batch's marks come here inside the store's
        transaction, without the synchronizer's lock (which comes before the store's):
        this reads its memory of marks only."""
        if isinstance(key, tuple):
            if t <= self.marks.get(key, -_INF):
                return None
            mk = f"{key[0]}/{key[1]}"
        else:
            if t <= self.name_marks.get(key, -_INF):
                return None
            mk = f"{key}/*"
        # the store keeps the larger mark (another process may have stored one meanwhile)
        with self.store.transaction():
            stored = self.store.meta_raise(f"sync/mark/{mk}", t)
            if stored == t:
                self.store.meta_set(f"sync/marksrc/{mk}", source)
            else:
                source = self.store.meta_get(f"sync/marksrc/{mk}", source)
        return stored, source

    def remember_mark(self, key: Any, stored: float, source: str) -> None:
        """A committed mark (:meth:`store_mark`) in memory."""
        if isinstance(key, tuple):
            self.marks[key] = max(self.marks.get(key, -_INF), stored)
        else:
            self.name_marks[key] = max(self.name_marks.get(key, -_INF), stored)
        self.mark_src[key] = source

    def observe(self, events: list, arrival: float) -> set:
        """Learn delays from stored ``(name, args, start, end)`` events; returns the in_order
        types that received events (their latest end / arrival counter moved). A batch the
        store filled with its types' end times (``events.ends``, an
        :class:`slr_sql.store.EventBatch`) is not walked again."""
        spans = getattr(events, "ends", None)
        if spans is None:
            spans = _end_spans(events)
        learned = self.learned
        in_order = self._decls().in_order
        grew: dict[tuple[str, int], float] = {}
        moved: set = set()
        cap = self.max_learned
        for key, (earliest, latest) in spans.items():
            best = arrival - earliest
            if cap is not None and best > cap:
                if learned.get(key, 0.0) < cap:   # said once, when the store first hits it
                    self._capped(key, best, cap)
                best = cap
            if best > learned.get(key, 0.0):
                grew[key] = best
            if in_order and key in in_order:
                if latest > self.latest_end(key):
                    self.max_end[key] = latest
                moved.add(key)
        if grew or self._unwritten:
            learned.update(grew)
            # persist when it grew by more than 1 ms (or 1 %): a stream whose delay creeps up
            # by float noise must not cost a durable write per event; close() writes the rest
            persisted = self._persisted
            due = {k: d for k, d in grew.items()
                   if d > persisted.get(k, 0.0) + max(1e-3, 0.01 * persisted.get(k, 0.0))}
            # a write that failed before, tried again now; alone, without waiting for a
            # lock (an add that learned nothing does not wait the busy timeout for it)
            retry = {k: learned[k] for k in self._unwritten if k not in due}
            if due or retry:
                try:
                    self.flush({**retry, **due}, wait=bool(due))
                    self._unwritten.clear()
                except SLRUnavailable:
                    # the events are committed: an add that raised now would be retried and
                    # store them twice. The delay stays learned here; the next add (of any
                    # type), or close, writes it -- not only one that learns more of it:
                    # another process must not judge the type complete earlier meanwhile
                    self._unwritten.update(due)
                    self._unwritten.update(retry)
        arrivals = self.arrivals
        for key in spans:   # every type: tf_lookup waits for an arrival of any type
            arrivals[key] = arrivals.get(key, 0) + 1
        return moved


class Synchronizer:
    """Pending synchronized queries of one knowledge base (created by :func:`attach`)."""

    def __init__(self, kb: Host, workers: int = 4):
        self.kb = kb
        self.clock = kb.clock
        self.store = kb.store
        self.lock = ordered_lock("sync", reentrant=True)
        self.cond = threading.Condition(self.lock)
        self.tracker = Completeness(kb.store, kb.clock, lambda: kb.declarations,
                                    getattr(kb, "max_learned_delay", DEFAULT_MAX_LEARNED_DELAY))
        self.workers = workers
        self._heaps: dict[tuple[str, int], list] = {}       # key -> [(time, seq, q, gen)]
        self._arrival_waits: dict[tuple[str, int], list] = {}  # key -> [(q, gen)]
        self._timers: list = []      # [(clock deadline, seq, key)]
        self._timeouts: list = []    # [(monotonic deadline, seq, q)]
        self._queries: dict[str, PendingQuery] = {}
        # the queries submitted inside a transaction, by id, until it ended and they are
        # registered in _queries (changed by single dict operations: atomic, no lock taken)
        self._deferred: dict[str, PendingQuery] = {}
        self._seq = itertools.count()
        self._ids = itertools.count(1)
        self._executor: ThreadPoolExecutor | None = None
        self._thread: threading.Thread | None = None
        self._worker_threads: set = set()
        self._closed = False
        self._inflight = 0
        self._fired = False   # a timer fired since the timer loop last told the listeners
        # other processes writing the same file (e.g. `slr add DB "fullyUpdated(seg/2)^14"`
        # while `slr query DB G --wait` waits): SQLite cannot notify us, so while queries are
        # pending the timer thread checks PRAGMA data_version every `external_poll` seconds.
        self.external_poll: float | None = None
        self._external_failure: str | None = None   # the re-read's failure, said once
        self._data_version: int | None = None
        # clocks that tell when they move serve time-driven wake-ups from their listener
        self._clock_driven = isinstance(self.clock, (ManualClock, StreamClock))
        # called (no lock held) when completeness may have advanced outside an add: the
        # clock moving, a timer of wake_at or wake_after firing, mark_complete (the event
        # pipeline's decision stage; an add's own marks and events go through it directly);
        # its argument says whether the timer thread calls it (no caller to raise to)
        self.progress_hook: Callable[[bool], None] | None = None
        if hasattr(self.clock, "subscribe"):
            self.clock.subscribe(self._on_clock)

    # -- public operations (KnowledgeBase delegates here) ----------------------------------------
    def submit(self, goal: str, at: float | None = None, id: str | None = None,
               args: dict | None = None, timeout: float | None = None,
               callback: Callable[[PendingQuery], Any] | None = None,
               robot: str | None = None) -> PendingQuery:
        if self._closed:
            raise SLRError("the knowledge base is closed")
        plan = self.kb.plans.plan(goal, tuple(args) if args else ())  # syntax errors raise here
        if at is None:
            at = float(self.clock.now())
        at = float(at)
        if self.store.in_transaction_here:
            return self._submit_after_transaction(goal, at, id, args, timeout, callback,
                                                  robot, plan)
        with self.lock:
            if id is None:
                id = f"q{next(self._ids)}"
                while id in self._queries or id in self._deferred:
                    id = f"q{next(self._ids)}"
            elif id in self._queries or id in self._deferred:
                raise SLRError(f"a query with id {id!r} is already pending")
            q = PendingQuery(self, str(id), goal, at, args)
            q.robot = robot
            q._plan = plan
            self._queries[q.id] = q
            if self.external_poll is not None:
                self.cond.notify_all()
            if timeout is not None:
                q._deadline = time.monotonic() + float(timeout)
                q._timeout = float(timeout)
                heapq.heappush(self._timeouts, (q._deadline, next(self._seq), q))
                self._ensure_thread()
                self.cond.notify_all()
        q.add_done_callback(self._forget)
        if callback is not None:
            q.add_done_callback(callback)
        # the goal-set condition is checked here, on the caller's thread: a query that must
        # wait is parked at once, without a trip through the worker pool
        try:
            term, _frame = instantiate(plan, args)
            ready = self._static_ready(q, term, self.clock.now())
        except BaseException as exc:
            self._set_exception(q, exc)
            return q
        if ready:
            self._schedule(q)
        return q

    def _submit_after_transaction(self, goal: str, at: float, id: str | None,
                                  args: dict | None, timeout: float | None,
                                  callback: Callable[[PendingQuery], Any] | None,
                                  robot: str | None, plan: Any) -> PendingQuery:
        """:meth:`submit` inside a transaction the calling thread holds: the synchronizer's
        lock comes before the store's, so the query is made now and registered once the
        transaction ended -- committed or rolled back (a query is no state of the store):
        it is answered on what was committed. Its ``timeout`` counts from now."""
        deferred = self._deferred
        if id is None:
            id = f"q{next(self._ids)}"
            while id in self._queries or id in deferred:
                id = f"q{next(self._ids)}"
        elif id in self._queries or id in deferred:
            raise SLRError(f"a query with id {id!r} is already pending")
        id = str(id)
        q = PendingQuery(self, id, goal, at, args)
        deferred[id] = q
        q.robot = robot
        q._plan = plan
        if timeout is not None:
            q._deadline = time.monotonic() + float(timeout)
            q._timeout = float(timeout)
        q.add_done_callback(self._forget)
        if callback is not None:
            q.add_done_callback(callback)

        def register() -> None:
            try:
                if q.done():         # cancelled meanwhile
                    return
                self._register_deferred(q)
            finally:
                deferred.pop(id, None)   # (after: pending() lists it all along)

        self.store.after_commit(register, always=True)
        return q

    def _register_deferred(self, q: PendingQuery) -> None:
        """Register and start a query :meth:`submit` made inside a transaction, once that
        ended; what fails is the query's answer, not an error of the transaction."""
        id, plan, args = q.id, q._plan, q.args
        try:
            if self._closed:
                raise SLRError(f"the knowledge base was closed while query {id!r} was "
                               f"waiting")
            with self.lock:
                if id in self._queries:
                    raise SLRError(f"a query with id {id!r} is already pending")
                self._queries[id] = q
                if self.external_poll is not None:
                    self.cond.notify_all()
                if q._deadline is not None:
                    heapq.heappush(self._timeouts, (q._deadline, next(self._seq), q))
                    self._ensure_thread()
                    self.cond.notify_all()
            term, _frame = instantiate(plan, args)
            ready = self._static_ready(q, term, self.clock.now())
        except BaseException as exc:   # the query's answer, not the transaction's error
            self._set_exception(q, exc)
            return
        if ready:
            self._schedule(q)

    def pending(self) -> list[PendingQuery]:
        # copies of the tables, not the synchronizer's lock: one C call each, atomic under
        # the GIL, and so callable inside a transaction of the store (whose lock comes after
        # it); a query submitted inside one waits too, registered or not yet
        queries = self._queries.copy()
        for id, q in self._deferred.copy().items():   # (registered, it is in both a moment)
            queries.setdefault(id, q)
        return [q for q in queries.values() if not q.done()]

    def mark_complete(self, spec: Any, t: float, source: str | None = None) -> None:
        """Apply a mark and tell the progress hook (decisions it makes possible are made)."""
        self.mark(spec, t, source)
        self._progress()

    def mark(self, spec: Any, t: float, source: str | None = None) -> None:
        """Apply a mark: persist it, release the queries it completes (the event pipeline's
        completeness stage: the caller runs the decisions)."""
        mark = self._mark_of(spec, t, source)
        with self.lock:   # (held while a mark is written, as while learned delays are)
            written = self.store_marks([mark])
        self.apply_marks(written)

    def write_mark(self, spec: Any, t: float, source: str | None = None) -> WrittenMarks:
        """Write a mark inside the transaction the calling thread holds (the store's lock
        is taken already: the synchronizer's, ordered before it, is not); the caller applies
        it (:meth:`apply_marks`) once that committed."""
        return self.store_marks([self._mark_of(spec, t, source)])

    @staticmethod
    def _mark_of(spec: Any, t: float, source: str | None) -> tuple[Any, float, str]:
        name, n = parse_type(spec)
        t = float(t)
        if math.isnan(t):
            raise SLRError("mark_complete: the time must be a number")
        key: Any = name if n is None else (name, n)
        if source is None:
            source = f"kb.mark_complete({type_text(key) if n is not None else name!r}, {_fmt(t)})"
        return key, t, source

    def complete_until(self, spec: Any) -> float:
        name, n = parse_type(spec)
        if n is None:
            arities = sorted({a for (nm, a) in self._known_types() if nm == name})
            if len(arities) != 1:
                raise SLRError(f"complete_until: say which arity of {name} "
                               f"({', '.join(f'{name}/{a}' for a in arities) or 'none known'})")
            n = arities[0]
        return self.tracker.horizon((name, n))

    def watch_external(self, interval: float = 0.05) -> None:
        """Also release queries on marks/events that *other processes* write to the file
        (checked every ``interval`` s while queries are pending; see docs). Inside a
        transaction the calling thread holds, once it ended (the synchronizer's lock comes
        before the store's)."""
        if self.store.in_transaction_here:
            self.store.after_commit(lambda: self.watch_external(interval), always=True)
            return
        with self.cond:
            self.external_poll = float(interval)
            self._data_version = self._read_data_version()
            self._ensure_thread()
            self.cond.notify_all()

    def _read_data_version(self) -> int | None:
        try:
            return self.store.data_version()
        except Exception:
            return None

    def on_progress(self) -> None:
        """Progress listener of the kb: another connection raised learned delays or
        completeness marks; re-read them and release the queries they complete."""
        with self.lock:
            released = self._reread()
        self._schedule_all(released)

    def run_decisions(self) -> None:
        """Run the decisions of event rules that completeness allows now (the progress
        hook: the event pipeline's stages 4-6), as a mark or a clock move does. For marks
        raised on this knowledge base's own connection other than by a mark (a fleet
        store's shipments and retirements raise the fleet's marks): :meth:`on_progress`
        re-reads them, and this makes the decisions they allow.

        >>> import slr_sql
        >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0))
        >>> kb.load(":- consumption(recent).\\nr(X) <- a(X) seq b(X).")
        >>> kb.add_many(["a(1)^1", "b(1)^3"])
        []
        >>> kb.query("r(X)^T")     # recent: the decision waits for a/1 and b/1 up to 3
        []
        >>> kb.store.meta_raise("sync/mark/a/1", 5.0); kb.store.meta_raise("sync/mark/b/1", 5.0)
        5.0
        5.0
        >>> kb.synchronizer.on_progress(); kb.synchronizer.run_decisions(); kb.query("r(X)^[S, E]")
        [{'X': 1, 'S': 1.0, 'E': 3.0}]
        >>> kb.close()
        """
        self._progress()

    def _external_changes(self) -> list:
        """Reload marks, learned delays and in-order ends if another connection committed
        (lock held); returns the queries that may now go on."""
        version = self._read_data_version()
        if version is None or version == self._data_version:
            return []
        released: list = []
        try:
            self._reread(released)
        except (SLRError, DatabaseError) as exc:
            # (the store busy or damaged, its tables changed under it by another process:
            # the timer thread has no caller to raise to and serves every later timer; the
            # queries released before the failure go on, the others stay parked, and the
            # next poll reads again -- said once, not at every poll)
            if isinstance(exc, DatabaseError):
                exc = store_error(exc, getattr(self.store, "path", None),
                                  outcome="nothing was read")
            if str(exc) != self._external_failure:
                self._external_failure = str(exc)
                log_failure(log, "re-reading what other processes wrote to the store", exc,
                            then="read again at every poll until it reads")
            return released
        if self._external_failure is not None:
            self._external_failure = None
            log.warning("re-reading what other processes wrote to the store works again")
        self._data_version = version
        return released

    def _reread(self, out: list | None = None) -> list:
        """Reload what the store says of completeness and release the queries it completes,
        appended to ``out`` (so that those released before a failing read are not lost)."""
        tracker = self.tracker
        tracker.load()
        tracker.max_end.clear()
        if out is None:
            out = []
        for key in list(self._heaps) + list(self._arrival_waits):
            if tracker.in_order(key):
                tracker.arrivals[key] = tracker.arrivals.get(key, 0) + 1
            out += self._release(key, arrival=True)
        return out

    def drain(self, timeout: float | None = None) -> bool:
        """Wait until no evaluation is queued or running (tests). True if idle."""
        end = None if timeout is None else time.monotonic() + timeout
        with self.cond:
            while self._inflight:
                left = None if end is None else end - time.monotonic()
                if left is not None and left <= 0:
                    return False
                self.cond.wait(left)
        return True

    def close(self) -> None:
        with self.cond:
            if self._closed:
                return
            self._closed = True
            queries = list(self._queries.values())
            self.cond.notify_all()
        if hasattr(self.clock, "unsubscribe"):
            self.clock.unsubscribe(self._on_clock)
        with self.lock:
            self.tracker.flush_at_close()
        for q in queries:
            if not q.done():
                self._set_exception(q, SLRError(f"the knowledge base was closed while query "
                                                f"{q.id!r} was waiting"))
        in_worker = threading.current_thread() in self._worker_threads
        if self._executor is not None:
            self._executor.shutdown(wait=not in_worker)
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=5.0)

    # -- events and marks (called by KnowledgeBase._add) ---------------------------------------
    def take_marks(self, events: list, atomic: bool) -> tuple[list, list, list]:
        """Split ``fullyUpdated(p/N)^t`` / ``fullyUpdated(p)^t`` out of an add batch:
        returns (events, marks, rejected)."""
        try:  # the common case, a batch without marks, seen at C speed
            if MARK_NAME not in set(map(_first_item, events)):
                return events, [], []
        except (TypeError, IndexError, KeyError):
            if not any(ev[0] == MARK_NAME for ev in events if isinstance(ev, tuple) and ev):
                return events, [], []
        keep, marks, errors = [], [], []
        for ev in events:
            try:
                name, args, start, end = ev
            except (TypeError, ValueError):
                keep.append(ev)
                continue
            if name != MARK_NAME or len(args) != 1:
                keep.append(ev)
                continue
            try:
                tname, n = parse_type(args[0])
                t = check_times(start, end)[1]  # numbers, finite, start <= end
            except (SLRError, BadEvent, TypeError, ValueError) as exc:
                err = EventRejected(f"{MARK_NAME}({args[0]})^{end}: {exc} (a completeness "
                                    f"mark is written fullyUpdated(p/N)^T or fullyUpdated(p)^T)")
                err.event = ev
                if atomic:
                    raise err from None
                errors.append(err)
                continue
            key: Any = tname if n is None else (tname, n)
            src = f"{MARK_NAME}({tname if n is None else type_text(key)})^{_fmt(t)}"
            marks.append((key, t, src))
        return keep, marks, errors

    def store_marks(self, marks: list) -> WrittenMarks:
        """Write marks -- those taken from an add (:meth:`take_marks`) in the transaction
        that stores its events, so that the batch is stored whole or not at all; returns
        them for :meth:`apply_marks` after the commit, with the store's marks as the same
        transaction reads them once they are written: of two marks made at once (their raises
        take turns, :meth:`EventStore.meta_raise`), the one committed last sees both and
        decides. Read here, not after the commit: a read that failed then would fail a call
        whose batch is stored, and its retry would store it twice."""
        with self.store.transaction():
            written = [(key, t, source, self.tracker.store_mark(key, t, source))
                       for key, t, source in marks]
            seen = self.store.meta_items("sync/") \
                if any(stored is not None for *_, stored in written) else {}
        return WrittenMarks(written, seen)

    def apply_marks(self, written: WrittenMarks) -> None:
        """Marks as :meth:`store_marks` wrote them (for an add, its completeness stage of the
        event pipeline): held in memory, waiting queries they complete released."""
        released: list = []
        with self.lock:
            keys = []
            for key, _t, source, stored in written.marks:
                if stored is not None:
                    self.tracker.remember_mark(key, *stored)
                    keys.append(key)
            self.tracker.merge(written.seen)
            for key in keys:
                released += self._released_by_mark(key)
        self._schedule_all(released)

    def _released_by_mark(self, key: Any) -> list:
        keys = [key] if isinstance(key, tuple) else [k for k in list(self._heaps) if k[0] == key]
        released: list = []
        for k in keys:
            released += self._release(k)
        return released

    def on_add(self, stored: list) -> None:
        """Events were stored (the event pipeline's completeness stage): learn delays, move
        in-order horizons, release waiting queries."""
        if not stored:
            return
        clock = self.clock
        if isinstance(clock, StreamClock):
            spans = getattr(stored, "ends", None)
            clock.observe_event(max(span[1] for span in spans.values()) if spans
                                else max(map(_fourth, stored)))
        arrival = float(clock.now())
        released: list = []
        with self.lock:
            moved = self.tracker.observe(stored, arrival)
            if self._arrival_waits:   # waits for an arrival of a type that is not in order
                spans = getattr(stored, "ends", None)
                arrived = spans.keys() if spans is not None else _end_spans(stored).keys()
                moved = moved | (arrived & self._arrival_waits.keys())
            for key in moved:
                released += self._release(key, arrival=True)
        self._schedule_all(released)

    # -- event rules (slr_sql.cep) ---------------------------------------------------------------
    def _progress(self, timer: bool = False) -> None:
        hook = self.progress_hook
        if hook is not None and not self._closed:
            hook(timer)

    def _progress_from_timer(self) -> None:
        """:meth:`_progress` on the timer thread, which serves every later timer: what the
        round raises (an add listener's own error; a failed decision round is tried again by
        the pipeline) has no caller to go to, and is logged instead of ending the thread."""
        try:
            self._progress(timer=True)
        except Exception as exc:   # (no traceback: a listener's text is the user's)
            log.warning("a round the clock started failed (%s: %s); later timers still run",
                        type(exc).__name__, exc)

    def recheck(self, keys: Iterable[tuple[str, int]]) -> None:
        """Release the queries parked on ``keys`` whose condition holds now (complex event
        types: their completeness moves when the event rules decide, not by a timer)."""
        released: list = []
        with self.lock:
            for key in keys:
                if key in self._heaps:
                    released += self._release(key)
        self._schedule_all(released)

    def wake_at(self, key: tuple[str, int], z: float) -> None:
        """Tell the progress listeners when the clock completes ``key`` up to ``z``."""
        with self.cond:
            if not self._closed:
                self._push_timer(key, self.tracker.deadline(key, z))

    def wake_after(self, seconds: float) -> None:
        """Tell the progress listeners again ``seconds`` of the clock from now (a decision
        round that failed busy, tried again). A wall clock only: the next move of a clock
        that tells when it moves tells them anyway."""
        with self.cond:
            if not self._closed and not self._clock_driven:
                self._push_timer(None, float(self.clock.now()) + seconds)

    # -- internals ----------------------------------------------------------------------------
    def _known_types(self) -> set:
        return set(self.store.event_types()) | set(self.kb.declarations.event_types)

    def _clock_span(self, w: Wait) -> str:
        return f"{_dur(self.clock.now() - w.since)} s"

    def _forget(self, q: PendingQuery) -> None:
        if q.answered_at is None:
            q.answered_at = self.clock.now()
            q.answered_wall = time.monotonic()
        if self.store.in_transaction_here:
            # q.cancel() inside a transaction this thread holds: the synchronizer's lock
            # comes before the store's, so q leaves the table once the transaction ended
            # (done already, it is in no list of pending queries meanwhile)
            self.store.after_commit(lambda: self._forget(q), always=True)
            return
        with self.lock:
            if self._queries.get(q.id) is q:
                del self._queries[q.id]

    def _ensure_executor(self) -> ThreadPoolExecutor:
        if self._executor is None:
            self._executor = ThreadPoolExecutor(max_workers=self.workers,
                                                thread_name_prefix="slr-sync",
                                                initializer=self._register_worker)
        return self._executor

    def _register_worker(self) -> None:
        self._worker_threads.add(threading.current_thread())

    def _ensure_thread(self) -> None:
        if self._thread is None and not self._closed:
            self._thread = threading.Thread(target=self._timer_loop, name="slr-sync-timer",
                                            daemon=True)
            self._thread.start()

    def _schedule(self, q: PendingQuery) -> None:
        with self.lock:
            if self._closed:
                return
            self._inflight += 1
            executor = self._ensure_executor()
        try:
            executor.submit(self._run, q)
        except RuntimeError:  # shut down meanwhile
            with self.cond:
                self._inflight -= 1
                self.cond.notify_all()

    def _schedule_all(self, queries: Iterable[PendingQuery]) -> None:
        for q in queries:
            self._schedule(q)

    def _run(self, q: PendingQuery) -> None:
        try:
            if not q.done() and not self._closed:
                self._attempt(q)
        except BaseException as exc:  # an evaluation error is the query's answer
            self._set_exception(q, exc)
        finally:
            with self.cond:
                self._inflight -= 1
                if not self._inflight:
                    self.cond.notify_all()

    def _set_exception(self, q: PendingQuery, exc: BaseException) -> None:
        try:
            q.set_exception(exc)
        except InvalidStateError:
            pass

    def _release_waits(self, q: PendingQuery, now: float) -> None:
        """Mark the current waits whose condition holds now as released (explanations)."""
        tracker = self.tracker
        for w in q.waiting_for:
            if w.released_at is not None:
                continue
            if tracker.complete(w.key, w.time, now):
                why = tracker.why(w.key, w.time, now)
            elif w.kind == "arrival" and tracker.arrivals.get(w.key, 0) != w.seen:
                why = f"the arrival of a {w.type} event it waited for"
            else:
                continue
            w.released_at = now
            w.released_wall = time.monotonic()
            w.released_by = why

    def _attempt(self, q: PendingQuery) -> None:
        kb = self.kb
        now = self.clock.now()
        released_at = q._released_at
        if released_at is not None:   # the clock when the scheduler released it
            self._release_waits(q, min(released_at, now))
        self._release_waits(q, now)
        plan = q._plan
        term, frame = instantiate(plan, q.args)
        if not self._static_ready(q, term, now):
            return
        answers = self._sql_answers(q, now)
        if answers is not None:
            q.evaluations += 1
            q.engine = "sql"
            self._finish(q, answers)
            return
        remaining = None
        if q._deadline is not None:
            remaining = max(q._deadline - time.monotonic(), 0.001)
        m = kb.engine.machine(at=q.at, timeout=remaining)
        m.robot = q.robot
        m.stop = q._stop
        m.synchronized = True  # for engines that bypass the hooks (SQL): do not
        m.on_prev = self._check_prev
        m.on_next = lambda name, n, lo, hi, args, s=None, e=None: \
            self._check_next(m, name, n, lo, hi, args, s, e)
        m.on_arrival = lambda name, n, t, args: self._check_arrival(m, name, n, t, args)
        answers = []
        q.evaluations += 1
        solving = m.solve(term)
        try:
            for _ in solving:
                answers.append(answer_bindings(plan.names, frame, m.deadline, plan.named))
        except _MustWait as w:
            m.abandon(solving)
            wait = Wait(w.key, w.time, w.reason, self.clock.now(), w.kind)
            wait.seen = w.seen
            self._park(q, [wait], [(w.key, w.time, w.kind, w.seen)])
            return
        q.engine = "interpreter"
        self._finish(q, answers)

    def _finish(self, q: PendingQuery, answers: list) -> None:
        with self.lock:
            q.waiting_for = []
            q.answered_at = self.clock.now()
            q.answered_wall = time.monotonic()
        try:
            q.set_result(answers)
        except InvalidStateError:
            pass

    def _sql_answers(self, q: PendingQuery, now: float) -> list | None:
        """The answers through the compiled statement, when the goal compiles and every
        prev/next in it reads a history that is complete up to its (constant) time — the
        dynamic condition of docs/synchronization.md checked before the statement runs, for
        all of them at once. None: evaluate in the interpreter, whose hooks wait for exactly what the
        evaluation reaches."""
        kb = self.kb
        from .planner import SqlPlan, compiles_for, plan_for

        if not kb.sql_enabled or not compiles_for(kb.store) or q.robot is not None:
            return None   # (one robot's answers: the interpreter)

        # the kb's current parse of the goal, not q._plan: a load or define while the query
        # waited drops the kb's plans, and the compiled statement with them (the program and
        # so the statement may have changed)
        plan = kb.plans.plan(q.goal, tuple(q.args) if q.args else ())
        entry = plan_for(kb, plan, q.at is not None)
        if type(entry) is not SqlPlan:
            return None
        times = entry.history_times(q.at)
        if times is None:
            return None
        complete = self.tracker.complete
        for key, t in times:
            if t is None or not complete(key, t, now):
                return None
        return _try_run(kb, entry, q)

    def _static_ready(self, q: PendingQuery, term: Any, now: float) -> bool:
        """The goal-set condition; parks ``q`` on the missing types when it does not hold.
        The goal set is computed once per program (a load replaces the Program object)."""
        program = self.kb.program
        if q._gs_program is not program:
            gs = goal_set(program, term)
            if gs.unknown:
                gs = goal_set(program, term, known_types=self._known_types())
            q.goal_set = gs
            q._gs_program = program
            q._gs_sorted = sorted(gs)
        z = q.at
        complete = self.tracker.complete
        missing = [k for k in q._gs_sorted if not complete(k, z, now)]
        if missing:
            waits = [Wait(k, z, "goal set", now) for k in missing]
            self._park(q, waits, [(k, z, "complete", 0) for k in missing])
            return False
        return True

    def _check_prev(self, name: str, n: int, t: float) -> None:
        key = (name, n)
        if not self.tracker.complete(key, t):
            raise _MustWait(key, t, f"prev({name}/{n}) up to {_fmt(t)}")

    def _check_next(self, m: Any, name: str, n: int, lo: float, hi: float, args: tuple,
                    s: Any, e: Any) -> None:
        key = (name, n)
        tracker = self.tracker
        if tracker.complete(key, hi):
            return
        reason = f"next({name}/{n}) in [{_fmt(lo)}, {_fmt(hi)}]"
        if tracker.in_order(key):
            seen = tracker.arrivals.get(key, 0)
            if self._stored_match(m, name, n, lo, hi, args, s, e):
                return
            raise _MustWait(key, hi, reason, "arrival", seen)
        raise _MustWait(key, hi, reason)

    def _check_arrival(self, m: Any, name: str, n: int, t: float, args: tuple) -> None:
        """tf_lookup found no observation of an edge at or after ``t``: wait until an event
        of the type arrives (then evaluate again). An event that arrived since the lookup
        read the store makes the query run again at once."""
        key = (name, n)
        seen = self.tracker.arrivals.get(key, 0)
        if self._stored_match(m, name, n, t, _INF, args, None, None):
            seen = -1
        raise _MustWait(key, _INF, f"an observation of {name}/{n} at or after {_fmt(t)}",
                        "arrival", seen)

    def _stored_match(self, m: Any, name: str, n: int, lo: float, hi: float, args: tuple,
                      s: Any, e: Any) -> bool:
        from .builtins import matching_rows
        from .unify import bound_args

        pattern = tuple(args) + (Var() if s is None else s, Var() if e is None else e)
        rows = self.store.next_candidates(name, n, bound_args(args), lo, hi)
        return next(matching_rows(m, pattern, rows), None) is not None

    def _park(self, q: PendingQuery, waits: list[Wait], conds: list[tuple]) -> None:
        """Index ``q`` on each condition ``(key, t, kind, seen)`` — released when any of them
        holds (it is then re-checked as a whole) — or re-run it at once if one holds already."""
        rerun = False
        with self.cond:
            if q.done() or self._closed:
                return
            # keep the Wait objects of conditions that are still the same (their start time)
            old = [w for w in q.waiting_for if w.released_at is None]
            merged = []
            for w in waits:
                same = next((o for o in old if o.same(w)), None)
                if same is not None:
                    merged.append(same)
                else:
                    merged.append(w)
                    q.waits.append(w)
            q.waiting_for = merged
            now = self.clock.now()
            tracker = self.tracker
            for key, t, kind, seen in conds:
                if tracker.complete(key, t, now) or \
                        (kind == "arrival" and tracker.arrivals.get(key, 0) != seen):
                    rerun = True
                    break
            if not rerun:
                q._gen += 1
                gen = q._gen
                for key, t, kind, seen in conds:
                    heapq.heappush(self._heaps.setdefault(key, []),
                                   (t, next(self._seq), q, gen))
                    if kind == "arrival":
                        self._arrival_waits.setdefault(key, []).append((q, gen))
                    self._push_timer(key, tracker.deadline(key, t))
        if rerun:
            self._schedule(q)

    def _push_timer(self, key: tuple[str, int] | None, deadline: float) -> None:
        """A timer at the clock's ``deadline``: ``key``'s parked queries are looked at and
        the progress listeners told (``key`` None: only told)."""
        if deadline == _INF or math.isnan(deadline):
            return
        timers = self._timers
        first = not timers or deadline < timers[0][0]
        heapq.heappush(timers, (deadline, next(self._seq), key))
        if not self._clock_driven and first:
            self._ensure_thread()
            self.cond.notify_all()

    def _release(self, key: tuple[str, int], arrival: bool = False) -> list:
        """Pop the queries parked on ``key`` whose condition holds now (lock held)."""
        out = []
        now = self.clock.now()
        tracker = self.tracker
        heap = self._heaps.get(key)
        if heap:
            while heap:
                t, _, q, gen = heap[0]
                if q._gen != gen or q.done():
                    heapq.heappop(heap)
                    continue
                if not tracker.complete(key, t, now):
                    break
                heapq.heappop(heap)
                q._gen += 1
                q._released_at = now
                out.append(q)
            if heap:
                self._push_timer(key, tracker.deadline(key, heap[0][0]))
            else:
                del self._heaps[key]
        if arrival:
            for q, gen in self._arrival_waits.pop(key, ()):
                if q._gen == gen and not q.done():
                    q._gen += 1
                    q._released_at = now
                    out.append(q)
        return out

    def _fire_timers(self, now: float) -> list:
        """Release what the clock passing ``now`` completes (lock held)."""
        timers = self._timers
        keys = set()
        while timers and timers[0][0] < now:
            keys.add(heapq.heappop(timers)[2])
            self._fired = True
        keys.discard(None)   # (wake_after's: nothing parked on it)
        out = []
        for key in keys:
            out += self._release(key)
        return out

    def _on_clock(self, t: float) -> None:
        """Clock listener (ManualClock / StreamClock): serve time-driven completeness."""
        if self._closed:
            return
        if self.store.in_transaction_here:
            # the clock moved inside a transaction this thread holds: the synchronizer's
            # lock comes before the store's (a mark takes them in that order), so the
            # timers fire once it ended -- also after a rollback, which does not take
            # back the clock's move
            self.store.after_commit(lambda: self._on_clock(t), always=True)
            return
        with self.lock:
            released = self._fire_timers(float(t))
            self._fired = False
        self._schedule_all(released)
        self._progress()

    def _expire(self, mono: float) -> list:
        out = []
        timeouts = self._timeouts
        while timeouts and timeouts[0][0] <= mono:
            _, _, q = heapq.heappop(timeouts)
            if not q.done():
                q._gen += 1
                out.append(q)
        return out

    def _timer_loop(self) -> None:
        """One thread: sleeps until the earliest clock deadline (WallClock) or query timeout."""
        with self.cond:
            while not self._closed:
                released: list = []
                if not self._clock_driven:
                    released = self._fire_timers(float(self.clock.now()))
                expired = self._expire(time.monotonic())
                if self.external_poll is not None and self._queries:
                    released += self._external_changes()
                wait = None
                if not self._clock_driven and self._timers:
                    wait = max(self._timers[0][0] - self.clock.now(), 0.0) + 1e-4
                if self._timeouts:
                    w2 = max(self._timeouts[0][0] - time.monotonic(), 0.0) + 1e-4
                    wait = w2 if wait is None else min(wait, w2)
                if self.external_poll is not None and self._queries:
                    wait = self.external_poll if wait is None else min(wait, self.external_poll)
                if released or expired or self._fired:
                    fired, self._fired = self._fired, False
                    self.cond.release()
                    try:
                        if fired:
                            self._progress_from_timer()
                        self._schedule_all(released)
                        for q in expired:
                            self._set_exception(q, SLRTimeout(
                                q.timeout_message(getattr(q, "_timeout", None))))
                    finally:
                        self.cond.acquire()
                    continue
                # a deadline far away (a query at 1e12) would overflow the platform's
                # time_t and kill this thread: wake up hourly instead and look again
                self.cond.wait(None if wait is None else min(wait, 3600.0))


def attach(kb: Host) -> Synchronizer:
    """Create the synchronizer of ``kb`` (the event pipeline calls it for adds and marks).

    >>> import slr_sql
    >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0))  # its __init__ calls attach(kb)
    >>> q = kb._sync.submit("findall(X, step(X)^_, L)", at=5)  # as kb.submit: waits for step/1
    >>> q.done()
    False
    >>> kb.add("step(a)^3"); kb.mark_complete("step/1", 5); q.result(timeout=5)
    [{'L': [Atom('a')]}]
    >>> kb.close()
    """
    sync = Synchronizer(kb)
    kb.progress_listeners.append(sync.on_progress)
    return sync


def _try_run(kb: Host, entry: Any, q: PendingQuery) -> list | None:
    from .encoding import Unencodable

    try:
        return entry.run(kb, q.args or {}, q.at, None, q._deadline, stop=q._stop)
    except (DatabaseError, Unencodable, ValueError, TypeError, KeyError, OverflowError):
        return None
