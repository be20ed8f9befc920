"""slr_sql.analysis: dependency graph, goal sets, meta-predicates, recursion."""
from __future__ import annotations

import pytest

import slr_sql

from slr_sql.analysis import (Analysis, Node, analyze, dependency_graph, goal_set,
                               recursive_predicates, sccs)
from slr_sql.demo import CUPS_ON_TABLE1, ROBOT_PROGRAM
from slr_sql.parser import parse_program
from slr_sql.program import Program


def program(text: str) -> Program:
    p = Program()
    for clause in parse_program(text):
        if clause.head is not None:
            p.add_clause(clause)
    return p


def test_goal_set_follows_rules_and_event_goals():
    p = program("""
        color(O, C)^T :- prev(obj(O, _, C)^_, T).
        red(O) :- color(O, red)^3.
        fresh(O) :- seg(O, _)^_, \\+ stale(O).
        stale(O) :- old(O)^_.
        unrelated :- tf(a, b, _)^_.
    """)
    assert goal_set(p, "red(X)") == {("color", 2), ("obj", 3)}
    assert goal_set(p, "fresh(X)") == {("seg", 2), ("old", 1)}
    assert goal_set(p, "findall(X, (red(X) ; fresh(X)), L)") == \
        {("color", 2), ("obj", 3), ("seg", 2), ("old", 1)}
    assert goal_set(p, "X = 1") == set()
    assert not goal_set(p, "red(X)").unknown
    # with_output_to/2 runs its goal (a synchronized query waits for what it reads)
    assert goal_set(p, "with_output_to(string(S), fresh(X))") == {("seg", 2), ("old", 1)}


def test_prev_and_next_read_stored_events_only():
    p = program("""
        color(O, C)^T :- prev(obj(O, _, C)^_, T).
        last_color(O, C, T) :- prev(color(O, C)^_, T).
    """)
    # prev over color/2 never calls the color rule, so obj/3 is not in the goal set
    assert goal_set(p, "last_color(a, C, 3)") == {("color", 2)}
    assert goal_set(p, "next(seg(O, P)^T, [1, 2])") == {("seg", 2)}


def test_unknown_calls_give_every_known_type():
    p = program("""
        a(X) :- p(X)^_.
        b(X) :- q(X)^_.
        run(G) :- call(G).
        any(E) :- prev(E, 3).
    """)
    g = goal_set(p, "G = a(1), call(G)", known_types=[("z", 9)])
    assert g.unknown and {("p", 1), ("q", 1), ("z", 9)} <= set(g)
    assert any("variable" in r for r in g.reasons)
    # a meta-argument given at the call site is resolved
    assert goal_set(p, "run(a(X))") == {("p", 1)}
    assert not goal_set(p, "run(a(X))").unknown
    assert goal_set(p, "any(p(_)^_)").unknown          # prev on a variable event


def test_library_meta_predicates_are_resolved():
    p = program("""
        seen(X) :- s(X)^_.
        ok(L) :- maplist(seen, L).
        some(L, R) :- include(seen, L, R).
        f(X, A0, A) :- w(X)^_, A is A0 + 1.
        count(L, N) :- foldl(f, L, 0, N).
    """)
    a = analyze(p)
    assert (0, 1) in a.meta[("maplist", 2)] and (0, 3) in a.meta[("foldl", 4)]
    assert goal_set(p, "ok([1,2])") == {("s", 1)}
    assert goal_set(p, "some([1], R)") == {("s", 1)}
    assert goal_set(p, "count([1], N)") == {("w", 1)}
    assert goal_set(p, "once(seen(1))") == {("s", 1)}


def test_the_papers_cups_query():
    p = program(ROBOT_PROGRAM)
    g = goal_set(p, CUPS_ON_TABLE1.goal)
    assert set(g) == {("obj", 3), ("seg", 2), ("tf", 3)} and not g.unknown


def test_dependency_graph_and_recursion():
    p = program("""
        anc(X, Y) :- par(X, Y).
        anc(X, Y) :- par(X, Z), anc(Z, Y).
        par(a, b).
        even(0).
        even(N) :- N > 0, M is N - 1, odd(M).
        odd(N) :- N > 0, M is N - 1, even(M).
        walk(X)^T :- walk(X)^T0, T0 < T.
        flat(X) :- par(X, _), member(X, [a]).
    """)
    edges = dependency_graph(p)
    assert Node("pred", "par", 2) in edges[Node("pred", "anc", 2)]
    rec = recursive_predicates(p)
    assert rec == {Node("pred", "anc", 2), Node("pred", "even", 1), Node("pred", "odd", 1),
                   Node("event", "walk", 1)}
    assert Node("pred", "append", 3) in recursive_predicates(p, include_library=True)


