"""The shape of the Python functions that SQL statements call: :class:`SqlFunctions`.

SQLite runs a statement inside this process, so a statement may call Python: the query
compiler's Prolog arithmetic and det builtins, the event rules' comparisons, the
aggregates of ``findall``/``setof``. The one list of them is
:data:`slr_sql.sql_functions.SQL_FUNCTIONS` (it needs the compiler and the builtins, which
sit above the store); the facade hands it to the store once
(``EventStore.install_functions``), and the SQLite backend registers it on every
connection it opens. PostgreSQL cannot run Python inside the server: each entry says
whether a migration installs a function of the same name and number of arguments there
(``Native.MIGRATION``) or the goals needing it run in the interpreter on PostgreSQL
(``Native.INTERPRETER_ONLY``); ``tests/test_sql_functions.py`` checks both against a real
server.

>>> twice = SqlFunction("twice", 1, lambda x: 2 * x, on_postgres=Native.INTERPRETER_ONLY)
>>> functions = SqlFunctions((twice,), ())
>>> from slr_sql.store import EventStore
>>> s = EventStore(None); s.install_functions(functions)
>>> s.sql("SELECT twice(21)")
(['twice(21)'], [(42,)])
>>> functions.names()
[('twice', 1)]
"""
from __future__ import annotations

import enum
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

__all__ = ["Native", "SqlAggregate", "SqlFunction", "SqlFunctions"]


class Native(enum.Enum):
    """Whether a function slr_sql calls from SQL exists inside a PostgreSQL server."""

    MIGRATION = "installed by a pg_NNNN migration, same name and number of arguments"
    INTERPRETER_ONLY = "interpreter only on PostgreSQL: goals needing it are not compiled"
    BUILTIN = "a wrapper of a SQLite built-in; PostgreSQL has its own (store/bounded_builtins.py)"


@dataclass(frozen=True)
class SqlFunction:
    """A scalar function: ``name(arg, ...)`` in SQL calls ``fn`` (``arity`` -1: any number
    of arguments); ``deterministic``: the same arguments always give the same result (SQLite
    may then use it in indexes and factor calls out).

    >>> SqlFunction("one", 0, lambda: 1, on_postgres=Native.INTERPRETER_ONLY).deterministic
    True
    """

    name: str
    arity: int
    fn: Callable[..., Any]
    on_postgres: Native
    deterministic: bool = True


@dataclass(frozen=True)
class SqlAggregate:
    """An aggregate function: ``cls()`` per group, ``step(value)`` per row, ``finalize()``.

    >>> class Count:
    ...     def __init__(self): self.n = 0
    ...     def step(self, value): self.n += 1
    ...     def finalize(self): return self.n
    >>> SqlAggregate("how_many", 1, Count, on_postgres=Native.INTERPRETER_ONLY).arity
    1
    """

    name: str
    arity: int
    cls: type
    on_postgres: Native


@dataclass(frozen=True)
class SqlFunctions:
    """The scalar functions and the aggregates statements may call (see the module).

    >>> SqlFunctions((), ()).names()
    []
    """

    functions: tuple[SqlFunction, ...]
    aggregates: tuple[SqlAggregate, ...]

    def names(self) -> list[tuple[str, int]]:
        """``(name, arity)`` of every function and aggregate, in the order listed."""
        return [(f.name, f.arity) for f in self.functions] + \
            [(a.name, a.arity) for a in self.aggregates]
