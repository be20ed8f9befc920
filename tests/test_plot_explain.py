"""Plots that explain: a row and a color per object (--by), arrival lags, a relative time axis
for epoch-second data, internal types hidden, value lines per object, a rule's answers over
time (--query/--every), image formats by suffix. The PNG pixels are read back."""
from __future__ import annotations

import numpy as np
import pytest
from matplotlib.colors import to_rgb
from conftest import copy_of_store
from test_cli import slr
from test_plot import blue, inside_columns, pixel, render, row_band, runs

import slr_sql
from slr_sql.plot import LAG_COLOR, PALETTE


def colored(img, color: str, tolerance: float = 0.12):
    """Pixels of exactly this color (up to antialiasing)."""
    return (np.abs(img[..., :3] - np.array(to_rgb(color))) < tolerance).all(axis=-1)


def columns_of(img, fig, ax, y: int, color: str) -> list[tuple[int, int]]:
    inside = inside_columns(fig, ax)
    band = colored(img[row_band(fig, ax, y, half=0.4), inside], color)
    return runs(np.nonzero(band.any(axis=0))[0] + inside.start)


@pytest.fixture
def kb():
    k = slr_sql.open(clock=slr_sql.ManualClock(0.0))
    yield k
    k.close()


def test_by_gives_each_object_its_row_and_color(kb, tmp_path):
    kb.add_many(["seg(cup1, table)^2", "seg(cup2, shelf)^5", "seg(cup1, shelf)^8"])
    fig = kb.plot(["seg"], by=["seg:1"], start=0, end=10, size=(800, 240), lags=False)
    assert [row.label for row in fig.slr_timeline.rows] == ["seg/2 cup1", "seg/2 cup2"]
    img = render(fig, tmp_path / "by.png")
    ax = fig.axes[0]
    cup1 = columns_of(img, fig, ax, 0, PALETTE[0])
    cup2 = columns_of(img, fig, ax, 1, PALETTE[1])
    assert len(cup1) == 2 and len(cup2) == 1
    for (first, last), t in zip(cup1 + cup2, (2, 8, 5)):
        assert abs((first + last) / 2 - pixel(fig, ax, t, 0)[0]) <= 1.5
    assert not columns_of(img, fig, ax, 0, PALETTE[1])   # cup2's color only in cup2's row


def test_each_late_event_shows_its_arrival_lag(tmp_path):
    clock = slr_sql.ManualClock(2.5)
    kb = slr_sql.open(clock=clock)
    kb.add("seen(a)^2")           # arrived half a second late
    clock.set(7.0)
    kb.add("seen(b)^3")           # arrived four seconds late
    fig = kb.plot(start=0, end=10, size=(800, 200))
    row = fig.slr_timeline.rows[0]
    assert row.lags == [(2.0, 2.5), (3.0, 7.0)]
    img = render(fig, tmp_path / "lag.png")
    ax = fig.axes[0]
    lines = columns_of(img, fig, ax, 0, LAG_COLOR)
    assert len(lines) == 2
    for (first, last), (end, arrival) in zip(lines, row.lags):
        assert abs(first - pixel(fig, ax, end, 0)[0]) <= 2
        assert abs(last - pixel(fig, ax, arrival, 0)[0]) <= 4   # the dot at the arrival
    without = render(kb.plot(start=0, end=10, size=(800, 200), lags=False), tmp_path / "no.png")
    assert not colored(without, LAG_COLOR).any()
    kb.close()


@pytest.mark.filterwarnings("ignore:.*after its end time")   # (said on purpose: an import)
def test_arrivals_on_another_clock_draw_no_lag(tmp_path):
    with slr_sql.open(clock=slr_sql.ManualClock(1_800_000_000.0)) as kb:  # an import's clock
        kb.add_many(["seen(a)^2", "seen(b)^3"])
        fig = kb.plot(start=0, end=10, size=(800, 200))
        assert fig.slr_timeline.rows[0].lags == []
        assert not colored(render(fig, tmp_path / "import.png"), LAG_COLOR).any()


