"""SQL a user hands the store (``kb.sql``, ``slr sql``, the service's ``/sql``) cannot reach
into the process: ``fts3_tokenizer`` (a pointer read and a jump to any address), native
extensions, other files, settings, or gigabyte values (docs/sql.md, "What a statement may
call"). Each refusal is an SLRError in words, and the store stays as it was and usable."""
from __future__ import annotations

import os
import sqlite3
import subprocess
import sys
import textwrap

import pytest

import slr_sql
from slr_sql import SLRError
from slr_sql.store import run_sql_file

from service_helpers import HTTP, ROOT, ServiceProcess
from test_cli import slr
from test_cli_errors import fails_in_words

TOKENIZER = r"fts3_tokenizer\(\) is not allowed"


@pytest.fixture
def kb(tmp_path):
    # a ManualClock: events stamped 1, 2 on a wall clock would be "decades late" (a
    # LearnedDelayWarning); nothing here waits on the store's time
    kb = slr_sql.open(tmp_path / "robot.db", clock=slr_sql.ManualClock(0.0))
    kb.add_many(["p(a)^1", "p(b)^2"])
    yield kb
    kb.close()


def unchanged(kb) -> None:
    """The store answers as before and still takes events."""
    assert [a["X"] for a in kb.query("p(X)^T")] == ["a", "b"]
    kb.add("p(c)^3")
    assert kb.sql("SELECT count(*) FROM p")[1] == [(3,)]


def test_the_tokenizer_attack_no_longer_crashes_the_process(tmp_path):
    """The attack of the finding, end to end in a process of its own: re-point the "simple"
    tokenizer through read-only SQL, then use an FTS3 table. Without the guard the process
    dies of SIGSEGV."""
    script = textwrap.dedent(f"""
        import slr_sql
        kb = slr_sql.open({str(tmp_path / "robot.db")!r})
        for statement in ("SELECT fts3_tokenizer('simple', x'4141414141414141')",
                          "SELECT fts3_tokenizer('simple')"):
            try:
                kb.sql(statement)
            except slr_sql.SLRError as exc:
                print("refused:", exc)
        kb.sql("CREATE VIRTUAL TABLE notes USING fts3(body)", write=True)
        kb.sql("INSERT INTO notes VALUES ('the gripper slipped')", write=True)
        print(kb.sql("SELECT body FROM notes WHERE body MATCH 'gripper'")[1])
    """)
    r = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                       cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=60)
    assert r.returncode == 0, (r.returncode, r.stderr)
    assert r.stdout.count("refused: sql: fts3_tokenizer() is not allowed") == 2, r.stdout
    assert "[('the gripper slipped',)]" in r.stdout


@pytest.mark.parametrize("statement, params", [
    ("SELECT fts3_tokenizer('simple')", ()),                        # leaks a library address
    ("SELECT fts3_tokenizer('simple', x'4141414141414141')", ()),   # re-points it
    ("SELECT fts3_tokenizer('simple', ?)", (b"AAAAAAAA",)),         # a bound address
    ("SELECT FTS3_TOKENIZER('porter')", ()),
    ("SELECT 1 WHERE fts3_tokenizer('simple') IS NOT NULL", ()),
    ("WITH t(x) AS (SELECT fts3_tokenizer('simple')) SELECT x FROM t", ()),
])
@pytest.mark.parametrize("write", [False, True])
def test_fts3_tokenizer_is_refused_in_every_form(kb, statement, params, write):
    with pytest.raises(SLRError, match=r"^sql: fts3_tokenizer\(\) is not allowed"):
        kb.sql(statement, params, write=write)
    unchanged(kb)


def test_a_view_calling_fts3_tokenizer_is_refused_when_read(kb):
    """A view written by another program into the file: SQLite refuses the function there
    itself (it is "direct only"), the authorizer would too."""
    outside = sqlite3.connect(kb.store.path)
    outside.execute("CREATE VIEW leak AS SELECT fts3_tokenizer('simple') AS address")
    outside.commit()
    outside.close()
    for write in (False, True):
        with pytest.raises(SLRError, match=r"^sql: .*fts3_tokenizer\(\)"):
            kb.sql("SELECT address FROM leak", write=write)
    unchanged(kb)


def test_the_fts3_tokenizer_switch_of_sqlite_is_off_too(kb):
    """The second line: SQLite's own switch (SQLITE_DBCONFIG_ENABLE_FTS3_TOKENIZER) is off
    on the store's connection, so even without the authorizer an address written into a
    statement is refused by SQLite itself."""
    conn = kb.store._conn
    conn.set_authorizer(None)
    try:
        with pytest.raises(Exception, match="fts3tokenize disabled"):
            conn.execute("SELECT fts3_tokenizer('simple', x'4141414141414141')")
    finally:
        conn.set_authorizer(kb.store._db.guard.always)


