"""tf_lookup/4,5 (SPEC §1, docs/language.md "tf_lookup"): tf2's lookupTransform over stored
tf and tf_static events, checked against an independent implementation of the pose math
(transforms3d's quaternions and 4x4 matrices), on random frame trees."""
from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st
from transforms3d import affines, quaternions

import slr_sql
from slr_sql import ManualClock, SLREvaluationError, Struct
from slr_sql.terms import String

REPO = Path(__file__).resolve().parent.parent
S = math.sqrt(0.5)


def settle(kb) -> None:
    assert kb._sync.drain(timeout=10.0), "evaluations did not finish"


# -- the reference: transforms3d (w, x, y, z quaternions) and homogeneous matrices ----------

def ref_slerp(q1, q2, s):
    """Slerp by quaternion powers: q1·(q1⁻¹·q2)^s, on the shorter arc."""
    a = np.array(q1, float) / np.linalg.norm(q1)
    b = np.array(q2, float) / np.linalg.norm(q2)
    if np.dot(a, b) < 0:
        b = -b
    rel = quaternions.qmult(quaternions.qinverse(a), b)
    return quaternions.qmult(a, quaternions.qpow(rel, s))


def matrix(translation, q_wxyz):
    return affines.compose(np.array(translation, float), quaternions.quat2mat(q_wxyz), np.ones(3))


def edge_matrix(observations, t, extrapolate=False):
    """The edge's 4x4 transform at t from [(time, translation, quaternion xyzw)], or None."""
    observations = sorted(observations, key=lambda o: o[0])
    before = [o for o in observations if o[0] <= t]
    after = [o for o in observations if o[0] >= t]
    if before and before[-1][0] == t:
        o = before[-1]
        return matrix(o[1], xyzw_to_wxyz(o[2]))
    if not before or not after:
        if not extrapolate or not observations:
            return None
        o = before[-1] if before else after[0]
        return matrix(o[1], xyzw_to_wxyz(o[2]))
    (t1, p1, q1), (t2, p2, q2) = before[-1], after[0]
    s = (t - t1) / (t2 - t1)
    p = [a + (b - a) * s for a, b in zip(p1, p2)]
    return matrix(p, ref_slerp(xyzw_to_wxyz(q1), xyzw_to_wxyz(q2), s))


def xyzw_to_wxyz(q):
    return (q[3], q[0], q[1], q[2])


def answer_matrix(pose: Struct):
    (x, y, z), (qx, qy, qz, qw) = pose.args
    assert math.isclose(qx * qx + qy * qy + qz * qz + qw * qw, 1.0, rel_tol=1e-9)
    return matrix((x, y, z), (qw, qx, qy, qz))


def tf_event(name, parent, child, t, p, q):
    return (name, (parent, child, Struct("pose", (list(p), list(q)))), t, t)


# -- random frame trees ----------------------------------------------------------------------

unit = st.floats(-1.0, 1.0, allow_nan=False)
quat = st.tuples(unit, unit, unit, unit).filter(lambda q: sum(c * c for c in q) > 0.05)
vec = st.tuples(*[st.floats(-5.0, 5.0, allow_nan=False)] * 3)


@st.composite
def frame_trees(draw):
    """A tree of frames f0..fn (each frame's parent has a smaller index), each edge stored
    parent->child or child->parent, dynamic (observed at a few times) or static."""
    n = draw(st.integers(2, 7))
    edges = []
    for child in range(1, n):
        parent = draw(st.integers(0, child - 1))
        flipped = draw(st.booleans())
        static = draw(st.booleans())
        times = [0.0] if static else sorted(draw(st.sets(st.integers(0, 10), min_size=1,
                                                         max_size=4)))
        obs = [(float(t), draw(vec), draw(quat)) for t in times]
        a, b = (f"f{child}", f"f{parent}") if flipped else (f"f{parent}", f"f{child}")
        edges.append((a, b, static, obs))
    return n, edges


