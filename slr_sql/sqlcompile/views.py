"""The inspection views of derived predicates (``refresh_views`` in the planner): the
branches the compiler emitted for ``name(A1..An)``, glued into one SELECT of
``arg1..argN`` in Prolog's order of solutions."""
from __future__ import annotations

from typing import Any

from .model import Part

__all__ = ["view_select"]


def view_select(parts: list[Part], arity: int, dialect: Any = None) -> str:
    """One SELECT of ``arg1..argN`` over the compiled branches ``parts`` (their projections
    ``proj`` and order keys ``keys``): ``UNION ALL`` of the branches, ordered by the keys
    (a branch with fewer keys pads them with the ``dialect``'s NULL key; SQLite's when
    none is given), the keys left out of the answer.

    >>> print(view_select([Part([], [], ["1"], ["'a'"]), Part([], [], [], ["'b'"])], 1))
    SELECT arg1 FROM (SELECT 'a' AS arg1, 1 AS k0 UNION ALL SELECT 'b' AS arg1, NULL AS k0 ORDER BY k0)
    """
    null_key = "NULL" if dialect is None else dialect.null_key
    alias = "" if dialect is None else dialect.subquery_alias
    nk = max(len(p.keys) for p in parts)
    selects = []
    for p in parts:
        cols = [f"{x} AS arg{i + 1}" for i, x in enumerate(p.proj)] or ["1 AS ok"]
        cols += [f"{k} AS k{i}" for i, k in enumerate(p.keys)]
        cols += [f"{null_key} AS k{i}" for i in range(len(p.keys), nk)]
        selects.append(p.select(cols))
    inner = " UNION ALL ".join(selects)
    if nk:
        inner += " ORDER BY " + ", ".join(f"k{i}" for i in range(nk))
    outer = ", ".join(f"arg{i + 1}" for i in range(arity)) or "ok"
    return f"SELECT {outer} FROM ({inner}){alias}"
