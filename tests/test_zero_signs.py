"""-0.0 and 0.0 in stored events, on SQLite and PostgreSQL, against SWI-Prolog.

SWI-Prolog tells the floats -0.0 and 0.0 apart as terms (``-0.0 = 0.0`` fails, ``-0.0 @<
0.0``) and not as numbers (``-0.0 =:= 0.0``); docs/semantics.md, "Terms". SQLite's ``=``
and grouping take one for the other; PostgreSQL keeps the values as text ('-0.0' and
'0.0' differ). Each example runs on a SQLite file and a PostgreSQL schema, through the
compiled SQL and through the interpreter, and must give SWI-Prolog's answers in the same
order (tests/test_swi_prev_next.py's comparison); the goals on plain terms are in
tests/test_swi_builtins.py.
"""
from __future__ import annotations

import itertools
import math

import pytest
import test_swi_prev_next as swipn

import slr_sql
from slr_sql import ManualClock

# arguments of both signs and kinds: a key (p's first, q's only argument) and a value
EVENTS = [("p", ("a", "0.0"), 1.0, 1.0), ("p", ("a", "-0.0"), 2.0, 2.0),
          ("p", ("a", "0.0"), 3.0, 3.0), ("p", ("a", "0"), 3.5, 3.5),
          ("p", ("-0.0", "1"), 1.5, 1.5), ("p", ("0.0", "1"), 2.5, 2.5),
          ("p", ("-0.0", "-0.0"), 4.0, 4.0), ("q", ("-0.0",), 1.0, 1.0),
          ("q", ("0.0",), 2.0, 2.0), ("q", ("0",), 2.0, 2.0)]

RULES = ("h(K)^T :- prev(q(K)^Z, T), p(K, V)^_.\n",
         "h(K, T, T) :- prev_q(K, Z, Z, T), p(K, V, _, _).\n")
PLAIN = ("g(K, T) :- prev(p(K, -0.0)^Z, T).\n", "g(K, T) :- prev_p(K, -0.0, Z, Z, T).\n")


def query(slr: str, swi: str | None = None, at: str | None = None) -> tuple:
    return (slr, swi if swi is not None else slr, at)


def ev(slr: str) -> tuple:
    """An event goal query ``p(..)^Z`` (SWI-Prolog: ``p(.., Z, Z)``)."""
    name, rest = slr.split("(", 1)
    args, stamp = rest.rsplit(")^", 1)
    return query(slr, f"{name}({args}, {stamp}, {stamp})")