def reference(edges, target, source, t, extrapolate):
    """The pose of source in target by walking the tree with matrices (None: no value)."""
    adjacent: dict = {}
    for parent, child, static, obs in edges:
        adjacent.setdefault(child, []).append((parent, parent, child, static, obs))
        adjacent.setdefault(parent, []).append((child, parent, child, static, obs))
    # depth-first: a tree has one path
    def walk(frame, seen):
        if frame == target:
            return np.eye(4)
        for other, parent, child, static, obs in adjacent.get(frame, ()):
            if other in seen:
                continue
            rest = walk(other, seen | {other})
            if rest is None:
                continue
            if isinstance(rest, str):
                return rest
            m = matrix(obs[-1][1], xyzw_to_wxyz(obs[-1][2])) if static \
                else edge_matrix(obs, t, extrapolate)
            if m is None:
                return "gap"
            step = m if parent == other else np.linalg.inv(m)
            return rest @ step
        return None
    out = walk(source, {source})
    return None if out is None or isinstance(out, str) else out


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(tree=frame_trees(), data=st.data())
def test_tf_lookup_matches_an_independent_implementation_on_random_trees(tree, data):
    n, edges = tree
    events = []
    for parent, child, static, obs in edges:
        for t, p, q in obs:
            events.append(tf_event("tf_static" if static else "tf", parent, child, t, p, q))
    target = f"f{data.draw(st.integers(0, n - 1))}"
    source = f"f{data.draw(st.integers(0, n - 1))}"
    t = data.draw(st.sampled_from([0.0, 2.5, 5.0, 7.25, 10.0, 11.0, -1.0]))
    extrapolate = data.draw(st.booleans())
    with slr_sql.open(None, clock=ManualClock(100.0)) as kb:
        kb.add_many(events)
        goal = "tf_lookup(Target, Source, T, P, extrapolate)" if extrapolate \
            else "tf_lookup(Target, Source, T, P)"
        answers = kb.query(goal, args={"Target": slr_sql.Atom(target),
                                       "Source": slr_sql.Atom(source), "T": t})
    expected = reference(edges, target, source, t, extrapolate)
    if expected is None:
        assert answers == []
    else:
        assert len(answers) == 1
        np.testing.assert_allclose(answer_matrix(answers[0]["P"]), expected, atol=1e-9)


# -- the rules of the lookup, one by one -----------------------------------------------------

@pytest.fixture
def robot():
    """map -> odom (static), odom -> base (moving along x, turning about z), base -> cam
    (static, on the head), and cam stored the other way round: tf(cam, laser)."""
    kb = slr_sql.open(None, clock=ManualClock(100.0))
    kb.add_many([
        tf_event("tf_static", "map", "odom", 0.0, (10.0, 0.0, 0.0), (0, 0, 0, 1)),
        tf_event("tf", "odom", "base", 1.0, (0.0, 0.0, 0.0), (0, 0, 0, 1)),
        tf_event("tf", "odom", "base", 3.0, (2.0, 0.0, 0.0), (0, 0, S, S)),
        tf_event("tf_static", "base", "cam", 0.0, (0.0, 0.0, 1.0), (0, 0, 0, 1)),
        tf_event("tf", "laser", "cam", 2.0, (0.5, 0.0, 0.0), (0, 0, 0, 1)),
    ])
    yield kb
    kb.close()


def pose_of(kb, goal, **args):
    rows = kb.query(goal, args=args)
    return [(np.round(r["P"].args[0], 9).tolist(), np.round(r["P"].args[1], 9).tolist())
            for r in rows]


def test_interpolates_each_edge_between_its_observations(robot):
    q = [0.0, 0.0, math.sin(math.pi / 8), math.cos(math.pi / 8)]  # half of 90 degrees
    assert pose_of(robot, "tf_lookup(map, cam, 2, P)") == [([11.0, 0.0, 1.0], np.round(q, 9).tolist())]


def test_an_observation_at_t_is_used_as_it_is(robot):
    assert pose_of(robot, "tf_lookup(odom, base, 3, P)") == [([2.0, 0.0, 0.0], [0.0, 0.0, round(S, 9), round(S, 9)])]


def test_the_inverse_where_an_edge_points_the_other_way(robot):
    # base in map at 1 is (10, 0, 0); map in base is its inverse
    assert pose_of(robot, "tf_lookup(base, map, 1, P)") == [([-10.0, 0.0, 0.0], [-0.0, -0.0, -0.0, 1.0])]
    # laser is the parent of cam: cam -> laser is the stored pose, laser -> cam its inverse
    assert pose_of(robot, "tf_lookup(laser, cam, 2, P)") == [([0.5, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])]


