"""A store file deleted, moved or replaced while a knowledge base has it open: the next write
raises SLRStoreGone naming the path before anything is acknowledged (it used to be written
into the deleted file and lost at close)."""
from __future__ import annotations

import os
import shutil

import pytest

import slr_sql
from slr_sql import ManualClock, SLRError, SLRStoreGone


def remove_store(path) -> list[str]:
    """``rm robot.db*``: returns the names removed."""
    folder, base = os.path.split(str(path))
    removed = sorted(n for n in os.listdir(folder) if n.startswith(base))
    for name in removed:
        os.remove(os.path.join(folder, name))
    return removed


# The stores here get a ManualClock: their events are stamped 1, 2 (not wall-clock times,
# which would make each type's first event "decades late", a LearnedDelayWarning), and no
# test here waits on time.
@pytest.fixture
def kb(tmp_path):
    kb = slr_sql.open(tmp_path / "robot.db", clock=ManualClock(0.0))
    kb.add("p(1)^1")
    yield kb
    kb.close()


@pytest.mark.parametrize("write", [
    lambda kb: kb.add("p(2)^2"),
    lambda kb: kb.add_many(["p(2)^2", "q(1)^2"]),
    lambda kb: kb.add_event("p", [2], 2, 2),
    lambda kb: kb.load("r(1)."),
    lambda kb: kb.add_buffer("p(_)", keep_last=3),
    # a table of no event type: kb.sql runs it outside a transaction, no COMMIT checks
    lambda kb: kb.sql("CREATE TABLE notes (body)", write=True),
    lambda kb: kb.sql("UPDATE slr_meta SET value = value", write=True),
], ids=["add", "add_many", "add_event", "load", "add_buffer", "sql_create", "sql_update"])
def test_writing_after_rm_of_the_store_raises_naming_the_path(kb, tmp_path, write):
    assert "robot.db" in remove_store(tmp_path / "robot.db")
    with pytest.raises(SLRStoreGone) as caught:
        write(kb)
    message = str(caught.value)
    assert str(tmp_path / "robot.db") in message
    assert "deleted or replaced while open" in message and "nothing of this call" in message
    with pytest.raises(SLRStoreGone):   # and again: it does not pass by itself
        kb.add("p(3)^3")


def test_a_statement_failing_on_a_deleted_store_says_store_gone(kb, tmp_path):
    """A statement the store runs for the parts above outside a transaction (no commit
    checks the file) that fails on the file (here at its page limit) once the file was
    deleted: what the failure is about is a file no longer the store, and it says so."""
    store = kb.store
    store.execute("CREATE TABLE notes (body)")
    store.execute(f"PRAGMA max_page_count = {store.execute('PRAGMA page_count')[0][0]}")
    remove_store(tmp_path / "robot.db")
    with pytest.raises(SLRStoreGone, match="robot.db: the store file was deleted or replaced "
                                           "while open") as caught:
        store.execute("INSERT INTO notes VALUES (?)", (b"x" * 100_000,))
    assert "disk is full" not in str(caught.value)


def test_a_store_replaced_by_another_file_is_noticed(kb, tmp_path):
    other = tmp_path / "other.db"
    with slr_sql.open(other, clock=ManualClock(0.0)) as second:
        second.add("x(1)^1")
    os.replace(other, tmp_path / "robot.db")
    with pytest.raises(SLRStoreGone, match="robot.db: the store file was deleted or replaced"):
        kb.add("p(2)^2")
    kb.close()
    with slr_sql.open(tmp_path / "robot.db") as reopened:  # the replacement is untouched
        assert reopened.query("x(X)^T") == [{"X": 1, "T": 1.0}]
        assert "p" not in [n for n, in reopened.sql("SELECT name FROM sqlite_master")[1]]


def test_a_store_moved_away_is_noticed_and_the_moved_file_keeps_its_events(kb, tmp_path):
    shutil.move(tmp_path / "robot.db", tmp_path / "moved.db")
    with pytest.raises(SLRStoreGone):
        kb.add("p(2)^2")


def test_a_deleted_write_ahead_log_is_noticed(kb, tmp_path):
    os.remove(tmp_path / "robot.db-wal")
    with pytest.raises(SLRStoreGone, match=r"write-ahead log \(-wal\) was deleted"):
        kb.add("p(2)^2")


def test_changing_the_working_directory_is_not_a_replacement(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with slr_sql.open("robot.db", clock=ManualClock(0.0)) as kb:
        kb.add("p(1)^1")
        elsewhere = tmp_path / "elsewhere"
        elsewhere.mkdir()
        monkeypatch.chdir(elsewhere)
        kb.add("p(2)^2")
        assert kb.sql("SELECT count(*) FROM p")[1] == [(2,)]


def test_reads_keep_working_and_close_is_quiet(kb, tmp_path):
    remove_store(tmp_path / "robot.db")
    assert [a["X"] for a in kb.query("p(X)^T")] == [1]   # what the open file holds
    kb.close()
    assert not (tmp_path / "robot.db").exists()


def test_store_gone_is_retryable_and_an_slr_error():
    assert issubclass(SLRStoreGone, SLRError)
    assert "SLRStoreGone" in slr_sql.__all__