@pytest.mark.parametrize("text", [
    "",
    "anc(X,Y) :- par(X,Y). anc(X,Y) :- par(X,Z), anc(Z,Y). par(a,b).",
    "even(0). even(N) :- N > 0, M is N - 1, odd(M). odd(N) :- N > 0, M is N - 1, even(M).",
    "walk(X)^T :- walk(X)^S, T is S + 1. use(L) :- append(L, [a], M), member(x, M).",
    "append(X, Y, Z) :- call(X, Y, Z), use(Z). use(L) :- append(L, [a], _).",
    "maplist(G, L) :- w(G, L). w(G, L) :- maplist(G, L).",
    # a cycle through the library: the program's select/3 calls selectchk/3, which calls
    # select/3
    "select(X, L, R) :- selectchk(X, L, R).",
    ROBOT_PROGRAM,
])
def test_the_recursive_predicates_are_those_of_the_whole_graph(text):
    """Asked from the program's own nodes (not the library's graph), the recursive
    predicates are those the components of the whole graph give, also where the program
    defines a predicate the library calls."""
    p = program(text)
    edges = analyze(p).edges
    whole = {n for comp in sccs(edges) for n in comp
             if len(comp) > 1 or comp[0] in edges.get(comp[0], ())}
    user = {Node("pred", *k) for k in p.preds} | {Node("event", *k) for k in p.temporal}
    assert recursive_predicates(p) == whole & user
    assert recursive_predicates(p, include_library=True) == whole


def test_sccs_orders_callees_first():
    comps = sccs({"a": ["b"], "b": ["c", "a"], "c": ["c"], "d": []})
    assert comps.index(["c"]) < next(i for i, c in enumerate(comps) if set(c) == {"a", "b"})
    assert ["d"] in comps


# The library's part of the graph is computed once per process and copied into each program's
# analysis; the reference computes the library's clauses and the program's together, as one
# program with no library: every field must come out the same, also for programs that define a
# predicate the library calls (append/3, maplist/2) or call library meta-predicates.
@pytest.mark.parametrize("text", [
    "",
    "p(X) :- q(X)^T, X > 1.\nr(X) :- p(X).",
    "seen(O) :- seg(O, _)^_. all(Os) :- maplist(seen, Os).",
    "p(G) :- call(G, 1). q :- p(r). r(_).",
    "ok(L) :- foldl(add, L, 0, S), S > 2. add(X, A, B) :- B is A + X.",
    "append(X, Y, Z) :- call(X, Y, Z). use(L) :- append(L, [a], _).",
    "maplist(G, L) :- w(G, L). w(_, _) :- seg(_, _)^_.",
    "bad(G) :- G. worse :- prev(E, 3), call(E).",
    ROBOT_PROGRAM,
])
def test_each_program_shares_the_library_part_computed_once(text):
    from slr_sql.builtins import LIBRARY_SOURCE

    alone = Program()
    for clause in parse_program(LIBRARY_SOURCE + "\n" + text):
        if clause.head is not None:
            alone.add_clause(clause)
    reference = Analysis(alone, Program())
    for _ in range(2):          # the first builds the library's part, the second copies it
        got = Analysis(program(text))
        assert got.meta == reference.meta
        assert got.edges == reference.edges and list(got.edges) == list(reference.edges)
        assert got.stored == reference.stored
        assert got.unknown == reference.unknown


def test_a_programs_analysis_does_not_change_the_next_ones():
    first = analyze(program("p(G) :- call(G, 1). q :- p(r). r(_). maplist(G, L) :- w(G, L). w(_, _)."))
    assert Node("pred", "w", 2) in first.edges[Node("pred", "maplist", 2)]
    second = analyze(program("x."))
    assert Node("pred", "w", 2) not in second.edges[Node("pred", "maplist", 2)]
    assert ("p", 1) not in second.meta


def test_a_programs_analysis_goes_with_the_program():
    """analyze() caches its result: a cache that held the analysis (which refers to its
    program) kept every program analysed since the process started alive, and a server that
    loads program after program, or the suite's workers, grew without end."""
    import gc
    import weakref

    import slr_sql

    p = program("p(X) :- q(X)^T, X > 1.")
    a = analyze(p)
    assert analyze(p) is a                       # cached
    gone = weakref.ref(p), weakref.ref(a)
    del p, a
    gc.collect()
    assert [ref() for ref in gone] == [None, None]
    with slr_sql.open() as kb:                   # a store's programs, loaded and replaced
        kb.load("r(X) :- s(X).\ns(1).")
        assert kb.query("r(X)") == [{"X": 1}]
        held = weakref.ref(kb.engine.program)
        kb.load("t(2).")
    gc.collect()
    assert held() is None


def test_a_replaced_program_is_freed_by_reference_counting_alone():
    """The analysis kept on a program refers to it weakly: no cycle, so a program a server
    replaces is freed at once, not when the cyclic collector next runs a full pass."""
    import gc
    import weakref

    gc.disable()
    try:
        p = program("p(X) :- q(X)^T, X > 1.")
        a = analyze(p)
        assert a.program is p
        gone = weakref.ref(p), weakref.ref(a)
        del p
        assert [ref() for ref in gone] == [None, a]       # (no collection ran)
        with pytest.raises(ReferenceError):
            a.program
    finally:
        gc.enable()


def test_a_program_rebuilt_text_by_text_is_analysed_whole():
    """Replacing a text rebuilds the program from every stored text in turn; an event rule's
    where goal has the half-built program analysed on the way: the analysis the queries use
    must still know the clauses of the texts added after it."""
    kb = slr_sql.open()
    try:
        kb.load("c(X) <- a(X) seq b(X) where ok(X).\nok(_).\n", name="one")
        kb.load("r(X) :- s(X)^T.\n", name="two")
        kb.load("c(X) <- a(X) seq b(X) where ok(X).\nok(_).\n", name="one", replace=True)
        program = kb.engine.program
        assert sorted(goal_set(program, "r(X)")) == [("s", 1)]
        assert sorted(goal_set(program, "r(X)")) == sorted(goal_set(program.copy(), "r(X)"))
    finally:
        kb.close()
