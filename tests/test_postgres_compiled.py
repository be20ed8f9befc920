"""Compiled queries on PostgreSQL: the query compiler prints through the store's dialect
(slr_sql/store/query_printers.py), so a goal compiles to one statement on the server too.

* the generated programs of the SQL differential: on one PostgreSQL store, compiled SQL ==
  the interpreter == SQLite's answers, errors included, with a real share compiled there;
* the SWI-Prolog corpus (tests/golden/swi_differential.json) answered on PostgreSQL, its
  compiled path included;
* every statement printed for PostgreSQL parses with PostgreSQL's own parser (pglast);
* Prolog's ``1 \\= 1.0`` and ``1 \\= '1'`` in compiled statements, floats as Python writes
  them, a failing statement inside a transaction, and the goals that stay interpreted.

The programs run in schemas of one database per module (a store per schema), so the
server's set-up cost is paid once.
"""
from __future__ import annotations

import collections
import math
import random
import re
import struct

import pglast
import pytest
import test_sql_differential as sqldiff
import test_swi_differential as swidiff
from hypothesis import HealthCheck, given, settings

import slr_sql
from slr_sql import ManualClock
from slr_sql.planner import plan_for
from slr_sql.store.dialect import POSTGRES

STATS: collections.Counter = collections.Counter()
_SCHEMAS = iter(range(1 << 30))


@pytest.fixture(scope="module")
def database(postgres_server):
    from conftest import postgres_database
    return postgres_database(postgres_server[1])


def _schema(url: str, prefix: str) -> str:
    return url + ("&" if "?" in url else "?") + f"schema={prefix}{next(_SCHEMAS)}"


def _plan(kb, goal: str, at=None):
    return plan_for(kb, kb.plans.plan(goal, ()), at is not None)


# ------------------------------------------------------------------ the differential contract

@settings(max_examples=40, derandomize=True, deadline=None,
          suppress_health_check=list(HealthCheck))
@given(sqldiff.program())
def _compiled_equals_interpreted(database, prog):
    text, events, queries, at = prog
    # the events' times are small numbers, not the wall clock's: both stores get one
    # ManualClock (the queries are unsynchronized, so where it stands changes no answer)
    local = slr_sql.open(clock=ManualClock(0.0))
    try:
        local.load(text)
    except slr_sql.errors.SLRError:
        local.close()
        return
    server = slr_sql.open(_schema(database, "d"), clock=ManualClock(0.0))
    try:
        server.load(text)
        parsed = [local._event_from_text(e) for e in events]
        assert local.add_many(parsed) == [] and server.add_many(parsed) == []
        for q in queries:
            try:
                entry = _plan(server, q, at)
            except slr_sql.errors.SLRError:
                continue
            STATS["queries"] += 1
            if hasattr(entry, "reason"):
                STATS["interpreted: " + " ".join(entry.reason.split()[:4])] += 1
            else:
                STATS["compiled"] += 1
                for sql in [entry.sql or "SELECT 1", *entry.guards]:
                    _parses_as_postgresql(sql)
                _runs_or_hands_over(server, entry, at)
            compiled = sqldiff.run(server, q, at, True)
            interpreted = sqldiff.run(server, q, at, False)
            expected = sqldiff.run(local, q, at, True)
            context = f"\nprogram:\n{text}\nevents: {events}\n?- {q} at={at}\n{server.explain(q)}"
            assert compiled == interpreted, context
            assert compiled == expected, context
    finally:
        local.close()
        server.close()


def _runs_or_hands_over(kb, entry, at) -> None:
    """The statement itself runs on the server; the one error it may raise is slr_num's
    (a comparison meeting a non-number, which the interpreter raises as Prolog does):
    anything else (a type clash, a syntax error) is a printer bug that the fallback to the
    interpreter would hide from the comparison of answers."""
    try:
        entry.run(kb, {}, at, None)
    except Exception as exc:   # noqa: BLE001 - whatever it is, it must be slr_num's
        STATS["handed over at run time"] += 1
        assert "slr_num" in str(exc), f"{type(exc).__name__}: {exc}\n{entry.sql}"


