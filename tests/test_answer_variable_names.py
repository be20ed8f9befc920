"""The variables an answer holds are named as SWI-Prolog 9's top level names them, compared
with a live swipl: a query's own variables by their names (a fresh variable a query
variable is bound to by that variable's name), every other one -- a clause's, an `_`, one a
builtin made -- `_` when the answer holds it once, `_A`, `_B`, ... when more than once,
never by the name a clause gave it (docs/printed_text.md, "Answers"). The same from the
compiled SQL as from the interpreter, on both backends, in `slr query` (a local store and a
served one) and `slr run`. `tests/test_shell.py` compares `slr shell` the same way."""
from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, example, given, settings, strategies as st
from service_helpers import ServiceProcess, slr_env

import slr_sql
from slr_sql.answers import answer_text
from slr_sql.cli import answer_lines
from slr_sql.planner import try_sql
from slr_sql.terms import Struct, Var


def layout(answer: str) -> str:
    """An answer's text without the layout swipl and we print it in (a binding a line, a
    space after each comma; our ` .`)."""
    return re.sub(r",\s+", ",", answer.strip()).rstrip(".").strip()


def swipl_texts(program: str, goals: list[str]) -> list[str]:
    """swipl's top level's first answer to each goal (deterministic goals: swipl reads the
    next goal where a terminal would type `;`), with ``program`` consulted."""
    swipl = shutil.which("swipl")
    if swipl is None:
        pytest.fail("swipl (SWI-Prolog) is not installed: this test compares with it "
                    "(apt-get install swi-prolog-nox)")
    with tempfile.TemporaryDirectory(prefix="slr_swi_names_") as folder:
        path = Path(folder) / "program.pl"
        path.write_text(program, encoding="utf-8")
        done = subprocess.run([swipl, "-q", "-f", "none", str(path)],
                              input="".join(f"{goal}.\n" for goal in goals),
                              capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    texts = [layout(a) for a in done.stdout.split("\n\n") if a.strip()]
    assert len(texts) == len(goals), (done.stdout, done.stderr)
    return texts


def our_text(kb, goal: str) -> str:
    return layout(answer_lines(kb.query(goal))[0])


# ---------------------------------------------------------------------------------------------
# the data: what kb.query returns (and the service sends) names the variables so
# ---------------------------------------------------------------------------------------------

def var_names(value) -> list[str]:
    todo, names = [value], []
    while todo:
        x = todo.pop()
        if isinstance(x, Var):
            names.append(x.name)
        elif isinstance(x, Struct):
            todo.extend(x.args)
        elif isinstance(x, list):
            todo.extend(x)
    return names


def test_an_answer_names_no_variable_after_a_clause_nor_an_underscore():
    """`q(X), Y = 1.` answered {'X': f(Var('Y'), Var('Y'), Var('Z')), 'Y': 1}: the clause's
    names, one of them the query's Y (bound to 1); a client reading it over the service
    (variables by name) took X's Y for the query's. Two `_` of a query were two variables
    named `_`, one over the service."""
    kb = slr_sql.open(clock=slr_sql.ManualClock(0))
    kb.load("q(f(Y, Y, Z)).\n")
    (answer,) = kb.query("q(X), Y = 1")
    assert answer["Y"] == 1
    first, second, third = answer["X"].args
    assert first is second and first is not third
    assert all(re.fullmatch(r"_G\d+", name) for name in var_names(answer["X"]))
    (answer,) = kb.query("X = f(_, _)")
    first, second = answer["X"].args
    assert first is not second and first.name != second.name


def test_a_fresh_variable_a_query_variable_is_bound_to_has_that_variables_name():
    """`X = f(Y, _), Y = _.` answered X = f(_G7, _G8): Y's name was lost (swipl: f(Y, _));
    `X = f(Z), Y = Z.` named the variable Z (the engine's binding), swipl names it Y (the
    last of the query's variables that hold it)."""
    kb = slr_sql.open(clock=slr_sql.ManualClock(0))
    (answer,) = kb.query("X = f(Y, _), Y = _")
    assert list(answer) == ["X"]
    y, other = var_names(answer["X"])[::-1]
    assert y == "Y" and re.fullmatch(r"_G\d+", other)
    (answer,) = kb.query("X = f(Z), Y = Z")
    assert {k: var_names(v) for k, v in answer.items()} == \
        {"X": ["Y"], "Z": ["Y"], "Y": ["Y"]}


def test_a_cyclic_terms_labels_keep_their_names_among_renamed_variables():
    """A cyclic answer comes as `@(Template, [S_1 = Value])` (docs/language.md): its labels
    stand for subterms, so they are not renamed as the variables it holds are."""
    kb = slr_sql.open(clock=slr_sql.ManualClock(0))
    assert answer_lines(kb.query("X = f(X, Y, _), Z = g(Y)")) == \
        ["X = @(S_1,[S_1=f(S_1,Y,_)]), Z = g(Y)"]


def test_query_solutions_and_a_synchronized_query_name_them_alike():
    """Each way to ask names the variables the query's `_Y` holds after it (an answer
    leaves `_Y` out, not its name) and the clause's after none."""
    kb = slr_sql.open(clock=slr_sql.ManualClock(0))
    kb.load("q(f(Y, Y, Z)).\n")
    goal = "X = g(_Y, Y, _), Y = _, q(Z)"
    expected = ["X = g(_Y,Y,_), Z = f(_A,_A,_)"]
    assert swipl_texts("q(f(Y, Y, Z)).\n", [goal]) == [layout(expected[0])]
    for sql in (True, False):   # (compiled to SQL, a program's facts as its tables)
        kb.sql_enabled = sql
        assert answer_lines(kb.query(goal)) == expected
        assert answer_lines(list(kb.solutions(goal))) == expected
        assert answer_lines(kb.query(goal, wait=True)) == expected


# ---------------------------------------------------------------------------------------------
# compiled SQL and the interpreter, on both backends, against swipl
# ---------------------------------------------------------------------------------------------

EVENT_PROGRAM = """\
k(O, f(Y, Y, Z)) :- seg(O, _)^_.
m(O, g(A, B)) :- seg(O, A)^_.
pairs(O, P, Q) :- seg(O, _)^_, P = Q.
"""
# the same program for swipl: an event p(Args)^T is the fact p(Args, T)
SWI_EVENT_PROGRAM = """\
seg(cup1, desk, 1).
seg(cup2, shelf, 2).
k(O, f(Y, Y, Z)) :- seg(O, _, _).
m(O, g(A, B)) :- seg(O, A, _).
pairs(O, P, Q) :- seg(O, _, _), P = Q.
"""
EVENT_GOALS = [
    "k(cup1, X)",
    "k(cup1, X), Y = 1",
    "k(cup1, f(P, Q, R))",
    "m(cup1, g(P, Q)), X = f(Q)",
    "m(cup2, X), Y = f(Z)",
    "pairs(cup1, X, Y)",
    "k(cup1, f(_, Y, _))",
]


def test_compiled_and_interpreted_answers_name_variables_as_swipl_on_both_backends(backend):
    """`k(cup1, f(P, Q, R))` printed `Q = P` from the compiled SQL and `P = Q` from the
    interpreter (each kept the name of the variable the engine bound the other to); a
    clause's Y and Z were printed under their names from both."""
    theirs = swipl_texts(SWI_EVENT_PROGRAM, EVENT_GOALS)
    with slr_sql.open(backend, clock=slr_sql.ManualClock(0)) as kb:
        kb.load(EVENT_PROGRAM)
        assert kb.add_many(["seg(cup1, desk)^1", "seg(cup2, shelf)^2"]) == []
        for goal, expected in zip(EVENT_GOALS, theirs):
            compiled = try_sql(kb, kb.plans.plan(goal, ()), {}, None)
            assert compiled is not None, f"{goal} is not compiled to SQL"
            kb.sql_enabled = False
            interpreted = kb.query(goal)
            kb.sql_enabled = True
            assert layout(answer_lines(compiled)[0]) == expected, goal
            assert layout(answer_lines(interpreted)[0]) == expected, goal
            assert our_text(kb, goal) == expected, goal


# ---------------------------------------------------------------------------------------------
# small programs whose clauses hold shared and singleton variables, drawn
# ---------------------------------------------------------------------------------------------

CLAUSE_VARIABLES = ["A", "B", "Y", "Z", "_"]     # Y and Z: names queries use too
QUERY_VARIABLES = ["X", "Y", "Z", "W", "_"]
CONSTANTS = ["a", "1"]


def terms(variables: list[str]) -> st.SearchStrategy[str]:
    leaves = st.sampled_from(variables + CONSTANTS)
    return st.recursive(leaves, lambda inner: st.one_of(
        st.tuples(inner, inner).map(lambda ab: f"f({ab[0]}, {ab[1]})"),
        inner.map(lambda a: f"g({a})"),
        st.lists(inner, min_size=1, max_size=3).map(lambda xs: f"[{', '.join(xs)}]"),
        st.tuples(inner, inner).map(lambda ab: f"[{ab[0]}|{ab[1]}]")), max_leaves=4)


@st.composite
def programs_and_goals(draw) -> tuple[str, list[str]]:
    """A fact p/2 or two and a rule r/2 over p, and goals on them (each wrapped in once/1:
    one answer, as swipl's top level reads piped goals)."""
    clause_term = terms(CLAUSE_VARIABLES)
    lines = [f"p({draw(clause_term)}, {draw(clause_term)})."
             for _ in range(draw(st.integers(1, 2)))]
    # (mostly variables where a goal is matched: most goals then have an answer)
    body_term = st.one_of(st.sampled_from(CLAUSE_VARIABLES), clause_term)
    lines.append(f"r({draw(clause_term)}, {draw(clause_term)}) :- "
                 f"p({draw(body_term)}, {draw(body_term)}).")
    query_term = st.one_of(st.sampled_from(QUERY_VARIABLES), st.sampled_from(QUERY_VARIABLES),
                           terms(QUERY_VARIABLES))
    goals = []
    for _ in range(3):
        goal = f"{draw(st.sampled_from(['p', 'r']))}({draw(query_term)}, {draw(query_term)})"
        more = draw(st.sampled_from(["", "Y = _", "Z = 1", "Y = Z", "W = X", "X = f(_, W)"]))
        goals.append(f"once(({goal}{', ' + more if more else ''}))")
    return "\n".join(lines) + "\n", goals


def joined_by_swipl(answer: dict) -> bool:
    """Whether swipl's top level prints this answer otherwise than one binding a variable:
    it joins variables of equal values (`X = Y, Y = a`, docs/semantics.md), and prints a
    cyclic term as itself (`X = f(X)`; answers hold `@(S_1, ...)`, docs/language.md)."""
    ids: dict[int, int] = {}

    def key(value):
        if isinstance(value, Var):
            return ("var", ids.setdefault(id(value), len(ids)))
        if isinstance(value, Struct):
            return (str(value.name), tuple(key(a) for a in value.args))
        if isinstance(value, list):
            return ("list", tuple(key(a) for a in value))
        return (type(value).__name__, value)

    values = [key(v) for v in answer.values()]
    for i, v in enumerate(values):
        same = values.count(v)
        if same > 2 or (same == 2 and v[0] != "var"):
            return True
    return any(isinstance(v, Struct) and str(v.name) == "@" for v in answer.values())


@settings(max_examples=40, deadline=None, suppress_health_check=list(HealthCheck))
@given(programs_and_goals())
@example(("p(f(Y, Y, Z), _).\nr(g(A, B), A) :- p(B, _).\n",
          ["once((p(X, W), Y = 1))", "once((r(X, Y), Z = 1))", "once((p(f(X, Y, _), Z)))"]))
@example(("p([A, B, A|_], B).\nr(A, [B]) :- p(A, B).\n",
          ["once((p(X, Y)))", "once((r(X, Y), Y = Z))", "once((r([_|X], W), X = f(_, W)))"]))
def test_answers_to_goals_on_clauses_with_shared_and_singleton_variables_read_as_swipls(
        program_goals):
    program, goals = program_goals
    kb = slr_sql.open(clock=slr_sql.ManualClock(0))
    kb.load(program)
    answers = [kb.query(goal) for goal in goals]
    theirs = swipl_texts(program, goals)
    for goal, answer, expected in zip(goals, answers, theirs):
        if answer and joined_by_swipl(answer[0]):
            continue
        assert layout(answer_lines(answer)[0]) == expected, (program, goal)


# ---------------------------------------------------------------------------------------------
# the commands that print answers
# ---------------------------------------------------------------------------------------------

PROGRAM = "q(f(Y, Y, Z)).\nr(A, B) :- A = g(B, C, C).\n"
GOALS = ["q(X), Y = 1", "X = f(Y, _), Y = _", "X = f(Z), Y = Z", "r(X, Y)"]


def slr(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "slr_sql", *args], capture_output=True,
                          text=True, env=slr_env(), timeout=120)


