"""A timeline reads the same data from a PostgreSQL store as from a SQLite file: the
statements are printed per dialect (slr_sql/store/timeline.py), the answers must not
differ -- exact rows, binned rows (bins are truncated, never rounded), value series exact and
binned, rows split by an argument."""
from __future__ import annotations

import pytest

import slr_sql
from slr_sql.clocks import ManualClock
from slr_sql.plot import collect_timeline
from slr_sql.store.dialect import POSTGRES
from slr_sql.store.timeline import timeline_statements

EVENTS = ([("move", ("r1",), 1.0 + i, 2.5 + i) for i in range(0, 40, 3)]
          + [("move", ("r2",), 0.5 + i, 0.9 + i) for i in range(0, 40, 7)]
          + [("ping", (), 0.3 * i, 0.3 * i) for i in range(120)]
          + [("speed", ("r1", 0.1 * i), 0.25 * i, 0.25 * i) for i in range(150)]
          + [("speed", ("r2", 2 + i), 0.5 * i, 0.5 * i) for i in range(60)]
          + [("speed", ("r3", "fast"), 3.0, 3.0)])


def _plain(value):
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, float):
        return round(value, 9)
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def _drawn(where: str, **options) -> list:
    with slr_sql.open(where, clock=ManualClock(100.0)) as kb:
        assert kb.add_many(EVENTS) == []
        timeline = collect_timeline(kb, start=0, end=40, size=(400, None), **options)
        rows = [(r.label, r.mode, r.count, _plain(r.intervals), _plain(r.points),
                 _plain(r.coverage), _plain(r.point_counts)) for r in timeline.rows]
        series = [(s.type.label, s.mode, s.count, _plain(s.times), _plain(s.values),
                   _plain(s.lows), _plain(s.highs),
                   [(k, _plain(t), _plain(v)) for k, _c, t, v in s.lines]) for s in timeline.series]
        return [rows, series]


@pytest.mark.parametrize("options", [
    {},                                                   # every row exact
    {"exact_limit": 5},                                   # every row binned
    {"values": ["speed:2"]},                              # a value series, exact
    {"values": ["speed:2"], "exact_limit": 20},           # ... binned
    {"types": ["move"], "by": ["move:1"]},                # one row per robot
    {"types": ["move"], "by": ["move:1"], "exact_limit": 2},
])
def test_postgres_draws_what_sqlite_draws(options, postgres_url, tmp_path):
    on_sqlite = _drawn(str(tmp_path / "robot.db"), **options)
    assert any(on_sqlite[0]) or any(on_sqlite[1])
    assert _drawn(postgres_url, **options) == on_sqlite


def test_a_value_path_into_json_on_postgres_says_it_needs_sqlite(postgres_url):
    with slr_sql.open(postgres_url, clock=ManualClock(100.0)) as kb:
        kb.add("pose(r1, [1.0, 2.0])^1")
        with pytest.raises(slr_sql.SLRError, match="SQLite store only"):
            collect_timeline(kb, values=["pose:2[0]"], start=0, end=2)


def test_bins_are_truncated_on_both_dialects():
    """A cast to an integer rounds on PostgreSQL: its bin number is printed as floor()."""
    sqlite, postgres = timeline_statements(), timeline_statements(POSTGRES)
    assert "CAST((" in sqlite.start_bins('"t"', 0.0, 1.0, 0.1)[0]
    assert "floor((" in postgres.start_bins('"t"', 0.0, 1.0, 0.1)[0]
    assert "GREATEST(t_start, ?)" in postgres.start_bins('"t"', 0.0, 1.0, 0.1)[0]