def test_compiled_sql_on_postgres_equals_the_interpreter_and_sqlite(database):
    """SQL on the server == the interpreter on the server == SQLite, and the sample is a
    real one: a quarter of the generated queries compile on PostgreSQL."""
    STATS.clear()
    _compiled_equals_interpreted(database)
    assert STATS["queries"] >= 40, dict(STATS)
    assert STATS["compiled"] >= STATS["queries"] // 4, dict(STATS)


def _parses_as_postgresql(sql: str) -> None:
    """The statement as sent to the server is PostgreSQL to PostgreSQL's own parser
    (pglast; parameters as $n)."""
    sent = POSTGRES.statement(sql)
    names: dict[str, int] = {}
    positional = re.sub(r"%\((\w+)\)s",
                        lambda m: f"${names.setdefault(m.group(1), len(names) + 1)}",
                        sent).replace("%%", "%")
    assert len(pglast.parse_sql(positional)) == 1, sent


def test_the_swi_corpus_answers_alike_on_postgres(database):
    """SWI-Prolog's committed answers, given by a PostgreSQL store (the interpreter with a
    step limit, then the compiled path: check_example runs both). A store per example
    costs a schema on the server (~0.3 s): every other example with events, every fourth
    of those with a program only (the whole corpus runs on SQLite)."""
    entries = [e for i, e in enumerate(swidiff.CORPUS)
               if (e["events"] and i % 2 == 0) or (e["program"] and i % 4 == 0)]
    plans: list = []
    for entry in entries:
        assert swidiff.check_example(swidiff.corpus_example(entry), entry["swi"],
                                     _schema(database, "w"), plans) is not swidiff.DISCARDED
    compiled = sum(not hasattr(p, "reason") for p in plans)
    STATS["swi corpus queries"], STATS["swi corpus compiled"] = len(plans), compiled
    assert len(entries) >= 60 and compiled >= 25, (len(entries), len(plans), compiled)


# ------------------------------------------------------------------ values and fallbacks

def test_prolog_types_hold_in_compiled_statements(postgres_url):
    """``1``, ``1.0`` and ``'1'`` are three terms: a compiled match tells them apart by the
    column's text, and the answers keep their types."""
    with slr_sql.open(postgres_url, clock=ManualClock(100.0)) as kb:
        kb.load("same(A, B) :- v(A, X)^_, v(B, Y)^_, X = Y.\n"
                "late(A, T) :- w(A, X)^T, X >= 1.")
        kb.add_many(["v(a, 1)^1", "v(b, 1.0)^2", "v(c, '1')^3", "v(d, 2.5)^4", "v(e, 1)^5",
                     "w(a, 1)^1", "w(b, 1.0)^2", "w(c, 0.5)^3", "w(d, 2.5)^4", "w(e, 1)^5"])
        cases = {"v(A, 1)^T": [("a", 1.0), ("e", 5.0)], "v(A, 1.0)^T": [("b", 2.0)],
                 "v(A, '1')^T": [("c", 3.0)]}
        for goal, expected in cases.items():
            assert not hasattr(_plan(kb, goal), "reason"), kb.explain(goal)
            assert [(str(a["A"]), a["T"]) for a in kb.query(goal)] == expected
        pairs = [(str(a["A"]), str(a["B"])) for a in kb.query("same(A, B)")]
        assert ("a", "e") in pairs and ("a", "b") not in pairs and ("a", "c") not in pairs
        assert [type(a["X"]) for a in kb.query("v(_, X)^_")] == [int, float, slr_sql.Atom,
                                                                 float, int]
        assert not hasattr(_plan(kb, "late(A, T)"), "reason")
        assert [str(a["A"]) for a in kb.query("late(A, T)")] == ["a", "b", "d", "e"]


