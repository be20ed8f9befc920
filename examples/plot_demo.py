"""The README's timeline picture, made from the robot scenario of ``slr demo``.

    python examples/plot_demo.py                 # writes docs/img/demo_timeline.png
    python examples/plot_demo.py -o /tmp/x.png

It publishes the scenario's events (tf, seg, obj, in their arrival order) into a temporary
store with the demo's robot program, adds the control component's look at table1 as an
interval, and derives two complex event types with the program's own rules:

* ``fresh(O)^[A, B]``: while ``location(O, L)`` answers a position (not "outdated"), asked
  every 0.1 s — the temporal-validity rule of the paper;
* ``base_x(X)^T``: the base's x in the world, ``tf(base, world, TF)^T`` every 0.1 s — the
  interpolation / extrapolation rule, drawn as a value line as well.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from slr_sql.demo import TABLE_SWEEP, open_robot_kb, publish, scenario_events  # noqa: E402

STEP = 0.1            # seconds between the rule queries that derive the complex events
HORIZON = (10.0, 20.0)
SIZE = (1000, 460)    # pixels


def _grid() -> list[float]:
    steps = int(round((HORIZON[1] - HORIZON[0]) / STEP))
    return [round(HORIZON[0] + i * STEP, 6) for i in range(steps + 1)]


def fresh_intervals(kb, objects: list[str]) -> list[tuple]:
    """``fresh(O)^[A, B]`` for each run of grid times where ``location(O, L)^T`` is a position."""
    events = []
    for obj in objects:
        run_start = last = None
        for t in _grid():
            answers = kb.query("location(O, L)^T", args={"O": obj, "T": t})
            fresh = bool(answers) and isinstance(answers[0]["L"], list)
            if fresh and run_start is None:
                run_start = t
            if fresh:
                last = t
            if not fresh and run_start is not None:
                events.append(("fresh", [obj], run_start, last))
                run_start = None
        if run_start is not None:
            events.append(("fresh", [obj], run_start, last))
    return events


def base_positions(kb) -> list[tuple]:
    """``base_x(X)^T``: the x of ``tf(base, world, TF)^T`` as the rules give it."""
    events = []
    for t in _grid():
        answers = kb.query("tf(base, world, pose([X, _, _], _))^T", args={"T": t})
        if answers:
            events.append(("base_x", [float(answers[0]["X"])], t, t))
    return events


def build_figure(db_path: str):
    kb, clock = open_robot_kb(db_path)
    try:
        publish(kb, clock, scenario_events())
        kb.add_event("look_at", ["table1"], start=TABLE_SWEEP[0], end=TABLE_SWEEP[1])
        objects = sorted({str(row[0]) for row in kb.sql("SELECT arg1 FROM seg")[1]})
        kb.add_many(fresh_intervals(kb, objects) + base_positions(kb))
        return kb.plot(["tf", "seg", "obj", "look_at", "fresh", "base_x"],
                       values=["base_x:1"], complex_types={"fresh", "base_x"},
                       start=9.5, end=20.5, size=SIZE,
                       title="slr demo: robot X looks at table1")
    finally:
        kb.close()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--output", default=str(ROOT / "docs" / "img" / "demo_timeline.png"))
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as scratch:
        figure = build_figure(str(Path(scratch) / "demo.db"))
    Path(args.output).parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(args.output, dpi=figure.dpi)
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
