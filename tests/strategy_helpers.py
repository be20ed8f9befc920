"""Hypothesis strategies built once and drawn from again, for the generators of the tests.

Hypothesis validates, labels and inspects each new strategy object the first time it draws
from it. A generator that writes ``draw(st.sampled_from(...))`` builds a new object at every
draw: tens of thousands in one run of a differential test, about half of the SQL
differential's CPU. These functions build each strategy once per distinct argument and hand
back the same object. A strategy is built exactly as the call it replaces would build it (a
list stays a list: hypothesis labels a list and a tuple differently), so a derandomized test
draws the same examples as before.

>>> from hypothesis import strategies as st
>>> sampled(["a", "b"]) is sampled(["a", "b"]), sampled([0.0]) is sampled([-0.0])
(True, False)
>>> sampled(("a", "b")) is sampled(["a", "b"])
False
>>> integers(0, 3) is integers(0, 3)
True
"""
from __future__ import annotations

from typing import Any, Callable

from hypothesis import strategies as st

_BUILT: dict = {}

BOOLEANS = st.booleans()


def once(key: Any, build: Callable[[], Any]) -> Any:
    """The strategy ``build()`` made the first time ``key`` is asked for, that one after."""
    strategy = _BUILT.get(key)
    if strategy is None:
        strategy = _BUILT[key] = build()
    return strategy


def sampled(options: list | tuple) -> Any:
    """``st.sampled_from(options)``, built once per distinct ``options`` (a list or a tuple,
    built from a copy of the same type; anything else is built at each call): the options
    told apart by type and repr, so that 0.0 and -0.0, or 1 and 1.0, stay different."""
    kind = type(options)
    if kind is not list and kind is not tuple:
        return st.sampled_from(options)
    return once(("sampled", kind, tuple((type(o), repr(o)) for o in options)),
                lambda: st.sampled_from(kind(options)))


def integers(low: int, high: int) -> Any:
    """``st.integers(low, high)``, built once per pair of bounds."""
    return once(("integers", low, high), lambda: st.integers(low, high))
