"""benchmarks/bench_events.py's throughput method: ours and ETALIS in rounds taking turns, the
headline the median of the per-round ratios. The figures themselves are the benchmark's
business (benchmarks/README.md); these tests hold the method: the order of the runs, which
rates each column is computed from, and the command line that asks for it."""
from __future__ import annotations

import argparse
import doctest
import importlib.util
import itertools
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
SCRIPT = REPO / "benchmarks" / "bench_events.py"


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("bench_events_under_test", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module   # its dataclasses look their module up there
    spec.loader.exec_module(module)
    yield module
    del sys.modules[spec.name]


@pytest.mark.parametrize("ours, theirs, expected", [
    # the ratio of the medians would be 90 / 50 = 1.8: each ratio pairs runs made together
    ([100.0, 60.0, 90.0], [50.0, 40.0, 100.0], (1.5, 0.9, 2.0)),
    ([3.0, 8.0], [2.0, 4.0], (1.75, 1.5, 2.0)),
    ([5.0], [4.0], (1.25, 1.25, 1.25)),
])
def test_the_headline_is_the_median_of_the_per_round_ratios(bench, ours, theirs, expected):
    assert bench.spread(ours, theirs) == pytest.approx(expected)


def _recording(bench, order, etalis_results):
    """Run functions that record their calls: ours at 2,000 events per CPU second, the
    baseline at 4,000, ETALIS's results taken in turn."""
    results = iter(etalis_results)

    def run_ours():
        order.append("ours")
        return (2000.0, 2000.0, 5)

    def run_etalis():
        order.append("etalis")
        return next(results)

    def run_baseline():
        order.append("baseline")
        return (4000.0, 4000.0, 0)

    return run_ours, run_etalis, run_baseline


def test_rounds_take_turns_and_go_on_until_both_engines_ran_long_enough(bench):
    order: list[str] = []
    # ETALIS at 1,000 events per CPU second: 1,000 events take it 1 s a round, ours 0.5 s
    runs = _recording(bench, order, [bench.EtalisRun(1000.0, 1000.0, 5, 1100.0)] * 20)
    rounds = bench.interleave(*runs, repeats=2, events=1000, least_seconds=3.0)
    # ours needs six rounds for 3 CPU seconds, ETALIS three: six rounds, order alternating
    assert order == ["ours", "etalis", "baseline", "etalis", "ours", "baseline"] * 3
    assert [pair.etalis_first for pair in rounds.pairs] == [False, True] * 3
    assert len(rounds.compared()) == 6 and rounds.etalis_failure == ""


def test_the_rounds_stop_at_the_most_unless_more_are_asked_for(bench):
    slow = [bench.EtalisRun(1e9, 1e9, 5, 1e9)] * 40   # never reaches its CPU seconds
    order: list[str] = []
    assert len(bench.interleave(*_recording(bench, order, slow), repeats=2, events=1,
                                least_seconds=10.0).pairs) == bench.MOST_ROUNDS
    order = []
    assert len(bench.interleave(*_recording(bench, order, slow), repeats=20, events=1,
                                least_seconds=10.0).pairs) == 20


def test_once_etalis_fails_ours_goes_on_alone(bench):
    order: list[str] = []
    runs = _recording(bench, order, ["> 60 s"])
    rounds = bench.interleave(*runs, repeats=3)
    assert order == ["ours", "etalis", "baseline", "ours", "baseline", "ours", "baseline"]
    assert rounds.etalis_failure == "> 60 s" and rounds.compared() == []
    assert len(rounds.pairs) == 3


def _cells(row: str) -> list[str]:
    return [cell.strip() for cell in row.strip().strip("|").split("|")]


def test_a_row_compares_real_runs_of_ours_with_the_median_etalis(bench, monkeypatch):
    """Ours runs for real (200 events of seq2 recent); ETALIS is replaced by three results
    whose CPU rates are 1, 3 and 2 million events/s: its median, 2 million, is what the
    floor's columns divide by, and the headline is the median of ours / each of them."""
    given = iter([bench.EtalisRun(rate, rate, 100, rate * 1.1)
                  for rate in (1e6, 3e6, 2e6)])
    monkeypatch.setattr(bench, "etalis", lambda *args: next(given))
    args = argparse.Namespace(n=200, n_one=0, synchronous="OFF", etalis_timeout=1.0,
                              repeats=3, round_seconds=0.0, no_one=True)
    row, order = bench.throughput_row("seq2", "recent", args, etalis_dir="given")
    cells = dict(zip(_cells(bench.THROUGHPUT_HEADER), _cells(row), strict=True))
    assert cells["detections (ours / ETALIS)"] == "100 / 100"

    ours = [float(rate.replace(",", "")) for rate in re.findall(r"ours ([\d,]+)", order)]
    assert len(ours) == 3 and order.index("ours") < order.index("ETALIS")
    def ratios(*rates: float) -> list[float]:
        return sorted(rate / etalis for rate, etalis in zip(rates, (1e6, 3e6, 2e6)))
    headline = cells["**add_many / ETALIS, median of the pairs (wall / CPU)**"]
    assert headline.rsplit("/ ", 1)[1] in _printings(
        lambda *rates: f"{ratios(*rates)[1]:.2f}x**", *ours)
    assert cells["CPU ratio, least–greatest (pairs)"] in _printings(
        lambda *rates: f"{ratios(*rates)[0]:.2f}–{ratios(*rates)[2]:.2f}x (3)", *ours)
    assert cells["ETALIS ev/s, median (wall / CPU / CPU main thread)"] == \
        "2,000,000 / 2,000,000 / 2,200,000"
    floor, floor_prov = (float(f.replace(",", "")) for f in
                         cells["floor ev/s, CPU (tables / + prov.)"].split(" / "))
    # The floor cell is rounded to whole events/s, the cells derived from it are not: each
    # may print either rounding of a value half an event/s either side of the cell's.
    assert cells["floor / ETALIS (CPU)"] in _printings(
        lambda f, g: f"{f / 2e6:.2f}x / {g / 2e6:.2f}x", floor, floor_prov)
    assert cells["1.5x budget the floor takes"] in _printings(
        lambda f, g: f"{1.5 * 2e6 / f:.0%} / {1.5 * 2e6 / g:.0%}", floor, floor_prov)


def _printings(show, *printed: float) -> set[str]:
    """What `show` prints for every value within the rounding of the printed whole numbers."""
    return {show(*values) for values in itertools.product(
        *[(value - 0.5, value, value + 0.5) for value in printed])}


def test_the_command_line_runs_the_rounds_it_is_asked_for():
    environment = {**os.environ, "ETALIS_DIR": ""}
    result = subprocess.run(
        [sys.executable, str(SCRIPT), "--part", "throughput", "--rules", "seq2", "--policies",
         "recent", "--no-one", "--n", "200", "--repeats", "2", "--round-seconds", "0",
         "--synchronous", "OFF"],
        capture_output=True, text=True, env=environment, timeout=120, check=True)
    lines = result.stdout.splitlines()
    header = next(line for line in lines if line.startswith("| rule |"))
    assert "median of the pairs" in header and "least–greatest (pairs)" in header
    row = next(line for line in lines if line.startswith("| seq2 | recent |"))
    assert len(_cells(row)) == len(_cells(header)) and "not run" in row
    runs = next(line for line in lines if line.startswith("* seq2 recent:"))
    assert len(re.findall(r"ours [\d,]+", runs)) == 2


def test_fewer_than_one_round_is_refused():
    result = subprocess.run([sys.executable, str(SCRIPT), "--part", "throughput",
                             "--repeats", "0"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 2 and "--repeats must be at least 1" in result.stderr


def test_the_examples_in_the_benchmark_run(bench):
    failures, tried = doctest.testmod(bench, verbose=False)
    assert tried >= 2 and failures == 0


def test_the_hand_written_engine_detects_what_ours_detects(bench):
    """The ceiling's engine, written for seq2 recent alone, finds the same complex events as
    ours on the same events, and stores them as ours does (rows in the complex type's and
    the provenance table)."""
    hand = bench.hand_written_seq2_recent(400, 100, "OFF")
    ours = bench.ours("seq2", "recent", 400, 100, "OFF")
    assert hand[2] == ours[2] == 200 and hand[1] > 0


def test_the_ceiling_row_divides_by_the_median_etalis(bench, monkeypatch):
    given = iter([bench.EtalisRun(rate, rate, 100, rate) for rate in (1e6, 3e6, 2e6)])
    monkeypatch.setattr(bench, "etalis", lambda *args: next(given))
    args = argparse.Namespace(n=200, synchronous="OFF", etalis_timeout=1.0, repeats=3,
                              round_seconds=0.0)
    row, order = bench.ceiling_row(args, etalis_dir="given")
    cells = _cells(row)
    assert cells[0] == "100 / 100" and cells[3] == "2,000,000"
    hand = [float(r.replace(",", "")) for r in re.findall(r"hand ([\d,]+)", order)]
    def ratios(*rates: float) -> list[float]:
        return sorted(h / e for h, e in zip(rates, (1e6, 3e6, 2e6)))
    assert any(cells[4].startswith(printed) for printed in _printings(
        lambda *rates: (f"**{ratios(*rates)[1]:.2f}x** "
                        f"({ratios(*rates)[0]:.2f}–{ratios(*rates)[2]:.2f}x)"), *hand))


def test_the_flat_run_builds_the_start_order_before_its_timing(bench, monkeypatch):
    """With a history stored, the start-ordered indexes the rule's statements want are
    built over the whole history once, before the timing: by the rule's load (and, before
    loads built them, by the flat part's first batch, added untimed, its CPU returned
    apart)."""
    at_timing: list[set[str]] = []
    feed = bench._feed

    def timed_feed(kb, *args):
        at_timing.append(set(kb.store.index_names("face")))
        feed(kb, *args)

    monkeypatch.setattr(bench, "_feed", timed_feed)
    first: list[float] = []
    rate, cpu, detections = bench.ours("seq3", "unrestricted", 300, 100, "OFF", history=3000,
                                       warmup=100, warmup_cpu=first)
    assert {"slr_ix__face__start", "slr_ix__face__a1_start"} <= at_timing[0]
    assert len(first) == 1 and first[0] > 0 and rate > 0 and cpu > 0 and detections > 0
    # (without the first batch too: the rule's load builds them now, not its first add)
    bench.ours("seq3", "unrestricted", 300, 100, "OFF", history=3000)
    assert {"slr_ix__face__start", "slr_ix__face__a1_start"} <= at_timing[1]
