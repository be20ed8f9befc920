"""Tests for slr_sql.robotlib: interpolation, pose composition and distances."""
from __future__ import annotations

import math

import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from slr_sql.robotlib import (
    RobotValueError, distance, extrapolate, interpolate, make_pose, pos_multiply,
    quat_multiply, quat_normalize, quat_rotate, slerp, value_kind,
)
from slr_sql.terms import Atom, Struct

import slr_sql

TOL = 1e-9
S = math.sqrt(0.5)
IDENTITY = make_pose([0, 0, 0], [0, 0, 0, 1])


def rot_z(angle: float) -> list[float]:
    return [0.0, 0.0, math.sin(angle / 2), math.cos(angle / 2)]


def close(a, b, tol=1e-7) -> bool:
    if isinstance(a, (int, float)):
        return abs(a - b) <= tol
    return len(a) == len(b) and all(abs(x - y) <= tol for x, y in zip(a, b))


def same_rotation(q1, q2, tol=1e-7) -> bool:
    """Quaternions q and -q are the same rotation."""
    return close(q1, q2, tol) or close(q1, [-c for c in q2], tol)


def assert_pose_close(p1, p2, tol=1e-7):
    assert p1.name == "pose" and p2.name == "pose"
    assert close(p1.args[0], p2.args[0], tol), (p1, p2)
    assert same_rotation(p1.args[1], p2.args[1], tol), (p1, p2)


def norm(q) -> float:
    return math.sqrt(sum(c * c for c in q))


# ---------------------------------------------------------------- strategies

coord = st.floats(-100, 100, allow_nan=False, allow_infinity=False)
point = st.lists(coord, min_size=3, max_size=3)


@st.composite
def unit_quat(draw):
    q = draw(st.lists(st.floats(-1, 1, allow_nan=False), min_size=4, max_size=4))
    assume(norm(q) > 0.1)
    return list(quat_normalize(q))


@st.composite
def pose(draw):
    return make_pose(draw(point), draw(unit_quat()))


# ---------------------------------------------------------------- doctests


# (the examples run, and each public function has one: tests/test_doctests.py, for every
# module of the package)


# ---------------------------------------------------------------- quaternions


def test_rotate_90_about_z():
    assert close(quat_rotate([0, 0, S, S], [1, 0, 0]), [0, 1, 0])
    assert close(quat_rotate([0, 0, S, S], [0, 1, 0]), [-1, 0, 0])
    assert close(quat_rotate([0, 0, S, S], [0, 0, 1]), [0, 0, 1])


def test_rotate_180_about_x():
    assert close(quat_rotate([1, 0, 0, 0], [0, 1, 2]), [0, -1, -2])


def test_rotate_normalizes_quaternion():
    assert close(quat_rotate([0, 0, 3, 3], [1, 0, 0]), [0, 1, 0])


def test_quat_multiply_composes_rotations():
    # two 90° turns about z = 180° about z
    q = quat_multiply([0, 0, S, S], [0, 0, S, S])
    assert same_rotation(q, [0, 0, 1, 0])
    # Hamilton convention: i*j = k
    assert close(quat_multiply([1, 0, 0, 0], [0, 1, 0, 0]), [0, 0, 1, 0])


@given(unit_quat(), unit_quat(), point)
def test_quat_multiply_matches_sequential_rotation(q1, q2, v):
    assert close(quat_rotate(quat_multiply(q1, q2), v), quat_rotate(q1, quat_rotate(q2, v)), 1e-6)


@given(unit_quat(), point)
def test_rotation_preserves_length(q, v):
    assert math.isclose(norm(quat_rotate(q, v)), norm(v), rel_tol=1e-9, abs_tol=1e-9)


def test_zero_quaternion_raises():
    with pytest.raises(RobotValueError):
        quat_normalize([0, 0, 0, 0])
    with pytest.raises(RobotValueError):
        pos_multiply([1, 2, 3], [make_pose([0, 0, 0], [0, 0, 0, 0])])


# ---------------------------------------------------------------- slerp


def test_slerp_halfway_is_45_degrees():
    q = slerp([0, 0, 0, 1], rot_z(math.pi / 2), 0.5)
    assert close(q, rot_z(math.pi / 4))


