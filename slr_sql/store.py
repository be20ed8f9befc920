"""The persistent event store: one SQLite file (or an in-memory database).

This is the only module of slr_sql that talks to SQLite. Layout of the file:

* ``slr_meta``, ``slr_program``, ``slr_event_types`` (and later ``slr_*`` tables): internal
  state, created by the numbered migrations in ``migrations/`` (tracked in
  ``PRAGMA user_version``).
* One table per event type name/arity, named after the event when that is a plain SQL
  identifier (``seg``), otherwise a sanitized unique name (``seg__3``, ``ev_my_event``); the
  mapping is ``slr_event_types``. Columns::

      seq      INTEGER PRIMARY KEY   -- arrival sequence (the rowid)
      arg1..N                        -- data arguments, encoded by slr_sql.encoding
      t_start  REAL NOT NULL
      t_end    REAL NOT NULL
      arrival  REAL NOT NULL         -- store clock time of the add that stored the event

  Indexes ``(t_end, t_start)`` and ``(t_start, t_end)``, plus ``(arg1, t_end, t_start)`` and
  ``(arg1, t_start, t_end)`` when there is a first argument. Every index entry ends with the
  rowid, so *store order* (``ORDER BY t_end, t_start, seq``) and the reverse order prev needs
  are read straight from an index, never sorted.

Durability: file databases use ``journal_mode=WAL`` with ``synchronous=FULL``: when
:meth:`EventStore.add_events` returns, its transaction is in the WAL *and* fsynced, so the
events survive a process kill and a power loss. (``synchronous=NORMAL`` would survive a kill
but may lose the last transactions on power loss; pass ``synchronous="NORMAL"`` to trade that
for speed.) Values are always bound parameters; identifiers are always quoted.

Threads: one connection, serialized by ``EventStore.lock`` (an ``RLock``); a
:meth:`EventStore.transaction` holds the lock until it ends.

>>> store = EventStore(None)
>>> store.add_events([("seg", ("cup1", 1), 2.0, 2.0)])
[]
>>> [row[:3] for row in store.scan("seg", 2, {})]
[((Atom('cup1'), 1), 2.0, 2.0)]
"""
from __future__ import annotations

import importlib.resources
import json
import math
import re
import sqlite3
import threading
import time
import weakref
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterable, Iterator

from .encoding import Unencodable, decode, encode
from .errors import EventRejected, SLRError
from .terms import Atom, String, Struct, Var

__all__ = ["EventStore", "Event", "Row", "CACHE_SIZE_KIB", "quote_identifier", "format_event",
           "migration_scripts", "split_sql_script", "DatabaseError"]

# What a failed statement raises (callers outside the store catch this, not sqlite3's).
DatabaseError = sqlite3.Error

Event = tuple  # (name: str, args: tuple[term, ...], start: float, end: float)
Row = tuple    # (args: tuple[term, ...], start: float, end: float, seq: int)

_INF = math.inf
_NEG_INF = -math.inf
_INSERT_CHUNK = 20_000
CACHE_SIZE_KIB = 65536  # PRAGMA cache_size of the store's connection (64 MiB)  # rows per executemany: bounds memory on huge batches

_SAFE_IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
_RESERVED_PREFIXES = ("slr_", "sqlite_")
# SQLite keywords: an event named like one gets a sanitized table name, so that
# ``SELECT * FROM <table>`` works without quoting for every table we create.
_SQL_KEYWORDS = frozenset("""
abort action add after all alter always analyze and as asc attach autoincrement before begin
between by cascade case cast check collate column commit conflict constraint create cross
current current_date current_time current_timestamp database default deferrable deferred
delete desc detach distinct do drop each else end escape except exclude exclusive exists
explain fail filter first following for foreign from full generated glob group groups having
if ignore immediate in index indexed initially inner insert instead intersect into is isnull
join key last left like limit match materialized natural no not nothing notnull null nulls of
offset on or order others outer over partition plan pragma preceding primary query raise range
recursive references regexp reindex release rename replace restrict returning right rollback
row rows savepoint select set table temp temporary then ties to transaction trigger unbounded
union unique update using vacuum values view virtual when where window with without
rowid oid _rowid_
""".split())


def quote_identifier(name: str) -> str:
    """Quote an SQL identifier (``"`` doubled).

    >>> print(quote_identifier('a"b'))
    "a""b"
    """
    return '"' + name.replace('"', '""') + '"'


class _EventType:
    """What the store knows about one event type (cached per name/arity)."""

    __slots__ = ("name", "arity", "table", "declared", "insert_sql", "quoted", "columns",
                 "index_end", "index_start", "index_arg1_end", "index_arg1_start")

    def __init__(self, name: str, arity: int, table: str, declared: bool):
        self.name = name
        self.arity = arity
        self.table = table
        self.declared = declared
        self.quoted = quote_identifier(table)
        arg_columns = [f"arg{i}" for i in range(1, arity + 1)]
        self.columns = ", ".join(arg_columns + ["t_start", "t_end", "seq"])
        insert_columns = arg_columns + ["t_start", "t_end", "arrival"]
        self.insert_sql = (f"INSERT INTO {self.quoted} ({', '.join(insert_columns)}) "
                           f"VALUES ({', '.join('?' * len(insert_columns))})")
        self.index_end = quote_identifier(f"slr_ix__{table}__end")
        self.index_start = quote_identifier(f"slr_ix__{table}__start")
        self.index_arg1_end = quote_identifier(f"slr_ix__{table}__a1_end")
        self.index_arg1_start = quote_identifier(f"slr_ix__{table}__a1_start")


def _index_names(table: str) -> list[str]:
    return [f"slr_ix__{table}__{suffix}" for suffix in ("end", "start", "a1_end", "a1_start")]


class _BadEvent(Exception):
    """Internal: why an event is rejected (turned into EventRejected with the event text)."""


class _WallClock:
    def now(self) -> float:
        return time.time()


def _migrations_dir() -> Any:
    """The migrations folder: the installed ``slr_sql.migrations`` package, or the source
    checkout's top-level ``migrations/``."""
    try:
        folder = importlib.resources.files("slr_sql.migrations")
        if any(entry.name.endswith(".sql") for entry in folder.iterdir()):
            return folder
    except Exception:  # not installed as a package: running from a source checkout
        pass
    return Path(__file__).resolve().parent.parent / "migrations"


def migration_scripts() -> list[tuple[int, str, str]]:
    """``(number, file name, sql text)`` of every ``NNNN_name.sql`` migration, in order.

    >>> migration_scripts()[0][:2]
    (1, '0001_initial.sql')
    """
    scripts = []
    for entry in _migrations_dir().iterdir():
        match = re.match(r"(\d+)_.*\.sql\Z", entry.name)
        if match:
            scripts.append((int(match.group(1)), entry.name, entry.read_text(encoding="utf-8")))
    scripts.sort()
    return scripts


def split_sql_script(script: str) -> list[str]:
    """Split SQL text into complete statements (trigger bodies stay whole).

    >>> split_sql_script("CREATE TABLE a(x); CREATE TABLE b(y);")
    ['CREATE TABLE a(x);', 'CREATE TABLE b(y);']
    """
    statements = []
    buffer = ""
    pieces = script.split(";")
    for number, piece in enumerate(pieces):
        buffer += piece
        if number < len(pieces) - 1:
            buffer += ";"
            # a ';' inside a string or a trigger body does not end the statement
            if sqlite3.complete_statement(buffer):
                if _has_sql(buffer):
                    statements.append(buffer.strip())
                buffer = ""
    if _has_sql(buffer):  # a last statement without its ';'
        statements.append(buffer.strip())
    return statements


