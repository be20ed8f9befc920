"""What the store keeps besides events: program text, meta keys, buffers, fact tables, views.

* ``slr_program``: every loaded program text, in load order (a reopened store reloads it).
* ``slr_meta``: JSON values by key (delays, view names, settings of other modules).
* ``slr_buffers`` / ``slr_counters`` (migrations/0002_buffers.sql): one row per event-history
  buffer with its counters; its schema objects are named ``slr_buf_<id>_*`` (triggers) and
  ``slr_bix_<id>`` (indexes). slr_sql.buffers decides *what* they are; this runs the SQL.
* ``slr_facts_<name>_<arity>`` (``ord, arg1..argN``) tables and the inspection views of
  derived predicates, written by the SQL compiler (view names kept in ``slr_meta`` under
  ``sql_views``).
"""
from __future__ import annotations

import json
from typing import Any, Iterable

from .connection import Database
from .sqltext import SAFE_IDENTIFIER, quote_identifier

__all__ = ["Catalog", "BufferTables"]


class Catalog:
    """Program text, meta keys, fact tables and views of one database.

    >>> from slr_sql.store import EventStore
    >>> s = EventStore(None); s.meta_set("k", [1]); s.meta_get("k")
    [1]
    """

    def __init__(self, db: Database):
        self.db = db

    # ------------------------------------------------------------------ program

    def append_program(self, source: str, filename: str | None = None) -> int:
        """Persist one loaded program text; returns its id (load order).

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.append_program("p(1).", "a.slr"); s.program_sources()
        1
        [('p(1).', 'a.slr')]
        """
        with self.db.lock:
            self.db.check_open()
            cursor = self.db.conn.execute(
                "INSERT INTO slr_program (source, filename, loaded_at) VALUES (?, ?, ?)",
                (source, filename, float(self.db.clock.now())))
            return cursor.lastrowid

    def program_sources(self) -> list[tuple[str, str | None]]:
        """Every persisted program text with its file name, in load order.

        >>> from slr_sql.store import EventStore
        >>> EventStore(None).program_sources()
        []
        """
        with self.db.lock:
            self.db.check_open()
            return [(source, filename) for source, filename in self.db.conn.execute(
                "SELECT source, filename FROM slr_program ORDER BY id")]

    def replace_program(self, sources: Iterable[tuple[str, str | None]]) -> None:
        """Replace the persisted program by ``sources`` (``(text, filename)`` pairs), atomically.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.append_program("a.", None); s.replace_program([("b.", None)])
        1
        >>> s.program_sources()
        [('b.', None)]
        """
        with self.db.transaction():
            self.db.conn.execute("DELETE FROM slr_program")
            now = float(self.db.clock.now())
            self.db.conn.executemany(
                "INSERT INTO slr_program (source, filename, loaded_at) VALUES (?, ?, ?)",
                [(source, filename, now) for source, filename in sources])

    # ------------------------------------------------------------------ meta keys

    def meta_get(self, key: str, default: Any = None) -> Any:
        """A persisted JSON value from ``slr_meta``, or ``default``.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.meta_set("delay/seg/2", 0.5); s.meta_get("delay/seg/2")
        0.5
        """
        with self.db.lock:
            self.db.check_open()
            row = self.db.conn.execute("SELECT value FROM slr_meta WHERE key = ?",
                                       (key,)).fetchone()
        return default if row is None else json.loads(row[0])

    def meta_set(self, key: str, value: Any) -> None:
        """Persist a JSON-serializable value under ``key`` (replacing any previous one).

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.meta_set("k", {"a": [1, 2]}); s.meta_get("k")
        {'a': [1, 2]}
        """
        text = json.dumps(value)
        with self.db.lock:
            self.db.check_open()
            self.db.conn.execute("INSERT INTO slr_meta (key, value) VALUES (?, ?) "
                                 "ON CONFLICT(key) DO UPDATE SET value = excluded.value",
                                 (key, text))

    def meta_delete(self, key: str) -> None:
        """Remove ``key`` from ``slr_meta`` (no error if absent).

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.meta_set("k", 1); s.meta_delete("k"); s.meta_get("k", 0)
        0
        """
        with self.db.lock:
            self.db.check_open()
            self.db.conn.execute("DELETE FROM slr_meta WHERE key = ?", (key,))

    def meta_items(self, prefix: str = "") -> dict[str, Any]:
        """Every ``slr_meta`` entry whose key starts with ``prefix``.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.meta_set("delay/a", 1); s.meta_items("delay/")
        {'delay/a': 1}
        """
        with self.db.lock:
            self.db.check_open()
            rows = self.db.conn.execute(
                "SELECT key, value FROM slr_meta WHERE substr(key, 1, ?) = ? ORDER BY key",
                (len(prefix), prefix)).fetchall()
        return {key: json.loads(value) for key, value in rows}

    # ------------------------------------------------------------------ fact tables and views

    @staticmethod
    def fact_table_name(name: str, arity: int) -> str:
        """``slr_facts_<name>_<arity>`` (a hex name for names that are not identifiers).

        >>> Catalog.fact_table_name("usedFor", 2), Catalog.fact_table_name("a b", 1)
        ('slr_facts_usedFor_2', 'slr_facts_x612062_1')
        """
        safe = name if SAFE_IDENTIFIER.match(name) else "x" + name.encode("utf-8").hex()
        return f"slr_facts_{safe}_{arity}"

    def replace_fact_tables(self, tables: dict[tuple[str, int], list[tuple]]) -> dict:
        """Make the ``slr_facts_*`` tables exactly ``{(name, arity): [encoded rows]}`` (rows
        in clause order; ``ord`` is the position). Returns ``{(name, arity): quoted table}``.

        >>> from slr_sql.store import EventStore
        >>> EventStore(None).replace_fact_tables({("color", 2): [("cup1", "red")]})
        {('color', 2): '"slr_facts_color_2"'}
        """
        out = {}
        with self.db.transaction():
            conn = self.db.conn
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
        used by a table or index is skipped). Returns the names created.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.replace_views({"answer": "SELECT 42 AS x", "slr_meta": "SELECT 1"})
        ['answer']
        """
        created = []
        with self.db.transaction():
            conn = self.db.conn
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


class BufferTables:
    """The rows of ``slr_buffers`` / ``slr_counters`` and each buffer's triggers and indexes.

    >>> from slr_sql.store import EventStore
    >>> s = EventStore(None); s.insert_buffer("cBuffer", "program", "p(_)", "p", 1, 2.0,
    ...                                       None, None, "cBuffer(p(_), 2)")
    1
    >>> [(row["id"], row["kind"], row["pruned"]) for row in s.buffer_rows()]
    [(1, 'cBuffer', 0)]
    """

    def __init__(self, db: Database):
        self.db = db

    def buffer_rows(self, active_only: bool = True) -> list[dict[str, Any]]:
        """The rows of ``slr_buffers`` (oldest first) with their counters, as dicts.

        >>> from slr_sql.store import EventStore
        >>> EventStore(None).buffer_rows()
        []
        """
        where = " WHERE b.removed_at IS NULL" if active_only else ""
        with self.db.lock:
            self.db.check_open()
            cursor = self.db.conn.execute(
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
        with self.db.transaction():
            cursor = self.db.conn.execute(
                "INSERT INTO slr_buffers (kind, source, pattern_text, type_name, type_arity, "
                "amount, t1, t2, origin, created_at) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (kind, source, pattern_text, type_name, type_arity, amount, t1, t2, origin,
                 float(self.db.clock.now())))
            buffer_id = cursor.lastrowid
            self.db.conn.execute("INSERT OR IGNORE INTO slr_counters (buffer_id) VALUES (?)",
                                 (buffer_id,))
            return buffer_id

    def mark_buffer_removed(self, buffer_id: int) -> None:
        """Deactivate a buffer (its row and counters stay, for statistics)."""
        with self.db.transaction():
            self.db.conn.execute("UPDATE slr_buffers SET removed_at = ? WHERE id = ?",
                                 (float(self.db.clock.now()), int(buffer_id)))

    def count_buffer(self, buffer_id: int, pruned: int = 0, dropped: int = 0) -> None:
        """Add to a buffer's counters."""
        with self.db.transaction():
            self.db.conn.execute("UPDATE slr_counters SET pruned = pruned + ?, "
                                 "dropped = dropped + ? WHERE buffer_id = ?",
                                 (int(pruned), int(dropped), int(buffer_id)))

    def set_buffer_cutoff(self, buffer_id: int, cutoff: float) -> None:
        """Record the time before which a buffer has dropped events."""
        with self.db.transaction():
            self.db.conn.execute("UPDATE slr_buffers SET cutoff = ? WHERE id = ?",
                                 (float(cutoff), int(buffer_id)))

    def buffer_objects(self, buffer_id: int) -> dict[str, str]:
        """The triggers and indexes of one buffer: ``{name: sql}``."""
        with self.db.lock:
            self.db.check_open()
            rows = self.db.conn.execute(
                "SELECT name, sql FROM sqlite_master WHERE type IN ('trigger', 'index') "
                "AND (name LIKE ? ESCAPE '!' OR name = ?)",
                (f"slr!_buf!_{int(buffer_id)}!_%", f"slr_bix_{int(buffer_id)}")).fetchall()
        return {name: sql for name, sql in rows}

    def install_buffer_objects(self, buffer_id: int, statements: dict[str, str]) -> bool:
        """Make the triggers/indexes of ``buffer_id`` exactly ``statements`` (``{name: CREATE
        ...}``): objects whose SQL differs are re-created, missing ones created, others
        dropped. Returns True if anything changed."""
        with self.db.transaction():
            existing = self.buffer_objects(buffer_id)
            changed = False
            for name, sql in existing.items():
                if statements.get(name) != sql:
                    kind = "INDEX" if name.startswith("slr_bix_") else "TRIGGER"
                    self.db.conn.execute(f"DROP {kind} IF EXISTS {quote_identifier(name)}")
                    changed = True
            for name, sql in statements.items():
                if existing.get(name) != sql:
                    self.db.conn.execute(sql)
                    changed = True
            return changed

    def drop_buffer_objects(self, buffer_id: int) -> None:
        """Drop every trigger and index of one buffer."""
        self.install_buffer_objects(buffer_id, {})

    def prune(self, sql: str, buffer_id: int) -> int:
        """Run one buffer's DELETE statement (generated by slr_sql.buffers; constants in it
        come from :func:`sql_literal`) and add the deleted rows to its ``pruned`` counter."""
        with self.db.transaction():
            deleted = self.db.conn.execute(sql).rowcount
            if deleted > 0:
                self.db.conn.execute("UPDATE slr_counters SET pruned = pruned + ? "
                                     "WHERE buffer_id = ?", (deleted, int(buffer_id)))
            return max(deleted, 0)