def test_slerp_shortest_path():
    # -q2 is the same rotation; slerp must still go the short way (45°, not 135°)
    q = slerp([0, 0, 0, 1], [-c for c in rot_z(math.pi / 2)], 0.5)
    assert same_rotation(q, rot_z(math.pi / 4))


def test_slerp_nearly_parallel_uses_nlerp():
    q = slerp([0, 0, 0, 1], rot_z(1e-6), 0.5)
    assert close(q, rot_z(0.5e-6), 1e-9)
    assert math.isclose(norm(q), 1.0, abs_tol=1e-12)


def test_slerp_extrapolates():
    q = slerp([0, 0, 0, 1], rot_z(math.pi / 4), 2.0)
    assert same_rotation(q, rot_z(math.pi / 2))
    q = slerp([0, 0, 0, 1], rot_z(math.pi / 4), -1.0)
    assert same_rotation(q, rot_z(-math.pi / 4))


@given(unit_quat(), unit_quat())
def test_slerp_endpoints(q1, q2):
    assert same_rotation(slerp(q1, q2, 0.0), q1, 1e-6)
    assert same_rotation(slerp(q1, q2, 1.0), q2, 1e-6)


@given(unit_quat(), unit_quat(), st.floats(-2, 3, allow_nan=False))
def test_slerp_unit_norm(q1, q2, s):
    assert math.isclose(norm(slerp(q1, q2, s)), 1.0, abs_tol=1e-9)


@given(unit_quat(), unit_quat(), st.floats(0, 1))
def test_slerp_angle_is_proportional(q1, q2, s):
    """The rotation from q1 to slerp(s) is s times the (shortest) rotation from q1 to q2."""
    def angle(a, b):
        d = abs(sum(x * y for x, y in zip(a, b)))
        return 2 * math.acos(min(1.0, d))
    total = angle(q1, q2)
    assume(total > 1e-3)
    assert math.isclose(angle(q1, slerp(q1, q2, s)), s * total, abs_tol=1e-5)


# ---------------------------------------------------------------- interpolate / extrapolate


def test_interpolate_numbers():
    assert interpolate(1.5, 10, 1, 20, 2) == 15.0
    assert interpolate(1, 10, 1, 20, 2) == 10.0
    assert interpolate(2, 10, 1, 20, 2) == 20.0
    assert interpolate(3, 10, 1, 20, 2) == 30.0   # extrapolation past t2
    assert interpolate(0, 10, 1, 20, 2) == 0.0    # extrapolation before t1


def test_interpolate_vectors():
    assert close(interpolate(0.25, [0, 0, 0], 0, [4, -8, 2], 1), [1, -2, 0.5])


def test_interpolate_equal_times_gives_v1():
    assert interpolate(5, 1.0, 3, 2.0, 3) == 1.0
    assert interpolate(5, [1, 2], 3, [7, 8], 3) == [1, 2]
    p = make_pose([1, 2, 3], [0, 0, 0, 1])
    assert interpolate(5, p, 3, IDENTITY, 3) is p


def test_interpolate_pose_halfway():
    p1 = make_pose([0, 0, 0], [0, 0, 0, 1])
    p2 = make_pose([2, 4, -6], rot_z(math.pi / 2))
    r = interpolate(10.5, p1, 10, p2, 11)
    assert isinstance(r, Struct) and r.name == "pose"
    assert close(r.args[0], [1, 2, -3])
    assert close(r.args[1], rot_z(math.pi / 4))


def test_interpolate_pose_extrapolates():
    p1 = make_pose([0, 0, 0], [0, 0, 0, 1])
    p2 = make_pose([1, 0, 0], rot_z(math.pi / 4))
    r = interpolate(2, p1, 0, p2, 1)
    assert_pose_close(r, make_pose([2, 0, 0], rot_z(math.pi / 2)))


def test_interpolate_accepts_atom_named_pose():
    p1 = Struct(Atom("pose"), ([0, 0, 0], [0, 0, 0, 1]))
    p2 = Struct(Atom("pose"), ([2, 0, 0], [0, 0, 0, 1]))
    assert close(interpolate(0.5, p1, 0, p2, 1).args[0], [1, 0, 0])


