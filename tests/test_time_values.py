"""Times match by value; empty lists come back as ``[]``; a plain call of a predicate that
only has ``^T`` clauses explains itself; a second arity of a stored event name is refused.

Every query runs three ways and must give the same answers: the compiled SQL plan, the
interpreter alone (``sql_enabled = False``), and the interpreter calling compiled sub-goals
(a trailing cut keeps the query itself out of SQL).

An event's start and end are stored as floats. A time written in a goal or a pattern --
an event goal's stamp, a prev/next pattern's stamp, ``^[S, E]`` -- matches a stored time by
numeric value (``seen(X)^5`` finds ``seen(x)^5.0``), and a time variable is bound to the
stored float. Data arguments keep Prolog's rule (``1 \\= 1.0``), and clause heads of
temporal rules unify as Prolog clauses do.
"""
from __future__ import annotations

import pytest

import slr_sql
from slr_sql import Atom, SLRError, SLREvaluationError, Struct

@pytest.fixture
def kb():
    """A fresh in-memory store with a ManualClock: the events here are stamped with small
    times (on a wall clock they would be "decades late", a LearnedDelayWarning); nothing
    here waits on the store's time."""
    with slr_sql.open(clock=slr_sql.ManualClock(0.0)) as k:
        yield k

ENGINES = ["sql", "interpreter", "interpreter+compiled"]


def ask(kb, goal: str, engine: str, **kw) -> list[dict]:
    """Answers of ``goal`` through one engine (see the module docstring)."""
    if engine == "sql":
        return kb.query(goal, **kw)
    if engine == "interpreter":
        kb.sql_enabled = False
        try:
            return kb.query(goal, **kw)
        finally:
            kb.sql_enabled = True
    # a local cut keeps the query itself in the interpreter (which may call compiled rules)
    wrapped = f"call(!), ({goal})"
    assert "engine: interpreter" in kb.explain(wrapped)
    return kb.query(wrapped, **kw)


def typed(answers: list[dict]) -> list[dict]:
    """Answers with each value's type beside it (5 and 5.0 must not compare equal)."""
    return [{k: (type(v).__name__, v) for k, v in a.items()} for a in answers]


@pytest.fixture
def seen_kb(kb):
    kb.add_many(["seen(x)^5", "seen(y)^[1, 2]", "seen(z)^7.5", "q(5)^1", "r(5)^5"])
    return kb


# ------------------------------------------------------------------------ times match by value

@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("goal, want", [
    ("seen(X)^5", [{"X": Atom("x")}]),
    ("seen(X)^5.0", [{"X": Atom("x")}]),
    ("seen(X)^[5, 5]", [{"X": Atom("x")}]),
    ("seen(X)^[5, 5.0]", [{"X": Atom("x")}]),
    ("seen(X)^[1, 2]", [{"X": Atom("y")}]),
    ("seen(X)^[1.0, E]", [{"X": Atom("y"), "E": 2.0}]),
    ("seen(X)^T", [{"X": Atom("x"), "T": 5.0}, {"X": Atom("z"), "T": 7.5}]),
    ("T = 5, seen(X)^T", [{"T": 5, "X": Atom("x")}]),
    ("seen(X)^6", []),
    ("seen(X)^five", []),
    ("prev(seen(X)^5, 9)", [{"X": Atom("x")}]),
    ("prev(seen(X)^5.0, 9)", [{"X": Atom("x")}]),
    ("prev(seen(X)^T, 6)", [{"X": Atom("x"), "T": 5.0}]),
    ("prev(seen(X)^[1, 2], [0, 9])", [{"X": Atom("y")}]),
    ("next(seen(X)^[1, 2], [0, inf])", [{"X": Atom("y")}]),
    ("next(seen(X)^5, [0, inf])", [{"X": Atom("x")}]),   # the first *matching* event
    ("next(seen(X)^5, [0, 4])", []),
    ("next(seen(X)^5, 3, 9)", [{"X": Atom("x")}]),
    ("next(seen(X)^T, [3, inf])", [{"X": Atom("x"), "T": 5.0}]),
    # data arguments keep Prolog's rule: the stored integer 5 is not 5.0
    ("q(5)^T", [{"T": 1.0}]),
    ("q(5.0)^T", []),
    ("q(X)^1", [{"X": 5}]),
    # a variable shared by data and time: bound by the data (the integer), then matched
    # against the stored time by value
    ("r(T)^T", [{"T": 5}]),
    ("seen(_)^T, r(T)^_", []),                  # T = 5.0 from the time: r's data is 5
])
def test_times_match_by_value(seen_kb, engine, goal, want):
    assert typed(ask(seen_kb, goal, engine)) == typed(want)


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("t", [5, 5.0])
def test_times_given_from_python_match_by_value(seen_kb, engine, t):
    for goal in ("seen(X)^T", "prev(seen(X)^T, 9)"):
        got = ask(seen_kb, goal, engine, args={"T": t})
        assert typed(got) == typed([{"X": Atom("x"), "T": t}]), goal


