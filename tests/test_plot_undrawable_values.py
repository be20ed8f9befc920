"""Red team of ``slr plot`` / ``kb.plot`` (docs/plots.md): values and times a figure cannot
draw get an SLRError in words before anything is drawn, never a raw matplotlib error (which
the command line can only print as "a bug in slr_sql") nor numpy overflow warnings."""
from __future__ import annotations

import io
import os
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

import slr_sql
from slr_sql import ManualClock
from slr_sql.plot import UndrawableRange

REPO = Path(__file__).resolve().parent.parent


def slr(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "slr_sql", *args], capture_output=True,
                          text=True, timeout=120, env={**os.environ, "PYTHONPATH": str(REPO)})


def far_store():
    """A store for events at far times: their delay declared, so none is learned from the
    clock (their "lateness" against ManualClock(0) is no delay of the store's)."""
    kb = slr_sql.open(clock=ManualClock(0.0))
    kb.load(":- max_delay(far/1, 0).")
    return kb


def drawn(kb, **options) -> bytes:
    """The PNG of kb.plot(**options): matplotlib works out ticks and limits only here."""
    out = io.BytesIO()
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)   # numpy overflow: a broken picture
        kb.plot(**options).savefig(out, format="png")
    return out.getvalue()


@pytest.mark.parametrize("values", [[1e308, -1e308], [1.7e308, 1.6e308], [8e307, -8e307],
                                    [0.5, 1.5e307]])
def test_values_beyond_what_a_plot_draws_are_refused_in_words(values):
    with slr_sql.open(clock=ManualClock(0.0)) as kb:
        kb.add_many([("speed", (v,), float(i), float(i)) for i, v in enumerate(values)])
        with pytest.raises(UndrawableRange, match=r"speed:1.*beyond what a plot can draw"):
            drawn(kb, values=["speed:1"])
        # the same values inside the limit draw
        kb.add_many([("speed2", (v / 1e10,), float(i), float(i))
                     for i, v in enumerate(values)])
        assert drawn(kb, values=["speed2:1"]).startswith(b"\x89PNG")


def test_a_binned_value_line_beyond_what_a_plot_draws_is_refused():
    with slr_sql.open(clock=ManualClock(0.0)) as kb:
        kb.add_many([("speed", (float(i),), float(i), float(i)) for i in range(500)]
                    + [("speed", (1e308,), 250.5, 250.5)])
        with pytest.raises(UndrawableRange, match="speed:1"):
            drawn(kb, values=["speed:1"], exact_limit=10)


@pytest.mark.parametrize("times", [[1e300], [3e11, 4e11], [1e305, 1.00001e305]])
def test_times_far_in_the_future_draw_on_a_plain_axis(times):
    """Beyond the year 9999 there is no calendar date to name: the axis is not made relative
    to one (it was: an OverflowError from datetime, as 'plot: OverflowError: ...')."""
    with far_store() as kb:
        kb.add_many([("far", (1,), t, t) for t in times])
        assert drawn(kb).startswith(b"\x89PNG")


@pytest.mark.parametrize("times", [[1.7e308, 1.6e308], [-1.7e308, -1.69e308], [1e308],
                                   [-1e308, 1e307]])
def test_times_beyond_what_a_plot_draws_are_refused_in_words(times):
    with far_store() as kb:
        kb.add_many([("far", (1,), t, t) for t in times])
        with pytest.raises(UndrawableRange, match="beyond what a plot can draw"):
            drawn(kb)


def test_relative_axis_asked_for_far_times_is_named_in_seconds():
    with far_store() as kb:
        kb.add_many([("far", (1,), t, t) for t in (3e11, 3e11 + 60)])
        png = drawn(kb, relative=True)
        assert png.startswith(b"\x89PNG")
        assert kb.plot(relative=True).axes[-1].get_xlabel() == "time (s) since 300000000000"


def test_the_cli_says_why_it_cannot_draw_the_values(tmp_path):
    db = tmp_path / "r.db"
    with slr_sql.open(db, clock=ManualClock(0.0)) as kb:
        kb.add_many([("v", (1e308,), 0.0, 0.0), ("v", (-1e308,), 1.0, 1.0)])
    result = slr("plot", str(db), "--value", "v:1", "-o", str(tmp_path / "x.png"))
    assert result.returncode == 1
    assert "error: bad value 'v:1': 1e+308 at t=0 is beyond what a plot can draw" \
        in result.stderr, result.stderr
    assert "bug" not in result.stderr and "warning" not in result.stderr
    assert "Traceback" not in result.stderr
    assert not (tmp_path / "x.png").exists()


@pytest.mark.parametrize("every", ["1e-300", "5e-324"])
def test_a_query_row_sampled_too_finely_is_refused_in_words(tmp_path, every):
    """``--every`` so small that the number of samples is beyond floats raised a raw
    OverflowError ("cannot convert float infinity to integer ... a bug in slr_sql")."""
    db = tmp_path / "r.db"
    with slr_sql.open(db, clock=ManualClock(0.0)) as kb:
        kb.add_many([("p", (1,), 0.0, 0.0), ("p", (2,), 10.0, 10.0)])
    result = slr("plot", str(db), "--query", "p(X)^T", "--every", every,
                 "-o", str(tmp_path / "q.png"))
    assert result.returncode == 1
    assert f"error: --every {float(every):g} asks the goal " in result.stderr, result.stderr
    assert "times between -0.2 and 10.2; at most 5000" in result.stderr
    assert len(result.stderr) < 200, result.stderr
    assert "bug" not in result.stderr and "Traceback" not in result.stderr


def test_the_number_of_samples_is_said_as_a_number_not_300_digits():
    with far_store() as kb:
        kb.add_many([("far", (1,), -1e300, -1e300), ("far", (2,), 1e300, 1e300)])
        with pytest.raises(slr_sql.SLRError) as caught:
            kb.plot(query="far(X)^T", every=100.0)
    message = str(caught.value)
    assert "asks the goal 2.08e+298 times between" in message, message
    assert len(message) < 200


def test_a_store_whose_file_name_is_no_utf8_is_drawn_with_its_name_escaped(tmp_path):
    """The figure's title is the store's file name; one holding a byte that is no UTF-8
    (a lone surrogate in Python) made matplotlib raise "TypeError: set_text(): incompatible
    function arguments" (printed as a bug in slr_sql). So did such a --title."""
    db = os.fsdecode(os.fsencode(str(tmp_path)) + b"/r\xffobot.db")
    with slr_sql.open(db, clock=ManualClock(0.0)) as kb:
        kb.add_many(["p(1)^1", "p(2)^2"])
    for args in ((), ("--title", os.fsdecode(b"run \xfe"))):
        result = slr("plot", db, *args, "-o", str(tmp_path / "out.png"))
        assert result.returncode == 0, result.stderr
        assert (tmp_path / "out.png").read_bytes()[:4] == b"\x89PNG"
        (tmp_path / "out.png").unlink()
