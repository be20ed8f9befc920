"""The statements a timeline plot reads (:mod:`slr_sql.plot`), printed for one dialect.

A plot reads a store through whatever door it was given: a local knowledge base or the
client of ``slr serve`` (both run read-only SQL with ``sql(query, params)``). So the
statements are not run here: each method returns one :data:`Statement` (text with ``?``
parameters, and the parameters) for the caller to run, and the text lives with the store,
printed for the database's dialect (:mod:`slr_sql.store.dialect`): SQLite's text is what plots always ran;
PostgreSQL's uses its spellings of the two-argument ``max``/``min``, of truncation to a
bin number, of ``IS`` against a parameter, and reads the text columns as numbers.

>>> statements = TimelineStatements(SQLITE)
>>> statements.time_span_first('"e_p_1"')
('SELECT min(t_start) FROM "e_p_1"', ())
>>> TimelineStatements(POSTGRES).numeric("v")
"slr_typeof(v) IN ('integer', 'real')"
"""
from __future__ import annotations

from typing import Any, Protocol

from ..errors import SLRError
from .dialect import POSTGRES, SQLITE

__all__ = ["Statement", "TimelineStatements", "timeline_statements"]

Statement = tuple[str, tuple[Any, ...]]


class _Printer(Protocol):
    """What a timeline needs of a dialect (:mod:`slr_sql.store.dialect`)."""

    name: str

    def typeof(self, expr: str) -> str: ...

    def number(self, expr: str) -> str: ...

    def scalar(self, name: str) -> str: ...


