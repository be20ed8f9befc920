"""A statement handed to ``kb.sql`` runs on the store's own connection, whose transactions are
the store's: a BEGIN, COMMIT, END, ROLLBACK, SAVEPOINT or RELEASE (PostgreSQL: also START
TRANSACTION, ABORT, PREPARE TRANSACTION, SET TRANSACTION) is refused in words before anything
runs, with ``write=True`` or without, on both backends, and the store is as it was: its
transaction still open, nothing committed halfway (docs/sql.md, "What a statement may
call"). Legitimate write SQL still runs."""
from __future__ import annotations

import pytest

import slr_sql
from slr_sql import SLRError

REFUSED = "is not allowed: the store begins and ends its own transactions"

BOTH = ["BEGIN", "BEGIN TRANSACTION", "COMMIT", "END", "ROLLBACK", "SAVEPOINT mine",
        "RELEASE mine", "RELEASE SAVEPOINT mine", "ROLLBACK TO mine",
        "ROLLBACK TO SAVEPOINT mine", "  /* a comment */ -- and a line\n commit;", "commit"]
SQLITE_ONLY = ["BEGIN IMMEDIATE", "BEGIN EXCLUSIVE", "BEGIN DEFERRED", "COMMIT TRANSACTION"]
POSTGRES_ONLY = ["START TRANSACTION", "START TRANSACTION READ ONLY", "ABORT", "COMMIT WORK",
                 "END WORK", "PREPARE TRANSACTION 'mine'", "COMMIT PREPARED 'mine'",
                 "ROLLBACK PREPARED 'mine'", "SET TRANSACTION READ ONLY",
                 "SET SESSION CHARACTERISTICS AS TRANSACTION READ ONLY",
                 "/* nested /* block */ comment */ COMMIT", "-- a line ended by CR\rCOMMIT"]


@pytest.fixture
def kb(backend):
    kb = slr_sql.open(backend, clock=slr_sql.ManualClock(10.0))
    kb.add("p(a)^1")
    yield kb
    kb.close()


def statements(kb) -> list[str]:
    postgres = kb.store.dialect.name == "postgresql"
    return BOTH + (POSTGRES_ONLY if postgres else SQLITE_ONLY)


def stored(backend) -> list:
    """What another knowledge base on the same store reads: what was committed."""
    with slr_sql.open(backend, clock=slr_sql.ManualClock(10.0)) as other:
        return sorted(a["X"] for a in other.query("p(X)^T"))


@pytest.mark.parametrize("write", [True, False])
def test_each_is_refused_in_words_and_the_store_goes_on(kb, backend, write):
    for statement in statements(kb):
        with pytest.raises(SLRError) as caught:
            kb.sql(statement, write=write)
        assert str(caught.value).startswith("sql: ") and REFUSED in str(caught.value), \
            (statement, str(caught.value))
        # the store's own transactions still begin and commit (a BEGIN let through left the
        # connection in a transaction: the next add could not begin its own)
        kb.add("p(b)^2")
        assert stored(backend) == ["a", "b"], statement
        kb.sql("DELETE FROM p WHERE arg1 = 'b'", write=True)


@pytest.mark.parametrize("write", [True, False])
def test_inside_a_transaction_nothing_is_committed_halfway(kb, backend, write):
    """A COMMIT (or RELEASE, ROLLBACK) inside the store's transaction would end it there:
    the add before it committed although the transaction then failed."""
    for statement in statements(kb):
        with pytest.raises(RuntimeError):
            with kb.store.transaction():
                kb.add("p(b)^2")
                with pytest.raises(SLRError, match=REFUSED):
                    kb.sql(statement, write=write)
                raise RuntimeError("the transaction fails after it")
        assert stored(backend) == ["a"], statement
    with kb.store.transaction():   # and a transaction that ends well commits all of it
        kb.add("p(b)^2")
        with pytest.raises(SLRError, match=REFUSED):
            kb.sql("COMMIT", write=write)
        kb.add("p(c)^3")
    assert stored(backend) == ["a", "b", "c"]


def test_legitimate_write_sql_still_runs(kb, backend):
    kb.sql("CREATE TABLE notes (body text)", write=True)
    kb.sql("INSERT INTO notes VALUES (?)", ["kept"], write=True)
    kb.sql("UPDATE notes SET body = ? WHERE body = ?", ["begin", "kept"], write=True)
    with kb.store.transaction():
        kb.sql("INSERT INTO notes VALUES ('commit')", write=True)
        kb.sql("DELETE FROM p WHERE arg1 = 'a'", write=True)
    # a statement that merely starts with a word such as END or BEGIN is no transaction control
    assert kb.sql("SELECT body AS end_ FROM notes ORDER BY body")[1] == [("begin",), ("commit",)]
    assert stored(backend) == []


def test_a_second_statement_in_the_text_is_refused_on_postgres(kb, backend):
    """The extended protocol on PostgreSQL (as SQLite, which compiles one statement): a
    COMMIT behind a first statement cannot end the store's transaction."""
    with pytest.raises(RuntimeError):
        with kb.store.transaction():
            kb.add("p(b)^2")
            with pytest.raises(SLRError):
                kb.sql("SELECT 1; COMMIT", write=True)
            raise RuntimeError("the transaction fails after it")
    assert stored(backend) == ["a"]
    kb.add("p(c)^3")
    assert stored(backend) == ["a", "c"]


@pytest.mark.parametrize("pragma", ["query_only = 1", "locking_mode = EXCLUSIVE",
                                    "journal_mode = DELETE", "main.journal_mode = TRUNCATE"])
