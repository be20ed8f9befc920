"""Timelines (``kb.plot``, ``slr plot``): the PNG itself is checked — its size, and where the
colored pixels of known data land (docs/plots.md)."""
from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from matplotlib.image import imread

import slr_sql
from slr_sql.plot import (COMPLEX_MARK, collect_timeline, parse_size, parse_value_spec,
                          save_timeline, timeline)
from slr_sql.store import EventStore

REPO = Path(__file__).resolve().parent.parent


# The events here carry small times (1, 2.5, ...): the stores get a ManualClock, on which they
# are not "decades late" (a LearnedDelayWarning on the wall clock); a plot's window is given
# or the events' own, never the clock's.
def _open(where=None) -> slr_sql.KnowledgeBase:
    return slr_sql.open(where, clock=slr_sql.ManualClock(0.0))


@pytest.fixture
def kb():
    """A fresh in-memory knowledge base with a ManualClock, closed after the test."""
    with _open() as k:
        yield k


# ---------------------------------------------------------------------------------------------
# reading pictures
# ---------------------------------------------------------------------------------------------

def render(fig, path: Path) -> np.ndarray:
    """Save as slr plot does and read the PNG back: an (height, width, channels) array of 0..1."""
    save_timeline(fig, str(path))
    return imread(str(path))


def blue(img):   # interval bars (#1f77b4 at alpha 0.8 over white)
    return (img[..., 2] - img[..., 0]) > 0.25


def red(img):    # complex events (#d62728)
    return ((img[..., 0] - img[..., 2]) > 0.3) & ((img[..., 0] - img[..., 1]) > 0.3)


def purple(img):  # value lines (#6a3d9a)
    return ((img[..., 2] - img[..., 1]) > 0.2) & ((img[..., 0] - img[..., 1]) > 0.1)


def dark(img):   # point ticks (#222222), but also text and spines: look inside the axes only
    return img[..., :3].max(axis=-1) < 0.4


def pixel(fig, ax, x: float, y: float) -> tuple[float, float]:
    """Data coordinates -> (column, row) in the saved PNG (rows count from the top)."""
    px, py = ax.transData.transform((x, y))
    return px, fig.get_size_inches()[1] * fig.dpi - py


def row_band(fig, ax, y: int, half: float = 0.2) -> slice:
    """Image rows of the middle of timeline row ``y``."""
    _, top = pixel(fig, ax, 0, y - half)
    _, bottom = pixel(fig, ax, 0, y + half)
    return slice(int(math.ceil(min(top, bottom))), int(max(top, bottom)))


def inside_columns(fig, ax) -> slice:
    """Image columns strictly inside the axes (no spines)."""
    x0, x1 = ax.get_xlim()
    left, _ = pixel(fig, ax, x0, 0)
    right, _ = pixel(fig, ax, x1, 0)
    return slice(int(left) + 2, int(right) - 1)


def runs(columns: np.ndarray) -> list[tuple[int, int]]:
    """Contiguous runs of column indices, as (first, last)."""
    out: list[tuple[int, int]] = []
    for c in columns.tolist():
        if out and c == out[-1][1] + 1:
            out[-1] = (out[-1][0], c)
        else:
            out.append((c, c))
    return out


# ---------------------------------------------------------------------------------------------
# size
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("width,height,dpi", [(600, 200, 100), (800, 300, 50), (1000, 450, 150)])
def test_png_has_the_requested_size(kb, tmp_path, width, height, dpi):
    kb.add("move(r1)^[2, 8]")
    img = render(kb.plot(size=(width, height), dpi=dpi), tmp_path / "t.png")
    assert img.shape[:2] == (height, width)


def test_height_grows_with_the_rows_when_not_given(kb, tmp_path):
    kb.add("a(1)^1")
    one = render(kb.plot(size=(700, None)), tmp_path / "one.png")
    for name in "bcdefgh":
        kb.add(f"{name}(1)^1")
    eight = render(kb.plot(size=(700, None)), tmp_path / "eight.png")
    with_values = render(kb.plot(size=(700, None), values=["a:1"]), tmp_path / "v.png")
    assert one.shape[1] == eight.shape[1] == with_values.shape[1] == 700
    assert one.shape[0] < eight.shape[0] < with_values.shape[0]


