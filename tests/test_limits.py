"""Deep, cyclic, huge and endless inputs through the knowledge base: every one either works or
stops with an SLRError (SLRTimeout when ``timeout=`` runs out, an ISO resource error at a
documented bound), never with a raw Python exception, a hang or a crash.

The bounds (docs/language.md, "Limits"): integers of at most terms.MAX_INTEGER_BITS bits;
lists of at most builtins.MAX_BUILT_LIST cells built by one numlist/3, length/2 or
functor/3 call; a query grows the process's memory by at most engine.MAX_QUERY_GROWTH; texts of at most builtins.MAX_BUILT_TEXT characters made by repeating (format/2's
counts, tab/1, atomic_list_concat/3's separator); no limit on term nesting.
"""
from __future__ import annotations

import pytest

import slr_sql
from slr_sql import engine
from slr_sql.builtins import MAX_BUILT_LIST, MAX_BUILT_TEXT
from slr_sql.errors import SLRError, SLREvaluationError, SLRTimeout
from slr_sql.terms import MAX_INTEGER_BITS, Struct, Var, format_term

DEEP = 100_000


@pytest.fixture
def kb():
    """A fresh in-memory store with a ManualClock: the events here are stamped 1, 2, 5 (not
    wall-clock times, which would make each type's first event "decades late", a
    LearnedDelayWarning), and no test here waits on the store's time."""
    with slr_sql.open(clock=slr_sql.ManualClock(0.0)) as k:
        yield k


def error_of(kb, goal: str, **kw) -> str:
    """The ISO error term an SLREvaluationError carries, as text (``error(F, _)`` -> F)."""
    with pytest.raises(SLREvaluationError) as ei:
        kb.query(goal, **kw)
    term = ei.value.term
    assert type(term) is Struct and term.name == "error", term
    return format_term(term.args[0])


# ------------------------------------------------------------------ deep terms, end to end
def test_a_term_nested_100k_deep_goes_through_every_part_of_the_engine(kb):
    deep = "f(" * DEEP + "a" + ")" * DEEP
    kb.load(f"deep({deep}).\nwrap(X, g(X)).\n")
    goal = ("deep(X), copy_term(X, C), X == C, compare(O, X, C), msort([C, X], S), "
            "findall(Y, deep(Y), [F]), F = X, catch(throw(X), B, true), B == X, "
            "wrap(X, W), format(atom(A), '~w', [W]), atom_length(A, N), "
            "term_variables(f(X, V1, C, V2, V1), Vs), Vs == [V1, V2]")
    (answer,) = kb.query(goal)
    assert answer["N"] == len(deep) + len("g()") and answer["O"] == "="
    text = str(answer["X"])
    assert text == deep and str(answer["W"]) == f"g({deep})"
    # the same term matched against a clause head and unified with a query argument
    assert kb.query(f"deep({deep})") == [{}]


def test_long_arithmetic_and_long_bodies(kb):
    assert kb.query("X is " + "+".join(["1"] * DEEP)) == [{"X": DEEP}]
    assert kb.query("X is " + "-".join(["1"] * 1000) + " * 2") == [{"X": 1 - 999 + 1 - 2}]
    n = DEEP // 2
    kb.load("many :- " + ", ".join(f"X{i} = {i}" for i in range(n)) + ".\n")
    assert kb.query("many") == [{}]
    assert kb.query("; ".join(["fail"] * n) + "; X = done") == [{"X": "done"}]


# \+ nested this deep: each \+ walked its whole body again (N²/2 steps), over 1.5 minutes;
# once walked, about 0.1 s
NEGATIONS = 20_000


@pytest.mark.parametrize("innermost, expected", [
    ("true", [{}]),
    ("fail", []),
    ("(X = 1, X == 1)", [{}]),
])
def test_negations_nested_deep_answer_within_the_timeout(kb, innermost, expected):
    goal = "\\+ " * NEGATIONS + innermost
    assert kb.query(goal, timeout=ANSWERS_WITHIN * 4) == expected
    # the same body built at run time and called
    assert kb.query(f"\\+ \\+ (G = ({goal}), call(G))", timeout=ANSWERS_WITHIN * 4) == expected


