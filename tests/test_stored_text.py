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