# ---------------------------------------------------------------------------------------------
# content
# ---------------------------------------------------------------------------------------------

def test_an_interval_is_a_bar_over_exactly_its_columns(kb, tmp_path):
    kb.add("move(r1)^[2, 8]")
    fig = kb.plot(start=0, end=10, size=(800, 200))
    img = render(fig, tmp_path / "bar.png")
    ax = fig.axes[0]
    band = img[row_band(fig, ax, 0)]
    columns = np.nonzero(blue(band).any(axis=0))[0]
    assert len(runs(columns)) == 1
    left, _ = pixel(fig, ax, 2, 0)
    right, _ = pixel(fig, ax, 8, 0)
    assert abs(columns[0] - left) <= 1.5 and abs(columns[-1] - right) <= 1.5
    assert blue(band[:, columns[0]:columns[-1] + 1]).all(axis=0).all()  # solid, no holes
    inside = img[row_band(fig, ax, 0, half=0.5)]  # the whole row (the legend is above it)
    assert not blue(inside[:, : int(left) - 2]).any() and not blue(inside[:, int(right) + 3:]).any()


def test_points_are_ticks_at_their_times(kb, tmp_path):
    for t in (1, 4.5, 9):
        kb.add(f"bump(r1)^{t}")
    fig = kb.plot(start=0, end=10, size=(800, 200))
    img = render(fig, tmp_path / "ticks.png")
    ax = fig.axes[0]
    inside = inside_columns(fig, ax)
    band = dark(img[row_band(fig, ax, 0), inside])
    ticks = runs(np.nonzero(band.all(axis=0))[0] + inside.start)
    assert len(ticks) == 3
    for (first, last), t in zip(ticks, (1, 4.5, 9)):
        assert abs((first + last) / 2 - pixel(fig, ax, t, 0)[0]) <= 1.5
        assert last - first <= 3  # a tick, not a bar
    assert not blue(img).any()


def test_each_type_gets_its_row_in_the_order_asked(kb, tmp_path):
    kb.add("move(r1)^[2, 4]")
    kb.add("dock(r1)^[6, 8]")
    fig = kb.plot(["dock", "move"], start=0, end=10, size=(800, 240))
    img = render(fig, tmp_path / "rows.png")
    ax = fig.axes[0]
    assert [t.get_text() for t in ax.get_yticklabels()] == ["dock/1", "move/1"]
    for y, (lo, hi) in enumerate([(6, 8), (2, 4)]):
        columns = np.nonzero(blue(img[row_band(fig, ax, y)]).any(axis=0))[0]
        assert abs(columns[0] - pixel(fig, ax, lo, 0)[0]) <= 1.5
        assert abs(columns[-1] - pixel(fig, ax, hi, 0)[0]) <= 1.5


def test_overlapping_intervals_are_stacked_in_lanes(kb, tmp_path):
    kb.add_many(["move(r1)^[1, 6]", "move(r2)^[4, 9]"])
    fig = kb.plot(start=0, end=10, size=(800, 200))
    img = render(fig, tmp_path / "lanes.png")
    ax = fig.axes[0]
    x = int(pixel(fig, ax, 5, 0)[0])
    _, top = pixel(fig, ax, 0, -0.3)
    _, bottom = pixel(fig, ax, 0, 0.3)
    column = blue(img[int(top):int(bottom) + 1, x])
    # both bars cross t=5, one above the other with a white seam between them
    assert len(runs(np.nonzero(column)[0])) == 2


VALUES = [3.0, 1.0, 4.0, 1.5, 5.0, 9.0, 2.0, 6.0]


def test_value_line_heights_follow_the_data(kb, tmp_path):
    kb.add_many([("speed", [v], float(t), float(t)) for t, v in enumerate(VALUES, start=1)])
    kb.add("speed(text)^9.5")  # not a number: not on the line
    fig = kb.plot(start=0, end=10, values=["speed:1"], size=(800, 400))
    img = render(fig, tmp_path / "values.png")
    value_ax = fig.axes[1]
    line = purple(img)
    heights = []
    for t, v in enumerate(VALUES, start=1):
        x, y = pixel(fig, value_ax, t, v)
        rows = np.nonzero(line[:, int(round(x))])[0]
        assert len(rows), f"no line at t={t}"
        assert abs(rows.mean() - y) <= 3
        heights.append(-rows.mean())
    assert np.argsort(heights).tolist() == np.argsort(VALUES).tolist()
    assert fig.slr_timeline.series[0].count == len(VALUES)