NEGATED_40 = "\\+ " * 40 + "true"


@pytest.mark.parametrize("goal", [
    NEGATED_40 + ", (true, 1)",                 # found before any of it runs
    NEGATED_40 + ", G = (true, 1), call(G)",    # a body made at run time
    "X = 1, " + "\\+ " * 40 + "(true, X)",         # a goal bound after the body began
    # bound again on backtracking: true, then 1
    "member(X, [true, 1]), " + "\\+ " * 40 + "(true, X), fail",
])
def test_a_deeply_negated_body_that_is_no_body_is_still_a_type_error(kb, goal):
    assert error_of(kb, goal).startswith("type_error(callable,")


# ------------------------------------------------------------------------- cyclic terms
def test_cyclic_answers_come_back_as_swi_prints_them(kb):
    (answer,) = kb.query("X = f(X)")
    assert str(answer["X"]) == "@(S_1,[S_1=f(S_1)])"
    (answer,) = kb.query("L = [a, b|L], Y = g(L, L)")
    assert str(answer["Y"]) == "@(g(S_1,S_1),[S_1=[a,b|S_1]])"
    # what the value is made of: '@'(Template, [S_1 = Value])
    value = answer["L"]
    assert value.name == "@" and type(value.args[0]) is Var
    assert str(value.args[1][0]) == "S_1=[a,b|S_1]"


@pytest.mark.parametrize("goal,expected", [
    ("X = f(X), Y = f(Y), X = Y, X == Y", [{}]),               # unify, compare two cycles
    ("X = f(X), copy_term(X, C), C = f(D), D == C", [{}]),     # the copy is cyclic too
    ("X = f(X), findall(X, true, [Y]), Y = f(Y)", [{}]),
    ("X = f(X), ground(X)", [{}]),
    # (a variable is written as '_' and a number of its own, the cycle's S_1 by term_to_atom
    # too, as SWI-Prolog's: '@(_424,[_424=f(_424,_426)])'; write/1 keeps S_1)
    ("X = f(X, Z), term_to_atom(X, A), sub_atom(A, 0, 3, _, P)", [{"P": "@(_"}]),
    ("X = f(X, Z), format(atom(A), '~w', [X]), sub_atom(A, 0, 18, _, P)", [{"P": "@(S_1,[S_1=f(S_1,_"}]),
    ("L = [a|L], (is_list(L) -> R = yes ; R = no)", [{"R": "no"}]),
    ("X = f(X), Y = f(Y), compare(O, X, Y)", [{"O": "="}]),
])
def test_cyclic_terms_do_not_hang(kb, goal, expected):
    answers = kb.query(goal, timeout=10)
    for a in answers:  # keep only the bindings the test names
        for k in list(a):
            if not any(k in e for e in expected):
                del a[k]
    assert [{k: str(v) for k, v in a.items()} for a in answers] == \
        [{k: str(v) for k, v in e.items()} for e in expected]


def test_a_cyclic_list_is_not_a_list(kb):
    # the error term holds the cyclic list: it is printed factorized, as any cyclic term
    assert error_of(kb, "L = [a|L], length(L, N)") == "@(type_error(list,S_1),[S_1=[a|S_1]])"
    assert error_of(kb, "L = [a, b|L], msort(L, S)") == \
        "@(type_error(list,S_1),[S_1=[a,b|S_1]])"


