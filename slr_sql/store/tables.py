"""Event types and their tables: naming, creating and finding one table per name/arity.

A type's table is named after the event when that is a plain SQL identifier (``seg``),
otherwise a sanitized unique name (``seg__3``, ``ev_my_event``); ``slr_event_types`` holds
the mapping. Columns::

    seq      INTEGER PRIMARY KEY AUTOINCREMENT  -- arrival sequence (the rowid), never reused
    arg1..N                        -- data arguments, encoded by slr_sql.encoding
    t_start  REAL NOT NULL
    t_end    REAL NOT NULL
    arrival  REAL NOT NULL         -- store clock time of the add that stored the event
    robot    TEXT                  -- the robot that observed or derived it (NULL: unnamed)

Indexes ``(t_end, t_start)`` and ``(t_start, t_end)``, plus ``(arg1, t_end, t_start)`` and
``(arg1, t_start, t_end)`` when there is a first argument. Every index entry ends with the
rowid, so *store order* (``ORDER BY t_end, t_start, seq``) and the reverse order prev needs
are read straight from an index, never sorted.

*Start order on first need.* The two start-ordered indexes, ``(t_start, t_end)`` and
``(arg1, t_start, t_end)``, serve only the readers in start order: ``next``, the ties at a
start, the after-part of ``bracket``, compiled ``next`` subqueries and the statements whose
plan would use them. A new table gets only the two end-ordered ones: events arrive roughly in
end order, so those stay appends at the right edge of their B-trees, while each
start-ordered entry is a B-tree of its own to write (two of a row's five; seq2 pairs an old
``a`` with a new ``b`` and lands its start entries at random places), and storing an event
with them cost 20-25% more CPU (benchmarks/README.md). :meth:`EventTables.ensure_start_order`
builds them (``CREATE INDEX IF NOT EXISTS``, names as ever) the first time a reader needs
them: a one-time cost proportional to the table. Which statements need them is asked of
SQLite's planner (:meth:`EventTables.start_orders_wanted`); existing tables keep the indexes
they have.
"""
from __future__ import annotations

import hashlib
import re
import sqlite3
from contextlib import contextmanager
from typing import Any, Callable, Iterable, Iterator

from ..errors import SLRError, SLRUnavailable
from .connection import Database, DatabaseError
from .dialect import SQLITE
from .sqltext import RESERVED_PREFIXES, SAFE_IDENTIFIER, SQL_KEYWORDS, quote_identifier

__all__ = ["EventType", "EventTables", "START_ORDER_RETRY", "START_ORDER_RETRY_LOOKUPS",
           "START_ORDER_ONE_BY_ONE"]

# Seconds of the store's clock after a start-order build met another session's lock before
# a reader tries that table's build again (a try is a round trip and a failed savepoint;
# the readers in between read without the index, as they do while it is being built).
START_ORDER_RETRY = 0.1
# ... or after this many lookups of the table skipped the build, whatever the clock says (a
# ManualClock that never moves, a clock that stands still: one try per this many lookups)
START_ORDER_RETRY_LOOKUPS = 100


