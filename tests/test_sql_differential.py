"""Differential test: compiled SQL answers == interpreter answers, in the same order.

Hypothesis generates non-recursive programs (facts, rules with joins, disjunction, negation,
if-then-else, comparisons, arithmetic, prev/next, findall, aggregate_all, temporal rules,
list/compound patterns with unbound parts over stored lists and compounds) and event streams
(ties on end and start times, intervals, mixed value types; goals whose times are integers,
written or bound at run time, which match the stored float times by value), then runs every
generated query twice on the same store: with the SQL compiler (kb.query) and with
``kb.sql_enabled = False`` (the interpreter). The database is derandomized, so a failure
replays the same way everywhere; the generated cases are counted and at least a third must
actually run as SQL (the rest exercise the fallbacks).
"""
from __future__ import annotations

import collections
import re
import shutil
import sqlite3
import subprocess
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st
from strategy_helpers import BOOLEANS, integers, once, sampled

import slr_sql
from slr_sql.errors import SLREvaluationError, SLRError
from slr_sql.planner import plan_for
from slr_sql.terms import Struct, Var

HAVE_SWIPL = shutil.which("swipl") is not None
STATS = collections.Counter()
EVENTS: dict = {}
NEGATED_DISJUNCTIONS: set = set()   # texts of the generated \+ (A ; B), to count their plans

ATOMS = ["x", "y", "z"]
NUMS = ["1", "2", "3", "1.0", "2.5", "0"]
ODD = ['"x"', "[1,2]", "f(x)", "[]", "'[q'", "-1"]
# c/2 events hold lists and compounds; patterns with unbound parts take them apart in SQL.
# V stands for the whole value, E and F for parts; E also meets arithmetic (type errors).
VALUES = ["[x, 1]", '[1.0, "x"]', "[x|y]", "g(x, 1)", "f(-0.0)", "[[1, 2], '[q']",
          "[0.0, x]", "[x, [y|z]]", "[y]", "g([], 2.5)", "x", "[]", "[x, y|z]", '"s"']
PATTERNS = ["[E]", "[E, F]", "[E|F]", "f(E)", "[x|E]", "[_, E]", "[E, E]", "g(E, _)",
            "[[E|_]|F]", "[E, 0.0]", "[E|y]", "[E, [F|_]]", "[E, F|z]", "g(E, F)"]
PVARS = ["V", "E", "F"]
# for V = <pattern>: E only as an element, never in a tail or nested, so two of them
# unified with each other never bind E to a term holding E (no cyclic terms)
V_PATTERNS = ["[E]", "f(E)", "[_, E]", "[E, E]", "g(E, _)", "[E, 0.0]", "[E|y]", "[x, E]"]
TIMES = [0.0, 1.0, 1.5, 2.0, 3.0]
CUTS = ["!", "(true ; !)", "\\+ fail"]

OVARS = ["O", "P"]
NVARS = ["N", "M", "K"]
TVARS = ["T", "S"]


def o_arg(draw):
    return draw(sampled(OVARS + OVARS + ATOMS + ["_"]))


def p_arg(draw):
    return draw(sampled(PATTERNS + PVARS + ["_", "[x|y]", "g(x, 1)", "[]"]))


def n_arg(draw):
    return draw(sampled(NVARS + NVARS + NUMS + ["_"] + ODD[:2]))


def t_arg(draw):
    # integer times match the stored float times by value (``a(..)^2`` finds an event added
    # at 2.0); so do integers bound at run time (S, T from data arguments or arithmetic)
    return draw(sampled(TVARS + ["_", "[S,T]", "[_,T]", "2.0", "1.5", "2", "1",
                                         "[1, T]", "[S, 2]"]))


def num_expr(draw):
    # E (a part of a stored list/compound: often not a number) makes type errors, which
    # the compiled statement must raise even where the result is not used (State.checks)
    a = draw(sampled(NVARS + TVARS + ["1", "2", "0.5", "E"]))
    op = draw(sampled(["", "+ 1", "- 1", "* 2", "/ 2", "// 2", "mod 2", "+ 0.5"]))
    return f"{a} {op}".strip()