# ------------------------------------------------------- timeouts and resource bounds
# X1 = f(X0, X0), X2 = f(X1, X1), ...: 41 cells, 2**40 nodes as a tree
SHARED = "dag(0, z) :- !.\ndag(N, f(X, X)) :- M is N - 1, dag(M, X).\n"
CYCLIC = "X = f(X,X,X,X,X,X), Y = f(Y,Y,Y,Y,Y,Y)"
ARITY_40 = "X = f({0}), Y = f({1})".format(",".join(["X"] * 40), ",".join(["Y"] * 40))
# what "timeout=1 holds" allows, generously (a loaded machine, a slow thread start): a walk
# that ignores the deadline runs for half a minute (the cycles) to hours (the shared terms)
FINISHES_WITHIN = 15.0
# the timeout of a query whose answer must come (~0.1 s on an idle machine): the walk that
# ignores sharing or cycles runs far longer, so it still fails, while a loaded machine
# (a whole-file run on 2 busy cores took over 1 s for the arity-40 cycles) does not
ANSWERS_WITHIN = 5.0
# the timeout of a query that must run out of time (a walk of 2**40 nodes, a list of
# millions of cells): the test waits it out, and any timeout is as far from the work's end
RUNS_OUT = 0.3


def finishes(kb, goal: str, timeout: float = 1):
    """kb.query(goal, timeout=...) in a thread: its answers, or the SLRError it raised; the
    test fails if it has not finished FINISHES_WITHIN seconds later."""
    import threading

    box: list = []

    def run():
        try:
            box.append(kb.query(goal, timeout=timeout))
        except SLRError as exc:
            box.append(exc)

    worker = threading.Thread(target=run, daemon=True)
    worker.start()
    worker.join(FINISHES_WITHIN)
    assert box, f"{goal} ignored timeout={timeout}"
    return box[0]


@pytest.mark.parametrize("goal,expected", [
    (f"{CYCLIC}, X = Y, fail", []),
    (f"{ARITY_40}, X = Y, fail", []),
    (f"\\+ \\+ ({CYCLIC}, X = Y, X == Y, copy_term(X, C), C = Y, findall(X, true, [F]), F = Y)",
     [{}]),
    # shared terms: unify, compare, copy and group as a graph, not as a 2**40-node tree
    ("\\+ \\+ (dag(40, X), dag(40, Y), X = Y, X == Y, compare(=, X, Y), X @>= Y, "
     "copy_term(X, C), C = Y, findall(X, true, [F]), F == Y, catch(throw(X), B, true), B = Y, "
     "msort([X, Y], [_, _]), bagof(K, member(K-W, [1-X, 2-Y]), [1, 2]), "
     "term_variables(f(X, Z, Y, X), Vs), Vs == [Z])", [{}]),
    # the occurs check walks a shared term as a graph too
    ("\\+ \\+ (dag(40, X), dag(40, Y), unify_with_occurs_check(X, Y), "
     "\\+ unify_with_occurs_check(V, f(V, X)), unify_with_occurs_check(W, g(X)), W == g(Y))",
     [{}]),
])
def test_cyclic_and_shared_terms_meet_the_timeout_with_the_answer(kb, goal, expected):
    kb.load(SHARED)
    assert finishes(kb, goal, timeout=ANSWERS_WITHIN) == expected


@pytest.mark.parametrize("goal", [
    "dag(40, X)",                                   # the answer itself
    "dag(40, X), format(atom(A), '~w', [X])",
    "dag(40, X), term_to_atom(X, A)",
    "dag(40, X), write(X)",
])
def test_writing_a_huge_shared_term_stops_at_the_timeout(kb, goal):
    kb.load(SHARED)
    assert isinstance(finishes(kb, goal, timeout=RUNS_OUT), SLRTimeout)


def test_an_error_about_a_huge_term_has_a_bounded_message(kb):
    kb.load(SHARED)
    error = finishes(kb, "dag(40, X), length(X, N)")
    assert isinstance(error, SLREvaluationError) and len(str(error)) < 100_000
    assert str(error).startswith("error(type_error(list,f(f(") and str(error).endswith(" ...")


@pytest.mark.parametrize("timeout", [1, None])
def test_a_list_of_fifty_million_cells_is_a_resource_error_at_once(kb, timeout):
    assert error_of(kb, "length(L, 50000000)", timeout=timeout) == "resource_error(memory)"
    assert error_of(kb, f"numlist(1, {MAX_BUILT_LIST + 1}, L)", timeout=timeout) == \
        "resource_error(memory)"
    assert error_of(kb, "functor(F, f, 100000000)", timeout=timeout) == "resource_error(memory)"


