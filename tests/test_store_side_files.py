"""SQLite keeps a database's write-ahead log, shared-memory index and rollback journal in files
named after it (``robot.db-wal``, ``-shm``, ``-journal``) and truncates or deletes them when
it opens the database. A store at such a name, or a store whose side file is a database, is
refused before anything is written: a store ``robot.db-wal`` was gone after the next ``slr
query robot.db``, and ``slr fleet push robot.db robot.db-wal`` reported its events shipped
to a fleet store that the push itself deleted."""
from __future__ import annotations

import os

import pytest

import slr_sql
from slr_sql import ManualClock
from test_cli import slr

SIDE_WORDS = [("-wal", "write-ahead log"), ("-shm", "shared-memory index"),
              ("-journal", "rollback journal")]


def _store(path, robot=None, events=("seen(a)^1",)):
    with slr_sql.open(str(path), robot=robot, clock=ManualClock(10)) as kb:
        kb.add_many(list(events))
    return path


@pytest.mark.parametrize("suffix", ["-wal", "-shm", "-journal"])
def test_a_store_named_as_a_side_file_of_a_database_beside_it_is_refused(tmp_path, suffix):
    db = _store(tmp_path / "robot.db")
    side = tmp_path / f"robot.db{suffix}"
    with pytest.raises(slr_sql.SLRError, match=r"robot\.db" + suffix + r": the name of the .* "
                       r"of the SQLite database .*robot\.db beside it"):
        slr_sql.open(str(side), clock=ManualClock(10))
    assert not side.exists()
    with slr_sql.open(str(db), clock=ManualClock(10)) as kb:
        assert kb.query("seen(X)^T") == [{"X": slr_sql.Atom("a"), "T": 1.0}]


def test_slr_add_to_a_wal_name_is_refused_and_the_database_beside_it_kept(tmp_path):
    _store(tmp_path / "robot.db")
    done = slr("add", str(tmp_path / "robot.db-wal"), "other(b)^2")
    assert done.returncode == 1, done.stdout
    assert "the name of the write-ahead log of the SQLite database" in done.stderr
    assert "Traceback" not in done.stderr
    assert not (tmp_path / "robot.db-wal").exists()


def test_a_store_whose_wal_name_holds_a_database_is_not_opened_and_that_database_is_kept(
        tmp_path):
    # the other order: the store beside was made first (or moved there)
    other = _store(tmp_path / "robot.db-wal", events=("other(b)^2",))
    before = other.read_bytes()
    done = slr("add", str(tmp_path / "robot.db"), "seen(a)^1")
    assert done.returncode == 1, done.stdout
    assert done.stderr.startswith(f"error: {tmp_path / 'robot.db'}: {other} beside it is an "
                                  f"SQLite database"), done.stderr
    assert other.read_bytes() == before
    assert not (tmp_path / "robot.db").exists()


def test_a_fleet_push_to_the_robot_stores_wal_name_ships_nothing_and_says_why(tmp_path):
    robot = _store(tmp_path / "r1.db", robot="r1")
    done = slr("fleet", "push", str(robot), str(tmp_path / "r1.db-wal"))
    assert done.returncode == 1, done.stdout
    assert "shipped" not in done.stdout
    assert "the name of the write-ahead log of the SQLite database" in done.stderr
    assert not (tmp_path / "r1.db-wal").exists()


@pytest.mark.parametrize("suffix", ["-wal", "-shm", "-journal"])
@pytest.mark.parametrize("kind", ["a named pipe", "a directory"])
def test_a_side_file_that_is_no_file_is_said_and_never_waited_on(tmp_path, suffix, kind):
    # a named pipe at robot.db-wal made the check for a database there wait for a writer
    # for ever; a directory made SQLite say 'disk I/O error' or 'unable to open database'
    db = _store(tmp_path / "robot.db")
    side = tmp_path / f"robot.db{suffix}"
    if kind == "a named pipe":
        os.mkfifo(side)
    else:
        side.mkdir()
    done = slr("query", str(db), "seen(X)^_", timeout=60)
    assert done.returncode == 1, done.stdout
    assert done.stderr == (f"error: {db}: {side} beside it is {kind}, where SQLite keeps the "
                           f"{dict(SIDE_WORDS)[suffix]} of {db}: remove or rename it\n")