def time_expr(draw):
    return draw(sampled(TVARS + ["2", "1.5", "3.0", "inf", "T + 1", "S - 0.5"]))


def goal(depth, rules, trules):
    """A goal of at most ``depth`` nested levels (a strategy built once per distinct
    arguments: tests/strategy_helpers.py)."""
    return once(("goal", depth, tuple(rules), trules), lambda: _goal(depth, list(rules), trules))


@st.composite
def _goal(draw, depth, rules, trules):
    kinds = ["event", "event", "fact", "cmp", "eq", "is", "prev", "next", "pattern"]
    if rules:
        kinds += ["rule", "rule"]
    if trules:
        kinds += ["trule"]
    if depth > 0:
        kinds += ["not", "or", "ite", "findall", "agg", "conj",
                  "not_or", "not_or", "not_ite", "not_not"]
    kind = draw(sampled(kinds))
    if kind == "event":
        name = draw(sampled(["a", "a", "b"]))
        if name == "a":
            return f"a({o_arg(draw)}, {n_arg(draw)})^{t_arg(draw)}"
        return f"b({o_arg(draw)})^{t_arg(draw)}"
    if kind == "pattern":
        form = draw(sampled(["event", "event", "eq", "same"]))
        if form == "event":
            return f"c({o_arg(draw)}, {p_arg(draw)})^{t_arg(draw)}"
        if form == "eq":
            return f"V = {draw(sampled(V_PATTERNS))}"
        return f"{draw(sampled(['E', 'F']))} {draw(sampled(['=', '==']))} " \
               f"{draw(sampled(['E', 'F', 'x', '1', '[y|z]', '0.0']))}"
    if kind == "fact":
        return f"f({o_arg(draw)}, {n_arg(draw)})"
    if kind == "cmp":
        op = draw(sampled(["<", ">", "=<", ">=", "=:=", "=\\="]))
        return f"{num_expr(draw)} {op} {num_expr(draw)}"
    if kind == "eq":
        left = draw(sampled(OVARS + NVARS))
        right = draw(sampled(OVARS + NVARS + ATOMS + NUMS + ODD))
        op = draw(sampled(["=", "=", "\\==", "=="]))
        return f"{left} {op} {right}"
    if kind == "is":
        return f"{draw(sampled(NVARS))} is {num_expr(draw)}"
    if kind == "prev":
        return f"prev(a({o_arg(draw)}, {n_arg(draw)})^{draw(sampled(['_Z', 'T', 'S', '2']))}, " \
               f"{draw(sampled([time_expr(draw), '[' + time_expr(draw) + ', ' + time_expr(draw) + ']']))})"
    if kind == "next":
        return f"next(a({o_arg(draw)}, {n_arg(draw)})^{draw(sampled(['_Z', 'T', 'S', '[1, T]']))}, " \
               f"[{time_expr(draw)}, {time_expr(draw)}])"
    if kind == "rule":
        name, arity = draw(sampled(rules))
        return f"{name}({o_arg(draw)}, {n_arg(draw)})"
    if kind == "trule":
        return f"tr({o_arg(draw)})^{draw(sampled(TVARS + ['2.0', '_', '1']))}"
    sub = lambda: draw(goal(depth - 1, rules, trules))  # noqa: E731
    if kind == "not":
        return f"\\+ ({sub()})"
    if kind == "not_or":   # every branch must fail, not only the first
        text = f"\\+ ({sub()} ; {sub()})"
        NEGATED_DISJUNCTIONS.add(text)
        return text
    if kind == "not_ite":
        return f"\\+ ({sub()} -> {sub()} ; {sub()})"
    if kind == "not_not":
        return draw(sampled([f"\\+ \\+ ({sub()})", f"\\+ ({sub()}, \\+ {sub()})"]))
    if kind == "or":
        return f"({sub()} ; {sub()})"
    if kind == "ite":
        return f"({sub()} -> {sub()} ; {sub()})"
    if kind == "conj":
        return f"({sub()}, {sub()})"
    if kind == "findall":
        templ = draw(sampled(["O", "N", "O-N", "[O,T]", "x", "E"]))
        return f"findall({templ}, ({sub()}), L)"
    spec = draw(sampled(["count", "sum(N)", "max(N)", "min(T)", "bag(O)", "set(N)"]))
    return f"aggregate_all({spec}, ({sub()}), A)"


