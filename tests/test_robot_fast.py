"""pos_multiply's fast path gives exactly the results of the general implementation.

``robotlib.pos_multiply`` does its common case (plain numbers, well-formed poses) inline and
the ``pos_multiply/2`` builtin reads points and poses straight from the terms; both must
return the same floats, bit for bit, as the implementation they replace -- kept here as
``reference_pos_multiply``, built from the library's validating quaternion helpers -- and
fall back to the same errors for anything else.
"""
from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

import slr_sql
from slr_sql import robotlib
from slr_sql.robotlib import (RobotValueError, make_pose, pos_multiply, quat_multiply,
                              quat_normalize, quat_rotate)
from slr_sql.builtins import _pos_multiply_terms
from slr_sql.terms import Struct, from_python, to_python


def reference_pos_multiply(p, transforms):
    """The implementation before the fast path: every step through the checked helpers."""
    parts = [([float(c) for c in a.args[0]], quat_normalize(a.args[1])) for a in transforms]
    if isinstance(p, Struct):
        t, q = [float(c) for c in p.args[0]], quat_normalize(p.args[1])
        for ta, qa in parts:
            r = quat_rotate(qa, t)
            t, q = [a + b for a, b in zip(ta, r)], quat_normalize(quat_multiply(qa, q))
        return make_pose(t, q)
    x = [float(c) for c in p]
    for ta, qa in parts:
        r = quat_rotate(qa, x)
        x = [a + b for a, b in zip(ta, r)]
    return x


number = st.one_of(st.floats(-1e6, 1e6, allow_nan=False), st.integers(-1000, 1000))
quat_part = st.one_of(st.floats(-10, 10, allow_nan=False), st.integers(-3, 3))
point = st.lists(number, min_size=3, max_size=3)
quaternion = st.lists(quat_part, min_size=4, max_size=4).filter(
    lambda q: 1e-6 < math.sqrt(sum(float(c) ** 2 for c in q)) < 1e6)
pose = st.builds(lambda t, q: Struct("pose", (t, q)), point, quaternion)


def as_floats(value):
    """A result as plain nested floats, to compare exactly (a pose as two lists)."""
    if isinstance(value, Struct):
        return ("pose", list(value.args[0]), list(value.args[1]))
    return list(value)


@given(st.one_of(point, pose), st.lists(pose, max_size=4))
def test_fast_path_equals_reference_exactly(p, transforms):
    expected = reference_pos_multiply(p, transforms)
    got = pos_multiply(p, transforms)
    assert as_floats(got) == as_floats(expected)
    assert all(type(c) is float for c in (got if isinstance(got, list) else got.args[0]))
    assert robotlib.pos_multiply_fast(p, transforms) is not None   # the fast path ran


@given(st.one_of(point, pose), st.lists(pose, min_size=1, max_size=3))
def test_builtin_from_terms_equals_reference_exactly(p, transforms):
    kb = slr_sql.open()
    answers = kb.query("pos_multiply([P | Ts], R)", args={"P": p, "Ts": transforms})
    assert len(answers) == 1
    expected = reference_pos_multiply(p, transforms)
    assert as_floats(answers[0]["R"]) == as_floats(expected)
    # the builtin read the terms directly (no to_python / from_python round trip)
    items = [from_python(p)] + [from_python(t) for t in transforms]
    assert to_python(_pos_multiply_terms(items)) == to_python(from_python(expected))


@pytest.mark.parametrize("p, transforms, message", [
    ([1, 2, 3], [make_pose([0, 0, 0], [0, 0, 0, 0])], "cannot normalize"),
    ([1, 2], [make_pose([0, 0, 0], [0, 0, 0, 1])], "first element must be a point"),
    ([1, 2, 3], [Struct("pose", ([0, 0], [0, 0, 0, 1]))], "transform #1"),
    ([1, True, 3], [], "first element must be a point"),
    ([1, 2, 3], "no list", "list of pose transforms"),
])
def test_malformed_values_keep_the_general_errors(p, transforms, message):
    assert robotlib.pos_multiply_fast(p, transforms) is None
    with pytest.raises(RobotValueError, match=message):
        pos_multiply(p, transforms)


def test_builtin_malformed_pose_is_the_same_domain_error():
    kb = slr_sql.open()
    with pytest.raises(slr_sql.SLRError, match="cannot normalize"):
        kb.query("pos_multiply([[1, 2, 3], pose([0, 0, 0], [0, 0, 0, 0])], R)")
    with pytest.raises(slr_sql.SLRError, match="transform #1"):
        kb.query("pos_multiply([[1, 2, 3], pose([0, 0], [0, 0, 0, 1])], R)")


def exact(value):
    """A result's floats as hex text: equal only when bit for bit equal (-0.0 is not 0.0)."""
    if isinstance(value, Struct):
        return ("pose", [float.hex(c) for c in value.args[0]],
                [float.hex(c) for c in value.args[1]])
    return [float.hex(c) for c in value]


@given(st.one_of(point, pose), st.lists(pose, max_size=4))
def test_transforms_worked_out_once_move_as_pos_multiply_does(p, transforms):
    # event rules read each stored pose once into a transform (pose_transform) and apply it
    # to many points: the same floats as the reference, applied once or again
    parts = [robotlib.pose_transform(*a.args) for a in transforms]
    subject = robotlib.pos_multiply_subject(p)
    assert subject is not None and None not in parts
    got = robotlib.apply_transforms(subject, parts)
    assert exact(got) == exact(reference_pos_multiply(p, transforms))
    assert exact(robotlib.apply_transforms(subject, parts)) == exact(got)
    assert exact(robotlib.pos_multiply_fast(p, transforms)) == exact(got)


@pytest.mark.parametrize("translation, rotation", [
    ([0, 0], [0, 0, 0, 1]), ([0, 0, 0], [0, 0, 0, 0]), ([0, 0, True], [0, 0, 0, 1]),
    ([0, 0, 0], [0, 0, 0, math.inf]), ("abc", [0, 0, 0, 1]), ([0, 0, 0], None),
])
def test_a_transform_that_is_not_plain_is_left_to_the_general_path(translation, rotation):
    assert robotlib.pose_transform(translation, rotation) is None
