"""tf_lookup where observations overlap (docs/language.md, "An observation over an interval"):
an observation over [S, E] holds at every time inside it, so a point observation at P inside
it counts at P only; after P (still inside [S, E]) the interval holds again. The rule: of the
observations that hold at T (start <= T <= end), the one that started last counts (ties: the
greatest end, then the last stored); when none holds, the interpolation runs from the one
that ended last before T to the first that starts after T. The lookup took the latest
started at or before T even once it had ended: a point inside an interval took over the rest
of the interval. Checked against a direct implementation of the rule, on both backends."""
from __future__ import annotations

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

import slr_sql
from slr_sql import ManualClock

from test_tf_lookup import interval_event, pose_of


def reference_x(observations, t, extrapolate=False):
    """The x of the edge at ``t`` by the rule, from ``[(start, end, x)]`` in store order."""
    stored = [(s, e, x, seq) for seq, (s, e, x) in enumerate(observations)]
    holding = [o for o in stored if o[0] <= t <= o[1]]
    if holding:
        return max(holding, key=lambda o: (o[0], o[1], o[3]))[2]
    ended = [o for o in stored if o[1] <= t]
    before = max(ended, key=lambda o: (o[1], o[0], o[3])) if ended else None
    started = [o for o in stored if o[0] >= t]
    after = min(started, key=lambda o: (o[0], -o[3])) if started else None
    if before is None or after is None:
        if not extrapolate or (before is None and after is None):
            return None
        return (before or after)[2]
    s = (t - before[1]) / (after[0] - before[1])
    return before[2] + (after[2] - before[2]) * s


def lookup_x(kb, t, extrapolate=False, child="base"):
    mode = ", extrapolate" if extrapolate else ""
    found = [p[0][0] for p in pose_of(kb, f"tf_lookup(map, {child}, {t!r}, P{mode})")]
    assert len(found) <= 1
    return found[0] if found else None


def store_at(request, backend):
    return request.getfixturevalue("postgres_url") if backend == "postgres" else None


@pytest.mark.parametrize("backend", ["sqlite", "postgres"])
def test_a_point_inside_an_interval_counts_at_its_time_only(backend, request):
    with slr_sql.open(store_at(request, backend), clock=ManualClock(100.0)) as kb:
        # base at x=1 over [1, 10], a point at 5 (x=2) inside it, a point at 12 (x=3)
        observations = [(1.0, 10.0, 1.0), (5.0, 5.0, 2.0), (12.0, 12.0, 3.0)]
        kb.add_many([interval_event("map", "base", s, e, x) for s, e, x in observations])
        x = {t: lookup_x(kb, t) for t in (3, 5, 5.5, 7, 10, 11, 12)}
    # at 7 the interval holds (the point said x=2 at 5 only); at 11 halfway from its end
    assert x == {3: 1.0, 5: 2.0, 5.5: 1.0, 7: 1.0, 10: 1.0, 11: 2.0, 12: 3.0}
    assert x == {t: reference_x(observations, t) for t in x}


@pytest.mark.parametrize("backend", ["sqlite", "postgres"])
def test_a_shorter_interval_inside_a_longer_one_counts_while_it_lasts(backend, request):
    with slr_sql.open(store_at(request, backend), clock=ManualClock(100.0)) as kb:
        # x=1 over [1, 20], x=5 over [3, 10] inside it, a point at 30 (x=7)
        observations = [(1.0, 20.0, 1.0), (3.0, 10.0, 5.0), (30.0, 30.0, 7.0)]
        kb.add_many([interval_event("map", "base", s, e, x) for s, e, x in observations])
        x = {t: lookup_x(kb, t) for t in (2, 3, 10, 12, 20, 25, 31)}
    assert x == {2: 1.0, 3: 5.0, 10: 5.0, 12: 1.0, 20: 1.0, 25: 4.0, 31: None}
    assert x == {t: reference_x(observations, t) for t in x}


observation = st.tuples(st.integers(0, 12), st.integers(0, 4), st.integers(-3, 3)).map(
    lambda o: (float(o[0]), float(o[0] + o[1] * (o[1] > 1)), float(o[2])))


@pytest.mark.parametrize("backend", ["sqlite", "postgres"])
def test_lookups_over_points_and_intervals_follow_the_rule(backend, request):
    edges = iter(range(1 << 30))    # each example an edge of its own, in one store

    @settings(max_examples=30 if backend == "postgres" else 80, deadline=None,
              suppress_health_check=[HealthCheck.too_slow,
                                     HealthCheck.function_scoped_fixture])
    @given(observations=st.lists(observation, min_size=1, max_size=8),
           times=st.lists(st.integers(-2, 36).map(lambda n: n / 2), min_size=1, max_size=6),
           extrapolate=st.booleans())
    def check(observations, times, extrapolate):
        child = f"base{next(edges)}"
        kb.add_many([interval_event("map", child, s, e, x) for s, e, x in observations])
        for t in times:
            found = lookup_x(kb, t, extrapolate, child)
            expected = reference_x(observations, t, extrapolate)
            assert found == (None if expected is None else pytest.approx(expected)), \
                (observations, t, extrapolate)

    with slr_sql.open(store_at(request, backend), clock=ManualClock(100.0)) as kb:
        check()