def test_slr_query_prints_them_as_swipl_from_a_store_and_from_a_served_one(tmp_path):
    """`slr query DB 'q(X), Y = 1'` printed `X = f(Y,Y,Z), Y = 1`; from `slr serve` (the
    answer as JSON, its variables by name) the same."""
    theirs = swipl_texts(PROGRAM, GOALS)
    db = tmp_path / "robot.db"
    program = tmp_path / "names.slr"
    program.write_text(PROGRAM, encoding="utf-8")
    loaded = slr("load", str(db), str(program))
    assert loaded.returncode == 0, loaded.stderr
    for goal, expected in zip(GOALS, theirs):
        done = slr("query", str(db), goal)
        assert done.returncode == 0, done.stderr
        assert [layout(line) for line in done.stdout.splitlines()] == [expected], goal
    with ServiceProcess(db) as server:
        for goal, expected in zip(GOALS, theirs):
            done = slr("query", server.url, goal)
            assert done.returncode == 0, done.stderr
            assert [layout(line) for line in done.stdout.splitlines()] == [expected], goal
        done = slr("query", server.url, "q(X), Y = 1", "--json")
        assert done.returncode == 0, done.stderr
        (answer,) = [json.loads(line) for line in done.stdout.splitlines()]
        names = [arg["$var"] for arg in answer["X"]["f"]]
        assert names[0] == names[1] != names[2] and not {"Y", "Z"} & set(names), answer