def test_value_paths_reach_into_lists_and_compound_terms(kb):
    kb.add_event("seg", ["cup1", [0.4, 0.1, 0.9]], start=1.0, end=1.0)
    kb.add_event("seg", ["cup1", [0.6, 0.1, 0.9]], start=2.0, end=2.0)
    kb.add("tf(base, world, pose([1.5, 0, 0], [0, 0, 0, 1]))^3")
    drawn = collect_timeline(kb, values=["seg:2[0]", "tf:arg3.pose[0][0]"])
    assert drawn.series[0].values == [0.4, 0.6]
    assert drawn.series[1].values == [1.5]


def test_complex_types_are_marked(kb, tmp_path):
    kb.add("alarm(x)^[2, 4]")
    kb.add("move(r1)^[6, 8]")
    fig = kb.plot(start=0, end=10, complex_types={"alarm/1"}, size=(800, 240))
    img = render(fig, tmp_path / "complex.png")
    ax = fig.axes[0]
    labels = ax.get_yticklabels()
    assert labels[0].get_text() == COMPLEX_MARK + "alarm/1"
    assert labels[1].get_text() == "move/1"
    inside = inside_columns(fig, ax)  # the label, left of the axes, is red too
    alarm = red(img[row_band(fig, ax, 0), inside]).any(axis=0)
    move = red(img[row_band(fig, ax, 1), inside]).any(axis=0)
    columns = np.nonzero(alarm)[0] + inside.start
    assert abs(columns[0] - pixel(fig, ax, 2, 0)[0]) <= 1.5
    assert abs(columns[-1] - pixel(fig, ax, 4, 0)[0]) <= 1.5
    assert not move.any() and blue(img[row_band(fig, ax, 1)]).any()


def test_complex_types_are_asked_of_the_source_when_not_given(kb):
    kb.add("alarm(x)^[2, 4]")
    kb.add("move(r1)^[6, 8]")

    class RuleEngineStore:
        """What an event-rule engine that stores derived events offers."""

        def sql(self, query, params=()):
            return kb.sql(query, params)

        def complex_event_types(self):
            return ["alarm"]

    rows = collect_timeline(RuleEngineStore()).rows
    assert [(r.label, r.complex) for r in rows] == [("alarm/1", True), ("move/1", False)]
    assert not any(r.complex for r in collect_timeline(RuleEngineStore(), complex_types=()).rows)


def test_default_rows_are_the_types_with_events_in_the_window(kb):
    kb.add_many(["b(1)^1", "a(1)^[2, 3]", "c(1)^50", "a(1, 2)^2"])
    assert [r.label for r in collect_timeline(kb, start=0, end=10).rows] == ["a/1", "a/2", "b/1"]
    assert [r.label for r in collect_timeline(kb, ["c", "a/1"], start=0, end=10).rows] == \
        ["c/1", "a/1"]


def test_an_event_store_is_a_source_too(tmp_path):
    with EventStore(tmp_path / "s.db") as store:
        store.add_event("move", ("r1",), 2.0, 8.0)
        img = render(timeline(store, start=0, end=10, size=(400, 150)), tmp_path / "s.png")
    assert img.shape[:2] == (150, 400) and blue(img).any()


def test_an_empty_store_draws_an_empty_timeline(kb, tmp_path):
    fig = kb.plot(size=(500, 200))
    img = render(fig, tmp_path / "empty.png")
    assert img.shape[:2] == (200, 500)
    assert not blue(img).any() and fig.slr_timeline.rows == []


# ---------------------------------------------------------------------------------------------
# many events: aggregated per pixel column
# ---------------------------------------------------------------------------------------------

N_TICKS, N_SPANS = 150_000, 50_000


@pytest.fixture(scope="module")
def big_kb():
    """200,000 events between t=2 and t=8: 150k points with a value, 50k short intervals."""
    k = _open()
    k.add_many([("tick", [i % 7], 2 + 6 * i / N_TICKS, 2 + 6 * i / N_TICKS)
                for i in range(N_TICKS)])
    k.add_many([("span", [i], 2 + 6 * i / N_SPANS, 2 + 6 * i / N_SPANS + 1e-3)
                for i in range(N_SPANS)])
    yield k
    k.close()