def body(rules, trules, max_goals=3):
    """A rule's or query's body (a strategy built once per distinct arguments)."""
    return once(("body", tuple(rules), trules, max_goals),
                lambda: _body(list(rules), trules, max_goals))


@st.composite
def _body(draw, rules, trules, max_goals):
    n = draw(integers(0, max_goals - 1))
    first = draw(sampled(["a(O, N)^T", "a(O, N)^[S,T]", "f(O, N)", "b(O)^T, f(O, N)",
                                  "a(O, N)^T, f(P, M)", "c(O, V)^T", "c(O, [E|F])^T",
                                  # a time bound by data (an int, a float, an atom...) at run time
                                  "a(O, N)^N", "f(O, N), b(P)^N", "a(O, N)^[1, M]"]
                                 + [f"{r}(O, N)" for r, _ in rules]))
    return ", ".join([first] + [draw(goal(2, rules, trules)) for _ in range(n)])


@st.composite
def program(draw):
    lines = []
    nfacts = draw(integers(0, 7))
    for _ in range(nfacts):
        lines.append(f"f({draw(sampled(ATOMS))}, {draw(sampled(NUMS + ODD[:2]))}).")
    rules = []
    for i in range(draw(integers(0, 3))):
        name = f"r{i}"
        for _ in range(draw(integers(1, 2))):
            head = f"{name}({draw(sampled(OVARS + ATOMS))}, {draw(sampled(NVARS + NUMS[:2]))})"
            lines.append(f"{head} :- {draw(body(rules, False, 2))}.")
        rules.append((name, 2))
    trules = draw(BOOLEANS)
    if trules:
        lines.append(f"tr(O)^T :- {draw(body(rules, False, 2))}.")
    events = []
    for _ in range(draw(integers(0, 11))):
        s = draw(sampled(TIMES))
        e = draw(sampled([s, s, s + 0.5, s + 1.0]))
        stamp = f"{s}" if s == e else f"[{s},{e}]"
        if draw(integers(0, 3)) == 0:
            events.append(f"c({draw(sampled(ATOMS))}, "
                          f"{draw(sampled(VALUES))})^{stamp}")
        elif draw(BOOLEANS):
            events.append(f"a({draw(sampled(ATOMS))}, "
                          f"{draw(sampled(NUMS + ODD))})^{stamp}")
        else:
            events.append(f"b({draw(sampled(ATOMS + ODD[:1]))})^{stamp}")
    if draw(BOOLEANS):
        events.append("tr(x)^1.0")
    queries = [draw(body(rules, trules)) for _ in range(2)]
    if rules and draw(BOOLEANS):
        # a cut keeps the query itself in the interpreter, which then calls the rules it
        # reaches through SQL (planner.CompiledCall): those answers must be the same too
        rule = draw(sampled([r for r, _ in rules]))
        cut = draw(sampled(CUTS))
        queries[1] = f"{rule}(O, N), {queries[1]}, {cut}"

    at = draw(sampled([None, None, 1.5, 2.0]))
    return "\n".join(lines), events, queries, at


def normalize(answers):
    """Answers as comparable data; unbound variables by their sharing within one answer."""
    names: dict = {}

    def norm(v):
        if isinstance(v, Var):
            return ("var", names.setdefault(id(v), len(names)))
        if isinstance(v, Struct):
            return ("struct", str(v.name), tuple(norm(a) for a in v.args))
        if isinstance(v, list):
            return ("list", tuple(norm(a) for a in v))
        return (type(v).__name__, v)

    out = []
    for a in answers:
        names.clear()
        out.append(sorted((k, norm(v)) for k, v in sorted(a.items())))
    return out


