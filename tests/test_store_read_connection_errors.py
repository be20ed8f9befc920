"""A store's read connections (:class:`ReadConnection`: the subscription hub's journal reads)
turn every failure of SQLite into an SLRError named after the condition, as the store's
own connection does (``store_error``): a journal another connection dropped, a file
overwritten with garbage (damaged, not a database), the store file deleted. No
``sqlite3.Error`` reaches the caller, and the hub logs such a failed pass as one line. The
store's own connection says a damaged file in the same words (``Database.failure``).

Every condition is real: another ``sqlite3`` connection drops the table, the file's bytes
are overwritten on disk, the file is removed."""
from __future__ import annotations

import logging
import os
import sqlite3

import pytest

import slr_sql
from slr_sql.errors import SLRError, SLRStoreGone
from slr_sql.store import EventStore
from slr_sql.store.connection import Database

from hub_helpers import hub_with_one_delivery
from store_conditions import file_condition, slr_failure

DEADLINE = 30.0


def _drop_table_behind_the_store(path: str, table: str) -> None:
    """Drop ``table`` of the store file at ``path`` as another process would."""
    raw = sqlite3.connect(path, isolation_level=None)
    try:
        raw.execute(f'DROP TABLE "{table}"')
    finally:
        raw.close()


def _store_with_journal(path: str) -> EventStore:
    store = EventStore(path)
    store.add_event("p", ("a",), 1, 1)
    store.create_journal("p", 1, "slr_subj_p", "slr_subt_p")
    store.add_event("p", ("b",), 2, 2)
    return store


def test_a_journal_dropped_by_another_connection_is_an_slr_error(tmp_path):
    path = str(tmp_path / "s.db")
    store = _store_with_journal(path)
    reads = store.journal_reader(own_connection=True)
    try:
        # read once: the reader holds the statement prepared when the table goes
        assert reads.journal_rows("slr_subj_p", 1, 0, 10) == [(1, 2, "b", 2.0, 2.0)]
        _drop_table_behind_the_store(path, "slr_subj_p")
        exc = slr_failure(lambda: reads.journal_rows("slr_subj_p", 1, 0, 10))
        assert type(exc) is SLRError
        assert str(exc) == f"{path}: the store failed (no such table: slr_subj_p)"
        assert reads.event_table("p", 1) is not None   # the connection itself still reads
    finally:
        reads.close()
        store.close()


@pytest.mark.parametrize("through", ["reader", "execute", "run_compiled"])
def test_pages_overwritten_with_garbage_are_a_damaged_file(tmp_path, through):
    """On a reading connection, and on the store's own: its statements for the parts
    above (``execute``, a compiled query's ``run_compiled``) say it in the same words."""
    path = str(tmp_path / "s.db")
    store = EventStore(path)
    for i in range(200):
        store.add_event("p", (f"x{i}" * 20,), i, i)
    store.close()                       # checkpointed: every page is in the file
    reader = EventStore(path)
    conn = reader.open_reader()
    run = {"reader": conn.execute, "execute": reader.execute,
           "run_compiled": lambda sql: reader.run_compiled(sql, {})}[through]
    try:
        assert run("SELECT count(*) FROM p") == [(200,)]
        with open(path, "r+b") as f:    # the same file (inode), its pages garbage
            f.seek(4096)
            f.write(b"\x0d" * (os.path.getsize(path) - 4096))
        exc = slr_failure(lambda: run("SELECT * FROM p"))
        assert type(exc) is SLRError
        assert str(exc).startswith(f"{path}: the file is damaged (database disk image is "
                                   f"malformed)")
    finally:
        conn.close()
        reader.close()


def test_a_file_that_became_no_database_is_a_damaged_file(tmp_path):
    path = str(tmp_path / "s.db")
    store = _store_with_journal(path)
    conn = store.open_reader()
    try:
        assert conn.execute("SELECT count(*) FROM slr_subj_p") == [(1,)]
        store.close()
        with open(path, "r+b") as f:    # the whole file, header included
            f.write(b"\xff" * os.path.getsize(path))
        exc = slr_failure(lambda: conn.execute("SELECT count(*) FROM p"))
        assert type(exc) is SLRError and "the file is damaged" in str(exc)
        # a reader opened on it now: the same words, at its open
        exc = slr_failure(lambda: slr_sql.store.ReadConnection(path))
        assert type(exc) is SLRError and "the file is damaged" in str(exc)
    finally:
        conn.close()