def _has_sql(text: str) -> bool:
    stripped = re.sub(r"--[^\n]*|/\*.*?\*/", "", text, flags=re.S)
    return stripped.strip(" \t\r\n;") != ""


def _format_term(term: Any) -> str:
    try:
        from .printer import format_term  # the project's printer, when available
        return format_term(term)
    except Exception:
        return _simple_format(term)


def _simple_format(term: Any) -> str:
    tt = type(term)
    if tt is Var:
        return str(term)
    if tt is String:
        return json.dumps(str(term), ensure_ascii=False)
    if isinstance(term, str):
        if re.fullmatch(r"[a-z][A-Za-z0-9_]*|\[\]", term):
            return str(term)
        return "'" + term.replace("\\", "\\\\").replace("'", "\\'") + "'"
    if tt is Struct:
        if term.name == "." and len(term.args) == 2:
            items, tail = [], term
            while type(tail) is Struct and tail.name == "." and len(tail.args) == 2:
                items.append(_simple_format(tail.args[0]))
                tail = tail.args[1]
                while type(tail) is Var and tail.ref is not None:
                    tail = tail.ref
            inner = ",".join(items)
            return f"[{inner}]" if tail == "[]" else f"[{inner}|{_simple_format(tail)}]"
        return f"{_simple_format(term.name)}({','.join(_simple_format(a) for a in term.args)})"
    if isinstance(term, (list, tuple)):
        return "[" + ",".join(_simple_format(a) for a in term) + "]"
    return repr(term)


def format_event(name: Any, args: Any, start: Any, end: Any) -> str:
    """Event text for messages: ``seg(X,1)^2.0`` or ``seg(a)^[1.0,2.0]``.

    >>> format_event("seg", (Atom("a"), 1), 2.0, 2.0)
    'seg(a,1)^2.0'
    """
    try:
        head = _simple_format(Atom(name)) if not args else _format_term(Struct(name, tuple(args)))
    except Exception:
        head = f"{name}{tuple(args)!r}"
    if start == end:
        return f"{head}^{start!r}"
    return f"{head}^[{start!r},{end!r}]"


def _event_time(value: Any) -> float:
    if type(value) is float:
        return value
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        try:
            return float(value)
        except OverflowError:
            raise _BadEvent("event times must be finite") from None
    raise _BadEvent(f"event times must be numbers (got {value!r})")


def _check_times(start: Any, end: Any) -> tuple[float, float]:
    start = _event_time(start)
    end = _event_time(end)
    if not (math.isfinite(start) and math.isfinite(end)):
        raise _BadEvent("event times must be finite (not inf or NaN)")
    if start > end:
        raise _BadEvent(f"start time {start!r} is after end time {end!r}")
    return start, end


def _reason(exc: Exception) -> str:
    if isinstance(exc, Unencodable):
        if "unbound" in exc.reason:
            return f"event arguments must be ground ({exc.reason})"
        if "NaN" in exc.reason:
            return "event arguments must not contain NaN"
        return f"event argument cannot be stored: {exc.reason}"
    return str(exc)


