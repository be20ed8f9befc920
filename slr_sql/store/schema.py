"""The schema of the internal ``slr_*`` tables: numbered SQL migrations, applied in order.

Each ``migrations/NNNN_name.sql`` runs once and is recorded in ``slr_migrations``; the
migrations an open applies run in one transaction (all or nothing), whatever the gaps in the
numbering; ``PRAGMA user_version`` holds the highest number applied. A database written by a
newer slr_sql (a higher number than the last script) is refused rather than guessed at.
A statement naming ``{event_table}`` runs once per event table (``0006_robots.sql`` adds the
``robot`` column to the tables a store already has); a change SQL cannot spell as one statement
per table runs as a Python step after its script (``0007_sequences.sql`` rebuilds every event
table with a never-reused ``seq``).
"""
from __future__ import annotations

import functools
import json
import importlib.resources
import re
import sqlite3
import threading
from pathlib import Path
from typing import Any

from ..errors import SLRError
from .sqltext import busy_error, quote_identifier, split_sql_script
from .stored_text import fetch_row, fetch_rows

__all__ = ["migration_scripts", "migrate", "migrate_new_memory_store", "applied_migrations"]


def _migrations_dir() -> Any:
    """The migrations folder: the source checkout's top-level ``migrations/`` when this module
    runs from a checkout (so a worktree uses its own migrations, not an editable install's),
    else the installed ``slr_sql.migrations`` package."""
    checkout = Path(__file__).resolve().parents[2] / "migrations"
    if checkout.is_dir() and any(entry.name.endswith(".sql") for entry in checkout.iterdir()):
        return checkout
    try:
        folder = importlib.resources.files("slr_sql.migrations")
        if any(entry.name.endswith(".sql") for entry in folder.iterdir()):
            return folder
    except Exception:  # not installed as a package: running from a source checkout
        pass
    return Path(__file__).resolve().parents[2] / "migrations"


def migration_scripts() -> list[tuple[int, str, str]]:
    """``(number, file name, sql text)`` of every ``NNNN_name.sql`` migration, in order.

    >>> migration_scripts()[0][:2]
    (1, '0001_initial.sql')
    """
    return _scripts(r"(\d+)_.*\.sql\Z")


# Every store opened reads the migrations: their text is kept per file, read again only when
# the folder's listing or a file's size or modification time changes.
_SCRIPT_TEXTS: dict[tuple[str, int, int], str] = {}


def _scripts(pattern: str) -> list[tuple[int, str, str]]:
    scripts = []
    for entry in _migrations_dir().iterdir():
        match = re.match(pattern, entry.name)
        if match:
            scripts.append((int(match.group(1)), entry.name, _script_text(entry)))
    scripts.sort()
    return scripts


def _script_text(entry: Any) -> str:
    try:
        info = entry.stat()
    except (AttributeError, OSError):   # a resource that is not a file: read it every time
        return str(entry.read_text(encoding="utf-8"))
    key = (str(entry), info.st_size, info.st_mtime_ns)
    text = _SCRIPT_TEXTS.get(key)
    if text is None:
        text = _SCRIPT_TEXTS[key] = entry.read_text(encoding="utf-8")
    return text


@functools.lru_cache(maxsize=128)
def _statements(text: str) -> tuple[str, ...]:
    return tuple(split_sql_script(text))


def applied_migrations(conn: sqlite3.Connection,
                       scripts: list[tuple[int, str, str]] | None = None) -> set[int]:
    """The numbers of the migrations applied to ``conn``'s database: those recorded in
    ``slr_migrations``, or (a store from before that table) every number up to
    ``PRAGMA user_version``.

    >>> conn = sqlite3.connect(":memory:", isolation_level=None); migrate(conn, None)
    >>> sorted(applied_migrations(conn)) == [n for n, _, _ in migration_scripts()]
    True
    """
    current = fetch_row(conn.execute("PRAGMA user_version"))[0]
    has_table = fetch_row(conn.execute("SELECT 1 FROM sqlite_master WHERE type = 'table' "
                                       "AND name = 'slr_migrations'"))
    if has_table:
        return {row[0] for row in
                fetch_rows(conn.execute("SELECT number FROM slr_migrations"))}
    return {number for number, _, _ in (migration_scripts() if scripts is None else scripts)
            if number <= current}


def _per_event_table(conn: sqlite3.Connection, statement: str) -> list[str]:
    """``statement`` itself, or, when it names ``{event_table}``, one copy per event table
    (the quoted table name in its place): a migration that changes every event table."""
    if "{event_table}" not in statement:
        return [statement]
    tables = [row[0] for row in
              fetch_rows(conn.execute("SELECT table_name FROM slr_event_types"))]
    return [statement.replace("{event_table}", quote_identifier(t)) for t in tables]