class EventType:
    """What the store knows about one event type (cached per name/arity)."""

    __slots__ = ("name", "arity", "table", "declared", "insert_sql", "insert_unnamed_sql",
                 "quoted", "columns", "_insert_heads", "_multi_row_sql",
                 "index_end", "index_start", "index_arg1_end", "index_arg1_start",
                 "start_order")

    def __init__(self, name: str, arity: int, table: str, declared: bool,
                 start_order: bool | None = None):
        self.name = name
        self.arity = arity
        self.table = table
        self.declared = declared
        # whether the start-ordered indexes exist: True known (built here, or seen in the
        # catalog), False created without them here, None not looked at yet (a table read
        # from slr_event_types: another process may have built them). Only a True is
        # trusted without a look at the catalog; a rollback reloads every type (None).
        self.start_order = start_order
        self.quoted = quote_identifier(table)
        arg_columns = [f"arg{i}" for i in range(1, arity + 1)]
        self.columns = ", ".join(arg_columns + ["t_start", "t_end", "seq"])
        insert_columns = arg_columns + ["t_start", "t_end", "arrival", "robot"]
        self.insert_sql = (f"INSERT INTO {self.quoted} ({', '.join(insert_columns)}) "
                           f"VALUES ({', '.join('?' * len(insert_columns))})")
        # the rows of a store that has no robot name: robot is left to the column's NULL
        # instead of a NULL bound per row (a bulk add of an unnamed store spends ~10% of its
        # time in executemany binding that one extra parameter)
        unnamed_columns = insert_columns[:-1]
        self.insert_unnamed_sql = (f"INSERT INTO {self.quoted} ({', '.join(unnamed_columns)}) "
                                   f"VALUES ({', '.join('?' * len(unnamed_columns))})")
        self._insert_heads = {
            True: (f"INSERT INTO {self.quoted} ({', '.join(insert_columns)}) VALUES ",
                   f"({', '.join('?' * len(insert_columns))})"),
            False: (f"INSERT INTO {self.quoted} ({', '.join(unnamed_columns)}) VALUES ",
                    f"({', '.join('?' * len(unnamed_columns))})")}
        self._multi_row_sql: dict[tuple[int, bool], str] = {}
        self.index_end = quote_identifier(f"slr_ix__{table}__end")
        self.index_start = quote_identifier(f"slr_ix__{table}__start")
        self.index_arg1_end = quote_identifier(f"slr_ix__{table}__a1_end")
        self.index_arg1_start = quote_identifier(f"slr_ix__{table}__a1_start")

    def start_index_statements(self, dialect: Any = SQLITE) -> dict[str, str]:
        """The start-ordered indexes' names and ``CREATE INDEX IF NOT EXISTS`` statements
        (no ``(arg1, ...)`` one for a type without arguments; those over the first
        argument as the ``dialect``'s :meth:`~slr_sql.store.dialect.SQLiteDialect.key_indexes`).

        >>> list(EventType("p", 1, "p", False).start_index_statements().values())[1]
        'CREATE INDEX IF NOT EXISTS "slr_ix__p__a1_start" ON "p" (arg1, t_start, t_end)'
        >>> from slr_sql.store.dialect import POSTGRES
        >>> list(EventType("p", 1, "p", False).start_index_statements(POSTGRES))
        ['slr_ix__p__start', 'slr_ix__p__a1_start', 'slr_ix__p__a1_start_k']
        """
        made = {self.index_start.strip('"'): "(t_start, t_end)"}
        if self.arity >= 1:
            for suffix, columns in dialect.key_indexes(["arg1"], ["t_start", "t_end"]):
                made[self.index_arg1_start.strip('"') + suffix] = columns
        return {index: f"CREATE INDEX IF NOT EXISTS {quote_identifier(index)} ON "
                       f"{self.quoted} {columns}" for index, columns in made.items()}

    def insert_rows_sql(self, rows: int, with_robot: bool) -> str:
        """One INSERT of ``rows`` rows (multi-row VALUES), with the robot column bound or
        left to its NULL; the texts are kept, as the connection keeps their statements.

        >>> EventType("p", 1, "p", False).insert_rows_sql(2, False)
        'INSERT INTO "p" (arg1, t_start, t_end, arrival) VALUES (?, ?, ?, ?),(?, ?, ?, ?)'
        """
        key = (rows, with_robot)
        sql = self._multi_row_sql.get(key)
        if sql is None:
            head, row = self._insert_heads[with_robot]
            sql = self._multi_row_sql[key] = head + ",".join([row] * rows)
        return sql


# the longest table name whose derived names (indexes, journals, the event rules' indexes)
# fit 63 bytes
_LONG_TABLE = 30


def _shortened(base: str, name: str, arity: int) -> str:
    """``base`` (ASCII) cut to :data:`_LONG_TABLE` characters, the cut part replaced by a
    digest of the type, so that two long names that share a beginning get two tables.

    >>> _shortened("a" * 70, "a" * 70, 1)
    'aaaaaaaaaaaaaaaaa_baf26e4537d9'
    """
    digest = hashlib.sha1(f"{name}/{arity}".encode()).hexdigest()[:12]
    return f"{base[:_LONG_TABLE - 13]}_{digest}"