QUERIES = {
    "event goals": [ev("p(a, -0.0)^T"), ev("p(a, 0.0)^T"), ev("p(K, -0.0)^T"),
                    ev("p(-0.0, V)^T"), ev("p(0.0, V)^T"), ev("q(-0.0)^T"), ev("q(0.0)^T")],
    "prev and next": [
        query("prev(p(a, -0.0)^Z, 3)", "prev_p(a, -0.0, Z, Z, 3)"),
        query("prev(p(a, 0.0)^Z, 2.5)", "prev_p(a, 0.0, Z, Z, 2.5)"),
        query("prev(p(-0.0, V)^Z, 3)", "prev_p(-0.0, V, Z, Z, 3)"),
        query("prev(q(0.0)^Z, inf)", "prev_q(0.0, Z, Z, inf)"),
        query("next(p(a, -0.0)^Z, [0, inf])", "next_p(a, -0.0, Z, Z, 0, inf)"),
        query("next(p(a, 0.0)^Z, 1.5, inf)", "next_p(a, 0.0, Z, Z, 1.5, inf)"),
        query("next(p(0.0, V)^Z, [0, inf])", "next_p(0.0, V, Z, Z, 0, inf)")],
    "joins": [
        query("q(K)^Z, p(K, V)^Y", "q(K, Z, Z), p(K, V, Y, Y)"),
        query("p(K, V)^Y, q(V)^Z", "p(K, V, Y, Y), q(V, Z, Z)"),
        query("p(a, V)^Y, p(K, W)^Z, V = W", "p(a, V, Y, Y), p(K, W, Z, Z), V = W"),
        query("p(a, V)^Y, p(K, W)^Z, V == W", "p(a, V, Y, Y), p(K, W, Z, Z), V == W"),
        query("q(K)^Z, \\+ p(K, _)^_", "q(K, Z, Z), \\+ p(K, _, _, _)"),
        query("p(a, V)^Y, X is V * -1, q(X)^Z", "p(a, V, Y, Y), X is V * -1, q(X, Z, Z)")],
    "tests and collections": [
        query("p(a, V)^Y, V == -0.0", "p(a, V, Y, Y), V == -0.0"),
        query("p(a, V)^Y, V = 0.0", "p(a, V, Y, Y), V = 0.0"),
        query("p(a, V)^Y, V =:= 0", "p(a, V, Y, Y), V =:= 0"),
        query("p(a, V)^Y, V @< 0.0", "p(a, V, Y, Y), V @< 0.0"),
        query("findall(V, p(a, V)^_, L), sort(L, S), msort(L, M)",
              "findall(V, p(a, V, _, _), L), sort(L, S), msort(L, M)"),
        query("findall(K, q(K)^_, L), sort(0, @>=, L, S)",
              "findall(K, q(K, _, _), L), sort(0, @>=, L, S)"),
        query("setof(V-Z, p(a, V)^Z, L)", "setof(V-Z, p(a, V, Z, Z), L)"),
        query("bagof(Z, p(K, V)^Z, L)", "bagof(Z, p(K, V, Z, Z), L)"),
        query("aggregate_all(count, p(a, -0.0)^_, N)", "aggregate_all(count, p(a, -0.0, _, _), N)"),
        query("aggregate_all(set(K), q(K)^_, S)", "aggregate_all(set(K), q(K, _, _), S)"),
        query("p(a, V)^Y, member(V, [-0.0])", "p(a, V, Y, Y), member(V, [-0.0])"),
        query("p(K, V)^Y, member(K-V, [0.0-1, a-(-0.0)])",
              "p(K, V, Y, Y), member(K-V, [0.0-1, a-(-0.0)])"),
        query("q(K)^Y, memberchk(K, [0.0, x])", "q(K, Y, Y), memberchk(K, [0.0, x])"),
        query("q(K)^Y, K \\== 0.0", "q(K, Y, Y), K \\== 0.0"),
        query("q(K)^Y, K \\= -0.0", "q(K, Y, Y), K \\= -0.0"),
        query("q(K)^Y, compare(O, K, 0.0)", "q(K, Y, Y), compare(O, K, 0.0)"),
        query("p(a, V)^Y, L = [V], L = [0.0]", "p(a, V, Y, Y), L = [V], L = [0.0]")],
    "rules": [query("h(K)^T", "h(K, T, T)"), query("h(-0.0)^3", "h(-0.0, 3, 3)"),
              query("h(0.0)^3", "h(0.0, 3, 3)"), query("g(K, 5)"), query("g(-0.0, 5)"),
              query("findall(K-T, h(K)^T, L)", "findall(K-T, h(K, T, T), L)")],
}

_SCHEMAS = itertools.count()


@pytest.fixture(scope="module")
def database(postgres_server):
    """One database for the module's examples, a schema each."""
    from conftest import postgres_database
    return postgres_database(postgres_server[1])


@pytest.fixture(scope="module")
def swipl():
    with swipn.swidiff.live_swipl() as s:
        yield s


@pytest.mark.parametrize("group", sorted(QUERIES))
def test_zero_signs_answer_as_swipl_on_both_backends(swipl, database, group):
    url = database + ("&" if "?" in database else "?") + f"schema=zs{next(_SCHEMAS)}"
    example = (RULES[0] + PLAIN[0], RULES[1] + PLAIN[1], EVENTS, list(range(len(EVENTS))),
               [4], [], QUERIES[group])
    swipn.compare(swipl, example, url)