def artists(fig) -> int:
    return sum(len(ax.collections) + len(ax.lines) + len(ax.images) + len(ax.patches)
               + len(ax.texts) for ax in fig.axes)


def test_many_events_are_binned_into_a_bounded_figure(big_kb, tmp_path):
    fig = big_kb.plot(start=0, end=10, values=["tick:1"], size=(900, 300))
    drawn = fig.slr_timeline
    assert [(r.label, r.mode, r.count) for r in drawn.rows] == [
        ("span/1", "binned", N_SPANS), ("tick/1", "binned", N_TICKS)]
    assert drawn.series[0].mode == "binned" and drawn.series[0].count == N_TICKS
    assert artists(fig) <= 12  # a few per row, not one per event
    img = render(fig, tmp_path / "big.png")
    ax = fig.axes[0]
    left, right = pixel(fig, ax, 2, 0)[0], pixel(fig, ax, 8, 0)[0]
    for y, mask in ((0, blue), (1, dark)):
        band = img[row_band(fig, ax, y), inside_columns(fig, ax)]
        columns = np.nonzero(mask(band).any(axis=0))[0] + inside_columns(fig, ax).start
        assert abs(columns[0] - left) <= 2 and abs(columns[-1] - right) <= 2
        assert len(columns) >= 0.95 * (right - left)  # dense: (nearly) every column inked
    # the envelope of the values is their true range in every column: 0..6
    assert min(drawn.series[0].lows) == 0 and max(drawn.series[0].highs) == 6


def test_binned_counts_add_up(big_kb):
    drawn = collect_timeline(big_kb, start=0, end=10, size=(500, 200))
    spans, ticks = drawn.rows
    assert int(ticks.point_counts.sum()) == N_TICKS
    assert int(spans.coverage.max()) >= 1 and int(spans.coverage.sum()) >= N_SPANS
    assert spans.point_counts.sum() == 0 and ticks.coverage.sum() == 0


@settings(max_examples=40)
@given(events=st.lists(st.tuples(st.integers(0, 200), st.integers(0, 60)), min_size=1,
                       max_size=30),
       window=st.tuples(st.integers(-20, 100), st.integers(1, 200)))
def test_binned_coverage_matches_a_direct_count(events, window):
    """Per pixel column: the intervals overlapping it and the points in it, by brute force."""
    lo, hi = window[0] / 2, window[0] / 2 + window[1] / 2
    with _open() as kb:
        kb.add_many([("e", [i], s / 2, (s + d) / 2) for i, (s, d) in enumerate(events)])
        drawn = collect_timeline(kb, ["e"], start=lo, end=hi, size=(160, 100), exact_limit=0)
    row = drawn.rows[0]
    width, bins = (hi - lo) / drawn.bins, drawn.bins

    def column(t):
        return min(max(int((t - lo) / width), 0), bins - 1)

    coverage, points = np.zeros(bins, int), np.zeros(bins, int)
    for s, d in events:
        start, end = s / 2, (s + d) / 2
        if end < lo or start > hi:
            continue
        if start == end:
            points[column(start)] += 1
        else:
            coverage[column(max(start, lo)):column(min(end, hi)) + 1] += 1
    if row.mode == "exact":  # nothing in the window: nothing to bin
        assert row.count == 0 and not coverage.any() and not points.any()
        return
    assert row.coverage.tolist() == coverage.tolist()
    assert row.point_counts.tolist() == points.tolist()


