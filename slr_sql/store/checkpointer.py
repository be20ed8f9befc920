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

import sqlite3
import threading

from .authorizer import harden_connection

__all__ = ["WalCheckpointer", "CHECKPOINT_MODES", "CHECKPOINT_INTERVAL"]

CHECKPOINT_MODES = ("auto", "background")
CHECKPOINT_INTERVAL = 0.2  # seconds; at 1,000 one-event transactions a second ~1,000 pages


class WalCheckpointer:
    """A daemon thread checkpointing the WAL of ``path`` every ``interval`` seconds until
    :meth:`stop`. ``runs`` counts the checkpoints run, ``complete`` those that copied the
    whole log (what the log held when it started), ``ran`` is set after each run."""

    def __init__(self, path: str, interval: float = CHECKPOINT_INTERVAL):
        self.path = path
        self.interval = interval
        self.runs = 0
        self.complete = 0
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
            conn.execute("PRAGMA cache_size=-256")  # the copy reads the log, not the cache
            while not self._stopping.wait(self.interval):
                try:
                    busy, log, copied = conn.execute("PRAGMA wal_checkpoint(PASSIVE)").fetchone()
                except sqlite3.Error:
                    continue  # another checkpoint was running, or the file went away: next turn
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
