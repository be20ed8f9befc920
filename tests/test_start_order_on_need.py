"""The start-ordered indexes of an event type are built on first need.

A new event table (a rule's head type, a type an added event creates, a declared one) gets
only its end-ordered indexes ``(t_end, t_start)`` and ``(arg1, t_end, t_start)``;
``(t_start, t_end)`` and ``(arg1, t_start, t_end)`` are built by the first reader in start
order (a ``next`` lookup, the ties at a start, ``bracket``, compiled ``next``, a statement of
a rule or a compiled query whose plan would use them -- on PostgreSQL every statement of a
rule reading the type, as its planner cannot be asked without the data). Answers are
those of a store whose type was declared up front (all four indexes from the start), on
SQLite and PostgreSQL, through SQL and through the interpreter; a build rolled back leaves
no belief behind, another process's build is found in the catalog, and a reader that cannot
build (another writer holds the lock) still answers.
"""
from __future__ import annotations

import json
import os
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

import slr_sql
from store_holders import table_written
from conftest import postgres_database
from slr_sql import ManualClock

REPO = Path(__file__).resolve().parent.parent

RULE = ":- consumption(unrestricted).\n:- max_delay(a/1, 0).\n:- max_delay(b/1, 0).\n" \
       "c(X) <- a(X) seq b(X).\n"
DECLARED = ":- event c/1.\n" + RULE
# a(K)^I and b(K)^(I + 0.5), K = I mod 3: unrestricted pairs every earlier a(K) with a b(K),
# so that many complex events share a start or an end
EVENTS = [f"a({i % 3})^{i}" for i in range(1, 13)] + \
         [f"b({i % 3})^{i + 0.5}" for i in range(4, 13)]
END_INDEXES = {"slr_ix__c__end", "slr_ix__c__a1_end"}
START_INDEXES = {"slr_ix__c__start", "slr_ix__c__a1_start"}
INTERVALS = [(0.0, 100.0), (2.5, 9.0), (5.0, 13.0), (11.5, 100.0)]


def _opened(location: str, program: str, **options) -> slr_sql.KnowledgeBase:
    kb = slr_sql.open(location, clock=ManualClock(100.0), **options)
    kb.load(program)
    kb.add_many(EVENTS)
    return kb


@pytest.fixture
def reference(request, backend, tmp_path):
    """The same store with c/1 declared up front, on the same backend (ties between rows
    go by arrival there): its table has all four indexes."""
    if backend.startswith("postgresql"):
        location = postgres_database(request.getfixturevalue("postgres_server")[1])
    else:
        location = str(tmp_path / "declared.db")
    kb = _opened(location, DECLARED)
    assert kb.store.ensure_start_order("c", 1)
    assert END_INDEXES | START_INDEXES <= kb.store.index_names("c")
    yield kb
    kb.close()


def _indexes(kb) -> set[str]:
    """The store's own indexes of c's table (PostgreSQL also lists its primary key's), an
    index over the first argument standing for its companion over the argument's key on
    PostgreSQL (``NAME_k``: long values), which is built with it."""
    names = {name for name in kb.store.index_names("c") if name.startswith("slr_ix__")}
    companions = {name for name in names if name.endswith("_k")}
    assert {name[:-2] for name in companions} <= names, names
    if kb.store.dialect.name == "postgresql":
        assert {f"{name}_k" for name in names - companions if "__a1_" in name} <= companions, \
            names
    return names - companions


def _next(kb, lo: float, hi: float, bound=None) -> list:
    return [row[:3] for row in kb.store.next_candidates("c", 1, bound, lo, hi)]


def _lookups(kb) -> list:
    """Every lookup in start order, over several intervals, bound and not."""
    out = []
    for lo, hi in INTERVALS:
        out.append(_next(kb, lo, hi))
        out.append(_next(kb, lo, hi, {0: 1}))
        first = next(kb.store.next_candidates("c", 1, None, lo, hi), None)
        if first is not None:
            out.append([row[:3] for row in kb.store.rows_at_start("c", 1, None, first[1], hi)])
            out.append([row[:3] for row in kb.store.rows_at_start("c", 1, {0: 1}, first[1], hi)])
    for t in (0.0, 4.5, 7.0, 50.0):
        out.append(kb.store.bracket("c", 1, {0: 2}, t))
    return out


