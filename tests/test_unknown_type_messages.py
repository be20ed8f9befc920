"""A type that is not in the store, named to `slr export` or `slr plot`, is refused in one
line: the store's types are listed with their names as the terminal draws them (an event
type's name may hold a line break: it made a line of the message of its own, and a type
named so could print a line that reads as another message)."""
from __future__ import annotations

import pytest

import slr_sql
from slr_sql import ManualClock
from test_cli import slr


@pytest.mark.parametrize("command", [
    ["export", "{db}", "{out}.mcap", "nope"], ["plot", "{db}", "nope", "-o", "{out}.png"],
    ["plot", "{db}", "--value", "nope:1", "-o", "{out}.png"]])
def test_an_unknown_type_is_refused_in_one_line(tmp_path, command):
    db = tmp_path / "robot.db"
    with slr_sql.open(db, clock=ManualClock(10)) as kb:
        kb.add_many(["seen(a)^1", "'x\\nerror: forged'(a)^2"])
    done = slr(*[part.format(db=db, out=tmp_path / "out") for part in command])
    assert done.returncode == 1, done.stdout
    assert done.stderr.count("\n") == 1, done.stderr
    assert "the store" in done.stderr and "seen/1, 'x\\nerror: forged'/1" in done.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["robot.db"]