@pytest.mark.parametrize("engine", ENGINES)
def test_integers_beyond_64_bits_match_by_value(kb, engine):
    """2**53 + 1 equals no float; 10**20 equals the float 1e20 exactly."""
    kb.add_many(["big(x)^1.0e20", "big(y)^9007199254740992"])
    for goal, args, want in [
            ("big(X)^T", {"T": 10 ** 20}, [{"X": Atom("x"), "T": 10 ** 20}]),
            ("big(X)^100000000000000000000", None, [{"X": Atom("x")}]),
            ("big(X)^9007199254740993", None, []),
            ("big(X)^T", {"T": 2 ** 53 + 1}, []),
            ("prev(big(X)^T, 1.0e21)", {"T": 10 ** 20}, [{"X": Atom("x"), "T": 10 ** 20}])]:
        assert typed(ask(kb, goal, engine, args=args)) == typed(want), goal


@pytest.mark.parametrize("engine", ENGINES)
def test_stream_view_with_an_integer_time(seen_kb, engine):
    assert typed(ask(seen_kb, "seen(X)^5", engine, at=5)) == typed([{"X": Atom("x")}])
    assert ask(seen_kb, "seen(X)^5", engine, at=4) == []


TF = """
tf(S, D, V)^T :- number(T), prev(tf(S, D, V)^T0, T), T0 < T.
"""


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("goal, want", [
    # the stored event at 200 first (by value), then the rule (whose prev finds it at 200.0,
    # not earlier than 200: no second answer)
    ("tf(cam, base, X)^200", [{"X": 2}]),
    ("tf(cam, base, X)^200.0", [{"X": 2}]),
    ("tf(cam, base, X)^150", [{"X": 1}]),       # the rule only
    ("tf(cam, base, X)^T", [{"X": 1, "T": 100.0}, {"X": 2, "T": 200.0}]),
])
def test_events_and_rules_of_one_name_match_times_by_value(kb, engine, goal, want):
    kb.load(TF)
    kb.add_many(["tf(cam, base, 1)^100", "tf(cam, base, 2)^200"])
    assert typed(ask(kb, goal, engine)) == typed(want)


@pytest.mark.parametrize("engine", ENGINES)
def test_rule_heads_keep_prolog_unification(kb, engine):
    """Only stored times match by value: a rule head's constant time is a Prolog term."""
    kb.load("alarm^5 :- true.\nbell^T :- T = 5.")
    assert ask(kb, "alarm^5", engine) == [{}]
    assert ask(kb, "alarm^5.0", engine) == []
    assert typed(ask(kb, "bell^T", engine)) == typed([{"T": 5}])
    assert ask(kb, "bell^5.0", engine) == []


def test_synchronized_query_with_an_integer_time():
    kb = slr_sql.open(clock=slr_sql.ManualClock(0.0))
    try:
        kb.add("seen(x)^5")
        kb.mark_complete("seen/1", 10.0)
        pending = kb.submit("seen(X)^5", at=6)
        assert typed(pending.result(timeout=10)) == typed([{"X": Atom("x")}])
        pending = kb.submit("prev(seen(X)^5, 9)", at=9)
        assert typed(pending.result(timeout=10)) == typed([{"X": Atom("x")}])
    finally:
        kb.close()


# ------------------------------------------------------------------------ the empty list

@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("goal, name, want", [
    ("X = []", "X", []),
    ("X = '[]'", "X", []),
    ("X = f([])", "X", Struct("f", ([],))),
    ("X = [[], a]", "X", [[], Atom("a")]),
    ("findall(Y, fail, X)", "X", []),
    ("e(X)^_", "X", []),
    ("g(X)^_", "X", Struct("k", ([], [[]]))),
    ("h(X)^_", "X", [[], 1]),
])
def test_the_empty_list_is_a_python_list(kb, engine, goal, name, want):
    kb.add_many(["e([])^1", "g(k([], [[]]))^1", "h([[], 1])^1"])
    got = ask(kb, goal, engine)
    assert len(got) == 1, got
    assert _strict(got[0][name]) == _strict(want)


def _strict(v):
    """Structure with types: [] (a list) is not Atom('[]')."""
    if type(v) is list:
        return ("list", tuple(_strict(x) for x in v))
    if type(v) is Struct:
        return ("struct", str(v.name), tuple(_strict(x) for x in v.args))
    return (type(v).__name__, v)


