"""Disk space of one store file: statistics, giving free pages back, bounding the WAL.

The file uses ``auto_vacuum=INCREMENTAL`` (chosen when it is created), so pages freed by
pruned events go to a free list that :meth:`Space.reclaim_space` can release without a full
``VACUUM``.
"""
from __future__ import annotations

import os
from typing import Any

from .connection import Database
from .sqltext import quote_identifier
from .tables import EventTables

__all__ = ["Space"]


class Space:
    """Row counts, page statistics and space reclaiming of one database.

    >>> from slr_sql.store import EventStore
    >>> EventStore(None).space_stats()["free_pages"]
    0
    """

    def __init__(self, db: Database, tables: EventTables):
        self.db = db
        self.tables = tables

    def table_rows(self) -> dict[tuple[str, int], int]:
        """Rows stored now per event type (a full count: for statistics).

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.add_event("p", (1,), 1, 1); s.table_rows()
        {('p', 1): 1}
        """
        with self.db.lock:
            self.db.check_open()
            out = {}
            for key, table in sorted(self.tables.event_types().items()):
                out[key] = self.db.execute(
                    f"SELECT count(*) FROM {quote_identifier(table)}")[0][0]
            return out

    def space_stats(self) -> dict[str, Any]:
        """Page size/count, free pages, and the sizes of the file and its WAL (bytes).

        >>> from slr_sql.store import EventStore
        >>> sorted(EventStore(None).space_stats())
        ['file_bytes', 'free_pages', 'page_count', 'page_size', 'wal_bytes']
        """
        path = self.db.path
        with self.db.lock:
            self.db.check_open()
            execute = self.db.execute
            page_size = execute("PRAGMA page_size")[0][0]
            page_count = execute("PRAGMA page_count")[0][0]
            free = execute("PRAGMA freelist_count")[0][0]
        file_bytes = wal_bytes = 0
        if path is not None:
            try:
                file_bytes = os.path.getsize(path)
            except OSError:
                pass
            try:
                wal_bytes = os.path.getsize(path + "-wal")
            except OSError:
                pass
        else:
            file_bytes = page_size * page_count
        return {"page_size": page_size, "page_count": page_count, "free_pages": free,
                "file_bytes": file_bytes, "wal_bytes": wal_bytes}

    def reclaim_space(self, min_free_pages: int = 2048, min_free_fraction: float = 0.25,
                      keep_fraction: float = 0.10, wait: bool = True) -> int:
        """Give free pages back to the file system (``PRAGMA incremental_vacuum``) when the
        free list is large: more than ``min_free_pages`` pages and ``min_free_fraction`` of
        the file. ``keep_fraction`` of the file is left free for the next inserts to reuse.
        Returns the number of pages released (0 for in-memory stores). ``wait=False``: when
        another connection holds the write lock, SLRBusy at once instead of waiting
        ``busy_timeout`` (housekeeping that a later call does as well).

        >>> from slr_sql.store import EventStore
        >>> EventStore(None).reclaim_space()
        0
        """
        if self.db.path is None:
            return 0
        with self.db.lock:
            self.db.check_open()
            execute = self.db.execute
            # (after most adds the free list is short: one read decides)
            free = execute("PRAGMA freelist_count")[0][0]
            if free <= min_free_pages:
                return 0
            page_count = execute("PRAGMA page_count")[0][0]
            if free < min_free_fraction * page_count:
                return 0
            release = free - int(keep_fraction * page_count)
            if release <= 0:
                return 0
            with self.db.transaction(wait):
                # each execution gives back one page (~15 µs each)
                for _ in range(int(release)):
                    execute("PRAGMA incremental_vacuum(1)")
            after = execute("PRAGMA freelist_count")[0][0]
            if not self.db.tx_depth:
                execute("PRAGMA wal_checkpoint(PASSIVE)")
            return max(free - after, 0)

    def limit_wal(self, max_bytes: int = 64 * 1024 * 1024) -> None:
        """Truncate the WAL file to at most ``max_bytes`` after each checkpoint
        (``PRAGMA journal_size_limit``; the WAL is checkpointed every 1000 pages by SQLite).

        >>> from slr_sql.store import EventStore
        >>> EventStore(None).limit_wal(1 << 20)
        """
        if self.db.path is None:
            return
        with self.db.lock:
            self.db.check_open()
            self.db.execute(f"PRAGMA journal_size_limit = {int(max_bytes)}")


class ServerSpace(Space):
    """Space on a database server: the server manages its files (autovacuum, its own
    write-ahead log), so reclaiming and bounding the WAL are the server's; the statistics
    are the schema's relation sizes in the same keys (``page_size`` 8 KiB pages)."""

    def space_stats(self) -> dict[str, Any]:
        with self.db.lock:
            self.db.check_open()
            [size] = self.db.execute(
                "SELECT coalesce(sum(pg_total_relation_size(c.oid)), 0)::bigint, "
                "current_setting('block_size')::int FROM pg_class c JOIN pg_namespace n "
                "ON n.oid = c.relnamespace WHERE n.nspname = current_schema() "
                "AND c.relkind IN ('r', 'm')")
        file_bytes, page_size = int(size[0]), int(size[1])
        return {"page_size": page_size, "page_count": file_bytes // page_size,
                "free_pages": 0, "file_bytes": file_bytes, "wal_bytes": 0}

    def reclaim_space(self, min_free_pages: int = 2048, min_free_fraction: float = 0.25,
                      keep_fraction: float = 0.10, wait: bool = True) -> int:
        return 0

    def limit_wal(self, max_bytes: int = 64 * 1024 * 1024) -> None:
        return None
