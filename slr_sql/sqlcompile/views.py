"""The inspection views of derived predicates (``refresh_views`` in the planner): the
branches the compiler emitted for ``name(A1..An)``, glued into one SELECT of
``arg1..argN`` in Prolog's order of solutions."""
from __future__ import annotations

from typing import Any

from ..store.dialect import SQLITE
from .model import Part, key_columns

__all__ = ["view_select"]


def view_select(parts: list[Part], arity: int, dialect: Any = None) -> str:
    """One SELECT of ``arg1..argN`` over the compiled branches ``parts`` (their projections
    ``proj`` and order keys ``keys``): ``UNION ALL`` of the branches, ordered by the keys
    (a branch with fewer keys pads them with the ``dialect``'s NULL of their kind,
    see :func:`key_columns`; SQLite's when none is given), the keys left out of the answer.

    >>> print(view_select([Part([], [], ["1"], ["'a'"]), Part([], [], [], ["'b'"])], 1))
    SELECT arg1 FROM (SELECT +('a') AS arg1, 1 AS k0 UNION ALL SELECT +('b') AS arg1, NULL AS k0 ORDER BY k0)
    """
    dialect = SQLITE if dialect is None else dialect
    alias = dialect.subquery_alias
    nk = max(len(p.keys) for p in parts)
    selects = []
    for p, keys in zip(parts, key_columns(parts, dialect)):
        cols = [f"{dialect.view_column(x)} AS arg{i + 1}" for i, x in enumerate(p.proj)] \
            or ["1 AS ok"]
        selects.append(p.select(cols + keys))
    inner = " UNION ALL ".join(selects)
    if nk:
        inner += " ORDER BY " + ", ".join(f"k{i}" for i in range(nk))
    outer = ", ".join(f"arg{i + 1}" for i in range(arity)) or "ok"
    return f"SELECT {outer} FROM ({inner}){alias}"