def _queries(kb) -> list:
    return [kb.query(f"next(c(X)^[S, E], [{lo}, {hi}])") for lo, hi in INTERVALS] + \
        [kb.query(f"next(c(2)^[S, E], [{lo}, {hi}])") for lo, hi in INTERVALS]


def _start_indexes(kb, table: str) -> set[str]:
    return {name for name in kb.store.index_names(table)
            if name in (f"slr_ix__{table}__start", f"slr_ix__{table}__a1_start")}


def test_a_rule_head_table_has_no_start_ordered_index_after_detections(backend):
    with _opened(backend, RULE) as kb:
        assert kb.store.count("c", 1) > 20
        assert _indexes(kb) == END_INDEXES
        # b's are: the statement finding the b's after a new a searches them by start
        # (asked of SQLite's planner; PostgreSQL builds them for every type a rule reads)
        assert _start_indexes(kb, "b") == {"slr_ix__b__start", "slr_ix__b__a1_start"}
        sqlite = kb.store.dialect.index_hints
        assert _start_indexes(kb, "a") == (set() if sqlite else
                                           {"slr_ix__a__start", "slr_ix__a__a1_start"})
        # a declared type, and one an added event creates, get only the end-ordered ones too
        kb.load(":- event d/1.")
        kb.add("f(1, 2)^1")
        assert _start_indexes(kb, "d") == _start_indexes(kb, "f") == set()
        assert {"slr_ix__d__end", "slr_ix__d__a1_end"} <= kb.store.index_names("d")
        # readers in end order build nothing
        assert kb.query("prev(c(X)^[S, E], 9)") and kb.query("c(1)^[S, E]")
        assert kb.query("prev(f(X, Y)^T, 9)") and kb.query("f(1, Y)^T")
        assert _indexes(kb) == END_INDEXES
        assert _start_indexes(kb, "f") == set()


@pytest.mark.parametrize("reader", ["lookups", "compiled", "interpreted"])
def test_the_first_reader_in_start_order_builds_them_and_answers_as_before(
        backend, reference, reader):
    with _opened(backend, RULE) as kb:
        assert _indexes(kb) == END_INDEXES
        if reader == "lookups":
            assert _lookups(kb) == _lookups(reference)
        else:
            kb.sql_enabled = reader == "compiled"
            if reader == "compiled":
                assert "engine: sql" in kb.explain("next(c(X)^[S, E], [0, 10])")
            answers = _queries(kb)
            assert answers == _queries(reference)
            kb.sql_enabled = True
            assert _queries(kb) == answers   # SQL == interpreter
        assert _indexes(kb) == END_INDEXES | START_INDEXES
        assert _lookups(kb) == _lookups(reference)
        if kb.store.dialect.index_hints:
            assert 'INDEXED BY "slr_ix__c__a1_start"' in kb.store.lookup_sql(
                "next", "c", 1, {0: 1})


def test_a_bracket_builds_them(backend, reference):
    with _opened(backend, RULE) as kb:
        assert kb.store.bracket("c", 1, {0: 1}, 6.0) == reference.store.bracket("c", 1, {0: 1}, 6.0)
        assert _indexes(kb) == END_INDEXES | START_INDEXES