@pytest.mark.parametrize("statement, words", [
    ("SELECT load_extension('/tmp/evil.so')", "load_extension() is not allowed"),
    ("SELECT load_extension('/tmp/evil.so', 'entry')", "load_extension() is not allowed"),
    ("SELECT rtreenode(2, x'0000')", "rtreenode() is not allowed"),
    ("SELECT rtreedepth(x'0000')", "rtreedepth() is not allowed"),
    ("ATTACH 'other.db' AS other", "read-only: the statement would write a database file"),
    ("VACUUM", "read-only: the statement would write a database file"),
    ("PRAGMA max_page_count = 10", "read-only: PRAGMA max_page_count"),
    # (not even with write=True: tests/test_sql_transaction_control.py)
    ("PRAGMA writable_schema = ON", "PRAGMA writable_schema with an argument is not allowed"),
    ("PRAGMA query_only = 0", "PRAGMA query_only with an argument is not allowed"),
    ("PRAGMA journal_mode = DELETE", "PRAGMA journal_mode with an argument is not allowed"),
    ("PRAGMA wal_checkpoint", "read-only: PRAGMA wal_checkpoint"),
    ("PRAGMA main.wal_checkpoint(TRUNCATE)", "read-only: PRAGMA wal_checkpoint"),
    ("PRAGMA optimize", "read-only: PRAGMA optimize"),
    ("PRAGMA incremental_vacuum", "read-only: PRAGMA incremental_vacuum"),
    ("PRAGMA shrink_memory", "read-only: PRAGMA shrink_memory"),
    ("PRAGMA temp_store_directory = '/tmp'", "read-only: PRAGMA temp_store_directory"),
    ("SELECT length(randomblob(2000000000))", "at most 64 MiB"),
    ("SELECT length(randomblob(100000000))", "at most 64 MiB"),
    ("SELECT length(zeroblob(2000000000))", "at most 64 MiB"),
    ("SELECT length(zeroblob(100000000))", "at most 64 MiB"),
    ("SELECT length(hex(randomblob(40000000)))", "at most 64 MiB"),
    ("SELECT length(replace(hex(zeroblob(20000000)), '0', 'xyzw'))", "at most 64 MiB"),
    ("WITH RECURSIVE c(i) AS (SELECT 1 UNION ALL SELECT i + 1 FROM c WHERE i < 70) "
     "SELECT length(group_concat(randomblob(1000000))) FROM c", "at most 64 MiB"),
    ("SELECT * FROM sqlite_dbpage", "no such table: sqlite_dbpage"),  # not compiled in
])
def test_dangerous_read_only_statements_are_refused_in_words(kb, statement, words):
    with pytest.raises(SLRError) as caught:
        kb.sql(statement)
    assert words in str(caught.value)
    unchanged(kb)


def test_a_result_of_many_large_rows_is_refused_in_words(kb):
    """Each value is within the limit, their sum is not: 140 rows of 1 MB."""
    with pytest.raises(SLRError, match=r"^sql: the result of a read-only statement is larger "
                                       r"than 128 MiB of text and blobs \(each value counted "
                                       r"as 16 bytes besides its text\): ask for fewer rows"):
        kb.sql("WITH RECURSIVE c(i) AS (SELECT 1 UNION ALL SELECT i + 1 FROM c WHERE i < 140) "
               "SELECT zeroblob(1000000) FROM c")
    rows = kb.sql("WITH RECURSIVE c(i) AS (SELECT 1 UNION ALL SELECT i + 1 FROM c "
                  "WHERE i < 100) SELECT zeroblob(1000000) FROM c")[1]
    assert len(rows) == 100   # 100 MB: within the bound
    unchanged(kb)


def test_a_result_of_many_values_without_text_is_refused_in_words(kb, monkeypatch):
    """Numbers and NULLs hold no text, but each costs memory: 2,000 columns of NULL over
    20,000 rows took a server answering /sql 1.5 GB, within a bound that counted text
    alone. Here the bound is 1 MiB, so that 100 columns over 1,000 rows pass it."""
    from slr_sql.store import connection
    monkeypatch.setattr(connection, "READ_ONLY_RESULT_BYTES", 1 << 20)
    # (the statements' column lists are built here: literals and one column name, no value)
    nulls = ", ".join(["NULL"] * 100)
    many = "WITH RECURSIVE c(i) AS (SELECT 1 UNION ALL SELECT i + 1 FROM c WHERE i < 1000) "
    with pytest.raises(SLRError, match=r"^sql: the result of a read-only statement is larger "
                                       r"than 1 MiB .*ask for fewer rows"):
        kb.sql(many + f"SELECT {nulls} FROM c")
    with pytest.raises(SLRError, match=r"larger than 1 MiB"):
        kb.sql(many + f"SELECT {', '.join(['i'] * 100)} FROM c")
    rows = kb.sql(many + f"SELECT {', '.join(['i'] * 50)} FROM c")[1]
    assert len(rows) == 1000 and rows[-1] == (1000,) * 50   # 800,000 bytes counted
    unchanged(kb)


def test_vacuum_into_is_refused_before_the_file_is_created(kb, tmp_path):
    target = tmp_path / "copy.db"
    with pytest.raises(SLRError, match="read-only: the statement would write a database file"):
        kb.sql(f"VACUUM INTO '{target}'")
    assert not target.exists()
    unchanged(kb)