# SQLite's refusals of a write that stay until the file is opened otherwise (a busy, full or
# failing disk may pass: those are tried again)
_REFUSED_FOR_GOOD = (sqlite3.SQLITE_READONLY, sqlite3.SQLITE_PERM, sqlite3.SQLITE_AUTH)


# a search's bound columns in a step of EXPLAIN QUERY PLAN: "... INDEX x (arg1=? AND t_end<?)"
_SEARCH_BOUNDS = re.compile(r"^SEARCH .* \(([^()]*)\)$")
_RANGE = re.compile(r"^(\w+)(<|>|<=|>=)\?$")
_TIMES = frozenset({"t_start", "t_end"})


# beyond this many types whose start order a plan uses, they are judged together
# (EventTables.start_orders_wanted)
START_ORDER_ONE_BY_ONE = 8


def plan_cost(steps: list[str]) -> tuple[int, int, int]:
    """How costly a plan's steps read, to compare two plans of one statement: its full
    scans (an automatic index, which a run builds by reading the whole table, is one), then
    its sorts (temporary B-trees), then, fewer being worse, what its searches bind: four
    for each column bound by ``=``, three for one bounded on both sides, two on one side --
    but one for a time bounded only from above: times grow with the store, so ``t_end < ?``
    reads the whole history before it (a ``cnot``'s ``t_start > S AND t_end < E``, read
    again at each check), ``t_start > ?`` only what came after.

    >>> plan_cost(["SEARCH e1 USING INDEX i (arg1=? AND t_start>?)", "SCAN e0"])
    (1, 0, -6)
    >>> plan_cost(["SEARCH e0 USING INDEX s (t_start=? AND t_end>? AND t_end<?)"])
    (0, 0, -7)
    >>> plan_cost(["SEARCH e0 USING INDEX e (t_end=? AND t_start=?)"])
    (0, 0, -8)
    >>> plan_cost(["SEARCH n0 USING INDEX e (t_end<?)"]) > plan_cost(
    ...     ["SEARCH n0 USING INDEX s (t_start>?)"])
    True
    """
    scans = sorts = bound = 0
    for step in steps:
        if "AUTOMATIC" in step or (step.startswith("SCAN ")
                                   and not step.startswith("SCAN CONSTANT ROW")):
            scans += 1
        if "USE TEMP B-TREE" in step:
            sorts += 1
        match = _SEARCH_BOUNDS.match(step)
        if match:
            ranges: dict[str, set[str]] = {}
            for term in match.group(1).split(" AND "):
                ranged = _RANGE.match(term)
                if ranged is None:
                    bound += 4   # (=, IN, rowid=)
                else:
                    ranges.setdefault(ranged.group(1), set()).add(ranged.group(2)[0])
            bound += sum(3 if len(sides) > 1 else 1 if sides == {"<"} and column in _TIMES
                         else 2 for column, sides in ranges.items())
    return scans, sorts, -bound


_POINT = re.compile(r"\b(\w+)\.t_start = \1\.t_end\b")


def start_compared(sql: str, quoted: str) -> bool:
    """Whether ``sql`` compares the start time of the table ``quoted`` (one of its aliases'
    ``t_start`` after the statement's first ``FROM``, not in what it selects: a condition, a
    join, a subquery's order): where no planner can be asked, what its start-ordered
    indexes may serve.

    >>> start_compared('SELECT f(t1.t_start) AS v1 FROM "q" AS t1 WHERE t1.t_end > :c0',
    ...                '"q"')
    False
    >>> start_compared('SELECT 1 FROM "p" AS t0 CROSS JOIN "q" AS t1 '
    ...                'WHERE t0.t_start = t1.t_start', '"q"')
    True
    >>> start_compared('SELECT 1 FROM "q" AS t0 WHERE t0.t_start = t0.t_end', '"q"')
    False
    """
    # (a point event's own start = end is no search)
    body = _POINT.sub("", sql.partition(" FROM ")[2])
    return any(re.search(rf"\b{re.escape(alias)}\.t_start\b", body)
               for alias in re.findall(re.escape(quoted) + r" AS (\w+)", sql))