def _in_another_process(location: str, code: str) -> object:
    env = dict(os.environ, PYTHONPATH=str(REPO))
    done = subprocess.run(
        [sys.executable, "-c", "import json, sys\nfrom slr_sql.store import EventStore\n"
         f"store = EventStore({location!r})\n{code}\nstore.close()"],
        env=env, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def test_another_process_builds_them_and_this_one_finds_them_in_the_catalog(backend):
    with _opened(backend, RULE, busy_timeout=0.3) as kb:
        assert _indexes(kb) == END_INDEXES   # created here: known to lack them
        built = _in_another_process(backend, (
            'rows = [row[:3] for row in store.next_candidates("c", 1, None, 0, 100)]\n'
            'print(json.dumps([sorted(n for n in store.index_names("c") if n[:4] == "slr_" and n[-2:] != "_k"),'
            ' len(rows)]))'))
        assert built == [sorted(END_INDEXES | START_INDEXES), kb.store.count("c", 1)]
        other = table_written(backend)
        try:
            # a build now would wait for the lock past the busy timeout and give up: found
            # in the catalog instead, the indexes are used at once
            assert kb.store.ensure_start_order("c", 1)
            if kb.store.dialect.index_hints:
                assert "INDEXED BY" in kb.store.lookup_sql("next", "c", 1)
        finally:
            other.rollback()
            other.close()
        assert len(_next(kb, 0, 100)) == kb.store.count("c", 1)


def test_a_reader_that_cannot_build_still_answers(backend, reference):
    with _opened(backend, RULE, busy_timeout=0.3) as kb:
        other = table_written(backend)
        try:
            assert _lookups(kb) == _lookups(reference)
            assert _queries(kb) == _queries(reference)
            assert _indexes(kb) == END_INDEXES
            if kb.store.dialect.index_hints:   # (naming a missing index is an error)
                assert "INDEXED BY" not in kb.store.lookup_sql("next", "c", 1)
        finally:
            other.rollback()
            other.close()
        kb.clock.advance(1)   # (a busy build is tried again once the store's clock moved on)
        assert _lookups(kb) == _lookups(reference)
        assert _indexes(kb) == END_INDEXES | START_INDEXES


def test_a_rolled_back_build_leaves_no_belief_behind(backend, reference):
    with _opened(backend, RULE) as kb:
        expected = _next(reference, 0, 100)
        with pytest.raises(RuntimeError):
            with kb.store.transaction():
                stream = kb.store.next_candidates("c", 1, None, 0, 100)
                first = [next(stream)[:3]]   # (built inside the transaction)
                assert _indexes(kb) == END_INDEXES | START_INDEXES
                raise RuntimeError("undo")
        assert _indexes(kb) == END_INDEXES
        # the stream goes on after the rollback, the lookups work: neither names an index
        # the rollback took, and the next reader builds them again
        assert first + [row[:3] for row in stream] == expected
        assert _lookups(kb) == _lookups(reference)
        assert _indexes(kb) == END_INDEXES | START_INDEXES


def test_a_rule_reading_the_complex_type_builds_what_its_plans_use(backend, reference):
    with _opened(backend, RULE) as kb:
        assert _indexes(kb) == END_INDEXES
        kb.load(":- max_delay(e/1, 0).\nd(X) <- c(X) seq e(X).")
        kb.add_many(["e(1)^20", "e(2)^21"])
        derived = sorted((r["X"], r["S"], r["E"]) for r in kb.query("d(X)^[S, E]"))
        # every c(1) and c(2) ends before e's start: one d per c of the same argument
        ends = {1: 20.0, 2: 21.0}
        assert derived == sorted((r["X"], r["S"], ends[r["X"]])
                                 for r in reference.query("c(X)^[S, _]") if r["X"] in ends)
        assert len(derived) > 10
        # the new e's find their c's by end: SQLite's planner wants no start order of c
        # (PostgreSQL builds it for every type a rule reads)
        assert _indexes(kb) == (END_INDEXES if kb.store.dialect.index_hints
                                else END_INDEXES | START_INDEXES)
        assert _lookups(kb) == _lookups(reference)
        assert _indexes(kb) == END_INDEXES | START_INDEXES


RECENT = ":- consumption(recent).\n:- max_delay(a/1, 0).\n:- max_delay(b/1, 0).\n" \
         "c(X) <- a(X) seq b(X).\n"


def test_a_recent_sequence_searches_only_by_end(backend):
    """seq under recent decides each b by the latest a ending before it: no statement it
    runs reads a or b in start order (SQLite's planner says so), so storing their events
    writes no start-ordered entry (benchmarks/README.md: 20% of the CPU of the rule's run)."""
    with _opened(backend, RECENT) as kb:
        kb.add_many([f"a({i % 3})^{i}" for i in range(20, 40)]
                    + [f"b({i % 3})^{i + 0.5}" for i in range(20, 40)])
        kb.clock.set(200.0)
        assert kb.store.count("c", 1) > 10
        sqlite = kb.store.dialect.index_hints
        for table in ("a", "b"):
            assert _start_indexes(kb, table) == (
                set() if sqlite else {f"slr_ix__{table}__start", f"slr_ix__{table}__a1_start"})


def test_a_compiled_query_builds_the_start_order_its_plan_uses(tmp_path):
    """A join on the start time searches the second type by start: its indexes are built
    before the statement's first run; the answers are the interpreter's."""
    kb = slr_sql.open(str(tmp_path / "s.db"), clock=ManualClock(100.0))
    kb.add_many(["p(1)^[1, 3]", "p(2)^[2, 5]", "q(1)^[1, 4]", "q(2)^[2, 2.5]", "q(3)^[2, 9]"])
    goal = "p(X)^[S, E1], q(Y)^[S, E2]"
    assert "engine: sql" in kb.explain(goal)
    assert _start_indexes(kb, "q") == set()
    answers = kb.query(goal)
    assert _start_indexes(kb, "q") == {"slr_ix__q__start", "slr_ix__q__a1_start"}
    assert _start_indexes(kb, "p") == set()   # (the outer loop: read in end order)
    kb.sql_enabled = False
    assert kb.query(goal) == answers and len(answers) == 3
    kb.close()


def test_a_build_a_rollback_took_back_is_made_again(tmp_path):
    """A rule's statement whose first run built an index inside a transaction that rolled
    back is built again, and its index with it, at its next run."""
    kb = _opened(str(tmp_path / "r.db"), RULE)
    kb.add_many(["z(1)^1"])
    kb.load(":- event y/1.\n:- max_delay(y/1, 0).\n:- max_delay(w/1, 0).\n"
            "v(X) <- y(X) seq w(X).")
    kb.add_many(["w(0)^101"])          # both tables exist; no new y yet: nothing searches w
    assert _start_indexes(kb, "w") == set()
    with pytest.raises(RuntimeError):
        with kb.store.transaction():
            kb.add_many(["y(1)^102", "w(1)^103"])   # a new y: its w's found by start
            assert _start_indexes(kb, "w") == {"slr_ix__w__start", "slr_ix__w__a1_start"}
            raise RuntimeError("undo")
    assert _start_indexes(kb, "w") == set()
    kb.add_many(["y(2)^104", "w(2)^105"])
    assert _start_indexes(kb, "w") == {"slr_ix__w__start", "slr_ix__w__a1_start"}
    kb.clock.set(200.0)
    assert [r["X"] for r in kb.query("v(X)^[S, E]")] == [2]
    kb.close()


def test_an_inspection_view_gets_the_start_order_its_plan_uses(tmp_path):
    """A rule's view is read by other programs, which cannot build indexes: the ones its
    plan would use are built when the view is made; the view answers as the query does."""
    path = str(tmp_path / "v.db")
    kb = slr_sql.open(path, clock=ManualClock(100.0))
    kb.add_many(["p(1)^[1, 3]", "p(2)^[2, 5]", "q(1)^[1, 4]", "q(2)^[2, 2.5]"])
    assert _start_indexes(kb, "q") == set()
    kb.load("same_start(X, Y) :- p(X)^[S, _], q(Y)^[S, _].")
    assert _start_indexes(kb, "q") == {"slr_ix__q__start", "slr_ix__q__a1_start"}
    expected = sorted((r["X"], r["Y"]) for r in kb.query("same_start(X, Y)"))
    kb.close()
    import sqlite3
    with sqlite3.connect(path) as outside:
        rows = outside.execute("SELECT * FROM same_start").fetchall()
    assert sorted(rows) == expected == [(1, 1), (2, 2)]


def test_a_plot_of_the_whole_history_builds_start_order_first(tmp_path):
    """A plot without a window starts at the earliest start of its types, read from the
    start-ordered index a local store builds for it (a remote one reads without)."""
    kb = slr_sql.open(str(tmp_path / "p.db"), clock=ManualClock(100.0))
    kb.add_many(["move(1)^[2, 8]", "move(2)^[1, 30]", "seen(1)^4"])
    assert _start_indexes(kb, "move") == set()
    kb.plot(["move"], start=0, end=40)    # a window given: no earliest start is read
    assert _start_indexes(kb, "move") == set()
    figure = kb.plot(["move"], size=(600, 120))
    assert figure.get_size_inches().tolist() == [6.0, 1.2]
    assert _start_indexes(kb, "move") == {"slr_ix__move__start", "slr_ix__move__a1_start"}
    assert _start_indexes(kb, "seen") == set()
    kb.close()


def test_a_negation_over_a_long_history_searches_it_from_the_interval_start(tmp_path):
    """``cnot n`` asks for no n with ``t_start > S AND t_end < E``: by the end order that
    is every n ending before E -- the type's whole history before the interval, read again
    at each check -- while by the start order it is the n's after S. The two one-sided
    bounds bind as many columns; the history only grows, so an upper bound alone on a time
    is the costlier read and n's start-ordered indexes are wanted (without them: 1.2 s per
    pair against 0.6 ms at 100k n's)."""
    kb = slr_sql.open(str(tmp_path / "n.db"), clock=ManualClock(0.0))
    kb.load(":- max_delay(n/0, 0).\n:- max_delay(a/0, 0).\n:- max_delay(b/0, 0).\n"
            "c <- (a seq b) cnot n.\n")
    kb.add_many([f"n^{i}" for i in range(1, 41)])
    kb.clock.set(41.0)
    kb.add_many(["a^42", "b^43", "n^44", "a^45", "b^46"])
    kb.clock.set(50.0)
    assert _start_indexes(kb, "n") == {"slr_ix__n__start"}
    # the answers are the interpreter's: (a^42 seq b^43), (a^45 seq b^46); n^44 blocks the
    # pairs around it
    found = sorted((r["S"], r["E"]) for r in kb.query("c^[S, E]"))
    kb.sql_enabled = False
    assert found == sorted((r["S"], r["E"]) for r in kb.query("c^[S, E]")) \
        == [(42.0, 43.0), (45.0, 46.0)]
    kb.close()


def test_a_compiled_query_whose_build_a_rollback_took_back_builds_it_again(tmp_path):
    """A compiled query's first run inside a transaction that rolls back (a caller's, or
    the add a ``where`` goal runs in) built the start-ordered indexes its plan uses, and the
    rollback took them back: its next run asks again, not reading without them for good."""
    kb = slr_sql.open(str(tmp_path / "q.db"), clock=ManualClock(100.0))
    kb.add_many(["p(1)^[1, 3]", "p(2)^[2, 5]", "q(1)^[1, 4]", "q(2)^[2, 2.5]", "q(3)^[2, 9]"])
    goal = "p(X)^[S, E1], q(Y)^[S, E2]"
    with pytest.raises(RuntimeError):
        with kb.store.transaction():
            answers = kb.query(goal)
            assert _start_indexes(kb, "q") == {"slr_ix__q__start", "slr_ix__q__a1_start"}
            raise RuntimeError("undo")
    assert _start_indexes(kb, "q") == set()
    assert kb.query(goal) == answers and len(answers) == 3
    assert _start_indexes(kb, "q") == {"slr_ix__q__start", "slr_ix__q__a1_start"}
    kb.close()


def test_a_table_of_the_users_own_that_the_copy_cannot_make_leaves_the_planner_askable(
        tmp_path):
    """The planner is asked of a copy of the schema: a table of the user's (kb.sql) whose
    statement cannot be run again as it stands -- an FTS5 table, whose own shadow tables
    are listed after it -- is left out of the copy, not the end of every question (which
    left a compiled query without the start order its plan wants)."""
    kb = slr_sql.open(str(tmp_path / "f.db"), clock=ManualClock(100.0))
    kb.add_many(["p(1)^[1, 3]", "p(2)^[2, 5]", "q(1)^[1, 4]", "q(2)^[2, 2.5]", "q(3)^[2, 9]"])
    kb.sql("CREATE VIRTUAL TABLE notes USING fts5(body)", write=True)
    kb.sql("INSERT INTO notes (body) VALUES ('q is late')", write=True)
    goal = "p(X)^[S, E1], q(Y)^[S, E2]"
    answers = kb.query(goal)
    assert _start_indexes(kb, "q") == {"slr_ix__q__start", "slr_ix__q__a1_start"}
    assert _start_indexes(kb, "p") == set()
    kb.sql_enabled = False
    assert kb.query(goal) == answers and len(answers) == 3
    assert kb.sql("SELECT body FROM notes WHERE notes MATCH 'late'")[1] == [("q is late",)]
    kb.close()


def test_a_build_taken_back_by_the_outer_rollback_after_an_inner_one_is_made_again(tmp_path):
    """A build inside a transaction, then a nested part of it rolled back (the build
    stays), statements built again finding the index there, then the whole transaction
    rolled back (the build goes): the statements are built again after that rollback too,
    and their index with them."""
    kb = _opened(str(tmp_path / "r.db"), RULE)
    kb.load(":- event y/1.\n:- max_delay(y/1, 0).\n:- max_delay(w/1, 0).\n"
            "v(X) <- y(X) seq w(X).")
    kb.add_many(["w(0)^101"])
    wanted = {"slr_ix__w__start", "slr_ix__w__a1_start"}
    with pytest.raises(RuntimeError):
        with kb.store.transaction():
            kb.add_many(["y(1)^102", "w(1)^103"])   # a new y: its w's found by start
            assert _start_indexes(kb, "w") == wanted
            with pytest.raises(ValueError):
                with kb.store.transaction():        # a nested part rolled back
                    raise ValueError("inner")
            kb.add_many(["y(2)^104", "w(2)^105"])   # statements built again: index there
            assert _start_indexes(kb, "w") == wanted
            raise RuntimeError("undo")
    assert _start_indexes(kb, "w") == set()
    kb.add_many(["y(3)^106", "w(3)^107"])
    assert _start_indexes(kb, "w") == wanted
    kb.clock.set(200.0)
    assert [r["X"] for r in kb.query("v(X)^[S, E]")] == [3]
    kb.close()


def test_a_schema_a_rollback_took_back_is_not_taken_for_a_later_one(tmp_path):
    """SQLite's schema_version goes back with a rollback, and the next two changes bring it
    to the number it had inside the rolled-back transaction: the planner's copy of the
    schema made in there (with w's start-ordered indexes, which the rollback took) is not
    the schema then, and w's statements, built again, still get their indexes."""
    kb = _opened(str(tmp_path / "v.db"), RULE)
    kb.add_many(["z(1)^1"])
    kb.load(":- event y/1.\n:- max_delay(y/1, 0).\n:- max_delay(w/1, 0).\n"
            "v(X) <- y(X) seq w(X).")
    kb.add_many(["w(0)^101"])
    wanted = {"slr_ix__w__start", "slr_ix__w__a1_start"}
    version = kb.sql("PRAGMA schema_version")[1][0][0]
    with pytest.raises(RuntimeError):
        with kb.store.transaction():
            kb.add_many(["y(1)^102", "w(1)^103"])   # w's two indexes: the version + 2
            assert _start_indexes(kb, "w") == wanted
            inside = kb.sql("PRAGMA schema_version")[1][0][0]
            raise RuntimeError("undo")
    assert _start_indexes(kb, "w") == set()
    assert kb.store.ensure_start_order("z", 1)     # two other indexes: the same number
    assert kb.sql("PRAGMA schema_version")[1][0][0] == inside == version + 2
    kb.add_many(["y(2)^104", "w(2)^105"])
    assert _start_indexes(kb, "w") == wanted
    kb.clock.set(200.0)
    assert [r["X"] for r in kb.query("v(X)^[S, E]")] == [2]
    kb.close()


@pytest.mark.parametrize("goal, searched", [
    ("p(X)^[S, E1], q(Y)^[S, E2]", {"q"}),          # a join on the start time
    ("q(Y)^[S, E], S >= 2, S =< 2.5", {"q"}),        # a range of starts
    ("q(Y)^[S, E], E >= 4", set()),                  # by end only
])
def test_a_compiled_query_builds_the_start_order_it_searches_on_either_backend(
        backend, goal, searched):
    """A compiled query that compares a type's start time (a join on it, a range of it)
    gets that type's start-ordered indexes before its first run on PostgreSQL too, whose
    planner cannot be asked: without them every run reads the type's whole table (a
    ``where`` goal of an event rule: once per detection); there both sides of a join on the
    start get them (which one the server searches depends on its statistics). One that
    reads by end builds none."""
    with slr_sql.open(backend, clock=ManualClock(100.0)) as kb:
        kb.add_many(["p(1)^[1, 3]", "p(2)^[2, 5]", "q(1)^[1, 4]", "q(2)^[2, 2.5]",
                     "q(3)^[2, 9]"])
        assert "engine: sql" in kb.explain(goal)
        answers = kb.query(goal)
        if not kb.store.dialect.index_hints and len(searched):
            searched = {"p", "q"} & {t for t in ("p", "q") if f'"{t}"' in
                                     kb.explain(goal)}   # (no planner: both sides of a join)
        for table in ("p", "q"):
            assert _start_indexes(kb, table) == (
                {f"slr_ix__{table}__start", f"slr_ix__{table}__a1_start"}
                if table in searched else set()), table
        kb.sql_enabled = False
        assert kb.query(goal) == answers and answers


def test_a_query_of_another_constant_does_not_ask_the_planner_again(tmp_path):
    """Goals alike but for a constant compile plans of one statement text (the constant
    is a parameter): whether it wants a start-ordered index is asked of the planning copy
    once (the synchronizer compiles such a plan for each released query), and the answers
    are each constant's."""
    kb = slr_sql.open(str(tmp_path / "p.db"), clock=ManualClock(100.0))
    kb.add_many([f"s({k})^{k}" for k in range(1, 20)])
    db = kb.store._db
    assert kb.query("prev(s(X)^T, 5), X > 0") == [{"X": 5, "T": 5.0}]
    copy = db._planning[1]
    asked: list[int] = []

    def counting(action, *_):
        # (the authorizer sees every statement prepared, an EXPLAIN too, which no trace
        # callback reports: a SELECT's is one question to the planner)
        if action == sqlite3.SQLITE_SELECT:
            asked.append(action)
        return sqlite3.SQLITE_OK

    copy.set_authorizer(counting)
    answers = [kb.query(f"prev(s(X)^T, {z}), X > 0") for z in (7, 9.5, 12)]
    assert answers == [[{"X": 7, "T": 7.0}], [{"X": 9, "T": 9.0}], [{"X": 12, "T": 12.0}]]
    assert db._planning[1] is copy and asked == []
    # (a statement of another text is asked)
    assert len(kb.query("s(X)^[S, E], S > 15")) == 4
    assert db._planning[1] is copy and asked
    assert _start_indexes(kb, "s") == set()
    kb.close()


# (policy, pattern) -> the types whose start-ordered indexes SQLite's planner wants for the
# statements of the rule (PostgreSQL: every type the rule reads)
AT_LOAD = {
    ("unrestricted", "a(X) seq b(X)"): {"b"},
    ("recent", "a(X) starts b(X)"): {"a", "b"},
    ("chronological", "(a(X) seq b(X)) cnot d(X)"): {"d"},
}


@pytest.mark.parametrize("policy, pattern", list(AT_LOAD))
def test_a_rule_loaded_on_a_stored_history_builds_its_start_order_at_the_load(
        backend, policy, pattern):
    """On a store already holding many events the build is long (~1-1.6 s CPU at
    1,000,000 events): the load, which a user expects to cost, makes it, not the first add
    after it, which a live stream waits on. The adds after the load build none."""
    types = ("a", "b", "d")
    with slr_sql.open(backend, clock=ManualClock(0.0)) as kb:
        kb.add_many([f"a({i % 3})^{i}" for i in range(1, 13)]
                    + [f"b({i % 3})^{i + 0.5}" for i in range(4, 13)]
                    + [f"d({i % 3})^[{i + 0.2}, {i + 0.7}]" for i in range(4, 13)])
        assert all(_start_indexes(kb, t) == set() for t in types)
        kb.load(f":- consumption({policy}).\n"
                + "".join(f":- max_delay({t}/1, 0).\n" for t in types)
                + f"c(X) <- {pattern}.")
        wanted = set(AT_LOAD[(policy, pattern)]) if kb.store.dialect.index_hints \
            else set(types) - ({"d"} if "d(" not in pattern else set())
        built = {t: _start_indexes(kb, t) for t in types}
        assert built == {t: ({f"slr_ix__{t}__start", f"slr_ix__{t}__a1_start"}
                             if t in wanted else set()) for t in types}
        # (a(1) starts b(1); a(2) seq b(2), no d(2) between them)
        for event in ("a(1)^[21, 21.5]", "b(1)^[21, 22]", "a(2)^23", "d(1)^[23.2, 23.3]",
                      "b(2)^24"):
            kb.add(event)
            kb.clock.set(kb.clock.now() + 1.0)
        kb.clock.set(40.0)
        assert {t: _start_indexes(kb, t) for t in types} == built
        assert kb.query("c(X)^[S, E], S > 20")