def test_slr_run_prints_them_as_swipl(tmp_path):
    example_file = tmp_path / "names.slr"
    example_file.write_text(PROGRAM + "%% query: q(X), Y = 1\n%% query: X = f(Y, _), Y = _\n"
                            "%% events\n", encoding="utf-8")
    done = slr("run", str(example_file))
    assert done.returncode == 0, done.stderr
    printed = [layout(line) for line in done.stdout.splitlines() if line.startswith("        ")]
    assert printed == swipl_texts(PROGRAM, GOALS[:2])


# ---------------------------------------------------------------------------------------------
# what is printed otherwise than swipl prints it, on purpose (docs/printed_text.md)
# ---------------------------------------------------------------------------------------------

def test_the_differences_docs_printed_text_keeps():
    kb = slr_sql.open(clock=slr_sql.ManualClock(0))
    goals = [
        # answers leave out the query's _-variables, so a variable both A and _B hold is
        # named A, which the answer shows (swipl: X = f(_B, _B), A = _B)
        "X = f(A, _B), _B = A",
        # a query's own variable named as the engine names its own is taken for one of them
        "X = f(_G5)",
    ]
    ours = [our_text(kb, goal) for goal in goals]
    assert ours == ["X = f(A,A)", "X = f(_)"]
    assert swipl_texts("", goals) == ["X = f(_B,_B),A = _B", "X = f(_G5)"]
    assert answer_text({"X": Struct("f", (Var("_G5"),))}) == "X = f(_)"