def test_fails_outside_an_edges_observations_unless_extrapolate(robot):
    assert robot.query("tf_lookup(map, cam, 0.5, P)") == []   # before odom->base's first
    assert robot.query("tf_lookup(map, cam, 3.5, P)") == []   # after its last
    assert pose_of(robot, "tf_lookup(map, cam, 3.5, P, extrapolate)") == \
        pose_of(robot, "tf_lookup(map, cam, 3, P)")
    assert pose_of(robot, "tf_lookup(map, cam, 0.5, P, extrapolate)") == \
        pose_of(robot, "tf_lookup(map, cam, 1, P)")
    assert pose_of(robot, "tf_lookup(map, cam, 2, P, interpolate)") == \
        pose_of(robot, "tf_lookup(map, cam, 2, P)")


def test_a_static_edge_holds_for_all_time(robot):
    assert pose_of(robot, "tf_lookup(map, odom, -100, P)") == [([10.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])]
    assert pose_of(robot, "tf_lookup(map, odom, 1.0e9, P)") == [([10.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])]
    # re-published with a new value: the last stored one counts
    robot.add_many([tf_event("tf_static", "map", "odom", 5.0, (20.0, 0.0, 0.0), (0, 0, 0, 1))])
    assert pose_of(robot, "tf_lookup(map, odom, 1, P)") == [([20.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])]


def test_unconnected_frames_fail_and_a_frame_in_itself_is_the_identity(robot):
    robot.add_many([tf_event("tf", "elsewhere", "thing", 1.0, (1, 1, 1), (0, 0, 0, 1))])
    assert robot.query("tf_lookup(map, thing, 1, P)") == []
    assert robot.query("tf_lookup(map, nowhere, 1, P)") == []
    assert pose_of(robot, "tf_lookup(cam, cam, 7, P)") == [([0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])]


def test_new_edges_and_observations_are_seen_by_the_next_lookup(robot, tmp_path):
    assert robot.query("tf_lookup(map, gripper, 2, P)") == []
    robot.add_many([tf_event("tf", "cam", "gripper", 2.0, (0, 0, 0.5), (0, 0, 0, 1))])
    assert len(robot.query("tf_lookup(map, gripper, 2, P)")) == 1
    # another connection writing the same file
    db = tmp_path / "robot.db"
    with slr_sql.open(db, clock=ManualClock(100.0)) as kb, \
            slr_sql.open(db, clock=ManualClock(100.0)) as other:
        kb.add_many([tf_event("tf", "a", "b", 1.0, (1, 0, 0), (0, 0, 0, 1))])
        assert kb.query("tf_lookup(a, c, 1, P)") == []
        other.add_many([tf_event("tf", "b", "c", 1.0, (0, 1, 0), (0, 0, 0, 1))])
        assert pose_of(kb, "tf_lookup(a, c, 1, P)") == [([1.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0])]


def test_a_pose_that_is_not_a_pose_fails_the_lookup(robot):
    robot.add("tf(cam, broken, not_a_pose)^2")
    assert robot.query("tf_lookup(cam, broken, 2, P)") == []


@pytest.mark.parametrize("goal, error", [
    ("tf_lookup(F, cam, 1, P)", "instantiation_error"),
    ("tf_lookup(map, cam, T, P)", "instantiation_error"),
    ("tf_lookup(map, cam, 1, P, Mode)", "instantiation_error"),
    ("tf_lookup(map, cam, 1, P, 3)", "type_error(atom,3)"),
    ("tf_lookup(map, cam, 1, P, sideways)", "domain_error(tf_lookup_mode,sideways)"),
])
def test_errors(robot, goal, error):
    with pytest.raises(SLREvaluationError) as info:
        robot.query(goal)
    assert error in str(info.value).replace(" ", "")


def test_equals_the_papers_hand_written_rules_on_a_two_edge_chain(robot):
    robot.load("""
        itf(P, C, TF)^T :- prev(tf(P, C, TF1)^T1, T), next(tf(P, C, TF2)^T2, [T, inf]),
                           interpolate([TF, T], [TF1, T1], [TF2, T2]).
        cam_in_odom(T, P) :- itf(odom, base, TF)^T, prev(tf_static(base, cam, C)^_, inf),
                             pos_multiply([pose([0,0,0],[0,0,0,1]), C, TF], P).
    """)
    for t in (1.0, 1.5, 2.25, 3.0):
        (rule,) = robot.query("cam_in_odom(T, P)", args={"T": t})
        (looked,) = robot.query("tf_lookup(odom, cam, T, P)", args={"T": t})
        np.testing.assert_allclose(answer_matrix(looked["P"]), answer_matrix(rule["P"]),
                                   atol=1e-12)


