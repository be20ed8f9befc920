"""Storing events: checked, encoded, batched into their tables in one transaction per add.

Every add first records the store clock's "now" in ``slr_clock`` (the buffer triggers read
it), then inserts the valid events with ``executemany`` per run of one type; invalid events
are skipped and reported (or, with ``atomic=True``, abort the whole add). A slice of
well-formed events takes a fast path that checks whole columns at once, one statement per
table (:meth:`EventWriter._insert_uniform`, and :meth:`EventWriter._insert_mixed` for
interleaved types on SQLite); anything else, or any doubt, goes event by event.
"""
from __future__ import annotations

import math
import sqlite3
from itertools import chain, islice, repeat
from operator import attrgetter, itemgetter, le as _le
from typing import Any, Iterable, Iterator

from ..encoding import Unencodable, encode, encode_column, event_columns_loop
from ..errors import EventRejected
from .checks import BadEvent, arguments_problem, check_times, event_rejection, \
    shown, text_problem
from .connection import Database
from .stored_text import fetch_row
from .tables import EventTables, EventType

__all__ = ["Event", "EventBatch", "EventWriter"]

Event = tuple[Any, ...]  # (name: str, args: tuple[term, ...], start: float, end: float)


class EventBatch(list):
    """A list of events that :meth:`EventWriter.add_events` also describes while it stores
    them: ``ends`` becomes ``{(name, arity): (earliest end, latest end)}`` of the events it
    stored, so that what follows an add (learned delays, in-order horizons) need not walk a
    big batch again. ``ends`` is None until an add of the batch completes (and again while
    another add of it runs, or after one failed).

    >>> from slr_sql.store import EventStore
    >>> batch = EventBatch([("p", (1,), 1.0, 2.0), ("p", (2,), 0.5, 0.5), ("q", (), 1.0, 1.0)])
    >>> EventStore(None).add_events(batch), batch.ends
    ([], {('p', 1): (0.5, 2.0), ('q', 0): (1.0, 1.0)})
    """

    ends: dict | None = None


_INF = math.inf
_NEG_INF = -math.inf
_INSERT_CHUNK = 20_000  # events checked and inserted together: bounds memory on huge batches
# rows per multi-row INSERT on SQLite: one statement of many rows costs ~35 % less than as many
# executions of a one-row statement (binding and stepping a statement is per execution); the
# sizes are powers of two so that a few statement texts, kept prepared, serve every batch
_ROWS_PER_INSERT = 512
# ... but only into a small table: as a table's indexes grow, each row of a multi-row INSERT
# costs more than a row of an ``executemany`` of the one-row statement (measured on SQLite
# 3.40 with the two end-ordered indexes: equal at ~100,000 rows stored, multi-row 1.4x at
# 1,000,000, and 1.2-1.5x for 10,000 to 100,000 rows added to 900,000). Above this many rows
# (the table's seq span once the rows are in) the rows go in by ``executemany``.
_MULTI_ROW_TABLE_ROWS = 65_536
_FOUR = {4}
_FLOAT = frozenset({float})
_SEQUENCES = frozenset({tuple, list})
_first, _second, _third, _fourth = (itemgetter(i) for i in range(4))


def _chunks(events: Iterable[Event]) -> Iterator[tuple[int, list]]:
    """``(index of the first event, list of events)`` for slices of ``events``."""
    if type(events) is list or type(events) is tuple or type(events) is EventBatch:
        for base in range(0, len(events), _INSERT_CHUNK):
            yield base, events[base:base + _INSERT_CHUNK]
        return
    iterator = iter(events)
    base = 0
    while True:
        chunk = list(islice(iterator, _INSERT_CHUNK))
        if not chunk:
            return
        yield base, chunk
        base += len(chunk)


