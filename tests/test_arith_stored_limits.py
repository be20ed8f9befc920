"""Infinities, overflow and signed zeros in arithmetic over stored events, on both backends
and both of slr_sql's paths (the compiled SQL plan and the interpreter), against a live
SWI-Prolog given the same values as a list.

Stored (in this time order): ``r(1.0e308)^1, r(inf)^2, r(-inf)^3`` (floats: the Python API
stores a float infinity; SLR text would store the atom ``inf``), ``z(-0.0)^1, z(0.0)^2``,
``y(0.0)^1, y(-0.0)^2``. A time ``T`` is 1.0, 2.0 or 3.0: ``T * 0.6e308`` overflows at the
third event only, in SQL's own float arithmetic (the compiled plan computes float ``+ - *`` of
times natively) as in Prolog's.
"""
from __future__ import annotations

import math

import pytest
import test_swi_differential as swidiff

import slr_sql
from slr_sql.errors import SLREvaluationError

EVENTS = [("r", [1.0e308], 1.0, 1.0), ("r", [math.inf], 2.0, 2.0), ("r", [-math.inf], 3.0, 3.0),
          ("z", [-0.0], 1.0, 1.0), ("z", [0.0], 2.0, 2.0),
          ("y", [0.0], 1.0, 1.0), ("y", [-0.0], 2.0, 2.0)]

R = "member(X-T, [1.0e308-1.0, 1.0Inf-2.0, -1.0Inf-3.0])"

# goal over the stored events -> the same goal over the same values in SWI-Prolog
GOALS = {
    # -0.0 and 0.0: max takes 0.0, min -0.0, whichever comes first
    "aggregate_all(max(X), z(X)^_, M)": "aggregate_all(max(X), member(X, [-0.0, 0.0]), M)",
    "aggregate_all(min(X), z(X)^_, M)": "aggregate_all(min(X), member(X, [-0.0, 0.0]), M)",
    "aggregate_all(max(X), y(X)^_, M)": "aggregate_all(max(X), member(X, [0.0, -0.0]), M)",
    "aggregate_all(min(X), y(X)^_, M)": "aggregate_all(min(X), member(X, [0.0, -0.0]), M)",
    "z(X)^_, y(Y)^_, M is max(X, Y)":
        "member(X, [-0.0, 0.0]), member(Y, [0.0, -0.0]), M is max(X, Y)",
    "z(X)^_, y(Y)^_, M is min(X, Y)":
        "member(X, [-0.0, 0.0]), member(Y, [0.0, -0.0]), M is min(X, Y)",
    # -0.0 and 0.0 written in the goal are two values (two parameters of the statement)
    "aggregate_all(max(X), (z(_)^_, (X = -0.0 ; X = 0.0)), M)":
        "aggregate_all(max(X), (member(_, [-0.0, 0.0]), (X = -0.0 ; X = 0.0)), M)",
    "aggregate_all(min(X), (y(_)^_, (X = 0.0 ; X = -0.0)), M)":
        "aggregate_all(min(X), (member(_, [0.0, -0.0]), (X = 0.0 ; X = -0.0)), M)",
    "z(X)^_, (Y = -0.0 ; Y = 0.0), M is max(Y, X)":
        "member(X, [-0.0, 0.0]), (Y = -0.0 ; Y = 0.0), M is max(Y, X)",
    # a stored infinity in arithmetic: + is checked, -, abs and max pass it on
    "r(X)^_, Y is X + 1": f"{R}, Y is X + 1",
    "r(X)^_, Y is X * 0": f"{R}, Y is X * 0",
    "r(X)^_, Y is -X": f"{R}, Y is -X",
    "r(X)^_, Y is abs(X)": f"{R}, Y is abs(X)",
    "r(X)^_, Y is max(X, 1)": f"{R}, Y is max(X, 1)",
    "r(X)^_, Y is float(X)": f"{R}, Y is float(X)",
    "r(X)^_, Y is X / 2": f"{R}, Y is X / 2",
    "r(X)^_, Y is 1 / X": f"{R}, Y is 1 / X",
    "r(X)^_, X > 1": f"{R}, X > 1",
    "r(X)^_, X =:= inf": f"{R}, X =:= inf",
    "aggregate_all(sum(X), r(X)^_, S)": f"aggregate_all(sum(X), {R}, S)",
    "aggregate_all(max(X), r(X)^_, M)": f"aggregate_all(max(X), {R}, M)",
    "aggregate_all(min(X), r(X)^_, M)": f"aggregate_all(min(X), {R}, M)",
    "aggregate_all(count, r(X)^_, N)": f"aggregate_all(count, {R}, N)",
    "aggregate_all(bag(X), r(X)^_, L)": f"aggregate_all(bag(X), {R}, L)",
    # a finite time overflowing in float arithmetic (SQL's native + - * on the compiled path)
    "r(_)^T, Y is T * 0.6e308": f"{R}, Y is T * 0.6e308",
    "r(_)^T, Y is T * 0.6e308 - T * 0.6e308": f"{R}, Y is T * 0.6e308 - T * 0.6e308",
    "r(_)^T, Y is max(T * 0.6e308, 0)": f"{R}, Y is max(T * 0.6e308, 0)",
    "r(_)^T, Y is -(T * 0.6e308 + 1.0)": f"{R}, Y is -(T * 0.6e308 + 1.0)",
    "r(_)^T, T * 0.6e308 > 1.0": f"{R}, T * 0.6e308 > 1.0",
    "r(_)^T, Y is T * 0.6e308, Y > 1.0": f"{R}, Y is T * 0.6e308, Y > 1.0",
    "aggregate_all(sum(Y), (r(_)^T, Y is T * 0.6e308), S)":
        f"aggregate_all(sum(Y), ({R}, Y is T * 0.6e308), S)",
    "aggregate_all(max(Y), (r(_)^T, Y is T * 0.6e308), M)":
        f"aggregate_all(max(Y), ({R}, Y is T * 0.6e308), M)",
    "aggregate_all(count, (r(_)^T, Y is T * 0.6e308), N)":
        f"aggregate_all(count, ({R}, Y is T * 0.6e308), N)",
}