def test_floats_built_in_sql_are_written_as_python_writes_them(postgres_url):
    """A list built by findall in the statement holds its floats exactly as the encoder
    writes them (the text is compared with stored lists), over the whole float range."""
    rng = random.Random(7)
    values = [1e15, 1.5e15, 1234567890123456.7, 1e16, 7.18373363955321e16, 1e-5, 0.1, -0.0,
              1e22, 5e-324, 1.7976931348623157e308, 3.0, math.inf, -math.inf]
    values += [struct.unpack("d", struct.pack("Q", rng.getrandbits(64)))[0] for _ in range(300)]
    values += [rng.uniform(-1e17, 1e17) for _ in range(300)]
    values = [v for v in values if v == v]
    with slr_sql.open(postgres_url) as kb:
        rows = kb.store.run_compiled(
            "SELECT slr_float_json(x) FROM unnest(CAST(:xs AS float8[])) AS t(x)", {"xs": values})
    assert [r[0] for r in rows] == [slr_sql.encoding.encode_json(v) for v in values]


def test_findall_of_times_compiles_and_equals_stored_lists(postgres_url):
    with slr_sql.open(postgres_url, clock=ManualClock(100.0)) as kb:
        kb.load("ts(L) :- findall(T, p(_)^T, L).\nmatch(X) :- ts(L), seen(X, L)^_.")
        kb.add_many(["p(a)^1.5", "p(b)^2", "p(c)^12345678901234567.0",
                     "seen(yes, [1.5, 2.0, 12345678901234567.0])^3", "seen(no, [1.5])^4"])
        assert not hasattr(_plan(kb, "match(X)"), "reason"), kb.explain("match(X)")
        assert kb.query("match(X)") == [{"X": slr_sql.Atom("yes")}]


def test_a_failing_statement_inside_a_transaction_leaves_it_usable(postgres_url):
    """slr_num meets an atom: the statement fails on the server, the interpreter raises
    Prolog's type error, and the caller's transaction goes on."""
    with slr_sql.open(postgres_url, clock=ManualClock(100.0)) as kb:
        kb.add_many(["v(a, 1)^1", "v(b, x)^2"])
        assert not hasattr(_plan(kb, "v(A, X)^_, X > 0"), "reason")
        with kb.store.transaction():
            with pytest.raises(slr_sql.errors.SLREvaluationError, match="type_error"):
                kb.query("v(A, X)^_, X > 0")
            assert kb.query("v(A, 1)^T") == [{"A": slr_sql.Atom("a"), "T": 1.0}]


@pytest.mark.parametrize("goal, reason", [
    ("v(A, X)^_, Y is X * 2", "arithmetic"),
    ("v(A, X)^_, atom_length(A, N)", "det builtin"),
    ("v(A, X)^_, double(X, Y)", "det builtin"),
    ("aggregate_all(sum(X), v(_, X)^_, S)", "aggregate"),
    ("v(A, [X|_])^_", "parts of a stored list"),
])
def test_goals_needing_python_stay_interpreted_on_postgres(postgres_url, goal, reason):
    """What needs a Python function inside the statement (docs/postgres.md, "what runs
    where") is answered by the interpreter on PostgreSQL, with the reason in explain, and
    the answers are SQLite's compiled ones."""
    events = ["v(a, 1)^1", "v(b, 2.5)^2", "v(c, [3, x])^3"]
    with slr_sql.open(postgres_url, clock=ManualClock(100.0)) as kb, \
            slr_sql.open(clock=ManualClock(100.0)) as local:
        for k in (kb, local):
            k.define("double", 2, lambda x, y: (x, 2 * x) if isinstance(x, (int, float)) else None)
            k.add_many(events)
        assert reason in _plan(kb, goal).reason
        assert not hasattr(_plan(local, goal), "reason")
        run = sqldiff.run
        assert run(kb, goal, None, True) == run(local, goal, None, True)