def test_the_empty_list_from_submit():
    kb = slr_sql.open(clock=slr_sql.ManualClock(0.0))
    try:
        kb.add("e([])^1")
        kb.mark_complete("e/1", 5.0)
        got = kb.submit("e(X)^T", at=2).result(timeout=10)
        assert _strict(got[0]["X"]) == ("list", ())
    finally:
        kb.close()


def test_str_of_a_returned_term_is_its_prolog_text(kb):
    assert str(kb.query("X = []")[0]["X"]) == "[]"
    value = kb.query('X = f([a, "s", [], g([1])], [])')[0]["X"]
    assert str(value) == 'f([a,"s",[],g([1])],[])'


# ------------------------------------------------------------------------ ^T predicates called plainly

COLOR = """
color(O, C)^T :- prev(obj(O, _, C)^_, T).
shown(O) :- color(O, _).
"""


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("goal, hint", [
    ("color(cup1, C)", "color/2 is defined with ^T: did you mean color(cup1, C)^T?"),
    ("color(O, T)", "color/2 is defined with ^T: did you mean color(O, T)^T1?"),
    ("shown(cup1)", "color/2 is defined with ^T: did you mean color(cup1, _"),
])
def test_plain_call_of_a_temporal_predicate_explains(kb, engine, goal, hint):
    kb.load(COLOR)
    kb.add("obj(cup1, cup, red)^1")
    with pytest.raises(SLREvaluationError) as info:
        ask(kb, goal, engine)
    term = info.value.term
    assert term.name == "error"
    assert str(term.args[0]) == "existence_error(procedure,color/2)"
    assert hint in str(info.value), str(info.value)


@pytest.mark.parametrize("engine", ENGINES)
def test_plain_call_of_a_temporal_predicate_is_catchable(kb, engine):
    kb.load(COLOR)
    got = ask(kb, "catch(color(cup1, C), error(E, _), true)", engine)
    assert [str(a["E"]) for a in got] == ["existence_error(procedure,color/2)"]


@pytest.mark.parametrize("engine", ENGINES)
def test_plain_call_of_an_event_type_explains(kb, engine):
    kb.add("seen(x)^5")
    with pytest.raises(SLREvaluationError) as info:
        ask(kb, "seen(X)", engine)
    assert str(info.value.term.args[0]) == "existence_error(procedure,seen/1)"
    assert "seen/1 is an event type: did you mean seen(X)^T?" in str(info.value)


def test_dynamic_predicate_still_fails_quietly(kb):
    kb.load(":- dynamic color/2.\n" + COLOR)
    assert kb.query("color(cup1, C)") == []


# ------------------------------------------------------------------------ one name, two arities

def test_declaring_a_second_arity_of_stored_events_is_refused(kb):
    kb.add("seg(cup1)^1")
    with pytest.raises(SLRError) as info:
        kb.load(":- event seg/2.")
    message = str(info.value)
    assert "seg/2" in message and "seg/1" in message and ":- event seg/1" in message
    assert kb.store.declared_types() == set()
    # nothing was loaded: seg/1 events are still accepted, seg/2 is not declared
    kb.add("seg(cup2)^2")
    assert len(kb.query("seg(O)^T")) == 2


@pytest.mark.parametrize("program", [
    ":- event seg/1, seg/2.",
    ":- event seg/2.\n:- event seg/1.",
])
def test_both_arities_declared_together_are_accepted(kb, program):
    kb.add("seg(cup1)^1")
    kb.load(program)
    kb.add("seg(cup1, [1, 2])^2")
    assert len(kb.query("seg(O)^T")) == 1 and len(kb.query("seg(O, L)^T")) == 1


def test_second_arity_next_to_a_declared_one_is_accepted(kb):
    kb.load(":- event seg/1.")
    kb.add("seg(cup1)^1")
    kb.load(":- event seg/2.")
    kb.add("seg(cup1, [1, 2])^2")
    assert len(kb.query("seg(O, L)^T")) == 1


# ------------------------------------------------------------------------ buffers

@pytest.mark.parametrize("stamp", ["5", "5.0", "[1, 2]"])
def test_buffer_patterns_take_no_time_to_match(kb, stamp):
    """A buffer selects events by their arguments: a time in its pattern is refused (so no
    time there is ever compared), a variable stamp is ignored."""
    with pytest.raises(SLRError, match="time stamp must be a variable"):
        kb.load(f"tBuffer(p(_)^{stamp}, 10).")
    kb.load("tBuffer(p(_)^T, 10).")
    assert [b.pattern for b in kb.buffers()] == ["p(_)"]
