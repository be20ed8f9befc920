"""What the store keeps besides events: program text, meta keys, buffers, fact tables, views.

* ``slr_program``: every loaded program text with the name of the program it belongs to, in
  load order (a reopened store reloads it); ``version/program`` in ``slr_meta`` counts its
  changes, so that every connection can tell cheaply that another one changed the program.
* ``slr_meta``: JSON values by key (delays, view names, settings of other modules); values
  that must only grow (learned delays, completeness marks) are written by
  :meth:`Catalog.meta_raise`, which keeps the larger of the stored and the new value.
* ``slr_buffers`` / ``slr_counters`` (migrations/0002_buffers.sql): one row per event-history
  buffer with its counters; its schema objects are named ``slr_buf_<id>_*`` (triggers) and
  ``slr_bix_<id>`` (indexes); :mod:`.buffering` prints and installs them.
* ``slr_facts_<arity>_<name>`` (``ord, arg1..argN``) tables and the inspection views of
  derived predicates, written by the SQL compiler (view names kept in ``slr_meta`` under
  ``sql_views``; ``facts/version`` is the program version they were built for). Names are
  derived so that any Prolog name works: see :meth:`Catalog.fact_table_name` and
  :meth:`Catalog.view_name`.
"""
from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass
from typing import Any, Iterable

from .connection import Database, DatabaseError
from .sqltext import RESERVED_PREFIXES, quote_identifier, sql_literal


def sql_text_literal(text: str) -> str:
    """A text constant for a statement that cannot take parameters (a function body).

    >>> sql_text_literal("it's"), sql_text_literal("cup1")
    ("'it''s'", "'cup1'")
    """
    return sql_literal(text)

__all__ = ["Catalog", "ProgramText", "PROGRAM_VERSION", "PROGRESS_VERSION",
           "FACTS_VERSION"]

PROGRAM_VERSION = "version/program"    # bumped with every change of slr_program
PROGRESS_VERSION = "version/progress"  # bumped whenever meta_raise raises a value
FACTS_VERSION = "facts/version"        # the program version the fact tables were built for
# the advisory lock of meta_raise on a server (b"slr_rais": apart from the writer groups' hashes)
_RAISE_LOCK = int.from_bytes(b"slr_rais", "big")

# id NULL: the next id, as SQLite's rowid would choose it (spelled out for other engines)
_INSERT_TEXT = ("INSERT INTO slr_program (id, name, source, filename, loaded_at) VALUES "
                "(coalesce(?, (SELECT coalesce(max(id), 0) + 1 FROM slr_program)), ?, ?, ?, ?) "
                "RETURNING id")


@dataclass(frozen=True)
class ProgramText:
    """One stored program text: its row id (load order), program name, text, file name and
    the store clock's time when it was loaded."""

    id: int
    name: str
    source: str
    filename: str | None
    loaded_at: float | None


# One read of what another connection may have changed (a server): the change counter, the
# program and progress versions, whether a tBuffer is active
_CHANGE_CHECK = (
    "SELECT pg_snapshot_xmax(pg_current_snapshot())::text::bigint AS slr_counter, "
    "(SELECT value FROM slr_meta WHERE key = ?) AS slr_program, "
    "(SELECT value FROM slr_meta WHERE key = ?) AS slr_progress, "
    "EXISTS (SELECT 1 FROM slr_buffers WHERE kind = 'tBuffer' "
    "AND removed_at IS NULL) AS slr_timed")


def _number_text(value: float) -> str:
    """A float as JSON text that SQLite's ``CAST(... AS REAL)`` reads back exactly
    (``1e999`` for infinity, which both JSON and SQLite read as infinity)."""
    if value == math.inf:
        return "1e999"
    if value == -math.inf:
        return "-1e999"
    return repr(float(value))


def _stored_number(dialect: Any) -> str:
    """The stored number of a meta value, in SQL (texts written by json.dumps may spell
    infinity)."""
    return (f"(CASE slr_meta.value WHEN 'Infinity' THEN {dialect.infinity()} "
            f"WHEN '-Infinity' THEN {dialect.infinity(negative=True)} "
            f"ELSE CAST(slr_meta.value AS {dialect.real}) END)")