# ---------------------------------------------------------------------------------------------
# errors, in words
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("options,message", [
    ({"types": ["nosuch"]}, r"unknown event type: nosuch \(the store has: move/1, speed/1\)"),
    ({"types": ["move/2"]}, r"unknown event type: move/2"),
    ({"values": ["speed"]}, r"bad value 'speed': expected TYPE:ARG"),
    ({"values": ["speed:0"]}, r"numbered from 1"),
    ({"values": ["speed:2"]}, r"speed/1 has 1 argument, not 2"),
    ({"values": ["nosuch:1"]}, r"unknown event type nosuch"),
    ({"values": ["move:1"]}, r"argument 1 of move/1 has no numeric values .*\(e\.g\. r1\)"),
    ({"start": 5, "end": 3}, r"empty time window: from 5 to 3"),
    ({"start": 5, "end": 5}, r"empty time window"),
    ({"start": float("nan")}, r"from must be a finite number"),
    # (an integer beyond any float raised OverflowError; one of 5,001 digits is described)
    ({"start": 10 ** 400}, r"from must be a finite number, not 1000.*\(401 characters\)"),
    ({"end": 10 ** 5000}, r"to must be a finite number, not an integer of about 5001 digits"),
    ({"end": "soon"}, r"to must be a number"),
    ({"start": -1e308, "end": 1e308}, r"too wide to draw"),
    ({"size": (5, 100)}, r"width must be a whole number of pixels"),
    ({"dpi": 0}, r"dpi must be"),
])
def test_bad_options_are_slr_errors(kb, options, message):
    kb.add("move(r1)^[2, 8]")
    kb.add("speed(0.5)^3")
    options = dict(options)
    types = options.pop("types", None)
    with pytest.raises(slr_sql.SLRError, match=message):
        kb.plot(types, **options)


def test_a_damaged_store_is_an_slr_error(kb):
    kb.add("move(r1)^[2, 8]")
    kb.sql('DROP TABLE "move"', write=True)  # the catalog still names the table
    with pytest.raises(slr_sql.SLRError, match="reading the store for the plot failed: .*no such table"):
        kb.plot()


def test_a_list_argument_without_a_path_gets_a_hint(kb):
    kb.add_event("seg", ["cup1", [0.4, 0.1, 0.9]], start=1.0, end=1.0)
    with pytest.raises(slr_sql.SLRError, match=r"give a path into it, e.g. seg:2\[0\]"):
        kb.plot(values=["seg:2"])


def test_option_parsers():
    assert parse_size("640x480") == (640, 480) and parse_size("640") == (640, None)
    assert parse_value_spec("seg/2:arg2[1]").path == "$[1]"
    with pytest.raises(slr_sql.SLRError, match="bad size"):
        parse_size("big")


# ---------------------------------------------------------------------------------------------
# the command line, through real processes
# ---------------------------------------------------------------------------------------------

def slr(*args: str, code: str | None = None) -> subprocess.CompletedProcess:
    command = [sys.executable, "-m", "slr_sql", *args] if code is None else \
        [sys.executable, "-c", code, *args]
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.run(command, capture_output=True, text=True, timeout=120, env=env,
                          cwd=REPO)


@pytest.fixture
def robot_db(db_path):
    with _open(db_path) as kb:
        kb.add_many(["move(r1)^[2, 8]", "bump(r1)^5", "speed(0.5)^1", "speed(0.9)^4"])
    return db_path


def test_cli_writes_the_picture_the_library_draws(robot_db, tmp_path):
    out = tmp_path / "cli.png"
    done = slr("plot", str(robot_db), "move", "bump", "--from", "0", "--to", "10",
               "--value", "speed:1", "--size", "640x360", "--dpi", "80", "-o", str(out))
    assert done.returncode == 0, done.stderr
    assert f"wrote {out} (640x360 px, 2 rows, 1 value line)" in done.stdout
    cli_img = imread(str(out))
    assert cli_img.shape[:2] == (360, 640)
    with slr_sql.open(robot_db) as kb:
        fig = kb.plot(["move", "bump"], start=0, end=10, values=["speed:1"], size=(640, 360),
                      dpi=80, title=robot_db.name)
        lib_img = render(fig, tmp_path / "lib.png")
    assert np.array_equal(cli_img, lib_img)
    assert blue(cli_img).any() and purple(cli_img).any()


def test_cli_marks_complex_types(robot_db, tmp_path):
    out = tmp_path / "c.png"
    done = slr("plot", str(robot_db), "--complex", "move", "-o", str(out))
    assert done.returncode == 0, done.stderr
    img = imread(str(out))
    assert img.shape[1] == 1200 and red(img).any() and not blue(img[:, :, :]).any()


