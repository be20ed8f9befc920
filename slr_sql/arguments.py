"""Checks of the arguments that public methods of several layers share: numbers of seconds
(``at=``, ``timeout=``), the timeout of a wait (``PendingQuery.result``,
``Subscription.get``), callables (``callback=``, listeners) and flags. Each raises an
:class:`~slr_sql.errors.SLRError` in words naming the argument; a local knowledge base, its
parts (the synchronizer, the subscriptions, the clocks) and the client of ``slr serve`` run
the same check, so the same bad value gets the same error wherever it is given.

>>> check_time_option("at", 12.5)
>>> wait_seconds("result: timeout", float("inf")) is None    # inf: wait for ever
True
>>> check_callable("submit: callback", 5)
Traceback (most recent call last):
...
slr_sql.errors.SLRError: submit: callback must be callable (a function), not 5
"""
from __future__ import annotations

import math
import numbers
import threading
from typing import Any, Iterable, TypeVar

from .errors import SLRError
from .printable import shown

__all__ = ["check_time_option", "wait_seconds", "check_callable", "check_flag",
           "check_option_names", "ListenerList"]

T = TypeVar("T")


def check_time_option(name: str, value: Any, minimum: float | None = None, *,
                      required: bool = False) -> None:
    """``at=`` and ``timeout=`` are numbers of seconds (``None``: not given, unless
    ``required``), else an :class:`SLRError` (run by the client of ``slr serve`` too, before
    sending, and by the command line's ``--at`` and ``--timeout``). Any real number is taken
    (``numbers.Real``: numpy's numbers, ``fractions.Fraction``), as ``mark_complete``'s time
    is, but not a bool. Infinities are numbers (SPEC: ``inf`` is +∞ where a number is
    expected); NaN is none.

    >>> check_time_option("timeout", 2.5, minimum=0.0)
    >>> check_time_option("timeout", -1, minimum=0.0)
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: timeout must be a number of seconds >= 0, not -1

    >>> from fractions import Fraction
    >>> check_time_option("ManualClock.set: t", Fraction(1, 2), required=True)
    """
    if value is None and not required:
        return
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise SLRError(f"{name} must be a number of seconds, not {shown(value)}")
    try:
        number = float(value)
    except OverflowError:
        raise SLRError(f"{name} is out of range (an integer of {int(value).bit_length()} "
                       f"bits)") from None
    if math.isnan(number) or (minimum is not None and number < minimum):
        raise SLRError(f"{name} must be a number of seconds"
                       f"{'' if minimum is None else f' >= {minimum:g}'}, not {shown(value)}")


def wait_seconds(name: str, timeout: Any) -> float | None:
    """The ``timeout`` of a wait (a Future's ``result``, a subscription's ``get``) as the
    seconds to wait, None for ever (None, ``inf``, or more than a thread can wait: Python's
    waits refuse those with an OverflowError); else an :class:`SLRError` as for any
    ``timeout=`` (a number of seconds >= 0).

    >>> wait_seconds("get: timeout", 2), wait_seconds("get: timeout", None)
    (2.0, None)
    >>> wait_seconds("get: timeout", float("nan"))
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: get: timeout must be a number of seconds >= 0, not nan
    """
    check_time_option(name, timeout, minimum=0.0)
    if timeout is None:
        return None
    seconds = float(timeout)
    return None if seconds >= threading.TIMEOUT_MAX else seconds


def check_callable(name: str, value: Any) -> Any:
    """``value`` if it can be called, else an :class:`SLRError` naming the argument: a
    callback that is no function is refused where it is given, not when it is first called
    (on another thread, where its TypeError would only be logged).

    >>> check_callable("subscribe: callback", print) is print
    True
    """
    if not callable(value):
        raise SLRError(f"{name} must be callable (a function), not {shown(value)}")
    return value


def check_flag(name: str, value: Any) -> bool:
    """A flag argument (``replace=``, ``atomic=``, ``wait=``, ``write=``): True or False,
    else an :class:`SLRError` (a string such as ``"no"`` is true to Python, so taking its
    truth would do the opposite of what was meant).

    >>> check_flag("atomic", False)
    False
    >>> check_flag("atomic", "no")
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: atomic must be True or False, not 'no'
    """
    if type(value) is not bool:
        raise SLRError(f"{name} must be True or False, not {shown(value)}")
    return value


def check_option_names(method: str, options: Iterable[str], known: Iterable[str]) -> None:
    """The keyword options given to ``method`` (``open``, ``connect``) are among ``known``,
    else an :class:`SLRError` naming the first unknown one and the known ones (not Python's
    ``TypeError: ... got an unexpected keyword argument``).

    >>> check_option_names("open", ["robot"], ["busy_timeout", "robot"])
    >>> check_option_names("open", ["bogus"], ["busy_timeout", "robot"])
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: open has no option 'bogus' (its options: busy_timeout, robot)
    """
    known = list(known)
    for name in options:
        if name not in known:
            raise SLRError(f"{method} has no option {shown(name)} "
                           f"(its options: {', '.join(known)})")


class ListenerList(list[T]):
    """A list of listeners that takes only callables: ``append``, ``insert``, ``extend``,
    ``+=`` and item assignment refuse anything else with an :class:`SLRError`, at the call
    (a listener is called later, inside another operation, where a non-callable would fail
    that operation instead).

    >>> heard = ListenerList("kb.add_listeners"); heard.append(print); len(heard)
    1
    >>> heard.append(5)
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: kb.add_listeners: a listener must be callable (a function), not 5
    """

    def __init__(self, name: str, listeners: Iterable[T] = ()) -> None:
        super().__init__()
        self.name = name
        self.extend(listeners)

    def _checked(self, listeners: Iterable[T]) -> list[T]:
        items = list(listeners)
        for fn in items:
            check_callable(f"{self.name}: a listener", fn)
        return items

    def append(self, fn: T) -> None:
        super().append(check_callable(f"{self.name}: a listener", fn))

    def insert(self, index: Any, fn: T) -> None:
        super().insert(index, check_callable(f"{self.name}: a listener", fn))

    def extend(self, listeners: Iterable[T]) -> None:
        super().extend(self._checked(listeners))

    def __iadd__(self, listeners: Iterable[T]) -> "ListenerList[T]":  # type: ignore[override,misc]
        self.extend(listeners)
        return self

    def __setitem__(self, index: Any, value: Any) -> None:
        if isinstance(index, slice):
            super().__setitem__(index, self._checked(value))
        else:
            super().__setitem__(index, check_callable(f"{self.name}: a listener", value))


def refuse_memory_store(path: str | None, command: str) -> None:
    """Refuse ``":memory:"`` as the store of ``command`` (``slr add``, ...), which writes to
    it: a store in memory would start empty and vanish with what was written when the
    command exits (an API call, ``slr_sql.open(":memory:")``, keeps it while it runs).

    >>> refuse_memory_store("robot.db", "slr add")
    >>> refuse_memory_store(":memory:", "slr add")
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: slr add: ':memory:' is a store in memory, which would start empty and vanish with what slr add writes when it exits; give the store's file (or a PostgreSQL URL)
    """
    if path == ":memory:":
        raise SLRError(f"{command}: ':memory:' is a store in memory, which would start empty "
                       f"and vanish with what {command} writes when it exits; give the "
                       "store's file (or a PostgreSQL URL)")
