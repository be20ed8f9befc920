"""The bound ``prev`` lookup (``kb.query("prev(p(A, B)^Z, T)", args={...})``, answered by one
cached statement without the interpreter) gives exactly the interpreter's answers, and still
sees what other connections write to the file."""
from __future__ import annotations

import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

import slr_sql
from slr_sql import SLRError
from slr_sql.encoding import decode, decode_answer
from slr_sql.terms import Atom, String, Struct, make_list, to_python

# argument values chosen to collide: 1 and 1.0 (equal in SQL, not in Prolog), atoms that look
# like the JSON of other terms, strings and atoms of one text, the empty list and its atom
KEYS = [Atom("cup"), Atom("café"), Atom("[x"), Atom('{"a":1}'), Atom("[]"), Atom(""), String("cup"),
        String("[x"), 1, 1.0, 2, -0.0, 2 ** 63 - 1, 2 ** 70, 1e300]
VALUES = KEYS + [make_list([0.1, 2, -3.5]), make_list([]), make_list([1, Atom("a")]),
                 make_list([make_list([1.0])]), Struct(Atom("f"), (1, Atom("x"))),
                 Struct(Atom("."), (1, Atom("b")))]

EVENTS = st.lists(st.tuples(st.sampled_from(KEYS), st.sampled_from(VALUES),
                            st.integers(0, 6), st.integers(0, 2)), max_size=25)
# what a caller hands over in args: Python values of every kind the lookup treats itself,
# and some it leaves to the general path (lists, None, booleans, NaN)
ARGS = st.sampled_from(["cup", "café", "[x", '{"a":1}', "[]", "", String("cup"), String("[x"),
                        Atom("cup"), 1, 1.0, 2, -0.0, 2 ** 63 - 1, 2 ** 70, 1e300,
                        [1], None, True, float("nan")])
TIMES = st.sampled_from([0, 1, 2.5, 3, 6, 9.0, -1])


def reference(kb, goal, args):
    """The interpreter's answers (a limit keeps every fast path out), or its error."""
    kb.sql_enabled = False
    try:
        return answered(kb, goal, args, limit=10 ** 6)
    finally:
        kb.sql_enabled = True


def answered(kb, goal, args, **options):
    """The typed answers, or the SLRError (args that are no term, None or a bool, are
    refused by the lookup and by the interpreter alike)."""
    try:
        return typed(kb.query(goal, args=args, **options))
    except SLRError as exc:
        return ("error", type(exc).__name__, str(exc))


def typed(answers):
    return [[(k, type(v).__name__, repr(v)) for k, v in a.items()] for a in answers]


