"""A new in-memory store gets its schema as a copy of one migrated earlier in the process
(store/schema.py, migrate_new_memory_store): the copy is what the migrations make."""
from __future__ import annotations

import sqlite3
import threading

import slr_sql
from slr_sql.store.schema import migrate, migrate_new_memory_store


def contents(conn: sqlite3.Connection) -> dict:
    """Everything a store's schema holds: its objects, the rows of its tables (bar the time
    each migration was applied), its header's versions and settings."""
    objects = conn.execute("SELECT type, name, tbl_name, sql FROM sqlite_master "
                           "ORDER BY type, name").fetchall()
    rows = {}
    for (name,) in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'"):
        columns = [c[1] for c in conn.execute(f'PRAGMA table_info("{name}")')
                   if not (name == "slr_migrations" and c[1] == "applied_at")]
        rows[name] = sorted(conn.execute(
            f'SELECT {", ".join(chr(34) + c + chr(34) for c in columns)} FROM "{name}"'))
    pragmas = {p: conn.execute(f"PRAGMA {p}").fetchone()[0]
               for p in ("user_version", "auto_vacuum", "page_size", "application_id")}
    return {"objects": objects, "rows": rows, "pragmas": pragmas}


def fresh() -> sqlite3.Connection:
    conn = sqlite3.connect(":memory:", isolation_level=None)
    conn.execute("PRAGMA auto_vacuum=INCREMENTAL")   # as the store sets it first
    return conn


def test_a_copied_schema_is_the_migrated_one():
    migrated = fresh()
    migrate(migrated, None)
    first, second = fresh(), fresh()
    migrate_new_memory_store(first)      # (migrates, or copies: a store may have come first)
    migrate_new_memory_store(second)     # copies
    assert contents(first) == contents(migrated)
    assert contents(second) == contents(migrated)
    assert contents(migrated)["rows"]["slr_migrations"]   # the comparison saw real rows


def test_stores_made_at_once_in_threads_are_each_whole_and_apart():
    made: list = []

    def open_one() -> None:
        kb = slr_sql.open(clock=slr_sql.ManualClock(0.0))
        kb.add(f"seen(t{threading.get_ident()})^1")
        made.append(kb)

    threads = [threading.Thread(target=open_one) for _ in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=60)
    assert len(made) == 8
    for kb in made:    # each store holds its own event only
        assert len(kb.query("seen(X)^T")) == 1
        kb.close()