def run(kb, goal, at, sql):
    kb.sql_enabled = sql
    try:
        return ("ok", normalize(kb.query(goal, at=at)))
    except SLRError as exc:
        return ("error", type(exc).__name__, str(exc).split("\n")[0][:200])
    finally:
        kb.sql_enabled = True


# what a compiled statement may raise when it runs: an slr_ function (arithmetic, a builtin,
# a Python predicate) meeting what the interpreter would reject hands over to it; anything
# else (no such column, a syntax error, a misuse of an aggregate) is a compiler bug that the
# silent fallback to the interpreter would hide from the comparison of answers
HANDOVER = ("user-defined function raised exception",)


def run_time_handover(kb, entry, at) -> None:
    try:
        entry.run(kb, {}, at, None)
    except sqlite3.DatabaseError as exc:
        STATS["handed over at run time"] += 1
        assert any(h in str(exc) for h in HANDOVER), f"{type(exc).__name__}: {exc}"
    except SLRError:
        pass


def check(prog):
    text, events, queries, at = prog
    # the events' times are small numbers, not the wall clock's: a ManualClock (the queries
    # are unsynchronized, so where it stands changes no answer)
    kb = slr_sql.open(clock=slr_sql.ManualClock(0.0))
    try:
        kb.load(text)
    except SLRError:
        STATS["bad program"] += 1
        return
    parsed = []
    for text_event in events:  # the same few event texts recur: parse each once
        ev = EVENTS.get(text_event)
        if ev is None:
            ev = EVENTS[text_event] = kb._event_from_text(text_event)
        parsed.append(ev)
    assert kb.add_many(parsed) == []
    calls = kb.engine.sql_calls
    for q in queries:
        STATS["queries"] += 1
        try:
            plan = kb.plans.plan(q, ())
        except SLRError:
            STATS["bad query"] += 1
            continue
        entry = plan_for(kb, plan, at is not None)
        compiled = not hasattr(entry, "reason")
        interp = run(kb, q, at, False)
        sql = run(kb, q, at, True)
        if compiled:
            run_time_handover(kb, entry, at)
            STATS["compiled"] += 1
            if any(t in q for t in NEGATED_DISJUNCTIONS):
                STATS["compiled negated disjunction"] += 1
            if interp[0] == "error":
                STATS["interpreter error"] += 1
                # the same error: the plan's guards evaluate every goal that may raise on
                # the rows Prolog reaches it with (docs/sql.md "Errors in Prolog's order")
            if interp[0] == "ok" and interp[1]:
                STATS["compiled with answers"] += 1
        else:
            STATS["fallback"] += 1
            STATS["fallback: " + " ".join(entry.reason.split(" ")[:3])] += 1
        assert sql == interp, (f"\nprogram:\n{text}\nevents: {events}\n?- {q}  at={at}\n"
                               f"sql: {sql}\ninterpreter: {interp}\n{kb.explain(q)}")
    STATS["sub-goals answered by SQL"] += sum(c.answered for c in calls.values())
    kb.close()


# a longer hunt: SLR_DIFF_EXAMPLES=5000 with HYPOTHESIS_PROFILE=explore for fresh examples
# (derandomized by the suite's ci profile, not here, so that the explore profile draws anew)
EXAMPLES = int(__import__("os").environ.get("SLR_DIFF_EXAMPLES", "1000"))


@settings(max_examples=EXAMPLES, deadline=None,
          suppress_health_check=list(HealthCheck))
@given(program())
def _sql_equals_interpreter(prog):
    check(prog)


