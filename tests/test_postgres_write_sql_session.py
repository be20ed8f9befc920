"""PostgreSQL: what a statement handed to ``kb.sql(..., write=True)`` leaves in the store's
own connection's session. A temporary table it made does not hide the store's table of the
same name (the store's search_path names ``pg_temp`` last: unnamed, the session's temporary
schema is searched first), and a session advisory lock it took is let go after it, as after a
read-only statement (docs/sql.md, "What a statement may call")."""
from __future__ import annotations

import pytest

import slr_sql


@pytest.fixture
def kb(postgres_url):
    with slr_sql.open(postgres_url, clock=slr_sql.ManualClock(10.0)) as kb:
        kb.add("p(0)^0")
        yield kb


def events(kb) -> list:
    return sorted(a["X"] for a in kb.query("p(X)^_"))


@pytest.mark.parametrize("in_transaction", [False, True])
def test_a_temporary_table_does_not_hide_the_stores_table(kb, postgres_url, in_transaction):
    statements = ["CREATE TEMP TABLE p (x int)", "CREATE TEMPORARY TABLE slr_event_types (x int)",
                  "INSERT INTO pg_temp.p VALUES (7)"]
    if in_transaction:
        with kb.store.transaction():
            for statement in statements:
                kb.sql(statement, write=True)
            kb.add("p(1)^1")
    else:
        for statement in statements:
            kb.sql(statement, write=True)
        kb.add("p(1)^1")
    kb.add("p(2)^2")
    kb.add("q(5)^3")   # (a new type: slr_event_types is the store's)
    assert events(kb) == [0, 1, 2]
    assert [a["X"] for a in kb.query("q(X)^_")] == [5]
    # the temporary table is there all the same, named by its schema
    assert kb.sql("SELECT x FROM pg_temp.p", write=True)[1] == [(7,)]
    with slr_sql.open(postgres_url, clock=slr_sql.ManualClock(10.0)) as other:
        assert events(other) == [0, 1, 2]
        other.add("p(3)^4")
    assert events(kb) == [0, 1, 2, 3]