# goals with arguments bound from Python (kb.query(goal, args=...)): a single prev takes the
# bound lookup, whose SQL finds the other zero first on SQLite
BOUND = [("prev(p(K, V)^Z, T)", {"K": -0.0, "T": 10.0}), ("prev(p(K, V)^Z, T)", {"K": 0.0, "T": 10.0}),
         ("prev(p(K, V)^Z, T)", {"K": "a", "V": -0.0, "T": 10.0}),
         ("prev(p(K, V)^Z, T)", {"K": "a", "V": 0.0, "T": 10.0}),
         ("prev(p(a, V)^Z, T)", {"V": -0.0, "T": 3.0}), ("p(K, V)^Z", {"K": -0.0}),
         ("h(K)^T", {"K": 0.0, "T": 3.0}), ("next(p(K, V)^Z, [0, inf])", {"K": "a", "V": -0.0})]


def _swi_goal(goal: str, args: dict) -> str:
    """The SWI-Prolog query of ``goal`` with ``args`` bound first (event goals and prev/next
    as tests/test_swi_prev_next.py writes them)."""
    texts = {"prev(p(K, V)^Z, T)": "prev_p(K, V, Z, Z, T)", "prev(p(a, V)^Z, T)":
             "prev_p(a, V, Z, Z, T)", "p(K, V)^Z": "p(K, V, Z, Z)", "h(K)^T": "h(K, T, T)",
             "next(p(K, V)^Z, [0, inf])": "next_p(K, V, Z, Z, 0, inf)"}
    binds = [f"{name} = {value!r}" if type(value) is float else f"{name} = {value}"
             for name, value in args.items()]
    return ", ".join(binds + [texts[goal]])


@pytest.mark.parametrize("place", ["sqlite", "postgres"])
def test_arguments_bound_from_python_match_their_own_zero(swipl, database, place, tmp_path):
    where = str(tmp_path / "s.db") if place == "sqlite" else \
        database + ("&" if "?" in database else "?") + f"schema=zs{next(_SCHEMAS)}"
    with swipn.fill(where, RULES[0], EVENTS, list(range(len(EVENTS))), [], []) as kb:
        queries = [(goal, _swi_goal(goal, args), None) for goal, args in BOUND]
        swi = swipl.run(swipn.swi_program(RULES[1], swipn.stored_facts(kb), queries))
        for qi, (goal, args) in enumerate(BOUND):
            names = list(dict.fromkeys(swipn.swidiff.var_names(goal) + list(args)))
            want = swipn.expected(swi[qi], names)
            for options in ({}, {"max_steps": swipn.swidiff.SLR_MAX_STEPS}):
                got = [swipn.swidiff.slr_answer(a, names)
                       for a in kb.query(goal, args=args, **options)]
                assert ("answers", got) == want, (goal, args, options)


# event rules: a join on a variable, a constant pattern argument, both zeros of each
CEP_EVENTS = [("a", (-0.0,), 1.0, 1.0), ("a", (0.0,), 2.0, 2.0), ("b", (0.0,), 3.0, 3.0),
              ("b", (-0.0,), 4.0, 4.0), ("a", (0,), 4.5, 4.5), ("b", (0,), 5.0, 5.0)]
CEP_RULES = [
    ("seq", ("leaf", "a", ("X",)), ("leaf", "b", ("X",))),
    ("seq", ("leaf", "a", (-0.0,)), ("leaf", "b", ("Y",))),
    ("and", ("leaf", "b", (-0.0,)), ("leaf", "a", ("X",))),
]


