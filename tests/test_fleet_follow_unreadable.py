"""A following pusher (``slr fleet push --follow``) whose robot store cannot be read for a
while: the file's bytes turn to garbage under it (a disk fault, a botched copy) while the
robot's own process goes on writing to its write-ahead log, then the file is restored from a
copy. The follower says once that the robot's store cannot be read, keeps trying with a
backoff (the thread never ends on it, the connection to the fleet is kept), says when the
store reads again, and ships the events added meanwhile and afterwards."""
from __future__ import annotations

import sqlite3
import threading
import time
from pathlib import Path

import slr_sql
from slr_sql import fleet

DEADLINE = 30.0


def wait_until(condition, what: str) -> None:
    poll = threading.Event()
    end = time.monotonic() + DEADLINE
    while not condition():
        assert time.monotonic() < end, f"timed out waiting for {what}"
        poll.wait(0.01)


def fleet_count(path: Path) -> int:
    if not path.exists():
        return 0
    conn = sqlite3.connect(path, timeout=5)
    try:
        return sum(conn.execute(f'SELECT count(*) FROM "{t}"').fetchone()[0]
                   for (t,) in conn.execute("SELECT table_name FROM slr_event_types"))
    except sqlite3.OperationalError:   # not created yet
        return 0
    finally:
        conn.close()


def test_a_follower_outlives_a_robot_store_it_cannot_read_and_ships_on(tmp_path):
    robot_db, fleet_db = tmp_path / "r1.db", tmp_path / "fleet.db"
    said: list[str] = []
    failures: list[BaseException] = []
    stop = threading.Event()

    def follow() -> None:
        try:
            fleet.push(str(robot_db), str(fleet_db), follow=True, stop=stop, say=said.append)
        except BaseException as exc:   # (the test says what ended the thread)
            failures.append(exc)

    with slr_sql.open(robot_db, robot="r1", clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add_many([f"seen({i})^{i}" for i in range(20)])
        follower = threading.Thread(target=follow, daemon=True)
        follower.start()
        try:
            wait_until(lambda: fleet_count(fleet_db) == 20, "the first events shipped")
            # the file alone holds the store, then the robot writes to the log again: the
            # copy and that log make the store whole
            kb.sql("PRAGMA wal_checkpoint(TRUNCATE)", write=True)
            kb.add("seen(20)^20")
            wait_until(lambda: fleet_count(fleet_db) == 21, "the event after the checkpoint")
            copy = robot_db.read_bytes()
            with open(robot_db, "r+b") as f:   # (the same file: its bytes turned to garbage)
                f.write(b"\xff" * len(copy))
            # the robot goes on (its pages are cached): the follower's next read of the store,
            # which another connection changed, reads the file
            kb.add("seen(21)^21")
            wait_until(lambda: any("cannot be read" in s for s in said) or failures,
                       "the failure said")
            assert follower.is_alive(), failures
            kb.add("seen(22)^22")
            with open(robot_db, "r+b") as f:   # restored from the copy
                f.write(copy)
            kb.add("seen(23)^23")
            wait_until(lambda: fleet_count(fleet_db) == 24, "the events since shipped")
            wait_until(lambda: any("reads again" in s for s in said), "the recovery said")
            assert follower.is_alive(), failures
        finally:
            stop.set()
            follower.join(DEADLINE)
    assert not failures and not follower.is_alive()
    unreadable = [s for s in said if "cannot be read" in s]
    assert len(unreadable) == 1, said
    # SQLite names the garbage by what it read first: the header (on a fresh read of the
    # schema) or another page (with the schema still cached): the same condition
    assert unreadable[0] in [f"the robot's store cannot be read ({robot_db}: the file is "
                             f"damaged ({sqlite_words}); restore it from a copy); retrying "
                             f"with backoff"
                             for sqlite_words in ("file is not a database",
                                                  "database disk image is malformed")], said
    assert said.count("the robot's store reads again; shipping resumed") == 1, said
    assert not [s for s in said if "unreachable" in s], said   # (not the fleet's outage)
