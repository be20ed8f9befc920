"""trim/ltrim/rtrim with a set of characters and json_patch are bounded like LIKE
(slr_sql/store/bounded_builtins.py): SQLite compares each character taken off against every
character of the set, and json_patch looks each key of the patch up in the target it grows,
so one call can run for minutes, and a statement's timeout cannot stop it midway. A call
whose work is over the bound is refused in words; every other call answers exactly as
SQLite's own built-in (compared here with a plain sqlite3 connection)."""
from __future__ import annotations

import sqlite3

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import slr_sql
from slr_sql import SLRError

REFUSED = "timeout cannot stop a call midway"
# without the bound each runs ~3 s here (quadratic: ten times the sizes, five minutes)
BOMBS = {
    "trim": "SELECT length(trim(printf('%.*c', 20000, 'a'), printf('%.*c', 20000, 'b') || 'a'))",
    "ltrim": "SELECT length(ltrim(printf('%.*c', 20000, 'a'), printf('%.*c', 20000, 'b') || 'a'))",
    "rtrim": "SELECT length(rtrim(printf('%.*c', 20000, 'a'), printf('%.*c', 20000, 'b') || 'a'))",
    "json_patch": "WITH RECURSIVE c(i) AS (SELECT 1 UNION ALL SELECT i + 1 FROM c WHERE i < 30000) "
                  "SELECT length(json_patch('{}', (SELECT json_group_object(i, 0) FROM c)))",
}


@pytest.fixture
def store(tmp_path):
    with slr_sql.open(tmp_path / "robot.db", clock=slr_sql.ManualClock(10.0)) as kb:
        yield kb


@pytest.mark.parametrize("name", sorted(BOMBS))
@pytest.mark.parametrize("write", [False, True])
def test_a_call_that_could_run_for_minutes_is_refused_in_words(store, name, write):
    with pytest.raises(SLRError, match=REFUSED) as caught:
        store.sql(BOMBS[name], write=write, timeout=5)
    assert f"{name}()" in str(caught.value)


def test_a_long_text_with_a_short_run_to_take_off_is_trimmed(store):
    # 24 M characters, a set of four: only the characters taken off cost anything
    query = ("SELECT length(trim(' \t' || printf('%.*c', 24000000, 'x') || char(10), "
             "' \t' || char(10, 13)))")
    assert store.sql(query, timeout=30)[1] == [(24000000,)]


def test_json_patch_of_ordinary_sizes_answers_as_sqlite(store):
    target = '{"a": 1, "b": {"c": 2, "d": [1, 2]}, "e": null}'
    patch = '{"b": {"c": null, "x": "y"}, "e": 5, "f": {"g": 1}}'
    expected = sqlite3.connect(":memory:").execute(
        "SELECT json_patch(?, ?)", (target, patch)).fetchall()
    assert store.sql("SELECT json_patch(?, ?)", [target, patch])[1] == expected
    with pytest.raises(SLRError, match="malformed JSON"):
        store.sql("SELECT json_patch('{', '{}')")


@pytest.fixture(scope="module")
def memory_store():
    with slr_sql.open(clock=slr_sql.ManualClock(0.0)) as kb:
        yield kb


VALUES = st.one_of(st.none(), st.integers(-1000, 1000), st.floats(allow_nan=False, width=32),
                   st.text("ab ._é\u4e2d", max_size=8), st.binary(max_size=4))


@settings(max_examples=150, deadline=None, derandomize=True)
@given(text=VALUES, chars=VALUES)
def test_the_trims_answer_as_sqlites_own(memory_store, text, chars):
    plain = sqlite3.connect(":memory:")
    for name in ("trim", "ltrim", "rtrim"):
        query = f"SELECT {name}(?, ?), typeof({name}(?, ?))"
        try:
            expected = plain.execute(query, (text, chars, text, chars)).fetchall()
        except sqlite3.Error:
            continue
        assert memory_store.sql(query, [text, chars, text, chars])[1] == expected


UNDECODABLE = "SELECT CAST(x'ff41' AS TEXT) LIKE '%A'"


@pytest.mark.parametrize("write", [False, True])
def test_text_that_is_not_utf8_passed_to_a_wrapped_built_in_is_said_in_words(store, write):
    # (Python reads a function's text arguments as UTF-8: the wrapper is never called)
    with pytest.raises(SLRError, match="not valid UTF-8.*CAST"):
        store.sql(UNDECODABLE, write=write)
    assert store.sql("SELECT CAST(x'ff41' AS BLOB) LIKE '%A'")[1] == \
        sqlite3.connect(":memory:").execute("SELECT x'ff41' LIKE '%A'").fetchall()


def test_the_slr_sql_command_says_it_in_words_too(tmp_path):
    from slr_sql.store.connection import run_sql_file
    slr_sql.open(tmp_path / "robot.db").close()
    with pytest.raises(SLRError, match="not valid UTF-8"):
        run_sql_file(tmp_path / "robot.db", UNDECODABLE)
