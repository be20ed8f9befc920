"""Checking events before they are stored, and writing them as text for messages.

An invalid event (bad times, non-ground or NaN arguments, wrong arity) raises
:class:`BadEvent` inside the store; :mod:`slr_sql.store.events` turns it into an
:class:`~slr_sql.errors.EventRejected` whose message starts with :func:`format_event`.
"""
from __future__ import annotations

import json
import math
import re
from typing import Any

from ..encoding import Unencodable, encode
from ..errors import EventRejected
from ..printable import shorten, shown
from ..terms import Atom, String, Struct, Var

__all__ = ["BadEvent", "check_times", "rejection_reason", "format_event", "arguments_problem",
           "text_problem", "shorten", "shown", "event_arguments",
           "event_rejection"]


class BadEvent(Exception):
    """Internal: why an event is rejected (turned into EventRejected with the event text)."""


def arguments_problem(args: Any) -> str:
    """Why ``args`` is not an argument list: only a list or a tuple is one (a ``str`` would
    otherwise be split into one-character atoms).

    >>> arguments_problem("abc")
    "event arguments must be a list or tuple, not str 'abc'"
    """
    described = shown(args)
    what = "None" if args is None else described if described.startswith("an integer of") \
        else f"{type(args).__name__} {described}"
    return f"event arguments must be a list or tuple, not {what}"


def event_arguments(name: Any, args: Any, start: Any, end: Any) -> tuple:
    """The arguments of an event as a tuple, or :class:`EventRejected` naming the event when
    ``args`` is not a list or tuple.

    >>> event_arguments("p", ["a", 1], 1.0, 1.0)
    ('a', 1)
    """
    if type(args) is tuple:
        return args
    if type(args) is list:
        return tuple(args)
    error = EventRejected(f"{format_event(name, (), start, end)}: {arguments_problem(args)}")
    error.event = (name, args, start, end)
    raise error


def text_problem(text: str) -> str | None:
    """Why ``text`` (an event name) cannot be stored, or None.

    >>> text_problem("seg") is None, text_problem("seg" + chr(0xD800))
    (True, "text with a lone surrogate ('\\\\ud800') is not valid Unicode")
    """
    try:
        encode(Atom(text))
    except Unencodable as exc:
        return exc.reason
    return None


def _event_time(value: Any) -> float:
    if type(value) is float:
        return value
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        try:
            return float(value)
        except OverflowError:
            raise BadEvent("event times must be finite") from None
    raise BadEvent(f"event times must be numbers (got {shown(value)})")


def check_times(start: Any, end: Any) -> tuple[float, float]:
    """``(start, end)`` as floats, or :class:`BadEvent` when they are not finite numbers with
    ``start <= end``.

    >>> check_times(1, 2.5)
    (1.0, 2.5)
    """
    start = _event_time(start)
    end = _event_time(end)
    if not (math.isfinite(start) and math.isfinite(end)):
        raise BadEvent("event times must be finite (not inf or NaN)")
    if start > end:
        raise BadEvent(f"start time {start!r} is after end time {end!r}")
    return start + 0.0, end + 0.0   # (a time -0.0 is the time 0.0: see store_time)


def event_rejection(event: Any, exc: Exception) -> EventRejected:
    """The :class:`EventRejected` of ``event`` ``(name, args, start, end)`` refused for
    ``exc`` (a :class:`BadEvent` or an Unencodable argument): the store's, and the client
    of ``slr serve``'s for what it refuses before sending.

    >>> print(event_rejection(("p", [1], 2.0, 1.0), BadEvent("start time 2.0 is after end time 1.0")))
    p(1)^[2.0,1.0]: start time 2.0 is after end time 1.0
    """
    try:
        name, args, start, end = event
        message = f"{format_event(name, args, start, end)}: {rejection_reason(exc)}"
    except Exception:  # an event too malformed to print (the reason says what it is)
        message = rejection_reason(exc)
    error = EventRejected(message)
    error.event = event
    return error


def rejection_reason(exc: Exception) -> str:
    """The reason part of a rejection message, for a :class:`BadEvent` or an
    :class:`~slr_sql.encoding.Unencodable` argument.

    >>> rejection_reason(BadEvent("start time 3.0 is after end time 2.0"))
    'start time 3.0 is after end time 2.0'
    """
    if isinstance(exc, Unencodable):
        if "unbound" in exc.reason:
            return f"event arguments must be ground ({exc.reason})"
        if "NaN" in exc.reason:
            return "event arguments must not contain NaN"
        return f"event argument cannot be stored: {exc.reason}"
    return str(exc)


def _format_term(term: Any) -> str:
    try:
        from ..terms import MESSAGE_TOKENS, format_term  # the project's printer
        return format_term(term, limit=MESSAGE_TOKENS, message=True)  # (huge: its start)
    except Exception:
        return _simple_format(term)


def _simple_format(term: Any) -> str:
    tt = type(term)
    if tt is Var:
        return str(term)
    if tt is String:
        return json.dumps(str(term), ensure_ascii=False)
    if isinstance(term, str):
        if re.fullmatch(r"[a-z][A-Za-z0-9_]*|\[\]", term):
            return str(term)
        return "'" + term.replace("\\", "\\\\").replace("'", "\\'") + "'"
    if tt is Struct:
        if term.name == "." and len(term.args) == 2:
            items, tail = [], term
            while type(tail) is Struct and tail.name == "." and len(tail.args) == 2:
                items.append(_simple_format(tail.args[0]))
                tail = tail.args[1]
                while type(tail) is Var and tail.ref is not None:
                    tail = tail.ref
            inner = ",".join(items)
            return f"[{inner}]" if tail == "[]" else f"[{inner}|{_simple_format(tail)}]"
        return f"{_simple_format(term.name)}({','.join(_simple_format(a) for a in term.args)})"
    if isinstance(term, (list, tuple)):
        return "[" + ",".join(_simple_format(a) for a in term) + "]"
    return repr(term)


def format_event(name: Any, args: Any, start: Any, end: Any) -> str:
    """Event text for messages: ``seg(X,1)^2.0`` or ``seg(a)^[1.0,2.0]``.

    >>> format_event("seg", (Atom("a"), 1), 2.0, 2.0)
    'seg(a,1)^2.0'
    >>> format_event("note", (10 ** 300,), 4.0, 4.0)[-30:]
    '00000... (307 characters)^4.0'
    """
    if not isinstance(name, str):  # not a name at all: the reason shows what it is
        name, args = "event", ()
    try:
        if type(args) is not tuple and type(args) is not list:
            args = ()  # not an argument list: the reason shows it
        head = _simple_format(Atom(name)) if not args else _format_term(Struct(name, tuple(args)))
    except Exception:  # a term too deep or too large to print
        try:
            head = shorten(f"{name}{tuple(args)!r}")
        except Exception:  # an integer of more digits than Python prints
            head = f"{name}(...)"
    head = shorten(head, 200)   # (a rejection of a 20 MB atom need not repeat it)
    if start == end:
        return f"{head}^{shown(start)}"
    return f"{head}^[{shown(start)},{shown(end)}]"