def _never_reused_sequences(conn: sqlite3.Connection) -> None:
    """Rebuild every event table whose ``seq`` is a plain ``INTEGER PRIMARY KEY`` with
    ``AUTOINCREMENT``, keeping its rows (sequences included), indexes and triggers: SQLite
    cannot add AUTOINCREMENT to a table in place (the documented copy, drop, rename)."""
    tables = [row[0] for row in
              fetch_rows(conn.execute("SELECT table_name FROM slr_event_types"))]
    for table in tables:
        row = fetch_row(conn.execute("SELECT sql FROM sqlite_master WHERE type = 'table' "
                                     "AND name = ?", (table,)))
        if row is None or re.search(r"\bAUTOINCREMENT\b", row[0], re.IGNORECASE):
            continue
        info = fetch_rows(conn.execute(f"PRAGMA table_info({quote_identifier(table)})"))
        columns = [(name, kind, notnull) for _, name, kind, notnull, _, _ in info]
        if not columns or columns[0][0] != "seq":
            continue
        definitions = ["seq INTEGER PRIMARY KEY AUTOINCREMENT"] + [
            f"{quote_identifier(name)}{' ' + kind if kind else ''}"
            f"{' NOT NULL' if notnull else ''}" for name, kind, notnull in columns[1:]]
        names = ", ".join(quote_identifier(name) for name, _, _ in columns)
        others = fetch_rows(conn.execute(
            "SELECT sql FROM sqlite_master WHERE tbl_name = ? AND type IN ('index', "
            "'trigger') AND sql IS NOT NULL ORDER BY type, name", (table,)))
        new = quote_identifier(f"slr_rebuild__{table}")
        conn.execute(f"CREATE TABLE {new} ({', '.join(definitions)})")
        conn.execute(f"INSERT INTO {new} ({names}) SELECT {names} FROM "
                     f"{quote_identifier(table)} ORDER BY seq")
        conn.execute(f"DROP TABLE {quote_identifier(table)}")
        # legacy renaming: views and other tables' triggers (a buffer's tick on slr_clock)
        # name the table, which does not exist between the drop and the rename
        conn.execute("PRAGMA legacy_alter_table = ON")
        try:
            conn.execute(f"ALTER TABLE {new} RENAME TO {quote_identifier(table)}")
        finally:
            conn.execute("PRAGMA legacy_alter_table = OFF")
        for (sql,) in others:
            conn.execute(sql)


def old_fleet_mark_reading(rest: str, known: set[str]) -> tuple[str, str] | None:
    """``(robot, mark)`` of a fleet mark key of schema version 13 and before, ``rest`` being
    the key after ``fleet/mark/`` (``robot/name/arity``, the robot's name and the type's name
    as they are), or None when it cannot be told whose mark it is: a key of more than three
    segments is read as the mark of the one robot of ``known`` it starts with.

    >>> old_fleet_mark_reading("r1/seen/2", set())
    ('r1', 'seen/2')
    >>> old_fleet_mark_reading("r1/x/seen/2", {"r1"}), old_fleet_mark_reading("r1/x/seen/2", {"r1", "r1/x"})
    (('r1', 'x/seen/2'), None)
    """
    segments = rest.split("/")
    last = segments[-1]
    if len(segments) < 3 or not (last == "*" or (last.isascii() and last.isdigit())):
        return None
    if len(segments) == 3:
        return segments[0], "/".join(segments[1:])
    readings = [("/".join(segments[:k]), "/".join(segments[k:]))
                for k in range(1, len(segments) - 1)]
    readings = [r for r in readings if r[0] in known]
    return readings[0] if len(readings) == 1 else None


def _unambiguous_fleet_mark_keys(conn: sqlite3.Connection) -> None:
    """Rewrite the fleet mark keys of version 13 and before into the escaped form of
    :func:`slr_sql.store.fleet_keys.fleet_mark_key` (see ``0014_fleet_mark_keys.sql``)."""
    from .fleet_keys import FLEET_MARK, fleet_mark_key
    known = {row[0] for row in fetch_rows(conn.execute(
        "SELECT name FROM slr_robots UNION SELECT robot FROM slr_fleet_robots "
        "UNION SELECT robot FROM slr_fleet_routes UNION SELECT via FROM slr_fleet_routes"))}
    own = fetch_row(conn.execute("SELECT value FROM slr_meta WHERE key = 'robot'"))
    if own is not None:
        try:
            known.add(json.loads(own[0]))
        except ValueError:
            pass
    rows = fetch_rows(conn.execute("SELECT key, value FROM slr_meta WHERE "
                                   "substr(key, 1, ?) = ?", (len(FLEET_MARK), FLEET_MARK)))
    rewritten = []
    for key, value in rows:
        reading = old_fleet_mark_reading(key[len(FLEET_MARK):], known)
        new = None if reading is None else fleet_mark_key(*reading)
        if new != key:
            rewritten.append((key, new, value))
    # every old key out first: a new key may be the old key of another mark
    conn.executemany("DELETE FROM slr_meta WHERE key = ?", [(k,) for k, _, _ in rewritten])
    conn.executemany("INSERT INTO slr_meta (key, value) VALUES (?, ?)",
                     [(new, value) for _, new, value in rewritten if new is not None])


