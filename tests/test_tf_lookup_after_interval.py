"""tf_lookup after an interval observation (docs/language.md: an observation over an interval
is its pose at each end for the interpolation outside it) interpolates from the observation
that ended last before T. It took the one that *started* last instead: with a shorter
observation inside the interval (which started later, and ended earlier), a time after the
interval was interpolated from that older, farther observation."""
from __future__ import annotations

import pytest

import slr_sql
from slr_sql import ManualClock

from test_tf_lookup import interval_event, pose_of


@pytest.mark.parametrize("backend", ["sqlite", "postgres"])
def test_after_an_interval_the_interpolation_starts_at_its_end(backend, request):
    where = request.getfixturevalue("postgres_url") if backend == "postgres" else None
    with slr_sql.open(where, clock=ManualClock(100.0)) as kb:
        # base at x=1 over [1, 10], a point inside it at 5 (x=2), then a point at 12 (x=3)
        kb.add_many([interval_event("map", "base", 1.0, 10.0, 1.0),
                     interval_event("map", "base", 5.0, 5.0, 2.0),
                     interval_event("map", "base", 12.0, 12.0, 3.0)])
        x = {t: [p[0][0] for p in pose_of(kb, f"tf_lookup(map, base, {t}, P)")]
             for t in (5, 11, 12)}
    # at 11: halfway from the interval's end (10, x=1) to the point at 12 (x=3)
    assert x == {5: [2.0], 11: [2.0], 12: [3.0]}