@pytest.mark.parametrize("goal", [
    'format(atom(A), "~1000000000n", [])', 'format(atom(A), "~900000000d", [1])',
    'format(atom(A), "~*c", [1000000000, 0\'a])', 'format(atom(A), "~900000000D", [1])',
    f'format(atom(A), "~{MAX_BUILT_TEXT // 2 + 1}c~{MAX_BUILT_TEXT // 2 + 1}c", [0\'a, 0\'b])',
    "tab(900000000)",
    "length(L, 1000), maplist(=(x), L), format(atom(S), \"~100000c\", [0'-]), "
    "atomic_list_concat(L, S, A)",
])
def test_a_text_repeated_beyond_the_bound_is_a_resource_error_at_once(kb, goal):
    """Each was a single Python step building gigabytes (5 GB of memory for the first, 20 s,
    past any timeout), which a query over the service could ask for."""
    assert error_of(kb, goal, timeout=5) == "resource_error(memory)"
    assert kb.query('format(atom(A), "~3c~2d~n", [0\'a, 314])') == [{"A": slr_sql.Atom("aaa3.14\n")}]


@pytest.mark.parametrize("goal", [
    "nth1(100000000, L, x)", "length(L, N), N > 20000000",
    "findall(X, between(1, inf, X), L)"])
def test_a_query_that_keeps_growing_is_a_resource_error_not_a_timeout(kb, goal, monkeypatch):
    """Each grew the process by tens of MB a second until its timeout (4 of them over the
    service: gigabytes); past engine.MAX_QUERY_GROWTH (1 GiB, lowered here to 4 MiB to be
    quick: growing 16 MiB took 0.5-1.3 s a query) of the process's resident memory it is
    resource_error(memory), which catch/3 catches."""
    monkeypatch.setattr(engine, "MAX_QUERY_GROWTH", 4 << 20)
    assert error_of(kb, goal, timeout=120) == "resource_error(memory)"
    caught = f"catch(({goal}), error(resource_error(memory), _), true)"
    assert kb.query(caught, timeout=120) == [{}] or goal.startswith("length")
    assert kb.query("X = 1") == [{"X": 1}]


def test_building_a_long_list_stops_when_the_time_is_up(kb):
    with pytest.raises(SLRTimeout):
        kb.query("numlist(1, 5000000, L)", timeout=RUNS_OUT)
    with pytest.raises(SLRTimeout):
        kb.query("length(L, N), N > 100000000", timeout=RUNS_OUT)
    assert kb.query("numlist(1, 3, L)") == [{"L": [1, 2, 3]}]  # the kb is fine afterwards


def test_reverse_of_a_partial_list_with_no_solution_meets_the_limits(kb):
    # (reverse/2 completes L to one length after another; [a|L] is never one of them: a walk
    # inside one builtin call, counted by the cells of each length it tries)
    with pytest.raises(SLRTimeout, match="step limit"):
        kb.query("reverse(L, [a|L])", max_steps=5000, timeout=5)
    with pytest.raises(SLRTimeout):
        kb.query("reverse(L, [a|L])", timeout=RUNS_OUT)
    assert kb.query("reverse(L, [a, b])") == [{"L": ["b", "a"]}]


def test_reverse_into_an_unbound_list_takes_one_walk(kb):
    # (the other list proper: the one length its cells allow is made at once, not each
    # shorter one tried first -- quadratic, minutes for these 100,000 cells)
    # (a bound of a minute: a 5 s one was met on a machine loaded to 18 runnable processes,
    # and the quadratic walk takes minutes even on an idle one; max_steps bounds the rest)
    goal = "numlist(1, 100000, L), reverse(R, L), R = [X|_], length(R, N)"
    assert kb.query(goal, timeout=60, max_steps=1000)[0]["X"] == 100000