@pytest.mark.parametrize("place", ["sqlite", "postgres"])
@pytest.mark.parametrize("policy", ["unrestricted", "recent", "chronological"])
@pytest.mark.parametrize("pattern", CEP_RULES, ids=["join", "constant", "and"])
def test_event_rules_tell_the_zeros_apart_as_the_reference(database, place, policy, pattern):
    import test_cep_differential as cepdiff

    rule = {"pattern": pattern, "head": sorted(cepdiff._vars(pattern)), "where": [],
            "cnot": None, "within": None, "policy": policy}
    expected = [(tuple(h), s, e) for h, s, e in cepdiff.reference(rule, CEP_EVENTS)]
    for order in (list(range(len(CEP_EVENTS))), list(reversed(range(len(CEP_EVENTS))))):
        where = None if place == "sqlite" else \
            database + ("&" if "?" in database else "?") + f"schema=zs{next(_SCHEMAS)}"
        got = cepdiff.run(rule, CEP_EVENTS, order, [], False, False, where=where)
        assert sorted(cepdiff._typed(got)) == sorted(cepdiff._typed(expected)), \
            (cepdiff.rule_text(rule), order)



# events of one time told apart by their zeros alone: which is the newest (recent) or the
# oldest (chronological), and which terminator goes first, is the order of the values (-0.0
# before 0.0, Prolog's standard order), never the order they arrived in
TIED_EVENTS = [("a", (-0.0,), 1.0, 1.0), ("a", (0.0,), 1.0, 1.0), ("a", (1,), 0.0, 0.0),
               ("b", (0.0,), 2.0, 2.0), ("b", (-0.0,), 2.0, 2.0)]


@pytest.mark.parametrize("place", ["sqlite", "postgres"])
@pytest.mark.parametrize("policy", ["recent", "chronological"])
def test_events_of_one_time_and_zeros_of_two_signs_are_chosen_in_any_arrival_order(
        database, place, policy):
    import test_cep_differential as cepdiff

    pattern = ("seq", ("leaf", "a", ("X",)), ("leaf", "b", ("Y",)))
    rule = {"pattern": pattern, "head": ["X", "Y"], "where": [], "cnot": None,
            "within": None, "policy": policy}
    expected = {"recent": [((0.0, -0.0), 1.0, 2.0), ((0.0, 0.0), 1.0, 2.0)],
                "chronological": [((1, -0.0), 0.0, 2.0), ((-0.0, 0.0), 1.0, 2.0)]}[policy]
    assert cepdiff._typed(cepdiff.reference(rule, TIED_EVENTS)) == \
        sorted(cepdiff._typed(expected))
    # (the a's first or last; a(0.0) before a(-0.0) and b(0.0) before b(-0.0), or after)
    for order in ([1, 0, 2, 3, 4], [0, 1, 2, 4, 3], [4, 3, 2, 1, 0], [3, 4, 0, 2, 1]):
        where = None if place == "sqlite" else \
            database + ("&" if "?" in database else "?") + f"schema=zt{next(_SCHEMAS)}"
        got = cepdiff.run(rule, TIED_EVENTS, order, [], False, False, where=where)
        assert sorted(cepdiff._typed(got)) == sorted(cepdiff._typed(expected)), order


# facts and rules of a program (no events): clause indexing, the facts' SQL tables, joins
PROGRAM = """f(0.0, a).
f(-0.0, b).
f(0, c).
f(X, d) :- X = -0.0.
g(-0.0).
g(0.0).
g(0.0).
same(X) :- f(X, _), g(X).
"""
PROGRAM_GOALS = ["f(-0.0, Y)", "f(0.0, Y)", "f(X, Y), g(X)", "same(X)", "g(X), f(X, Y)",
                 "setof(X-Y, f(X, Y), L)", "findall(X, g(X), L), sort(L, S), length(S, N)",
                 "aggregate_all(count, g(-0.0), N)", "f(X, b), X == -0.0", "\\+ f(-0.0, a)",
                 "bagof(Y, f(X, Y), L)"]


@pytest.mark.parametrize("goal", PROGRAM_GOALS)
def test_program_facts_and_rules_answer_as_swipl(swipl, goal):
    swidiff = swipn.swidiff
    names = swidiff.var_names(goal)
    swi_program = PROGRAM + (f"query(0, ({goal}), [{', '.join(repr(n) for n in names)}], "
                             f"[{', '.join(names)}]).\n")
    example = (PROGRAM, [], swi_program, [(goal, goal, names)])
    assert swidiff.check_example(example, swipl.run(swi_program)) is not swidiff.DISCARDED