class EventStore:
    """Events, program and state of one knowledge base, in one SQLite database.

    ``path`` None or ``":memory:"`` gives an in-memory store. ``clock`` is any object with
    ``now() -> float`` (arrival times); the default is the wall clock.

    >>> store = EventStore(":memory:")
    >>> store.add_event("obj", ("cup1", "red"), 1.0, 1.0); store.count("obj", 2)
    1
    >>> store.close()
    """

    def __init__(self, path: str | Path | None = None, clock: Any = None, *,
                 synchronous: str = "FULL"):
        self.path = None if path in (None, ":memory:") else str(path)
        self.clock = clock if clock is not None else _WallClock()
        self.lock = threading.RLock()
        self._tx_depth = 0
        self._closed = False
        self._types: dict[tuple[str, int], _EventType] = {}
        self._declared_arities: dict[str, set[int]] = {}
        self._sql_cache: dict[tuple, str] = {}
        self._open_cursors: weakref.WeakSet = weakref.WeakSet()
        # buffers (issue 4): called as hook(name, arity, table) inside the transaction that
        # creates a new event type's table (slr_sql.buffers installs its triggers there)
        self.table_created_hooks: list = []
        self._conn = sqlite3.connect(self.path or ":memory:", check_same_thread=False,
                                     isolation_level=None, timeout=30.0,
                                     cached_statements=512)
        if synchronous.upper() not in ("OFF", "NORMAL", "FULL", "EXTRA"):
            raise ValueError(f"synchronous must be OFF, NORMAL, FULL or EXTRA, not {synchronous!r}")
        conn = self._conn
        # auto_vacuum must be chosen before the first table exists; it is a no-op afterwards.
        conn.execute("PRAGMA auto_vacuum=INCREMENTAL")
        if self.path is not None:
            conn.execute("PRAGMA journal_mode=WAL")
        conn.execute(f"PRAGMA synchronous={synchronous.upper()}")
        conn.execute("PRAGMA foreign_keys=ON")
        # Every event type has four indexes; SQLite's default 2 MiB page cache makes large
        # ingests spill and re-read index pages constantly. The cache grows only as used.
        conn.execute(f"PRAGMA cache_size=-{CACHE_SIZE_KIB}")
        self._migrate()
        self._reload_types()

    # ------------------------------------------------------------------ lifecycle

    def _migrate(self) -> None:
        conn = self._conn
        scripts = migration_scripts()
        latest = scripts[-1][0] if scripts else 0
        current = conn.execute("PRAGMA user_version").fetchone()[0]
        if current > latest:
            raise SLRError(f"{self.path}: database schema version {current} is newer than this "
                           f"slr_sql supports ({latest}); upgrade slr_sql")
        for number, filename, text in scripts:
            if number <= current:
                continue
            conn.execute("BEGIN IMMEDIATE")
            try:
                # another process may have migrated between our check and the lock
                if conn.execute("PRAGMA user_version").fetchone()[0] >= number:
                    conn.execute("COMMIT")
                    continue
                for statement in split_sql_script(text):
                    conn.execute(statement)
                conn.execute(f"PRAGMA user_version = {int(number)}")
                conn.execute("COMMIT")
            except BaseException:
                conn.execute("ROLLBACK")
                raise
            current = number

    def schema_version(self) -> int:
        """The number of the last migration applied (``PRAGMA user_version``).

        >>> EventStore(None).schema_version() >= 1
        True
        """
        with self.lock:
            return self._conn.execute("PRAGMA user_version").fetchone()[0]

    def close(self) -> None:
        """Checkpoint the WAL into the main file and close. Idempotent.

        >>> s = EventStore(None); s.close(); s.close()
        """
        with self.lock:
            if self._closed:
                return
            self._closed = True
            try:
                if self._tx_depth:
                    self._conn.execute("ROLLBACK")
                    self._tx_depth = 0
                for cursor in list(self._open_cursors):  # iterators still open
                    cursor.close()
                if self.path is not None:
                    try:
                        self._conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
                    except sqlite3.OperationalError:
                        pass  # best effort: the WAL is checkpointed on the next open anyway
            finally:
                self._conn.close()

    def __enter__(self) -> "EventStore":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    @property
    def closed(self) -> bool:
        return self._closed

    # ------------------------------------------------------------------ transactions

    @contextmanager
    def transaction(self) -> Iterator["EventStore"]:
        """Run several store calls as one atomic unit (BEGIN IMMEDIATE ... COMMIT).

        Re-entrant: nested uses become savepoints, so an inner failure undoes only the inner
        part. The store lock is held for the whole transaction.

        >>> s = EventStore(None)
        >>> with s.transaction():
        ...     table = s.declare_type("seg", 2); program_id = s.append_program("seg.", None)
        >>> s.event_types(), s.program_sources()
        ({('seg', 2): 'seg'}, [('seg.', None)])
        """
        with self.lock:
            self._check_open()
            depth = self._tx_depth
            conn = self._conn
            if depth == 0:
                conn.execute("BEGIN IMMEDIATE")
            else:
                conn.execute(f"SAVEPOINT slr_sp{depth}")
            self._tx_depth = depth + 1
            try:
                yield self
            except BaseException:
                self._tx_depth = depth
                try:
                    if depth == 0:
                        conn.execute("ROLLBACK")
                    else:
                        conn.execute(f"ROLLBACK TO slr_sp{depth}")
                        conn.execute(f"RELEASE slr_sp{depth}")
                finally:
                    self._reload_types()  # types created inside were rolled back too
                raise
            self._tx_depth = depth
            try:
                conn.execute("COMMIT" if depth == 0 else f"RELEASE slr_sp{depth}")
            except BaseException:
                if depth == 0 and conn.in_transaction:
                    conn.execute("ROLLBACK")
                self._reload_types()
                raise

    @property
    def in_transaction(self) -> bool:
        return self._tx_depth > 0

    def _check_open(self) -> None:
        if self._closed:
            raise SLRError("the event store is closed")

    # ------------------------------------------------------------------ event types

    def _reload_types(self) -> None:
        types: dict[tuple[str, int], _EventType] = {}
        declared: dict[str, set[int]] = {}
        if not self._closed:
            for name, arity, table, is_declared in self._conn.execute(
                    "SELECT name, arity, table_name, declared FROM slr_event_types"):
                types[(name, arity)] = _EventType(name, arity, table, bool(is_declared))
                if is_declared:
                    declared.setdefault(name, set()).add(arity)
        self._types = types
        self._declared_arities = declared

    def _lookup_type(self, name: str, arity: int) -> _EventType | None:
        event_type = self._types.get((name, arity))
        if event_type is None:
            # another connection (process) may have created it since we last looked
            row = self._conn.execute(
                "SELECT table_name, declared FROM slr_event_types WHERE name = ? AND arity = ?",
                (str(name), arity)).fetchone()
            if row is not None:
                event_type = _EventType(str(name), arity, row[0], bool(row[1]))
                self._types[(str(name), arity)] = event_type
                if row[1]:
                    self._declared_arities.setdefault(str(name), set()).add(arity)
        return event_type

    def _choose_table_name(self, name: str, arity: int) -> str:
        taken = {row[0].lower() for row in self._conn.execute("SELECT name FROM sqlite_master")}

        def free(candidate: str) -> bool:
            return all(n.lower() not in taken for n in [candidate] + _index_names(candidate))

        lowered = name.lower()
        if (_SAFE_IDENTIFIER.match(name) and not lowered.startswith(_RESERVED_PREFIXES)
                and lowered not in _SQL_KEYWORDS):
            base = name
            if free(base):
                return base
        else:
            base = "ev_" + re.sub(r"[^A-Za-z0-9_]", "_", name)
            if free(base):
                return base
        candidate = f"{base}__{arity}"
        suffix = 2
        while not free(candidate):
            candidate = f"{base}__{arity}_{suffix}"
            suffix += 1
        return candidate

    def _register_type(self, name: str, arity: int, declared: bool) -> _EventType:
        """Create the table of a new type. Must run inside a write transaction."""
        existing = self._lookup_type(name, arity)
        if existing is not None:
            if declared and not existing.declared:
                self._conn.execute("UPDATE slr_event_types SET declared = 1 "
                                   "WHERE name = ? AND arity = ?", (name, arity))
                existing.declared = True
                self._declared_arities.setdefault(name, set()).add(arity)
            return existing
        table = self._choose_table_name(name, arity)
        event_type = _EventType(name, arity, table, declared)
        arg_columns = "".join(f", arg{i}" for i in range(1, arity + 1))
        conn = self._conn
        # arg columns have no declared type: SQLite keeps INTEGER / REAL / TEXT as given.
        conn.execute(f"CREATE TABLE {event_type.quoted} (seq INTEGER PRIMARY KEY{arg_columns}, "
                     "t_start REAL NOT NULL, t_end REAL NOT NULL, arrival REAL NOT NULL)")
        conn.execute(f"CREATE INDEX {event_type.index_end} ON {event_type.quoted} (t_end, t_start)")
        conn.execute(f"CREATE INDEX {event_type.index_start} ON {event_type.quoted} "
                     "(t_start, t_end)")
        if arity >= 1:
            conn.execute(f"CREATE INDEX {event_type.index_arg1_end} ON {event_type.quoted} "
                         "(arg1, t_end, t_start)")
            conn.execute(f"CREATE INDEX {event_type.index_arg1_start} ON {event_type.quoted} "
                         "(arg1, t_start, t_end)")
        conn.execute("INSERT INTO slr_event_types (name, arity, table_name, declared) "
                     "VALUES (?, ?, ?, ?)", (name, arity, table, int(declared)))
        self._types[(name, arity)] = event_type
        if declared:
            self._declared_arities.setdefault(name, set()).add(arity)
        for hook in self.table_created_hooks:  # buffers (issue 4)
            hook(name, arity, table)
        return event_type

    def declare_type(self, name: str, arity: int) -> str:
        """Declare event type name/arity (``:- event name/arity.``); returns its table name.

        Once a name is declared with some arity, events of that name with an arity that is
        neither declared nor already stored are rejected as a wrong-arity mistake.

        >>> EventStore(None).declare_type("seg", 2)
        'seg'
        """
        if not isinstance(name, str) or not isinstance(arity, int) or arity < 0:
            raise ValueError(f"bad event type {name!r}/{arity!r}")
        with self.transaction():
            return self._register_type(str(name), arity, declared=True).table

    def event_types(self) -> dict[tuple[str, int], str]:
        """Every known event type ``(name, arity)`` -> its table name.

        >>> s = EventStore(None); s.declare_type("seg", 2); s.event_types()
        'seg'
        {('seg', 2): 'seg'}
        """
        with self.lock:
            self._check_open()
            if not self._tx_depth:
                self._reload_types()  # pick up types other processes created
            return {key: t.table for key, t in self._types.items()}

    def declared_types(self) -> set[tuple[str, int]]:
        """The types declared with :meth:`declare_type` (not merely created by an event).

        >>> s = EventStore(None); s.declare_type("seg", 2); sorted(s.declared_types())
        'seg'
        [('seg', 2)]
        """
        with self.lock:
            self._check_open()
            return {key for key, t in self._types.items() if t.declared}

    def table_for(self, name: str, arity: int) -> str | None:
        """The table holding events of name/arity, or None if there is none yet.

        >>> s = EventStore(None); s.table_for("seg", 2) is None
        True
        """
        with self.lock:
            self._check_open()
            event_type = self._lookup_type(name, arity)
            return None if event_type is None else event_type.table

    # ------------------------------------------------------------------ adding events

    def add_events(self, events: Iterable[Event], atomic: bool = False) -> list[EventRejected]:
        """Store events ``(name, args, start, end)`` in one transaction.

        Invalid events (non-ground or NaN arguments, non-finite times, start > end, wrong arity
        for a declared type) are skipped and returned as :class:`EventRejected` errors (with
        ``.index`` and ``.event``); the others are stored. With ``atomic=True`` the first
        invalid event is raised and nothing is stored. All events of one call share one
        arrival time, taken from the clock; their order is their arrival order.

        >>> s = EventStore(None)
        >>> [str(e) for e in s.add_events([("p", (1,), 1.0, 1.0), ("p", (2,), 3.0, 2.0)])]
        ['p(2)^[3.0,2.0]: start time 3.0 is after end time 2.0']
        """
        errors: list[EventRejected] = []
        if type(events) in (list, tuple) and not events:
            return errors
        enc = encode
        with self.transaction():
            arrival = float(self.clock.now())
            self.record_now(arrival)  # buffers (issue 4): "now" for the buffer triggers
            executemany = self._conn.executemany
            types = self._types
            rows: list = []
            append = rows.append
            current_name: Any = None
            current_arity = -1
            current_type: _EventType | None = None
            for index, event in enumerate(events):
                try:
                    try:
                        name, args, start, end = event
                        arity = len(args)
                    except (TypeError, ValueError):
                        raise _BadEvent(f"event #{index} is not a (name, args, start, end) "
                                        f"tuple: {event!r}") from None
                    if not (type(start) is float and type(end) is float
                            and _NEG_INF < start <= end < _INF):
                        start, end = _check_times(start, end)
                    if arity == 1:
                        row = (enc(args[0]), start, end, arrival)
                    elif arity == 2:
                        row = (enc(args[0]), enc(args[1]), start, end, arrival)
                    else:
                        row = (*map(enc, args), start, end, arrival)
                    if arity != current_arity or name != current_name:
                        if rows:
                            executemany(current_type.insert_sql, rows)
                            rows = []
                            append = rows.append
                        current_type = (isinstance(name, str) and types.get((name, arity))
                                        or self._type_for_new_event(name, arity))
                        current_name = name
                        current_arity = arity
                    append(row)
                    if len(rows) >= _INSERT_CHUNK:
                        executemany(current_type.insert_sql, rows)
                        rows = []
                        append = rows.append
                except (_BadEvent, Unencodable) as exc:
                    error = self._rejection(index, event, exc)
                    if atomic:
                        raise error from None
                    errors.append(error)
            if rows:
                executemany(current_type.insert_sql, rows)
        return errors

    def _type_for_new_event(self, name: Any, arity: int) -> _EventType:
        if not isinstance(name, str):
            raise _BadEvent(f"event name must be an atom, not {name!r}")
        name = str(name)
        event_type = self._lookup_type(name, arity)
        if event_type is not None:
            return event_type
        declared = self._declared_arities.get(name)
        if declared and arity not in declared:
            arities = " and ".join(f"{name}/{a}" for a in sorted(declared))
            raise _BadEvent(f"wrong number of arguments: event type {arities} is declared, "
                            f"{name}/{arity} is not")
        return self._register_type(name, arity, declared=False)

    def _rejection(self, index: int, event: Any, exc: Exception) -> EventRejected:
        try:
            name, args, start, end = event
            text = format_event(name, args, start, end)
            message = f"{text}: {_reason(exc)}"
        except Exception:
            message = _reason(exc)
        error = EventRejected(message)
        error.index = index
        error.event = event
        return error

    def add_event(self, name: str, args: Iterable[Any], start: float, end: float) -> None:
        """Store one event; raises :class:`EventRejected` if it is invalid.

        >>> s = EventStore(None); s.add_event("tick", (), 1, 1); s.count("tick", 0)
        1
        """
        try:
            args = args if type(args) is tuple else tuple(args)
        except TypeError:
            raise EventRejected(f"{name}: event arguments must be a sequence, not "
                                f"{args!r}") from None
        self.add_events([(name, args, start, end)], atomic=True)

    # ------------------------------------------------------------------ reading events

    def _pushdown(self, event_type: _EventType, bound: dict[int, Any] | None
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
            positions.append(position)
            values.append(value)
        return tuple(positions), values

    def _select_sql(self, event_type: _EventType, kind: str, positions: tuple[int, ...],
                    flags: tuple[bool, ...]) -> str:
        key = (event_type.table, kind, positions, flags)
        sql = self._sql_cache.get(key)
        if sql is not None:
            return sql
        by_arg1 = bool(positions) and positions[0] == 0
        conditions = [f"arg{p + 1} = ?" for p in positions]
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
        where = f" WHERE {' AND '.join(conditions)}" if conditions else ""
        sql = (f"SELECT {event_type.columns} FROM {event_type.quoted} INDEXED BY {index}"
               f"{where} ORDER BY {order}")
        self._sql_cache[key] = sql
        return sql

    def _stream(self, sql: str, params: list, arity: int) -> Iterator[Row]:
        """Rows decoded lazily, fetched in growing batches; the lock is held per batch only."""
        with self.lock:
            self._check_open()
            cursor = self._conn.execute(sql, params)
            self._open_cursors.add(cursor)
        try:
            batch = 8  # prev/next callers usually need only the first row or two
            dec = decode
            while True:
                with self.lock:
                    rows = cursor.fetchmany(batch)
                if not rows:
                    return
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
            with self.lock:
                try:
                    cursor.close()
                except sqlite3.ProgrammingError:  # the store was closed meanwhile
                    pass

    def _query(self, name: str, arity: int, bound: dict[int, Any] | None, kind: str,
               flags: tuple[bool, ...], times: list) -> Iterator[Row]:
        with self.lock:
            self._check_open()
            event_type = self._lookup_type(name, arity)
            if event_type is None:
                return iter(())
            positions, values = self._pushdown(event_type, bound)
            sql = self._select_sql(event_type, kind, positions, flags)
        return self._stream(sql, values + times, arity)

    def scan(self, name: str, arity: int, bound: dict[int, Any] | None = None,
             end_le: float | None = None) -> Iterator[Row]:
        """Stored events of name/arity in store order (end, start, arrival), as
        ``(args, start, end, seq)``; only ``end <= end_le`` when given (the stream view).
        ``bound`` maps 0-based argument positions to ground terms that must be equal (SQL
        equality: the int 1 also finds 1.0 — the caller unifies anyway).

        >>> s = EventStore(None); s.add_events([("p", ("a",), 2, 2), ("p", ("b",), 1, 1)])
        []
        >>> [row[0] for row in s.scan("p", 1, {})], [row[0] for row in s.scan("p", 1, {0: "a"})]
        ([(Atom('b'),), (Atom('a'),)], [(Atom('a'),)])
        """
        has_end = end_le is not None
        return self._query(name, arity, bound, "scan", (has_end,),
                           [float(end_le)] if has_end else [])

    def prev_candidates(self, name: str, arity: int, bound: dict[int, Any] | None,
                        t: float, start_ge: float | None = None) -> Iterator[Row]:
        """Events with ``end <= t`` (and ``start >= start_ge`` when given), latest end first
        (streamed backwards from an index). Use :meth:`rows_at_end` for the tied rows of the
        first match in store order.

        >>> s = EventStore(None); s.add_events([("p", ("a",), 1, 1), ("p", ("b",), 2, 2)])
        []
        >>> next(s.prev_candidates("p", 1, {}, 1.5))[0]
        (Atom('a'),)
        """
        has_start = start_ge is not None
        times = [float(t)] + ([float(start_ge), float(start_ge)] if has_start else [])
        return self._query(name, arity, bound, "prev", (has_start,), times)

    def rows_at_end(self, name: str, arity: int, bound: dict[int, Any] | None, end: float,
                    start_ge: float | None = None, end_le: float | None = None
                    ) -> Iterator[Row]:
        """Events whose end is exactly ``end`` (and ``start >= start_ge``, ``end <= end_le``
        when given) in store order (start, arrival).

        >>> s = EventStore(None); s.add_events([("p", ("a",), 1, 2), ("p", ("b",), 0, 2)])
        []
        >>> [row[0] for row in s.rows_at_end("p", 1, {}, 2.0)]
        [(Atom('b'),), (Atom('a'),)]
        """
        flags = (start_ge is not None, end_le is not None)
        times = [float(end)] + ([float(start_ge)] if flags[0] else []) \
            + ([float(end_le)] if flags[1] else [])
        return self._query(name, arity, bound, "at_end", flags, times)

    def next_candidates(self, name: str, arity: int, bound: dict[int, Any] | None,
                        a: float, b: float) -> Iterator[Row]:
        """Events with ``a <= start`` and ``end <= b``, earliest start first (streamed from an
        index). Use :meth:`rows_at_start` for the tied rows of the first match.

        >>> s = EventStore(None); s.add_events([("p", ("a",), 1, 1), ("p", ("b",), 2, 2)])
        []
        >>> next(s.next_candidates("p", 1, {}, 1.5, math.inf))[0]
        (Atom('b'),)
        """
        return self._query(name, arity, bound, "next", (), [float(a), float(b), float(b)])

    def rows_at_start(self, name: str, arity: int, bound: dict[int, Any] | None,
                      start: float, b: float) -> Iterator[Row]:
        """Events whose start is exactly ``start`` and whose end is ``<= b``, in store order
        (end, arrival).

        >>> s = EventStore(None); s.add_events([("p", ("a",), 1, 3), ("p", ("b",), 1, 2)])
        []
        >>> [row[0] for row in s.rows_at_start("p", 1, {}, 1.0, 10.0)]
        [(Atom('b'),), (Atom('a'),)]
        """
        return self._query(name, arity, bound, "at_start", (), [float(start), float(b)])

    def lookup_sql(self, kind: str, name: str, arity: int,
                   bound: dict[int, Any] | None = None, *, start_ge: bool = False,
                   end_le: bool = False) -> str | None:
        """The SQL a lookup runs (for explain output and plan tests). ``kind`` is ``scan``,
        ``prev``, ``at_end``, ``next`` or ``at_start``; ``start_ge``/``end_le`` say whether
        those optional bounds are given. None if the type has no table.

        >>> s = EventStore(None); s.declare_type("p", 1)
        'p'
        >>> s.lookup_sql("prev", "p", 1)
        'SELECT arg1, t_start, t_end, seq FROM "p" INDEXED BY "slr_ix__p__end" WHERE t_end <= ? ORDER BY t_end DESC, t_start DESC, seq DESC'
        """
        flags = {"scan": (end_le,), "prev": (start_ge,), "at_end": (start_ge, end_le),
                 "next": (), "at_start": ()}[kind]
        with self.lock:
            self._check_open()
            event_type = self._lookup_type(name, arity)
            if event_type is None:
                return None
            positions, _ = self._pushdown(event_type, bound)
            return self._select_sql(event_type, kind, positions, flags)

    def query_plan(self, sql: str) -> list[str]:
        """SQLite's ``EXPLAIN QUERY PLAN`` lines for a statement (parameters bound to NULL).

        >>> EventStore(None).query_plan("SELECT * FROM slr_meta WHERE key = ?")
        ['SEARCH slr_meta USING INDEX sqlite_autoindex_slr_meta_1 (key=?)']
        """
        with self.lock:
            self._check_open()
            cursor = self._conn.execute("EXPLAIN QUERY PLAN " + sql, [None] * sql.count("?"))
            return [row[3] for row in cursor.fetchall()]

    def latest_at_or_before(self, name: str, arity: int, bound: dict[int, Any], t: float,
                            point: bool) -> list[Row] | None:
        """The whole answer of ``prev`` for a pattern whose bound arguments are all atomic and
        whose other arguments are distinct variables, in one statement: the events with the
        greatest end <= t (only point events, start = end, when ``point``), in store order.

        Returns None when a bound value cannot be pushed into SQL exactly (the caller then
        takes the general path). SQL's ``1 = 1.0`` is re-checked by the caller.

        >>> s = EventStore(None); s.add_events([("p", ("a",), 1, 1), ("p", ("a",), 2, 2)])
        []
        >>> [row[2] for row in s.latest_at_or_before("p", 1, {0: "a"}, 1.5, True)]
        [1.0]
        """
        with self.lock:
            self._check_open()
            event_type = self._lookup_type(name, arity)
            if event_type is None:
                return []
            positions, values = self._pushdown(event_type, bound)
            if len(positions) != len(bound):
                return None
            key = (event_type.table, "latest", positions, point)
            sql = self._sql_cache.get(key)
            if sql is None:
                where = " AND ".join([f"arg{p + 1} = ?" for p in positions]
                                     + (["t_start = t_end"] if point else []))
                where = (where + " AND ") if where else ""
                columns = ", ".join([f"arg{i + 1}" for i in range(arity)]
                                    + ["t_start", "t_end", "seq"])
                # ORDER BY ... LIMIT 1 rather than max(): max() with the extra start = end
                # filter is an aggregate over every row of the key, LIMIT 1 stops at the first
                sql = (f"SELECT {columns} FROM {event_type.quoted} WHERE {where}t_end = "
                       f"(SELECT t_end FROM {event_type.quoted} WHERE {where}t_end <= ? "
                       f"ORDER BY t_end DESC LIMIT 1) ORDER BY t_start, seq")
                self._sql_cache[key] = sql
            rows = self._conn.execute(sql, values + values + [float(t)]).fetchall()
        dec = decode
        return [(tuple([dec(v) for v in row[:arity]]), row[arity], row[arity + 1], row[arity + 2])
                for row in rows]

    def count(self, name: str, arity: int) -> int:
        """Number of stored events of name/arity.

        >>> EventStore(None).count("p", 1)
        0
        """
        with self.lock:
            self._check_open()
            event_type = self._lookup_type(name, arity)
            if event_type is None:
                return 0
            return self._conn.execute(f"SELECT count(*) FROM {event_type.quoted}").fetchone()[0]

    def max_end(self, name: str, arity: int) -> float | None:
        """The greatest end time stored for name/arity, or None.

        >>> s = EventStore(None); s.add_event("p", (1,), 1, 4); s.max_end("p", 1)
        4.0
        """
        with self.lock:
            self._check_open()
            event_type = self._lookup_type(name, arity)
            if event_type is None:
                return None
            return self._conn.execute(
                f"SELECT max(t_end) FROM {event_type.quoted}").fetchone()[0]

    # ------------------------------------------------------------------ program and state

    def append_program(self, source: str, filename: str | None = None) -> int:
        """Persist one loaded program text; returns its id (load order).

        >>> s = EventStore(None); s.append_program("p(1).", "a.slr"); s.program_sources()
        1
        [('p(1).', 'a.slr')]
        """
        with self.lock:
            self._check_open()
            cursor = self._conn.execute(
                "INSERT INTO slr_program (source, filename, loaded_at) VALUES (?, ?, ?)",
                (source, filename, float(self.clock.now())))
            return cursor.lastrowid

    def program_sources(self) -> list[tuple[str, str | None]]:
        """Every persisted program text with its file name, in load order.

        >>> EventStore(None).program_sources()
        []
        """
        with self.lock:
            self._check_open()
            return [(source, filename) for source, filename in self._conn.execute(
                "SELECT source, filename FROM slr_program ORDER BY id")]

    def replace_program(self, sources: Iterable[tuple[str, str | None]]) -> None:
        """Replace the persisted program by ``sources`` (``(text, filename)`` pairs), atomically.

        >>> s = EventStore(None); s.append_program("a.", None); s.replace_program([("b.", None)])
        1
        >>> s.program_sources()
        [('b.', None)]
        """
        with self.transaction():
            self._conn.execute("DELETE FROM slr_program")
            now = float(self.clock.now())
            self._conn.executemany(
                "INSERT INTO slr_program (source, filename, loaded_at) VALUES (?, ?, ?)",
                [(source, filename, now) for source, filename in sources])

    def meta_get(self, key: str, default: Any = None) -> Any:
        """A persisted JSON value from ``slr_meta``, or ``default``.

        >>> s = EventStore(None); s.meta_set("delay/seg/2", 0.5); s.meta_get("delay/seg/2")
        0.5
        """
        with self.lock:
            self._check_open()
            row = self._conn.execute("SELECT value FROM slr_meta WHERE key = ?",
                                     (key,)).fetchone()
        return default if row is None else json.loads(row[0])

    def meta_set(self, key: str, value: Any) -> None:
        """Persist a JSON-serializable value under ``key`` (replacing any previous one).

        >>> s = EventStore(None); s.meta_set("k", {"a": [1, 2]}); s.meta_get("k")
        {'a': [1, 2]}
        """
        text = json.dumps(value)
        with self.lock:
            self._check_open()
            self._conn.execute("INSERT INTO slr_meta (key, value) VALUES (?, ?) "
                               "ON CONFLICT(key) DO UPDATE SET value = excluded.value",
                               (key, text))

    def meta_delete(self, key: str) -> None:
        """Remove ``key`` from ``slr_meta`` (no error if absent).

        >>> s = EventStore(None); s.meta_set("k", 1); s.meta_delete("k"); s.meta_get("k", 0)
        0
        """
        with self.lock:
            self._check_open()
            self._conn.execute("DELETE FROM slr_meta WHERE key = ?", (key,))

    def meta_items(self, prefix: str = "") -> dict[str, Any]:
        """Every ``slr_meta`` entry whose key starts with ``prefix``.

        >>> s = EventStore(None); s.meta_set("delay/a", 1); s.meta_items("delay/")
        {'delay/a': 1}
        """
        with self.lock:
            self._check_open()
            rows = self._conn.execute(
                "SELECT key, value FROM slr_meta WHERE substr(key, 1, ?) = ? ORDER BY key",
                (len(prefix), prefix)).fetchall()
        return {key: json.loads(value) for key, value in rows}

    # ------------------------------------------------------------------ raw SQL

    def sql(self, query: str, params: Iterable[Any] = ()) -> tuple[list[str], list[tuple]]:
        """Run one SQL statement as given (for ``slr sql``; meant for reading) and return
        ``(column names, rows)``.

        >>> EventStore(None).sql("SELECT 1 AS one")
        (['one'], [(1,)])
        """
        with self.lock:
            self._check_open()
            cursor = self._conn.execute(query, tuple(params))
            columns = [d[0] for d in cursor.description] if cursor.description else []
            return columns, cursor.fetchall()

    def execute(self, sql: str, params: Iterable[Any] = ()) -> list[tuple]:
        """Execute one statement for another slr_sql module (triggers, buffer pruning, ...)
        and return its rows. Inside :meth:`transaction` it is part of the transaction.

        >>> EventStore(None).execute("SELECT ? + 1", (1,))
        [(2,)]
        """
        with self.lock:
            self._check_open()
            return self._conn.execute(sql, tuple(params)).fetchall()

    def executemany(self, sql: str, rows: Iterable[Iterable[Any]]) -> None:
        """``executemany`` for other slr_sql modules.

        >>> s = EventStore(None); s.executemany("INSERT INTO slr_meta VALUES (?, ?)", [("a", "1")])
        """
        with self.lock:
            self._check_open()
            self._conn.executemany(sql, rows)

    def executescript(self, script: str) -> None:
        """Run several statements (e.g. ``CREATE TRIGGER`` ... ``END;``) in one transaction.
        (Unlike ``sqlite3``'s ``executescript`` it does not commit an enclosing transaction.)

        >>> s = EventStore(None); s.executescript("CREATE TABLE slr_x(a); CREATE TABLE slr_y(b);")
        """
        with self.transaction():
            for statement in split_sql_script(script):
                self._conn.execute(statement)

    def changes(self) -> int:
        """Rows changed by the last statement (``changes()``)."""
        with self.lock:
            return self._conn.execute("SELECT changes()").fetchone()[0]

    # ================================================================== buffers (issue 4)
    # Event-history management (slr_sql.buffers decides *what*; these methods run the SQL).
    # Tables: slr_buffers, slr_counters, slr_clock (migrations/0002_buffers.sql); schema
    # objects named slr_buf_<id>_* (triggers) and slr_bix_<id> (indexes).

    def record_now(self, now: float) -> None:
        """Record the store clock's current time in ``slr_clock`` (read by the buffer
        triggers). Moving it runs the time-driven tBuffer pruning (``slr_buf_<id>_tick``
        triggers). Called at the start of every add batch and by clock listeners.

        >>> s = EventStore(None); s.record_now(5.0); s.recorded_now()
        5.0
        """
        now = float(now)
        if now != now:
            return
        sql = "UPDATE slr_clock SET now = ? WHERE id = 1 AND now IS NOT ?"
        with self.lock:
            if self._tx_depth:  # inside add_events: part of its transaction
                self._check_open()
                self._conn.execute(sql, (now, now))
                return
        with self.transaction():
            self._conn.execute(sql, (now, now))

    def recorded_now(self) -> float:
        """The "now" buffer triggers currently use (``-inf`` before the first record)."""
        with self.lock:
            self._check_open()
            return self._conn.execute("SELECT now FROM slr_clock WHERE id = 1").fetchone()[0]

    def buffer_rows(self, active_only: bool = True) -> list[dict[str, Any]]:
        """The rows of ``slr_buffers`` (oldest first) with their counters, as dicts.

        >>> EventStore(None).buffer_rows()
        []
        """
        where = " WHERE b.removed_at IS NULL" if active_only else ""
        with self.lock:
            self._check_open()
            cursor = self._conn.execute(
                "SELECT b.id, b.kind, b.source, b.pattern_text, b.type_name, b.type_arity, "
                "b.amount, b.t1, b.t2, b.origin, b.cutoff, b.created_at, b.removed_at, "
                "coalesce(c.pruned, 0) AS pruned, coalesce(c.dropped, 0) AS dropped "
                "FROM slr_buffers b LEFT JOIN slr_counters c ON c.buffer_id = b.id"
                f"{where} ORDER BY b.id")
            names = [d[0] for d in cursor.description]
            return [dict(zip(names, row)) for row in cursor.fetchall()]

    def insert_buffer(self, kind: str, source: str, pattern_text: str, type_name: str,
                      type_arity: int, amount: float | None, t1: float | None,
                      t2: float | None, origin: str) -> int:
        """Add a row to ``slr_buffers`` (and its counters); returns the new buffer id."""
        with self.transaction():
            cursor = self._conn.execute(
                "INSERT INTO slr_buffers (kind, source, pattern_text, type_name, type_arity, "
                "amount, t1, t2, origin, created_at) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (kind, source, pattern_text, type_name, type_arity, amount, t1, t2, origin,
                 float(self.clock.now())))
            buffer_id = cursor.lastrowid
            self._conn.execute("INSERT OR IGNORE INTO slr_counters (buffer_id) VALUES (?)",
                               (buffer_id,))
            return buffer_id

    def mark_buffer_removed(self, buffer_id: int) -> None:
        """Deactivate a buffer (its row and counters stay, for statistics)."""
        with self.transaction():
            self._conn.execute("UPDATE slr_buffers SET removed_at = ? WHERE id = ?",
                               (float(self.clock.now()), int(buffer_id)))

    def count_buffer(self, buffer_id: int, pruned: int = 0, dropped: int = 0) -> None:
        """Add to a buffer's counters."""
        with self.transaction():
            self._conn.execute("UPDATE slr_counters SET pruned = pruned + ?, "
                               "dropped = dropped + ? WHERE buffer_id = ?",
                               (int(pruned), int(dropped), int(buffer_id)))

    def set_buffer_cutoff(self, buffer_id: int, cutoff: float) -> None:
        with self.transaction():
            self._conn.execute("UPDATE slr_buffers SET cutoff = ? WHERE id = ?",
                               (float(cutoff), int(buffer_id)))

    def buffer_objects(self, buffer_id: int) -> dict[str, str]:
        """The triggers and indexes of one buffer: ``{name: sql}``."""
        with self.lock:
            self._check_open()
            rows = self._conn.execute(
                "SELECT name, sql FROM sqlite_master WHERE type IN ('trigger', 'index') "
                "AND (name LIKE ? ESCAPE '!' OR name = ?)",
                (f"slr!_buf!_{int(buffer_id)}!_%", f"slr_bix_{int(buffer_id)}")).fetchall()
        return {name: sql for name, sql in rows}

    def install_buffer_objects(self, buffer_id: int, statements: dict[str, str]) -> bool:
        """Make the triggers/indexes of ``buffer_id`` exactly ``statements`` (``{name: CREATE
        ...}``): objects whose SQL differs are re-created, missing ones created, others
        dropped. Returns True if anything changed."""
        with self.transaction():
            existing = self.buffer_objects(buffer_id)
            changed = False
            for name, sql in existing.items():
                if statements.get(name) != sql:
                    kind = "INDEX" if name.startswith("slr_bix_") else "TRIGGER"
                    self._conn.execute(f"DROP {kind} IF EXISTS {quote_identifier(name)}")
                    changed = True
            for name, sql in statements.items():
                if existing.get(name) != sql:
                    self._conn.execute(sql)
                    changed = True
            return changed

    def drop_buffer_objects(self, buffer_id: int) -> None:
        """Drop every trigger and index of one buffer."""
        self.install_buffer_objects(buffer_id, {})

    def prune(self, sql: str, buffer_id: int) -> int:
        """Run one buffer's DELETE statement (generated by slr_sql.buffers; constants in it
        come from :func:`sql_literal`) and add the deleted rows to its ``pruned`` counter."""
        with self.transaction():
            deleted = self._conn.execute(sql).rowcount
            if deleted > 0:
                self._conn.execute("UPDATE slr_counters SET pruned = pruned + ? "
                                   "WHERE buffer_id = ?", (deleted, int(buffer_id)))
            return max(deleted, 0)

    def table_rows(self) -> dict[tuple[str, int], int]:
        """Rows stored now per event type (a full count: for statistics)."""
        with self.lock:
            self._check_open()
            out = {}
            for key, table in sorted(self.event_types().items()):
                out[key] = self._conn.execute(
                    f"SELECT count(*) FROM {quote_identifier(table)}").fetchone()[0]
            return out

    def space_stats(self) -> dict[str, Any]:
        """Page size/count, free pages, and the sizes of the file and its WAL (bytes).

        >>> sorted(EventStore(None).space_stats())
        ['file_bytes', 'free_pages', 'page_count', 'page_size', 'wal_bytes']
        """
        import os

        with self.lock:
            self._check_open()
            page_size = self._conn.execute("PRAGMA page_size").fetchone()[0]
            page_count = self._conn.execute("PRAGMA page_count").fetchone()[0]
            free = self._conn.execute("PRAGMA freelist_count").fetchone()[0]
        file_bytes = wal_bytes = 0
        if self.path is not None:
            try:
                file_bytes = os.path.getsize(self.path)
            except OSError:
                pass
            try:
                wal_bytes = os.path.getsize(self.path + "-wal")
            except OSError:
                pass
        else:
            file_bytes = page_size * page_count
        return {"page_size": page_size, "page_count": page_count, "free_pages": free,
                "file_bytes": file_bytes, "wal_bytes": wal_bytes}

    def reclaim_space(self, min_free_pages: int = 2048, min_free_fraction: float = 0.25,
                      keep_fraction: float = 0.10) -> int:
        """Give free pages back to the file system (``PRAGMA incremental_vacuum``) when the
        free list is large: more than ``min_free_pages`` pages and ``min_free_fraction`` of
        the file. ``keep_fraction`` of the file is left free for the next inserts to reuse.
        Returns the number of pages released (0 for in-memory stores)."""
        if self.path is None:
            return 0
        with self.lock:
            self._check_open()
            conn = self._conn
            page_count = conn.execute("PRAGMA page_count").fetchone()[0]
            free = conn.execute("PRAGMA freelist_count").fetchone()[0]
            if free <= min_free_pages or free < min_free_fraction * page_count:
                return 0
            release = free - int(keep_fraction * page_count)
            if release <= 0:
                return 0
            with self.transaction():
                conn.execute(f"PRAGMA incremental_vacuum({int(release)})").fetchall()
            after = conn.execute("PRAGMA freelist_count").fetchone()[0]
            if not self._tx_depth:
                conn.execute("PRAGMA wal_checkpoint(PASSIVE)").fetchall()
            return max(free - after, 0)

    def limit_wal(self, max_bytes: int = 64 * 1024 * 1024) -> None:
        """Truncate the WAL file to at most ``max_bytes`` after each checkpoint
        (``PRAGMA journal_size_limit``; the WAL is checkpointed every 1000 pages by SQLite)."""
        if self.path is None:
            return
        with self.lock:
            self._check_open()
            self._conn.execute(f"PRAGMA journal_size_limit = {int(max_bytes)}").fetchall()


    # ================================================================== SQL compiler (issue 3)
    # Execution helpers for slr_sql.planner / slr_sql.sqlcompile: application-defined
    # functions, running compiled statements (parameters always bound), fact tables
    # (slr_facts_<name>_<arity>: ord, arg1..argN) and the inspection views of derived
    # predicates (names kept in slr_meta under "sql_views").

    def create_function(self, name: str, narg: int, fn: Any, deterministic: bool = True) -> None:
        """Register a scalar function on the store's connection."""
        with self.lock:
            self._check_open()
            self._conn.create_function(name, narg, fn, deterministic=deterministic)

    def create_aggregate(self, name: str, narg: int, cls: Any) -> None:
        """Register an aggregate function (a class with step/finalize)."""
        with self.lock:
            self._check_open()
            self._conn.create_aggregate(name, narg, cls)

    def run_compiled(self, sql: str, params: dict, limit: int | None = None,
                     deadline: float | None = None) -> list[tuple]:
        """Run a compiled SELECT with named parameters; all rows, or the first ``limit``.
        ``deadline`` (``time.monotonic()``): past it the statement is interrupted and
        :class:`SLRTimeout` raised, as the interpreter does for ``timeout=``."""
        with self.lock:
            self._check_open()
            conn = self._conn
            # a statement run from inside another (a kb.define predicate querying the kb
            # from SQL) keeps the outer deadline: the handler is per connection
            outer = getattr(self, "_deadline", None)
            if deadline is None or (outer is not None and outer <= deadline):
                deadline = outer
            if deadline is not outer:
                self._deadline = deadline
                conn.set_progress_handler(
                    lambda: 1 if time.monotonic() > deadline else 0, 20000)
            try:
                cursor = conn.execute(sql, params)
                try:
                    return cursor.fetchall() if limit is None else cursor.fetchmany(limit)
                finally:
                    cursor.close()
            except sqlite3.OperationalError as exc:
                if deadline is not None and time.monotonic() > deadline \
                        and "interrupt" in str(exc):
                    from .errors import SLRTimeout

                    raise SLRTimeout("query timed out (in its compiled SQL statement)") from None
                raise
            finally:
                if deadline is not outer:
                    self._deadline = outer
                    if outer is None:
                        conn.set_progress_handler(None, 0)
                    else:
                        conn.set_progress_handler(
                            lambda: 1 if time.monotonic() > outer else 0, 20000)

    def event_table_sql(self, name: str, arity: int) -> str | None:
        """The quoted table of an event type (for compiled SQL), or None if it has none."""
        event_type = self._types.get((name, arity))
        if event_type is None:
            with self.lock:
                self._check_open()
                event_type = self._lookup_type(name, arity)
        return None if event_type is None else event_type.quoted

    @staticmethod
    def fact_table_name(name: str, arity: int) -> str:
        """``slr_facts_<name>_<arity>`` (a hex name for names that are not identifiers).

        >>> EventStore.fact_table_name("usedFor", 2), EventStore.fact_table_name("a b", 1)
        ('slr_facts_usedFor_2', 'slr_facts_x612062_1')
        """
        safe = name if _SAFE_IDENTIFIER.match(name) else "x" + name.encode("utf-8").hex()
        return f"slr_facts_{safe}_{arity}"

    def replace_fact_tables(self, tables: dict[tuple[str, int], list[tuple]]) -> dict:
        """Make the ``slr_facts_*`` tables exactly ``{(name, arity): [encoded rows]}`` (rows
        in clause order; ``ord`` is the position). Returns ``{(name, arity): quoted table}``."""
        out = {}
        with self.transaction():
            conn = self._conn
            existing = [row[0] for row in conn.execute(
                "SELECT name FROM sqlite_master WHERE type = 'table' AND name LIKE 'slr!_facts!_%' "
                "ESCAPE '!'")]
            for table in existing:
                conn.execute(f"DROP TABLE {quote_identifier(table)}")
            for (name, arity), rows in tables.items():
                table = quote_identifier(self.fact_table_name(name, arity))
                cols = "".join(f", arg{i}" for i in range(1, arity + 1))
                conn.execute(f"CREATE TABLE {table} (ord INTEGER PRIMARY KEY{cols})")
                if arity:
                    conn.execute(f"CREATE INDEX {quote_identifier(self.fact_table_name(name, arity) + '__a1')} "
                                 f"ON {table} (arg1)")
                conn.executemany(f"INSERT INTO {table} VALUES (?{', ?' * arity})",
                                 [(i,) + tuple(row) for i, row in enumerate(rows)])
                out[(name, arity)] = table
        return out

    def replace_views(self, views: dict[str, str]) -> list[str]:
        """Drop the views created last time and create ``{name: select sql}`` (a name already
        used by a table or index is skipped). Returns the names created."""
        created = []
        with self.transaction():
            conn = self._conn
            for name in self.meta_get("sql_views", []):
                conn.execute(f"DROP VIEW IF EXISTS {quote_identifier(name)}")
            taken = {row[0].lower() for row in conn.execute("SELECT name FROM sqlite_master")}
            for name, select in views.items():
                if name.lower() in taken:
                    continue
                conn.execute(f"CREATE VIEW {quote_identifier(name)} AS {select}")
                created.append(name)
                taken.add(name.lower())
            self.meta_set("sql_views", created)
        return created

