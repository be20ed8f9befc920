"""PostgreSQL: a statement handed to ``kb.sql(..., write=True)`` runs on the store's own
connection, whose settings last for every later statement of the store: a ``SET`` or
``RESET`` (``LOCAL`` or not, of a setting, the role, the session authorization) is refused in
words before anything is sent, and a statement that changed a setting or the role all the
same (``set_config(..., false)``, in a ``DO`` block, beside an INSERT) is rolled back and
refused: nothing of it is written, the store's search_path, read-only default and role are
as they were, and the store adds and queries in its own schema as before -- in a transaction
of the caller's too, which goes on and commits the rest (docs/sql.md, "What a statement
may call"). A read-only statement's settings are undone with its transaction
(tests/test_postgres_read_only_sql_session.py)."""
from __future__ import annotations

import psycopg
import pytest

import slr_sql
from slr_sql import SLRError

ROLE = "slr_settings_other"

REFUSED_BY_KEYWORD = [
    "SET search_path = public", "SET default_transaction_read_only = on",
    "set local search_path = public", "SET SESSION statement_timeout = 1",
    "RESET search_path", "RESET ALL", f"SET ROLE {ROLE}", f"SET SESSION AUTHORIZATION {ROLE}",
    "/* a comment */ SET TIME ZONE 'Europe/Paris'"]

# (statement, the setting it changes)
REFUSED_BY_EFFECT = [
    ("SELECT set_config('search_path', 'public', false)", "search_path"),
    ("SELECT set_config('default_transaction_read_only', 'on', false)",
     "default_transaction_read_only"),
    ("SELECT set_config('search_path', 'public', true)", "search_path"),
    ("DO $$ BEGIN PERFORM set_config('extra_float_digits', '-15', false); END $$",
     "extra_float_digits"),
    ("WITH w AS (INSERT INTO notes VALUES ('lost') RETURNING 1) "
     "SELECT set_config('work_mem', '8MB', false) FROM w", "work_mem"),
    (f"SELECT set_config('role', '{ROLE}', false)", "role"),
]


@pytest.fixture
def kb(postgres_url):
    with psycopg.connect(postgres_url, autocommit=True) as admin:
        admin.execute(f"DO $$ BEGIN CREATE ROLE {ROLE}; "
                      f"EXCEPTION WHEN duplicate_object THEN NULL; END $$")
    with slr_sql.open(postgres_url, clock=slr_sql.ManualClock(10.0)) as kb:
        kb.add("p(0)^0")
        kb.sql("CREATE TABLE notes (body text)", write=True)
        yield kb


def session(kb) -> list:
    """The store's connection's settings that matter here, read on it."""
    return kb.store.execute("SELECT current_setting('search_path'), "
                            "current_setting('default_transaction_read_only'), "
                            "current_setting('extra_float_digits'), "
                            "current_setting('work_mem'), current_user, session_user")


def works_as_before(kb, postgres_url, n: int) -> None:
    """An add and a query in the store's own schema, and what another store reads."""
    kb.add(f"p({n})^{n}")
    assert [a["X"] for a in kb.query("p(X)^_")] == list(range(n + 1))
    with slr_sql.open(postgres_url, clock=slr_sql.ManualClock(10.0)) as other:
        assert [a["X"] for a in other.query("p(X)^_")] == list(range(n + 1))
    assert kb.sql("SELECT count(*) FROM notes")[1] == [(0,)]


def test_a_set_or_reset_is_refused_before_anything_is_sent(kb, postgres_url):
    before = session(kb)
    for n, statement in enumerate(REFUSED_BY_KEYWORD, 1):
        with pytest.raises(SLRError, match=r"^sql: (SET|RESET) is not allowed with "
                                           r"write=True: a setting of the store's own "
                                           r"connection would last for every later"):
            kb.sql(statement, write=True)
        assert session(kb) == before, statement
        works_as_before(kb, postgres_url, n)


def test_a_statement_that_changed_a_setting_is_rolled_back_and_refused(kb, postgres_url):
    before = session(kb)
    for n, (statement, setting) in enumerate(REFUSED_BY_EFFECT, 1):
        with pytest.raises(SLRError) as caught:
            kb.sql(statement, write=True)
        assert str(caught.value).startswith(
            f"sql: the statement changed {setting} of the session, which is not allowed "
            f"with write=True: "), str(caught.value)
        assert str(caught.value).endswith("; it was rolled back, nothing of it was written")
        assert session(kb) == before, statement
        works_as_before(kb, postgres_url, n)


def test_in_a_transaction_only_the_statement_is_taken_back(kb, postgres_url):
    """Rolled back to a savepoint before it: the caller's transaction goes on and commits
    the rest; a statement with a timeout (the store's own SET LOCAL) is no change."""
    before = session(kb)
    with kb.store.transaction():
        kb.add("p(1)^1")
        for statement, _ in REFUSED_BY_EFFECT:
            with pytest.raises(SLRError, match="; it was rolled back, nothing of it was"):
                kb.sql(statement, write=True)
            with pytest.raises(SLRError, match=r"^sql: SET is not allowed"):
                kb.sql("SET LOCAL search_path = public", write=True)
            assert session(kb) == before, statement
        kb.sql("INSERT INTO notes VALUES ('kept')", write=True, timeout=30)
        kb.add("p(2)^2")
    assert session(kb) == before
    assert kb.sql("SELECT body FROM notes")[1] == [("kept",)]
    kb.sql("DELETE FROM notes", write=True, timeout=30)
    works_as_before(kb, postgres_url, 3)


def test_what_changes_no_setting_still_runs(kb):
    assert kb.sql("SET CONSTRAINTS ALL IMMEDIATE", write=True) == ([], [])
    assert kb.sql("SELECT set_config('search_path', current_setting('search_path'), false)",
                  write=True)[1] == [("slr, pg_temp",)]
    # a read-only statement's settings are undone with its own transaction
    assert kb.sql("SET search_path = public") == ([], [])
    assert kb.sql("SELECT count(*) FROM p")[1] == [(1,)]
