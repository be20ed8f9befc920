"""checkpoint="background": the store's thread copies the write-ahead log into the database
file, SQLite's own checkpoint (inside a commit) is off, durability and sharing are unchanged."""
from __future__ import annotations

import logging
import os
import sqlite3
import threading
import time

import pytest

import slr_sql
from slr_sql import ManualClock
from slr_sql.store.checkpointer import WalCheckpointer
from slr_sql.store.connection import Database


# The stores here get a ManualClock: their events are stamped 0, 1, 2... (not wall-clock
# times, which would make each type's first event "decades late", a LearnedDelayWarning), and
# no test here waits on the store's time.
def rows_in_main_file(path) -> int:
    """Rows of table p as the database file alone holds them (``immutable``: the WAL is
    not read), i.e. what has been checkpointed."""
    conn = sqlite3.connect(f"file:{path}?immutable=1", uri=True)
    try:
        names = [r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type='table'")]
        return conn.execute('SELECT count(*) FROM "p"').fetchone()[0] if "p" in names else 0
    finally:
        conn.close()


def wait_for(condition, seconds=20.0):
    deadline = time.monotonic() + seconds
    while not condition():
        assert time.monotonic() < deadline, "condition not reached before the deadline"
        time.sleep(0.01)


def checkpointer_threads():
    return [t for t in threading.enumerate() if t.name.startswith("slr-checkpoint")]


def test_background_checkpoints_reach_the_file_without_close(tmp_path):
    path = tmp_path / "kb.db"
    kb = slr_sql.open(path, synchronous="NORMAL", checkpoint="background", clock=ManualClock(0.0))
    try:
        for i in range(300):  # one transaction each
            kb.add(f"p({i})^{i}")
        db = kb.store._db
        assert db.conn.execute("PRAGMA wal_autocheckpoint").fetchone()[0] == 0
        runs = db.checkpointer.complete
        wait_for(lambda: db.checkpointer.complete > runs + 1)  # two more after the last add
        assert rows_in_main_file(path) == 300
        assert kb.query("aggregate_all(count, p(_)^_, N)") == [{"N": 300}]
    finally:
        kb.close()
    assert not checkpointer_threads()


def test_the_default_leaves_checkpoints_to_sqlite(tmp_path):
    kb = slr_sql.open(tmp_path / "kb.db")
    try:
        assert kb.store._db.checkpointer is None
        assert kb.store._db.conn.execute("PRAGMA wal_autocheckpoint").fetchone()[0] == 1000
        assert not checkpointer_threads()
    finally:
        kb.close()


def test_the_wal_stays_bounded_while_a_writer_adds(tmp_path):
    """The writer starts the log again once a checkpoint copied all of it: with SQLite's own
    checkpoint off, the log would otherwise hold every transaction."""
    path = tmp_path / "kb.db"
    db = Database(path, synchronous="NORMAL", checkpoint="background", checkpoint_interval=0.01)
    db.conn.execute("CREATE TABLE t (x)")
    try:
        largest = 0
        for i in range(3000):
            db.conn.execute("INSERT INTO t VALUES (?)", (i,))
            if i % 100 == 0:
                # two runs: the second starts after this wait did, with no write going on,
                # so it copies the whole log (the first may have begun amid the inserts)
                wait_for(lambda n=db.checkpointer.runs: db.checkpointer.runs > n + 1)
                largest = max(largest, (tmp_path / "kb.db-wal").stat().st_size)
        # 3,000 transactions of one page or more each: ~12 MB of log without checkpoints
        assert largest < 2_000_000
    finally:
        db.close()


def test_other_processes_and_a_reopen_see_everything(tmp_path):
    path = tmp_path / "kb.db"
    with slr_sql.open(path, checkpoint="background", clock=ManualClock(0.0)) as kb:
        kb.add_many([f"p({i})^{i}" for i in range(50)])
        # a second connection, SQLite's own checkpoints
        with slr_sql.open(path, clock=ManualClock(0.0)) as other:
            assert other.query("aggregate_all(count, p(_)^_, N)") == [{"N": 50}]
            other.add("p(50)^50")
        assert kb.query("aggregate_all(count, p(_)^_, N)") == [{"N": 51}]
    with slr_sql.open(path, clock=ManualClock(0.0)) as kb:
        assert kb.query("aggregate_all(count, p(_)^_, N)") == [{"N": 51}]


@pytest.mark.parametrize("mode", ["sometimes", "", None])
def test_an_unknown_mode_is_refused(tmp_path, mode):
    with pytest.raises(slr_sql.SLRError, match="checkpoint must be"):
        slr_sql.open(tmp_path / "kb.db", checkpoint=mode)
    assert not checkpointer_threads()


def test_an_in_memory_store_has_no_thread():
    with slr_sql.open(None, checkpoint="background", clock=ManualClock(0.0)) as kb:
        kb.add("p(1)^1")
        assert kb.store._db.checkpointer is None


def test_the_page_cache_bound_is_an_option(tmp_path):
    with slr_sql.open(tmp_path / "kb.db", cache_mib=8) as kb:
        assert kb.store._db.conn.execute("PRAGMA cache_size").fetchone()[0] == -8 * 1024
    with slr_sql.open(tmp_path / "kb.db") as kb:
        assert kb.store._db.conn.execute("PRAGMA cache_size").fetchone()[0] == -64 * 1024
    for bad in (0, -1, "64", True):
        with pytest.raises(slr_sql.SLRError, match="cache_mib"):
            slr_sql.open(tmp_path / "kb.db", cache_mib=bad)


def test_a_damaged_file_is_said_once_and_so_is_its_end(tmp_path, caplog):
    """The checkpointer meets a store file that is no database any more (its bytes turned to
    garbage before its first run read the schema): one WARNING line naming the store, without
    traceback, however many runs fail; once the file is restored from a copy, one line that
    it works again, and the thread checkpoints on."""
    path = tmp_path / "kb.db"
    with slr_sql.open(path, clock=ManualClock(0.0)) as kb:
        kb.add_many([f"p({i})^{i}" for i in range(50)])
    copy = path.read_bytes()          # (checkpointed whole at close: the file alone holds it)
    path.write_bytes(b"\xff" * len(copy))
    failed = "checkpointing the write-ahead log failed (SLRError: " \
             f"{path}: the file is damaged (file is not a database); restore it from a copy)"
    with caplog.at_level(logging.WARNING, logger="slr_sql.store"):
        failing_until_cured(WalCheckpointer(str(path), interval=0.01), caplog, path, failed,
                            cure=lambda: path.write_bytes(copy))
    assert caplog.text.count(failed) == 1
    with slr_sql.open(path, clock=ManualClock(0.0)) as kb:
        assert kb.query("aggregate_all(count, p(_)^_, N)") == [{"N": 50}]


def failing_until_cured(checkpointer, caplog, path, said: str, cure,
                        meanwhile=lambda: True) -> None:
    """Runs of ``checkpointer`` fail (none succeeds, ``said`` logged once, ``meanwhile()``
    holds) until ``cure()``; then it checkpoints again, alive, and says so once."""
    try:
        wait_for(lambda: checkpointer.failed >= 3 or checkpointer.runs)
        assert checkpointer.runs == 0 and meanwhile()
        assert caplog.text.count(said) == 1, caplog.text
        cure()
        wait_for(lambda: checkpointer.runs >= 2)
        assert checkpointer._thread.is_alive()
    finally:
        checkpointer.stop()
    said_once_then_recovered(caplog, path)


def said_once_then_recovered(caplog, path) -> None:
    """The checkpointer's log of one episode: a WARNING when it began, one when it ended
    ("works again"), nothing else, and never a traceback."""
    assert caplog.text.count(f"{path}: checkpointing the write-ahead log works again") == 1
    assert "Traceback" not in caplog.text
    assert [r.levelno for r in caplog.records if r.name == "slr_sql.store"] == \
        [logging.WARNING, logging.WARNING]


def test_another_connections_lock_is_waited_out_quietly(tmp_path, caplog):
    path = tmp_path / "kb.db"
    with slr_sql.open(path, clock=ManualClock(0.0)) as kb:
        kb.add_many([f"p({i})^{i}" for i in range(50)])
    holder = sqlite3.connect(path, isolation_level=None)
    holder.execute("PRAGMA locking_mode=EXCLUSIVE")
    holder.execute("BEGIN EXCLUSIVE")   # (held to its end: every checkpoint meets the lock)
    with caplog.at_level(logging.DEBUG, logger="slr_sql.store"):
        checkpointer = WalCheckpointer(str(path), interval=0.01)
        try:
            wait_for(lambda: checkpointer.locked >= 3)
            holder.execute("COMMIT")
            holder.close()
            wait_for(lambda: checkpointer.runs >= 1)
        finally:
            checkpointer.stop()
    assert checkpointer.failed == 0
    assert not [r for r in caplog.records if r.name == "slr_sql.store"]


def test_a_store_file_moved_away_is_not_made_again_and_is_said_once(tmp_path, caplog):
    """The store's file moved away while the store is open (before the thread's connection
    opened it): the thread does not make an empty database at the path (sqlite3.connect
    would), says so in one WARNING line without traceback however many runs find it
    missing, and checkpoints again once the file is back."""
    path = tmp_path / "kb.db"
    with slr_sql.open(path, clock=ManualClock(0.0)) as kb:
        kb.add_many([f"p({i})^{i}" for i in range(50)])
    identity = (path.stat().st_dev, path.stat().st_ino)
    moved = tmp_path / "elsewhere.db"
    path.rename(moved)
    missing = f"checkpointing the write-ahead log failed (SLRStoreGone: {path}: the store's " \
              f"file is no longer at its path (deleted or moved away) while the store is " \
              f"open; nothing was copied); tried again every 0.01 s"
    with caplog.at_level(logging.WARNING, logger="slr_sql.store"):
        failing_until_cured(WalCheckpointer(str(path), interval=0.01, identity=identity),
                            caplog, path, missing, cure=lambda: moved.rename(path),
                            meanwhile=lambda: not path.exists() and
                            not (tmp_path / "kb.db-wal").exists())


def test_another_file_put_at_the_path_is_left_alone_and_said_once(tmp_path, caplog):
    """The store's file replaced by another one while the store is open: the thread stops
    checkpointing (the store's own file, now elsewhere, no longer is the store anyone opening
    the path reads) and says so once; the other file is not touched; once the store's file is
    back, it checkpoints again."""
    path = tmp_path / "kb.db"
    other = tmp_path / "other.db"
    with slr_sql.open(other, clock=ManualClock(0.0)) as kb:
        kb.add("q(1)^1")
    db = Database(path, synchronous="NORMAL", checkpoint="background", checkpoint_interval=0.01)
    replaced = f"checkpointing the write-ahead log failed (SLRStoreGone: {path}: another " \
               f"file is at the store's path (the store's was replaced) while the store is " \
               f"open; nothing was copied); tried again every 0.01 s"
    try:
        db.conn.execute("CREATE TABLE t (x)")
        wait_for(lambda: db.checkpointer.runs >= 2)
        aside = tmp_path / "kb-aside.db"
        with caplog.at_level(logging.WARNING, logger="slr_sql.store"):
            os.link(path, aside)     # (the store's file kept aside, the other put in its
            os.replace(other, path)  # place at once: never missing in between)
            their_bytes = path.read_bytes()
            failed, runs = db.checkpointer.failed, db.checkpointer.runs
            wait_for(lambda: db.checkpointer.failed >= failed + 3 or
                     db.checkpointer.runs >= runs + 3)
            assert db.checkpointer.runs <= runs + 1   # (one run may have been under way)
            runs = db.checkpointer.runs
            wait_for(lambda: db.checkpointer.failed >= failed + 6)
            assert db.checkpointer.runs == runs   # (none of the store's file meanwhile)
            assert path.read_bytes() == their_bytes
            assert caplog.text.count(replaced) == 1, caplog.text
            os.replace(aside, path)
            wait_for(lambda: db.checkpointer.runs >= runs + 2)
            assert db.checkpointer._thread.is_alive()
        said_once_then_recovered(caplog, path)
    finally:
        db.close()
    assert path.read_bytes() != their_bytes   # (the store's file is back)