@pytest.mark.parametrize("timeout", [1, None])
@pytest.mark.parametrize("goal", [
    "X is 7**100000000", "X is 7^100000000", "X is 1 << 100000000000",
    f"X is 2**{MAX_INTEGER_BITS}", f"X is 2**{MAX_INTEGER_BITS - 1} * 2",
    f"X is 2**{MAX_INTEGER_BITS - 1} + 2**{MAX_INTEGER_BITS - 1}",
])
def test_integers_beyond_the_bound_are_a_resource_error(kb, goal, timeout):
    assert error_of(kb, goal, timeout=timeout) == "resource_error(max_integer_size)"


def test_integers_up_to_the_bound_work_and_print(kb):
    (a,) = kb.query(f"X is 2**{MAX_INTEGER_BITS - 1}, Y is X mod 1000, atom_length(X, N)")
    assert a["X"].bit_length() == MAX_INTEGER_BITS and a["Y"] == pow(2, MAX_INTEGER_BITS - 1, 1000)
    assert a["N"] == len(format_term(a["X"])) > 78_000
    (b,) = kb.query("X is 10**5000 + 1, format(atom(A), '~d', [X]), atom_number(A, Y), Y =:= X")
    assert b["A"] == "1" + "0" * 4999 + "1"


@pytest.mark.parametrize("goal,error", [
    ("format(atom(A), '~c', [-1])", "format_argument_type(c,-1)"),   # as SWI
    ("format(atom(A), '~c', [1114112])", "representation_error(code_point)"),
    ("char_code(C, 55296)", "type_error(character_code,55296)"),   # a surrogate, as SWI
    ("format(atom(A), '~1r', [10])", "domain_error(radix,1)"),
    ("format(atom(A), '~99999999999999c', [120])", "resource_error(memory)"),
    ("functor(F, f, -1)", "domain_error(not_less_than_zero,-1)"),
])
def test_bad_builtin_arguments_are_iso_errors(kb, goal, error):
    assert error_of(kb, goal) == error


def test_a_time_beyond_the_largest_float_compares_beyond_every_event(kb):
    kb.add("seen(x)^5")
    assert kb.query("prev(seen(X)^T, 2**2000)") == [{"X": "x", "T": 5.0}]
    assert kb.query("next(seen(X)^T, [-(2**2000), 2**2000])") == [{"X": "x", "T": 5.0}]


def test_storing_a_huge_shared_term_is_refused_not_built(kb):
    # 41 Python lists, 2**40 as text: the event is rejected with its reason (a short one)
    x: list = [1]
    for _ in range(40):
        x = [x, x]
    import threading

    box: list = []
    worker = threading.Thread(target=lambda: box.append(
        kb.add_many([("p", [x], 1.0, 1.0), ("p", [1], 2.0, 2.0)])), daemon=True)
    worker.start()
    worker.join(FINISHES_WITHIN)
    assert box, "encoding a huge shared term did not stop"
    (rejected,) = box[0]
    assert "too large to be stored" in str(rejected) and len(str(rejected)) < 100_000
    assert kb.query("p(X)^T") == [{"X": 1, "T": 2.0}]


def test_an_event_rule_deriving_a_huge_shared_term_counts_an_error(kb):
    kb.load(SHARED + "c(Y) <- a(N) where dag(N, Y).")
    kb.add_many(["a(2)^1", "a(40)^2"])
    assert [str(a["Y"]) for a in kb.query("c(Y)^T")] == ["f(f(z,z),f(z,z))"]
    (rule,) = kb.event_rules()
    assert rule["errors"] == 1 and "too large to be stored" in rule["last_error"]


# ------------------------------------------------------------- Python predicates' errors
def test_python_errors_in_defined_predicates_are_slr_errors(kb):
    def exhausted(x):
        raise MemoryError

    def buggy(x):
        return {}["missing"]

    kb.define("exhausted", 1, exhausted)
    kb.define("buggy", 1, buggy)
    assert error_of(kb, "exhausted(1)") == "resource_error(memory)"
    assert kb.query("catch(exhausted(1), error(resource_error(R), _), true)") == [{"R": "memory"}]
    assert error_of(kb, "buggy(1)") == "python_error(\"buggy raised KeyError: 'missing'\")"
