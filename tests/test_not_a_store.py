"""Files that are not stores: ``slr_sql.open`` refuses them with an SLRError naming the path and
the reason, and without changing a byte of them (nor leaving -wal/-shm/-journal files beside
them); ``adopt=True`` takes a foreign SQLite file over on purpose; migrations are all or
nothing."""
from __future__ import annotations

import os
import random
import sqlite3
from pathlib import Path

import pytest

import slr_sql
from slr_sql import ManualClock, SLRError
from slr_sql.store import EventStore, migration_scripts

SIDE_FILES = ("-wal", "-shm", "-journal")


def snapshot(path: Path) -> tuple:
    """What must not change: the bytes, the modification time and the files beside it."""
    stat = path.stat()
    side = sorted(p.name for p in path.parent.iterdir() if p.name != path.name)
    return path.read_bytes(), stat.st_mtime_ns, side


def refuse(path: Path, *reason_words: str, **options) -> str:
    """Open ``path``, expect a refusal naming it, check nothing changed; the message."""
    before = snapshot(path)
    with pytest.raises(SLRError) as raised:
        slr_sql.open(path, **options)
    message = str(raised.value)
    assert str(path) in message
    for word in reason_words:
        assert word in message, message
    assert snapshot(path) == before
    assert not any(Path(str(path) + suffix).exists() for suffix in SIDE_FILES)
    return message


# The stores here get a ManualClock: their events are stamped 0.0, 1.0 (not wall-clock times,
# which would make each type's first event "decades late", a LearnedDelayWarning), and no
# test here waits on time.
def make_store(path: Path, events: int = 3) -> Path:
    with slr_sql.open(path, clock=ManualClock(0.0)) as kb:
        kb.load("color(O, C)^T :- prev(obj(O, C)^_, T).")
        kb.add_many([("obj", [f"o{i}", "red"], float(i), float(i)) for i in range(events)])
    return path


def foreign_sqlite(path: Path, *statements: str) -> Path:
    conn = sqlite3.connect(path, isolation_level=None)
    for statement in statements or ("CREATE TABLE customers(id INTEGER PRIMARY KEY, name TEXT)",
                                    "INSERT INTO customers(name) VALUES ('ada')"):
        conn.execute(statement)
    conn.close()
    return path


# ---------------------------------------------------------------- not SQLite at all

@pytest.mark.parametrize("content", [
    pytest.param(b"color(O, C)^T :- prev(obj(O, C)^_, T).\n" * 40, id="a program text"),
    pytest.param(random.Random(3).randbytes(8192), id="random bytes"),
    pytest.param(b"hello", id="five bytes"),
    pytest.param(b"SQLite format 2\x00" + bytes(200), id="a different magic"),
])
def test_a_file_that_is_not_sqlite_is_refused_untouched(tmp_path, content):
    path = tmp_path / "robot.db"
    path.write_bytes(content)
    refuse(path, "not an SQLite database")


def test_a_directory_is_refused(tmp_path):
    path = tmp_path / "robot.db"
    path.mkdir()
    with pytest.raises(SLRError, match="is a directory") as raised:
        slr_sql.open(path)
    assert str(path) in str(raised.value)
    assert list(path.iterdir()) == []


def test_a_path_in_a_missing_directory_is_an_error_and_creates_nothing(tmp_path):
    path = tmp_path / "no" / "such" / "robot.db"
    with pytest.raises(SLRError, match="no such directory") as raised:
        slr_sql.open(path)
    assert str(path) in str(raised.value)
    assert not (tmp_path / "no").exists()


# ---------------------------------------------------------------- SQLite files that are not stores

def test_a_foreign_sqlite_file_is_refused_untouched(tmp_path):
    path = foreign_sqlite(tmp_path / "shop.db")
    message = refuse(path, "not an slr_sql store", "customers", "adopt=True")
    assert "journal" not in message
    conn = sqlite3.connect(path)
    assert conn.execute("PRAGMA journal_mode").fetchone()[0] == "delete"  # not switched to WAL
    conn.close()


