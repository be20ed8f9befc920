"""Another connection holding a store against writers, for tests of retryable busy writes."""
from __future__ import annotations

import sqlite3
from collections.abc import Iterator
from contextlib import contextmanager

import psycopg


@contextmanager
def meta_held(where: str) -> Iterator[None]:
    """Another connection holding the store's meta table (where marks are kept) against
    writers while the block runs: on PostgreSQL that table alone (reads go on, the event
    tables stay free); on SQLite, which locks whole files, the file."""
    if where.startswith("postgres"):
        with psycopg.connect(where) as other:
            other.execute("LOCK TABLE slr.slr_meta IN SHARE MODE")
            yield
            other.rollback()
    else:
        other = sqlite3.connect(where, isolation_level=None)
        other.execute("BEGIN IMMEDIATE")
        try:
            yield
        finally:
            other.execute("ROLLBACK")
            other.close()


def table_written(where: str, table: str = "c") -> sqlite3.Connection | psycopg.Connection:
    """Another connection writing to ``table``, not committed (the caller rolls it back and
    closes it): on PostgreSQL a ROW EXCLUSIVE lock of that table (a build of its indexes
    must wait); on SQLite, which locks whole files, an open write transaction."""
    if where.startswith("postgresql"):
        other = psycopg.connect(where)
        other.execute("SET search_path = slr")
        other.execute(f'LOCK TABLE "{table}" IN ROW EXCLUSIVE MODE')
        return other
    lite = sqlite3.connect(where, isolation_level=None)
    lite.execute("BEGIN IMMEDIATE")
    return lite