def _escape_name(name: str) -> str:
    """An injective spelling of a name in lowercase letters, digits and ``_``: SQLite names
    are case-insensitive and may not hold NUL, Prolog names are neither. Lowercase letters
    and digits stay, ``_`` is ``__``, an uppercase letter is ``_`` and the letter, anything
    else ``_0<hex>_``."""
    out = []
    for c in name:
        if "a" <= c <= "z" or "0" <= c <= "9":
            out.append(c)
        elif c == "_":
            out.append("__")
        elif "A" <= c <= "Z":
            out.append("_" + c.lower())
        else:
            out.append(f"_0{ord(c):x}_")
    return "".join(out)


class Catalog:
    """Program text, meta keys, fact tables and views of one database.

    >>> from slr_sql.store import EventStore
    >>> s = EventStore(None); s.meta_set("k", [1]); s.meta_get("k")
    [1]
    """

    def __init__(self, db: Database):
        self.db = db
        # a server: the versions read with the last data_version, for the versions() call
        # that follows it (one round trip for the change check instead of two)
        self._read_with_change: tuple[int, int] | None = None

    def data_version(self) -> int:
        """The connection's change counter (see ``Database.data_version``). On a server the
        same statement reads the program and progress versions and whether a tBuffer is
        active, for the :meth:`versions` call that follows a move (they are as fresh as the
        counter: a later commit moves it again)."""
        if self.db.dialect.name == "sqlite":
            return int(self.db.data_version())
        with self.db.lock:
            [(counter, program, progress, timed)] = self.db.execute(
                _CHANGE_CHECK, (PROGRAM_VERSION, PROGRESS_VERSION))
            self._read_with_change = (int(program or 0), int(progress or 0))
            self.db.tbuffers_active = bool(timed)
            return int(counter)

    def owe_change_check(self, program_version: int) -> tuple[Any, Any] | None:
        """On a server, outside a transaction: the change check of an add that runs with
        the program of version ``program_version`` (and, with ``db.tbuffers_active``, the
        tBuffer flag last read), sent with the add's first statement instead of before
        it -- inside that statement when the add is one statement of inserts alone (one
        round trip: :class:`~slr_sql.store.postgres.WriteCheck`). A check that finds either
        moved stores nothing of the add and raises ``ChangedMeanwhile``. Returns ``(check,
        the check it stands in front of)`` for :meth:`settle_change_check`, or None (SQLite,
        memory, inside a transaction: the caller checks as every call does).

        >>> from slr_sql.store import EventStore
        >>> EventStore(None).owe_change_check(0) is None   # (SQLite: PRAGMA data_version)
        True
        """
        db = self.db
        if db.dialect.name == "sqlite" or db.tx_depth:
            return None
        from .postgres import WriteCheck   # (a server's store: psycopg is there)
        check = WriteCheck(
            f"SELECT *, CAST(coalesce(slr_program, '0') AS bigint) = %s AND (%s OR NOT "
            f"slr_timed) AS slr_fresh FROM ({db.dialect.statement(_CHANGE_CHECK)}) AS slr_read",
            (int(program_version), db.tbuffers_active is not False,
             PROGRAM_VERSION, PROGRESS_VERSION))
        return check, db.conn.owe(check)

    def settle_change_check(self, owed: tuple[Any, Any]) -> tuple[int, int, int] | None:
        """The add that owed the check is done with it: ``(counter, program version,
        progress version)`` as the check read them, or None when it was not sent or found
        the program moved (a server's: see :meth:`owe_change_check`)."""
        check, outer = owed
        with self.db.lock:
            self.db.conn.settle(check, outer)
        if check.row is None or check.failed:
            return None
        counter, program, progress, timed, _ = check.row
        self.db.tbuffers_active = bool(timed)
        return int(counter), int(program or 0), int(progress or 0)

    # ------------------------------------------------------------------ program

    def _bump(self, key: str) -> int:
        """Add one to the counter ``key`` (in the caller's transaction); returns the new value."""
        execute = self.db.execute
        execute("INSERT INTO slr_meta (key, value) VALUES (?, '1') "
                f"ON CONFLICT ({self.db.dialect.key('key')}) "
                "DO UPDATE SET value = CAST(slr_meta.value AS INTEGER) + 1", (key,))
        return int(execute("SELECT value FROM slr_meta WHERE key = ?", (key,))[0][0])

    def _counter(self, key: str) -> int:
        rows = self.db.execute("SELECT value FROM slr_meta WHERE key = ?", (key,))
        return int(rows[0][0]) if rows else 0

    def program_version(self) -> int:
        """How many times the stored program changed (0 for a store never loaded).

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); v = s.program_version(); s.append_program("p(1)."); s.program_version() - v
        1
        1
        """
        with self.db.lock:
            self.db.check_open()
            return self._counter(PROGRAM_VERSION)

    def versions(self) -> tuple[int, int]:
        """``(program version, progress version)``: what another connection may have
        changed (the program texts; learned delays and completeness marks), in one read.

        >>> from slr_sql.store import EventStore
        >>> EventStore(None).versions()
        (0, 0)
        """
        with self.db.lock:
            self.db.check_open()
            read, self._read_with_change = self._read_with_change, None
            if read is not None:
                return read
            if self.db.dialect.name == "sqlite":
                rows = dict(self.db.execute(
                    "SELECT key, value FROM slr_meta WHERE key IN (?, ?)",
                    (PROGRAM_VERSION, PROGRESS_VERSION)))
            else:
                # in the same read: whether a tBuffer is active (a server's adds record
                # "now" only then, see EventWriter.add_events)
                rows = dict(self.db.execute(
                    "SELECT key, value FROM slr_meta WHERE key IN (?, ?) UNION ALL "
                    "SELECT ?, count(*)::text FROM (SELECT 1 FROM slr_buffers WHERE kind = "
                    "'tBuffer' AND removed_at IS NULL LIMIT 1) AS timed",
                    (PROGRAM_VERSION, PROGRESS_VERSION, "tbuffers")))
                self.db.tbuffers_active = rows.get("tbuffers") == "1"
        return int(rows.get(PROGRAM_VERSION, 0)), int(rows.get(PROGRESS_VERSION, 0))

    def append_program(self, source: str, filename: str | None = None,
                       name: str = "main") -> int:
        """Persist one loaded program text under the program ``name``; returns its id (load
        order). Bumps the program version in the same transaction.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.append_program("p(1).", "a.slr"); s.program_sources()
        1
        [('p(1).', 'a.slr')]
        """
        with self.db.transaction():
            self.db.lock_named("program")
            text_id = self.db.execute(_INSERT_TEXT, (None, str(name), source, filename,
                                                     float(self.db.clock.now())))[0][0]
            self._bump(PROGRAM_VERSION)
            return text_id

    def replace_named_program(self, name: str, source: str, filename: str | None = None) -> int:
        """Make the program ``name`` the one text ``source``, in the place of its first text
        (appended if there is no such program); returns the text's id. Atomic; bumps the
        program version.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); _ = s.append_program("a(1).", None, "a"); _ = s.append_program("b.", None, "b")
        >>> _ = s.replace_named_program("a", "a(2)."); [(t.name, t.source) for t in s.program_texts()]
        [('a', 'a(2).'), ('b', 'b.')]
        """
        with self.db.transaction():
            self.db.lock_named("program")
            execute = self.db.execute
            first = execute("SELECT min(id) FROM slr_program WHERE name = ?",
                            (str(name),))[0][0]
            execute("DELETE FROM slr_program WHERE name = ?", (str(name),))
            text_id = execute(_INSERT_TEXT, (first, str(name), source, filename,
                                             float(self.db.clock.now())))[0][0]
            self._bump(PROGRAM_VERSION)
            return text_id

    def delete_program(self, name: str) -> int:
        """Remove every text of the program ``name``; returns how many there were (the
        program version moves only if some were removed).

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); _ = s.append_program("a.", None, "a"); s.delete_program("a"), s.delete_program("a")
        (1, 0)
        """
        with self.db.transaction():
            self.db.lock_named("program")
            removed = len(self.db.execute("DELETE FROM slr_program WHERE name = ? "
                                          "RETURNING id", (str(name),)))
            if removed:
                self._bump(PROGRAM_VERSION)
            return removed

    def program_texts(self) -> list[ProgramText]:
        """Every stored program text, in load order.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); _ = s.append_program("p(1).", "a.slr", "tea"); s.program_texts()[0].name
        'tea'
        """
        return [ProgramText(*row) for row in self.db.execute(
            "SELECT id, name, source, filename, loaded_at FROM slr_program ORDER BY id")]

    def program_sources(self) -> list[tuple[str, str | None]]:
        """Every persisted program text with its file name, in load order.

        >>> from slr_sql.store import EventStore
        >>> EventStore(None).program_sources()
        []
        """
        return [(text.source, text.filename) for text in self.program_texts()]

    def replace_program(self, sources: Iterable[tuple[str, str | None]]) -> None:
        """Replace the persisted program by ``sources`` (``(text, filename)`` pairs, all in
        the program "main"), atomically.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.append_program("a.", None); s.replace_program([("b.", None)])
        1
        >>> s.program_sources()
        [('b.', None)]
        """
        with self.db.transaction():
            self.db.lock_named("program")
            self.db.execute("DELETE FROM slr_program")
            now = float(self.db.clock.now())
            for source, filename in sources:
                self.db.execute(_INSERT_TEXT, (None, "main", source, filename, now))
            self._bump(PROGRAM_VERSION)

    # ------------------------------------------------------------------ meta keys

    def meta_get(self, key: str, default: Any = None) -> Any:
        """A persisted JSON value from ``slr_meta``, or ``default``.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.meta_set("delay/seg/2", 0.5); s.meta_get("delay/seg/2")
        0.5
        """
        rows = self.db.execute("SELECT value FROM slr_meta WHERE key = ?", (key,))
        return json.loads(rows[0][0]) if rows else default

    def meta_set(self, key: str, value: Any) -> None:
        """Persist a JSON-serializable value under ``key`` (replacing any previous one).

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.meta_set("k", {"a": [1, 2]}); s.meta_get("k")
        {'a': [1, 2]}
        """
        text = json.dumps(value)
        with self.db.transaction():
            self.db.execute("INSERT INTO slr_meta (key, value) VALUES (?, ?) "
                            f"ON CONFLICT ({self.db.dialect.key('key')}) "
                            "DO UPDATE SET value = excluded.value",
                            (key, text))

    def meta_raise(self, key: str, value: float) -> float:
        """Store the number ``value`` under ``key`` unless the stored number is already as
        large, in one statement that compares inside SQLite (so a writer whose own copy is
        behind never lowers what another wrote); returns the number stored now. When it
        grows, the progress version moves in the same transaction.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.meta_raise("mark", 50.0), s.meta_raise("mark", 20.0)
        (50.0, 50.0)
        """
        value = float(value)
        if value != value:
            raise ValueError(f"{key}: NaN cannot be stored as a growing value")
        if self.db.dialect.name != "sqlite":
            # a server locks the row an upsert meets even when its WHERE keeps the value:
            # every writer of the type would wait for the others' commits. Read first.
            rows = self.db.execute("SELECT value FROM slr_meta WHERE key = ?", (key,))
            if rows and float(json.loads(rows[0][0])) >= value:
                return float(json.loads(rows[0][0]))
        with self.db.transaction():
            execute = self.db.execute
            dialect = self.db.dialect
            if dialect.name != "sqlite":
                # the writers of growing values take one lock first, held to their commit:
                # a transaction raising two values (a batch's marks) holds the first's row
                # and the progress counter while it writes the second, and another writer
                # of that second value would wait for the counter -- a deadlock. (SQLite
                # has one writer at a time.)
                execute("SELECT pg_advisory_xact_lock(?)", (_RAISE_LOCK,))
            # 1e999 (infinity in SQLite's CAST) is out of a PostgreSQL float's range
            text = _number_text(value) if dialect.infinity() == "9e999" or math.isfinite(value) \
                else json.dumps(value)
            # (a row comes back when the value was written: inserted, or raised)
            changed = execute(
                "INSERT INTO slr_meta (key, value) VALUES (?, ?) "
                f"ON CONFLICT ({dialect.key('key')}) DO UPDATE SET value = excluded.value "
                f"WHERE {_stored_number(dialect)} < CAST(excluded.value AS {dialect.real}) "
                "RETURNING 1", (key, text))
            if changed:
                self._bump(PROGRESS_VERSION)
            stored = execute("SELECT value FROM slr_meta WHERE key = ?", (key,))[0][0]
        return float(json.loads(stored))

    def meta_delete(self, key: str) -> None:
        """Remove ``key`` from ``slr_meta`` (no error if absent).

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.meta_set("k", 1); s.meta_delete("k"); s.meta_get("k", 0)
        0
        """
        with self.db.transaction():
            self.db.execute("DELETE FROM slr_meta WHERE key = ?", (key,))

    def meta_items(self, prefix: str = "") -> dict[str, Any]:
        """Every ``slr_meta`` entry whose key starts with ``prefix``.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.meta_set("delay/a", 1); s.meta_items("delay/")
        {'delay/a': 1}
        """
        rows = self.db.execute(
            "SELECT key, value FROM slr_meta WHERE substr(key, 1, ?) = ? ORDER BY key",
            (len(prefix), prefix))
        return {key: json.loads(value) for key, value in rows}

    # ------------------------------------------------------------------ fact tables and views

    def _fact_table(self, name: str, arity: int) -> str:
        """:meth:`fact_table_name`, cut on an engine that cuts names (PostgreSQL, 63 bytes)
        with a digest of the predicate, so that its index (``slr_facts_ix_...``, 3 longer)
        and a second long name sharing its beginning get names of their own."""
        plain = self.fact_table_name(name, arity)
        if self.db.dialect.identifier_bytes is None or len(plain) <= 60:
            return plain
        digest = hashlib.sha1(f"{name}/{arity}".encode()).hexdigest()[:12]
        return f"{plain[:47]}_{digest}"

    @staticmethod
    def fact_table_name(name: str, arity: int) -> str:
        """``slr_facts_<arity>_<name>``, the name spelled so that every Prolog name gets a
        table of its own (SQLite names ignore case and cannot hold NUL): lowercase letters
        and digits as they are, ``_`` doubled, an uppercase letter as ``_`` and the letter,
        any other character as ``_0<hex>_``.

        >>> Catalog.fact_table_name("usedFor", 2), Catalog.fact_table_name("a b", 1)
        ('slr_facts_2_used_for', 'slr_facts_1_a_020_b')
        """
        return f"slr_facts_{int(arity)}_{_escape_name(name)}"

    @staticmethod
    def view_name(name: str) -> str:
        """The name of the inspection view of the predicate ``name``: the name itself, with
        NUL written ``\\0`` and ``v_`` before a name that starts with a prefix SQLite or
        slr_sql reserve (``sqlite_``, ``slr_``, any case) or is empty.

        >>> Catalog.view_name("color"), Catalog.view_name("sqlite_foo"), Catalog.view_name("SLR_x")
        ('color', 'v_sqlite_foo', 'v_SLR_x')
        """
        name = name.replace("\0", "\\0")
        if not name or name.lower().startswith(RESERVED_PREFIXES):
            return "v_" + name
        return name

    def facts_version(self) -> int:
        """The program version the fact tables and views were last built for (0: never).

        >>> from slr_sql.store import EventStore
        >>> EventStore(None).facts_version()
        0
        """
        with self.db.lock:
            self.db.check_open()
            return self._counter(FACTS_VERSION)

    def replace_fact_tables(self, tables: dict[tuple[str, int], list[tuple]],
                            version: int | None = None) -> dict:
        """Make the ``slr_facts_*`` tables exactly ``{(name, arity): [encoded rows]}`` (rows
        in clause order; ``ord`` is the position). Returns ``{(name, arity): quoted table}``.
        ``version``: the program version they are built for (recorded with them). A
        predicate wider than a table may be (the store's column limit) gets no table.

        >>> from slr_sql.store import EventStore
        >>> EventStore(None).replace_fact_tables({("color", 2): [("cup1", "red")]})
        {('color', 2): '"slr_facts_2_color"'}
        """
        out = {}
        with self.db.transaction():
            execute = self.db.execute
            # the inspection views read these tables: PostgreSQL refuses to drop a table a
            # view depends on, so they go first and come back over the new tables
            views = self.db.view_statements(self.meta_get("sql_views", []))
            for name in views:
                execute(f"DROP VIEW {self.db.qualified(name)}")
            existing = sorted(name for name in self.db.table_names()
                              if name.startswith("slr_facts_"))
            for table in existing:
                execute(f"DROP TABLE {self.db.qualified(table)}")
            for (name, arity), rows in tables.items():
                if arity + 1 > self.db.max_columns:
                    # Prolog takes any arity; a table has a column limit. Such facts stay
                    # in the program (interpreted, or unfolded by the compiler).
                    continue
                plain = self._fact_table(name, arity)
                table = quote_identifier(plain)
                dialect = self.db.dialect
                cols = "".join(f", arg{i}{dialect.value}" for i in range(1, arity + 1))
                execute(f"CREATE TABLE {table} (ord BIGINT PRIMARY KEY{cols})"
                        if dialect.to_column else
                        f"CREATE TABLE {table} (ord INTEGER PRIMARY KEY{cols})")
                if dialect.to_column is not None:
                    rows = [tuple(map(dialect.to_column, row)) for row in rows]
                if arity:
                    index = quote_identifier("slr_facts_ix_" + plain[len("slr_facts_"):])
                    execute(f"CREATE INDEX {index} ON {table}{dialect.equality_index} (arg1)")
                self.db.executemany(f"INSERT INTO {table} VALUES (?{', ?' * arity})",
                                    [(i,) + tuple(row) for i, row in enumerate(rows)])
                out[(name, arity)] = table
            kept = []
            for name, statement in views.items():
                try:
                    with self.db.transaction():   # a savepoint: a view of a table now gone
                        execute(statement)
                    kept.append(name)
                except DatabaseError:
                    pass
            if views:
                self.meta_set("sql_views", kept)
            if version is not None:
                execute("INSERT INTO slr_meta (key, value) VALUES (?, ?) "
                        f"ON CONFLICT ({self.db.dialect.key('key')}) DO UPDATE SET value "
                        "= excluded.value", (FACTS_VERSION, int(version)))
        return out

    def fact_tables_for(self, keys: Iterable[tuple[str, int]]) -> dict:
        """``{(name, arity): quoted table}`` of the fact tables that exist for ``keys``
        (read only: for a connection whose program the stored tables were built for).

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); _ = s.replace_fact_tables({("c", 1): [("x",)]})
        >>> s.fact_tables_for([("c", 1), ("d", 1)])
        {('c', 1): '"slr_facts_1_c"'}
        """
        with self.db.lock:
            self.db.check_open()
            present = {name for name in self.db.table_names() if name.startswith("slr_facts_")}
        out = {}
        for name, arity in keys:
            table = self._fact_table(name, arity)
            if table in present:
                out[(name, arity)] = quote_identifier(table)
        return out

    def create_rule_tables(self, prov: str, width: int, arity: int,
                           used: str | None = None) -> None:
        """An event rule's tables, unless they exist: ``prov`` (quoted) holds one row per
        complex event derived (``id``, the alternative, the seqs ``r1..r<width>`` of its
        events, its interval, its head arguments ``h1..h<arity>`` and when it was
        detected); ``used`` (quoted, optional) the rows a chronological rule consumed.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.create_rule_tables('"slr_cep_m_x"', 2, 1)
        >>> s.execute('SELECT count(*) FROM "slr_cep_m_x"')
        [(0,)]
        """
        dialect = self.db.dialect
        real = dialect.real
        cols = [f"id {dialect.integer_key}", "alt INTEGER NOT NULL"]
        cols += [f"r{p + 1} BIGINT" if dialect.to_column else f"r{p + 1} INTEGER"
                 for p in range(width)]
        cols += [f"t_start {real} NOT NULL", f"t_end {real} NOT NULL"]
        cols += [f"h{i + 1}{dialect.value}" for i in range(arity)]
        cols += [f"detected {real} NOT NULL"]
        with self.db.transaction():
            self.db.lock_named("program")   # two processes installing the same rule
            self.db.execute(f"CREATE TABLE IF NOT EXISTS {prov} ({', '.join(cols)})")
            if used:
                self.db.execute(
                    f"CREATE TABLE IF NOT EXISTS {used} (tbl TEXT NOT NULL, seq BIGINT NOT "
                    f"NULL, PRIMARY KEY (tbl, seq)){dialect.without_rowid}")

    def rule_matches(self, prov: str, width: int) -> list[tuple]:
        """What each complex event of an event rule is made of, as its provenance table
        ``prov`` (quoted, see :meth:`create_rule_tables`) records it: one row per complex
        event derived, in the order of derivation, of the seqs of its ``width`` events
        (``r1..r<width>``) and its interval (start, end).

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.create_rule_tables('"slr_cep_m_x"', 2, 1)
        >>> s.rule_matches('"slr_cep_m_x"', 2)
        []
        """
        columns = "".join(f"r{p + 1}, " for p in range(width))
        return [tuple(row) for row in self.db.execute(
            f"SELECT {columns}t_start, t_end FROM {prov} ORDER BY id")]

    def create_journal(self, table: str, arity: int, journal: str, trigger: str) -> None:
        """The journal of event table ``table`` (unless it exists): ``journal`` gets a row
        (``jid`` in arrival order, never reused; the event's ``seq``, arguments and times)
        for every row stored in ``table``, by the trigger ``trigger``, in the transaction
        that stores it. On a server the trigger also takes the journal's advisory lock
        until the commit (so ``jid`` order is commit order: a reader of ``jid > n`` misses
        nothing) and notifies the store's channel with the table's name.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.add_event("p", ("a",), 1, 1)
        >>> s.create_journal("p", 1, "slr_subj_p", "slr_subt_p"); s.add_event("p", ("b",), 2, 2)
        >>> s.execute('SELECT jid, seq, arg1 FROM "slr_subj_p"')
        [(1, 2, 'b')]
        """
        dialect = self.db.dialect
        j, t, name = quote_identifier(journal), quote_identifier(table), quote_identifier(trigger)
        args = [f"arg{i}" for i in range(1, arity + 1)]
        cols = "".join(f", {a}" for a in args)
        typed = "".join(f", {a}{dialect.value}" for a in args)
        real = dialect.real
        key = ("jid INTEGER PRIMARY KEY AUTOINCREMENT" if dialect.name == "sqlite"
               else "jid BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY")
        execute = self.db.execute
        with self.db.transaction():
            execute(f"CREATE TABLE IF NOT EXISTS {j} ({key}, seq BIGINT NOT NULL{typed}, "
                         f"t_start {real} NOT NULL, t_end {real} NOT NULL, "
                         f"arrival {real} NOT NULL)" if dialect.name != "sqlite" else
                         f"CREATE TABLE IF NOT EXISTS {j} ({key}, seq INTEGER NOT NULL{cols}, "
                         f"t_start REAL NOT NULL, t_end REAL NOT NULL, arrival REAL NOT NULL)")
            execute(f"CREATE INDEX IF NOT EXISTS {quote_identifier(journal + '__seq')} "
                    f"ON {j} (seq)")
            if dialect.name == "sqlite":
                new = "".join(f", NEW.{a}" for a in args)
                execute(f"CREATE TRIGGER IF NOT EXISTS {name} AFTER INSERT ON {t} BEGIN "
                        f"INSERT INTO {j} (seq{cols}, t_start, t_end, arrival) VALUES "
                        f"(NEW.seq{new}, NEW.t_start, NEW.t_end, NEW.arrival); END")
                return
            self.db.lock_named("journals")
            if trigger in self.db.triggers(table):
                return
            function = quote_identifier(trigger + "_f")
            lock = sql_text_literal(f"{self.db.schema}:journal:{table}")
            channel = sql_text_literal(self.db.notify_channel)
            # the body runs with the search path of the session that inserts, which may be
            # another client's (its own schemas, pg_temp first): the journal is named with
            # the store's schema, or that insert failed, or filled a temporary table of the
            # journal's name and the subscribers never saw its events
            execute(
                f"CREATE OR REPLACE FUNCTION {function}() RETURNS trigger LANGUAGE plpgsql AS "
                f"$slr$ BEGIN PERFORM pg_advisory_xact_lock(hashtext({lock})); "
                f"INSERT INTO {self.db.qualified(journal)} (seq{cols}, t_start, t_end, "
                f"arrival) SELECT seq{cols}, t_start, t_end, arrival FROM slr_new_rows "
                f"ORDER BY seq; "
                f"PERFORM pg_notify({channel}, {sql_text_literal(table)}); RETURN NULL; "
                f"END $slr$")
            execute(f"CREATE TRIGGER {name} AFTER INSERT ON {t} REFERENCING NEW TABLE "
                    f"AS slr_new_rows FOR EACH STATEMENT EXECUTE FUNCTION {function}()")

    def drop_journal(self, table: str, journal: str, trigger: str) -> None:
        """Drop the journal of ``table`` and its trigger (if they exist)."""
        # named with the schema (db.qualified): another process may have dropped them
        # already, and the name alone would then reach a temporary table of this session's
        qualified = self.db.qualified
        with self.db.transaction():
            if self.db.dialect.name == "sqlite":
                self.db.execute(f"DROP TRIGGER IF EXISTS {qualified(trigger)}")
            else:
                self.db.execute(f"DROP TRIGGER IF EXISTS {quote_identifier(trigger)} ON "
                                f"{qualified(table)}")
                self.db.execute(f"DROP FUNCTION IF EXISTS {qualified(trigger + '_f')}()")
            self.db.execute(f"DROP TABLE IF EXISTS {qualified(journal)}")

    def fact_view_select(self, table: str, arity: int) -> str:
        """The SELECT of the inspection view of a predicate whose clauses are facts, read
        from its fact table (``table`` quoted, as :meth:`replace_fact_tables` returns it) in
        clause order: ``arg1..argN``, for :meth:`replace_views`.

        >>> from slr_sql.store import EventStore
        >>> EventStore(None).fact_view_select('"slr_facts_2_color"', 2)
        'SELECT arg1, arg2 FROM "slr_facts_2_color" ORDER BY ord'
        """
        columns = ", ".join(f"arg{i + 1}" for i in range(arity))
        return f"SELECT {columns} FROM {table} ORDER BY ord"

    def replace_views(self, views: dict[str, str]) -> list[str]:
        """Drop the views created last time and create ``{predicate name: select sql}``,
        each named by :meth:`view_name` (a name already used by a table, index or earlier
        view is skipped, and so is one PostgreSQL refuses: a column it cannot type, a name
        that its 63-byte cut makes one taken). Returns the names created.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.replace_views({"answer": "SELECT 42 AS x", "slr_meta": "SELECT 1"})
        ['answer', 'v_slr_meta']
        """
        created = []
        with self.db.transaction():
            execute = self.db.execute
            # (with the schema: a view a user dropped leaves its name to a temporary one)
            for name in self.meta_get("sql_views", []):
                execute(f"DROP VIEW IF EXISTS {self.db.qualified(name)}")
            taken = self.db.object_names()
            for predicate, select in views.items():
                name = self.view_name(predicate)
                if name.lower() in taken:
                    continue
                if self.db.dialect.name == "sqlite":
                    execute(f"CREATE VIEW {quote_identifier(name)} AS {select}")
                else:
                    # a column has one type there (a branch's time, a number, and another's
                    # data value, text, in one argument), names are cut at 63 bytes: a view
                    # the server refuses is not made (the program loads, its queries answer)
                    try:
                        with self.db.transaction():   # a savepoint
                            execute(f"CREATE VIEW {quote_identifier(name)} AS {select}")
                    except DatabaseError:
                        continue
                created.append(name)
                taken.add(name.lower())
            self.meta_set("sql_views", created)
        return created