def test_sql_equals_interpreter():
    """SQL == interpreter over generated programs, and the sample is a real one: a third of
    the queries compile, compiled rules answer sub-goals of interpreted ones, and negated
    disjunctions compile (the statistics are this run's own, whichever worker runs it)."""
    STATS.clear()
    _sql_equals_interpreter()
    assert STATS["queries"] >= EXAMPLES, dict(STATS)
    assert STATS["compiled"] >= STATS["queries"] // 3, dict(STATS)
    if EXAMPLES >= 1000:   # the default sample; a developer's smaller run checks the share only
        # interpreter runs calling compiled rules: a real share of the cases
        assert STATS["sub-goals answered by SQL"] >= 100, dict(STATS)
        assert STATS["compiled negated disjunction"] >= 20, dict(STATS)


# -- the two boundaries the generator reaches only by chance: prev at exactly an event's end
# (end <= T, not <), and a negated disjunction whose first branch fails (every branch counts)

@pytest.mark.parametrize("sql", [True, False])
@pytest.mark.parametrize("goal, expected", [
    ("prev(a(O, N)^T, 2)", [{"O": "y", "N": 2, "T": 2.0}]),
    ("prev(a(O, N)^T, 2.0)", [{"O": "y", "N": 2, "T": 2.0}]),
    ("prev(a(O, N)^T, 1.5)", [{"O": "x", "N": 1, "T": 1.0}]),
    ("prev(a(x, N)^T, 2)", [{"N": 1, "T": 1.0}]),
    ("prev(a(O, N)^T, [1, 2])", [{"O": "y", "N": 2, "T": 2.0}]),
    ("T0 = 2, prev(a(O, N)^T, T0)", [{"T0": 2, "O": "y", "N": 2, "T": 2.0}]),
    ("b(P)^T0, prev(a(O, N)^T, T0)", [{"P": "z", "T0": 2.0, "O": "y", "N": 2, "T": 2.0}]),
    ("next(a(O, N)^T, [2, 3])", [{"O": "y", "N": 2, "T": 2.0}]),
])
def test_prev_at_exactly_an_events_end_finds_it(sql, goal, expected):
    with slr_sql.open(clock=slr_sql.ManualClock(10.0)) as kb:
        kb.add_many(["a(x, 1)^1.0", "a(y, 2)^2.0", "a(z, 3)^3.0", "b(z)^2.0"])
        kb.sql_enabled = sql
        assert kb.query(goal) == expected


@pytest.mark.parametrize("goal, expected", [
    ("f(O), \\+ (a(O, _)^_ ; b(O)^_)", ["x"]),
    ("f(O), \\+ (fail ; b(O)^_)", ["x", "w"]),
    ("f(O), \\+ (a(O, 9)^_ ; g(O))", ["x", "w"]),
    ("f(O), \\+ ((a(O, _)^_, fail) ; (b(O)^_ ; g(O)))", ["x", "w"]),
    ("f(O), \\+ (a(O, _)^_ ; \\+ g(O))", ["y"]),
])
def test_a_compiled_negated_disjunction_checks_every_branch(goal, expected):
    with slr_sql.open(clock=slr_sql.ManualClock(10.0)) as kb:
        kb.load("f(x). f(y). f(w). g(y).")
        kb.add_many(["a(w, 1)^1", "b(y)^2"])
        entry = plan_for(kb, kb.plans.plan(goal, ()), False)
        assert not hasattr(entry, "reason"), kb.explain(goal)   # runs as one SQL statement
        assert kb.query(goal) == [{"O": o} for o in expected]
        kb.sql_enabled = False
        assert kb.query(goal) == [{"O": o} for o in expected]


def test_an_event_time_taken_from_a_stored_list_is_an_interval():
    """``b(P)^N`` with N from a fact: N = [1, 2] makes it the interval goal ``b(P)^[1, 2]`` in
    the interpreter, and SQL must not compare the list with a time (found by the generator)."""
    facts = "f(x, 1).\n" * 6 + "f(x, [1,2]).\nf(y, [1.0,2.0])."   # enough for a fact table
    check((facts, ["b(x)^[1.0,2.0]", "b(z)^1"],
           ["f(O, N), b(P)^N", "f(O, N), prev(b(P)^N, 5)", "f(O, N), next(b(P)^N, [0, 5])"],
           None))