def test_adopt_takes_a_foreign_file_over_and_keeps_its_tables(tmp_path):
    path = foreign_sqlite(tmp_path / "shop.db")
    with slr_sql.open(path, adopt=True, clock=ManualClock(0.0)) as kb:
        kb.add("seen(ada)^1")
        assert kb.sql("SELECT name FROM customers") == (["name"], [("ada",)])
    with slr_sql.open(path, clock=ManualClock(0.0)) as kb:  # a store now: no adopt needed
        assert kb.query("seen(X)^T") == [{"X": "ada", "T": 1.0}]


def test_an_empty_sqlite_file_becomes_a_store(tmp_path):
    path = foreign_sqlite(tmp_path / "empty.db", "PRAGMA page_size = 8192", "VACUUM")
    assert path.stat().st_size > 0
    with slr_sql.open(path, clock=ManualClock(0.0)) as kb:
        kb.add("p(1)^1")
    with slr_sql.open(path, clock=ManualClock(0.0)) as kb:
        assert kb.query("p(X)^_") == [{"X": 1}]


def test_an_empty_file_becomes_a_store(tmp_path):
    path = tmp_path / "robot.db"
    path.touch()
    with slr_sql.open(path, clock=ManualClock(0.0)) as kb:
        kb.add("p(1)^1")
    with slr_sql.open(path, clock=ManualClock(0.0)) as kb:
        assert kb.query("p(X)^_") == [{"X": 1}]


def test_adopt_refuses_a_file_using_user_version_for_itself(tmp_path):
    path = foreign_sqlite(tmp_path / "app.db", "CREATE TABLE t(x)", "PRAGMA user_version = 7")
    refuse(path, "user_version", adopt=True)


# ---------------------------------------------------------------- newer stores

def test_a_store_of_a_newer_schema_is_refused_without_switching_its_journal(tmp_path):
    path = make_store(tmp_path / "robot.db")
    latest = migration_scripts()[-1][0]
    conn = sqlite3.connect(path, isolation_level=None)
    conn.execute("PRAGMA journal_mode = DELETE")
    conn.execute(f"PRAGMA user_version = {latest + 1}")
    conn.close()
    refuse(path, f"schema version {latest + 1}", "newer")
    refuse(path, "newer", adopt=True)
    conn = sqlite3.connect(path)
    assert conn.execute("PRAGMA journal_mode").fetchone()[0] == "delete"
    conn.close()


# ---------------------------------------------------------------- damaged stores

def test_a_truncated_store_is_reported_with_its_path(tmp_path):
    path = make_store(tmp_path / "robot.db", events=3000)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    refuse(path, "truncated")


def test_a_store_cut_inside_its_header_is_reported(tmp_path):
    path = make_store(tmp_path / "robot.db")
    path.write_bytes(path.read_bytes()[:60])
    refuse(path, "truncated")


def test_a_store_with_a_corrupted_schema_page_is_reported(tmp_path):
    path = make_store(tmp_path / "robot.db")
    data = bytearray(path.read_bytes())
    page_size = int.from_bytes(data[16:18], "big")
    data[100:page_size] = random.Random(5).randbytes(page_size - 100)
    path.write_bytes(bytes(data))
    refuse(path, "damaged")


# ---------------------------------------------------------------- migrations are all or nothing

def test_a_failing_migration_leaves_the_file_as_it_was(tmp_path):
    # The foreign file has a table that a later migration creates: the first migrations
    # succeed, that one fails; nothing of them may stay behind.
    later_table = "slr_clock"
    assert any(later_table in text for number, _, text in migration_scripts() if number > 1)
    path = foreign_sqlite(tmp_path / "app.db", f"CREATE TABLE {later_table}(x)")
    message = refuse(path, later_table, adopt=True)
    assert "migration" in message
    conn = sqlite3.connect(path)
    assert conn.execute("PRAGMA user_version").fetchone()[0] == 0
    assert [r[0] for r in conn.execute("SELECT name FROM sqlite_master")] == [later_table]
    conn.close()


