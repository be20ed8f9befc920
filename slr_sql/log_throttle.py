r"""Log lines a stranger can make happen, kept few and one line each.

A client that opens and drops connections in a loop, sends bytes that are not HTTP or a
WebSocket text frame that is not UTF-8, or publishes messages that do not map, makes the
server or the bridge say so once per connection or message. Without a bound, such lines fill
a disk and bury the lines around them. :class:`LogThrottle` lets :data:`BURST` lines of one
kind through per :data:`PERIOD` seconds of a clock (``slr_sql.clocks``: a test moves a
:class:`~slr_sql.clocks.ManualClock`); the next line of that kind let through after some were
left out says how many. :class:`ThrottledLogFilter` applies it to a :mod:`logging` logger and
:class:`ThrottledLog` to a function that writes a line; both make each line one line of at
most :data:`~slr_sql.printable.LOG_TEXT_LIMIT` characters with its control characters
escaped (:func:`slr_sql.printable.log_text`), and the lines a client's bytes cause carry no
traceback (docs/printed_text.md).

>>> from slr_sql.clocks import ManualClock
>>> clock = ManualClock(0); lines = []
>>> say = ThrottledLog(lines.append, clock, burst=2, period=60)
>>> for port in range(5):
...     say(f"client 127.0.0.1:{port} connected")
>>> clock.advance(60); say("client 127.0.0.1:9 connected"); say("bad\nINFO: forged")
>>> lines[1:]
['client 127.0.0.1:1 connected', 'client 127.0.0.1:9 connected (3 lines like it left out before)', 'bad\\nINFO: forged']
"""
from __future__ import annotations

import logging
import re
import threading
from typing import Any, Callable, Hashable

from .clocks import Clock, WallClock
from .printable import log_text

__all__ = ["LogThrottle", "ThrottledLog", "ThrottledLogFilter", "line_kind", "with_left_out",
           "BURST", "PERIOD", "CLIENT_FAULTS"]

BURST = 20        # lines of one kind let through per period
PERIOD = 60.0     # seconds
MAX_KINDS = 256   # kinds remembered at once (a kind may hold a stranger's text)

# uvicorn's lines about a client's bytes that it logs with a traceback: the traceback says
# nothing about the server (one line in words instead)
CLIENT_FAULTS = frozenset({"Invalid UTF-8 sequence received from client."})

_NUMBERS = re.compile(r"\d+")


class LogThrottle:
    """At most ``burst`` lines of one kind per ``period`` seconds of ``clock``.

    >>> from slr_sql.clocks import ManualClock
    >>> clock = ManualClock(0); throttle = LogThrottle(clock, burst=1, period=10)
    >>> throttle.admit("k"), throttle.admit("k"), throttle.admit("k")
    (0, None, None)
    >>> clock.advance(10); throttle.admit("k")
    2
    """

    def __init__(self, clock: Clock | None = None, burst: int = BURST, period: float = PERIOD):
        self.clock = clock or WallClock()
        self.burst = burst
        self.period = period
        self._lock = threading.Lock()
        # kind -> [start of its period, lines let through in it, lines left out not yet said]
        self._kinds: dict[Hashable, list] = {}

    def admit(self, kind: Hashable) -> int | None:
        """None: leave this line out (counted); else let it through, and this many lines of
        its kind were left out before it."""
        now = self.clock.now()
        with self._lock:
            state = self._kinds.get(kind)
            if state is None:
                if len(self._kinds) >= MAX_KINDS:
                    self._forget_quiet(now)
                    if len(self._kinds) >= MAX_KINDS:
                        kind = "(kinds beyond the ones remembered)"
                state = self._kinds.setdefault(kind, [now, 0, 0])
            if now - state[0] >= self.period:
                state[0], state[1] = now, 0
            if state[1] >= self.burst:
                state[2] += 1
                return None
            state[1] += 1
            left_out, state[2] = state[2], 0
            return left_out

    def _forget_quiet(self, now: float) -> None:
        for kind, (start, _passed, left_out) in list(self._kinds.items()):
            if now - start >= self.period and not left_out:
                del self._kinds[kind]


def with_left_out(text: str, left_out: int) -> str:
    """``text``, and how many lines like it were left out before it, if any.

    >>> with_left_out("client left", 0), with_left_out("client left", 3)
    ('client left', 'client left (3 lines like it left out before)')
    """
    return f"{text} ({left_out} line{'s' if left_out != 1 else ''} like it left out before)" \
        if left_out else text


def line_kind(text: str) -> str:
    """The kind of a line for :class:`LogThrottle`: its text with numbers (ports,
    counts) made alike, cut short.

    >>> line_kind("client 127.0.0.1:40028 connected") == line_kind("client 127.0.0.1:5 connected")
    True
    """
    return _NUMBERS.sub("#", text[:80])


class ThrottledLog:
    """``emit(line)`` for each line a stranger's input makes: the line made safe
    (:func:`~slr_sql.printable.log_text`), at most ``burst`` lines of a kind
    (:func:`line_kind`) per ``period`` seconds."""

    def __init__(self, emit: Callable[[str], Any], clock: Clock | None = None,
                 burst: int = BURST, period: float = PERIOD):
        self.emit = emit
        self.throttle = LogThrottle(clock, burst, period)

    def __call__(self, text: str) -> None:
        left_out = self.throttle.admit(line_kind(text))
        if left_out is not None:
            self.emit(with_left_out(log_text(text), left_out))


class ThrottledLogFilter(logging.Filter):
    """A :mod:`logging` filter: each record made one safe line, at most ``burst`` records
    of a kind (logger, level, message template) per ``period`` seconds; a record of
    :data:`CLIENT_FAULTS` loses its traceback (its exception said in words instead).
    Records of ERROR and above that are no client's fault keep their traceback (a bug's),
    their message made safe and bounded all the same.

    >>> import io
    >>> from slr_sql.clocks import ManualClock
    >>> out = io.StringIO(); log = logging.getLogger("slr_sql.example.throttled")
    >>> log.addHandler(logging.StreamHandler(out)); log.propagate = False
    >>> log.addFilter(ThrottledLogFilter(ManualClock(0), burst=1))
    >>> for n in range(3):
    ...     log.warning("input the knowledge base did not take: %r", ValueError("x\\ny" * n))
    >>> print(out.getvalue(), end="")
    input the knowledge base did not take: ValueError('')
    """

    def __init__(self, clock: Clock | None = None, burst: int = BURST, period: float = PERIOD):
        super().__init__()
        self.throttle = LogThrottle(clock, burst, period)

    def filter(self, record: logging.LogRecord) -> bool:
        template = str(record.msg)
        left_out = self.throttle.admit((record.name, record.levelno,
                                        template if record.args else line_kind(template)))
        if left_out is None:
            return False
        try:
            text = record.getMessage()
        except Exception:  # noqa: BLE001 - a record that cannot be made says so
            text = f"{template} (its arguments could not be formatted)"
        if template in CLIENT_FAULTS and record.exc_info:
            exc = record.exc_info[1]
            if exc is not None:
                text = f"{text} ({type(exc).__name__}: {exc})"
            record.exc_info = None
            record.exc_text = None
        record.msg, record.args = with_left_out(log_text(text), left_out), None
        return True