class TimelineStatements:
    """The statements of a timeline for one dialect. Table and column names are given
    quoted (``quote_identifier``); values are always parameters."""

    def __init__(self, dialect: _Printer) -> None:
        self.dialect = dialect
        self._postgres = dialect.name == "postgresql"

    def _printed(self, text: str, params: tuple[Any, ...]) -> Statement:
        """A statement as ``sql()`` takes it: parameters as ``?`` on every engine (a server
        store's ``sql()`` prints them in its driver's style)."""
        return text, params

    def _bin(self, expr: str) -> str:
        """The bin number of a non-negative expression: truncated toward zero (a cast to an
        integer rounds on PostgreSQL)."""
        if self._postgres:
            return f"floor({expr})::bigint"
        return f"CAST({expr} AS INTEGER)"

    def numeric(self, expr: str) -> str:
        """True where ``expr`` is a stored number (not an atom, a string or a compound)."""
        return f"{self.dialect.typeof(expr)} IN ('integer', 'real')"

    def event_types(self) -> Statement:
        """Every event type of the catalog: (name, arity, table), by name and arity."""
        return self._printed("SELECT name, arity, table_name FROM slr_event_types "
                             "ORDER BY name, arity", ())

    def time_span_first(self, table: str) -> Statement:
        """The earliest start time of a table (one aggregate per statement: SQLite answers a
        lone min() from the index)."""
        text = (f"SELECT min(t_start) FROM {table}")
        return self._printed(text, ())

    def time_span_last(self, table: str) -> Statement:
        """The latest end time of a table."""
        text = (f"SELECT max(t_end) FROM {table}")
        return self._printed(text, ())

    def _only(self, key_column: str | None, key_value: Any) -> tuple[str, tuple[Any, ...]]:
        if key_column is None:
            return "", ()
        if self._postgres:
            return f" AND {key_column} IS NOT DISTINCT FROM ?", (key_value,)
        return f" AND {key_column} IS ?", (key_value,)

    def events(self, table: str, lo: float, hi: float, limit: int,
               key_column: str | None = None, key_value: Any = None) -> Statement:
        """(start, end, arrival) of the events overlapping [lo, hi] (only those whose
        ``key_column`` holds ``key_value`` when given), in end-time order, at most ``limit``."""
        only, params = self._only(key_column, key_value)
        text = (f"SELECT t_start, t_end, arrival FROM {table} WHERE t_end >= ? AND "
                f"t_start <= ?{only} ORDER BY t_end, t_start, seq LIMIT ?")
        return self._printed(text, (lo, hi, *params, limit))

    def start_bins(self, table: str, lo: float, hi: float, width: float,
                   key_column: str | None = None, key_value: Any = None) -> Statement:
        """(bin, is a point, count) of the events overlapping [lo, hi], by the bin of width
        ``width`` their start falls in (before ``lo``: the first)."""
        only, params = self._only(key_column, key_value)
        start = f"{self.dialect.scalar('max')}(t_start, ?)"
        text = (f"SELECT {self._bin(f'({start} - ?) / ?')} AS b, t_start = t_end, "
                f"count(*) FROM {table} WHERE t_end >= ? AND t_start <= ?{only} GROUP BY 1, 2")
        return self._printed(text, (lo, lo, width, lo, hi, *params))

    def end_bins(self, table: str, lo: float, hi: float, width: float,
                 key_column: str | None = None, key_value: Any = None) -> Statement:
        """(bin, count) of the intervals overlapping [lo, hi], by the bin their end falls in
        (after ``hi``: the last)."""
        only, params = self._only(key_column, key_value)
        end = f"{self.dialect.scalar('min')}(t_end, ?)"
        text = (f"SELECT {self._bin(f'({end} - ?) / ?')} AS b, count(*) "
                f"FROM {table} WHERE t_end >= ? AND t_start <= ? AND t_start < t_end"
                f"{only} GROUP BY 1")
        return self._printed(text, (hi, lo, width, lo, hi, *params))

    def distinct(self, table: str, column: str, lo: float, hi: float,
                 limit: int) -> Statement:
        """Up to ``limit`` distinct values of ``column`` among the events overlapping
        [lo, hi], in order."""
        text = (f"SELECT DISTINCT {column} FROM {table} "
                f"WHERE t_end >= ? AND t_start <= ? ORDER BY 1 LIMIT ?")
        return self._printed(text, (lo, hi, limit))

    def _values(self, table: str, column: str, path: str | None,
                split: str | None, lo: float, hi: float) -> Statement:
        """The events ending in [lo, hi] with the plotted value ``v`` (the argument, or the
        JSON ``path`` into it) and the key ``k`` of their line."""
        if path:
            # a JSON path on a value that is not JSON (an atom, a number) is no value
            if self._postgres:
                raise SLRError("a value with a path into JSON (p:1[0]) is plotted from a "
                               "SQLite store only")
            expr: str = f"CASE WHEN json_valid({column}) THEN json_extract({column}, ?) END"
            params: tuple[Any, ...] = (path,)
        else:
            expr, params = column, ()
        key = split if split is not None else "NULL"
        return (f"SELECT t_start, t_end, seq, {expr} AS v, {key} AS k FROM {table} "
                f"WHERE t_end >= ? AND t_end <= ?", (*params, lo, hi))

    def _number(self, expr: str) -> str:
        return self.dialect.number(expr)

    def samples(self, table: str, column: str, path: str | None, split: str | None,
                lo: float, hi: float, limit: int) -> Statement:
        """(end, value, key) of the events ending in [lo, hi] whose value is a number, in
        end-time order, at most ``limit``."""
        inner, params = self._values(table, column, path, split, lo, hi)
        text = (f"SELECT t_end, {self._number('v')}, k FROM ({inner}) AS e "
                f"WHERE {self.numeric('v')} ORDER BY t_end, t_start, seq LIMIT ?")
        return self._printed(text, (*params, limit))

    def value_bins(self, table: str, column: str, path: str | None, lo: float, hi: float,
                   width: float) -> Statement:
        """(bin, min, max, mean, count) of the numeric values of the events ending in
        [lo, hi], by the bin of width ``width`` their end falls in."""
        inner, params = self._values(table, column, path, None, lo, hi)
        v = self._number("v")
        text = (f"SELECT {self._bin('(t_end - ?) / ?')} AS b, min({v}), max({v}), avg({v}), "
                f"count(*) FROM ({inner}) AS e WHERE {self.numeric('v')} GROUP BY 1 ORDER BY 1")
        return self._printed(text, (lo, width, *params))

    def first_value(self, table: str, column: str, path: str | None, lo: float,
                    hi: float) -> Statement:
        """One value of the events ending in [lo, hi] (a present one first): what a message
        shows when none of them is a number."""
        inner, params = self._values(table, column, path, None, lo, hi)
        return self._printed(f"SELECT v FROM ({inner}) AS e ORDER BY v IS NULL LIMIT 1", params)


_BY_NAME = {"sqlite": TimelineStatements(SQLITE), "postgresql": TimelineStatements(POSTGRES)}


def timeline_statements(dialect: Any = None) -> TimelineStatements:
    """The statements for ``dialect`` (an object of :mod:`slr_sql.store.dialect`, or None:
    SQLite's, which a store served by ``slr serve`` speaks too).

    >>> timeline_statements().dialect.name, timeline_statements(POSTGRES).dialect.name
    ('sqlite', 'postgresql')
    """
    name = getattr(dialect, "name", "sqlite")
    return _BY_NAME.get(name, _BY_NAME["sqlite"])
