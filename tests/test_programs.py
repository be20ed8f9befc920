"""Named programs (``load(text, name=, replace=)``, ``unload``, ``programs``, ``slr load
--name --replace``) and predicate names that SQL reserves or cannot spell."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

import slr_sql
from slr_sql import SLRError

REPO = Path(__file__).resolve().parent.parent


# The events here carry small example times (1, 2, ...): the stores get a ManualClock, on
# which they are not "decades late" (a LearnedDelayWarning on the wall clock); no test here
# waits on the store's time.
def _open(where=None) -> slr_sql.KnowledgeBase:
    return slr_sql.open(where, clock=slr_sql.ManualClock(0.0))


@pytest.fixture
def kb():
    """A fresh in-memory knowledge base with a ManualClock, closed after the test."""
    with _open() as k:
        yield k


@pytest.fixture(params=["memory", "file"])
def any_kb(request, tmp_path):
    """The same test once on an in-memory and once on an on-disk knowledge base."""
    with _open(None if request.param == "memory" else tmp_path / "robot.db") as k:
        yield k


def values(kb, goal="p(X)", var="X"):
    """The values of ``var`` through the compiled SQL and through the interpreter (equal)."""
    out = []
    for sql in (True, False):
        kb.sql_enabled = sql
        try:
            out.append([a[var] for a in kb.query(goal)])
        finally:
            kb.sql_enabled = True
    assert out[0] == out[1]
    return out[0]


# ------------------------------------------------------------------ named programs

def test_programs_are_named_and_loading_a_name_again_adds_to_it(any_kb):
    kb = any_kb
    kb.load("p(1).", name="a")
    kb.load("p(2).", name="b")
    kb.load("p(3).", name="a")
    kb.load("p(4).")
    assert values(kb) == [1, 2, 3, 4]
    programs = kb.programs()
    assert list(programs) == ["a", "b", "main"]
    assert programs["a"].source == "p(1).\np(3)."
    assert programs["a"].texts == 2 and programs["main"].texts == 1
    assert programs["b"].filenames == ("<string>",)
    assert programs["a"].filenames == ("<string>", "<string>")


def test_replace_swaps_one_program_in_place(any_kb):
    kb = any_kb
    kb.load("p(1).", name="a")
    kb.load("p(2). q(b).", name="b")
    kb.load("p(3).", name="a")
    kb.load("p(10). p(11).", name="a", replace=True)
    assert values(kb) == [10, 11, 2]
    kb.load("p(20).", name="b", replace=True)
    assert values(kb) == [10, 11, 20]
    with pytest.raises(SLRError):      # q/1 went with the old text of b
        kb.query("q(X)")
    kb.load("p(30).", name="new", replace=True)   # replacing a name not loaded yet adds it
    assert values(kb) == [10, 11, 20, 30]


@pytest.mark.parametrize("bad", ["p(", "cBuffer(e(_), 3). tBuffer(e(_), 2).", "atom_length(a, 1).",
                                 ":- nosuch(1)."])
def test_a_bad_replacement_changes_nothing(any_kb, bad):
    kb = any_kb
    kb.load("p(1). p(2).", name="a")
    kb.load("cBuffer(e(_), 1).", name="buf")
    with pytest.raises(SLRError):
        kb.load(bad, name="a", replace=True)
    with pytest.raises(SLRError):
        kb.load(bad, name="buf", replace=True)
    assert values(kb) == [1, 2]
    assert list(kb.programs()) == ["a", "buf"]
    assert [b.pattern for b in kb.buffers()] == ["e(_)"]


def test_replace_and_unload_take_the_declarations_and_buffers_with_them(any_kb):
    kb = any_kb
    kb.load("cBuffer(e(_), 1).\np(1).", name="buf")
    kb.add_many(["e(1)^1", "e(2)^2"])
    assert values(kb, "e(X)^_") == [2]
    kb.load("p(1).", name="buf", replace=True)
    assert kb.buffers() == []
    kb.add_many(["e(3)^3", "e(4)^4"])
    assert values(kb, "e(X)^_") == [2, 3, 4]
    kb.load("tBuffer(e(_), 1).", name="buf2")
    kb.unload("buf2")
    kb.unload("buf")
    assert kb.buffers() == [] and kb.programs() == {}
    with pytest.raises(SLRError, match="no program named 'buf'"):
        kb.unload("buf")
    with pytest.raises(SLRError):
        kb.query("p(X)")


def test_program_names_persist(db_path):
    with slr_sql.open(db_path) as kb:
        kb.load("p(1).", name="a")
        kb.load("p(2).", name="b")
        kb.load("p(3).", name="a", replace=True)
    with slr_sql.open(db_path) as kb:
        assert list(kb.programs()) == ["a", "b"]
        assert values(kb) == [3, 2]
        kb.unload("a")
    with slr_sql.open(db_path) as kb:
        assert values(kb) == [2]


@pytest.mark.parametrize("name", ["", 3, None])
def test_a_program_name_is_a_nonempty_string(kb, name):
    with pytest.raises(SLRError):
        kb.load("p(1).", name=name)


def test_another_kb_sees_a_replacement_and_an_unload(db_path):
    with slr_sql.open(db_path) as a, slr_sql.open(db_path) as b:
        a.load("p(1).", name="x")
        assert values(b) == [1]
        b.load("p(2).", name="x", replace=True)
        assert values(a) == [2]
        b.unload("x")
        with pytest.raises(SLRError):
            a.query("p(X)")
        assert a.programs() == {}


# ------------------------------------------------------------------ command line and README

def slr(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "slr_sql", *args], cwd=str(cwd),
                          capture_output=True, text=True,
                          env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"})


def test_slr_load_name_and_replace(tmp_path):
    program = tmp_path / "tea.slr"
    program.write_text("usedFor(cup, tea).\n", encoding="utf-8")
    for _ in range(2):
        done = slr("load", "robot.db", str(program), "--name", "tea", "--replace", cwd=tmp_path)
        assert done.returncode == 0, done.stderr
    done = slr("query", "robot.db", "findall(T, usedFor(T, tea), L)", cwd=tmp_path)
    assert done.stdout.strip() == "L = [cup]"
    for _ in range(2):
        assert slr("load", "robot.db", str(program), "--name", "more", cwd=tmp_path).returncode == 0
    done = slr("query", "robot.db", "findall(T, usedFor(T, tea), L)", cwd=tmp_path)
    assert done.stdout.strip() == "L = [cup,cup,cup]"


def readme_tour() -> str:
    """The Python code blocks of the README's tour, as one script."""
    text = (REPO / "README.md").read_text(encoding="utf-8")
    tour = text.split("## A five-minute tour", 1)[1].split("\n## ", 1)[0]
    return "\n".join(re.findall(r"```python\n(.*?)```", tour, re.S))


