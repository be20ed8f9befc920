"""A statement handed to ``kb.sql`` on a SQLite store may not create a temporary table, view,
trigger or index: it would outlast the statement on the store's own connection, where SQLite
reads an unqualified name in the ``temp`` schema first. A temporary table named as an event
type's table took that type's reads (a query answered nothing) and its adds (lost when the
connection closed); a temporary trigger ran inside the store's own inserts. Each spelling is
refused in words, with ``write=True`` or without, and the store goes on as it was (docs/sql.md).
Tables, views and triggers in the store's file are still created with ``write=True``."""
from __future__ import annotations

import pytest

import slr_sql
from slr_sql import SLRError

REFUSED = "a temporary table, view, trigger or index is not allowed"

TEMPORARY = [
    "CREATE TEMP TABLE p AS SELECT * FROM main.p WHERE 0",
    "CREATE TEMPORARY TABLE p(seq INTEGER, arg1, t_start REAL, t_end REAL)",
    "CREATE TABLE temp.p AS SELECT * FROM main.p",
    'CREATE TABLE "TEMP".p(a)',
    "CREATE TEMP VIEW p AS SELECT * FROM main.p WHERE 0",
    "CREATE VIEW temp.p AS SELECT 1",
    "CREATE TEMP TRIGGER quiet BEFORE INSERT ON main.p BEGIN SELECT RAISE(IGNORE); END",
    "CREATE TRIGGER temp.quiet BEFORE INSERT ON p BEGIN SELECT RAISE(IGNORE); END",
]
# (a temporary index needs a temporary table: SQLite refuses one on a table of the file)


@pytest.fixture
def kb(tmp_path):
    kb = slr_sql.open(tmp_path / "s.db", clock=slr_sql.ManualClock(10.0))
    kb.add("p(a)^1")
    yield kb
    kb.close()


@pytest.mark.parametrize("write", [True, False])
@pytest.mark.parametrize("statement", TEMPORARY)
def test_a_temporary_object_is_refused_and_the_store_reads_and_adds_as_before(
        kb, tmp_path, statement, write):
    with pytest.raises(SLRError) as caught:
        kb.sql(statement, write=write)
    assert str(caught.value).startswith("sql: ") and REFUSED in str(caught.value), \
        str(caught.value)
    assert kb.sql("SELECT count(*) FROM temp.sqlite_master")[1] == [(0,)]
    kb.add("p(b)^2")
    assert [a["X"] for a in kb.query("p(X)^T")] == ["a", "b"]
    kb.close()
    with slr_sql.open(tmp_path / "s.db", clock=slr_sql.ManualClock(10.0)) as again:
        assert [a["X"] for a in again.query("p(X)^T")] == ["a", "b"]


def test_a_temporary_virtual_table_is_refused_in_the_same_words(kb):
    # (refused inside the virtual table's own statements: SQLite says only that its
    # constructor failed, and the reason is the guard's)
    with pytest.raises(SLRError) as caught:
        kb.sql("CREATE VIRTUAL TABLE temp.p USING fts3(arg1)", write=True)
    assert REFUSED in str(caught.value), str(caught.value)
    assert kb.sql("SELECT count(*) FROM temp.sqlite_master")[1] == [(0,)]
    assert [a["X"] for a in kb.query("p(X)^T")] == ["a"]


def test_objects_in_the_stores_file_are_still_created(kb):
    kb.sql("CREATE TABLE mine(a)", write=True)
    kb.sql("CREATE VIEW mine_v AS SELECT a FROM mine", write=True)
    kb.sql("CREATE TRIGGER mine_t AFTER INSERT ON mine BEGIN SELECT 1; END", write=True)
    kb.sql("CREATE INDEX mine_i ON mine(a)", write=True)
    kb.sql("INSERT INTO mine VALUES (1)", write=True)
    assert kb.sql("SELECT a FROM mine_v")[1] == [(1,)]
    assert kb.sql("WITH t(x) AS (SELECT 2) SELECT x FROM t")[1] == [(2,)]
