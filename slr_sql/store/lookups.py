"""Reading events: the indexed lookups behind ``prev``, ``next`` and stream scans.

Every lookup is one ``SELECT ... INDEXED BY`` over an event table (see
:mod:`slr_sql.store.tables` for the indexes), built once per shape and cached. A lookup in
start order (``next``, the ties at a start, ``bracket``'s event after ``t``) first makes
sure the type has its start-ordered indexes (a complex event type gets them on first need,
:meth:`~slr_sql.store.tables.EventTables.ensure_start_order`); where they cannot be built
it names no index, as naming a missing one is an error. Ground
arguments are pushed into the ``WHERE`` clause as bound parameters; rows come back decoded,
as ``(args, start, end, seq)``, streamed in growing batches so that a caller wanting the
first row or two does not read the rest.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
import sqlite3
from typing import Any, Callable, Iterable, Iterator

from ..encoding import INT64_MAX, INT64_MIN, Unencodable, decode, encode
from .catalog import PROGRAM_VERSION, PROGRESS_VERSION
from .connection import Database
from .dialect import short_text
from .sqltext import joined_balanced, quote_identifier
from .stored_text import fetch_row, fetch_rows
from .tables import EventTables, EventType

__all__ = ["Row", "RawPage", "EventReader", "null_argument_text"]

Row = tuple[Any, ...]    # (args: tuple[term, ...], start: float, end: float, seq: int)

# A stream whose statement was suspended (another thread's transaction began, see
# Database.suspend_streams) goes on with the rows after the last one it read, in its order:
# the condition added to its statement, and the key of a raw row (start, end, seq) for it.
_RESUME = {
    "scan": ("(t_end, t_start, seq) > (?, ?, ?)", lambda s, e, q: (e, s, q)),
    "prev": ("(t_end, t_start, seq) < (?, ?, ?)", lambda s, e, q: (e, s, q)),
    "at_end": ("(t_start, seq) > (?, ?)", lambda s, e, q: (s, q)),
    "next": ("(t_start, t_end, seq) > (?, ?, ?)", lambda s, e, q: (s, e, q)),
    "at_start": ("(t_end, seq) > (?, ?)", lambda s, e, q: (e, q)),
}


# the lookups that read in start order: they need the start-ordered indexes
_START_KINDS = frozenset({"next", "at_start"})


def _number_kind(value: Any) -> str | None:
    """The SQL type (typeof) a number term is stored as; None for other terms (and for
    integers beyond 64 bits, stored as text)."""
    if type(value) is float:
        return "real"
    if type(value) is int and INT64_MIN <= value <= INT64_MAX:
        return "integer"
    return None

def _exact(value: Any) -> tuple:
    """A stored value as a key that tells what SQL's = does not: 1 from 1.0, -0.0 from 0.0."""
    if type(value) is float:
        return (float, repr(value))
    return (type(value), value)


def _zero_signs(bound: dict[int, Any], positions: tuple[int, ...]) -> tuple[tuple[int, float], ...]:
    """The bound float zeros among ``positions``, with their signs (1.0 or -1.0)."""
    return tuple((p, math.copysign(1.0, bound[p])) for p in positions
                 if type(bound[p]) is float and bound[p] == 0.0)


def _first_of_signs(cursor: Any, signs: tuple[tuple[int, float], ...]) -> Any:
    """The first row of ``cursor`` (``(probe, arg1, ...)``) whose zeros at the positions of
    ``signs`` have those signs; None when none has. The cursor is closed (its statement
    stops there)."""
    try:
        while (row := fetch_row(cursor)) is not None:
            if all(math.copysign(1.0, row[p + 1]) == sign for p, sign in signs):
                return row
        return None
    finally:
        cursor.close()


def _earliest_holding_start(t: float, longest: float) -> float:
    """The earliest start of an event that lasts at most ``longest`` and holds at ``t``,
    a few units in the last place early (``t - longest`` is rounded, as ``longest`` was):
    reading a little more is harmless, missing one is not."""
    if not longest > 0.0:
        return t
    return t - longest - 4.0 * math.ulp(max(abs(t), longest))


def null_argument_text(name: str, arity: int, table: str, argument: int, seq: int) -> str:
    """A stored row whose argument ``argument`` is NULL, in words: what it is and the
    statement that removes it (the facade's and the subscriptions' NotAnEvent say the same).

    >>> print(null_argument_text("p", 1, "p", 1, 2))  # doctest: +ELLIPSIS
    p/1: the stored row of seq 2 is not an event: its arg1 is NULL, ... WHERE arg1 IS NULL)
    """
    return (f"{name}/{arity}: the stored row of seq {seq} is not an event: its arg{argument} "
            f"is NULL, which is no term (written by hand, by another client of the database); "
            f"fix or delete it (DELETE FROM {quote_identifier(table)} WHERE arg{argument} IS "
            f"NULL)")


@dataclass(frozen=True)
class RawPage:
    """A page of stored rows (see :meth:`EventReader.raw_page`): the rows, and whether rows
    were left after them when it was read."""

    rows: list[tuple]
    more: bool


