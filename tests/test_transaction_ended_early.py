"""A transaction whose statement met the store's size limit (SQLITE_FULL, for real:
``max_page_count``) on a table without indexes: SQLite rolls the whole transaction back by
itself, levels still open. The levels that go on must neither commit their later statements
one by one (outside any transaction) nor end with sqlite3's "cannot commit - no transaction is
active" or "no such savepoint": the error a level's body raised is what its caller hears,
a level that ends normally says the transaction was rolled back (SLRStoreFull, in words), and
the store holds what it held before the transaction began."""
from __future__ import annotations

import pytest

import slr_sql
from slr_sql import SLRError, SLRStoreFull
from slr_sql.store import EventStore

from store_conditions import slr_failure

BIG = b"x" * 100_000


@pytest.fixture
def store(tmp_path):
    """A store file with a table ``notes`` holding ``kept``, at its size limit: a row of
    ``BIG`` does not fit (a small one does, in the table's page)."""
    store = EventStore(str(tmp_path / "robot.db"))
    store.execute("CREATE TABLE notes (body)")
    store.execute("INSERT INTO notes VALUES ('kept')")
    pages = store.execute("PRAGMA page_count")[0][0]
    store.execute(f"PRAGMA max_page_count = {pages}")
    try:
        yield store
    finally:
        store.close()


def notes(store) -> list:
    return [body for body, in store.execute("SELECT body FROM notes ORDER BY rowid")]


def test_a_body_that_carries_on_after_the_full_disk_commits_nothing(store):
    def transaction():
        with store.transaction():
            store.execute("INSERT INTO notes VALUES ('before')")
            with pytest.raises(SLRStoreFull):   # (SQLite rolled the transaction back)
                store.execute("INSERT INTO notes VALUES (?)", (BIG,))
            store.execute("INSERT INTO notes VALUES ('after')")

    exc = slr_failure(transaction)
    assert isinstance(exc, SLRStoreFull)
    assert str(exc).startswith(f"{store.path}: the disk is full")
    assert "the transaction was rolled back, nothing of it was written" in str(exc)
    assert notes(store) == ["kept"]
    # and the store goes on: a transaction after it commits
    with store.transaction():
        store.execute("INSERT INTO notes VALUES ('later')")
    assert notes(store) == ["kept", "later"]


def test_a_nested_level_caught_by_its_caller(store):
    """The nested level's body error reaches its caller; the levels still open run their
    statements and nested levels inside the transaction begun again, and each one that ends
    normally raises that the transaction is rolled back."""
    heard = []

    def transaction():
        with store.transaction():
            store.execute("INSERT INTO notes VALUES ('before')")
            with store.transaction():
                try:
                    with store.transaction():
                        store.execute("INSERT INTO notes VALUES (?)", (BIG,))
                except SLRStoreFull as inner:
                    heard.append(inner)
                store.execute("INSERT INTO notes VALUES ('after')")
                try:
                    with store.transaction():     # a savepoint of the levels still open
                        store.execute("INSERT INTO notes VALUES ('inner after')")
                except SLRStoreFull as inner:
                    heard.append(inner)

    exc = slr_failure(transaction)
    assert isinstance(exc, SLRStoreFull) and "rolled back" in str(exc)
    assert [type(e) for e in heard] == [SLRStoreFull, SLRStoreFull]
    assert "nothing of it will be written" in str(heard[1])
    assert notes(store) == ["kept"]


def test_the_bodys_own_error_is_what_the_caller_hears(store):
    def transaction():
        with store.transaction():
            store.execute("INSERT INTO notes VALUES ('before')")
            with store.transaction():
                try:
                    store.execute("INSERT INTO notes VALUES (?)", (BIG,))
                except SLRStoreFull:
                    pass
                store.execute("INSERT INTO notes VALUES ('after')")
                raise SLRError("the body's own reason")

    exc = slr_failure(transaction)
    assert type(exc) is SLRError and str(exc) == "the body's own reason"
    assert notes(store) == ["kept"]


def test_a_statement_that_ends_the_transaction_is_said_in_words(tmp_path):
    """A ``ROLLBACK`` inside a transaction, run by a module of slr_sql on the store's
    connection (a user's is refused: tests/test_sql_transaction_control.py): the levels
    open end with an SLRError, not sqlite3's "no such savepoint" / "cannot commit", and what
    the transaction wrote afterwards is not kept."""
    with slr_sql.open(tmp_path / "robot.db", clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add("p(1)^1")

        def transaction():
            with kb.store.transaction():
                kb.add("p(2)^2")
                kb.store.execute("ROLLBACK")
                kb.add("p(3)^3")

        exc = slr_failure(transaction)
        assert type(exc) is SLRError
        assert str(exc) == f"{tmp_path / 'robot.db'}: the transaction ended before its end " \
                           f"(a statement ended it); the transaction is rolled back, nothing " \
                           f"of it will be written"
        assert kb.query("findall(X, p(X)^_, L)") == [{"L": [1]}]
        kb.add("p(4)^4")
        assert kb.query("findall(X, p(X)^_, L)") == [{"L": [1, 4]}]