T0 = 1_700_000_000.0


def test_epoch_times_get_a_relative_axis_from_the_first_event(kb, tmp_path):
    kb.add_many([f"dock(r1)^[{T0 + 100}, {T0 + 200}]", f"bump(r1)^{T0 + 600}"])
    fig = kb.plot(size=(800, 200))
    ax = fig.axes[0]
    assert fig.slr_timeline.origin == T0 + 100
    lo, hi = ax.get_xlim()
    assert -20 < lo < 0 and 500 < hi < 520        # 0 ... 500 s, not 1.7e9
    assert "since 2023-11-14 22:14:" in ax.get_xlabel() or "since" in fig.axes[-1].get_xlabel()
    assert all(abs(t) < 1000 for t in ax.get_xticks())
    img = render(fig, tmp_path / "epoch.png")
    inside = inside_columns(fig, ax)
    band = blue(img[row_band(fig, ax, 1), inside])    # dock/1 is the second row
    ((first, last),) = runs(np.nonzero(band.any(axis=0))[0] + inside.start)
    assert abs(first - pixel(fig, ax, 0, 1)[0]) <= 2 and abs(last - pixel(fig, ax, 100, 1)[0]) <= 2
    absolute = kb.plot(size=(800, 200), relative=False)
    assert absolute.axes[0].get_xlim()[0] > T0


def test_internal_types_are_hidden_unless_asked(kb):
    kb.add_many(["slr_import(bag, 1, 2)^1", "seen(a)^2"])
    assert [r.label for r in kb.plot().slr_timeline.rows] == ["seen/1"]
    assert [r.label for r in kb.plot(internal=True).slr_timeline.rows] == ["seen/1",
                                                                           "slr_import/3"]
    assert [r.label for r in kb.plot(["slr_import"]).slr_timeline.rows] == ["slr_import/3"]


def test_a_value_line_per_object_never_one_line_through_several(kb, tmp_path):
    # r1 at 1.0, r2 at 2.0, alternating: one line through both would zigzag across 1.5
    kb.add_many([f"speed({'r1' if i % 2 == 0 else 'r2'}, {1.0 if i % 2 == 0 else 2.0})^{i}"
                 for i in range(10)])
    fig = kb.plot(values=["speed:2"], start=-0.5, end=9.5, size=(800, 400))
    series = fig.slr_timeline.series[0]
    assert [(key, len(times)) for key, _, times, _ in series.lines] == [("r1", 5), ("r2", 5)]
    img = render(fig, tmp_path / "split.png")
    value_ax = fig.axes[1]
    _, middle = pixel(fig, value_ax, 4.5, 1.5)
    inside = inside_columns(fig, value_ax)
    band = img[int(middle) - 3:int(middle) + 4, inside]
    assert not (colored(band, PALETTE[0]) | colored(band, PALETTE[1])).any()
    _, r1_y = pixel(fig, value_ax, 4, 1.0)
    _, r2_y = pixel(fig, value_ax, 5, 2.0)
    assert colored(img[int(r1_y) - 1:int(r1_y) + 2, inside], PALETTE[0]).any()
    assert colored(img[int(r2_y) - 1:int(r2_y) + 2, inside], PALETTE[1]).any()


def test_a_rules_answers_over_time_are_a_row_of_colored_runs(kb, tmp_path):
    kb.load('location(O, L)^T :- prev(seg(O, L)^Z, T), T - Z =< 5, !.\n'
            'location(_, "outdated")^_.')
    kb.add_many(["seg(cup1, table)^2", "seg(cup1, shelf)^4"])
    fig = kb.plot(["seg"], query="location(cup1, L)^T", every=0.5, start=0, end=12,
                  size=(900, 200), lags=False)
    (row,) = fig.slr_timeline.queries
    assert [(a, b, text) for a, b, text in row.runs] == [
        (0.0, 2.0, 'L = "outdated"'), (2.0, 4.0, "L = table"), (4.0, 9.5, "L = shelf"),
        (9.5, 12.5, 'L = "outdated"')]
    img = render(fig, tmp_path / "query.png")
    ax = fig.axes[0]
    shelf = columns_of(img, fig, ax, 1, row.colors["L = shelf"])
    ((first, last),) = [r for r in shelf if r[1] - r[0] > 5]
    assert abs(first - pixel(fig, ax, 4, 1)[0]) <= 2 and abs(last - pixel(fig, ax, 9.5, 1)[0]) <= 2
    assert fig.axes[0].get_yticklabels()[1].get_text() == "location(cup1, L)^T"


