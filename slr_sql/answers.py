"""Answers as callers see them: the bindings of a query's named variables, in Python values.

>>> from slr_sql.terms import Var
>>> X = Var("X"); X.ref = 1; answer_bindings([("X", 0)], [X])
{'X': 1}
"""
from __future__ import annotations

from typing import Any

from .terms import Var, deref, to_python

__all__ = ["answer_bindings"]


def answer_bindings(names: list, frame: list, deadline: float | None = None) -> dict[str, Any]:
    """Bindings of the named variables, as SWI-Prolog's toplevel shows them: a variable left
    unbound is omitted unless it is shared with another named variable (``X = Y``).
    ``deadline`` (the query's, ``time.monotonic()``) also bounds converting a huge answer."""
    values = [(name, deref(frame[slot])) for name, slot in names]
    free = [id(v) for _, v in values if type(v) is Var]
    answer = {}
    for name, v in values:
        if type(v) is Var and free.count(id(v)) < 2:
            continue
        answer[name] = to_python(v, deadline)
    return answer