def test_explain_says_it_runs_in_the_interpreter(robot):
    text = robot.explain("tf_lookup(map, cam, 2, P)")
    assert "interpreter" in text and "tf_lookup/4 reads the stored transforms" in text


# -- synchronized queries ----------------------------------------------------------------------

def test_a_synchronized_lookup_waits_for_each_edge_like_prev_and_next():
    clock = ManualClock(0.0)
    with slr_sql.open(None, clock=clock) as kb:
        kb.load(":- max_delay(tf/3, 1). :- max_delay(tf_static/3, 1).")
        kb.add_many([tf_event("tf", "map", "base", 0.0, (0, 0, 0), (0, 0, 0, 1)),
                     tf_event("tf_static", "base", "cam", 0.0, (0, 0, 1), (0, 0, 0, 1))])
        clock.set(3.0)
        pending = kb.submit("tf_lookup(map, cam, 1, P)", at=1.0)
        settle(kb)
        assert not pending.done()       # no observation of map->base after 1 yet
        assert "at or after 1" in str(pending.waiting_for[0])
        kb.add_many([tf_event("tf", "map", "base", 2.0, (2, 0, 0), (0, 0, 0, 1))])
        settle(kb)
        assert not pending.done()       # it arrived; tf/3 is complete only up to 2 at 3 + 1
        assert "next(tf/3) in [1, 2]" in str(pending.waiting_for[0])
        clock.set(3.5)
        settle(kb)
        assert pending.done()
        assert pending.result()[0]["P"].args[0] == [1.0, 0.0, 1.0]


def test_a_synchronized_lookup_with_extrapolate_needs_only_the_history_up_to_t():
    clock = ManualClock(0.0)
    with slr_sql.open(None, clock=clock) as kb:
        kb.load(":- max_delay(tf/3, 1). :- max_delay(tf_static/3, 1).")
        kb.add_many([tf_event("tf", "map", "base", 0.0, (1, 0, 0), (0, 0, 0, 1))])
        pending = kb.submit("tf_lookup(map, base, 4, P, extrapolate)", at=4.0)
        clock.set(4.5)
        settle(kb)
        assert not pending.done()
        clock.set(5.5)
        settle(kb)
        assert pending.result()[0]["P"].args[0] == [1.0, 0.0, 0.0]


def test_an_in_order_edge_answers_as_soon_as_its_next_observation_arrives():
    clock = ManualClock(10.0)
    with slr_sql.open(None, clock=clock) as kb:
        kb.load(":- in_order(tf/3). :- max_delay(tf/3, 100). :- max_delay(tf_static/3, 0).")
        kb.add_many([tf_event("tf", "map", "base", 0.0, (0, 0, 0), (0, 0, 0, 1))])
        pending = kb.submit("tf_lookup(map, base, 1, P)", at=1.0)
        settle(kb)
        assert not pending.done()
        kb.add_many([tf_event("tf", "map", "base", 2.0, (2, 0, 0), (0, 0, 0, 1))])
        settle(kb)
        assert pending.result()[0]["P"].args[0] == [1.0, 0.0, 0.0]


# -- on an imported recording ---------------------------------------------------------------

def test_tf_lookup_on_an_imported_bag_through_a_static_edge(tmp_path):
    sys.path.insert(0, str(REPO / "examples" / "ros"))
    import make_bag

    bag = make_bag.write_bag(tmp_path / "demo_bag", "mcap", make_bag.demo_items("mcap"))
    db = tmp_path / "robot.db"
    env = {"PYTHONPATH": str(REPO)}
    import os
    subprocess.run([sys.executable, "-m", "slr_sql", "ros", "import", str(bag), str(db)],
                   check=True, capture_output=True, env={**os.environ, **env})
    with slr_sql.open(db) as kb:
        assert kb.query("tf_static(base, cam_mount, _)^T") == [{"T": float(make_bag.EPOCH)}]
        assert kb.query("tf(base, cam_mount, _)^_") == []
        (answer,) = kb.query("tf_lookup(map, cam_mount, T, P)",
                             args={"T": make_bag.EPOCH + 5.05})
    (x, y, z), q = answer["P"].args
    assert (round(x, 6), y, z) == (0.505, 0.0, 1.0) and q == [0.0, 0.0, 0.0, 1.0]


