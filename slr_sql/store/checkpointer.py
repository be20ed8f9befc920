"""Copying the write-ahead log into the database file on a thread of its own.

SQLite checkpoints a WAL database by itself: the transaction whose commit makes the log
longer than 1,000 pages copies the log into the file and, unless ``synchronous=OFF``,
waits for the disk (an fsync of the database file). That wait lands on whichever ``add``
happens to cross the limit: a live stream at 1 kHz sees a stall of 5–60 ms every few hundred
events on a busy disk (measured with ``benchmarks/bench_ros_import.py --bridge-only``).

A store opened with ``checkpoint="background"`` turns SQLite's automatic checkpoint off
(``PRAGMA wal_autocheckpoint=0``) and runs a :class:`WalCheckpointer`: a daemon thread with
a connection of its own that runs ``PRAGMA wal_checkpoint(PASSIVE)`` every ``interval``
seconds. A passive checkpoint never waits for the writer or for readers, and the writer never
waits for it (WAL lets them work at the same time); the writer starts the log again from its
beginning once a checkpoint has copied all of it. Durability does not change: a transaction
is durable when its commit returns, checkpointed or not. Long-running writers with a latency
budget use it (``slr ros bridge``, ``slr serve``); short scripts keep SQLite's default.

>>> import tempfile, os
>>> path = os.path.join(tempfile.mkdtemp(), "wal.db")
>>> import sqlite3; sqlite3.connect(path).execute("PRAGMA journal_mode=WAL").fetchone()
('wal',)
>>> checkpointer = WalCheckpointer(path, interval=0.05); checkpointer.stop()
"""
from __future__ import annotations

import logging
import os
import sqlite3
import threading

from ..errors import SLRError, SLRStoreGone, log_failure
from .authorizer import harden_connection
from .sqltext import busy_error, file_identity, file_uri, store_error
from .stored_text import fetch_row

__all__ = ["WalCheckpointer", "CHECKPOINT_MODES", "CHECKPOINT_INTERVAL"]

CHECKPOINT_MODES = ("auto", "background")
CHECKPOINT_INTERVAL = 0.2  # seconds; at 1,000 one-event transactions a second ~1,000 pages

_log = logging.getLogger("slr_sql.store")


class WalCheckpointer:
    """A daemon thread checkpointing the WAL of ``path`` every ``interval`` seconds until
    :meth:`stop`. ``runs`` counts the checkpoints run, ``complete`` those that copied the
    whole log (what the log held when it started), ``locked`` those that met another
    connection's lock, ``failed`` those that failed for another reason, ``ran`` is set after
    each run. ``identity``: ``(device, inode)`` of the file the store opened (by default,
    the file at ``path`` now).

    Another connection's lock (its checkpoint, an exclusive lock) is waited out quietly: the
    next run copies the log. Any other failure (the file damaged, the disk full or failing,
    the store's file gone from its path or another file there) is logged on
    ``slr_sql.store`` as one WARNING line naming the store, once while it lasts, and its end
    too; the thread goes on trying at every interval. Each run first compares the file at the
    path with the store's (a ``stat``): a file deleted or moved away is not made again,
    empty, by the thread's connection (it opens the path with ``mode=rw``), and another file
    put in its place is left alone."""

    def __init__(self, path: str, interval: float = CHECKPOINT_INTERVAL,
                 identity: tuple[int, int] | None = None):
        self.path = path
        self.interval = interval
        self.runs = 0
        self.complete = 0
        self.locked = 0
        self.failed = 0
        self.ran = threading.Event()
        # the path made absolute now (a later chdir changes nothing)
        self._absolute = os.path.abspath(path)
        self._identity = identity if identity is not None else file_identity(self._absolute)
        self._stopping = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"slr-checkpoint {path}",
                                        daemon=True)
        self._thread.start()

    def _run(self) -> None:
        conn: sqlite3.Connection | None = None
        failing: str | None = None   # what the failing runs meet, said once
        try:
            while not self._stopping.wait(self.interval):
                try:
                    gone = self._not_the_store()
                    if gone is not None:
                        raise gone
                    if conn is None:
                        conn = self._connect()
                    busy, log, copied = fetch_row(conn.execute("PRAGMA wal_checkpoint(PASSIVE)"))
                except (sqlite3.Error, SLRError) as exc:
                    if busy_error(exc, self.path) is not None or \
                            getattr(exc, "sqlite_errorcode", 0) & 0xFF == sqlite3.SQLITE_LOCKED:
                        self.locked += 1   # (another checkpoint running: the next run copies)
                        continue
                    self.failed += 1
                    failure = exc if isinstance(exc, SLRError) else \
                        store_error(exc, self.path, outcome="nothing was copied")
                    if str(failure) != failing:
                        failing = str(failure)
                        log_failure(_log, "checkpointing the write-ahead log", failure,
                                    then=f"tried again every {self.interval:g} s")
                    continue
                if failing is not None:
                    failing = None
                    _log.warning("%s: checkpointing the write-ahead log works again", self.path)
                self.runs += 1
                if not busy and copied == log:
                    self.complete += 1
                self.ran.set()
        finally:
            if conn is not None:
                conn.close()

    def _not_the_store(self) -> SLRStoreGone | None:
        """Why the file at the path is not the store's (deleted or moved away, or another
        file there), else None."""
        now = file_identity(self._absolute)
        if now == self._identity:
            return None
        what = "the store's file is no longer at its path (deleted or moved away)" \
            if now is None else "another file is at the store's path (the store's was replaced)"
        return SLRStoreGone(f"{self.path}: {what} while the store is open; nothing was copied")

    def _connect(self) -> sqlite3.Connection:
        """The thread's connection to the store's file: opened with ``mode=rw`` (a missing
        file is an error, not made anew), then checked to be the store's file (the path may
        have been replaced between the run's check and the open). Its cache size is set here,
        which reads the schema: a damaged file is this run's failure."""
        conn = sqlite3.connect(file_uri(self._absolute, "rw"), uri=True,
                               check_same_thread=False, isolation_level=None, timeout=0)
        try:
            harden_connection(conn)
            conn.execute("PRAGMA cache_size=-256")  # the copy reads the log
            gone = self._not_the_store()
            if gone is not None:
                raise gone
        except BaseException:
            conn.close()
            raise
        return conn

    def stop(self) -> None:
        """End the thread (waits for a checkpoint in progress to finish). Idempotent."""
        self._stopping.set()
        if self._thread is not threading.current_thread():
            self._thread.join()
