"""Space the buffers' pruning freed is given back after an add (the event pipeline's buffer
stage, ``PRAGMA incremental_vacuum`` in a transaction of its own): that write comes after
the add's events committed, so a lock another process holds then must not fail the add (its
retry would store the events twice). The space is given back by a later add.
"""
from __future__ import annotations

import sqlite3

import slr_sql
from slr_sql import ManualClock


class LockingClock(ManualClock):
    """A ManualClock that, once armed, has another connection take the file's write lock the
    first time it is read after the armed add's events are visible to other connections
    (after its commit, before its later stages): a writer of another process arriving
    exactly then."""

    def __init__(self, t: float, path: str) -> None:
        super().__init__(t)
        self.path = path
        self.armed_for: int | None = None   # the count of p/1 events that fires it
        self.holder: sqlite3.Connection | None = None

    def now(self) -> float:
        if self.armed_for is not None and self.holder is None:
            reader = sqlite3.connect(self.path)
            try:
                seen = reader.execute("SELECT count(*) FROM p").fetchone()[0]
            finally:
                reader.close()
            if seen >= self.armed_for:
                self.holder = sqlite3.connect(self.path, isolation_level=None)
                self.holder.execute("BEGIN IMMEDIATE")
        return super().now()


def _free_pages(path: str) -> int:
    conn = sqlite3.connect(path)
    try:
        return conn.execute("PRAGMA freelist_count").fetchone()[0]
    finally:
        conn.close()


def test_a_reclaim_meeting_another_writer_does_not_fail_the_committed_add(tmp_path):
    path = str(tmp_path / "r.db")
    clock = LockingClock(100.0, path)
    with slr_sql.open(path, clock=clock, busy_timeout=0.2) as kb:
        kb.load(":- max_delay(p/1, 0).")
        kb.add("p(0)^1")
        # another program's large table, dropped: most of the file is free pages
        other = sqlite3.connect(path, isolation_level=None)
        other.execute("CREATE TABLE junk (x BLOB)")
        # one transaction: 3000 of their own, each synced to the disk, took up to 20 s
        other.execute("BEGIN")
        other.executemany("INSERT INTO junk VALUES (zeroblob(8000))", [()] * 3000)
        other.execute("COMMIT")
        other.execute("DROP TABLE junk")
        other.close()
        assert _free_pages(path) > 4000
        clock.armed_for = 2
        assert kb.add_many(["p(1)^2"]) == []   # its reclaim met the lock: the add stands
        assert clock.holder is not None
        clock.holder.execute("ROLLBACK")
        clock.holder.close()
        assert kb.store.count("p", 1) == 2
        assert _free_pages(path) > 4000        # (not given back yet)
        kb.add("p(2)^3")                        # the next add gives the space back
        assert _free_pages(path) < 1000
        assert kb.store.count("p", 1) == 3