@pytest.mark.parametrize("args,message", [
    (["nosuch"], "error: unknown event type: nosuch"),
    (["--value", "speed"], "error: bad value 'speed': expected TYPE:ARG"),
    (["--value", "speed:3"], "error: bad value 'speed:3': speed/1 has 1 argument, not 3"),
    (["--from", "5", "--to", "3"], "error: empty time window: from 5 to 3"),
    (["--size", "huge"], "error: bad size 'huge'"),
])
def test_cli_errors_are_words(robot_db, tmp_path, args, message):
    out = tmp_path / "x.png"
    done = slr("plot", str(robot_db), *args, "-o", str(out))
    assert done.returncode == 1
    assert message in done.stderr and "Traceback" not in done.stderr
    assert not out.exists()


def _event_count(db) -> int:
    with slr_sql.open(db, clock=slr_sql.ManualClock(0)) as kb:
        return sum(len(kb.query(goal)) for goal in ("move(_)^_", "bump(_)^_", "speed(_)^_"))


@pytest.mark.parametrize("how", ["symlink", "hard link", "another store"])
def test_cli_does_not_write_its_image_over_a_store(robot_db, tmp_path, how):
    # matplotlib writes through a link and truncates the file: an image took the store's place
    out = tmp_path / "view.png"
    if how == "symlink":
        out.symlink_to(robot_db)
    elif how == "hard link":
        os.link(robot_db, out)
    else:
        with _open(out) as kb:
            kb.add("other(r2)^1")
    before, events = Path(os.path.realpath(out)).read_bytes(), _event_count(robot_db)
    done = slr("plot", str(robot_db), "-o", str(out))
    assert done.returncode == 1, done.stdout
    assert done.stderr.startswith(f"error: cannot write {out}: it is "), done.stderr
    assert "would destroy the store" in done.stderr or "an SQLite database" in done.stderr
    assert Path(os.path.realpath(out)).read_bytes() == before
    assert _event_count(robot_db) == events > 0


def test_cli_into_a_named_pipe_does_not_wait_to_read_it(robot_db, tmp_path):
    # the check that -o is no SQLite database opened the pipe to read its first bytes,
    # which waits for a writer: the command never ended
    out = tmp_path / "view.png"
    os.mkfifo(out)
    done = subprocess.run([sys.executable, "-m", "slr_sql", "plot", str(robot_db), "-o",
                           str(out)], capture_output=True, text=True, timeout=60,
                          env={**os.environ, "PYTHONPATH": str(REPO)}, cwd=REPO)
    assert done.returncode == 1, done.stdout
    assert done.stderr == f"error: cannot write {out}: File or stream is not seekable.\n"


def test_cli_on_a_missing_store(tmp_path):
    missing = tmp_path / "nope.db"
    done = slr("plot", str(missing), "-o", str(tmp_path / "x.png"))
    assert done.returncode == 1
    assert f"no such store: {missing}" in done.stderr and "Traceback" not in done.stderr
    assert not missing.exists()


def test_cli_without_matplotlib_says_how_to_install_it(robot_db, tmp_path):
    # The same CLI in a process where importing matplotlib fails, as on an install without
    # the extra.
    code = ("import sys; sys.modules['matplotlib'] = None\n"
            "from slr_sql.cli import main; main(sys.argv[1:])")
    done = slr("plot", str(robot_db), "-o", str(tmp_path / "x.png"), code=code)
    assert done.returncode == 1
    assert "pip install 'slr_sql[plot]'" in done.stderr and "Traceback" not in done.stderr


def test_importing_the_package_does_not_import_matplotlib():
    done = slr(code="import sys, slr_sql, slr_sql.plot, slr_sql.cli; "
                    "print('matplotlib' in sys.modules)")
    assert done.stdout.strip() == "False", done.stderr


# ---------------------------------------------------------------------------------------------
# the README's picture
# ---------------------------------------------------------------------------------------------

def test_the_demo_picture_script(tmp_path):
    out = tmp_path / "demo.png"
    done = subprocess.run([sys.executable, str(REPO / "examples" / "plot_demo.py"), "-o", str(out)],
                          capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    img = imread(str(out))
    committed = imread(str(REPO / "docs" / "img" / "demo_timeline.png"))
    assert img.shape == committed.shape
    assert blue(img).any() and red(img).any() and dark(img).any()