def test_the_stores_own_reads_of_a_file_that_became_no_database_say_damaged(tmp_path):
    """The store's connection (the reads of the subscription hub's housekeeping: the tables,
    a journal's positions) once the file's bytes are garbage and its cached pages dropped."""
    path = str(tmp_path / "s.db")
    _store_with_journal(path).close()
    store = EventStore(path)
    try:
        with open(path, "r+b") as f:    # the whole file, header included
            f.write(b"\xff" * os.path.getsize(path))
        store.execute("PRAGMA shrink_memory")   # the next read reads the file
        for call in (store.table_names, lambda: store.execute("SELECT count(*) FROM p"),
                     lambda: store.live_positions("p", 1)):
            exc = slr_failure(call)
            assert type(exc) is SLRError
            assert str(exc).startswith(f"{path}: the file is damaged (file is not a database)")
    finally:
        store.close()


# Every public method of the store's connection that runs a statement: each says a condition
# of the file (damaged, no longer the store) as an SLRError, in execute's words
READS = {
    "data_version": lambda db: db.data_version(),
    "schema_version": lambda db: db.schema_version(),
    "table_names": lambda db: db.table_names(),
    "triggers": lambda db: db.triggers("p"),
    "index_names": lambda db: db.index_names("p"),
    "object_names": lambda db: db.object_names(),
    "view_statements": lambda db: db.view_statements(["v"]),
    "sql": lambda db: db.sql("SELECT count(*) FROM p"),
    "sql_write": lambda db: db.sql_write("DELETE FROM p WHERE arg1 = ?", ("none",)),
}


@pytest.mark.parametrize("afterwards", ["damaged", "replaced"])
@pytest.mark.parametrize("read", READS.values(), ids=READS.keys())
def test_each_statement_of_the_stores_connection_says_the_files_condition(
        tmp_path, read, afterwards):
    """The file's bytes turned to garbage under the open connection (its cached pages
    dropped): a damaged file; and once another store took its place at the path as well,
    SLRStoreGone (the file open is no longer the store)."""
    path = str(tmp_path / "s.db")
    _store_with_journal(path).close()
    db = Database(path)
    try:
        exc = file_condition(path, db, read, afterwards, _store_with_journal)
        if afterwards == "damaged":
            assert "(file is not a database)" in str(exc)
    finally:
        db.close()


@pytest.mark.parametrize("read", [*READS.values(), lambda db: db.changes(),
                                  lambda db: db.query_plan("SELECT * FROM p")],
                         ids=[*READS.keys(), "changes", "query_plan"])
def test_each_statement_of_a_closed_store_says_it_is_closed(tmp_path, read):
    db = Database(str(tmp_path / "s.db"))
    db.close()
    assert str(slr_failure(lambda: read(db))) == "the event store is closed"


def test_a_reader_opened_after_the_store_file_was_deleted_is_store_gone(tmp_path):
    path = str(tmp_path / "s.db")
    store = _store_with_journal(path)
    try:
        for suffix in ("", "-wal", "-shm"):
            os.remove(path + suffix)
        exc = slr_failure(lambda: store.journal_reader(own_connection=True))
        assert isinstance(exc, SLRStoreGone)
        assert str(exc).startswith(f"{path}: the store file was deleted or replaced while open")
        assert not os.path.exists(path)   # no empty file made at the store's path
    finally:
        store.close()


def test_a_reader_opened_after_the_store_file_was_replaced_is_store_gone(tmp_path):
    path = str(tmp_path / "s.db")
    store = _store_with_journal(path)
    other = str(tmp_path / "other.db")
    _store_with_journal(other).close()
    try:
        os.replace(other, path)
        exc = slr_failure(store.open_reader)
        assert isinstance(exc, SLRStoreGone)
    finally:
        store.close()


