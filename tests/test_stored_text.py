"""Text that is no UTF-8 in a store file (another program wrote it: the sqlite3 shell with
``CAST(x'ff' AS TEXT)``, Python's sqlite3 writing bytes as text): every other row is read,
the bad text with U+FFFD in place of its bad bytes, and a warning says so and how to find
its row. Python's sqlite3 refused the value, so one bad row made its whole event type
unreadable by kb.query, kb.sql, `slr sql`, `slr query` and `slr describe`."""
from __future__ import annotations

import sqlite3
import warnings

import pytest
from test_cli import slr

import slr_sql
from slr_sql.store.stored_text import StoredTextWarning

BAD = b"gre\xffn"


@pytest.fixture
def store(tmp_path) -> str:
    """A store of three obj events; the second one's color rewritten by another program
    as text that is no UTF-8."""
    db = str(tmp_path / "robot.db")
    with slr_sql.open(db, clock=slr_sql.ManualClock(100)) as kb:
        kb.add_many(["obj(cup1, cup, red)^1", "obj(cup2, cup, blue)^2", "obj(cup3, cup, green)^3"])
    other = sqlite3.connect(db)
    other.execute("UPDATE obj SET arg3 = CAST(? AS TEXT) WHERE arg1 = 'cup2'", (BAD,))
    other.commit()
    other.close()
    return db


def test_the_library_reads_the_other_rows_and_the_bad_text_with_a_warning(store):
    with slr_sql.open(store, clock=slr_sql.ManualClock(100)) as kb:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            answers = [(a["O"], a["C"]) for a in kb.query("obj(O, _, C)^_")]
            columns, rows = kb.sql("SELECT arg1, arg3 FROM obj ORDER BY seq")
        assert answers == [("cup1", "red"), ("cup2", "gre\ufffdn"), ("cup3", "green")]
        assert [tuple(r) for r in rows] == answers
        said = {str(w.message) for w in caught if w.category is StoredTextWarning}
        assert len(said) == 1
        condition = said.pop().split("its row is found with the condition ")[1]
        # the condition the warning gives finds the row
        assert [r[0] for r in kb.sql(f"SELECT arg1 FROM obj WHERE "
                                     f"{condition.replace('column', 'arg3')}")[1]] == ["cup2"]


def test_the_commands_read_the_other_rows_and_warn_once(store):
    r = slr("sql", store, "SELECT arg1, arg3 FROM obj ORDER BY seq", "--csv")
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines() == ["arg1,arg3", "cup1,red", "cup2,gre\ufffdn", "cup3,green"]
    assert r.stderr.count("warning: the store holds text that is no UTF-8") == 1
    assert "x'677265ff6e'" in r.stderr and "Traceback" not in r.stderr
    r = slr("query", store, "obj(O, _, C)^_")
    assert r.returncode == 0, r.stderr
    assert "O = cup2, C = 'gre\ufffdn'" in r.stdout and "O = cup3, C = green" in r.stdout
    r = slr("describe", store, "obj")
    assert r.returncode == 0, r.stderr
    assert "events:      3" in r.stdout and "error" not in r.stderr


# -------------------------------------------------------------- read without a text factory
# No store connection has a text_factory (one cost sqlite3 a bytes object and a call per text
# cell of every read): rows are read with sqlite3's own decoding, and only a read that meets
# a text that is no UTF-8 reads on, from that row, with the tolerant one
# (slr_sql/store/stored_text.py, fetch_rows). The statement is never run again: the rows
# read before the bad one are kept, none is read twice, a statement that wrote is not run
# twice.

def _many(db: str, n: int, bad: int) -> None:
    """A store of ``n`` obj events (cup0, cup1, ...), the color of the ``bad``-th rewritten
    by another program as text that is no UTF-8."""
    with slr_sql.open(db, clock=slr_sql.ManualClock(n)) as kb:
        kb.add_many([("obj", (f"cup{i}", "cup", "red"), float(i), float(i)) for i in range(n)])
    other = sqlite3.connect(db)
    other.execute("UPDATE obj SET arg3 = CAST(? AS TEXT) WHERE arg1 = ?", (BAD, f"cup{bad}"))
    other.commit()
    other.close()


def _stored_text_warnings(caught) -> list[str]:
    return [str(w.message) for w in caught if w.category is StoredTextWarning]