# -- a time known only at run time may be a list [S, E]: the goal is then an interval goal.
# Its stamp is read when the goal is reached (as call/1 reads a goal term), whether the time
# comes straight from a stored column, from a part of a stored compound, or from a query
# parameter; SQL checks both readings (a number: a point, [S, E]: an interval) in one
# statement. SWI-Prolog is the oracle for the plain event goals: the stored events are
# facts in store order and an event goal reads its stamp when called (STAMP_MODEL).

STAMP_PROGRAM = ("f(z, g(3)).\n" * 6     # enough rows for a fact table
                 + "f(x, g(1)). f(x, g([1,2])). f(y, g([1.0,2.0])). f(w, g([1,x])).\n"
                 + "f(v, g(x)). f(u, g([2])).\n"
                 + "k(z, 3).\n" * 6 + "k(x, 1). k(x, [1,2]). k(y, [2]).\n"
                 + "pos(E^T, T) :- E^T.\n")
STAMP_EVENTS = ["b(x)^[1.0,2.0]", "b(z)^1", "b(q)^[1,1]", "b(r)^2"]
# the SWI-Prolog side: b/3 holds the stored events (times matched by value, docs/semantics.md
# "Stored times match by value"), '$stamp'/3 splits a stamp the way a reached goal is read
STAMP_MODEL = """
b_stored(z, 1.0, 1.0). b_stored(q, 1.0, 1.0). b_stored(x, 1.0, 2.0). b_stored(r, 2.0, 2.0).
'$tm'(T, T0) :- var(T), !, T = T0.
'$tm'(T, T0) :- number(T), T =:= T0.
b(P, S, E) :- b_stored(P, S0, E0), '$tm'(S, S0), '$tm'(E, E0).
'$stamp'(T, S, E) :- nonvar(T), T = [S0|R], nonvar(R), R = [E0|R2], R2 == [], !,
    S = S0, E = E0.
'$stamp'(T, T, T).
'$event'(b(P), T) :- '$stamp'(T, S, E), b(P, S, E).
pos(E^T, T) :- '$event'(E, T).
"""
ONE_G1 = [{"O": "x", "N": 1, "P": "z"}, {"O": "x", "N": 1, "P": "q"}]
LISTS = [{"O": "x", "N": [1, 2], "P": "x"}, {"O": "y", "N": [1.0, 2.0], "P": "x"}]


def _canonical(v) -> str:
    """A value of an answer as SWI-Prolog's write_canonical/1 prints it (simple atoms)."""
    if type(v) is list:
        return "[" + ",".join(_canonical(x) for x in v) + "]"
    return repr(v) if type(v) is float else str(v)


