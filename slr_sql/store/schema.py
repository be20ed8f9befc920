"""The schema of the internal ``slr_*`` tables: numbered SQL migrations, applied in order.

Each ``migrations/NNNN_name.sql`` runs once; the migrations an open applies run in one
transaction (all or nothing); ``PRAGMA user_version`` holds the number of the last one
applied. A database written by a newer slr_sql (a higher number than the last script) is
refused rather than guessed at.
"""
from __future__ import annotations

import importlib.resources
import re
import sqlite3
from pathlib import Path
from typing import Any

from ..errors import SLRError
from .sqltext import split_sql_script

__all__ = ["migration_scripts", "migrate"]


def _migrations_dir() -> Any:
    """The migrations folder: the installed ``slr_sql.migrations`` package, or the source
    checkout's top-level ``migrations/``."""
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
    scripts = []
    for entry in _migrations_dir().iterdir():
        match = re.match(r"(\d+)_.*\.sql\Z", entry.name)
        if match:
            scripts.append((int(match.group(1)), entry.name, entry.read_text(encoding="utf-8")))
    scripts.sort()
    return scripts


def migrate(conn: sqlite3.Connection, path: str | None) -> None:
    """Apply the migrations ``conn`` has not seen yet (``path`` names the file in errors).

    >>> conn = sqlite3.connect(":memory:", isolation_level=None); migrate(conn, None)
    >>> conn.execute("PRAGMA user_version").fetchone()[0] == migration_scripts()[-1][0]
    True
    """
    scripts = migration_scripts()
    latest = scripts[-1][0] if scripts else 0
    current = conn.execute("PRAGMA user_version").fetchone()[0]
    if current > latest:
        raise SLRError(f"{path}: database schema version {current} is newer than this "
                       f"slr_sql supports ({latest}); upgrade slr_sql")
    if all(number <= current for number, _, _ in scripts):
        return
    # All pending migrations in one transaction: a failure leaves the file as it was.
    conn.execute("BEGIN IMMEDIATE")
    try:
        # another process may have migrated between our check and the lock
        current = conn.execute("PRAGMA user_version").fetchone()[0]
        for number, filename, text in scripts:
            if number <= current:
                continue
            try:
                for statement in split_sql_script(text):
                    conn.execute(statement)
            except sqlite3.Error as exc:
                raise SLRError(f"{path}: migration {filename} failed ({exc}); the file is "
                               "left as it was") from None
            conn.execute(f"PRAGMA user_version = {int(number)}")
        conn.execute("COMMIT")
    except BaseException:
        if conn.in_transaction:
            conn.execute("ROLLBACK")
        raise