@pytest.fixture(scope="module")
def moved_store(tmp_path_factory):
    """A store holding one event, made once for the module by ``slr add`` (a process)."""
    db = tmp_path_factory.mktemp("moved") / "robot.db"
    assert slr("add", str(db), "move(r1)^[2, 8]").returncode == 0
    return db


@pytest.mark.parametrize("suffix, magic", [(".png", b"\x89PNG"), (".jpg", b"\xff\xd8\xff"),
                                           (".svg", b"<?xml"), (".pdf", b"%PDF")])
def test_the_suffix_says_the_format(tmp_path, moved_store, suffix, magic):
    db = copy_of_store(moved_store, tmp_path)
    out = tmp_path / f"timeline{suffix}"
    r = slr("plot", db, "-o", str(out))
    assert r.returncode == 0, r.stderr
    assert out.read_bytes().startswith(magic)


def test_an_unknown_suffix_is_refused_and_nothing_is_written(tmp_path, moved_store):
    db = copy_of_store(moved_store, tmp_path)
    r = slr("plot", db, "-o", str(tmp_path / "timeline.gif"))
    assert r.returncode == 1
    assert r.stderr.startswith("error: cannot write ") and ".gif names no image format" in r.stderr
    assert not (tmp_path / "timeline.gif").exists()


def test_cli_plot_by_and_query(tmp_path):
    db = str(tmp_path / "robot.db")
    program = tmp_path / "p.slr"
    program.write_text("location(O, L)^T :- prev(seg(O, L)^_, T).\n", encoding="utf-8")
    assert slr("load", db, str(program)).returncode == 0
    assert slr("add", db, "seg(cup1, table)^2", "seg(cup2, shelf)^3").returncode == 0
    out = tmp_path / "t.png"
    r = slr("plot", db, "seg", "--by", "seg:1", "--query", "location(cup1, L)^T",
            "--every", "0.5", "--from", "0", "--to", "5", "-o", str(out))
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith(f"wrote {out} (1200x") and "3 rows" in r.stdout


def test_cli_plot_query_gives_up_after_its_timeout_and_writes_nothing(tmp_path):
    db = str(tmp_path / "robot.db")
    program = tmp_path / "p.slr"
    # the sample at T = 3 never ends (no X below 0 among 1, 2, ...); the others answer at once
    program.write_text("spin(T) :- T =:= 3, between(1, inf, X), X < 0.\n"
                       "spin(T) :- T =\\= 3.\n", encoding="utf-8")
    assert slr("load", db, str(program)).returncode == 0
    assert slr("add", db, "seg(cup1, table)^2").returncode == 0
    out = tmp_path / "t.png"
    r = slr("plot", db, "--query", "spin(T)", "--every", "1", "--from", "0", "--to", "5",
            "--timeout", "0.3", "-o", str(out))
    assert r.returncode == 1, (r.stdout, r.stderr)
    assert "Traceback" not in r.stderr
    assert r.stderr.startswith("error: --query spin(T): the timeout of 0.3 s ran out at "
                               "T = 3, its ask 4 of 6; a larger --every"), r.stderr
    assert not out.exists()
    # within its timeout the row is drawn as without one
    r = slr("plot", db, "--query", "spin(T)", "--every", "1", "--from", "3.5", "--to", "5",
            "--timeout", "60", "-o", str(out))
    assert r.returncode == 0, r.stderr
    assert out.exists()
    r = slr("plot", db, "--timeout", "1", "-o", str(out))
    assert r.returncode == 2 and "--timeout goes with --query" in r.stderr