def _split_columns(chunk: list) -> tuple[str, int, list, list, list] | None:
    """``(name, arity, argument columns, starts, ends)`` of ``chunk`` -- events of one name
    -- when every event is a 4-tuple of one arity, its arguments a tuple or list, with
    finite float times, start <= end (a time -0.0 given as 0.0); None otherwise. What the
    C loop ``event_columns_loop`` gives in one pass (for a list of exact tuples and an exact
    str name; it declines the rest, which this decides)."""
    name = chunk[0][0]
    if not isinstance(name, str):
        return None
    argss = list(map(_second, chunk))
    if not _SEQUENCES.issuperset(map(type, argss)):
        return None
    arities = set(map(len, argss))
    if len(arities) != 1:
        return None
    (arity,) = arities
    starts = list(map(_third, chunk))
    ends_column = list(map(_fourth, chunk))
    if not (_FLOAT.issuperset(map(type, starts)) and _FLOAT.issuperset(map(type, ends_column))
            and all(map(_le, starts, ends_column))):  # False at a NaN, too
        return None
    if not (_NEG_INF < min(starts) and max(ends_column) < _INF):
        return None
    # a time -0.0 is stored as 0.0 on every backend (SQLite's REAL column keeps no sign
    # of a zero, PostgreSQL's would): x + 0.0 is x but for -0.0
    if 0.0 in starts:
        starts = [t + 0.0 for t in starts]
    if 0.0 in ends_column:
        ends_column = [t + 0.0 for t in ends_column]
    return name, arity, [list(map(itemgetter(i), argss)) for i in range(arity)], starts, \
        ends_column


def _encoded_columns(split: tuple[str, int, list, list, list]
                     ) -> tuple[str, int, list, list, list] | None:
    """``split`` (:func:`_split_columns`) with its argument columns encoded; None when an
    argument has no stored form."""
    name, arity, columns, starts, ends_column = split
    try:
        columns = [encode_column(column) for column in columns]
    except (Unencodable, RecursionError):
        return None
    return name, arity, columns, starts, ends_column


def _widen(ends: dict, key: tuple, earliest: float, latest: float) -> None:
    known = ends.get(key)
    if known is not None:
        earliest, latest = min(known[0], earliest), max(known[1], latest)
    ends[key] = (earliest, latest)


# a row is (*arguments, start, end, arrival, robot), or (*arguments, start, end, arrival) for
# a store that has no robot name (EventType.insert_unnamed_sql)
_END_OF_ROW = {True: itemgetter(-3), False: itemgetter(-2)}


def _widen_by_rows(ends: dict, event_type: EventType, rows: list, with_robot: bool) -> None:
    row_ends = list(map(_END_OF_ROW[with_robot], rows))
    _widen(ends, (event_type.name, event_type.arity), min(row_ends), max(row_ends))


