"""Red team of tf_lookup (docs/language.md, "tf_lookup"): stored transforms with infinite
coordinates, huge coordinates whose interpolation or chain overflows, and quaternions too
large or too small to square. A lookup gives a pose of finite numbers with a unit quaternion,
fails, or raises ``evaluation_error(float_overflow)`` as ``is`` does; never NaN."""
from __future__ import annotations

import math

import pytest

import slr_sql
from slr_sql import ManualClock, SLREvaluationError, Struct
from slr_sql.robotlib import slerp

S = math.sqrt(0.5)


def pose(p, q) -> Struct:
    return Struct("pose", (list(p), list(q)))


def store(*events):
    kb = slr_sql.open(clock=ManualClock(100.0))
    kb.add_many([("tf", (parent, child, pose(p, q)), t, t) for parent, child, t, p, q in events])
    return kb


def answer(kb, goal: str):
    rows = kb.query(goal)
    assert len(rows) <= 1
    if not rows:
        return None
    (x, y, z), q = rows[0]["P"].args
    return [x, y, z], list(q)


def assert_finite_unit(result) -> None:
    p, q = result
    assert all(math.isfinite(v) for v in p + q), result
    assert math.isclose(sum(c * c for c in q), 1.0, rel_tol=1e-12), result


@pytest.mark.parametrize("bad", [math.inf, -math.inf, 10 ** 400, -(10 ** 400)],
                         ids=["inf", "-inf", "int-beyond-floats", "-int-beyond-floats"])
def test_a_stored_transform_with_an_infinite_coordinate_is_not_a_pose(bad):
    """tf2 refuses such a transform; here the lookup over it fails, both ways (it answered
    [-inf, ..] one way and [nan, nan, nan] the other; an integer beyond any float stopped
    the query with "OverflowError: int too large to convert to float")."""
    with store(("a", "b", 0.0, [bad, 0.0, 0.0], [0, 0, 0, 1]),
               ("a", "b", 2.0, [1.0, 0.0, 0.0], [0, 0, 0, 1]),
               ("c", "d", 0.0, [0.0, 0.0, 0.0], [0, 0, bad, 1])) as kb:
        for goal in ("tf_lookup(a, b, 0, P)", "tf_lookup(b, a, 0, P)",
                     "tf_lookup(a, b, 1, P)", "tf_lookup(b, a, 1, P)",
                     "tf_lookup(c, d, 0, P)", "tf_lookup(d, c, 0, P)"):
            assert answer(kb, goal) is None, goal
        assert answer(kb, "tf_lookup(a, b, 2, P)") == ([1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])


def test_interpolating_between_huge_opposite_translations_gives_the_finite_value():
    with store(("a", "b", 0.0, [1e308, -1e308, 0.0], [0, 0, 0, 1]),
               ("a", "b", 2.0, [-1e308, 1e308, 0.0], [0, 0, 0, 1])) as kb:
        ahead = answer(kb, "tf_lookup(a, b, 1, P)")
        assert ahead == ([0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])
        quarter = answer(kb, "tf_lookup(a, b, 0.5, P)")
        assert quarter[0] == pytest.approx([5e307, -5e307, 0.0])
        back = answer(kb, "tf_lookup(b, a, 0.5, P)")
        assert_finite_unit(back)
        assert back[0] == pytest.approx([-5e307, 5e307, 0.0])


def test_a_chain_that_overflows_is_a_float_overflow_not_nan():
    """map -> a -> b, each 1e308 along x: b's origin in map is beyond every float. As
    ``X is 1.0e308 * 10`` the translation alone may be inf; a pose of inf and NaN numbers is
    no pose: evaluation_error(float_overflow), whichever way the chain is walked."""
    with store(("map", "a", 0.0, [1e308, 0.0, 0.0], [0, 0, 0, 1]),
               ("a", "b", 0.0, [1e308, 0.0, 0.0], [0, 0, 0, 1])) as kb:
        for goal in ("tf_lookup(map, b, 0, P)", "tf_lookup(b, map, 0, P)"):
            with pytest.raises(SLREvaluationError, match="float_overflow"):
                kb.query(goal)
        assert answer(kb, "tf_lookup(a, b, 0, P)") == ([1e308, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])


def test_a_chain_of_huge_translations_with_a_finite_pose_gives_it():
    """map -> a turned 90 degrees about z: a's (1e308, 1e308) is map's (-1e308, 1e308), and
    b sits at (0, 1e308) in map. Rotating (1e308, 1e308) overflowed inside the rotation
    (2 q x v) and answered NaN."""
    with store(("map", "a", 0.0, [1e308, 0.0, 0.0], [0, 0, S, S]),
               ("a", "b", 0.0, [1e308, 1e308, 0.0], [0, 0, 0, 1])) as kb:
        ahead = answer(kb, "tf_lookup(map, b, 0, P)")
        assert_finite_unit(ahead)
        assert ahead[0] == pytest.approx([0.0, 1e308, 0.0], abs=1e293)
        back = answer(kb, "tf_lookup(b, map, 0, P)")
        assert_finite_unit(back)
        assert back[0] == pytest.approx([-1e308, 0.0, 0.0], abs=1e293)


@pytest.mark.parametrize("scale", [1e200, 1e-200, 1e300, 5e-320])
def test_a_quaternion_too_large_or_small_to_square_is_normalized(scale):
    """The quaternion's norm was computed by squaring: beyond 1e154 (or below 1e-162) it
    overflowed (underflowed) and the lookup failed on a valid rotation."""
    with store(("a", "b", 0.0, [1.0, 0.0, 0.0], [scale, 0, 0, scale]),
               ("a", "b", 2.0, [1.0, 0.0, 0.0], [scale, 0, 0, 0])) as kb:
        assert answer(kb, "tf_lookup(a, b, 0, P)") == pytest.approx(
            ([1.0, 0.0, 0.0], [S, 0.0, 0.0, S]))
        assert answer(kb, "tf_lookup(a, b, 2, P)") == ([1.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0])
        expected = slerp([S, 0, 0, S], [1, 0, 0, 0], 0.5)
        between = answer(kb, "tf_lookup(a, b, 1, P)")
        assert between[1] == pytest.approx(list(expected))
        assert_finite_unit(answer(kb, "tf_lookup(b, a, 1, P)"))


def test_a_zero_quaternion_is_still_not_a_pose():
    with store(("a", "b", 0.0, [1.0, 0.0, 0.0], [0, 0, 0, 0])) as kb:
        assert answer(kb, "tf_lookup(a, b, 0, P)") is None


def test_a_lookup_over_a_long_chain_keeps_the_query_timeout():
    """One tf_lookup reads one edge per frame of its chain: over 10,000 frames that is
    seconds inside one builtin call, which ran past ``timeout=`` to the end (SPEC §4: never
    a hang past timeout=). Now the chain walk looks at the query's deadline."""
    from slr_sql import SLRTimeout

    n = 10_000
    kb = slr_sql.open(clock=ManualClock(100.0))
    kb.add_many([("tf", (f"f{i}", f"f{i + 1}", pose([1.0, 0.0, 0.0], [0, 0, 0, 1])), t, t)
                 for t in (0.0, 2.0) for i in range(n)])
    with kb:
        with pytest.raises(SLRTimeout):
            kb.query(f"tf_lookup(f0, f{n}, 1.0, P)", timeout=0.01)
        # the frame tree is usable afterwards: a short chain answers
        assert answer(kb, "tf_lookup(f0, f3, 1.0, P)") == ([3.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])