def test_printf_widths_cannot_allocate_past_the_value_limit(kb):
    """``printf('%.*c', N, 'x')`` builds at most 64 MiB in a read-only statement (SQLite
    gives NULL at the limit) where it used to build N bytes."""
    assert kb.sql("SELECT length(printf('%.*c', 100000000, 'x'))")[1] == [(None,)]
    assert kb.sql("SELECT length(printf('%.*c', 2000000000, 'x'))")[1] == [(None,)]
    assert kb.sql("SELECT length(printf('%.*c', 1000, 'x'))")[1] == [(1000,)]
    # write=True keeps SQLite's own bound: a statement the user means is not cut
    assert kb.sql("SELECT length(printf('%.*c', 100000000, 'x'))", write=True)[1] == \
        [(100000000,)]


@pytest.mark.parametrize("statement, expected", [
    ("SELECT count(*) > 0 FROM dbstat", [(1,)]),
    ("SELECT name FROM pragma_table_info('p') WHERE name = 'arg1'", [("arg1",)]),
    ("PRAGMA journal_mode", [("wal",)]),
    ("PRAGMA table_info(p)", None),
    ("SELECT length(randomblob(1000000))", [(1000000,)]),
    ("SELECT sqlite_compileoption_used('ENABLE_FTS3')", [(1,)]),
    ("SELECT value FROM json_each('[1,2]')", [(1,), (2,)]),
])
def test_what_only_reads_still_runs(kb, statement, expected):
    rows = kb.sql(statement)[1]
    assert rows if expected is None else rows == expected
    unchanged(kb)


def test_the_guard_holds_on_the_separate_connection_of_run_sql_file(kb):
    path = kb.store.path
    with pytest.raises(SLRError, match=TOKENIZER):
        run_sql_file(path, "SELECT fts3_tokenizer('simple')")
    with pytest.raises(SLRError, match=TOKENIZER):
        run_sql_file(path, "SELECT fts3_tokenizer('simple')", write=True)
    with pytest.raises(SLRError, match="^sql: read-only: PRAGMA max_page_count"):
        run_sql_file(path, "PRAGMA max_page_count = 10")
    assert run_sql_file(path, "SELECT count(*) FROM p")[1] == [(2,)]


def test_slr_sql_refuses_fts3_tokenizer_in_words(kb):
    path = kb.store.path
    kb.close()
    for write in ((), ("--write",)):
        fails_in_words(slr("sql", path, *write, "SELECT hex(fts3_tokenizer('simple'))"),
                       "fts3_tokenizer() is not allowed")
    fails_in_words(slr("sql", path, "SELECT load_extension('x')"), "load_extension()")


def test_the_service_refuses_fts3_tokenizer_and_stays_up(tmp_path):
    db = tmp_path / "robot.db"
    with slr_sql.open(db, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add("p(a)^1")
    with ServiceProcess(db) as server:
        for query in ("SELECT fts3_tokenizer('simple')",
                      "SELECT fts3_tokenizer('simple', x'4141414141414141')",
                      "SELECT length(randomblob(2000000000))"):
            r = HTTP.post(server.url + "/sql", json={"query": query}, timeout=30)
            assert r.status_code == 400, r.text
            assert r.json()["error"]["message"].startswith("sql: "), r.text
        r = HTTP.post(server.url + "/sql", json={"query": "SELECT fts3_tokenizer(?, ?)",
                                                  "params": ["simple", "AAAAAAAA"]},
                       timeout=30)
        assert r.status_code == 400, r.text
        r = HTTP.post(server.url + "/sql", json={"query": "SELECT count(*) AS n FROM p"},
                      timeout=30)
        assert r.status_code == 200 and server.healthy(), r.text


def test_the_tokenizer_is_switched_off_for_a_store_whose_file_name_is_no_utf8(tmp_path):
    """The switch off (defence under the guard) looks the connection's file name up to be
    sure of its handle; a name with a byte that is no UTF-8 was read as stored text (U+FFFD
    and a StoredTextWarning) and never matched: the switch was left on for such a store."""
    import warnings

    from slr_sql.store.authorizer import fts3_tokenizer_switch_off

    path = os.fsdecode(os.fsencode(str(tmp_path)) + b"/r\xffobot.db")
    conn = sqlite3.connect(path)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            switched = fts3_tokenizer_switch_off(conn)
        if sys.version_info[:2] == (3, 11) and sys.implementation.name == "cpython":
            assert switched
            with pytest.raises(sqlite3.OperationalError, match="fts3tokenize disabled"):
                conn.execute("SELECT fts3_tokenizer('simple', zeroblob(8))")
    finally:
        conn.close()
    with slr_sql.open(path, clock=slr_sql.ManualClock(0.0)) as kb, warnings.catch_warnings():
        warnings.simplefilter("error")
        kb.add("p(a)^1")
        assert kb.query("p(X)^T") == [{"X": "a", "T": 1.0}]