# (SQL cannot loop over tables and read their definitions: these steps run after their file)
_PYTHON_STEPS = {"0007_sequences.sql": _never_reused_sequences,
                 "0014_fleet_mark_keys.sql": _unambiguous_fleet_mark_keys}


def migrate(conn: sqlite3.Connection, path: str | None,
            scripts: list[tuple[int, str, str]] | None = None) -> None:
    """Apply the migrations ``conn`` has not seen yet (``path`` names the file in errors).

    Every script not applied yet runs, in number order, whatever the gaps in the numbering
    (a script merged later with a lower number than one applied already still runs); each
    is recorded in ``slr_migrations`` and ``PRAGMA user_version`` is the highest applied.
    A store that is up to date is only read (no write lock needed to open it). ``scripts``
    (default :func:`migration_scripts`) is for tests.

    >>> conn = sqlite3.connect(":memory:", isolation_level=None); migrate(conn, None)
    >>> conn.execute("PRAGMA user_version").fetchone()[0] == migration_scripts()[-1][0]
    True
    """
    if scripts is None:
        scripts = migration_scripts()
    latest = scripts[-1][0] if scripts else 0
    current = fetch_row(conn.execute("PRAGMA user_version"))[0]
    if current > latest:
        raise SLRError(f"{path}: database schema version {current} is newer than this "
                       f"slr_sql supports ({latest}); upgrade slr_sql")
    if all(number in applied_migrations(conn, scripts) for number, _, _ in scripts):
        return
    # All pending migrations in one transaction: a failure leaves the file as it was.
    try:
        conn.execute("BEGIN IMMEDIATE")
    except sqlite3.OperationalError as exc:
        raise busy_error(exc, path) or exc from None
    try:
        # another process may have migrated between our check and the lock
        applied = applied_migrations(conn, scripts)
        names = {n: name for n, name, _ in scripts}
        for number, filename, text in scripts:
            if number in applied:
                continue
            try:
                for statement in _statements(text):
                    for each in _per_event_table(conn, statement):
                        conn.execute(each)
                step = _PYTHON_STEPS.get(filename)
                if step is not None:
                    step(conn)
            except sqlite3.Error as exc:
                raise SLRError(f"{path}: migration {filename} failed ({exc}); the file is "
                               "left as it was") from None
            applied.add(number)
        conn.execute("CREATE TABLE IF NOT EXISTS slr_migrations (number INTEGER PRIMARY "
                     "KEY, name TEXT NOT NULL, applied_at REAL)")
        conn.executemany("INSERT OR IGNORE INTO slr_migrations (number, name, applied_at) "
                         "VALUES (?, ?, julianday('now'))",
                         [(n, names.get(n, "?")) for n in sorted(applied)])
        version = fetch_row(conn.execute("PRAGMA user_version"))[0]
        conn.execute(f"PRAGMA user_version = {int(max([version, *applied]))}")
        conn.execute("COMMIT")
    except BaseException:
        if conn.in_transaction:
            conn.execute("ROLLBACK")
        raise


# A new in-memory store gets its schema as a copy of the pages (SQLite's backup API) of one
# migrated earlier in this process from the same scripts: replaying the migrations (a table
# rebuilt and renamed among them) was ~5 ms of every in-memory open, the copy ~0.2 ms.
_MEMORY_TEMPLATES: dict[tuple, sqlite3.Connection] = {}
_MEMORY_TEMPLATES_LOCK = threading.Lock()   # one backup of a template at a time


def migrate_new_memory_store(conn: sqlite3.Connection) -> None:
    """Give the new, empty in-memory database ``conn`` the schema :func:`migrate` gives it
    (the same pages: tables, rows, ``user_version``; ``slr_migrations.applied_at`` is when
    this process first migrated one).

    >>> conn = sqlite3.connect(":memory:", isolation_level=None)
    >>> migrate_new_memory_store(conn)
    >>> conn.execute("PRAGMA user_version").fetchone()[0] == migration_scripts()[-1][0]
    True
    """
    scripts = migration_scripts()
    key = tuple(scripts)
    with _MEMORY_TEMPLATES_LOCK:
        template = _MEMORY_TEMPLATES.get(key)
        if template is not None:
            template.backup(conn)
            return
    migrate(conn, None, scripts)
    with _MEMORY_TEMPLATES_LOCK:
        if key not in _MEMORY_TEMPLATES:
            template = sqlite3.connect(":memory:", check_same_thread=False,
                                       isolation_level=None)
            conn.backup(template)
            _MEMORY_TEMPLATES[key] = template


def postgres_migration_scripts() -> list[tuple[int, str, str]]:
    """``(number, file name, sql text)`` of every ``pg_NNNN_name.sql`` migration: the
    PostgreSQL spelling of the SQLite migration with the same number.

    >>> [n for n, _, _ in postgres_migration_scripts()] == [n for n, _, _ in migration_scripts()]
    True
    """
    return _scripts(r"pg_(\d+)_.*\.sql\Z")
