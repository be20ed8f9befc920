"""The persistent event store: one SQLite file (or an in-memory database).

This package is the only part of slr_sql that talks to SQLite. :class:`EventStore` is its
whole interface: a facade over small parts that share one :class:`~.connection.Database`
(the connection, its lock, the transaction depth and the clock):

* :mod:`.connection` -- opening the file (WAL, ``synchronous``, cache), transactions
  (savepoints when nested), the deadline of compiled statements, raw SQL, and
  :func:`run_sql_file` (a connection of its own, read-only unless asked, for ``slr sql``);
* :mod:`.schema` -- the numbered migrations of the ``slr_*`` tables (``PRAGMA user_version``);
* :mod:`.tables` -- event types and their tables and indexes (``slr_event_types``);
* :mod:`.events` -- adding events (checks in :mod:`.checks`), the store clock ``slr_clock``;
* :mod:`.lookups` -- the indexed lookups behind ``prev``/``next``/stream scans;
* :mod:`.catalog` -- program text, meta keys, buffer rows and objects, fact tables, views;
* :mod:`.space` -- row counts, page statistics, reclaiming free pages, bounding the WAL;
* :mod:`.sqltext` -- quoting identifiers and literals, splitting SQL scripts.

Callers outside the package catch :data:`DatabaseError` (the base of the errors a statement
raises: its own, such as a missing table or a constraint) and never import ``sqlite3``; what
is about the file or its disk (busy, full, damaged, gone) is an :class:`~slr_sql.SLRError`
already (``Database.failure``). The SQL dialect lives here and in slr_sql.sqlcompile
only, so a second backend (PostgreSQL, for fleets) would sit beside this package with the
same :class:`EventStore` methods: a ``Database`` (connect, transactions as savepoints,
migrations of its own, a statement deadline), the table DDL and lookup statements of
``tables``/``lookups`` (``INDEXED BY`` becomes plain indexes), the catalog's upserts and
``sqlite_master`` queries against its own catalog, and ``space`` mapped to its own
statistics (or reporting none). Buffer triggers are printed here per engine
(:mod:`.buffering`) from the typed pattern tests slr_sql.buffers compiles.

Durability: file databases use ``journal_mode=WAL`` with ``synchronous=FULL``: when
:meth:`EventStore.add_events` returns, its transaction is in the WAL *and* fsynced, so the
events survive a process kill and a power loss. (``synchronous=NORMAL`` would survive a kill
but may lose the last transactions on power loss; pass ``synchronous="NORMAL"`` to trade that
for speed.) Values are always bound parameters; identifiers are always quoted.

Threads: one connection, serialized by ``EventStore.lock`` (an ``RLock``); a
:meth:`EventStore.transaction` holds the lock until it ends, and suspends the event scans
other threads left open (they resume after it, from where they were).

>>> store = EventStore(None)
>>> store.add_events([("seg", ("cup1", 1), 2.0, 2.0)])
[]
>>> [row[:3] for row in store.scan("seg", 2, {})]
[((Atom('cup1'), 1), 2.0, 2.0)]
"""
from __future__ import annotations

import math
import threading
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator

from ..errors import EventRejected
from ..lockorder import held_here
from .buffering import (ArgEquals, BufferPlan, BufferTables, JsonArray, JsonEquals, MixedTerm,
                        PatternMatch, SameTerm)
from .catalog import Catalog, ProgramText
from .checks import format_event
from .connection import CACHE_SIZE_KIB, DEFAULT_BUSY_TIMEOUT, Database, DatabaseError, \
    ReadConnection, check_file_options, is_postgres_url, refuse_no_store, run_sql_file, \
    shown_location
from .events import Event, EventBatch, EventWriter
from .fleet import ROBOT_NAME_MAX, Fleet, RouteConflict, ShipmentConflict, WriterInFlight, \
    check_robot_name
from .functions import SqlFunctions
from .journals import JournalReader, SubscriptionRecord, SubscriptionTables
from .lookups import EventReader, RawPage, Row, null_argument_text
from .schema import migration_scripts
from .space import ServerSpace, Space
from .sqltext import quote_identifier, split_sql_script, sql_literal, store_error
from .tables import EventTables, start_compared

__all__ = ["EventStore", "Event", "EventBatch", "Row", "RawPage", "ProgramText", "CACHE_SIZE_KIB", "DEFAULT_BUSY_TIMEOUT",
           "DatabaseError", "quote_identifier", "sql_literal", "format_event",
           "migration_scripts", "split_sql_script", "run_sql_file", "refuse_no_store", "shown_location", "store_error",
           "check_robot_name", "ROBOT_NAME_MAX", "RouteConflict", "ShipmentConflict", "WriterInFlight", "ReadConnection", "ArgEquals", "BufferPlan", "JsonArray",
           "JsonEquals", "MixedTerm", "PatternMatch", "SameTerm", "JournalReader", "null_argument_text",
           "SubscriptionRecord"]


def _doc(part_method: Callable) -> Callable:
    """Give a facade method the docstring of the part's method it calls."""
    def copy(method: Callable) -> Callable:
        method.__doc__ = part_method.__doc__
        return method
    return copy