def test_branches_with_fewer_order_keys_run_as_one_statement(postgres_url, tmp_path):
    """A branch with fewer order keys pads them with NULL; on PostgreSQL an untyped NULL in
    the first branches of a UNION resolves as text and meets a later branch's integer key:
    the statement (and the predicate's view) must still run, with SQLite's answers."""
    program = ("fa(2). fa(1).\n"
               "r2(b) :- fa(_).\nr2(X) :- fa(_), fa(X).\nr4(X) :- r2(X) ; X = c.\n")
    answers = {}
    for where in (str(tmp_path / "robot.db"), postgres_url):
        with slr_sql.open(where, clock=ManualClock(100.0)) as kb:
            kb.load(program)
            plan = _plan(kb, "r4(X)")
            assert not hasattr(plan, "reason"), kb.explain("r4(X)")
            answers[where] = plan.run(kb, {}, None, None)   # the statement itself, no fallback
            assert answers[where] == kb.query("r4(X)")
            assert [r[0] for r in kb.sql("SELECT * FROM r4")[1]] == ["b", "b", 2, 1, 2, 1, "c"] \
                if where.endswith(".db") else ["b", "b", "2", "1", "2", "1", "c"]
    assert answers[postgres_url] == answers[str(tmp_path / "robot.db")]


def test_branches_ordered_by_a_robot_name_run_or_are_interpreted_on_postgres(postgres_url,
                                                                             tmp_path):
    """origin(R, G) with R unbound orders G's rows by the robot's name, a text key. A branch
    without that key pads it with a NULL of the same type (a NULL typed as a number does
    not meet text in a UNION); a branch with a time at the same place cannot share the
    column on PostgreSQL, so that goal is interpreted there, with the reason. Answers as
    SQLite's and the interpreter's."""
    program = ("q(R, X) :- origin(R, seen(X, _)^_) ; X = none.\n"
               "q2(R, X) :- origin(R, seen(X, _)^_) ; other(X)^_.\n")
    events = ["seen(a, dock)^1", "seen(3, bay)^2", "other(b)^3"]
    answers = {}
    for where in (str(tmp_path / "robot.db"), postgres_url):
        with slr_sql.open(where, clock=ManualClock(100.0), robot="r1") as kb:
            kb.add_many(events)
            kb.load(program)
            plan = _plan(kb, "q(R, X)")
            assert not hasattr(plan, "reason"), kb.explain("q(R, X)")
            assert plan.run(kb, {}, None, None) == kb.query("q(R, X)")   # no fallback
            plan = _plan(kb, "q2(R, X)")
            if where == postgres_url:
                assert "robot" in plan.reason
            else:
                assert plan.run(kb, {}, None, None) == kb.query("q2(R, X)")
            goals = ("q(R, X)", "q2(R, X)", "findall(R-X, q(R, X), L)",
                     "aggregate_all(count, q(_, _), N)")
            answers[where] = [sqldiff.run(kb, g, None, True) for g in goals]
            assert [sqldiff.run(kb, g, None, False) for g in goals] == answers[where]
    assert answers[postgres_url] == answers[str(tmp_path / "robot.db")]
    assert len(answers[postgres_url][0][1]) == 3 and answers[postgres_url][3][1] != []


# ------------------------------------------------------------------ integers and floats

# A float beyond 2**53 and an integer near it: Python (the interpreter) and SQLite compare
# them exactly; the server read a float's text as the NUMERIC of its shortest decimal
# (2.0**60 as 1152921504606847000) and turned an integer meeting a double into a double
# (2**53 + 1 =:= 2.0**53), so compiled statements answered otherwise.
EXACT_EVENTS = ["v(a, 9007199254740993)^1", "v(b, 9007199254740992.0)^2",
                "v(c, 1152921504606846977)^3", "v(d, 1.152921504606847e+18)^4",
                "v(e, 0.30000000000000004)^5", "v(f, -1.5)^6", "w(x)^9007199254740992"]