def _refused_for_good(exc: BaseException) -> bool:
    """Whether a failed build of indexes will fail again (this connection may not write the
    table's indexes: not the table's owner on a server, a read-only file), not a condition
    that may pass (busy, the disk full, the server short of resources or gone)."""
    if isinstance(exc, SLRUnavailable):
        return False
    # (SQLite's own errors carry their code; the SLRError Database.failure said one in
    # words is raised while handling it)
    code = getattr(exc, "sqlite_errorcode", None)
    if code is None and isinstance(exc, SLRError):
        code = getattr(exc.__context__, "sqlite_errorcode", None)
    if code is not None:
        return code & 0xFF in _REFUSED_FOR_GOOD
    # a server's refusal (PgStatementError: not the table's owner) or a read-only SLRError
    return True


def _index_names(table: str) -> list[str]:
    return [f"slr_ix__{table}__{suffix}" for suffix in ("end", "start", "a1_end", "a1_start")]


class EventTables:
    """The event types of one database, cached from ``slr_event_types``.

    >>> tables = EventTables(Database(None)); tables.declare_type("seg", 2)
    'seg'
    >>> tables.lookup("seg", 2).insert_sql
    'INSERT INTO "seg" (arg1, arg2, t_start, t_end, arrival, robot) VALUES (?, ?, ?, ?, ?, ?)'
    """

    def __init__(self, db: Database):
        self.db = db
        self.types: dict[tuple[str, int], EventType] = {}
        self.declared_arities: dict[str, set[int]] = {}
        # buffers: called as hook(name, arity, table) inside the transaction that
        # creates a new event type's table (slr_sql.buffers installs its triggers there)
        self.table_created_hooks: list[Callable[[str, int, str], Any]] = []
        # the planner's views: called as hook([(name, arity, table), ...]) once per batch
        # of new tables (batch(): an add), inside its transaction after
        # the batch's work; a table made outside a batch is a batch of its own. And the
        # names (lower case) such a hook may give to what it creates: a new table whose
        # name could be one of them is named after the pending hooks ran, as it would be
        # had they run at each table
        self.tables_created_hooks: list[Callable[[list[tuple[str, int, str]]], Any]] = []
        self.batch_names: list[Callable[[], Iterable[str]]] = []
        self._batch_depth = 0
        self._batch_new: list[tuple[str, int, str]] = []
        # types created inside were rolled back too, and indexes built inside
        db.rollback_listeners.append(self._rolled_back)
        # tables whose start-ordered indexes this connection may not build (refused for
        # good): looked for in the catalog only, not tried again by every reader
        self._refused: set[str] = set()
        # tables whose build last met another session's lock: the store clock's time then,
        # and the lookups that skipped the build since (not tried again until the clock
        # moved on by START_ORDER_RETRY, or START_ORDER_RETRY_LOOKUPS lookups skipped it)
        self._busy: dict[str, tuple[float, int]] = {}
        # start-ordered indexes were built inside a transaction not committed yet; and how
        # many rollbacks may have taken such a build back (who built statements after a
        # build, knowing the index there, asks again when it moved)
        self._built_inside = False
        self.builds_undone = 0
        # the types could not be read again after a rollback: read at the next use
        self._stale = False
        # The most data arguments an event can have: its table has 5 more columns (seq,
        # t_start, t_end, arrival, robot) and the engine refuses tables wider than its limit.
        self.max_arity = db.max_columns - 5
        self.reload()

    def _rolled_back(self) -> None:
        if self._built_inside:
            self.builds_undone += 1
            # (a nested part rolled back may leave a build of the enclosing transaction
            # standing, which the outer rollback takes back: counted again then)
            if not self.db.tx_depth:
                self._built_inside = False
        # (the old objects too: a reader holding one must not trust a build taken back)
        for event_type in self.types.values():
            event_type.start_order = None
        try:
            self.reload(keep_start_order=False)
        except BaseException:
            # (the store unreadable now: a server that ended the connection and none to be
            # had, a damaged file) the cache may hold a type the rollback took back: every
            # type is read again at the next use under the lock (lookup, declared_types,
            # event_types); what a reader without the lock sees in the meantime trusts no
            # start-ordered index (reset above)
            self._stale = True
            raise

    def _fresh(self) -> None:
        """Read the types again if a rollback could not (lock held by the caller)."""
        if self._stale:
            self.reload(keep_start_order=False)

    def _kept(self) -> None:
        self._built_inside = False

    def reload(self, keep_start_order: bool = True) -> None:
        """Read every type again (others may have created some; a rollback undid some).
        A type known to have its start-ordered indexes keeps that knowledge (no index is
        ever dropped), unless ``keep_start_order`` is false: after a rollback, which may
        have taken back a build."""
        known = {(t.name, t.arity, t.table) for t in self.types.values() if t.start_order} \
            if keep_start_order else set()
        types: dict[tuple[str, int], EventType] = {}
        declared: dict[str, set[int]] = {}
        if not self.db.closed:
            for name, arity, table, is_declared in self.db.execute(
                    "SELECT name, arity, table_name, declared FROM slr_event_types"):
                types[(name, arity)] = EventType(name, arity, table, bool(is_declared),
                                                 True if (name, arity, table) in known else None)
                if is_declared:
                    declared.setdefault(name, set()).add(arity)
        self.types = types
        self.declared_arities = declared
        self._stale = False

    def lookup(self, name: str, arity: int) -> EventType | None:
        """The type name/arity, or None if it has no table (lock held by the caller)."""
        if self._stale:   # (inline: every add looks its type up)
            self._fresh()
        event_type = self.types.get((name, arity))
        if event_type is None and "\x00" in name and not self.db.dialect.text_holds_nul:
            return None   # a name this database cannot hold was never stored
        if event_type is None:
            # another connection (process) may have created it since we last looked
            rows = self.db.execute(
                "SELECT table_name, declared FROM slr_event_types WHERE name = ? AND arity = ?",
                (str(name), arity))
            if rows:
                row = rows[0]
                event_type = EventType(str(name), arity, row[0], bool(row[1]))
                self.types[(str(name), arity)] = event_type
                if row[1]:
                    self.declared_arities.setdefault(str(name), set()).add(arity)
        return event_type

    def _choose_table_name(self, name: str, arity: int) -> str:
        base = self._table_base(name, arity)
        if self._batch_new and self.batch_names:
            # (the candidates below: base, base__<arity>, base__<arity>_<n>)
            lowered = base.lower()
            longer = lowered + "__"
            if any(claimed == lowered or claimed.startswith(longer)
                   for names in self.batch_names for claimed in names()):
                self._run_batch_hooks()
        taken = self.db.object_names()

        def free(candidate: str) -> bool:
            return all(n.lower() not in taken for n in [candidate] + _index_names(candidate))

        if free(base):
            return base
        candidate = f"{base}__{arity}"
        suffix = 2
        while not free(candidate):
            candidate = f"{base}__{arity}_{suffix}"
            suffix += 1
        return candidate

    def _table_base(self, name: str, arity: int) -> str:
        """The first name tried for the table of name/arity."""
        lowered = name.lower()
        if (SAFE_IDENTIFIER.match(name) and not lowered.startswith(RESERVED_PREFIXES)
                and lowered not in SQL_KEYWORDS):
            base = name
        else:
            base = "ev_" + re.sub(r"[^A-Za-z0-9_]", "_", name)
        if self.db.dialect.identifier_bytes is not None and len(base) > _LONG_TABLE:
            # an engine that cuts names (PostgreSQL: 63 bytes) would give the table's four
            # indexes (slr_ix__<table>__a1_start, ...) and the event rules' ones one name
            base = _shortened(base, name, arity)
        return base

    @contextmanager
    def batch(self) -> Iterator[None]:
        """The tables made inside are one batch (lock held, inside the transaction that
        makes them; batches nest): :attr:`tables_created_hooks` run once, as the outermost
        ends without an error, in the same transaction (a failing batch's tables are taken
        back with it).

        >>> tables = EventTables(Database(None)); seen = []
        >>> tables.tables_created_hooks.append(seen.append)
        >>> with tables.batch():
        ...     _ = tables.declare_type("a", 1); _ = tables.declare_type("b", 0); print(seen)
        []
        >>> seen
        [[('a', 1, 'a'), ('b', 0, 'b')]]
        """
        self._batch_depth += 1
        ok = False
        try:
            yield
            ok = True
        finally:
            try:
                if ok and self._batch_depth == 1 and self._batch_new:
                    self._run_batch_hooks()
            finally:
                self._batch_depth -= 1
                if not self._batch_depth:
                    self._batch_new = []

    def _run_batch_hooks(self) -> None:
        new, self._batch_new = self._batch_new, []
        for hook in self.tables_created_hooks:  # the planner's views
            hook(new)

    def register(self, name: str, arity: int, declared: bool,
                 start_order: bool = False) -> EventType:
        """Create the table of a new type. Must run inside a write transaction. Its
        start-ordered indexes are left to :meth:`ensure_start_order`, unless
        ``start_order`` (an existing table is left as it is)."""
        existing = self.lookup(name, arity)
        if existing is None:
            # on a server, another process may be creating it now: take turns, look again
            self.db.lock_named("types")
            existing = self.lookup(name, arity)
        if existing is not None:
            if declared and not existing.declared:
                self.db.execute("UPDATE slr_event_types SET declared = 1 "
                                "WHERE name = ? AND arity = ?", (name, arity))
                existing.declared = True
                self.declared_arities.setdefault(name, set()).add(arity)
            return existing
        table = self._choose_table_name(name, arity)
        event_type = EventType(name, arity, table, declared, start_order)
        dialect = self.db.dialect
        # arg columns have no declared type on SQLite: it keeps INTEGER / REAL / TEXT as given
        # (PostgreSQL: TEXT spelling the type, see store/dialect.py)
        arg_columns = "".join(f", arg{i}{dialect.value}" for i in range(1, arity + 1))
        execute = self.db.execute
        real = dialect.real
        execute(f"CREATE TABLE {event_type.quoted} (seq {dialect.sequence_key}{arg_columns}, "
                f"t_start {real} NOT NULL, t_end {real} NOT NULL, arrival {real} NOT NULL, "
                "robot TEXT)")
        execute(f"CREATE INDEX {event_type.index_end} ON {event_type.quoted} (t_end, t_start)")
        if arity >= 1:
            for suffix, columns in dialect.key_indexes(["arg1"], ["t_end", "t_start"]):
                index = quote_identifier(event_type.index_arg1_end.strip('"') + suffix)
                execute(f"CREATE INDEX {index} ON {event_type.quoted} {columns}")
        if start_order:
            self._create_start_indexes(event_type)
        execute("INSERT INTO slr_event_types (name, arity, table_name, declared) "
                "VALUES (?, ?, ?, ?)", (name, arity, table, int(declared)))
        self.types[(name, arity)] = event_type
        if declared:
            self.declared_arities.setdefault(name, set()).add(arity)
        for hook in self.table_created_hooks:  # buffers
            hook(name, arity, table)
        if self.tables_created_hooks:
            self._batch_new.append((name, arity, table))
            if not self._batch_depth:
                self._run_batch_hooks()
        return event_type

    def _create_start_indexes(self, event_type: EventType) -> None:
        for statement in event_type.start_index_statements(self.db.dialect).values():
            self.db.execute(statement)

    def ensure_start_order(self, event_type: EventType) -> bool:
        """Whether ``event_type``'s start-ordered indexes exist, building them first when
        they do not (lock held by the caller). A type known to have them costs nothing; one
        not known is looked up in the catalog once (another process may have built them).

        The build (``CREATE INDEX IF NOT EXISTS``, the builders of one table taking turns
        on a server) runs in a transaction of its own, or as a savepoint of the current
        one: should that roll back, the reload of the types forgets what was built. Where
        no index can be built, the answer is False and the caller reads without naming the
        index: slower, never wrong. A build is never waited for (another connection's writer
        holds the lock: a later reader tries again); one this connection may not make (not
        the table's owner, a read-only file) is not tried again, only looked for in the
        catalog. A failed build takes back only itself: the store's rollback listeners are
        not called (nothing they know of changed). One that met another session's lock is
        not tried again before the store's clock has moved on by :data:`START_ORDER_RETRY`
        seconds, or :data:`START_ORDER_RETRY_LOOKUPS` lookups skipped it (on a server a try
        is a round trip and a 1 ms lock wait): the readers in between read without the
        index, and a clock that never moves still gets the build.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); _ = s.declare_type("c", 1, start_order=False)
        >>> sorted(s.index_names("c"))
        ['slr_ix__c__a1_end', 'slr_ix__c__end']
        >>> s.ensure_start_order("c", 1), len(s.index_names("c"))
        (True, 4)
        """
        if event_type.start_order:
            return True
        db = self.db
        # (end, start, a1_end, a1_start: a type without arguments has no a1_ ones)
        wanted = _index_names(event_type.table)[1::2][:2 if event_type.arity else 1]
        if set(wanted) <= db.index_names(event_type.table):
            event_type.start_order = True
            return True
        table = event_type.table
        if table in self._refused:
            return False
        busy = self._busy.get(table)
        if busy is not None:
            busy_since, skipped = busy
            if 0.0 <= db.clock.now() - busy_since < START_ORDER_RETRY \
                    and skipped + 1 < START_ORDER_RETRY_LOOKUPS:
                # (a clock gone back, or not a number, tries again)
                self._busy[table] = (busy_since, skipped + 1)
                return False
        try:
            # (not waiting for another connection's writer: a reader in start order must
            # not wait the busy timeout on every lookup while a writer holds its lock, and
            # a builder inside a transaction must not deadlock with one; it reads without
            # the index, and a reader tries again once the clock moved on. Its rollback
            # undoes only the build: the listeners -- types forgetting their start order,
            # the event rules reading their pending summaries again -- are not called)
            with db.transaction(wait=False, listeners=False):
                # (not the types' lock: a writer may hold it while it waits for this table)
                db.lock_named(f"start order {table}")
                self._create_start_indexes(event_type)
        except (DatabaseError, SLRError) as exc:
            if db.closed:
                raise
            if _refused_for_good(exc):
                # (a connection that may not build them never will: one try is enough)
                self._refused.add(table)
            else:
                self._busy[table] = (db.clock.now(), 0)
            return False
        self._busy.pop(table, None)
        if db.tx_depth:   # (inside the caller's transaction: it may still roll back)
            self._built_inside = True
            db.after_commit(self._kept)
        # (a rollback of an enclosing transaction reloads the types: this one is gone then)
        current = self.types.get((event_type.name, event_type.arity))
        if current is not None:
            current.start_order = True
        event_type.start_order = True
        return True

    def start_orders_wanted(self, sql: str) -> set[tuple[str, int]] | None:
        """The event types read by ``sql`` (their tables named in it) whose start-ordered
        indexes make its plan better; None where the backend cannot say (PostgreSQL: the
        caller decides). A type known to have them is not asked about.

        SQLite's planner is asked for the plan with every missing start-ordered index there
        (:meth:`Database.hypothetical_plan`); a type whose indexes that plan uses is asked
        about again without them: wanted only if the plan is then worse (:func:`plan_cost`:
        a full scan or a sort more, or fewer columns bound by its searches). Beyond
        :data:`START_ORDER_ONE_BY_ONE` such types they are asked about together: all wanted
        when the plan without any of them is worse, else none. So ``t_start =
        ? AND t_end = ?`` wants none (the end order binds both), ``arg1 = ? AND t_start > ?``
        does. The judgement is remembered with the copy's plans (:meth:`Database.plan_memo`)
        for the statement's text and the types it found lacking.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); _ = s.declare_type("b", 1)
        >>> tables = s._tables
        >>> tables.start_orders_wanted('SELECT seq FROM "b" WHERE arg1 = :k AND t_start > :t')
        {('b', 1)}
        >>> tables.start_orders_wanted('SELECT seq FROM "b" WHERE t_start = :s AND t_end = :e')
        set()
        """
        lacking = [t for t in self.types.values() if not t.start_order and t.quoted in sql]
        if not lacking:
            return set()
        # (judged once per statement text and types lacking them while the schema stays:
        # a query compiled again for another constant has the same text)
        memo = self.db.plan_memo()
        key = ("start orders wanted", sql, frozenset((t.name, t.arity) for t in lacking))
        if memo is not None and key in memo:
            return set(memo[key])
        wanted = self._start_orders_wanted(sql, lacking)
        if memo is not None and wanted is not None:
            memo[key] = frozenset(wanted)
        return wanted

    def _start_orders_wanted(self, sql: str,
                             lacking: list[EventType]) -> set[tuple[str, int]] | None:
        extra: dict[str, str] = {}
        own: dict[tuple[str, int], list[str]] = {}
        for event_type in lacking:
            statements = event_type.start_index_statements(self.db.dialect)
            extra.update(statements)
            own[(event_type.name, event_type.arity)] = list(statements)
        steps = self.db.hypothetical_plan(sql, extra)
        if steps is None:
            return None
        used = " ".join(steps)
        using = {key: names for key, names in own.items()
                 if any(f" {name} " in f"{used} " for name in names)}
        if len(using) > START_ORDER_ONE_BY_ONE:
            # (a statement over many types -- an event rule of many parts -- is asked once
            # without all of them: a plan of a join of 30 tables took SQLite ~10 ms, and
            # one per type was a second per statement, the most of a first add's time)
            without = self.db.hypothetical_plan(
                sql, extra, without=[name for names in using.values() for name in names])
            if without is not None and plan_cost(without) <= plan_cost(steps):
                return set()
            return set(using)
        wanted = set()
        for key, names in using.items():
            without = self.db.hypothetical_plan(sql, extra, without=names)
            if without is None or plan_cost(without) > plan_cost(steps):
                wanted.add(key)
        return wanted

    def declare_type(self, name: str, arity: int, start_order: bool = False) -> str:
        """Declare event type name/arity (``:- event name/arity.``); returns its table name.

        Once a name is declared with some arity, events of that name with an arity that is
        neither declared nor already stored are rejected as a wrong-arity mistake.
        A new table gets its start-ordered indexes when a reader first needs them
        (:meth:`ensure_start_order`), or at once with ``start_order=True``; an existing
        table is left as it is.

        >>> from slr_sql.store import EventStore
        >>> EventStore(None).declare_type("seg", 2)
        'seg'
        """
        if not isinstance(name, str) or not isinstance(arity, int) or arity < 0:
            raise ValueError(f"bad event type {name!r}/{arity!r}")
        if arity > self.max_arity:
            raise SLRError(f"cannot declare event {name}/{arity}: too many arguments (an "
                           f"event has at most {self.max_arity}, the column limit of the store's tables)")
        with self.db.transaction():
            return self.register(str(name), arity, declared=True,
                                 start_order=start_order).table

    def event_types(self) -> dict[tuple[str, int], str]:
        """Every known event type ``(name, arity)`` -> its table name.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.declare_type("seg", 2); s.event_types()
        'seg'
        {('seg', 2): 'seg'}
        """
        with self.db.lock:
            self.db.check_open()
            if not self.db.tx_depth:
                self.reload()  # pick up types other processes created
            else:
                self._fresh()
            return {key: t.table for key, t in self.types.items()}

    def declared_types(self) -> set[tuple[str, int]]:
        """The types declared with :meth:`declare_type` (not merely created by an event).

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.declare_type("seg", 2); sorted(s.declared_types())
        'seg'
        [('seg', 2)]
        """
        with self.db.lock:
            self.db.check_open()
            self._fresh()
            return {key for key, t in self.types.items() if t.declared}

    def table_for(self, name: str, arity: int) -> str | None:
        """The table holding events of name/arity, or None if there is none yet.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.table_for("seg", 2) is None
        True
        """
        with self.db.lock:
            self.db.check_open()
            event_type = self.lookup(name, arity)
            return None if event_type is None else event_type.table

    def event_table_sql(self, name: str, arity: int) -> str | None:
        """The quoted table of an event type (for compiled SQL), or None if it has none.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.add_event("my event", (), 1, 1); s.event_table_sql("my event", 0)
        '"ev_my_event"'
        """
        event_type = self.types.get((name, arity))
        if event_type is None:
            with self.db.lock:
                self.db.check_open()
                event_type = self.lookup(name, arity)
        return None if event_type is None else event_type.quoted
