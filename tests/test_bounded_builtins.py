"""One call of a SQLite built-in cannot hold a store for minutes (slr_sql/store/bounded_builtins.py).

A statement's timeout stops a statement between its steps, never inside one function call:
LIKE, GLOB, instr and replace do work that grows with the product of their arguments'
lengths, and printf repeats a character as often as asked. Such a call is refused in words
(or, for printf past the length limit, gives SQLite's NULL) before it starts, on every
connection of a SQLite store; every other call gives exactly what SQLite's built-in gives.
(PostgreSQL's LIKE is not bounded: docs/sql.md, "Limits".)
"""
from __future__ import annotations

import sqlite3

import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

import slr_sql
from slr_sql import SLRError
from slr_sql.store.connection import run_sql_file

# each would run for minutes to hours without its bound (a 6 MB text against a
# 20,000-character pattern: ~150 s for LIKE; instr and replace: 60 MB against 2 MB)
BOMBS = {
    "instr": "SELECT instr(hex(zeroblob(30000000)), hex(zeroblob(1000000)) || '1')",
    "replace": "SELECT length(replace(hex(zeroblob(30000000)), hex(zeroblob(1000000)) || '1', "
               "'x'))",
    "like": "SELECT hex(zeroblob(3000000)) LIKE ('%' || hex(zeroblob(10000)) || '1')",
    "glob": "SELECT hex(zeroblob(3000000)) GLOB ('*' || hex(zeroblob(10000)) || '1')",
}
REFUSED = "timeout cannot stop a call midway"


@pytest.fixture
def store(tmp_path):
    with slr_sql.open(tmp_path / "robot.db", clock=slr_sql.ManualClock(10.0)) as kb:
        kb.add("seg(cup1)^1")
        yield kb


@pytest.mark.parametrize("name", sorted(BOMBS))
@pytest.mark.parametrize("write", [False, True], ids=["read-only", "write"])
def test_a_call_that_could_run_for_minutes_is_refused_in_words(store, name, write):
    with pytest.raises(SLRError, match=rf"^sql: {name}\(\) over values of .*{REFUSED}"):
        store.sql(BOMBS[name], write=write, timeout=5)
    # the store is unchanged and its connection goes on
    assert store.sql("SELECT arg1 FROM seg")[1] == [("cup1",)]
    store.add("seg(cup2)^2")
    assert len(store.query("seg(X)^T")) == 2


@pytest.mark.parametrize("name", ["instr", "like"])
def test_the_separate_connection_of_slr_sql_refuses_it_too(store, name):
    with pytest.raises(SLRError, match=rf"{name}\(\) over values of .*{REFUSED}"):
        run_sql_file(store.store.path, BOMBS[name])