@settings(max_examples=150)
@given(EVENTS, ARGS, TIMES)
@example([(1, 2, 1, 0), (1.0, 3, 2, 0)], 1, 5)          # SQL's 1 = 1.0 is no Prolog match
@example([(1.0, 2, 1, 0), (1, 3, 2, 0)], 1.0, 5)
@example([(Atom("[x"), 2, 1, 0), (String("[x"), 3, 2, 0)], "[x", 5)
@example([(Atom("cup"), make_list([0.1, 2, -3.5]), 1, 1)], Atom("cup"), 9.0)
@example([(Atom("cup"), 2, 1, 0)], None, 5)             # no term: both refuse it alike
def test_bound_prev_equals_the_interpreter(events, key, t):
    # small times, not the wall clock's: a ManualClock (unsynchronized queries)
    with slr_sql.open(clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add_many([("p", (k, v), s, s + d) for k, v, s, d in events])
        for goal in ("prev(p(A, B)^Z, T)", "prev(p(A, B)^[S, E], T)", "prev(p(A, _)^Z, T)",
                     "prev(p(B, A)^Z, T)"):
            args = {"A": key, "T": t}
            want = reference(kb, goal, args)
            for _ in range(2):   # the plan's first use, then the cached plan
                assert answered(kb, goal, args) == want, goal


def test_bound_prev_with_constants_and_the_time_in_the_answer():
    with slr_sql.open(clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add_many(["p(a, 1, [1.5, 2])^1", "p(a, 2, x)^2", "p(a, 1, \"s\")^[2, 3]"])
        # a point stamp Z: point events only (the interval [2, 3] is not one)
        assert kb.query("prev(p(a, N, V)^Z, T)", args={"N": 1, "T": 5}) == \
            [{"N": 1, "V": [1.5, 2], "Z": 1.0, "T": 5}]
        assert kb.query("prev(p(a, N, V)^Z, 2.5)", args={"N": 2}) == \
            [{"N": 2, "V": "x", "Z": 2.0}]
        assert kb.query("prev(p(a, N, V)^[S, E], T)", args={"N": 1, "T": 3}) == \
            [{"N": 1, "V": "s", "S": 2.0, "E": 3.0, "T": 3}]


@pytest.mark.parametrize("text", ["[0.5,1,2.0]", "[]", "[1,\"a\"]", "[[1.0]]", "[1,2] ",
                                  "cup", "", "\"hi\"", '{"f":[1,"x"]}', '{"$atom":"[x"}',
                                  '{".":[1,"b"]}', "[1e400]"])
def test_decode_answer_is_to_python_of_decode(text):
    assert repr(decode_answer(text)) == repr(to_python(decode(text)))


def test_another_connection_loading_a_program_is_seen(db_path):
    with slr_sql.open(db_path, clock=slr_sql.ManualClock(0.0)) as kb, \
            slr_sql.open(db_path, clock=slr_sql.ManualClock(0.0)) as other:
        kb.add_many(["p(a, 1)^1", "p(a, 2)^2"])
        goal = "prev(p(A, B)^Z, T)"
        assert kb.query(goal, args={"A": "a", "T": 5}) == [{"A": "a", "B": 2, "Z": 2.0, "T": 5}]
        other.load("q(1).")
        # the same cached plan: the lookup's statement reads the program version with its
        # rows, sees it moved, and the kb re-reads the program before answering
        assert kb.query(goal, args={"A": "a", "T": 1.5}) == [{"A": "a", "B": 1, "Z": 1.0,
                                                              "T": 1.5}]
        assert kb.query("q(X)") == [{"X": 1}]
        other.add("p(a, 3)^3")
        assert kb.query(goal, args={"A": "a", "T": 5}) == [{"A": "a", "B": 3, "Z": 3.0, "T": 5}]


def test_another_connections_mark_is_seen_by_a_bound_prev(db_path):
    """A synchronized query waits for p to be complete; another connection marks it; the
    next bound prev of this knowledge base notices the progress and releases the query."""
    with slr_sql.open(db_path, clock=slr_sql.ManualClock(0.0)) as kb, \
            slr_sql.open(db_path, clock=slr_sql.ManualClock(0.0)) as other:
        kb.add_many(["p(a, 1)^1", "s(b)^1"])
        goal = "prev(p(A, B)^Z, T)"
        assert kb.query(goal, args={"A": "a", "T": 5}) == [{"A": "a", "B": 1, "Z": 1.0, "T": 5}]
        pending = kb.submit("prev(s(X)^Z, 4)")
        assert not pending.done()
        other.mark_complete("s/1", 10)
        assert kb.query(goal, args={"A": "a", "T": 5}) == [{"A": "a", "B": 1, "Z": 1.0, "T": 5}]
        assert pending.result(timeout=10) == [{"X": "b", "Z": 1.0}]


def test_another_connections_mark_is_seen_when_nothing_matches(db_path):
    with slr_sql.open(db_path, clock=slr_sql.ManualClock(0.0)) as kb, \
            slr_sql.open(db_path, clock=slr_sql.ManualClock(0.0)) as other:
        kb.add_many(["p(a, 1)^1", "s(b)^1"])
        goal = "prev(p(A, B)^Z, T)"
        assert kb.query(goal, args={"A": "zz", "T": 5}) == []
        pending = kb.submit("prev(s(X)^Z, 4)")
        other.mark_complete("s/1", 10)
        assert kb.query(goal, args={"A": "zz", "T": 5}) == []
        assert pending.result(timeout=10) == [{"X": "b", "Z": 1.0}]


def test_bound_prev_on_each_backend_equals_the_interpreter(backend):
    """On PostgreSQL the lookup's rows come back in its typed columns and are converted to
    the stored form (the dialect's from_column) before they are decoded."""
    events = [(Atom("cup"), make_list([0.1, 2, -3.5]), 1, 0), (Atom("cup"), 1, 2, 0),
              (Atom("[x"), String("s"), 2, 0), (1, Struct(Atom("f"), (1, Atom("x"))), 3, 0),
              (1.0, Atom("[]"), 4, 1)]
    with slr_sql.open(backend, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add_many([("p", (k, v), s, s + d) for k, v, s, d in events])
        for key in ("cup", "[x", 1, 1.0, "none"):
            for goal in ("prev(p(A, B)^Z, T)", "prev(p(A, B)^[S, E], T)"):
                args = {"A": key, "T": 9}
                want = reference(kb, goal, args)
                for _ in range(2):   # the plan's first use, then the cached plan
                    assert answered(kb, goal, args) == want, (goal, key)
