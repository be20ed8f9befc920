"""The statements of the inspection views: a derived predicate's view over the branches of
its compiled goal, and a fact predicate's view over its fact table.
"""
from __future__ import annotations

from typing import Any

from ..store.dialect import SQLITE
from .model import Part


def view_statement(parts: list[Part], arity: int, dialect: Any = SQLITE) -> str:
    """The SELECT of a view with columns ``arg1..argN`` (``ok`` for arity 0) over the
    branches ``parts`` (their ``proj`` the arguments), in the interpreter's order.

    >>> view_statement([Part([], [], [], ["'a'"])], 1)
    "SELECT arg1 FROM (SELECT 'a' AS arg1)"
    """
    nk = max(len(p.keys) for p in parts)
    selects = []
    for p in parts:
        cols = [f"{x} AS arg{i + 1}" for i, x in enumerate(p.proj)] or ["1 AS ok"]
        cols += [f"{k} AS k{i}" for i, k in enumerate(p.keys)]
        cols += [f"NULL AS k{i}" for i in range(len(p.keys), nk)]
        selects.append(p.select(cols))
    inner = " UNION ALL ".join(selects)
    if nk:
        inner += " ORDER BY " + ", ".join(f"k{i}" for i in range(nk))
    outer = ", ".join(f"arg{i + 1}" for i in range(arity)) or "ok"
    return f"SELECT {outer} FROM ({inner}){dialect.subquery_alias}"


def fact_view_statement(table: str, arity: int) -> str:
    """The SELECT of the view of a fact predicate over its fact table, in clause order.

    >>> fact_view_statement('"slr_facts_2_color"', 2)
    'SELECT arg1, arg2 FROM "slr_facts_2_color" ORDER BY ord'
    """
    cols = ", ".join(f"arg{i + 1}" for i in range(arity))
    return f"SELECT {cols} FROM {table} ORDER BY ord"