@pytest.fixture(scope="module")
def swipl():
    with swidiff.live_swipl() as s:
        yield s


@pytest.fixture
def kb(backend):
    with slr_sql.open(backend, clock=slr_sql.ManualClock(10)) as kb:
        assert kb.add_many(EVENTS) == []
        yield kb


def outcome(kb, goal: str, names: list[str]):
    """(answers, error) as swidiff compares them, with the answers before the error."""
    answers = []
    try:
        for a in kb.solutions(goal):
            answers.append(swidiff.slr_answer(a, names))
        return answers, None
    except SLREvaluationError as exc:
        return answers, swidiff.canonical_error(exc.term)


@pytest.mark.parametrize("goal", sorted(GOALS))
def test_stored_values_compute_as_in_swipl(swipl, kb, goal):
    example = swidiff.builtin_example(GOALS[goal])
    theirs = swipl.run(example[2])[0]
    names = [n for n in example[3][0][2] if n in goal]
    expected = ([swidiff.swi_answer(a, example[3][0][2]) for a in theirs["answers"]],
                None if theirs["error"] is None else swidiff.from_swi(theirs["error"], {}))
    expected = ([{n: v for n, v in a.items() if n in names} for a in expected[0]], expected[1])
    kb.sql_enabled = False
    assert outcome(kb, goal, names) == expected
    # the compiled plan: the same answers, or the same error (a statement that raises
    # delivers none of its rows, as in tests/test_swi_differential.py)
    kb.sql_enabled = True
    answers, error = outcome(kb, goal, names)
    assert (error, answers if error is None else None) == \
        (expected[1], expected[0] if expected[1] is None else None), kb.explain(goal)


# prev/next (no SWI-Prolog builtins): a time bound that overflows raises as `is` would, on
# the compiled path as in the interpreter (SQLite's own arithmetic made it an infinity: the
# window reached the end of time)
WINDOW_GOALS = [
    "r(_)^T, next(r(X)^Z, [T, T * 0.6e308])",
    "r(_)^T, prev(r(X)^Z, T * 0.6e308)",
    "aggregate_all(count, (r(_)^T, next(r(X)^Z, [T, T * 0.6e308])), N)",
]


@pytest.mark.parametrize("goal", WINDOW_GOALS)
def test_an_overflowing_time_bound_raises_on_both_paths(kb, goal):
    names = ["X", "Z", "T", "N"]
    kb.sql_enabled = False
    interpreted = outcome(kb, goal, names)
    assert interpreted[1] is not None   # the third event's bound, 1.8e308, overflows
    kb.sql_enabled = True
    assert outcome(kb, goal, names)[1] == interpreted[1], kb.explain(goal)