def swipl_rows(goal: str, names: list[str]) -> list[str]:
    """The rows of ``goal`` over STAMP_PROGRAM's facts and STAMP_MODEL in SWI-Prolog, each
    the list of ``names``' values as write_canonical/1 prints it."""
    facts = "\n".join(line for line in STAMP_PROGRAM.splitlines() if not line.startswith("pos("))
    program = (":- style_check(-singleton).\n" + facts + "\n" + STAMP_MODEL
               + f"main :- forall(({goal}), (write_canonical([{', '.join(names)}]), nl)).\n")
    with tempfile.TemporaryDirectory(prefix="slr_stamp_") as d:
        path = Path(d) / "stamps.pl"
        path.write_text(program)
        out = subprocess.run(["swipl", "-q", "-g", "main", "-t", "halt", str(path)],
                             capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    return out.stdout.splitlines()


@pytest.mark.parametrize("goal, args, swi_goal, expected", [
    # a part of a stored compound (the narrower case: it stayed compiled and disagreed)
    ("f(O, g(N)), b(P)^N", {}, "f(O, g(N)), '$event'(b(P), N)", ONE_G1 + LISTS),
    # a stored column
    ("k(O, N), b(P)^N", {}, "k(O, N), '$event'(b(P), N)", ONE_G1 + LISTS[:1]),
    # a query parameter taken apart by a rule head (position/2-style rules)
    ("pos(b(P)^T, W)", {"T": [1, 2]}, "T = [1, 2], pos(b(P)^T, W)",
     [{"P": "x", "T": [1, 2], "W": [1, 2]}]),
    ("pos(b(P)^T, W)", {"T": 1}, "T = 1, pos(b(P)^T, W)",
     [{"P": "z", "T": 1, "W": 1}, {"P": "q", "T": 1, "W": 1}]),
    # prev and next read their pattern's stamp the same way
    ("f(O, g(N)), prev(b(P)^N, 5)", {}, None, ONE_G1 + LISTS),
    ("f(O, g(N)), next(b(P)^N, [0, 5])", {}, None, ONE_G1 + LISTS),
    ("k(O, N), prev(b(P)^N, [0, 5])", {}, None, ONE_G1 + LISTS[:1]),
])
def test_an_event_time_that_is_a_list_at_run_time_is_an_interval(goal, args, swi_goal,
                                                                   expected):
    with slr_sql.open(clock=slr_sql.ManualClock(10.0)) as kb:
        kb.load(STAMP_PROGRAM)
        kb.add_many(STAMP_EVENTS)
        entry = plan_for(kb, kb.plans.plan(goal, tuple(args)), False)
        assert not hasattr(entry, "reason"), kb.explain(goal)   # one SQL statement
        sql = kb.query(goal, args=args)
        kb.sql_enabled = False
        assert kb.query(goal, args=args) == sql == expected
    if swi_goal is not None:
        assert HAVE_SWIPL, "SWI-Prolog is the reference: install swi-prolog (.ci/run does)"
        names = list(expected[0])
        assert swipl_rows(swi_goal, names) == [
            "[" + ",".join(_canonical(a[n]) for n in names) + "]" for a in expected]


# -- boundaries that mutation testing (mutation/, docs/testing.md) showed no test asked
# about: each goal compiles to one statement, and SQL, the interpreter and the expected
# answers (Prolog's) agree.

BOUNDARY_PROGRAM = "f(1). f(2).\n" * 4
BOUNDARY_EVENTS = ["a(x)^1", "b(y)^1", "c(big)^9007199254740992"]


@pytest.mark.parametrize("goal, expected", [
    # a stored time (float) and a count (integer) of equal value do not unify: 1.0 \= 1
    ("a(x)^T, aggregate_all(count, b(_)^_, N), T = N", []),
    ("a(x)^T, aggregate_all(count, b(_)^_, N), N = T", []),
    ("a(x)^T, aggregate_all(count, b(_)^_, N), T \\= N", [{"T": 1.0, "N": 1}]),
    ("a(x)^T, aggregate_all(count, b(_)^_, N), T =:= N", [{"T": 1.0, "N": 1}]),
    ("b(y)^T, a(x)^S, T = S", [{"T": 1.0, "S": 1.0}]),
    # max/min of nothing fail, the sum of nothing is 0 (a goal that fails when compiled)
    ("aggregate_all(max(X), fail, M)", []),
    ("aggregate_all(min(X), (f(X), fail), M)", []),
    ("f(A), aggregate_all(max(X), (X = A, fail), M)", []),
    ("aggregate_all(sum(X), fail, M)", [{"M": 0}]),
    # a unary minus or another operator is no witness (only X-W is): these compile
    ("aggregate_all(max(-X), f(X), M)", [{"M": -1}]),
    ("aggregate_all(max(X+1), f(X), M)", [{"M": 3}]),
    ("aggregate_all(min(X*2), f(X), M)", [{"M": 2}]),
    # call/1 and call/N: the extra arguments are appended, none for call/1
    ("f(A), call(true)", [{"A": 1}, {"A": 2}] * 4),
    ("call(f, A)", [{"A": 1}, {"A": 2}] * 4),
    ("call(f(A))", [{"A": 1}, {"A": 2}] * 4),
    ("f(A), call(=, A, B)", [{"A": 1, "B": 1}, {"A": 2, "B": 2}] * 4),
    # a \= with a variable of its own is decided by the statement (nothing is bound)
    ("f(A), A \\= g(_)", [{"A": 1}, {"A": 2}] * 4),
    ("f(A), g(B) \\= A, B = 1", [{"A": 1, "B": 1}, {"A": 2, "B": 1}] * 4),
    # findAll/3 (the paper's spelling) and a list template compile like findall/3
    ("findAll(X, f(X), L)", [{"L": [1, 2] * 4}]),
    ("findall([A, x], (f(A), A > 1), L)", [{"L": [[2, "x"]] * 4}]),
    # a disjunction whose right side is an if-then-else
    ("f(A), (A = 3 ; (A = 1 -> X = one ; X = other))",
     [{"A": 1, "X": "one"}, {"A": 2, "X": "other"}] * 4),
    # an integer no float equals matches no stored time (2**53 + 1 is not 2.0**53)
    ("c(X)^9007199254740993", []),
    ("c(X)^9007199254740992", [{"X": "big"}]),
    # a count (an integer column) equals an integer constant
    ("aggregate_all(count, f(_), N), N = 8", [{"N": 8}]),
    ("aggregate_all(count, f(_), N), N = 8.0", []),
])
def test_compiled_boundaries_agree_with_the_interpreter(goal, expected):
    with slr_sql.open(clock=slr_sql.ManualClock(10.0)) as kb:
        kb.load(BOUNDARY_PROGRAM)
        kb.add_many(BOUNDARY_EVENTS)
        entry = plan_for(kb, kb.plans.plan(goal, ()), False)
        assert not hasattr(entry, "reason"), kb.explain(goal)   # one SQL statement
        assert entry.run(kb, {}, None, None) == expected         # no hand-over at run time
        assert kb.query(goal) == expected
        kb.sql_enabled = False
        assert kb.query(goal) == expected


@pytest.mark.parametrize("goal", [
    "((fail ; a(O)^T) -> X = O ; X = none)",
    "g(_), ((fail ; a(O)^T) -> X = O ; X = none)",
    "g(_), ((a(O)^T ; fail) -> X = O ; X = none)",
    "g(_), ((fail ; fail ; a(O)^T) -> X = O ; X = none)",
])
def test_an_if_then_else_condition_in_a_branch_takes_its_first_solution_in_store_order(goal):
    """The condition's first solution is the first in store order (end time first), also
    when the condition is one branch of a disjunction: the branch's index is no ORDER BY
    column (it ordered by arrival, or was invalid SQL that the interpreter then answered;
    found by asserting that compiled statements run, ``run_time_handover``)."""
    with slr_sql.open(clock=slr_sql.ManualClock(10.0)) as kb:
        kb.load("g(1).")
        kb.add_many(["a(x)^5", "a(y)^2"])    # arrival order is not time order
        entry = plan_for(kb, kb.plans.plan(goal, ()), False)
        assert entry.run(kb, {}, None, None) == [{"O": "y", "T": 2.0, "X": "y"}]
        assert kb.query(goal) == [{"O": "y", "T": 2.0, "X": "y"}]
        kb.sql_enabled = False
        assert kb.query(goal) == [{"O": "y", "T": 2.0, "X": "y"}]


@pytest.mark.parametrize("goal, shown", [
    ("prev(a(X)^T, [2])", "[2]"),
    ("f(A), prev(a(X)^T, [2, 3, 4])", "[2,3,4]"),
    ("next(a(X)^T, [0])", "[0]"),
])
def test_an_interval_of_another_length_is_a_type_error(goal, shown):
    with slr_sql.open(clock=slr_sql.ManualClock(10.0)) as kb:
        kb.load(BOUNDARY_PROGRAM)
        kb.add_many(BOUNDARY_EVENTS)
        for sql in (True, False):
            kb.sql_enabled = sql
            with pytest.raises(SLREvaluationError, match=re.escape(f"type_error(interval,{shown})")):
                kb.query(goal)
