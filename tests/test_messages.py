"""Message terms (SPEC §9, docs/ros.md "Messages: fields by name"): a compound named by a
message type whose arguments are ``Name: Value`` is stored as a JSON object of its fields
(SQL reads them by name), decodes back to the same term, is read in SLR with get_field/3,
and gives the same answers through the SQL compiler as through the interpreter."""
from __future__ import annotations

import pytest
from hypothesis import given, settings, strategies as st

import slr_sql
from slr_sql import Atom, ManualClock, SLREvaluationError, SLRError, String, Struct
from slr_sql.encoding import decode, encode, encode_json
from slr_sql.terms import make_list


def message(msgtype: str, **fields) -> Struct:
    return Struct(msgtype, tuple(Struct(":", (Atom(k), v)) for k, v in fields.items()))


names = st.sampled_from(["x", "y", "data", "frame_id", "header", "pose", "stamp", "k_1"])
leaves = st.one_of(st.floats(allow_nan=False, allow_infinity=False), st.integers(-2**63, 2**63 - 1),
                   st.sampled_from([Atom("map"), Atom("[x"), Atom("[]"), String("s"), Atom("")]))


def terms(depth: int = 3):
    if depth == 0:
        return leaves
    inner = terms(depth - 1)
    return st.one_of(
        leaves,
        st.lists(inner, max_size=3).map(make_list),
        st.builds(lambda t, fields: message(t, **dict(fields)),
                  st.sampled_from(["geometry_msgs/msg/Point", "a/b", "std_msgs/msg/Header"]),
                  st.lists(st.tuples(names, inner), min_size=1, max_size=4,
                           unique_by=lambda f: f[0])),
        st.builds(lambda n, args: Struct(n, tuple(args)), st.sampled_from(["f", "p/q", ":"]),
                  st.lists(inner, min_size=1, max_size=3)))


@settings(max_examples=300, deadline=None)
@given(terms())
def test_every_term_round_trips_through_the_column_encoding(term):
    assert decode(encode(term)) == term
    assert encode(decode(encode(term))) == encode(term)


def test_a_message_is_an_object_of_its_fields():
    point = message("geometry_msgs/msg/Point", x=1.0, y=2, z=Atom("m"))
    assert encode(point) == '{"$type":"geometry_msgs/msg/Point","x":1.0,"y":2,"z":"m"}'
    assert encode_json(make_list([point])) == '[' + encode(point) + ']'
    # not messages: no "/" in the name, a key twice, a key that is not an atom or starts with $
    assert encode(message("point", x=1)) == '{"point":[{":":["x",1]}]}'
    twice = Struct("a/b", (Struct(":", (Atom("x"), 1)), Struct(":", (Atom("x"), 2))))
    assert encode(twice).startswith('{"a/b":[')
    assert encode(Struct("a/b", (Struct(":", (1, 2)),))).startswith('{"a/b":[')
    assert encode(message("a/b", **{"$type": 1})).startswith('{"a/b":[')


PROGRAM = """
goal_x(X) :- goal(M)^_, M = 'geometry_msgs/msg/PointStamped'(_, point: P),
             P = 'geometry_msgs/msg/Point'(x: X, _, _).
same(A, B) :- goal(A)^T1, goal(B)^T2, T1 < T2, A = B.
frames(F) :- goal(M)^_, get_field(M, 'header.frame_id', F).
first_point(P) :- goal(M)^_, M = 'geometry_msgs/msg/PointStamped'(_, P).
"""


def goal_message(frame: str, x: float) -> Struct:
    return message("geometry_msgs/msg/PointStamped",
                   header=message("std_msgs/msg/Header", stamp=1.5, frame_id=Atom(frame)),
                   point=message("geometry_msgs/msg/Point", x=x, y=0.0, z=0.0))


@pytest.mark.parametrize("goal", ["goal_x(X)", "same(A, B)", "frames(F)", "first_point(P)",
                                  "goal(M)^T", "goal(M)^T, M = f(_)",
                                  "goal(M)^T, M = 'geometry_msgs/msg/PointStamped'(_, _, _)",
                                  "findall(M, goal(M)^_, L)"])
def test_the_sql_compiler_and_the_interpreter_agree_on_message_terms(goal):
    answers = {}
    for sql in (True, False):
        with slr_sql.open(None, clock=ManualClock(100.0)) as kb:
            kb.sql_enabled = sql
            kb.load(PROGRAM)
            kb.add_many([("goal", (goal_message("map", 1.0),), 1.0, 1.0),
                         ("goal", (goal_message("odom", 2.0),), 2.0, 2.0),
                         ("goal", (goal_message("map", 1.0),), 3.0, 3.0)])
            answers[sql] = kb.query(goal)
    assert answers[True] == answers[False]
    assert answers[True] or "f(_)" in goal or "(_, _, _)" in goal


def test_buffer_patterns_refuse_to_look_inside_messages():
    with slr_sql.open(None, clock=ManualClock(100.0)) as kb, pytest.raises(SLRError, match="message type"):
        kb.load("cBuffer(goal('geometry_msgs/msg/PointStamped'(_, point: P)), 1).")
    with slr_sql.open(None, clock=ManualClock(100.0)) as kb:
        kb.load("cBuffer(goal(_), 1).")     # the message as a whole is fine
        kb.add_many([("goal", (goal_message("map", float(i)),), float(i), float(i))
                     for i in range(3)])
        assert len(kb.query("goal(M)^T")) == 1


@pytest.mark.parametrize("goal, error", [
    ("get_field(M, x, V)", "instantiation_error"),
    ("get_field(f(1), x, V)", "type_error(message,f(1))"),
    ("get_field('a/b'(x:1), 'x..y', V)", "domain_error(field_path"),
    ("get_field('a/b'(x:1), [x, 1.5], V)", "domain_error(field_path"),
])
def test_get_field_errors(goal, error):
    with slr_sql.open(None, clock=ManualClock(100.0)) as kb, pytest.raises(SLREvaluationError) as info:
        kb.query(goal)
    assert error in str(info.value).replace(" ", "")


@pytest.mark.parametrize("goal, answers", [
    ("get_field('a/b'(x:1, y:'c/d'(z:[5, 6])), 'y.z[1]', V)", [{"V": 6}]),
    ("get_field('a/b'(x:1, y:'c/d'(z:[5, 6])), 'y.z[-1]', V)", [{"V": 6}]),
    ("get_field('a/b'(x:1, y:'c/d'(z:[5, 6])), 'y.z[2]', V)", []),
    ("get_field('a/b'(x:1), nope, V)", []),
    ("get_field('a/b'(x:1), 'x.deeper', V)", []),
    ("get_field('a/b'(x:1, y:2), K, V)", [{"K": "x", "V": 1}, {"K": "y", "V": 2}]),
    ("get_field('a/b'(x:1, y:2), y, 2)", [{}]),
])
def test_get_field(goal, answers):
    with slr_sql.open(None, clock=ManualClock(100.0)) as kb:
        assert kb.query(goal) == answers