# -- both backends -----------------------------------------------------------------------------

def test_tf_lookup_gives_the_same_poses_on_postgresql(postgres_url):
    events = [tf_event("tf_static", "map", "odom", 0.0, (10.0, 0.0, 0.0), (0, 0, 0, 1)),
              tf_event("tf", "odom", "base", 1.0, (0.0, 0.0, 0.0), (0, 0, 0, 1)),
              tf_event("tf", "odom", "base", 3.0, (2.0, 0.0, 0.0), (0, 0, S, S)),
              tf_event("tf", "laser", "base", 2.0, (0.5, 0.0, 0.0), (0, 0, 0, 1))]
    goals = ["tf_lookup(map, base, 2, P)", "tf_lookup(laser, map, 2, P)",
             "tf_lookup(map, base, 4, P)", "tf_lookup(map, base, 4, P, extrapolate)"]
    answers = {}
    for where in (None, postgres_url):
        with slr_sql.open(where, clock=ManualClock(100.0)) as kb:
            kb.add_many(events)
            answers[where] = [pose_of(kb, goal) for goal in goals]
    assert answers[None] == answers[postgres_url]
    assert answers[None][2] == [] and answers[None][0]


# -- frame names are names: 1, 1.0 and '1' are three frames ----------------------------------

@pytest.mark.parametrize("backend", ["sqlite", "postgres"])
def test_frames_named_by_equal_numbers_of_two_types_are_two_frames(backend, request):
    where = request.getfixturevalue("postgres_url") if backend == "postgres" else None
    with slr_sql.open(where, clock=ManualClock(100.0)) as kb:
        # the float's edge is stored between the integer's two observations: a bracket that
        # took 1 for 1.0 would interpolate across the other frame's
        kb.add_many([tf_event("tf", "map", 1, 0.0, (1.0, 0.0, 0.0), (0, 0, 0, 1)),
                     tf_event("tf", "map", 1.0, 0.5, (2.0, 0.0, 0.0), (0, 0, 0, 1)),
                     tf_event("tf", "map", 1.0, 1.5, (2.0, 0.0, 0.0), (0, 0, 0, 1)),
                     tf_event("tf", "map", 1, 2.0, (1.0, 0.0, 0.0), (0, 0, 0, 1)),
                     tf_event("tf", "map", "1", 0.0, (3.0, 0.0, 0.0), (0, 0, 0, 1)),
                     tf_event("tf", "map", "1", 2.0, (3.0, 0.0, 0.0), (0, 0, 0, 1)),
                     tf_event("tf_static", "map", 2, 0.0, (4.0, 0.0, 0.0), (0, 0, 0, 1)),
                     tf_event("tf_static", "map", 2.0, 0.0, (5.0, 0.0, 0.0), (0, 0, 0, 1)),
                     tf_event("tf_static", "map", String("1"), 0.0, (6.0, 0.0, 0.0),
                              (0, 0, 0, 1))])
        x = {goal: [p[0][0] for p in pose_of(kb, goal)] for goal in (
            "tf_lookup(map, 1, 1, P)", "tf_lookup(map, 1.0, 1, P)", "tf_lookup(map, '1', 1, P)",
            "tf_lookup(map, 2, 1, P)", "tf_lookup(map, 2.0, 1, P)",
            "tf_lookup(1.0, 1, 1, P)", "tf_lookup(map, 1.0, 0.25, P)",
            'tf_lookup(map, "1", 1, P)', "tf_lookup('1', \"1\", 1, P)")}
    assert x == {"tf_lookup(map, 1, 1, P)": [1.0], "tf_lookup(map, 1.0, 1, P)": [2.0],
                 "tf_lookup(map, '1', 1, P)": [3.0], "tf_lookup(map, 2, 1, P)": [4.0],
                 "tf_lookup(map, 2.0, 1, P)": [5.0],
                 "tf_lookup(1.0, 1, 1, P)": [-1.0],   # not the identity: two frames
                 "tf_lookup(map, 1.0, 0.25, P)": [],  # before 1.0's first observation
                 'tf_lookup(map, "1", 1, P)': [6.0],  # a string names a frame of its own
                 "tf_lookup('1', \"1\", 1, P)": [3.0]}


# -- an observation over an interval holds at every time inside it ----------------------------

