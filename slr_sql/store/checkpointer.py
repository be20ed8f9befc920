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
import sqlite3
import threading

from ..errors import log_failure
from .authorizer import harden_connection
from .sqltext import busy_error, store_error

__all__ = ["WalCheckpointer", "CHECKPOINT_MODES", "CHECKPOINT_INTERVAL"]

CHECKPOINT_MODES = ("auto", "background")
CHECKPOINT_INTERVAL = 0.2  # seconds; at 1,000 one-event transactions a second ~1,000 pages

_log = logging.getLogger("slr_sql.store")


class WalCheckpointer:
    """A daemon thread checkpointing the WAL of ``path`` every ``interval`` seconds until
    :meth:`stop`. ``runs`` counts the checkpoints run, ``complete`` those that copied the
    whole log (what the log held when it started), ``locked`` those that met another
    connection's lock, ``failed`` those that failed for another reason, ``ran`` is set after
    each run.

    Another connection's lock (its checkpoint, an exclusive lock) is waited out quietly: the
    next run copies the log. Any other failure (the file damaged, the disk full or failing)
    is logged on ``slr_sql.store`` as one WARNING line naming the store, once while it lasts,
    and its end too; the thread goes on trying at every interval."""

    def __init__(self, path: str, interval: float = CHECKPOINT_INTERVAL):
        self.path = path
        self.interval = interval
        self.runs = 0
        self.complete = 0
        self.locked = 0
        self.failed = 0
        self.ran = threading.Event()
        self._stopping = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"slr-checkpoint {path}",
                                        daemon=True)
        self._thread.start()

    def _run(self) -> None:
        try:
            conn = sqlite3.connect(self.path, check_same_thread=False, isolation_level=None,
                                   timeout=0)
        except sqlite3.Error:
            return  # the writer's own connection still checkpoints on close
        try:
            harden_connection(conn)
            sized = False
            failing: str | None = None   # what the failing runs meet, said once
            while not self._stopping.wait(self.interval):
                try:
                    if not sized:   # (it reads the schema: a run's failure, if it fails)
                        conn.execute("PRAGMA cache_size=-256")  # the copy reads the log
                        sized = True
                    busy, log, copied = conn.execute("PRAGMA wal_checkpoint(PASSIVE)").fetchone()
                except sqlite3.Error as exc:
                    if busy_error(exc, self.path) is not None or \
                            getattr(exc, "sqlite_errorcode", 0) & 0xFF == sqlite3.SQLITE_LOCKED:
                        self.locked += 1   # (another checkpoint running: the next run copies)
                        continue
                    self.failed += 1
                    failure = store_error(exc, self.path, outcome="nothing was copied")
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
            conn.close()

    def stop(self) -> None:
        """End the thread (waits for a checkpoint in progress to finish). Idempotent."""
        self._stopping.set()
        if self._thread is not threading.current_thread():
            self._thread.join()