def sql_literal(value: Any) -> str:
    """Quote a constant as an SQL literal, strictly.

    The buffer triggers (slr_sql.buffers) are the one place where slr_sql writes constants
    into SQL text: ``CREATE TRIGGER`` bodies cannot have bound parameters, so a pattern
    constant such as ``bob`` in ``cBuffer(face(bob, L), 1)`` must appear as a literal. Only
    ``int`` (64-bit), finite or infinite ``float`` and ``str`` without NUL are accepted;
    quotes are doubled; anything else is rejected.

    >>> sql_literal("it's"), sql_literal(3), sql_literal(0.5), sql_literal(float("inf"))
    ("'it''s'", '3', '0.5', '9e999')
    >>> sql_literal(True)
    Traceback (most recent call last):
    ...
    TypeError: no SQL literal for bool value True
    """
    tv = type(value)
    if tv is int or (isinstance(value, int) and tv is not bool):
        value = int(value)
        if not -(2 ** 63) <= value < 2 ** 63:
            raise ValueError(f"integer {value} does not fit an SQL literal")
        return repr(value)
    if tv is float or (isinstance(value, float) and tv is not bool):
        value = float(value)
        if value != value:
            raise ValueError("NaN has no SQL literal")
        if value == _INF:
            return "9e999"
        if value == _NEG_INF:
            return "-9e999"
        return repr(value)
    if isinstance(value, str):
        text = str.__str__(value)
        if "\x00" in text:
            raise ValueError("a NUL character cannot be written as an SQL literal")
        return "'" + text.replace("'", "''") + "'"
    raise TypeError(f"no SQL literal for {tv.__name__} value {value!r}")