class EventStore:
    """Events, program and state of one knowledge base, in one SQLite database.

    ``path`` None or ``":memory:"`` gives an in-memory store. ``clock`` is any object with
    ``now() -> float`` (arrival times); the default is the wall clock. ``busy_timeout``:
    seconds a write waits for another connection's write transaction before
    :class:`~slr_sql.errors.SLRBusy`. A file that is not a store is refused with an
    :class:`~slr_sql.errors.SLRError` and left untouched, unless ``adopt=True`` (a foreign
    SQLite file then gets the store's tables added). ``checkpoint="background"`` copies the
    write-ahead log into the file on a thread of its own (:mod:`slr_sql.store.checkpointer`).
    ``cache_mib``: the bound of SQLite's page cache for this connection (default 64 MiB; it
    fills as the store is used and stays there).

    >>> store = EventStore(":memory:")
    >>> store.add_event("obj", ("cup1", "red"), 1.0, 1.0); store.count("obj", 2)
    1
    >>> store.close()
    """

    def __init__(self, path: str | Path | None = None, clock: Any = None, *,
                 synchronous: str = "FULL", busy_timeout: float = DEFAULT_BUSY_TIMEOUT,
                 adopt: bool = False, checkpoint: str = "auto",
                 cache_mib: float = CACHE_SIZE_KIB / 1024, robot: str | None = None):
        if robot is not None:
            check_robot_name(robot)
        db: Any
        if is_postgres_url(path):
            # imported here: ~2 ms of every process that opens a store, most of them SQLite's
            from .postgres import PgDatabase

            # checked as on SQLite (the same value refused or taken on both engines), then
            # unused: the server has its own durability, checkpoints and cache
            check_file_options(synchronous, checkpoint, cache_mib)
            db = PgDatabase(str(path), clock, busy_timeout=busy_timeout, adopt=adopt)
        else:
            db = Database(path, clock, synchronous, busy_timeout, adopt, checkpoint,
                          cache_mib=cache_mib)
        self._db = db
        self._tables = EventTables(db)
        self._writer = EventWriter(db, self._tables)
        self._reader = EventReader(db, self._tables)
        self._catalog = Catalog(db)
        self._buffers = BufferTables(db)
        self._subscriptions = SubscriptionTables(db)
        self._space = (ServerSpace if is_postgres_url(path) else Space)(db, self._tables)
        try:
            self._fleet = Fleet(db, self._tables, self._writer)
            if robot is not None:
                self._fleet.name(robot)
        except BaseException:
            db.close()
            raise

    # ------------------------------------------------------------------ shared state

    @property
    def path(self) -> str | None:
        """The database file (None for an in-memory store)."""
        return self._db.path

    @property
    def clock(self) -> Any:
        """The clock giving arrival times (``now() -> float``)."""
        return self._db.clock

    @clock.setter
    def clock(self, clock: Any) -> None:
        self._db.clock = clock

    @property
    def lock(self) -> Any:
        """The ``RLock`` serializing the connection (held by a whole transaction)."""
        return self._db.lock

    def owns_lock(self) -> bool:
        """Does this thread hold the store's lock (in a transaction, say)? A caller that
        must take a lock ordered before the store's (slr_sql.lockorder) waits until not."""
        return held_here(self._db.lock)

    @property
    def table_created_hooks(self) -> list:
        """Called as ``hook(name, arity, table)`` inside the transaction that creates a new
        event type's table (slr_sql.buffers installs its triggers there)."""
        return self._tables.table_created_hooks

    @table_created_hooks.setter
    def table_created_hooks(self, hooks: list) -> None:
        self._tables.table_created_hooks = hooks

    @property
    def tables_created_hooks(self) -> list:
        """Called as ``hook([(name, arity, table), ...])`` once per batch of new event
        tables (an add, a :meth:`table_batch`), inside its transaction after the batch's
        work; a table made outside a batch is a batch of its own (slr_sql.planner makes its
        views again there)."""
        return self._tables.tables_created_hooks

    @property
    def batch_names(self) -> list:
        """Callables giving the names (lower case) the :attr:`tables_created_hooks` may
        create objects with: a new table whose name could be one of them is named after
        the batch's pending hooks ran, as if they had run at every table."""
        return self._tables.batch_names

    @contextmanager
    def table_batch(self) -> Iterator[None]:
        """The new tables made inside are one batch for :attr:`tables_created_hooks`
        (run as it ends, unless it raises); used inside a transaction.

        >>> s = EventStore(None); seen = []; s.tables_created_hooks.append(seen.append)
        >>> with s.transaction(), s.table_batch():
        ...     _ = s.add_events([("a", (1,), 1.0, 1.0)]); _ = s.declare_type("b", 0)
        ...     print(seen)
        []
        >>> seen
        [[('a', 1, 'a'), ('b', 0, 'b')]]
        """
        with self._db.lock, self._tables.batch():
            yield

    @property
    def rollback_listeners(self) -> list:
        """Called as ``listener()`` after a transaction, or a nested one, rolled back (what
        a caller learned inside it may be gone).

        >>> s = EventStore(None); heard = []
        >>> s.rollback_listeners.append(lambda: heard.append("rolled back"))
        >>> with s.transaction(), s.transaction():
        ...     s.add_event("p", (1,), 1.0, 1.0)
        >>> try:
        ...     with s.transaction():
        ...         raise ValueError
        ... except ValueError:
        ...     pass
        >>> heard
        ['rolled back']
        """
        return self._db.rollback_listeners

    def table_names(self) -> set[str]:
        """Names of every table of the store (event tables, ``slr_*`` tables, journals)."""
        self._db.check_open()
        return self._db.table_names()

    def triggers(self, table: str | None = None) -> set[str]:
        """Names of the triggers of the store (on ``table`` only, when given)."""
        self._db.check_open()
        return self._db.triggers(table)

    def index_names(self, table: str) -> set[str]:
        """Names of the indexes of ``table`` (in the database's catalog).

        >>> s = EventStore(None); s.declare_type("seg", 2)
        'seg'
        >>> sorted(s.index_names("seg"))
        ['slr_ix__seg__a1_end', 'slr_ix__seg__end']
        """
        self._db.check_open()
        return self._db.index_names(table)

    def set_write_groups(self, groups: Iterable[Iterable[tuple[str, int]]]) -> None:
        """Event types whose writers must take turns, in groups (the types one event rule
        reads and derives): :meth:`lock_for_write` of a type waits for every transaction
        writing a type of its group. SQLite writers take turns anyway (one write
        transaction at a time); on a server the groups become advisory locks.

        >>> s = EventStore(None); s.set_write_groups([{("a", 1), ("r", 0)}])
        >>> with s.transaction(): s.lock_for_write([("a", 1)])
        """
        self._db.set_write_groups(groups)

    def lock_for_write(self, types: Iterable[tuple[str, int]]) -> None:
        """Inside a transaction: wait until no other transaction writes a type of the
        groups of ``types`` (:meth:`set_write_groups`), and hold that until the commit; a
        wait longer than ``busy_timeout`` is :class:`~slr_sql.errors.SLRBusy`."""
        self._db.lock_for_write(types)

    @property
    def dialect(self) -> Any:
        """The SQL dialect of the database (:mod:`slr_sql.store.dialect`)."""
        return self._db.dialect

    @property
    def python_functions(self) -> bool:
        """True when statements may call Python functions (SQLite's ``create_function``);
        on a server they cannot, and goals needing one run in the interpreter."""
        return self._db.python_functions

    @property
    def _conn(self) -> Any:  # the raw connection, for benchmarks comparing against it
        return self._db.conn

    # ------------------------------------------------------------------ lifecycle

    @_doc(Database.schema_version)
    def schema_version(self) -> int:
        return self._db.schema_version()

    @_doc(Database.stop_queries)
    def stop_queries(self) -> None:
        self._db.stop_queries()

    @_doc(Database.stop_query)
    def stop_query(self, stop: threading.Event) -> None:
        self._db.stop_query(stop)

    @_doc(Database.close)
    def close(self) -> None:
        self._db.close()

    @_doc(Database.open_reader)
    def open_reader(self) -> "ReadConnection | None":
        return self._db.open_reader()

    def __enter__(self) -> "EventStore":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    @property
    def closed(self) -> bool:
        return self._db.closed

    @contextmanager
    def transaction(self, wait: bool = True) -> Iterator["EventStore"]:
        """Run several store calls as one atomic unit (BEGIN IMMEDIATE ... COMMIT).

        Re-entrant: nested uses become savepoints, so an inner failure undoes only the inner
        part. The store lock is held for the whole transaction. ``wait=False``: a lock
        another connection holds is not waited for (SLRBusy at once), for work that may be
        left for later.

        >>> s = EventStore(None)
        >>> with s.transaction():
        ...     table = s.declare_type("seg", 2); program_id = s.append_program("seg.", None)
        >>> s.event_types(), s.program_sources()
        ({('seg', 2): 'seg'}, [('seg.', None)])
        """
        with self._db.transaction(wait):
            yield self

    @property
    def in_transaction(self) -> bool:
        return self._db.tx_depth > 0

    def after_commit(self, callback: Callable[[], None], always: bool = False) -> None:
        """Call ``callback()`` once the outermost transaction this thread is in committed
        and let go of the store's lock (never, should it or the nested one it was asked for
        in roll back; ``always``: once it ended, committed or not, for what a rollback does
        not take back, such as a clock's move); outside a transaction at once. The event pipeline runs the stages
        after the store of an add made inside a caller's transaction this way.

        >>> s = EventStore(None); heard = []
        >>> with s.transaction():
        ...     with s.transaction():
        ...         s.after_commit(lambda: heard.append("committed"))
        ...     heard.append("inside")
        >>> heard
        ['inside', 'committed']
        """
        self._db.after_commit(callback, always)

    @property
    def in_transaction_here(self) -> bool:
        """True when the calling thread is inside a transaction of this store; another
        thread's transaction does not count (``in_transaction`` counts any).

        >>> s = EventStore(None)
        >>> with s.transaction(): s.in_transaction_here
        True
        >>> s.in_transaction_here
        False
        """
        lock = self._db.lock
        if not lock.acquire(blocking=False):   # another thread holds the store
            return False
        try:
            return self._db.tx_depth > 0
        finally:
            lock.release()

    # ------------------------------------------------------------------ robots and fleets

    @property
    def robot(self) -> str | None:
        """The name of the robot this store belongs to (None: unnamed); new events are
        stored with it in their ``robot`` column."""
        return self._fleet.robot

    @_doc(Fleet.name)
    def name_robot(self, robot: str) -> None:
        self._fleet.name(robot)

    @_doc(Fleet.robots)
    def robots(self) -> list[str]:
        return self._fleet.robots()

    @_doc(Fleet.heads)
    def fleet_heads(self) -> dict[tuple[str, int], int]:
        return self._fleet.heads()

    @_doc(Fleet.counters)
    def fleet_counters(self) -> dict[tuple[str, int], int]:
        return self._fleet.counters()

    @_doc(Fleet.read_after)
    def fleet_read_after(self, name: str, arity: int, position: int, limit: int) -> list[tuple]:
        return self._fleet.read_after(name, arity, position, limit)

    @_doc(Fleet.backlog)
    def fleet_backlog(self, name: str, arity: int, position: int) -> tuple[int, float | None]:
        return self._fleet.backlog(name, arity, position)

    @_doc(Fleet.positions)
    def fleet_positions(self, robot: str) -> dict[tuple[str, int], int]:
        return self._fleet.positions(robot)

    @_doc(Fleet.column_values)
    def fleet_column_values(self, arity: int, rows: list[tuple], robot: str) -> list[tuple]:
        return self._fleet.column_values(arity, rows, robot)

    @_doc(Fleet.receive)
    def fleet_receive(self, robot: str, name: str, arity: int, rows: list[tuple],
                      store_events: Any = None, columns: list[tuple] | None = None,
                      resync: bool = False, take_retired: Any = None) -> int:
        return self._fleet.receive(robot, name, arity, rows, store_events, columns, resync,
                                   take_retired)

    @_doc(Fleet.record_contact)
    def fleet_record_contact(self, robot: str, pending: int, head_arrival: float | None) -> None:
        self._fleet.record_contact(robot, pending, head_arrival)

    @_doc(Fleet.contacts)
    def fleet_contacts(self) -> list[dict[str, Any]]:
        return self._fleet.contacts()

    @_doc(Fleet.retired)
    def fleet_retired(self, hold: str | None = None) -> dict[str, float]:
        return self._fleet.retired(hold)

    @_doc(Fleet.retire)
    def fleet_retire(self, robot: str, at: float) -> bool:
        return self._fleet.retire(robot, at)

    @_doc(Fleet.reinstate)
    def fleet_reinstate(self, robot: str) -> bool:
        return self._fleet.reinstate(robot)

    # ------------------------------------------------------------------ event types

    @_doc(EventTables.declare_type)
    def declare_type(self, name: str, arity: int, start_order: bool = False) -> str:
        return self._tables.declare_type(name, arity, start_order)

    def ensure_start_order(self, name: str, arity: int) -> bool:
        """Build the start-ordered indexes of name/arity if it lacks them (see
        :meth:`declare_type`); whether they exist now. False also when the type
        has no table. See :meth:`EventTables.ensure_start_order`.

        >>> s = EventStore(None); s.declare_type("c", 0)
        'c'
        >>> s.ensure_start_order("c", 0), s.ensure_start_order("d", 0)
        (True, False)
        """
        # known built: no lock (a compiled statement names no index, so a belief a
        # rollback in another thread is taking back at this moment costs at most speed)
        known = self._tables.types.get((name, arity))
        if known is not None and known.start_order:
            return True
        with self._db.lock:
            self._db.check_open()
            event_type = self._tables.lookup(name, arity)
            return event_type is not None and self._tables.ensure_start_order(event_type)

    @property
    def start_order_builds_undone(self) -> int:
        """How many rollbacks may have taken back a start-ordered index built inside the
        transaction (who prepared statements since asks again when it moved)."""
        return self._tables.builds_undone

    def prepare_start_order(self, sql: str, types: Iterable[tuple[str, int]],
                            build_if_unsure: bool = True) -> None:
        """Before a statement first runs: build the start-ordered indexes it would use of
        the event types ``types`` (those of them whose tables it names) -- the ones SQLite's
        planner would take (:meth:`EventTables.start_orders_wanted`); where the backend
        cannot say (PostgreSQL), all of them if ``build_if_unsure``, else those whose start
        time it compares (:func:`~slr_sql.store.tables.start_compared`).

        >>> s = EventStore(None); _ = s.declare_type("b", 1)
        >>> s.prepare_start_order('SELECT seq FROM "b" WHERE arg1 = :k AND t_end > :t', [("b", 1)])
        >>> len(s.index_names("b"))
        2
        >>> s.prepare_start_order('SELECT seq FROM "b" WHERE arg1 = :k AND t_start > :t', [("b", 1)])
        >>> len(s.index_names("b"))
        4
        """
        known = self._tables.types
        types = [key for key in types if key in known and not known[key].start_order
                 and known[key].quoted in sql]
        if not types:
            return
        with self._db.lock:
            self._db.check_open()
            wanted = self._tables.start_orders_wanted(sql)
        if wanted is None:
            wanted = set(types) if build_if_unsure else {
                key for key in types if start_compared(sql, known[key].quoted)}
        for key in types:
            if key in wanted:
                self.ensure_start_order(*key)

    @property
    def max_event_arity(self) -> int:
        """The most data arguments an event may have (SQLite's column limit less the
        ``seq``, ``t_start``, ``t_end`` and ``arrival`` columns)."""
        return self._tables.max_arity

    @_doc(EventTables.event_types)
    def event_types(self) -> dict[tuple[str, int], str]:
        return self._tables.event_types()

    @_doc(EventTables.declared_types)
    def declared_types(self) -> set[tuple[str, int]]:
        return self._tables.declared_types()

    @_doc(EventTables.table_for)
    def table_for(self, name: str, arity: int) -> str | None:
        return self._tables.table_for(name, arity)

    @_doc(EventTables.event_table_sql)
    def event_table_sql(self, name: str, arity: int) -> str | None:
        return self._tables.event_table_sql(name, arity)

    # ------------------------------------------------------------------ adding events

    @_doc(EventWriter.add_events)
    def add_events(self, events: Iterable[Event], atomic: bool = False, *,
                   join: bool = False) -> list[EventRejected]:
        return self._writer.add_events(events, atomic, join=join)

    @_doc(EventWriter.add_event)
    def add_event(self, name: str, args: Iterable[Any], start: float, end: float) -> None:
        self._writer.add_event(name, args, start, end)

    @_doc(EventWriter.record_now)
    def record_now(self, now: float) -> None:
        self._writer.record_now(now)

    @_doc(EventWriter.recorded_now)
    def recorded_now(self) -> float:
        return self._writer.recorded_now()

    # ------------------------------------------------------------------ reading events

    @_doc(EventReader.scan)
    def scan(self, name: str, arity: int, bound: dict[int, Any] | None = None,
             end_le: float | None = None, robot: str | None = None) -> Iterator[Row]:
        return self._reader.scan(name, arity, bound, end_le, robot)

    @_doc(EventReader.prev_candidates)
    def prev_candidates(self, name: str, arity: int, bound: dict[int, Any] | None,
                        t: float, start_ge: float | None = None,
                        robot: str | None = None) -> Iterator[Row]:
        return self._reader.prev_candidates(name, arity, bound, t, start_ge, robot)

    @_doc(EventReader.rows_at_end)
    def rows_at_end(self, name: str, arity: int, bound: dict[int, Any] | None, end: float,
                    start_ge: float | None = None, end_le: float | None = None,
                    robot: str | None = None) -> Iterator[Row]:
        return self._reader.rows_at_end(name, arity, bound, end, start_ge, end_le, robot)

    @_doc(EventReader.next_candidates)
    def next_candidates(self, name: str, arity: int, bound: dict[int, Any] | None,
                        a: float, b: float, robot: str | None = None) -> Iterator[Row]:
        return self._reader.next_candidates(name, arity, bound, a, b, robot)

    @_doc(EventReader.rows_at_start)
    def rows_at_start(self, name: str, arity: int, bound: dict[int, Any] | None,
                      start: float, b: float, robot: str | None = None) -> Iterator[Row]:
        return self._reader.rows_at_start(name, arity, bound, start, b, robot)

    @_doc(EventReader.lookup_sql)
    def lookup_sql(self, kind: str, name: str, arity: int,
                   bound: dict[int, Any] | None = None, *, start_ge: bool = False,
                   end_le: bool = False, robot: bool = False) -> str | None:
        return self._reader.lookup_sql(kind, name, arity, bound, start_ge=start_ge,
                                       end_le=end_le, robot=robot)

    @_doc(EventReader.latest_at_or_before)
    def latest_at_or_before(self, name: str, arity: int, bound: dict[int, Any], t: float,
                            point: bool) -> list[Row] | None:
        return self._reader.latest_at_or_before(name, arity, bound, t, point)

    @_doc(EventReader.latest_rows)
    def latest_rows(self, name: str, arity: int, positions: tuple[int, ...], values: list,
                    t: float, point: bool) -> list[tuple]:
        return self._reader.latest_rows(name, arity, positions, values, t, point)

    @_doc(EventReader.bracket)
    def bracket(self, name: str, arity: int, bound: dict[int, Any], t: float,
                longest: float = math.inf) -> tuple[Row | None, Row | None] | None:
        return self._reader.bracket(name, arity, bound, t, longest)

    @_doc(EventReader.distinct_pairs)
    def distinct_pairs(self, name: str, arity: int, after_seq: int = 0
                       ) -> tuple[list[tuple[Any, Any, float]], int]:
        return self._reader.distinct_pairs(name, arity, after_seq)

    @_doc(EventReader.null_arguments)
    def null_arguments(self, types: Iterable[tuple[str, int]] | None = None,
                       every: bool = False) -> list[tuple[str, int, str, int, int]]:
        return self._reader.null_arguments(types, every)

    @_doc(EventReader.max_seq)
    def max_seq(self, name: str, arity: int) -> int:
        return self._reader.max_seq(name, arity)

    @_doc(EventReader.raw_rows)
    def raw_rows(self, name: str, arity: int, *, after_seq: int | None = None,
                 end_from: float | None = None, end_to: float | None = None,
                 limit: int | None = None, after_key: tuple | None = None) -> list[tuple]:
        return self._reader.raw_rows(name, arity, after_seq=after_seq, end_from=end_from,
                                     end_to=end_to, limit=limit, after_key=after_key)

    @_doc(EventReader.raw_page)
    def raw_page(self, name: str, arity: int, *, rows: int, max_bytes: int,
                 after_seq: int | None = None, end_from: float | None = None,
                 end_to: float | None = None, after_key: tuple | None = None) -> RawPage:
        return self._reader.raw_page(name, arity, rows=rows, max_bytes=max_bytes,
                                     after_seq=after_seq, end_from=end_from, end_to=end_to,
                                     after_key=after_key)

    @_doc(EventReader.count)
    def count(self, name: str, arity: int) -> int:
        return self._reader.count(name, arity)

    @_doc(EventReader.max_end)
    def max_end(self, name: str, arity: int) -> float | None:
        return self._reader.max_end(name, arity)

    # ------------------------------------------------------------------ program and meta keys

    @_doc(Catalog.append_program)
    def append_program(self, source: str, filename: str | None = None,
                       name: str = "main") -> int:
        return self._catalog.append_program(source, filename, name)

    @_doc(Catalog.replace_named_program)
    def replace_named_program(self, name: str, source: str, filename: str | None = None) -> int:
        return self._catalog.replace_named_program(name, source, filename)

    @_doc(Catalog.delete_program)
    def delete_program(self, name: str) -> int:
        return self._catalog.delete_program(name)

    @_doc(Catalog.program_texts)
    def program_texts(self) -> list[ProgramText]:
        return self._catalog.program_texts()

    @_doc(Catalog.program_version)
    def program_version(self) -> int:
        return self._catalog.program_version()

    @_doc(Catalog.versions)
    def versions(self) -> tuple[int, int]:
        return self._catalog.versions()

    @_doc(Database.data_version)
    def data_version(self) -> int:
        return self._catalog.data_version()

    @_doc(Catalog.owe_change_check)
    def owe_change_check(self, program_version: int) -> tuple[Any, Any] | None:
        return self._catalog.owe_change_check(program_version)

    @_doc(Catalog.settle_change_check)
    def settle_change_check(self, owed: tuple[Any, Any]) -> tuple[int, int, int] | None:
        return self._catalog.settle_change_check(owed)

    @_doc(Database.others_version)
    def others_version(self) -> int:
        return self._db.others_version()

    @_doc(Catalog.program_sources)
    def program_sources(self) -> list[tuple[str, str | None]]:
        return self._catalog.program_sources()

    @_doc(Catalog.replace_program)
    def replace_program(self, sources: Iterable[tuple[str, str | None]]) -> None:
        self._catalog.replace_program(sources)

    @_doc(Catalog.meta_get)
    def meta_get(self, key: str, default: Any = None) -> Any:
        return self._catalog.meta_get(key, default)

    @_doc(Catalog.meta_set)
    def meta_set(self, key: str, value: Any) -> None:
        self._catalog.meta_set(key, value)

    @_doc(Catalog.meta_raise)
    def meta_raise(self, key: str, value: float) -> float:
        return self._catalog.meta_raise(key, value)

    @_doc(Catalog.meta_delete)
    def meta_delete(self, key: str) -> None:
        self._catalog.meta_delete(key)

    @_doc(Catalog.meta_items)
    def meta_items(self, prefix: str = "") -> dict[str, Any]:
        return self._catalog.meta_items(prefix)

    # ------------------------------------------------------------------ fact tables and views

    fact_table_name = staticmethod(Catalog.fact_table_name)
    view_name = staticmethod(Catalog.view_name)

    @_doc(Catalog.replace_fact_tables)
    def replace_fact_tables(self, tables: dict[tuple[str, int], list[tuple]],
                            version: int | None = None) -> dict:
        return self._catalog.replace_fact_tables(tables, version)

    @_doc(Catalog.fact_tables_for)
    def fact_tables_for(self, keys: Iterable[tuple[str, int]]) -> dict:
        return self._catalog.fact_tables_for(keys)

    @_doc(Catalog.facts_version)
    def facts_version(self) -> int:
        return self._catalog.facts_version()

    @_doc(Catalog.create_rule_tables)
    def create_rule_tables(self, prov: str, width: int, arity: int,
                           used: str | None = None) -> None:
        self._catalog.create_rule_tables(prov, width, arity, used)

    @_doc(Catalog.create_journal)
    def create_journal(self, table: str, arity: int, journal: str, trigger: str) -> None:
        self._catalog.create_journal(table, arity, journal, trigger)

    @_doc(Catalog.drop_journal)
    def drop_journal(self, table: str, journal: str, trigger: str) -> None:
        self._catalog.drop_journal(table, journal, trigger)

    def listen(self, callback: Callable[[], Any]) -> Callable[[], None] | None:
        """Call ``callback()`` whenever another connection stored events in a journal
        (:meth:`create_journal`), from a thread of the store's own; returns the function
        that stops it. None on SQLite, which cannot tell: its readers poll.

        >>> EventStore(None).listen(lambda: None) is None
        True
        """
        listen = getattr(self._db, "listen", None)
        return None if listen is None else listen(callback)

    def journal_reader(self, own_connection: bool) -> JournalReader | None:
        """The reading statements of subscription delivery: on a connection of their own
        (``own_connection``; None in memory, where there can be none), whose reads never
        wait for a writer's transaction, or on the store's connection (inside a
        transaction not committed yet, they see its rows).

        >>> EventStore(None).journal_reader(own_connection=True) is None
        True
        """
        if not own_connection:
            db = self._db

            def execute(sql: str, params: tuple) -> list[tuple]:
                # as the reader's own connection says them: a failure on the hub's thread
                # is an SLRError named after it (a journal another connection dropped, a
                # damaged file, the file deleted), never a raw sqlite3 error nor a server's
                # PgStatementError (the server's conditions its connection says already)
                try:
                    return db.execute(sql, params)
                except DatabaseError as exc:
                    raise db.read_error(exc) from None

            return JournalReader(execute, qualified=db.qualified)
        reader = self._db.open_reader()
        return None if reader is None else \
            JournalReader(reader.execute, reader.close, self._db.qualified)

    @_doc(SubscriptionTables.subscription_wanted)
    def subscription_wanted(self, name: str, arity: int) -> bool:
        return self._subscriptions.subscription_wanted(name, arity)

    @_doc(SubscriptionTables.subscription_record)
    def subscription_record(self, sub_id: str) -> SubscriptionRecord | None:
        return self._subscriptions.subscription_record(sub_id)

    @_doc(SubscriptionTables.insert_subscription)
    def insert_subscription(self, sub_id: str, durable: bool, pattern: str,
                            where_goal: str | None, since: float, until: float | None,
                            type_name: str, type_arity: int, history_top: int,
                            live_start: int, owner: str, lease_until: float,
                            created_at: float) -> None:
        self._subscriptions.insert_subscription(
            sub_id, durable, pattern, where_goal, since, until, type_name, type_arity,
            history_top, live_start, owner, lease_until, created_at)

    @_doc(SubscriptionTables.claim_subscription)
    def claim_subscription(self, sub_id: str, owner: str, lease_until: float) -> None:
        self._subscriptions.claim_subscription(sub_id, owner, lease_until)

    @_doc(SubscriptionTables.delete_subscription)
    def delete_subscription(self, sub_id: str, owner: str | None = None) -> bool:
        return self._subscriptions.delete_subscription(sub_id, owner)

    @_doc(SubscriptionTables.write_subscription_position)
    def write_subscription_position(self, sub_id: str, owner: str, history_done: int,
                                    history_pos: int, live_pos: int, finished: bool,
                                    lease_until: float | None,
                                    new_owner: str | None) -> None:
        self._subscriptions.write_subscription_position(
            sub_id, owner, history_done, history_pos, live_pos, finished, lease_until,
            new_owner)

    @_doc(SubscriptionTables.renew_subscriptions)
    def renew_subscriptions(self, owner: str, lease_until: float) -> set[str]:
        return self._subscriptions.renew_subscriptions(owner, lease_until)

    @_doc(SubscriptionTables.expire_subscriptions)
    def expire_subscriptions(self, now_wall: float) -> None:
        self._subscriptions.expire_subscriptions(now_wall)

    @_doc(SubscriptionTables.live_positions)
    def live_positions(self, name: str, arity: int) -> list[tuple[str, str | None, int]]:
        return self._subscriptions.live_positions(name, arity)

    @_doc(SubscriptionTables.trim_journal)
    def trim_journal(self, journal: str, through_jid: int) -> None:
        self._subscriptions.trim_journal(journal, through_jid)

    @_doc(SubscriptionTables.subscription_rows)
    def subscription_rows(self) -> list[dict[str, Any]]:
        return self._subscriptions.subscription_rows()

    @_doc(SubscriptionTables.journal_start)
    def journal_start(self, table: str, journal: str) -> tuple[int, int]:
        return self._subscriptions.journal_start(table, journal)

    @property
    def notify_channel(self) -> str | None:
        """The channel a server store notifies when events reach a journal (LISTEN to it),
        None where there is none (SQLite: poll)."""
        return getattr(self._db, "notify_channel", None)

    @property
    def connect_info(self) -> str | None:
        """The connection string of a server store (for a second, listening connection)."""
        return getattr(self._db, "conninfo", None)

    @_doc(Catalog.fact_view_select)
    def fact_view_select(self, table: str, arity: int) -> str:
        return self._catalog.fact_view_select(table, arity)

    @_doc(Catalog.rule_matches)
    def rule_matches(self, prov: str, width: int) -> list[tuple]:
        return self._catalog.rule_matches(prov, width)

    @_doc(Catalog.replace_views)
    def replace_views(self, views: dict[str, str]) -> list[str]:
        made = self._catalog.replace_views(views)
        # (read by other programs, which cannot build what their plans would use)
        for select in views.values():
            self.prepare_start_order(select, list(self._tables.types), build_if_unsure=False)
        return made

    # ------------------------------------------------------------------ buffers

    @_doc(BufferTables.buffer_rows)
    def buffer_rows(self, active_only: bool = True) -> list[dict[str, Any]]:
        return self._buffers.buffer_rows(active_only)

    @_doc(BufferTables.has_active_buffer)
    def has_active_buffer(self, kind: str) -> bool:
        return self._buffers.has_active_buffer(kind)

    @_doc(BufferTables.insert_buffer)
    def insert_buffer(self, kind: str, source: str, pattern_text: str, type_name: str,
                      type_arity: int, amount: float | None, t1: float | None,
                      t2: float | None, origin: str) -> int:
        return self._buffers.insert_buffer(kind, source, pattern_text, type_name, type_arity,
                                           amount, t1, t2, origin)

    @_doc(BufferTables.mark_buffer_removed)
    def mark_buffer_removed(self, buffer_id: int) -> None:
        self._buffers.mark_buffer_removed(buffer_id)

    @_doc(BufferTables.count_buffer)
    def count_buffer(self, buffer_id: int, pruned: int = 0, dropped: int = 0) -> None:
        self._buffers.count_buffer(buffer_id, pruned, dropped)

    @_doc(BufferTables.set_buffer_cutoff)
    def set_buffer_cutoff(self, buffer_id: int, cutoff: float) -> None:
        self._buffers.set_buffer_cutoff(buffer_id, cutoff)

    @_doc(BufferTables.buffer_objects)
    def buffer_objects(self, buffer_id: int) -> dict[str, str]:
        return self._buffers.buffer_objects(buffer_id)

    @_doc(BufferTables.buffer_statements)
    def buffer_statements(self, plan: BufferPlan, table: str) -> dict[str, str]:
        return self._buffers.buffer_statements(plan, table)

    @_doc(BufferTables.install_buffer_objects)
    def install_buffer_objects(self, plan: BufferPlan, table: str) -> bool:
        return self._buffers.install_buffer_objects(plan, table)

    @_doc(BufferTables.drop_buffer_objects)
    def drop_buffer_objects(self, buffer_id: int) -> None:
        self._buffers.drop_buffer_objects(buffer_id)

    @_doc(BufferTables.apply_buffer)
    def apply_buffer(self, plan: BufferPlan, table: str, now: float) -> int:
        return self._buffers.apply_buffer(plan, table, now)

    # ------------------------------------------------------------------ space

    @_doc(Space.table_rows)
    def table_rows(self) -> dict[tuple[str, int], int]:
        return self._space.table_rows()

    @_doc(Space.space_stats)
    def space_stats(self) -> dict[str, Any]:
        return self._space.space_stats()

    @_doc(Space.reclaim_space)
    def reclaim_space(self, min_free_pages: int = 2048, min_free_fraction: float = 0.25,
                      keep_fraction: float = 0.10, wait: bool = True) -> int:
        return self._space.reclaim_space(min_free_pages, min_free_fraction, keep_fraction,
                                         wait)

    @_doc(Space.limit_wal)
    def limit_wal(self, max_bytes: int = 64 * 1024 * 1024) -> None:
        self._space.limit_wal(max_bytes)

    # ------------------------------------------------------------------ raw and compiled SQL

    @_doc(Database.sql)
    def sql(self, query: str, params: Iterable[Any] = (), write: bool = False,
            timeout: float | None = None) -> tuple[list[str], list[tuple]]:
        return self._db.sql(query, params, write, timeout)

    @_doc(Database.tables_to_write)
    def tables_to_write(self, query: str, params: Iterable[Any] = ()) -> set[str] | None:
        return self._db.tables_to_write(query, params)

    @_doc(Database.sql_write)
    def sql_write(self, query: str, params: Iterable[Any] = (), timeout: float | None = None
                  ) -> tuple[list[str], list[tuple], set[str]]:
        return self._db.sql_write(query, params, timeout)

    @_doc(Database.execute)
    def execute(self, sql: str, params: Iterable[Any] = ()) -> list[tuple]:
        return self._db.execute(sql, params)

    @_doc(Database.executemany)
    def executemany(self, sql: str, rows: Iterable[Iterable[Any]]) -> None:
        self._db.executemany(sql, rows)

    @_doc(Database.executescript)
    def executescript(self, script: str) -> None:
        self._db.executescript(script)

    @_doc(Database.changes)
    def changes(self) -> int:
        return self._db.changes()

    @_doc(Database.query_plan)
    def query_plan(self, sql: str) -> list[str]:
        return self._db.query_plan(sql)

    @property
    def statement_deadline(self) -> float | None:
        """The deadline (``time.monotonic()``) of the compiled statement running now on
        this store, None when none runs or it has none: a Python function called from the
        statement keeps to it.

        >>> EventStore(None).statement_deadline is None
        True
        """
        return self._db.deadline

    @_doc(Database.install_functions)
    def install_functions(self, functions: SqlFunctions) -> None:
        self._db.install_functions(functions)

    @_doc(Database.run_compiled)
    def run_compiled(self, sql: str, params: dict, limit: int | None = None,
                     deadline: float | None = None, may_fall_back: bool = False,
                     instructions: int | None = None,
                     stop: threading.Event | None = None) -> list[tuple]:
        return self._db.run_compiled(sql, params, limit, deadline, may_fall_back,
                                     instructions, stop)

    @_doc(Database.run_compiled_many)
    def run_compiled_many(self, sql: str, rows: list) -> None:
        self._db.run_compiled_many(sql, rows)

    @_doc(Database.run_compiled_batch)
    def run_compiled_batch(self, statements: list) -> list[list[tuple]]:
        return self._db.run_compiled_batch(statements)