def interval_event(parent, child, start, end, x):
    return ("tf", (parent, child, Struct("pose", ([x, 0.0, 0.0], [0, 0, 0, 1]))), start, end)


@pytest.mark.parametrize("backend", ["sqlite", "postgres"])
def test_a_transform_over_an_interval_holds_inside_it_and_is_interpolated_from_its_ends(
        backend, request):
    where = request.getfixturevalue("postgres_url") if backend == "postgres" else None
    times = [1, 2, 3.5, 6, 7, 9, 10, 11, 12, 13, 14]
    with slr_sql.open(where, clock=ManualClock(100.0)) as kb:
        # base held at x=1 over [2, 6] (a pose stated for a span), then points at 10 and 14,
        # and a second interval [11, 12] between them
        kb.add_many([interval_event("map", "base", 2.0, 6.0, 1.0),
                     interval_event("map", "base", 10.0, 10.0, 3.0),
                     interval_event("map", "base", 11.0, 12.0, 5.0),
                     interval_event("map", "base", 14.0, 14.0, 3.0)])
        x = [[p[0][0] for p in pose_of(kb, f"tf_lookup(map, base, {t}, P)")] for t in times]
        held = [[p[0][0] for p in pose_of(kb, f"tf_lookup(map, base, {t}, P, extrapolate)")]
                for t in [1, 4, 15]]
    # the interval is its pose at each of its ends, and at every time between them
    assert x == [[], [1.0], [1.0], [1.0], [1.5], [2.5], [3.0], [5.0], [5.0], [4.0], [3.0]]
    assert held == [[1.0], [1.0], [3.0]]


# -- -0.0 and 0.0 are two frames, in the frame list as in the lookup -------------------------

@pytest.mark.parametrize("backend", ["sqlite", "postgres"])
def test_frames_named_minus_zero_and_zero_are_two_frames_in_the_frame_list_too(backend,
                                                                               request):
    where = request.getfixturevalue("postgres_url") if backend == "postgres" else None
    with slr_sql.open(where, clock=ManualClock(100.0)) as kb:
        # the two edges' observations interleave: a bracket that took -0.0 for 0.0 would
        # interpolate across the other frame's
        kb.add_many([tf_event("tf", -0.0, "b", 0.0, (1.0, 0.0, 0.0), (0, 0, 0, 1)),
                     tf_event("tf", 0.0, "b", 1.0, (5.0, 0.0, 0.0), (0, 0, 0, 1)),
                     tf_event("tf", -0.0, "b", 2.0, (3.0, 0.0, 0.0), (0, 0, 0, 1)),
                     tf_event("tf", 0.0, "b", 3.0, (7.0, 0.0, 0.0), (0, 0, 0, 1)),
                     tf_event("tf_static", "c", 0.0, 0.0, (0.0, 2.0, 0.0), (0, 0, 0, 1)),
                     tf_event("tf_static", "c", -0.0, 0.0, (0.0, 4.0, 0.0), (0, 0, 0, 1))])
        pairs, _ = kb.store.distinct_pairs("tf", 3)
        statics, _ = kb.store.distinct_pairs("tf_static", 3)
        listed = sorted(repr(parent) for parent, child, _ in pairs)
        listed_static = sorted(repr(child) for parent, child, _ in statics)
        x = {goal: [p[0][:2] for p in pose_of(kb, goal)] for goal in (
            "tf_lookup(-0.0, b, 1, P)", "tf_lookup(0.0, b, 2, P)",
            "tf_lookup(-0.0, 0.0, 2, P)", "tf_lookup(c, -0.0, 5, P)",
            "tf_lookup(c, 0.0, 5, P)")}
    assert listed == ["-0.0", "0.0"] and listed_static == ["-0.0", "0.0"]
    assert x == {"tf_lookup(-0.0, b, 1, P)": [[2.0, 0.0]],    # from 1 at 0 to 3 at 2
                 "tf_lookup(0.0, b, 2, P)": [[6.0, 0.0]],     # from 5 at 1 to 7 at 3
                 "tf_lookup(-0.0, 0.0, 2, P)": [[-3.0, 0.0]],  # b in -0.0 (3), 0.0 in b (-6)
                 "tf_lookup(c, -0.0, 5, P)": [[0.0, 4.0]],
                 "tf_lookup(c, 0.0, 5, P)": [[0.0, 2.0]]}
