"""Clocks: where "now" comes from (arrival times, tBuffer pruning, max_delay completeness).

* :class:`WallClock` — a live robot (``time.time()``), the default.
* :class:`ManualClock` — tests and simulation: time moves only by ``set``/``advance``.
* :class:`StreamClock` — replaying recorded data: now = the greatest end time received.

A clock notifies its listeners when it moves, so that anything waiting on time (synchronized
queries, time-driven pruning) is woken by the move itself rather than by polling.
"""
from __future__ import annotations

import math
import time
from typing import Any, Callable

from .arguments import check_callable, check_time_option
from .errors import SLRError
from .lockorder import ordered_lock
from .terms import Atom, deref, format_term

__all__ = ["Clock", "WallClock", "ManualClock", "StreamClock", "parse_duration",
           "DEFAULT_MAX_LEARNED_DELAY", "LearnedDelayWarning", "LearnedDelayNotWrittenWarning"]


DEFAULT_MAX_LEARNED_DELAY = 3600.0
"""Seconds a learned delay may reach (``slr_sql.open(max_learned_delay=)``; None: no cap).
An event that arrives later than this after its end time is still stored; its type's
history counts as complete up to ``now - max_learned_delay`` at most, so a clock far from
the events' times (events stamped 2.0, 5.0 on a store with a wall clock) cannot make
synchronized queries and ``until`` subscriptions wait for decades."""


class LearnedDelayWarning(UserWarning):
    """Events arrived much later than their end time: the store's clock and the events'
    times are probably not the same time (a wall clock and simulated or recorded times);
    the learned delay was capped (:data:`DEFAULT_MAX_LEARNED_DELAY`)."""


class LearnedDelayNotWrittenWarning(UserWarning):
    """``close()`` could not write a delay learned here (another session held a lock it
    needs past the busy timeout, or the connection was lost): the store keeps the smaller
    delay it had, so another process may judge that type complete earlier than this one
    did. The message names the type and the delay (``max_delay`` declares it for good)."""


class Clock:
    """Base class: ``now()`` plus listeners called with the new time when the clock moves."""

    def __init__(self) -> None:
        self._listeners: list[Callable[[float], None]] = []
        self._lock = ordered_lock("clock.listeners")

    def now(self) -> float:  # pragma: no cover - abstract
        raise NotImplementedError

    def subscribe(self, fn: Callable[[float], None]) -> None:
        """Call ``fn(t)`` each time the clock moves (to ``t``); ``fn`` must be callable.

        >>> ManualClock(0).subscribe(5)
        Traceback (most recent call last):
        ...
        slr_sql.errors.SLRError: Clock.subscribe: fn must be callable (a function), not 5
        """
        check_callable("Clock.subscribe: fn", fn)
        with self._lock:
            self._listeners.append(fn)

    def unsubscribe(self, fn: Callable[[float], None]) -> None:
        with self._lock:
            if fn in self._listeners:
                self._listeners.remove(fn)

    def _moved(self, t: float) -> None:
        with self._lock:
            listeners = list(self._listeners)
        for fn in listeners:
            fn(t)

    def observe_event(self, end: float) -> None:
        """Called by the store for each event stored (only StreamClock cares)."""


class WallClock(Clock):
    """Real time in seconds since the epoch.

    >>> WallClock().now() > 1e9
    True
    """

    def now(self) -> float:
        return time.time()


class ManualClock(Clock):
    """A clock that only moves when told to.

    >>> c = ManualClock(0.0); c.advance(1.5); c.now()
    1.5
    """

    def __init__(self, t: float = 0.0) -> None:
        super().__init__()
        check_time_option("ManualClock: t", t, required=True, real=True)
        self._t = float(t)

    def now(self) -> float:
        return self._t

    def set(self, t: float) -> None:
        check_time_option("ManualClock.set: t", t, required=True, real=True)
        if t < self._t:
            raise SLRError(f"ManualClock cannot go back in time ({t} < {self._t})")
        self._t = float(t)
        self._moved(self._t)

    def advance(self, dt: float) -> None:
        check_time_option("ManualClock.advance: dt", dt, minimum=0.0, required=True, real=True)
        self.set(self._t + dt)


class StreamClock(Clock):
    """Replay clock: now is the greatest end time of any event received so far.

    >>> c = StreamClock(); c.observe_event(3.0); c.observe_event(2.0); c.now()
    3.0
    """

    def __init__(self, t: float = float("-inf")) -> None:
        super().__init__()
        self._t = t

    def now(self) -> float:
        return self._t

    def observe_event(self, end: float) -> None:
        if end > self._t:
            self._t = end
            self._moved(end)


def parse_duration(t: Any) -> float:
    """A duration term in seconds: numbers (the parser already turned ``500ms`` into 0.5).

    >>> parse_duration(60), parse_duration(Atom("inf"))
    (60, inf)
    """
    t = deref(t)
    if type(t) in (int, float) and not (type(t) is float and math.isnan(t)) and t >= 0:
        return t
    if type(t) is Atom and t in ("inf", "infinite"):
        return math.inf
    raise SLRError(f"a duration must be a non-negative number of seconds, not {format_term(t)}")