@pytest.mark.parametrize("write", [True, False])
def test_sqlite_pragmas_the_stores_transactions_rely_on_are_refused(tmp_path, pragma, write):
    """On SQLite the pragmas that would change how the store's transactions work are
    refused even with write=True (query_only: its writes fail; locking_mode: its file stays
    locked after each transaction; journal_mode: its WAL); reading them is allowed."""
    path = str(tmp_path / "robot.db")
    with slr_sql.open(path, clock=slr_sql.ManualClock(10.0)) as kb:
        kb.add("p(a)^1")
        name = pragma.split()[0].split(".")[-1]
        with pytest.raises(SLRError, match=rf"^sql: PRAGMA {name} with an argument is not "
                                           r"allowed \("):
            kb.sql(f"PRAGMA {pragma}", write=write)
        assert kb.sql("PRAGMA journal_mode")[1] == [("wal",)]
        assert kb.sql("PRAGMA locking_mode", write=write)[1] == [("normal",)]
        assert kb.sql("PRAGMA query_only", write=True)[1] == [(0,)]
        kb.add("p(b)^2")
        assert kb.sql("PRAGMA wal_checkpoint(TRUNCATE)", write=True)[1] == [(0, 0, 0)]
        assert stored(path) == ["a", "b"]


def test_sqlite_vacuum_still_runs(tmp_path):
    """VACUUM begins and ends a transaction of its own as it runs (after attaching its
    target): no transaction control of the statement's."""
    path = str(tmp_path / "robot.db")
    with slr_sql.open(path, clock=slr_sql.ManualClock(10.0)) as kb:
        kb.add("p(a)^1")
        assert kb.sql("VACUUM", write=True) == ([], [])
        assert kb.sql(f"VACUUM INTO '{tmp_path / 'copy.db'}'", write=True) == ([], [])
        with pytest.raises(SLRError, match=REFUSED):
            kb.sql("BEGIN", write=True)   # (what VACUUM attached is forgotten)
        kb.add("p(b)^2")
    assert stored(path) == ["a", "b"]
    assert stored(str(tmp_path / "copy.db")) == ["a"]


# the pragmas the store sets on its connection itself, as it opens, around its BEGIN, in
# its migrations (slr_sql/store/connection.py, schema.py)
STORE_SET = ["synchronous", "busy_timeout", "foreign_keys", "cache_size", "wal_autocheckpoint",
             "auto_vacuum", "user_version", "legacy_alter_table"]
ASSIGNMENTS = ["synchronous = OFF", "main.synchronous = NORMAL", "synchronous(0)",
               "busy_timeout = 0", "foreign_keys = OFF", "cache_size = -2000",
               "wal_autocheckpoint = 1000", "auto_vacuum = NONE", "user_version = 1",
               "legacy_alter_table = ON"]


@pytest.mark.parametrize("pragma", ["writable_schema = ON", "schema_version = 7",
                                    "ignore_check_constraints = ON"])
def test_sqlite_pragmas_that_can_damage_the_store_are_refused(tmp_path, pragma):
    """writable_schema lets a statement rewrite the schema table itself, schema_version is
    SQLite's own (an assignment can damage the file), ignore_check_constraints drops the
    store's tables' CHECKs: refused in words even with write=True, nothing changed."""
    path = str(tmp_path / "robot.db")
    with slr_sql.open(path, clock=slr_sql.ManualClock(10.0)) as kb:
        kb.add("p(a)^1")
        name = pragma.split()[0]
        before = kb.sql(f"PRAGMA {name}")[1]
        with pytest.raises(SLRError, match=rf"^sql: PRAGMA {name} with an argument is not "
                                           r"allowed \(.+\)$"):
            kb.sql(f"PRAGMA {pragma}", write=True)
        assert kb.sql(f"PRAGMA {name}")[1] == before
        kb.add("p(b)^2")
    assert stored(path) == ["a", "b"]


def test_sqlite_pragmas_the_store_sets_itself_are_refused_and_kept(tmp_path):
    """An assignment of a pragma the store sets on its connection would last for every later
    statement of the store (synchronous = OFF: an add that returned would no longer be on
    disk, docs/schema.md "Durability"): refused in words before it runs, even with
    write=True, and each setting is as the store made it; reading them is allowed, and a
    pragma the store leaves alone can still be set."""
    path = str(tmp_path / "robot.db")
    with slr_sql.open(path, clock=slr_sql.ManualClock(10.0), checkpoint="background") as kb:
        kb.add("p(a)^1")
        settings = {name: kb.sql(f"PRAGMA {name}")[1] for name in STORE_SET}
        assert settings["synchronous"] == [(2,)] and settings["foreign_keys"] == [(1,)]
        assert settings["wal_autocheckpoint"] == [(0,)] and settings["auto_vacuum"] == [(2,)]
        for pragma in ASSIGNMENTS:
            name = pragma.split()[0].split("(")[0].split(".")[-1]
            for write in (True, False):
                with pytest.raises(SLRError, match=rf"^sql: PRAGMA {name} with an argument "
                                                   r"is not allowed \(.+\)$"):
                    kb.sql(f"PRAGMA {pragma}", write=write)
            with kb.store.transaction():
                with pytest.raises(SLRError, match=rf"PRAGMA {name} with an argument"):
                    kb.sql(f"PRAGMA {pragma}", write=True)
        assert {name: kb.sql(f"PRAGMA {name}", write=True)[1] for name in STORE_SET} == settings
        kb.add("p(b)^2")
        kb.sql("PRAGMA journal_size_limit = 1048576", write=True)
        assert kb.sql("PRAGMA max_page_count = 1073741823", write=True)[1] == [(1073741823,)]
    assert stored(path) == ["a", "b"]
