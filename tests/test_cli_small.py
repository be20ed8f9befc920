"""The small things of the command line: --help one-liners, empty files, `slr ros import
--db` and what a failed import leaves, `slr demo --db` with the event-rule scene."""
from __future__ import annotations

import os
import re

import pytest
from test_cli import slr
from test_ros_import import make_bag, robot_items


@pytest.mark.parametrize("group", [[], ["ros"], ["fleet"]])
def test_help_shows_each_commands_first_sentence_whole(group):
    r = slr(*group, "--help", env_extra={"COLUMNS": "250"})
    assert r.returncode == 0
    commands = r.stdout.split("Commands:\n", 1)[1]
    lines: list[str] = []   # one entry per command, its wrapped lines joined
    for line in commands.splitlines():
        if re.match(r"  \S", line):
            lines.append(line.strip())
        elif line.strip():
            lines[-1] += " " + line.strip()
    assert len(lines) >= (15 if not group else 3)
    for line in lines:
        assert not line.endswith("..."), line
        assert line.endswith((".", ".)")), line
    if group:
        return
    sql = next(line for line in lines if line.startswith("sql "))
    # (click wraps the line at a hyphen: "read-" / "only")
    assert sql.replace("read- only", "read-only").endswith(
        'e.g. "SELECT * FROM seg" (read-only unless --write).')


@pytest.mark.parametrize("command", [["stats"], ["query", "p(X)^T"], ["sql", "SELECT 1"],
                                     ["describe"], ["programs"], ["explain", "p(X)"],
                                     ["plot", "-o", "x.png"]])
def test_an_empty_file_does_not_become_a_store(tmp_path, command):
    empty = tmp_path / "empty.db"
    empty.write_bytes(b"")
    args = [command[0], str(empty), *command[1:]]
    if command[0] == "plot":
        args[-1] = str(tmp_path / "x.png")
    r = slr(*args)
    assert r.returncode == 1
    assert r.stderr.startswith(f"error: no such store: {empty} is an empty file")
    assert empty.stat().st_size == 0 and sorted(os.listdir(tmp_path)) == ["empty.db"]


@pytest.mark.parametrize("before, after", [(["export"], ["out.mcap"]),
                                           (["foxglove"], ["--port", "0"]),
                                           (["fleet", "status"], []),
                                           (["fleet", "push"], ["fleet.db"])])
def test_the_views_and_the_fleet_do_not_make_an_empty_file_a_store(tmp_path, before, after):
    """README: only the commands that add to a store create one; export, foxglove and the
    fleet's status and push read DB (FLEET) and refuse an empty file, as stats does."""
    empty = tmp_path / "empty.db"
    empty.write_bytes(b"")
    r = slr(*before, str(empty), *[str(tmp_path / a) if a.endswith((".mcap", ".db")) else a
                                   for a in after], timeout=30)
    assert r.returncode == 1, r.stdout
    assert r.stderr.startswith(f"error: no such store: {empty} is an empty file"), r.stderr
    assert empty.stat().st_size == 0 and sorted(os.listdir(tmp_path)) == ["empty.db"]


def test_an_empty_file_becomes_a_store_where_events_are_added(tmp_path):
    empty = tmp_path / "empty.db"
    empty.write_bytes(b"")
    assert slr("add", str(empty), "p(a)^1").returncode == 0
    assert slr("query", str(empty), "p(X)^T").stdout == "X = a, T = 1.0\n"


@pytest.fixture
def bag(tmp_path):
    return make_bag.write_bag(tmp_path / "rec", "mcap", robot_items("mcap"))


@pytest.fixture
def robot_map(tmp_path):
    path = tmp_path / "robot.yaml"
    path.write_text("topics:\n  /battery:\n    args: [data]\n", encoding="utf-8")
    return path


def test_ros_import_takes_db_as_an_option_and_as_the_old_second_argument(tmp_path, bag,
                                                                         robot_map):
    first = tmp_path / "a.db"
    r = slr("ros", "import", str(bag), "--db", str(first), "--map", str(robot_map))
    assert r.returncode == 0, r.stderr
    assert "imported 3 events from 3 messages" in r.stdout
    second = tmp_path / "b.db"
    r = slr("ros", "import", str(bag), str(second), "--map", str(robot_map))
    assert r.returncode == 0, r.stderr
    assert slr("query", str(second), "battery(V)^T", "--limit", "1").stdout == "V = 24.0, T = 50.7\n"


def test_ros_import_with_two_different_stores_or_none_is_a_usage_error(tmp_path, bag):
    r = slr("ros", "import", str(bag), str(tmp_path / "a.db"), "--db", str(tmp_path / "b.db"))
    assert r.returncode == 2 and "two stores given" in r.stderr
    r = slr("ros", "import", str(bag))
    assert r.returncode == 2 and "--db DB" in r.stderr
    assert not list(tmp_path.glob("*.db"))


def test_a_map_that_does_not_fit_the_bag_leaves_no_store(tmp_path, bag):
    bad_map = tmp_path / "bad.yaml"
    bad_map.write_text("topics:\n  /battery:\n    args: [dta]\n", encoding="utf-8")
    db = tmp_path / "r.db"
    r = slr("ros", "import", str(bag), "--db", str(db), "--map", str(bad_map))
    assert r.returncode == 1 and "has no field 'dta'" in r.stderr
    assert not [p for p in os.listdir(tmp_path) if p.startswith("r.db")]


def test_a_failed_import_into_an_existing_store_keeps_it(tmp_path, bag):
    db = tmp_path / "r.db"
    assert slr("add", str(db), "p(a)^1").returncode == 0
    bad_map = tmp_path / "bad.yaml"
    bad_map.write_text("topics:\n  /battery:\n    args: [dta]\n", encoding="utf-8")
    assert slr("ros", "import", str(bag), "--db", str(db), "--map", str(bad_map)).returncode == 1
    assert slr("query", str(db), "p(X)^T").stdout == "X = a, T = 1.0\n"


def test_demo_db_keeps_the_event_rule_scene(tmp_path):
    db = tmp_path / "demo.db"
    r = slr("demo", "--db", str(db))
    assert r.returncode == 0, r.stderr
    faces = slr("query", str(db), "findall(F-[S, E], relFace(F)^[S, E], L)")
    assert faces.stdout == "L = [antonio-[8.0,11.0]]\n"
    doors = slr("query", str(db), "findall(D, doorLeftOpen(D)^[_, _], L)")
    assert doors.stdout == "L = [d2]\n"
    programs = slr("programs", str(db)).stdout
    assert re.search(r"^event_rules: 1 text from event_rules\.slr", programs, re.MULTILINE)