def test_the_slr_sql_command_refuses_it_in_words(store):
    import subprocess
    import sys

    path = store.store.path
    result = subprocess.run([sys.executable, "-m", "slr_sql", "sql", str(path), BOMBS["instr"]],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode != 0
    assert REFUSED in result.stderr and "Traceback" not in result.stderr


@pytest.mark.parametrize("query", [
    "SELECT length(printf('%.*c', 2000000000, 'x'))",
    "SELECT length(printf('%.2000000000c', 'x'))",
    "SELECT length(format('%-5.*c', 2000000000, 'x'))",
    "SELECT length(printf('%d %*s %.*c', 1, 3, 'a', 2000000000, 'x'))",
])
@pytest.mark.parametrize("write", [False, True], ids=["read-only", "write"])
def test_printf_repeating_a_character_past_the_length_limit_is_null_at_once(store, query,
                                                                             write):
    # (SQLite's own loop takes ~9 s of CPU to reach the same NULL, uninterruptibly)
    assert store.sql(query, write=write, timeout=5)[1] == [(None,)]


def test_printf_repeats_within_the_limit_as_sqlite_does(store):
    assert store.sql("SELECT printf('%.*c|%5.2f|%%|%s', 4, 'y', 3.14159, 'z')")[1] == \
        [("yyyy| 3.14|%|z",)]
    # a read-only statement's values are at most 64 MiB; write=True keeps SQLite's own limit
    assert store.sql("SELECT length(printf('%.*c', 100000000, 'x'))")[1] == [(None,)]
    assert store.sql("SELECT length(printf('%.*c', 100000000, 'x'))", write=True)[1] == \
        [(100000000,)]


def test_an_error_of_the_built_in_keeps_sqlites_words(store):
    with pytest.raises(SLRError, match="like\\(\\): ESCAPE expression must be a single "
                                       "character"):
        store.sql("SELECT 'a' LIKE 'a' ESCAPE 'xy'")


# -- the wrapped built-ins give what SQLite's give ----------------------------------------

_TEXT = st.text(alphabet="ab%_*?[]^!-\\é1.", max_size=8)
_VALUE = st.one_of(_TEXT, st.none(), st.integers(-20, 20), st.sampled_from([1.5, -0.0, 1e20]),
                   st.binary(max_size=4))
_FORMAT = st.lists(st.sampled_from(["%d", "%s", "%5.2f", "%.*c", "%c", "%%", "%-4s", "%x",
                                    "%q", "%*d", "ab", "%!.3g", "%,d", "%.3c"]),
                   max_size=4).map("".join)


def _plain(query: str, params: tuple):
    conn = sqlite3.connect(":memory:")
    try:
        return ("value", conn.execute(query, params).fetchall())
    except sqlite3.Error:
        return ("error",)
    finally:
        conn.close()


def _ours(kb, query: str, params: tuple):
    try:
        return ("value", kb.sql(query, params)[1])
    except SLRError:
        return ("error",)


@pytest.fixture(scope="module")
def memory_store():
    with slr_sql.open(clock=slr_sql.ManualClock(0.0)) as kb:
        yield kb


@settings(max_examples=150, deadline=None, derandomize=True)
@given(text=_VALUE, pattern=_VALUE, other=_VALUE, escape=st.sampled_from(["!", "\\", "ab", None]))
@example(text="a_b", pattern="a!_b", other="x", escape="!")
@example(text="ÉA", pattern="éa", other=None, escape=None)
def test_the_wrapped_functions_answer_as_sqlites_own(memory_store, text, pattern, other,
                                                      escape):
    queries = [("SELECT ? LIKE ?", (text, pattern)), ("SELECT ? GLOB ?", (text, pattern)),
               ("SELECT instr(?, ?)", (text, pattern)),
               ("SELECT replace(?, ?, ?)", (text, pattern, other)),
               ("SELECT ? LIKE ? ESCAPE ?", (text, pattern, escape))]
    for query, params in queries:
        assert _ours(memory_store, query, params) == _plain(query, params), (query, params)


@settings(max_examples=150, deadline=None, derandomize=True)
@given(form=_FORMAT, args=st.lists(st.one_of(st.integers(-5, 40), _TEXT, st.floats(-1e3, 1e3),
                                             st.none()), max_size=5))
def test_printf_and_format_answer_as_sqlites_own(memory_store, form, args):
    marks = ", ".join("?" * (len(args) + 1))
    for name in ("printf", "format"):
        query = f"SELECT {name}({marks})"
        assert _ours(memory_store, query, (form, *args)) == _plain(query, (form, *args))


# -- PRAGMA case_sensitive_like would put SQLite's own LIKE back ---------------------------

# over the bound (20,001 x 20,001 > 2^28) yet quick for SQLite's own LIKE (~0.5 s): the
# test shows the bound, not a long run
_OVER_THE_BOUND = "SELECT hex(zeroblob(10000)) || 'a' LIKE ('%' || hex(zeroblob(10000)))"


@pytest.mark.parametrize("pragma", ["PRAGMA case_sensitive_like = 1",
                                    "PRAGMA case_sensitive_like=off",
                                    "pragma main.CASE_SENSITIVE_LIKE = true"])
def test_case_sensitive_like_is_refused_and_like_stays_bounded(store, pragma):
    # the pragma re-registers SQLite's LIKE on the connection, over the bounded one
    with pytest.raises(SLRError, match=r"^sql: PRAGMA case_sensitive_like is not allowed "
                                       r"\(.*LIKE.*timeout"):
        store.sql(pragma, write=True)
    with pytest.raises(SLRError, match=rf"like\(\) over values of .*{REFUSED}"):
        store.sql(_OVER_THE_BOUND, write=True)
    with pytest.raises(SLRError, match=rf"like\(\) over values of .*{REFUSED}"):
        store.sql(_OVER_THE_BOUND)
    # LIKE keeps SQLite's default (ASCII letters match either case), and the store goes on
    assert store.sql("SELECT 'Cup1' LIKE 'cup%'", write=True)[1] == [(1,)]
    store.add("seg(cup2)^2")
    assert len(store.query("seg(X)^T")) == 2


def test_case_sensitive_like_is_refused_read_only_and_on_a_connection_of_its_own(store):
    with pytest.raises(SLRError, match="case_sensitive_like"):
        store.sql("PRAGMA case_sensitive_like = 1")
    with pytest.raises(SLRError, match=r"PRAGMA case_sensitive_like is not allowed"):
        run_sql_file(store.store.path, "PRAGMA case_sensitive_like = 1", write=True)