def test_running_the_readme_tour_twice_leaves_one_copy_of_each_rule(tmp_path):
    script = tmp_path / "tour.py"
    script.write_text(readme_tour() + "\nkb.close()\n", encoding="utf-8")
    assert "replace=True" in script.read_text(encoding="utf-8")
    for _ in range(2):
        done = subprocess.run([sys.executable, str(script)], cwd=str(tmp_path),
                              capture_output=True, text=True,
                              env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"})
        assert done.returncode == 0, done.stderr
    with slr_sql.open(tmp_path / "robot.db") as kb:
        assert values(kb, "location(plate9, L)^13", "L") == ["never-observed"]
        assert values(kb, "findall(T, usedFor(T, tea), L)", "L") == [["cup"]]
        assert values(kb, "color(cup2, C)^20", "C") == []
        clauses = sum(text.count(":-") for text in (p.source for p in kb.programs().values()))
        assert clauses == 5   # color, location x2, tf: once each (and no directive twice)


# ------------------------------------------------------------------ names SQL reserves

NAMES = ["sqlite_foo", "'\\0'", "slr_facts_q_1", "slr_facts_1_q", "'SELECT'", "'usedFor'",
         "usedfor", "'a b'", "'x612062'", "'sqlite_master'", "slr_meta", "'\"'", "''"]


@pytest.mark.parametrize("name", NAMES)
def test_any_predicate_name_works_in_programs_views_and_fact_tables(any_kb, name):
    kb = any_kb
    facts = " ".join(f"{name}({i})." for i in range(6))
    kb.load(facts)
    kb.load(f"rule(X) :- {name}(X).")
    kb.load("q(1). q(2). q(3). q(4). q(5). q(6).")   # rebuilds every fact table and view
    kb.add_many([f"{name}({i})^{i}" for i in range(3)])
    assert values(kb, f"{name}(X)") == list(range(6))
    assert values(kb, "rule(X)") == list(range(6))
    assert values(kb, f"{name}(X)^_") == [0, 1, 2]
    assert values(kb, "q(X)") == [1, 2, 3, 4, 5, 6]
    assert values(kb, f"findall(X, ({name}(X)^_, {name}(X)), L)", "L") == [[0, 1, 2]]


def test_names_that_differ_in_case_get_their_own_fact_tables(any_kb):
    kb = any_kb
    kb.load(" ".join(f"usedFor({i})." for i in range(6)))
    kb.load(" ".join(f"usedfor({i})." for i in range(10, 16)))
    kb.add_many([f"e({i})^{i}" for i in (1, 11)])
    assert values(kb, "findall(X, (e(X)^_, usedFor(X)), L)", "L") == [[1]]
    assert values(kb, "findall(X, (e(X)^_, usedfor(X)), L)", "L") == [[11]]


def test_fact_table_names_are_distinct_and_lowercase():
    from slr_sql.store import EventStore

    names = [("usedFor", 2), ("usedfor", 2), ("used_for", 2), ("usedFor", 12), ("x", 1),
             ("a b", 1), ("x612062", 1), ("\0", 1), ("_a", 1), ("A", 1), ("a_", 1), ("", 1)]
    tables = [EventStore.fact_table_name(n, a) for n, a in names]
    assert len({t.lower() for t in tables}) == len(names)
    assert all(t == t.lower() and "\0" not in t for t in tables)


def test_a_stored_program_named_with_reserved_words_reopens(db_path):
    with slr_sql.open(db_path) as kb:
        kb.load("sqlite_foo(1). sqlite_foo(2). sqlite_foo(3). sqlite_foo(4). sqlite_foo(5).")
        kb.load("slr_facts_q_1(a).")
    with slr_sql.open(db_path) as kb:
        assert values(kb, "sqlite_foo(X)") == [1, 2, 3, 4, 5]
        assert values(kb, "slr_facts_q_1(X)") == ["a"]


# ------------------------------------------------------------------ migrations

def test_the_migration_runner_applies_a_lower_number_merged_later(tmp_path):
    import sqlite3

    from slr_sql.store.schema import applied_migrations, migrate, migration_scripts

    # a gap at 3: as when 0004 was applied before a 0003 written on another branch arrived
    scripts = [s for s in migration_scripts() if s[0] != 3]
    numbers = [n for n, _, _ in scripts]
    assert 3 not in numbers and 4 in numbers
    conn = sqlite3.connect(tmp_path / "s.db", isolation_level=None)
    migrate(conn, "s.db", scripts)
    assert applied_migrations(conn) == set(numbers)
    later = (3, "0003_later.sql", "CREATE TABLE slr_later (x INTEGER);")
    migrate(conn, "s.db", sorted(scripts + [later]))
    assert applied_migrations(conn) == set(numbers) | {3}
    assert conn.execute("PRAGMA user_version").fetchone()[0] == max(numbers)
    assert conn.execute("SELECT count(*) FROM slr_later").fetchone() == (0,)
    conn.close()


def test_a_store_from_before_named_programs_opens_with_its_program_as_main(tmp_path):
    import sqlite3

    from slr_sql.store.schema import migrate, migration_scripts

    path = tmp_path / "old.db"
    conn = sqlite3.connect(path, isolation_level=None)
    conn.execute("PRAGMA journal_mode=WAL")
    migrate(conn, str(path), [s for s in migration_scripts() if s[0] <= 2])
    facts = " ".join(f"usedFor(c{i}, tea)." for i in range(6))
    conn.execute("INSERT INTO slr_program (source, filename, loaded_at) VALUES (?, NULL, 0)",
                 (facts,))
    conn.execute("CREATE TABLE slr_facts_usedFor_2 (ord INTEGER PRIMARY KEY, arg1, arg2)")
    conn.execute("CREATE VIEW usedFor AS SELECT arg1, arg2 FROM slr_facts_usedFor_2")
    conn.execute("""INSERT INTO slr_meta VALUES ('sql_views', '["usedFor"]')""")
    conn.close()
    with _open(path) as kb:
        assert list(kb.programs()) == ["main"]
        kb.add_many(["obj(c1)^1", "obj(c5)^2"])
        assert values(kb, "findall(O, (obj(O)^_, usedFor(O, tea)), L)", "L") == [["c1", "c5"]]
        tables = [r[0] for r in kb.sql("SELECT name FROM sqlite_master WHERE type = 'table' "
                                       "AND name LIKE 'slr_facts%'")[1]]
        assert tables == ["slr_facts_2_used_for"]
        assert len(kb.sql("SELECT * FROM usedFor")[1]) == 6   # the view follows the table