@given(pose(), pose(), st.floats(0, 1))
def test_interpolated_pose_rotation_is_unit(p1, p2, s):
    r = interpolate(s, p1, 0.0, p2, 1.0)
    assert math.isclose(norm(r.args[1]), 1.0, abs_tol=1e-9)


@given(pose(), pose())
def test_interpolate_pose_endpoints(p1, p2):
    assert_pose_close(interpolate(0.0, p1, 0.0, p2, 1.0), p1, 1e-6)
    assert_pose_close(interpolate(1.0, p1, 0.0, p2, 1.0), p2, 1e-6)


@pytest.mark.parametrize("v1,v2", [
    (1, [1, 2]),
    ([1, 2], IDENTITY),
    (1.0, IDENTITY),
    ([1, 2], [1, 2, 3]),
    ("cup", 1),
    (Struct("pose", ([0, 0], [0, 0, 0, 1])), IDENTITY),
    (Struct("pose", ([0, 0, 0], [0, 0, 1])), IDENTITY),
    (Struct("foo", ([0, 0, 0], [0, 0, 0, 1])), IDENTITY),
    ([1, "a"], [1, 2]),
    (True, 1),
])
def test_interpolate_bad_kinds_raise(v1, v2):
    with pytest.raises(RobotValueError):
        interpolate(0.5, v1, 0, v2, 1)
    with pytest.raises(ValueError):  # RobotValueError is a ValueError
        interpolate(0.5, v2, 0, v1, 1)


def test_interpolate_bad_time_raises():
    with pytest.raises(RobotValueError):
        interpolate("now", 1, 0, 2, 1)


def test_extrapolate_holds_value():
    p = make_pose([1, 2, 3], [0, 0, 0, 1])
    assert extrapolate(p) is p
    assert extrapolate(3.5) == 3.5


# ---------------------------------------------------------------- pos_multiply


@given(point)
def test_pos_multiply_identity_point(p):
    assert close(pos_multiply(p, [IDENTITY]), p, 1e-12)
    assert close(pos_multiply(p, []), p, 0)


@given(pose())
def test_pos_multiply_identity_pose(p):
    assert_pose_close(pos_multiply(p, [IDENTITY]), p, 1e-12)


def test_pos_multiply_known_values():
    # rotate 90° about z then translate by (0,0,5)
    a = make_pose([0, 0, 5], [0, 0, S, S])
    assert close(pos_multiply([1, 0, 0], [a]), [0, 1, 5])
    # then translate by (10, 0, 0): B·(A·P), not A·(B·P)
    b = make_pose([10, 0, 0], [0, 0, 0, 1])
    assert close(pos_multiply([1, 0, 0], [a, b]), [10, 1, 5])
    assert close(pos_multiply([1, 0, 0], [b, a]), [0, 11, 5])


def test_pos_multiply_pose_composes_rotation():
    a = make_pose([1, 0, 0], rot_z(math.pi / 2))
    p = make_pose([1, 0, 0], rot_z(math.pi / 2))
    r = pos_multiply(p, [a])
    assert_pose_close(r, make_pose([1, 1, 0], rot_z(math.pi)))


def test_pos_multiply_camera_to_world():
    """Paper example shape: pos_multiply([RelPos, CamToBase, BaseToWorld], WorldPos)."""
    cam_to_base = make_pose([0, 0, 1.5], [0, 0, 0, 1])            # camera 1.5 m above base
    base_to_world = make_pose([3, 4, 0], rot_z(math.pi))         # base at (3,4) facing -x
    world = pos_multiply([2, 0, 0], [cam_to_base, base_to_world])
    assert close(world, [1, 4, 1.5])


@given(point, pose(), pose())
def test_pos_multiply_associative_point(p, a, b):
    r1 = pos_multiply(p, [a, b])
    r2 = pos_multiply(pos_multiply(p, [a]), [b])
    assert close(r1, r2, 1e-6)


@given(pose(), pose(), pose())
def test_pos_multiply_associative_pose(p, a, b):
    assert_pose_close(pos_multiply(p, [a, b]), pos_multiply(pos_multiply(p, [a]), [b]), 1e-6)