def test_a_store_connection_reads_without_a_text_factory(store):
    with slr_sql.open(store, clock=slr_sql.ManualClock(100)) as kb:
        conn = kb.store._db.conn
        assert conn.text_factory is str
        with warnings.catch_warnings(record=True):
            warnings.simplefilter("always")
            assert kb.sql("SELECT arg3 FROM obj ORDER BY seq")[1][1] == ("gre\ufffdn",)
        # (the tolerant reading was for the rest of that read only)
        assert conn.text_factory is str
        with warnings.catch_warnings():
            warnings.simplefilter("error")   # a warning made an error: the error, undone
            with pytest.raises(slr_sql.SLRError, match="StoredTextWarning"):
                kb.sql("SELECT arg3 FROM obj ORDER BY seq")
        assert conn.text_factory is str
        assert kb.sql("SELECT arg3 FROM obj WHERE arg1 <> 'cup2' ORDER BY seq")[1] == \
            [("red",), ("green",)]


@pytest.mark.parametrize("bad", [0, 255, 256, 300, 599])
def test_kb_sql_reads_every_row_whatever_page_the_bad_one_is_on(tmp_path, bad):
    # (a read-only statement's rows are read 256 at a time, their size checked)
    db = str(tmp_path / "robot.db")
    _many(db, 600, bad)
    with slr_sql.open(db, clock=slr_sql.ManualClock(600)) as kb:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            _, rows = kb.sql("SELECT arg1, arg3 FROM obj ORDER BY seq")
        assert [r[0] for r in rows] == [f"cup{i}" for i in range(600)]
        assert [i for i, r in enumerate(rows) if r[1] != "red"] == [bad]
        assert rows[bad][1] == "gre\ufffdn"
        assert len(_stored_text_warnings(caught)) == 1


def test_a_lazily_read_stream_meets_the_bad_row_mid_page_and_reads_each_row_once(tmp_path):
    # a scan reads its rows page by page (8, 32, 128, ...), its statement open between
    # pages; the bad row is the 13th of the second page, and the store's connection reads
    # other statements between the pages
    db = str(tmp_path / "robot.db")
    _many(db, 200, 20)
    from slr_sql.store import EventStore
    store = EventStore(db, clock=slr_sql.ManualClock(200))
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            rows = store.scan("obj", 3, {})
            read = [next(rows) for _ in range(10)]
            assert store.execute("SELECT count(*) FROM obj") == [(200,)]
            read.extend(rows)
        assert [str(r[0][0]) for r in read] == [f"cup{i}" for i in range(200)]
        assert [r[3] for r in read] == sorted({r[3] for r in read})   # each seq once
        assert [i for i, r in enumerate(read) if str(r[0][2]) != "red"] == [20]
        assert str(read[20][0][2]) == "gre\ufffdn"
        assert len(_stored_text_warnings(caught)) == 1
        assert store._db.conn.text_factory is str
    finally:
        store.close()


def test_a_statement_that_meets_a_bad_row_runs_once(store):
    with slr_sql.open(store, clock=slr_sql.ManualClock(100)) as kb:
        run = []
        kb.store._db.conn.set_trace_callback(run.append)
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                # a write whose RETURNING rows hold the bad text: run again, it would
                # write twice
                columns, rows = kb.sql("UPDATE obj SET arg2 = arg2 || '!' "
                                       "RETURNING arg1, arg3", write=True)
                _, read = kb.sql("SELECT arg1, arg3 FROM obj ORDER BY seq")
        finally:
            kb.store._db.conn.set_trace_callback(None)
        assert sorted(rows) == [("cup1", "red"), ("cup2", "gre\ufffdn"), ("cup3", "green")]
        assert read == [("cup1", "red"), ("cup2", "gre\ufffdn"), ("cup3", "green")]
        assert [s for s in run if s.startswith(("UPDATE obj", "SELECT arg1"))] == \
            ["UPDATE obj SET arg2 = arg2 || '!' RETURNING arg1, arg3",
             "SELECT arg1, arg3 FROM obj ORDER BY seq"]
        assert kb.sql("SELECT DISTINCT arg2 FROM obj")[1] == [("cup!",)]
        assert len(_stored_text_warnings(caught)) == 2   # one per read of it


def test_a_reading_connection_of_its_own_reads_the_bad_text(store):
    # (the subscription hub's journals and slr serve's readers use one)
    from slr_sql.store.connection import ReadConnection
    reader = ReadConnection(store)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            rows = reader.execute("SELECT arg1, arg3 FROM obj ORDER BY seq")
        assert rows == [("cup1", "red"), ("cup2", "gre\ufffdn"), ("cup3", "green")]
        assert len(_stored_text_warnings(caught)) == 1
        assert reader.conn.text_factory is str
    finally:
        reader.close()