EXACT_GOALS = {   # goal: the (A, B) of its answers, in order
    "v(A, X)^_, v(B, Y)^_, X < Y": [("a", "c"), ("a", "d"), ("b", "a"), ("b", "c"), ("b", "d"),
                                    ("d", "c"), ("e", "a"), ("e", "b"), ("e", "c"), ("e", "d"),
                                    ("f", "a"), ("f", "b"), ("f", "c"), ("f", "d"), ("f", "e")],
    "v(A, X)^_, v(B, Y)^_, X =:= Y": [(n, n) for n in "abcdef"],
    "v(A, X)^_, X >= 1152921504606846977, B = 0": [("c", "0")],
    "v(A, X)^_, X =:= 1152921504606847000, B = 0": [],
    "v(A, X)^_, X > 9007199254740992.0, B = 0": [("a", "0"), ("c", "0"), ("d", "0")],
    "v(A, X)^_, X < 0.3, B = 0": [("f", "0")],
    "w(A)^T, T < 9007199254740993, B = 0": [("x", "0")],
    "w(A)^T, T =:= 9007199254740993, B = 0": [],
    "w(B)^T, v(A, X)^_, X =:= T": [("b", "x")],
    "w(B)^T, v(A, X)^_, X > T, X < 1.0e18": [("a", "x")],
    "aggregate_all(count, v(_, _)^_, A), A > 5.999999999999999, B = 0": [("6", "0")],
}


def test_integers_and_floats_compare_exactly_on_both_backends(postgres_url, tmp_path):
    """Each goal runs as one statement on both backends and answers as the interpreter."""
    for where in (postgres_url, str(tmp_path / "robot.db")):
        with slr_sql.open(where, clock=ManualClock(100.0)) as kb:
            kb.add_many(EXACT_EVENTS)
            for goal, expected in EXACT_GOALS.items():
                entry = _plan(kb, goal)
                assert not hasattr(entry, "reason"), kb.explain(goal)
                compiled = entry.run(kb, {}, None, None)    # the statement itself
                kb.sql_enabled = False
                assert compiled == kb.query(goal), (where, goal)
                kb.sql_enabled = True
                assert [(str(a["A"]), str(a["B"])) for a in compiled] == expected, \
                    (where, goal, compiled)


def test_a_float_and_an_integer_beyond_64_bits_are_compared_by_the_interpreter(postgres_url):
    with slr_sql.open(postgres_url, clock=ManualClock(100.0)) as kb:
        kb.add_many(["v(a, 9.223372036854776e18)^1", "v(b, 1)^2"])
        goal = "v(A, X)^_, X < 9223372036854775809"
        assert "beyond 64 bits" in _plan(kb, goal).reason
        assert [str(a["A"]) for a in kb.query(goal)] == ["a", "b"]
        assert not hasattr(_plan(kb, "v(A, X)^_, X < 9223372036854775807"), "reason")


@pytest.mark.parametrize("goal, expected", [
    ("a(O, N)^_, prev(w(P)^T, N)", [("x", "q"), ("y", "p"), ("z", "p")]),
    ("a(O, N)^_, next(w(P)^T, [N, inf])", [("x", "q"), ("y", "p"), ("z", "p")]),
    ("a(O, N)^_, next(w(P)^T, [0, N])", [("x", "r"), ("y", "r"), ("z", "r")]),
])
def test_a_time_from_an_integer_is_its_float_in_compiled_prev_and_next(postgres_url, tmp_path,
                                                                      goal, expected):
    """prev/next take float(N) of an integer time, as the interpreter does: 2**53 + 3 is
    2.0**53 + 4 and 2**53 + 1 is 2.0**53 (SQLite compared the stored times with the integer
    itself; found by comparing the backends)."""
    events = ["w(r)^1", "w(p)^9007199254740992", "w(q)^9007199254740996",
              "a(x, 9007199254740995)^1", "a(y, 9007199254740993)^2", "a(z, 9007199254740992)^3"]
    for where in (str(tmp_path / "robot.db"), postgres_url):
        with slr_sql.open(where, clock=ManualClock(100.0)) as kb:
            kb.add_many(events)
            entry = _plan(kb, goal)
            assert not hasattr(entry, "reason"), kb.explain(goal)
            compiled = entry.run(kb, {}, None, None)
            kb.sql_enabled = False
            assert compiled == kb.query(goal), where
            assert [(str(a["O"]), str(a["P"])) for a in compiled] == expected, (where, compiled)