def test_the_store_layer_refuses_the_same_files(tmp_path):
    path = tmp_path / "robot.db"
    path.write_bytes(b"not a database at all" * 10)
    with pytest.raises(SLRError, match="not an SQLite database"):
        EventStore(path)
    foreign = foreign_sqlite(tmp_path / "shop.db")
    with pytest.raises(SLRError, match="not an slr_sql store"):
        EventStore(foreign)
    EventStore(foreign, adopt=True).close()


def test_an_unreadable_file_is_an_error_in_words(tmp_path):
    if os.geteuid() == 0:  # root reads every file: make the path a dangling symlink instead
        path = tmp_path / "robot.db"
        path.symlink_to(tmp_path / "gone" / "robot.db")
        with pytest.raises(SLRError) as raised:
            slr_sql.open(path)
        assert str(path) in str(raised.value)
        return
    path = make_store(tmp_path / "robot.db")
    path.chmod(0)
    try:
        with pytest.raises(SLRError) as raised:
            slr_sql.open(path)
        assert str(path) in str(raised.value)
    finally:
        path.chmod(0o644)


def test_a_newer_store_in_wal_mode_is_refused_without_side_files(tmp_path):
    path = make_store(tmp_path / "robot.db")
    conn = sqlite3.connect(path, isolation_level=None)
    conn.execute(f"PRAGMA user_version = {migration_scripts()[-1][0] + 1}")
    conn.close()
    assert path.read_bytes()[18:20] == b"\x02\x02"  # still a WAL database
    refuse(path, "newer")


def test_a_store_open_in_another_connection_opens_as_usual(tmp_path):
    path = make_store(tmp_path / "robot.db")
    with slr_sql.open(path, clock=ManualClock(0.0)) as first:
        first.add("p(1)^1")
        with slr_sql.open(path, clock=ManualClock(0.0)) as second:
            assert second.query("p(X)^_") == [{"X": 1}]


def test_a_path_beginning_with_file_colon_is_that_file_not_a_uri_of_another(tmp_path,
                                                                            monkeypatch):
    # SQLite reads a name beginning with 'file:' as a URI: the store's connection opened
    # foreign.db for 'file:foreign.db' and made it a store without adopt=True, which the
    # checks (on the path as given) had not looked at, while its readers opened the path
    foreign = tmp_path / "foreign.db"
    with sqlite3.connect(foreign) as conn:
        conn.execute("CREATE TABLE orders (id INTEGER)")
    before = snapshot(foreign)
    monkeypatch.chdir(tmp_path)
    with slr_sql.open("file:foreign.db", clock=ManualClock(0)) as kb:
        kb.add("seen(a)^1")
    assert snapshot(foreign)[:2] == before[:2]   # (its bytes and time: untouched)
    assert (tmp_path / "file:foreign.db").is_file()
    with slr_sql.open(str(tmp_path / "file:foreign.db"), clock=ManualClock(0)) as kb:
        assert kb.query("seen(X)^T") == [{"X": slr_sql.Atom("a"), "T": 1.0}]


def test_a_path_beginning_with_two_slashes_is_opened_and_read(tmp_path):
    # POSIX allows '//dir/robot.db' (abspath keeps it): its URI read '//dir' as a host, which
    # SQLite refuses ('invalid uri authority'), so a store added to could not be read back
    path = "/" + str(tmp_path / "robot.db")
    assert path.startswith("//")
    with slr_sql.open(path, clock=ManualClock(0)) as kb:
        kb.add("seen(a)^1")
    with slr_sql.open(path, clock=ManualClock(0)) as kb:
        assert kb.sql("SELECT arg1 FROM seen")[1] == [("a",)]
        assert kb.query("seen(X)^T") == [{"X": slr_sql.Atom("a"), "T": 1.0}]
