"""The store package's own interface beyond EventStore: run_sql_file, DatabaseError, migrations."""
from __future__ import annotations

from pathlib import Path

import pytest

import slr_sql
from slr_sql.store import DatabaseError, EventStore, migration_scripts, run_sql_file


@pytest.fixture
def store_file(tmp_path):
    path = tmp_path / "robot.db"
    with EventStore(path, slr_sql.ManualClock(5.0)) as store:
        store.add_events([("obj", ("cup1", "red"), 1.0, 1.0), ("obj", ("cup2", "blue"), 2.0, 3.0)])
    return path


def test_run_sql_file_returns_columns_and_rows(store_file):
    columns, rows = run_sql_file(store_file, "SELECT arg1, arg2, t_start, t_end FROM obj "
                                             "ORDER BY t_end")
    assert columns == ["arg1", "arg2", "t_start", "t_end"]
    assert rows == [("cup1", "red", 1.0, 1.0), ("cup2", "blue", 2.0, 3.0)]


def test_run_sql_file_is_read_only_unless_asked(store_file):
    with pytest.raises(slr_sql.SLRError, match=r"^sql: .*readonly"):
        run_sql_file(store_file, "DELETE FROM obj")
    assert run_sql_file(store_file, "SELECT count(*) FROM obj")[1] == [(2,)]
    assert run_sql_file(store_file, "DELETE FROM obj WHERE arg1 = 'cup1'", write=True) == ([], [])
    with EventStore(store_file) as store:
        assert [args for args, *_ in store.scan("obj", 2)] == [("cup2", "blue")]


@pytest.mark.parametrize("statement", ["SELECT * FROM no_such_table", "SELEC 1",
                                       "SELECT 1; SELECT 2"])
def test_run_sql_file_reports_sql_errors_as_slr_errors(store_file, statement):
    with pytest.raises(slr_sql.SLRError, match=r"^sql: "):
        run_sql_file(store_file, statement)


def test_run_sql_file_on_a_missing_file_names_it(tmp_path):
    missing = tmp_path / "nothing.db"
    with pytest.raises(slr_sql.SLRError, match="no such store: .*nothing.db"):
        run_sql_file(missing, "SELECT 1")
    assert not missing.exists()  # and it did not create one


def test_run_sql_file_handles_uri_characters_in_the_path(tmp_path):
    path = tmp_path / "odd?name#100%.db"
    EventStore(path).close()
    assert run_sql_file(path, "SELECT count(*) FROM slr_program") == (["count(*)"], [(0,)])


@pytest.mark.parametrize("call", [
    lambda s: s.execute("SELECT * FROM no_such_table"),
    lambda s: s.sql("SELEC 1"),
    lambda s: s.executemany("INSERT INTO slr_meta VALUES (?, ?)", [("k", "1"), ("k", "2")]),
    lambda s: s.run_compiled("SELECT :a + no_such_column", {"a": 1}),
])
def test_statement_errors_are_database_errors(call):
    with EventStore(None) as store:
        with pytest.raises(DatabaseError):
            call(store)


def test_migrations_come_from_the_migrations_folder():
    folder = Path(__file__).resolve().parent.parent / "migrations"
    on_disk = sorted(path.name for path in folder.glob("[0-9]*.sql"))
    assert [name for _, name, _ in migration_scripts()] == on_disk
    assert [text for *_, text in migration_scripts()] == [
        (folder / name).read_text(encoding="utf-8") for name in on_disk]