class _OpenStatement:
    """The statement of one stream, which a transaction may suspend (close) meanwhile."""

    __slots__ = ("cursor", "__weakref__")

    def __init__(self, cursor: Any):
        self.cursor = cursor

    def suspend(self) -> None:
        cursor, self.cursor = self.cursor, None
        if cursor is not None:
            cursor.close()


class EventReader:
    """Looks events up in the tables of one database.

    >>> from slr_sql.store import EventStore
    >>> store = EventStore(None); store.add_events([("seg", ("cup1", 1), 2.0, 2.0)])
    []
    >>> [row[:3] for row in store.scan("seg", 2, {})]
    [((Atom('cup1'), 1), 2.0, 2.0)]
    """

    def __init__(self, db: Database, tables: EventTables):
        self.db = db
        self.tables = tables
        self.sql_cache: dict[tuple, str] = {}
        # a server's typed columns (store/dialect.py): values converted both ways
        self.to_column = db.dialect.to_column
        from_column = db.dialect.from_column
        self.decode = decode if from_column is None else (lambda v: decode(from_column(v)))
        # whether a long first argument is looked up otherwise (see _equalities)
        self._keyed = db.dialect.key("arg1") != "arg1"

    def _pushdown(self, event_type: EventType, bound: dict[int, Any] | None
                  ) -> tuple[tuple[int, ...], list]:
        """Which bound argument positions go into SQL, with their encoded values."""
        if not bound:
            return (), []
        positions = []
        values = []
        for position in sorted(bound):
            if not 0 <= position < event_type.arity:
                raise IndexError(f"argument position {position} out of range for "
                                 f"{event_type.name}/{event_type.arity}")
            try:
                value = encode(bound[position])
            except Unencodable:
                continue  # not ground (or NaN): the caller filters by unification
            if self.to_column is not None:
                value = self.to_column(value)
            positions.append(position)
            values.append(value)
        return tuple(positions), values

    def _far(self, positions: tuple[int, ...], values: list) -> bool:
        """Whether the first argument is bound to a text that is not its own key (on
        PostgreSQL, of 64 characters or more): its rows are in another index."""
        return self._keyed and positions[:1] == (0,) and short_text(values[0]) is None

    def _equalities(self, positions: tuple[int, ...], far: bool) -> list[str]:
        """``argN = ?`` for each bound position, the first argument's as the dialect's
        ``key_equal`` (PostgreSQL's indexes over it are partial: a short text's, and a
        long one's key's; the latter binds the text twice, :meth:`_bound`)."""
        return [self.db.dialect.key_equal("arg1", "?", "NULL" if far else "?") if p == 0
                else f"arg{p + 1} = ?" for p in positions]

    def _bound(self, values: list, far: bool) -> list:
        """The parameters of :meth:`_equalities` for ``values``."""
        return values[:1] + values if far else values

    def _start_order(self, event_type: EventType) -> bool:
        """Whether the start-ordered indexes of ``event_type`` (or of the type of its name
        now, should a rollback have reloaded the types) may be named: built if need be."""
        if event_type.start_order:   # (a rollback makes every type it reloads forget)
            return True
        current = self.tables.lookup(event_type.name, event_type.arity) or event_type
        return self.tables.ensure_start_order(current)

    def _select_sql(self, event_type: EventType, kind: str, positions: tuple[int, ...],
                    flags: tuple[bool, ...], resume: bool = False, robot: bool = False,
                    far: bool = False) -> str:
        """The statement of a lookup (lock held); one in start order names its index only
        once it is there."""
        # (built on a server too, whose planner then finds it: the same indexes either way)
        ordered = kind not in _START_KINDS or self._start_order(event_type)
        hint = self.db.dialect.index_hints and ordered
        key = (event_type.table, kind, positions, flags, resume, robot, hint, far)
        sql = self.sql_cache.get(key)
        if sql is not None:
            return sql
        by_arg1 = bool(positions) and positions[0] == 0
        # one robot's events (a fleet store asked per robot): its parameter follows the
        # arguments'
        conditions = self._equalities(positions, far) + (["robot = ?"] if robot else [])
        if kind == "scan":
            index = event_type.index_arg1_end if by_arg1 else event_type.index_end
            if flags[0]:
                conditions.append("t_end <= ?")
            order = "t_end, t_start, seq"
        elif kind == "prev":
            index = event_type.index_arg1_end if by_arg1 else event_type.index_end
            conditions.append("t_end <= ?")
            if flags[0]:
                # start >= A implies end >= A: bounds the backwards index scan
                conditions.append("t_start >= ?")
                conditions.append("t_end >= ?")
            order = "t_end DESC, t_start DESC, seq DESC"
        elif kind == "at_end":
            index = event_type.index_arg1_end if by_arg1 else event_type.index_end
            conditions.append("t_end = ?")
            if flags[0]:
                conditions.append("t_start >= ?")
            if flags[1]:
                conditions.append("t_end <= ?")
            order = "t_start, seq"
        elif kind == "next":
            index = event_type.index_arg1_start if by_arg1 else event_type.index_start
            # end <= B implies start <= B: bounds the forwards index scan
            conditions.append("t_start >= ?")
            conditions.append("t_start <= ?")
            conditions.append("t_end <= ?")
            order = "t_start, t_end, seq"
        elif kind == "at_start":
            index = event_type.index_arg1_start if by_arg1 else event_type.index_start
            conditions.append("t_start = ?")
            conditions.append("t_end <= ?")
            order = "t_end, seq"
        else:  # pragma: no cover - internal misuse
            raise ValueError(kind)
        if resume:
            conditions.append(_RESUME[kind][0])
        where = f" WHERE {joined_balanced(conditions, 'AND')}" if conditions else ""
        named = f" INDEXED BY {index}" if hint else ""
        sql = (f"SELECT {event_type.columns} FROM {event_type.quoted}{named}"
               f"{where} ORDER BY {order}")
        self.sql_cache[key] = sql
        return sql

    def _stream(self, statement_sql: Callable[[bool], str], params: list, arity: int,
                kind: str) -> Iterator[Row]:
        """Rows decoded lazily, fetched in growing batches; the lock is held per batch only.
        If a transaction suspended the statement between two batches (or a rollback aborted
        it), the rest is read with ``statement_sql(True)``: the rows after the last one
        read. The texts are asked for as each statement starts (lock held): a rollback
        meanwhile may have taken an index a text named."""
        db = self.db
        if db.dialect.pages_streams:
            yield from self._pages(statement_sql, params, arity, kind)
            return
        with db.lock:
            db.check_open()
            try:
                statement = _OpenStatement(db.conn.execute(statement_sql(False), params))
            except sqlite3.Error as exc:   # (rows read as they come: not through execute)
                raise db.failure(exc) from None
            db.open_streams.add(statement)
        key = _RESUME[kind][1]
        last = None
        try:
            batch = 8  # prev/next callers usually need only the first row or two
            dec = self.decode
            while True:
                with db.lock:
                    for attempt in (1, 2):
                        if statement.cursor is None:
                            db.check_open()
                        try:
                            if statement.cursor is None:
                                statement.cursor = \
                                    db.conn.execute(statement_sql(False), params) \
                                    if last is None else \
                                    db.conn.execute(statement_sql(True), params + list(
                                        key(last[arity], last[arity + 1], last[arity + 2])))
                            rows = fetch_rows(statement.cursor, batch)
                            break
                        except sqlite3.Error as exc:
                            # "abort due to ROLLBACK": read again after the last row
                            if attempt == 2 or getattr(exc, "sqlite_errorcode", 0) & 0xFF \
                                    != sqlite3.SQLITE_ABORT:
                                raise db.failure(exc) from None
                            statement.cursor = None
                if not rows:
                    return
                last = rows[-1]
                if arity == 0:
                    for row in rows:
                        yield ((), row[0], row[1], row[2])
                elif arity == 1:
                    for a, s, e, q in rows:
                        yield ((dec(a),), s, e, q)
                elif arity == 2:
                    for a, b, s, e, q in rows:
                        yield ((dec(a), dec(b)), s, e, q)
                else:
                    for row in rows:
                        yield (tuple([dec(v) for v in row[:arity]]),
                               row[arity], row[arity + 1], row[arity + 2])
                if batch < 2048:
                    batch *= 4
        finally:
            with db.lock:
                try:
                    statement.suspend()
                except sqlite3.ProgrammingError:  # the store was closed meanwhile
                    pass

    def _pages(self, statement_sql: Callable[[bool], str], params: list, arity: int,
               kind: str) -> Iterator[Row]:
        """:meth:`_stream` on a server, whose driver reads a statement's whole result at
        once: growing pages (``LIMIT``), each after the last row of the one before."""
        db = self.db
        key = _RESUME[kind][1]
        dec = self.decode
        batch = 8
        last = None
        while True:
            with db.lock:
                db.check_open()
                if last is None:
                    rows = db.execute(f"{statement_sql(False)} LIMIT {batch}", params)
                else:
                    rows = db.execute(f"{statement_sql(True)} LIMIT {batch}", params + list(
                        key(last[arity], last[arity + 1], last[arity + 2])))
            for row in rows:
                yield (tuple([dec(v) for v in row[:arity]]), row[arity], row[arity + 1],
                       row[arity + 2])
            if len(rows) < batch:
                return
            last = rows[-1]
            if batch < 2048:
                batch *= 4

    def _query(self, name: str, arity: int, bound: dict[int, Any] | None, kind: str,
               flags: tuple[bool, ...], times: list, robot: str | None = None
               ) -> Iterator[Row]:
        with self.db.lock:
            self.db.check_open()
            event_type = self.tables.lookup(name, arity)
            if event_type is None:
                return iter(())
            positions, values = self._pushdown(event_type, bound)
        if any(t != t for t in times):
            # a NaN bound holds for no time (SQLite binds it as NULL): a server's float
            # order puts NaN above every number, and `t_end <= NaN` held for every row
            return iter(())
        by_robot = robot is not None
        if by_robot:
            values.append(robot)

        far = self._far(positions, values)

        def statement_sql(resume: bool) -> str:
            return self._select_sql(event_type, kind, positions, flags, resume, by_robot, far)
        return self._stream(statement_sql, self._bound(values, far) + times, arity, kind)

    def scan(self, name: str, arity: int, bound: dict[int, Any] | None = None,
             end_le: float | None = None, robot: str | None = None) -> Iterator[Row]:
        """Stored events of name/arity in store order (end, start, arrival), as
        ``(args, start, end, seq)``; only ``end <= end_le`` when given (the stream view).
        ``bound`` maps 0-based argument positions to ground terms that must be equal (SQL
        equality: the int 1 also finds 1.0 — the caller unifies anyway).

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.add_events([("p", ("a",), 2, 2), ("p", ("b",), 1, 1)])
        []
        >>> [row[0] for row in s.scan("p", 1, {})], [row[0] for row in s.scan("p", 1, {0: "a"})]
        ([(Atom('b'),), (Atom('a'),)], [(Atom('a'),)])
        """
        has_end = end_le is not None
        return self._query(name, arity, bound, "scan", (has_end,),
                           [float(end_le)] if has_end else [], robot)

    def prev_candidates(self, name: str, arity: int, bound: dict[int, Any] | None,
                        t: float, start_ge: float | None = None,
                        robot: str | None = None) -> Iterator[Row]:
        """Events with ``end <= t`` (and ``start >= start_ge`` when given), latest end first
        (streamed backwards from an index). Use :meth:`rows_at_end` for the tied rows of the
        first match in store order.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.add_events([("p", ("a",), 1, 1), ("p", ("b",), 2, 2)])
        []
        >>> next(s.prev_candidates("p", 1, {}, 1.5))[0]
        (Atom('a'),)
        """
        has_start = start_ge is not None
        times = [float(t)] + ([float(start_ge), float(start_ge)] if has_start else [])
        return self._query(name, arity, bound, "prev", (has_start,), times, robot)

    def rows_at_end(self, name: str, arity: int, bound: dict[int, Any] | None, end: float,
                    start_ge: float | None = None, end_le: float | None = None,
                    robot: str | None = None) -> Iterator[Row]:
        """Events whose end is exactly ``end`` (and ``start >= start_ge``, ``end <= end_le``
        when given) in store order (start, arrival).

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.add_events([("p", ("a",), 1, 2), ("p", ("b",), 0, 2)])
        []
        >>> [row[0] for row in s.rows_at_end("p", 1, {}, 2.0)]
        [(Atom('b'),), (Atom('a'),)]
        """
        flags = (start_ge is not None, end_le is not None)
        times = [float(end)] + ([float(start_ge)] if flags[0] else []) \
            + ([float(end_le)] if flags[1] else [])
        return self._query(name, arity, bound, "at_end", flags, times, robot)

    def next_candidates(self, name: str, arity: int, bound: dict[int, Any] | None,
                        a: float, b: float, robot: str | None = None) -> Iterator[Row]:
        """Events with ``a <= start`` and ``end <= b``, earliest start first (streamed from an
        index). Use :meth:`rows_at_start` for the tied rows of the first match.

        >>> import math; from slr_sql.store import EventStore
        >>> s = EventStore(None); s.add_events([("p", ("a",), 1, 1), ("p", ("b",), 2, 2)])
        []
        >>> next(s.next_candidates("p", 1, {}, 1.5, math.inf))[0]
        (Atom('b'),)
        """
        return self._query(name, arity, bound, "next", (), [float(a), float(b), float(b)],
                           robot)

    def rows_at_start(self, name: str, arity: int, bound: dict[int, Any] | None,
                      start: float, b: float, robot: str | None = None) -> Iterator[Row]:
        """Events whose start is exactly ``start`` and whose end is ``<= b``, in store order
        (end, arrival).

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.add_events([("p", ("a",), 1, 3), ("p", ("b",), 1, 2)])
        []
        >>> [row[0] for row in s.rows_at_start("p", 1, {}, 1.0, 10.0)]
        [(Atom('b'),), (Atom('a'),)]
        """
        return self._query(name, arity, bound, "at_start", (), [float(start), float(b)],
                           robot)

    def lookup_sql(self, kind: str, name: str, arity: int,
                   bound: dict[int, Any] | None = None, *, start_ge: bool = False,
                   end_le: bool = False, robot: bool = False) -> str | None:
        """The SQL a lookup runs (for explain output and plan tests). ``kind`` is ``scan``,
        ``prev``, ``at_end``, ``next`` or ``at_start``; ``start_ge``/``end_le`` say whether
        those optional bounds are given. None if the type has no table. Asked in start
        order (``next``, ``at_start``), it makes sure of the start-ordered indexes as the
        lookup would, and names them only if they are there.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.declare_type("p", 1)
        'p'
        >>> s.lookup_sql("prev", "p", 1)
        'SELECT arg1, t_start, t_end, seq FROM "p" INDEXED BY "slr_ix__p__end" WHERE t_end <= ? ORDER BY t_end DESC, t_start DESC, seq DESC'
        """
        flags = {"scan": (end_le,), "prev": (start_ge,), "at_end": (start_ge, end_le),
                 "next": (), "at_start": ()}[kind]
        with self.db.lock:
            self.db.check_open()
            event_type = self.tables.lookup(name, arity)
            if event_type is None:
                return None
            positions, _ = self._pushdown(event_type, bound)
            return self._select_sql(event_type, kind, positions, flags, robot=robot)

    def latest_at_or_before(self, name: str, arity: int, bound: dict[int, Any], t: float,
                            point: bool) -> list[Row] | None:
        """The whole answer of ``prev`` for a pattern whose bound arguments are all atomic and
        whose other arguments are distinct variables, in one statement: the events with the
        greatest end <= t (only point events, start = end, when ``point``), in store order.

        Returns None when a bound value cannot be pushed into SQL exactly (the caller then
        takes the general path). SQL's ``1 = 1.0`` is re-checked by the caller.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.add_events([("p", ("a",), 1, 1), ("p", ("a",), 2, 2)])
        []
        >>> [row[2] for row in s.latest_at_or_before("p", 1, {0: "a"}, 1.5, True)]
        [1.0]
        """
        with self.db.lock:
            self.db.check_open()
            event_type = self.tables.lookup(name, arity)
            if event_type is None:
                return []
            positions, values = self._pushdown(event_type, bound)   # (in the stored form)
            if len(positions) != len(bound):
                return None
            rows = self._latest_rows(event_type, positions, values, t, point)
        dec = decode
        return [(tuple([dec(v) for v in row[:arity]]), row[arity], row[arity + 1], row[arity + 2])
                for row in rows]

    def latest_rows(self, name: str, arity: int, positions: tuple[int, ...], values: list,
                    t: float, point: bool) -> list[tuple]:
        """:meth:`latest_at_or_before` for callers that encoded the bound values themselves
        (``values``, for the argument ``positions`` in increasing order) and decode what they
        need: the raw rows ``(arg1, ..., argN, t_start, t_end, seq, program version, progress
        version)``, one statement. The two versions (see :meth:`Catalog.versions`) are read
        in the same snapshot as the rows, so that a caller learns in the same statement
        whether another connection changed the program or the progress meanwhile.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.add_events([("p", ("a",), 1, 1), ("p", ("a",), 2, 2)])
        []
        >>> s.latest_rows("p", 1, (0,), ["a"], 1.5, True)
        [('a', 1.0, 1.0, 1, None, None)]
        """
        db = self.db
        with db.lock:
            if db.closed:   # (check_open's error; tested inline, as this call is frequent)
                db.check_open()
            event_type = self.tables.lookup(name, arity)
            if event_type is None:
                return []
            if self.to_column is not None:   # a server's columns (store/dialect.py)
                values = [self.to_column(v) for v in values]
            return self._latest_rows(event_type, positions, values, t, point)

    def _latest_rows(self, event_type: EventType, positions: tuple[int, ...], values: list,
                     t: float, point: bool) -> list[tuple]:
        """:meth:`latest_rows` with ``values`` in the stored form (lock held); the rows'
        arguments as :func:`~slr_sql.encoding.decode` reads them."""
        db = self.db
        if t != t:   # NaN: no end is at or before it (as in _query)
            return []
        far = self._far(positions, values)
        sql = self.sql_cache.get((event_type.table, "latest", positions, point, far))
        if sql is None:
            sql = self._latest_sql(event_type, positions, point, far)
        try:   # (the prev lookup: execute's mapping without its lock and check, made above)
            bound = self._bound(values, far)
            rows = fetch_rows(db.conn.execute(sql, (PROGRAM_VERSION, PROGRESS_VERSION, *bound,
                                                    *bound, float(t))))
        except sqlite3.Error as exc:
            raise db.failure(exc) from None
        if db.dialect.from_column is None:
            return rows
        return self._from_columns(rows, event_type.arity)

    def _latest_sql(self, event_type: EventType, positions: tuple[int, ...],
                    point: bool, far: bool) -> str:
        """The statement of :meth:`_latest_rows`, built now and cached (lock held)."""
        arity = event_type.arity
        where = joined_balanced(self._equalities(positions, far)
                                + (["t_start = t_end"] if point else []), "AND")
        where = (where + " AND ") if where else ""
        columns = ", ".join([f"arg{i + 1}" for i in range(arity)]
                            + ["t_start", "t_end", "seq"]
                            + ["(SELECT value FROM slr_meta WHERE key = ?)"] * 2)
        # ORDER BY ... LIMIT 1 rather than max(): max() with the extra start = end
        # filter is an aggregate over every row of the key, LIMIT 1 stops at the first
        sql = (f"SELECT {columns} FROM {event_type.quoted} WHERE {where}t_end = "
               f"(SELECT t_end FROM {event_type.quoted} WHERE {where}t_end <= ? "
               f"ORDER BY t_end DESC LIMIT 1) ORDER BY t_start, seq")
        self.sql_cache[(event_type.table, "latest", positions, point, far)] = sql
        return sql

    def _from_columns(self, rows: list[tuple], arity: int) -> list[tuple]:
        """Raw rows of a server's columns with their arguments as the store encodes them
        (the dialect's ``from_column``)."""
        from_column = self.db.dialect.from_column
        assert from_column is not None
        return [tuple([from_column(v) for v in row[:arity]]) + tuple(row[arity:])
                for row in rows]

    def count(self, name: str, arity: int) -> int:
        """Number of stored events of name/arity.

        >>> from slr_sql.store import EventStore
        >>> EventStore(None).count("p", 1)
        0
        """
        with self.db.lock:
            self.db.check_open()
            event_type = self.tables.lookup(name, arity)
            if event_type is None:
                return 0
            return self.db.execute(f"SELECT count(*) FROM {event_type.quoted}")[0][0]

    def max_end(self, name: str, arity: int) -> float | None:
        """The greatest end time stored for name/arity, or None.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.add_event("p", (1,), 1, 4); s.max_end("p", 1)
        4.0
        """
        with self.db.lock:
            self.db.check_open()
            event_type = self.tables.lookup(name, arity)
            if event_type is None:
                return None
            return self.db.execute(f"SELECT max(t_end) FROM {event_type.quoted}")[0][0]

    def bracket(self, name: str, arity: int, bound: dict[int, Any], t: float,
                longest: float = math.inf) -> tuple[Row | None, Row | None] | None:
        """The observations around ``t`` of the events matching ``bound`` (ground values at
        0-based positions, the first one included): before ``t``, of those that hold at ``t``
        (start ``<= t <= `` end: an observation at ``t``, an interval around it) the one that
        started last (ties: the greatest end, then the last stored); when none holds, the
        one with the greatest end ``<= t`` (ties: the greatest start, then the last stored),
        which the interpolation starts from -- for ``t`` infinite, the last in store order;
        and the one with the smallest start ``>= t`` (ties: the last stored among those
        starting at that time), in one statement; ``(None, None)`` parts when there are
        none. ``longest``: no matching event lasts longer (end - start) than that, so those
        holding at ``t`` started at ``t - longest`` or later (0: points only, the probe
        reads those at ``t``). None when a bound value cannot be pushed into SQL (the caller
        then takes the general path). Used by ``tf_lookup`` (:mod:`slr_sql.frames`) for each
        edge of a chain.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.add_events([("p", ("a", 1), 1, 1), ("p", ("a", 2), 3, 3)])
        []
        >>> [row[0][1] for row in s.bracket("p", 2, {0: "a"}, 2.0)]
        [1, 2]
        """
        with self.db.lock:
            self.db.check_open()
            event_type = self.tables.lookup(name, arity)
            if event_type is None:
                return None, None
            positions, values = self._pushdown(event_type, bound)
            if len(positions) != len(bound) or 0 not in positions:
                return None
            # the event after t is read in start order: its index is built on first need
            ordered = self._start_order(event_type)
            start_hint = self.db.dialect.index_hints and ordered
            # SQL's = takes 1 for 1.0; terms (and frame names) do not: a number matches
            # only a number of its own type
            kinds = tuple(_number_kind(bound[p]) for p in positions)
            # (before a finite t: the latest started of those holding at t, read in start
            # order from t back to t - longest; else the latest ended)
            holding = math.isfinite(t)
            far = self._far(positions, values)
            key = (event_type.table, "bracket", positions, start_hint, kinds, holding, far)
            # (SQL's = takes -0.0 for 0.0: each probe is then run on its own and read on to
            # the first row whose zeros have the bound ones' signs)
            signs = () if self.db.dialect.zero_signs_in_sql else _zero_signs(bound, positions)
            probes = 3 if holding else 2
            union = self.sql_cache.get(key)
            if union is None:
                typeof = self.db.dialect.typeof
                where = joined_balanced([
                    equal + ("" if kind is None else f" AND {typeof(f'arg{p + 1}')} = '{kind}'")
                    for equal, p, kind in zip(self._equalities(positions, far), positions,
                                              kinds)], "AND")
                cols = event_type.columns
                hints = self.db.dialect.index_hints
                by_end = f" INDEXED BY {event_type.index_arg1_end}" if hints else ""
                by_start = f" INDEXED BY {event_type.index_arg1_start}" if start_hint else ""
                ended = (f"{by_end} WHERE {where} AND t_end <= ? "
                         f"ORDER BY t_end DESC, t_start DESC, seq DESC")
                before = (f"{by_start} WHERE {where} AND t_start <= ? AND t_start >= ? "
                          f"AND t_end >= ? ORDER BY t_start DESC, t_end DESC, seq DESC"
                          if holding else ended)
                # (when none holds at t, the interpolation starts at the latest end)
                each = [f"SELECT {n}, {cols} FROM {event_type.quoted}{probe}" for n, probe in
                        enumerate([before, f"{by_start} WHERE {where} AND t_start >= ? "
                                           f"ORDER BY t_start, seq DESC", ended][:probes])]
                for n, probe in enumerate(each):
                    self.sql_cache[key + (n,)] = probe
                union = self.sql_cache[key] = " UNION ALL ".join(
                    f"SELECT * FROM ({probe} LIMIT 1) AS probe_{n}"
                    for n, probe in enumerate(each))
            t = float(t)
            values = self._bound(values, far)
            params = [values + [t, _earliest_holding_start(t, longest), t] if holding
                      else values + [t], values + [t], values + [t]][:probes]
            found: list = [None, None, None]
            if signs:
                for n, args in enumerate(params):
                    try:   # (read on to the first row of the signs: not through execute)
                        found[n] = _first_of_signs(
                            self.db.conn.execute(self.sql_cache[key + (n,)], args), signs)
                    except sqlite3.Error as exc:
                        raise self.db.failure(exc) from None
            else:
                for row in self.db.execute(union, [v for args in params for v in args]):
                    found[row[0]] = row
        if holding and found[0] is None:
            found[0] = found[2]   # (none holds at t)
        dec = self.decode
        out = [None if row is None else (tuple([dec(v) for v in row[1:arity + 1]]),
                                         row[arity + 1], row[arity + 2], row[arity + 3])
               for row in found[:2]]
        return out[0], out[1]

    def null_arguments(self, types: Iterable[tuple[str, int]] | None = None,
                       every: bool = False) -> list[tuple[str, int, str, int, int]]:
        """The stored rows that are no events because an argument is NULL (written by hand:
        the store never writes one): ``(name, arity, table, argument number, seq)``, the
        first such row of each type (``every``: each such row), of every type or of
        ``types``. Read only when a goal met one or a hand-written statement may have
        written one (a scan per type).

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.add_events([("p", ("a",), 1, 1)])
        []
        >>> s.execute('UPDATE p SET arg1 = NULL'); s.null_arguments()
        []
        [('p', 1, 'p', 1, 1)]
        """
        found = []
        with self.db.lock:
            self.db.check_open()
            wanted = None if types is None else set(types)
            for event_type in list(self.tables.types.values()):
                if not event_type.arity or (
                        wanted is not None and (event_type.name, event_type.arity) not in wanted):
                    continue
                columns = [f"arg{i + 1}" for i in range(event_type.arity)]
                flags = ", ".join(f"{c} IS NULL" for c in columns)
                rows = self.db.execute(
                    f"SELECT seq, {flags} FROM {event_type.quoted} "
                    f"WHERE {' OR '.join(f'{c} IS NULL' for c in columns)} "
                    f"ORDER BY seq{'' if every else ' LIMIT 1'}")
                for row in rows:
                    argument = next(i for i, flag in enumerate(row[1:], 1) if flag)
                    found.append((event_type.name, event_type.arity, event_type.table,
                                  argument, row[0]))
        return sorted(found)

    def distinct_pairs(self, name: str, arity: int, after_seq: int = 0
                       ) -> tuple[list[tuple[Any, Any, float]], int]:
        """The distinct (first, second) argument pairs of name/arity among the events stored
        after arrival sequence ``after_seq``, each with the longest duration (end - start,
        0 for points) of its events among those, and the greatest sequence number now (so
        that a caller keeping the pairs reads only what is new next time).

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.add_events([("p", ("a", "b"), 1, 1), ("p", ("a", "b"), 2, 5)])
        []
        >>> s.distinct_pairs("p", 2)
        ([(Atom('a'), Atom('b'), 3.0)], 2)
        """
        with self.db.lock:
            self.db.check_open()
            event_type = self.tables.lookup(name, arity)
            if event_type is None or arity < 2:
                return [], 0
            execute = self.db.execute
            top = execute(f"SELECT max(seq) FROM {event_type.quoted}")[0][0] or 0
            if top <= after_seq:
                return [], top
            # (grouping takes 1 and 1.0 for one value: their types keep them apart.) The
            # duration is halved in SQL, where 1e308 - -1e308 would overflow (an error on
            # PostgreSQL), and doubled here; an empty or reversed span counts 0
            dialect = self.db.dialect
            typeof = dialect.typeof
            groups = f"arg1, arg2, {typeof('arg1')}, {typeof('arg2')}"
            if not dialect.zero_signs_in_sql:
                # (grouping takes -0.0 for 0.0 too, two frame names: each row with a zero
                # is a group of its own, merged below by the values' signs)
                groups += (f", CASE WHEN ({typeof('arg1')} = 'real' AND arg1 = 0) OR "
                           f"({typeof('arg2')} = 'real' AND arg2 = 0) THEN seq END")
            rows = execute(
                f"SELECT arg1, arg2, max(CASE WHEN t_end > t_start THEN t_end / 2 - t_start / 2 "
                f"ELSE 0 END) FROM {event_type.quoted} WHERE seq > ? AND seq <= ? "
                f"GROUP BY {groups}", (after_seq, top))
        dec = self.decode
        pairs: dict[tuple, tuple[Any, Any, float]] = {}
        for first, second, half in rows:
            key = (_exact(first), _exact(second))
            longest = 2.0 * float(half)
            known = pairs.get(key)
            if known is None or known[2] < longest:
                pairs[key] = (dec(first), dec(second), longest)
        return list(pairs.values()), top

    def max_seq(self, name: str, arity: int) -> int:
        """The greatest arrival sequence number stored for name/arity (0 when none): it moves
        whenever an event of the type is added, by this process or another.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.max_seq("p", 1)
        0
        """
        with self.db.lock:
            self.db.check_open()
            event_type = self.tables.lookup(name, arity)
            if event_type is None:
                return 0
            return self.db.execute(f"SELECT max(seq) FROM {event_type.quoted}")[0][0] or 0

    def raw_rows(self, name: str, arity: int, *, after_seq: int | None = None,
                 end_from: float | None = None, end_to: float | None = None,
                 limit: int | None = None, after_key: tuple | None = None) -> list[tuple]:
        """Stored rows of name/arity *as stored* (column values undecoded, see
        :mod:`slr_sql.encoding`) with ``t_start, t_end, arrival, seq``: those after arrival
        sequence ``after_seq`` in arrival order (new events, for live views), else those with
        ``end_from <= end <= end_to`` in store order (exports), after the row whose
        ``(end, start, seq)`` is ``after_key`` (the next page); at most ``limit``.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.add_events([("p", ("a", [1, 2]), 1, 1)])
        []
        >>> [row[:3] for row in s.raw_rows("p", 2, after_seq=0)]
        [('a', '[1,2]', 1.0)]
        """
        with self.db.lock:
            self.db.check_open()
            event_type = self.tables.lookup(name, arity)
            if event_type is None:
                return []
            columns = ", ".join([f"arg{i + 1}" for i in range(arity)]
                                + ["t_start", "t_end", "arrival", "seq"])
            return self._as_stored(arity, self._raw_select(
                event_type, columns, after_seq, end_from, end_to, after_key, limit))

    def raw_page(self, name: str, arity: int, *, rows: int, max_bytes: int,
                 after_seq: int | None = None, end_from: float | None = None,
                 end_to: float | None = None, after_key: tuple | None = None) -> RawPage:
        """The rows :meth:`raw_rows` reads with the same arguments, at most ``rows`` of them
        and, past the first, at most ``max_bytes`` of argument values: a reader that pages
        through a type (a live view, an export) holds a bounded page however large each
        event is. The page says whether rows are left after it.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None)
        >>> s.add_events([("p", (str(i) * 100,), i, i) for i in range(1, 4)])
        []
        >>> page = s.raw_page("p", 1, rows=10, max_bytes=250, after_seq=0)
        >>> [row[0][:3] for row in page.rows], page.more
        (['111', '222'], True)
        """
        if rows < 1:
            raise ValueError("a page holds at least one row")
        with self.db.lock:
            self.db.check_open()
            event_type = self.tables.lookup(name, arity)
            if event_type is None:
                return RawPage([], False)
            size = joined_balanced(
                [f"coalesce({self.db.dialect.byte_length(f'arg{i + 1}')}, 0)"
                 for i in range(arity)], "+") or "0"
            # the sizes first (one more row than a page: whether any is left), then only the
            # rows that fit, so no statement ever hands over more than the bound of values
            sizes = self._raw_select(event_type, size, after_seq, end_from, end_to,
                                     after_key, rows + 1)
            taken, total = 0, 0
            for (row_size,) in sizes[:rows]:
                if taken and total + row_size > max_bytes:
                    break
                total += row_size
                taken += 1
            if not taken:
                return RawPage([], False)
            columns = ", ".join([f"arg{i + 1}" for i in range(arity)]
                                + ["t_start", "t_end", "arrival", "seq"])
            found = self._raw_select(event_type, columns, after_seq, end_from, end_to,
                                     after_key, taken)
        return RawPage(self._as_stored(arity, found), taken < len(sizes))

    def _raw_select(self, event_type: EventType, columns: str, after_seq: int | None,
                    end_from: float | None, end_to: float | None, after_key: tuple | None,
                    limit: int | None) -> list[tuple]:
        """``columns`` of a type's rows in :meth:`raw_rows`'s order and bounds."""
        params: list = []
        if after_seq is not None:
            where, order = "seq > ?", "seq"
            params.append(int(after_seq))
        else:
            conditions = []
            if end_from is not None:
                conditions.append("t_end >= ?")
                params.append(float(end_from))
            if end_to is not None:
                conditions.append("t_end <= ?")
                params.append(float(end_to))
            if after_key is not None:
                conditions.append("(t_end, t_start, seq) > (?, ?, ?)")
                params += [float(after_key[0]), float(after_key[1]), int(after_key[2])]
            # no condition: no WHERE (PostgreSQL refuses `WHERE 1`: it needs a boolean)
            where = " AND ".join(conditions)
            order = "t_end, t_start, seq"
        sql = (f"SELECT {columns} FROM {event_type.quoted}"
               + (f" WHERE {where}" if where else "") + f" ORDER BY {order}")
        if limit is not None:
            sql += " LIMIT ?"
            params.append(int(limit))
        return self.db.execute(sql, params)

    def _as_stored(self, arity: int, rows: list[tuple]) -> list[tuple]:
        """Rows with their argument values as SQLite stores them."""
        from_column = self.db.dialect.from_column
        if from_column is not None:   # a server's typed columns: as SQLite stores them
            rows = [tuple([from_column(v) for v in row[:arity]]) + tuple(row[arity:])
                    for row in rows]
        return rows
