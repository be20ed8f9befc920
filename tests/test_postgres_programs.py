"""Programs across reopen on both backends: facts become tables with inspection views, a later
load replaces them (PostgreSQL refuses to drop a table a view reads: the views are moved
aside and back), and a bad program changes nothing."""
from __future__ import annotations

import pytest

import slr_sql
from slr_sql import SLRError


def test_a_load_after_reopen_replaces_the_fact_tables_under_their_views(backend):
    with slr_sql.open(backend) as kb:
        kb.load("ok(1). ok(2).", name="a")
    with slr_sql.open(backend) as kb:
        kb.load("ok2(3).", name="b")
        assert [a["X"] for a in kb.query("ok(X)")] == [1, 2]
        assert [a["X"] for a in kb.query("ok2(X)")] == [3]
        _, rows = kb.sql("SELECT count(*) FROM ok")
        assert rows[0][0] == 2
        _, rows = kb.sql("SELECT count(*) FROM ok2")
        assert rows[0][0] == 1


@pytest.mark.parametrize("bad", ["bad( :- .", ":- no_such_directive(x).", "atom(x) :- true."])
def test_a_bad_program_after_reopen_changes_nothing(backend, bad):
    with slr_sql.open(backend) as kb:
        kb.load("ok(1).")
    with slr_sql.open(backend) as kb:
        with pytest.raises(SLRError):
            kb.load("ok2(1).\n" + bad)
        assert kb.query("ok(X)") == [{"X": 1}]
        kb.load("ok2(2).")
        assert kb.query("ok2(X)") == [{"X": 2}]