def test_the_hub_logs_a_read_of_a_dropped_journal_as_one_line(tmp_path, caplog):
    path = str(tmp_path / "s.db")
    with hub_with_one_delivery(path, caplog) as (kb, hub, sub):
        _drop_table_behind_the_store(path, "slr_subj_p")
        assert hub.drain(DEADLINE)
        records = [r for r in caplog.records if "delivery pass failed" in r.getMessage()]
        assert len(records) == 1, caplog.text
        [record] = records
        assert record.levelno == logging.WARNING
        assert record.exc_info is None and "Traceback" not in caplog.text
        assert "\n" not in caplog.handler.format(record)
        assert "SLRError" in record.getMessage()
        assert "no such table: slr_subj_p" in record.getMessage()
        sub.close()


def test_a_trim_of_a_journal_another_connection_dropped_is_an_slr_error(tmp_path, caplog):
    """The hub's housekeeping lists the journals, then trims each: one another connection
    dropped in between failed with the raw database error, which the housekeeping logged
    with a traceback (an ERROR: "a bug of this package"); it is the SLRError a read of that
    journal is (one WARNING line)."""
    path = str(tmp_path / "s.db")
    with hub_with_one_delivery(path, caplog) as (kb, hub, sub):
        _drop_table_behind_the_store(path, "slr_subj_p")
        with pytest.raises(SLRError, match="no such table: slr_subj_p"):
            kb.store.trim_journal("slr_subj_p", 1)
        assert kb.store.subscription_rows()   # (the registry reads on)
        sub.close()


def test_a_reader_opened_after_a_chdir_reads_the_store(tmp_path, monkeypatch):
    """A store opened by a relative path: its reader opens the file the store has open, not
    the path in the working directory of now (no empty file made there, no error)."""
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    monkeypatch.chdir(tmp_path / "a")
    store = _store_with_journal("s.db")
    try:
        monkeypatch.chdir(tmp_path / "b")
        reads = store.journal_reader(own_connection=True)
        try:
            assert reads.journal_rows("slr_subj_p", 1, 0, 10) == [(1, 2, "b", 2.0, 2.0)]
        finally:
            reads.close()
        assert not os.path.exists(tmp_path / "b" / "s.db")
    finally:
        store.close()


def test_a_pass_reading_through_the_stores_connection_logs_a_dropped_journal_as_one_line(
        tmp_path, caplog):
    """The pass after events added inside a transaction reads through the store's own
    connection (which waits for its commit): the same words, one WARNING line."""
    path = str(tmp_path / "s.db")
    with hub_with_one_delivery(path, caplog) as (kb, hub, sub):
        assert hub.drain(DEADLINE)
        _drop_table_behind_the_store(path, "slr_subj_p")
        hub.notify(through_store=True)    # the next pass reads through the store's connection
        assert hub.drain(DEADLINE)
        assert not [r for r in caplog.records if r.levelno >= logging.ERROR], caplog.text
        [record] = [r for r in caplog.records if "delivery pass failed" in r.getMessage()]
        assert record.levelno == logging.WARNING and record.exc_info is None
        assert f"SLRError: {path}: the store failed (no such table: slr_subj_p)" in \
            record.getMessage()
        sub.close()


def test_a_journal_read_through_the_stores_connection_is_an_slr_error(tmp_path):
    path = str(tmp_path / "s.db")
    store = _store_with_journal(path)
    try:
        reads = store.journal_reader(own_connection=False)
        _drop_table_behind_the_store(path, "slr_subj_p")
        exc = slr_failure(lambda: reads.max_jid("slr_subj_p"))
        assert str(exc) == f"{path}: the store failed (no such table: slr_subj_p)"
        for suffix in ("", "-wal", "-shm"):
            os.remove(path + suffix)
        assert isinstance(slr_failure(lambda: reads.max_jid("slr_subj_p")), SLRStoreGone)
    finally:
        store.close()