class EventWriter:
    """Adds events to the tables of one database.

    >>> from slr_sql.store import EventStore
    >>> EventStore(None).add_events([("seg", ("cup1", 1), 2.0, 2.0)])
    []
    """

    def __init__(self, db: Database, tables: EventTables):
        self.db = db
        self.tables = tables
        # the robot the rows of an add are stored with: the store's name (None: unnamed),
        # or, while a fleet store receives a shipped batch, the shipping robot
        self.robot: str | None = None
        # per table (its quoted name): at most how many rows it holds after this writer's
        # last multi-row add (the rows it added counted, what others added or pruned not),
        # and the tables found beyond _MULTI_ROW_TABLE_ROWS; the span is read only when the
        # bound crosses that line, not at every add of the ingest path
        self._rows_bound: dict[str, int] = {}
        self._large_tables: set[str] = set()

    def add_events(self, events: Iterable[Event], atomic: bool = False, *,
                   join: bool = False) -> list[EventRejected]:
        """Store events ``(name, args, start, end)`` in one transaction.

        Invalid events (arguments not a list or tuple, non-ground or NaN arguments, arguments
        with no stored form such as lone surrogates or integers of thousands of digits, more
        arguments than a table can have, times that are not finite numbers, start > end,
        wrong arity for a declared type) are skipped and returned as :class:`EventRejected`
        errors (with ``.index`` and ``.event``); the others are stored. With ``atomic=True`` the first
        invalid event is raised and nothing is stored. All events of one call share one
        arrival time, taken from the clock; their order is their arrival order. ``join``:
        inside a transaction whose every error the caller lets through to the level that
        takes it back (the event rules' rounds), the add opens no savepoint of its own
        (one costs ~5% of a round's CPU: SQLite keeps the pages it changes for a rollback).

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None)
        >>> [str(e) for e in s.add_events([("p", (1,), 1.0, 1.0), ("p", (2,), 3.0, 2.0)])]
        ['p(2)^[3.0,2.0]: start time 3.0 is after end time 2.0']
        """
        errors: list[EventRejected] = []
        ends = None
        if type(events) is EventBatch:
            ends = {}
            events.ends = None  # (a batch given again: not the last add's description)
        if type(events) in (list, tuple, EventBatch) and not events:
            if ends is not None:
                events.ends = ends
            return errors
        server = self.db.dialect.to_column is not None
        if server:
            arrival = float(self.db.clock.now())
            if self.db.tbuffers_active is not False:
                self._record_now_for_tbuffers(arrival)
        with self.db.transaction(join=join):
            if not server:
                arrival = float(self.db.clock.now())
                # buffers: "now" for the buffer triggers, in the add's transaction
                self.record_now(arrival)
            # (the views are made again once for all the tables the add makes)
            with self.tables.batch():
                for base, chunk in _chunks(events):
                    if not self._insert_uniform(chunk, arrival, ends):
                        self._insert_each(chunk, base, arrival, atomic, errors, ends)
        if ends is not None:
            events.ends = ends
        return errors

    def _insert_uniform(self, chunk: list, arrival: float, ends: dict | None) -> bool:
        """The fast path: insert ``chunk`` if it is uniform -- every event a 4-tuple of one
        type whose arguments are a tuple or list, with float times, finite, start <= end --
        and every argument encodes; return False (having stored nothing) otherwise, for
        :meth:`_insert_each` to check event by event and say what is wrong. The end times
        of what it stored widen ``ends`` (when not None).

        The checks run over whole columns (``set(map(type, ...))``, ``min``/``max``), or
        in one pass of the C loop (``event_columns_loop``, which declines what it does not
        know for these checks to decide), so the only Python work per event is encoding its
        arguments: a recording of one event type goes in at close to the speed of a plain
        ``executemany``.
        """
        split = None if event_columns_loop is None else event_columns_loop(chunk)
        try:
            if split is None:
                if set(map(len, chunk)) != _FOUR:
                    return False
                names = set(map(_first, chunk))
                if len(names) != 1:
                    return self._insert_mixed(chunk, names, arrival, ends)
                split = _split_columns(chunk)
            checked = None if split is None else _encoded_columns(split)
        except (TypeError, IndexError, KeyError):  # not sized, not indexable, unhashable
            return False
        if checked is None:
            return False
        name, arity, columns, starts, ends_column = checked
        event_type = self._type_or_none(name, arity)
        if event_type is None:
            return False
        self._insert_columns(event_type, columns, starts, ends_column, arrival)
        if ends is not None:
            _widen(ends, (name, arity), min(ends_column), max(ends_column))
        return True

    def _type_or_none(self, name: str, arity: int) -> EventType | None:
        """The table of name/arity, made if new; None when the name is refused (the column
        path then leaves the chunk to the event-by-event one, which rejects with reasons)."""
        event_type = self.tables.types.get((name, arity))
        if event_type is None:
            try:
                event_type = self.type_for_new_event(name, arity)
            except BadEvent:
                return None
        return event_type

    def _checked_columns(self, chunk: list) -> tuple[str, int, list, list, list] | None:
        """``(name, arity, encoded argument columns, starts, ends)`` of ``chunk`` -- events
        of one name -- when every event is a well-formed 4-tuple of one arity with finite
        float times, start <= end, and every argument encodes; None otherwise. Nothing is
        written (no table created)."""
        split = None if event_columns_loop is None else event_columns_loop(chunk)
        if split is None:
            split = _split_columns(chunk)
        return None if split is None else _encoded_columns(split)

    def _insert_mixed(self, chunk: list, names: set, arrival: float,
                      ends: dict | None) -> bool:
        """The fast path for a chunk of several event names (a stream of interleaved
        types): each name's events are checked column-wise as :meth:`_insert_uniform`
        checks one type's, and, only when all pass, each table gets one ``executemany`` of
        its rows in their order. A table's rows, its ``seq`` order, its triggers (buffers,
        journals: each reads only its own table) see what they see run by run; no table
        sees another's rows within an add. False (nothing stored) at any doubt: the chunk
        then goes event by event. SQLite only (a server's batch takes one pipeline in
        :meth:`_insert_each`)."""
        if self.db.dialect.to_column is not None or len(names) > 64:
            return False
        try:
            # in order of first appearance: the tables are written, and the batch's end
            # spans listed, in the order the event-by-event path would
            groups: dict[Any, list] = {name: [] for name in dict.fromkeys(map(_first, chunk))}
        except TypeError:  # an unhashable name
            return False
        for event in chunk:
            groups[event[0]].append(event)
        checked = []
        for group in groups.values():
            try:
                one = self._checked_columns(group)
            except (TypeError, IndexError, KeyError):  # an event not indexable
                return False
            if one is None:
                return False
            checked.append(one)
        prepared = []
        for name, arity, columns, starts, ends_column in checked:
            event_type = self._type_or_none(name, arity)
            if event_type is None:
                return False
            prepared.append((event_type, columns, starts, ends_column))
        for event_type, columns, starts, ends_column in prepared:
            self._insert_columns(event_type, columns, starts, ends_column, arrival)
            if ends is not None:
                _widen(ends, (event_type.name, event_type.arity), min(ends_column),
                       max(ends_column))
        return True

    def _insert_columns(self, event_type: EventType, columns: list, starts: list,
                        ends_column: list, arrival: float) -> None:
        """Insert the rows of ``event_type`` given column-wise, in their order."""
        to_column = self.db.dialect.to_column
        if to_column is not None:  # a server's typed columns: see store/dialect.py
            columns = [list(map(to_column, column)) for column in columns]
        robot = self.robot
        if to_column is None:
            if robot is None:  # the column's NULL, not a parameter bound per row
                rows = zip(*columns, starts, ends_column, repeat(arrival))
            else:
                rows = zip(*columns, starts, ends_column, repeat(arrival), repeat(robot))
            self._insert_rows(event_type, rows, len(starts), robot is not None)
        elif robot is None:
            self.db.conn.executemany(event_type.insert_unnamed_sql,
                                     zip(*columns, starts, ends_column, repeat(arrival)))
        else:
            self.db.conn.executemany(event_type.insert_sql,
                                     zip(*columns, starts, ends_column, repeat(arrival),
                                         repeat(robot)))

    def _insert_rows(self, event_type: EventType, rows: Iterable[tuple], count: int,
                     with_robot: bool) -> None:
        """Insert the ``count`` ``rows`` (SQLite), in their order: with multi-row INSERTs
        of power-of-two sizes into a small table, with an ``executemany`` of the one-row
        statement once the table holds more than :data:`_MULTI_ROW_TABLE_ROWS` rows (there
        it costs less per row). The same rows either way, in the add's transaction."""
        if not count:
            return
        execute = self.db.conn.execute
        try:   # (every add: execute's mapping, in the add's transaction, which holds the lock)
            if count > 1 and self._rows_after(event_type, count) > _MULTI_ROW_TABLE_ROWS:
                self.db.conn.executemany(event_type.insert_sql if with_robot
                                         else event_type.insert_unnamed_sql, rows)
                return
            values = list(chain.from_iterable(rows))
            width = len(values) // count
            most = _ROWS_PER_INSERT
            while most > 1 and most * width > self.db.max_parameters:
                most //= 2
            done = 0
            while done < count:
                size = min(most, 1 << ((count - done).bit_length() - 1))
                execute(event_type.insert_rows_sql(size, with_robot),
                        values[done * width:(done + size) * width])
                done += size
        except sqlite3.Error as exc:
            raise self.db.failure(exc) from None

    def _rows_after(self, event_type: EventType, count: int) -> int:
        """About how many rows ``event_type``'s table holds once ``count`` more are in: its
        seq span (two lookups at the ends of the rowid; rows pruned from the front of a
        buffered table are not counted) plus ``count``, read when this writer's bound
        (:attr:`_rows_bound`) says the table may have grown past the line. Only the speed of
        the insert rests on it: a table another connection filled meanwhile takes multi-row
        INSERTs until this writer's own adds bring the bound to the line."""
        quoted = event_type.quoted
        if quoted in self._large_tables:
            return _MULTI_ROW_TABLE_ROWS + count
        bound = self._rows_bound.get(quoted)
        if bound is None or bound + count > _MULTI_ROW_TABLE_ROWS:
            span = fetch_row(self.db.conn.execute(f"SELECT (SELECT max(seq) FROM {quoted}) - "
                                                  f"(SELECT min(seq) FROM {quoted})"))[0]
            bound = span or 0
            if bound > _MULTI_ROW_TABLE_ROWS:
                self._large_tables.add(quoted)
        self._rows_bound[quoted] = bound + count
        return bound + count

    def _insert_each(self, chunk: list, base: int, arrival: float, atomic: bool,
                     errors: list[EventRejected], ends: dict | None) -> None:
        """Check, encode and insert the events of ``chunk`` one by one (each type's rows go
        in together, in their order); a bad event is rejected with its reason and index
        (``base`` + its place in the chunk), or raised when ``atomic``. The end times of
        what it stored widen ``ends`` (when not None)."""
        enc: Any = encode
        to_column = self.db.dialect.to_column
        if to_column is not None:  # a server's typed columns: see store/dialect.py
            def enc(term: Any) -> Any:
                return to_column(encode(term))
        executemany = self.db.conn.executemany
        types = self.tables.types
        robot = self.robot
        with_robot = robot is not None  # else the column's NULL, not bound per row
        tail = (arrival, robot) if with_robot else (arrival,)
        insert_sql = attrgetter("insert_sql" if with_robot else "insert_unnamed_sql")
        rows: list = []
        append = rows.append
        # each type's rows, in their order: what a table's seq, its triggers and its journal
        # see is the same as run by run (tables do not see each other's rows), and an
        # interleaved stream (a, b, a, b) takes one insert per type, not one per event
        by_type: dict[EventType, list] = {}
        current_name: Any = None
        current_arity = -1
        current_type: EventType | None = None
        for index, event in enumerate(chunk, base):
            try:
                try:
                    name, args, start, end = event
                except (TypeError, ValueError):
                    raise BadEvent(f"event #{index} is not a (name, args, start, end) "
                                   f"tuple: {shown(event)}") from None
                if type(args) is not tuple and type(args) is not list:
                    raise BadEvent(arguments_problem(args))
                arity = len(args)
                if not (type(start) is float and type(end) is float
                        and _NEG_INF < start <= end < _INF):
                    start, end = check_times(start, end)
                elif start == 0.0 or end == 0.0:   # (-0.0: stored as 0.0, see above)
                    start, end = start + 0.0, end + 0.0
                if arity == 1:
                    row = (enc(args[0]), start, end, *tail)
                elif arity == 2:
                    row = (enc(args[0]), enc(args[1]), start, end, *tail)
                else:
                    row = (*map(enc, args), start, end, *tail)
                if arity != current_arity or name != current_name:
                    current_type = (isinstance(name, str) and types.get((name, arity))
                                    or self.type_for_new_event(name, arity))
                    current_name = name
                    current_arity = arity
                    append = by_type.setdefault(current_type, []).append
                append(row)
            except (BadEvent, Unencodable) as exc:
                error = self._rejection(index, event, exc)
                if atomic:
                    raise error from None
                errors.append(error)
        if to_column is not None:
            # a server: one statement per table in one pipeline, not a round trip per type
            with self.db.conn.pipeline(max(map(len, by_type.values()), default=0)):
                for event_type, typed_rows in by_type.items():
                    executemany(insert_sql(event_type), typed_rows)
        else:
            for event_type, typed_rows in by_type.items():
                self._insert_rows(event_type, typed_rows, len(typed_rows), with_robot)
        if ends is not None:
            for event_type, typed_rows in by_type.items():
                _widen_by_rows(ends, event_type, typed_rows, with_robot)

    def type_for_new_event(self, name: Any, arity: int) -> EventType:
        """The event type ``name/arity`` an event about to be written goes to, its table
        created on first sight; :class:`BadEvent` (with the reason) when the name cannot be
        stored, the arity is too large, or a declaration names other arities."""
        if not isinstance(name, str):
            raise BadEvent(f"event name must be an atom, not {shown(name)}")
        name = str(name)
        problem = text_problem(name)
        if problem:
            raise BadEvent(f"the event name cannot be stored: {problem}")
        if "\x00" in name and not self.db.dialect.text_holds_nul:
            raise BadEvent("the event name cannot be stored: PostgreSQL text cannot hold the "
                           "character U+0000 (an argument can: it is stored escaped)")
        if arity > self.tables.max_arity:
            raise BadEvent(f"too many arguments: {arity} (an event has at most "
                           f"{self.tables.max_arity}, the column limit of the store's tables)")
        event_type = self.tables.lookup(name, arity)
        if event_type is not None:
            return event_type
        declared = self.tables.declared_arities.get(name)
        if declared and arity not in declared:
            arities = " and ".join(f"{name}/{a}" for a in sorted(declared))
            raise BadEvent(f"wrong number of arguments: event type {arities} is declared, "
                           f"{name}/{arity} is not")
        return self.tables.register(name, arity, declared=False)

    def _rejection(self, index: int, event: Any, exc: Exception) -> EventRejected:
        error = event_rejection(event, exc)
        error.index = index
        return error

    def add_event(self, name: str, args: Iterable[Any], start: float, end: float) -> None:
        """Store one event (``args`` a list or tuple); raises :class:`EventRejected` if it is
        invalid.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.add_event("tick", (), 1, 1); s.count("tick", 0)
        1
        """
        self.add_events([(name, args, start, end)], atomic=True)

    # ------------------------------------------------------------------ the store clock
    # slr_clock (migrations/0002_buffers.sql) holds the "now" the buffer triggers use.

    def record_now(self, now: float) -> None:
        """Record the store clock's current time in ``slr_clock`` (read by the buffer
        triggers). Moving it runs the time-driven tBuffer pruning (``slr_buf_<id>_tick``
        triggers). Called at the start of every add batch and by clock listeners.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.record_now(5.0); s.recorded_now()
        5.0
        """
        now = float(now)
        if now != now:
            return
        sql = "UPDATE slr_clock SET now = ? WHERE id = 1 AND now <> ?"
        with self.db.lock:
            if self.db.tx_depth:  # inside add_events: part of its transaction
                self.db.check_open()
                try:   # (every add: execute's mapping, the lock held already)
                    self.db.conn.execute(sql, (now, now))
                except sqlite3.Error as exc:
                    raise self.db.failure(exc) from None
                return
        with self.db.transaction():
            self.db.execute(sql, (now, now))

    def _record_now_for_tbuffers(self, now: float) -> None:
        """On a server: record ``now`` before an add, only while a tBuffer is active (its
        triggers read it), as a statement of its own outside the add's transaction (one row
        that every writer would otherwise hold locked until its commit). Skipped while the
        last read of the versions found no tBuffer (``db.tbuffers_active`` False: a knowledge
        base reads them whenever another connection may have committed)."""
        if now != now:
            return
        self.db.execute(
            "UPDATE slr_clock SET now = ? WHERE id = 1 AND now <> ? AND EXISTS (SELECT 1 "
            "FROM slr_buffers WHERE kind = 'tBuffer' AND removed_at IS NULL)", (now, now))

    def recorded_now(self) -> float:
        """The "now" buffer triggers currently use (``-inf`` before the first record).

        >>> from slr_sql.store import EventStore
        >>> EventStore(None).recorded_now()
        -inf
        """
        return self.db.execute("SELECT now FROM slr_clock WHERE id = 1")[0][0]
