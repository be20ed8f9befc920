"""slr ros info BAG: topics, types, counts, time spans, frames in /tf and /tf_static, and a
draft MAP that imports the bag as it is."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

import slr_sql
from slr_sql.ros.bag_info import bag_info, draft_map
from slr_sql.ros.mapping import load_mapping
from test_ros_import import REPO, bag_path, make_bag, robot_items, tf_items


def slr(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "slr_sql", *args], capture_output=True,
                          text=True, timeout=60, cwd=REPO)


def static_items(fmt: str) -> list:
    return [("/tf_static", "tf2_msgs/msg/TFMessage", 99.0, {"transforms": [
        make_bag.transform(fmt, 0.0, "base", "laser", (0.2, 0.0, 0.3), (0.0, 0.0, 0.0, 1.0))]})]


@pytest.mark.parametrize("fmt", ["ros1", "sqlite3", "mcap"])
def test_info_lists_topics_time_spans_and_frames(tmp_path, fmt):
    path = make_bag.write_bag(bag_path(tmp_path, fmt), fmt,
                              tf_items(fmt, 4) + robot_items(fmt) + static_items(fmt))
    info = bag_info(path)
    by_topic = {t.topic: t for t in info.topics}
    assert sorted(by_topic) == ["/battery", "/detections", "/robot/goal", "/robot/status",
                                "/tf", "/tf_static"]
    assert by_topic["/battery"].msgtype == "std_msgs/msg/Float64"
    assert (by_topic["/battery"].count, by_topic["/battery"].first, by_topic["/battery"].last) \
        == (3, pytest.approx(50.7), pytest.approx(52.7))
    assert by_topic["/tf"].count == 4
    assert info.count == 4 + 12 + 1
    assert (info.start, info.end) == (pytest.approx(50.2), pytest.approx(100.76))
    frames = [(e.topic, e.parent, e.child, e.count, e.first, e.last) for e in info.frames]
    assert frames == [("/tf", "base", "cam", 4, 100.0, 100.75),
                      ("/tf", "map", "base", 4, 100.0, 100.75),
                      ("/tf_static", "base", "laser", 1, 0.0, 0.0)]


def test_the_draft_map_imports_the_bag_as_it_is(tmp_path):
    fmt = "mcap"
    path = make_bag.write_bag(bag_path(tmp_path, fmt), fmt, tf_items(fmt, 2) + robot_items(fmt))
    draft = tmp_path / "draft.yaml"
    out = slr("ros", "info", str(path), "--map-only")
    assert out.returncode == 0, out.stderr
    draft.write_text(out.stdout)
    mapping = load_mapping(draft)
    assert sorted(mapping.topics) == ["/battery", "/detections", "/robot/goal", "/robot/status"]
    db = tmp_path / "r.db"
    done = slr("ros", "import", str(path), str(db), "--map", str(draft))
    assert done.returncode == 0, done.stderr
    with slr_sql.open(db) as kb:
        assert [a["V"] for a in kb.query("battery(V)^T")] == [24.0, 23.0, 22.0]
        # a message with a header: its leaf fields, timed by the header stamp
        goal = kb.query("robot_goal(Frame, X, Y, Z)^T")
        assert goal[0] == {"Frame": "map", "X": 1.0, "Y": 2.0, "Z": 3.0, "T": pytest.approx(50.1)}
        assert len(kb.query("detections(F, Poses)^T")) == 3
        assert len(kb.query("tf(_, _, _)^_")) == 4


def test_the_cli_prints_tables_frames_and_the_draft(tmp_path):
    fmt = "ros1"
    path = make_bag.write_bag(bag_path(tmp_path, fmt), fmt, tf_items(fmt, 2) + static_items(fmt))
    out = slr("ros", "info", str(path))
    assert out.returncode == 0, out.stderr
    assert "/tf_static" in out.stdout and "laser" in out.stdout and "messages:  3" in out.stdout
    assert "draft MAP" in out.stdout and "topics: {}" in out.stdout
    data = json.loads(slr("ros", "info", str(path), "--json").stdout)
    assert data["count"] == 3 and {e["child"] for e in data["frames"]} == {"base", "cam", "laser"}


def test_a_missing_bag_is_an_error_without_a_traceback(tmp_path):
    out = slr("ros", "info", str(tmp_path / "nope.bag"))
    assert out.returncode == 1 and "cannot read" in out.stderr and "Traceback" not in out.stderr


def test_a_message_with_many_fields_is_taken_whole(tmp_path):
    fmt = "mcap"
    nine = [0.0] * 9
    items = [("/scan", "sensor_msgs/msg/Imu", 5.0, {
        "header": make_bag.header(fmt, 5.0, "imu"), "orientation_covariance": nine,
        "angular_velocity_covariance": nine, "linear_acceleration_covariance": nine})]
    path = make_bag.write_bag(bag_path(tmp_path, fmt), fmt, items)
    text = draft_map(bag_info(path))
    assert 'args: ["$msg"]' in text and "event: scan" in text


def test_info_of_an_slr_export(tmp_path):
    from slr_sql import ManualClock, Struct
    from slr_sql.viz.mcap_export import export_mcap

    with slr_sql.open(tmp_path / "r.db", clock=ManualClock(10.0)) as kb:
        kb.add_many([("tf", ("map", "base", Struct("pose", ([0.0, 0, 0], [0.0, 0, 0, 1]))), 1.0, 1.0),
                     ("tf", ("map", "base", Struct("pose", ([1.0, 0, 0], [0.0, 0, 0, 1]))), 2.0, 2.0),
                     ("seg", ("cup1", [1, 2, 3]), 1.5, 1.5)])
        export_mcap(kb.store, tmp_path / "out.mcap")
    info = bag_info(tmp_path / "out.mcap")
    assert info.export and info.count == 5 and (info.start, info.end) == (1.0, 2.0)
    kinds = {t.topic: (t.msgtype, t.count) for t in info.topics}
    assert kinds == {"/seg/2": ("slr event seg/2", 1), "/tf/3": ("slr event tf/3", 2),
                     "/tf": ("foxglove.FrameTransforms", 2)}
    assert [(e.parent, e.child, e.count, e.first, e.last) for e in info.frames] == \
        [("map", "base", 2, 1.0, 2.0)]
    assert "without a MAP" in draft_map(info)


def test_info_shows_the_id_the_import_of_an_export_records(tmp_path):
    # docs/ros.md: the id `slr ros info` shows is the one slr_import records; for an
    # export the two were computed apart, from other parts of the file, and differed
    from slr_sql import ManualClock
    from slr_sql.viz.mcap_export import export_mcap

    with slr_sql.open(tmp_path / "r.db", clock=ManualClock(10.0)) as kb:
        kb.add_many(["seen(a)^1", "seen(b)^2", "bump(r1)^3"])
        kb.mark_complete("seen/1", 2)
        export_mcap(kb.store, tmp_path / "out.mcap")
    shown = bag_info(tmp_path / "out.mcap").bag_id
    done = slr("ros", "import", str(tmp_path / "out.mcap"), "--db", str(tmp_path / "back.db"))
    assert done.returncode == 0, done.stderr
    assert done.stdout.rstrip().endswith(f"[{shown}]"), (shown, done.stdout)
    with slr_sql.open(tmp_path / "back.db", clock=ManualClock(10.0)) as kb:
        assert {str(a["B"]) for a in kb.query("slr_import(B, _, _)^_")} == {shown}


def test_info_of_an_slr_export_names_frames_as_tf_lookup_does(tmp_path):
    """An exported tf event's frames are terms: an atom is shown as it is, a string as
    "map" and a number as its text, so the frames tf_lookup keeps apart stay apart (a
    string was shown as the export's JSON object, {'$string': 'map'})."""
    from slr_sql import ManualClock, String, Struct
    from slr_sql.viz.mcap_export import export_mcap

    pose = Struct("pose", ([0.0, 0, 0], [0.0, 0, 0, 1]))
    with slr_sql.open(tmp_path / "r.db", clock=ManualClock(10.0)) as kb:
        kb.add_many([("tf", (String("map"), "base", pose), 1.0, 1.0),
                     ("tf", ("map", "base", pose), 2.0, 2.0),
                     ("tf", ("base", 1.0, pose), 3.0, 3.0)])
        export_mcap(kb.store, tmp_path / "out.mcap")
    info = bag_info(tmp_path / "out.mcap")
    assert sorted((e.parent, e.child, e.count) for e in info.frames) == \
        [('"map"', "base", 1), ("base", "1.0", 1), ("map", "base", 1)]