@given(pose(), point)
def test_pose_result_acts_as_transform(p, x):
    """pos_multiply(x, [P, A]) == pos_multiply(x, [A·P]) where A·P is computed by pos_multiply."""
    a = make_pose([1, -2, 3], rot_z(0.7))
    composed = pos_multiply(p, [a])
    assert close(pos_multiply(x, [p, a]), pos_multiply(x, [composed]), 1e-6)


@given(pose(), pose())
def test_pos_multiply_pose_rotation_is_unit(p, a):
    assert math.isclose(norm(pos_multiply(p, [a]).args[1]), 1.0, abs_tol=1e-9)


@pytest.mark.parametrize("p,ts", [
    ([1, 2], [IDENTITY]),
    (5, [IDENTITY]),
    ([1, 2, 3], [[0, 0, 0]]),
    ([1, 2, 3], IDENTITY),
    ([1, 2, 3], [IDENTITY, 7]),
    (Atom("cup"), [IDENTITY]),
])
def test_pos_multiply_bad_kinds_raise(p, ts):
    with pytest.raises(RobotValueError):
        pos_multiply(p, ts)


# ---------------------------------------------------------------- distance


def test_distance_known_values():
    assert distance([0, 0, 0], [3, 4, 0]) == pytest.approx(5.0)
    assert distance(2, 5) == 3.0
    assert distance(5.5, 2) == 3.5
    assert distance(make_pose([1, 1, 1], [0, 0, 0, 1]),
                    make_pose([1, 1, 3], rot_z(1.0))) == pytest.approx(2.0)


@given(point, point)
def test_distance_symmetric_and_nonnegative(a, b):
    assert distance(a, b) == distance(b, a)
    assert distance(a, b) >= 0


@given(point)
def test_distance_zero_on_equal(a):
    assert distance(a, a) == 0.0
    assert distance(a, list(a)) == 0.0


@given(pose(), pose())
def test_distance_poses_symmetric(p1, p2):
    assert distance(p1, p2) == pytest.approx(distance(p2, p1))
    assert distance(p1, p1) == 0.0


@given(point, point, point)
def test_distance_triangle_inequality(a, b, c):
    assert distance(a, c) <= distance(a, b) + distance(b, c) + 1e-9


@given(point, point, pose())
def test_rigid_transform_preserves_distance(a, b, t):
    d = distance(pos_multiply(a, [t]), pos_multiply(b, [t]))
    assert math.isclose(d, distance(a, b), rel_tol=1e-9, abs_tol=1e-9)


@pytest.mark.parametrize("a,b", [
    ([0, 0, 0], IDENTITY),
    (1, [1, 2, 3]),
    ([1, 2], [1, 2, 3]),
    ("a", "b"),
])
def test_distance_bad_kinds_raise(a, b):
    with pytest.raises(RobotValueError):
        distance(a, b)


def test_value_kind():
    assert value_kind(3) == "number"
    assert value_kind([1.0, 2]) == "vector"
    assert value_kind(IDENTITY) == "pose"
    with pytest.raises(RobotValueError):
        value_kind(Atom("x"))


@pytest.mark.parametrize("goal, words", [
    ("interpolate([V, 2.5], [pose([0,0,0],[0,0,0,1]), 2], [pose([1,0],[0,0,0,1]), 4])",
     "malformed pose pose([1,0],[0,0,0,1])"),
    ("interpolate([V, 2.5], [pose([0,0,0],[0,0,0,1]), 2], [pose(a,[0,0,0,1]), 4])",
     "malformed pose pose(a,[0,0,0,1])"),
    ("interpolate([V, 2.5], [1, 2], [[1,2], 4])",
     "cannot interpolate between a number (1) and a vector ([1,2])"),
])
def test_a_robot_value_error_shows_the_value_as_prolog_text(goal, words):
    """The value in a robot library error is Prolog text, never Python's repr of a term
    (it said Struct('pose', (Atom('a'), [0, 0, 0, 1])))."""
    kb = slr_sql.open()
    with pytest.raises(slr_sql.SLRError) as caught:
        kb.query(goal)
    assert words in str(caught.value) and "Struct(" not in str(caught.value)
    kb.close()