def test_a_rule_with_a_zero_constant_gets_no_inspection_view(tmp_path):
    """A view is read outside slr_sql's connection, where no function shows a zero's sign:
    a rule that needs one gets no view (docs/sql.md), the others keep theirs."""
    with slr_sql.open(str(tmp_path / "s.db"), clock=ManualClock(0)) as kb:
        kb.add_many(["p(-0.0, 1)^1", "p(0.0, 2)^2", "p(1.5, 3)^3"])
        kb.load("z(Y) :- p(-0.0, Y)^_.\nw(Y) :- p(1.5, Y)^_.")
        _, rows = kb.sql("SELECT name FROM sqlite_master WHERE type = 'view' ORDER BY name")
        assert [r[0] for r in rows] == ["w"]
        assert kb.query("z(Y)") == kb.query("z(Y)", max_steps=1000) == [{"Y": 1}]


SUBSCRIBED = {"p(-0.0, X)^T": "p(-0.0, X, T, T)", "p(0.0, X)^T": "p(0.0, X, T, T)",
              "p(X, X)^T": "p(X, X, T, T)", "p(X, -0.0)^T": "p(X, -0.0, T, T)"}


@pytest.mark.parametrize("place", ["sqlite", "postgres"])
@pytest.mark.parametrize("pattern", sorted(SUBSCRIBED))
def test_subscriptions_deliver_what_swipl_finds(swipl, database, place, pattern, tmp_path):
    """A subscription matches by Prolog unification, each zero its own events, in store
    order; a last event ``p(.., end)`` closes the stream (no waiting for silence)."""
    where = str(tmp_path / "s.db") if place == "sqlite" else \
        database + ("&" if "?" in database else "?") + f"schema=zs{next(_SCHEMAS)}"
    with slr_sql.open(where, clock=ManualClock(0)) as kb:
        sub = kb.subscribe(pattern, since=0)
        try:
            assert kb.add_many([swipn.event_text(e) for e in EVENTS]) == []
            facts = swipn.stored_facts(kb)
            kb.add(pattern.replace("X", "end").replace("^T", "^9"))
            got = []
            while True:
                item = sub.get(timeout=30)
                if item["X"] == "end":
                    break
                got.append(swipn.swidiff.slr_answer(item, ["X", "T"]))
        finally:
            sub.close()
    swi = swipl.run(swipn.swi_program("", facts, [(pattern, SUBSCRIBED[pattern], None)]))
    assert ("answers", got) == swipn.expected(swi[0], ["X", "T"])


@pytest.mark.parametrize("place", ["sqlite", "postgres"])
def test_an_event_time_of_minus_zero_is_stored_as_zero_on_both_backends(database, place,
                                                                        tmp_path):
    """A time is a point of the store's clock, not a term: -0.0 is stored as 0.0 (SQLite's
    REAL column keeps no sign of a zero; PostgreSQL's double precision would), by the
    column-wise path, the event-by-event path and an integer-typed time alike."""
    where = str(tmp_path / "t.db") if place == "sqlite" else \
        database + ("&" if "?" in database else "?") + f"schema=zs{next(_SCHEMAS)}"
    with slr_sql.open(where, clock=slr_sql.ManualClock(5.0)) as kb:
        kb.add_many([("p", (1,), -0.0, -0.0), ("p", (2,), -0.0, 1.0)])   # column-wise
        kb.add_many([("p", (3,), -0.0, -0.0), ("p", (4, 4), -0.0, -0.0)])  # two arities
        kb.add_event("p", [5], start=-0.0, end=-0.0)
        kb.add("p(6)^[-0.0, -0.0]")
        got = sorted((r["X"], r["S"], r["E"]) for r in kb.query("p(X)^[S, E]"))
        assert got == [(1, 0.0, 0.0), (2, 0.0, 1.0), (3, 0.0, 0.0), (5, 0.0, 0.0),
                       (6, 0.0, 0.0)]
        assert all(math.copysign(1.0, t) == 1.0 for _, s, e in got for t in (s, e))
