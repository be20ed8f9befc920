"""slr ros import: bags written here with rosbags (rosbag1, rosbag2 sqlite3 and MCAP, plain
MCAP files), the built-in tf mapping, MAP files, --all, pub_sub.xml, resuming, the CLI."""
from __future__ import annotations

import functools
import importlib.util
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import given, settings, strategies as st

import slr_sql
from slr_sql import Atom, StreamClock, Struct
from slr_sql.ros import fast_tf
from slr_sql.ros.bag_import import BagError, import_bag
from slr_sql.ros.mapping import MappingError, load_mapping, mapping_from_dict

REPO = Path(__file__).resolve().parent.parent
EXAMPLES = REPO / "examples" / "ros"


def _load_example():
    spec = importlib.util.spec_from_file_location("make_bag", EXAMPLES / "make_bag.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


make_bag = _load_example()
# The stores that import a bag get a StreamClock, the clock of recorded data (its now is the
# greatest end time imported): with the default wall clock, messages stamped at the bags'
# epoch would arrive "months late" and each type would say so with a LearnedDelayWarning.
# (`slr ros import` itself moves a ManualClock along the bag's record times and learns no
# delays: tests/test_ros_import_clock.py.)
FORMATS = ["ros1", "sqlite3", "mcap", "mcap-file"]


def bag_path(tmp_path: Path, fmt: str, name: str = "rec") -> Path:
    return tmp_path / (f"{name}.bag" if fmt == "ros1" else f"{name}.mcap" if fmt == "mcap-file"
                       else name)


def tf_items(fmt: str, n: int, start: float = 100.0) -> list:
    """n TFMessages of two transforms each (map->base moving along x, base->cam fixed)."""
    items = []
    for i in range(n):
        t = start + i * 0.25
        items.append(("/tf", "tf2_msgs/msg/TFMessage", t + 0.01, {"transforms": [
            make_bag.transform(fmt, t, "map", "base", (0.5 * i, 2.0, 0.0), (0.0, 0.0, 0.0, 1.0)),
            make_bag.transform(fmt, t, "base", "cam", (0.1, 0.0, 1.2), (0.0, 0.0, 0.6, 0.8))]}))
    return items


def all_events(kb, name: str, arity: int) -> list:
    args = ", ".join(f"A{i}" for i in range(arity))
    answers = kb.query(f"{name}({args})^[S, E]")
    return [(tuple(a[f"A{i}"] for i in range(arity)), a["S"], a["E"]) for a in answers]


# ---------------------------------------------------------------------------------------------
# the built-in tf mapping, every bag format
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("fmt", FORMATS)
def test_tf_builtin_mapping_every_format(tmp_path, fmt):
    path = make_bag.write_bag(bag_path(tmp_path, fmt), fmt, tf_items(fmt, 6))
    with slr_sql.open(tmp_path / "r.db", clock=StreamClock()) as kb:
        report = import_bag(kb, path)
        assert (report.messages, report.events, report.rejected) == (6, 12, [])
        events = all_events(kb, "tf", 3)
    assert len(events) == 12
    expected = []
    for i in range(6):
        t = 100.0 + i * 0.25
        expected.append((("map", "base", Struct("pose", ([0.5 * i, 2.0, 0.0], [0.0, 0.0, 0.0, 1.0]))), t, t))
        expected.append((("base", "cam", Struct("pose", ([0.1, 0.0, 1.2], [0.0, 0.0, 0.6, 0.8]))), t, t))
    assert events == expected  # header stamps, not record times; one event per transform


@pytest.mark.parametrize("fmt", ["ros1", "mcap"])
def test_tf_direct_decoder_equals_general_mapping(tmp_path, fmt):
    """The built-in mapping's direct decoder and the same mapping written as a MAP (decoded
    by rosbags, mapped by the general code) store the same rows."""
    items = tf_items(fmt, 5)
    items.append(("/tf", "tf2_msgs/msg/TFMessage", 200.0, {"transforms": []}))  # empty message
    path = make_bag.write_bag(bag_path(tmp_path, fmt), fmt, items)
    spelled = {"topics": {"/tf": {
        "event": "tf", "foreach": "transforms",
        "args": ["header.frame_id", "child_frame_id",
                 {"pose": [["transform.translation.x", "transform.translation.y",
                            "transform.translation.z"],
                           ["transform.rotation.x", "transform.rotation.y",
                            "transform.rotation.z", "transform.rotation.w"]]}]}}}
    rows = []
    for mapping in (None, mapping_from_dict(spelled)):
        with slr_sql.open(clock=StreamClock()) as kb:
            import_bag(kb, path, mapping)
            rows.append(kb.sql("SELECT arg1, arg2, arg3, t_start, t_end FROM tf ORDER BY rowid")[1])
    assert rows[0] == rows[1] and len(rows[0]) == 10


@functools.cache
def shared_typestore(fmt: str):
    """rosbags' type store for ``fmt``, made once: a new one generates its message classes
    and serializers again (nine tenths of the test below when each example made two)."""
    return make_bag.typestore(fmt)


@settings(max_examples=40)
@given(st.lists(st.tuples(st.text(min_size=0, max_size=6), st.text(min_size=1, max_size=6),
                          st.lists(st.floats(allow_nan=False, allow_infinity=False, width=64),
                                   min_size=7, max_size=7),
                          st.integers(0, 2 ** 31 - 1), st.integers(0, 999_999_999)),
                min_size=0, max_size=4))
def test_tf_direct_decoder_matches_rosbags(transforms):
    """Random TFMessages serialized by rosbags (CDR and ROS 1) decode to the same values."""
    for fmt in ("cdr", "ros1"):
        store = shared_typestore("ros1" if fmt == "ros1" else "mcap")
        values = {"transforms": [
            {"header": {"stamp": {"sec": sec, "nanosec": ns}, "frame_id": parent,
                        **({"seq": 7} if fmt == "ros1" else {})},
             "child_frame_id": child,
             "transform": {"translation": dict(zip("xyz", v[:3])),
                           "rotation": dict(zip("xyzw", v[3:]))}}
            for parent, child, v, sec, ns in transforms]}
        msg = make_bag.message(store, "tf2_msgs/msg/TFMessage", values)
        if fmt == "cdr":
            events = fast_tf.decode_cdr(store.serialize_cdr(msg, "tf2_msgs/msg/TFMessage"), 0.0)
        else:
            events = fast_tf.decode_ros1(store.serialize_ros1(msg, "tf2_msgs/msg/TFMessage"), 0.0)
        expected = [("tf", (p, c, Struct("pose", (list(v[:3]), list(v[3:])))), s + n * 1e-9,
                     s + n * 1e-9) for p, c, v, s, n in transforms]
        assert events == expected


def test_cdr_big_endian_decodes_too():
    store = make_bag.typestore("mcap")
    msg = make_bag.message(store, "tf2_msgs/msg/TFMessage", {"transforms": [
        make_bag.transform("mcap", 3.5, "odom", "base", (1.0, 2.0, 3.0), (0.0, 0.0, 0.0, 1.0))]})
    raw = store.serialize_cdr(msg, "tf2_msgs/msg/TFMessage", little_endian=False)
    assert raw[1] == 0
    assert fast_tf.decode_cdr(raw, 0.0) == [
        ("tf", ("odom", "base", Struct("pose", ([1.0, 2.0, 3.0], [0.0, 0.0, 0.0, 1.0]))), 3.5, 3.5)]


# ---------------------------------------------------------------------------------------------
# MAP files
# ---------------------------------------------------------------------------------------------

def robot_items(fmt: str) -> list:
    items = []
    for i in range(3):
        t = 50.0 + i
        items.append(("/detections", "geometry_msgs/msg/PoseArray", t + 0.2, {
            "header": make_bag.header(fmt, t, "cam"),
            "poses": [{"position": {"x": float(k), "y": 0.5, "z": 1.0 + i}} for k in range(2)]}))
        items.append(("/battery", "std_msgs/msg/Float64", t + 0.7, {"data": 24.0 - i}))
        items.append(("/robot/status", "std_msgs/msg/String", t + 0.3, {"data": f"ok{i}"}))
        items.append(("/robot/goal", "geometry_msgs/msg/PointStamped", t + 0.4, {
            "header": make_bag.header(fmt, t + 0.1, "map"),
            "point": {"x": 1.0, "y": 2.0, "z": 3.0}}))
    return items


ROBOT_MAP = """
topics:
  /detections:
    event: seg
    foreach: poses
    args:
      - $msg.header.frame_id
      - [position.x, position.y, position.z]
      - {obj: [{$const: cup}, {$string: $msg.header.frame_id}, 7, true]}
  battery:                     # a relative name is the absolute topic /battery
    - {event: battery, args: [data]}
    - {event: power, args: [data], time: record}
"""


@pytest.mark.parametrize("fmt", ["ros1", "mcap"])
def test_custom_map_with_foreach(tmp_path, fmt):
    path = make_bag.write_bag(bag_path(tmp_path, fmt), fmt, robot_items(fmt))
    map_file = tmp_path / "robot.yaml"
    map_file.write_text(ROBOT_MAP)
    with slr_sql.open(clock=StreamClock()) as kb:
        report = import_bag(kb, path, load_mapping(map_file))
        seg = all_events(kb, "seg", 3)
        battery = all_events(kb, "battery", 1)
        power = all_events(kb, "power", 1)
    assert sorted(report.unmapped) == ["/robot/goal", "/robot/status"]
    # one event per pose, at the message's header stamp (the poses have no header)
    assert seg == [(("cam", [float(k), 0.5, 1.0 + i],
                     Struct("obj", (Atom("cup"), "cam", 7, Atom("true")))), 50.0 + i, 50.0 + i)
                   for i in range(3) for k in range(2)]
    assert kb_strings_are_strings(seg)
    # no header: the record time
    assert battery == [((24.0 - i,), recorded(50.7 + i), recorded(50.7 + i)) for i in range(3)] == power


def recorded(t: float) -> float:
    """A record time as the bag keeps it (integer nanoseconds) and the import reads it."""
    return int(round(t * 1e9)) * 1e-9


def kb_strings_are_strings(seg: list) -> bool:
    return all(type(e[0][2].args[1]) is str and type(e[0][2].args[0]) is slr_sql.Atom for e in seg)


@pytest.mark.parametrize("fmt", ["sqlite3", "ros1"])
def test_all_topics_become_events_named_after_the_topic(tmp_path, fmt):
    path = make_bag.write_bag(bag_path(tmp_path, fmt), fmt, robot_items(fmt) + tf_items(fmt, 1))
    with slr_sql.open(clock=StreamClock()) as kb:
        report = import_bag(kb, path, all_topics=True)
        status = all_events(kb, "robot_status", 1)
        goal = all_events(kb, "robot_goal", 1)
        tf = all_events(kb, "tf", 3)
    assert report.unmapped == [] and report.rejected == []
    assert status == [((message("std_msgs/msg/String", data=Atom(f"ok{i}")),), recorded(50.3 + i),
                       recorded(50.3 + i)) for i in range(3)]
    header = (lambda t: message("std_msgs/msg/Header", seq=0, stamp=t, frame_id=Atom("map"))) \
        if fmt == "ros1" else \
        (lambda t: message("std_msgs/msg/Header", stamp=t, frame_id=Atom("map")))
    assert goal == [((message("geometry_msgs/msg/PointStamped", header=header(50.1 + i),
                              point=message("geometry_msgs/msg/Point", x=1.0, y=2.0, z=3.0)),),
                     50.1 + i, 50.1 + i)
                    for i in range(3)]
    assert len(tf) == 2  # /tf keeps its built-in mapping


def message(msgtype: str, **fields) -> Struct:
    """A message term: the compound named by the type, fields as Name: Value."""
    return Struct(msgtype, tuple(Struct(":", (Atom(k), v)) for k, v in fields.items()))


@pytest.mark.parametrize("fmt", ["mcap", "ros1"])
def test_whole_messages_keep_their_field_names_in_sql_and_slr(tmp_path, fmt):
    path = make_bag.write_bag(bag_path(tmp_path, fmt), fmt, robot_items(fmt))
    db = tmp_path / "r.db"
    mapping = mapping_from_dict({"topics": {"/detections": [
        {"event": "detection", "foreach": "poses", "args": ["$msg.header", "$item"]},
        {"event": "detections"}]}})
    with slr_sql.open(db, clock=StreamClock()) as kb:
        import_bag(kb, path, mapping, all_topics=True)
        # SQL reads fields by name (--all: the whole message; templates taking a message too)
        x = kb.sql("SELECT json_extract(arg1, '$.point.x'), json_extract(arg1, '$.header.frame_id'),"
                   " json_extract(arg1, '$.\"$type\"') FROM robot_goal ORDER BY t_end")[1]
        assert x == [(1.0, "map", "geometry_msgs/msg/PointStamped")] * 3
        frames = kb.sql("SELECT DISTINCT json_extract(arg1, '$.frame_id'),"
                        " json_extract(arg2, '$.position.z') FROM detection ORDER BY 2")[1]
        assert frames == [("cam", 1.0), ("cam", 2.0), ("cam", 3.0)]
        lists = kb.sql("SELECT json_extract(arg1, '$.poses[1].position.x') FROM detections")[1]
        assert lists == [(1.0,)] * 3
        # SLR: get_field/3 by a dotted path, a list path, or unification of Name: Value
        answers = kb.query("robot_goal(M)^T, get_field(M, 'point.y', Y), "
                           "get_field(M, [header, frame_id], F)")
        assert [(a["Y"], a["F"]) for a in answers] == [(2.0, "map")] * 3
        xs = kb.query("detections(M)^T, get_field(M, 'poses[1].position.x', X)")
        assert [a["X"] for a in xs] == [1.0] * 3
        named = kb.query("robot_goal(M)^T, M = 'geometry_msgs/msg/PointStamped'(_, point: P), "
                         "P = 'geometry_msgs/msg/Point'(x: X, _, _)")
        assert [a["X"] for a in named] == [1.0] * 3
        fields = kb.query("robot_status(M)^_, get_field(M, Name, V)", limit=1)
        assert (fields[0]["Name"], fields[0]["V"]) == ("data", "ok0")


def test_all_topics_name_clash_is_an_error(tmp_path):
    items = [("/a/b", "std_msgs/msg/Float64", 1.0, {"data": 1.0}),
             ("/a_b", "std_msgs/msg/Float64", 2.0, {"data": 2.0})]
    path = make_bag.write_bag(tmp_path / "clash", "mcap", items)
    with slr_sql.open(clock=StreamClock()) as kb, pytest.raises(slr_sql.SLRError, match="/a/b and /a_b|/a_b and /a/b"):
        import_bag(kb, path, all_topics=True)


def test_pub_sub_xml_is_a_mapping(tmp_path, fmt="mcap"):
    path = make_bag.write_bag(bag_path(tmp_path, fmt), fmt, robot_items(fmt) + tf_items(fmt, 2))
    xml = tmp_path / "pub_sub.xml"
    xml.write_text("""<?xml version="1.0"?>
<publish_subscribe>
    <!--<subscribe_to name="camera/image_raw" msg_type="sensor_msgs/Image"/>-->
    <subscribe_to name="tf" msg_type="tf/tfMessage"/>
    <subscribe_to name="robot/goal" msg_type="geometry_msgs/PointStamped"/>
    <publish_to name="marker1" msg_type="geometry_msgs/PoseStamped"/>
</publish_subscribe>
""")
    mapping = load_mapping(xml)
    assert [(p.topic, p.msgtype, p.event) for p in mapping.publish] == [
        ("/marker1", "geometry_msgs/msg/PoseStamped", "marker1(Msg)^T")]
    with slr_sql.open(clock=StreamClock()) as kb:
        report = import_bag(kb, path, mapping)
        assert len(all_events(kb, "tf", 3)) == 4
        goal = all_events(kb, "robot_goal", 1)
    assert [g[1] for g in goal] == [50.1, 51.1, 52.1]
    assert sorted(report.unmapped) == ["/battery", "/detections", "/robot/status"]


@pytest.mark.parametrize("text, key", [
    ("topics:\n  /odom:\n    evnt: odom\n", "topics./odom.evnt"),
    ("topic:\n  /odom: {}\n", "topic"),
    ("topics:\n  /odom:\n    event: Odom\n", "topics./odom.event"),
    ("topics:\n  /odom:\n    args: [a..b]\n", "topics./odom.args[0]"),
    ("topics:\n  /odom:\n    args: [[x, {f: 3}]]\n", "topics./odom.args[0][1].f"),
    ("topics:\n  /odom:\n    args: [{$nope: x}]\n", "topics./odom.args[0]"),
    ("topics:\n  /odom:\n    time: 3\n", "topics./odom.time"),
    ("topics:\n  /odom:\n    foreach: [a]\n", "topics./odom.foreach"),
    ("topics:\n  /odom:\n    type: nonsense\n", "topics./odom.type"),
    ("topics:\n  /odom:\n    event: slr_import\n", "topics./odom.event"),
    ("topics:\n  /odom:\n    - {event: a}\n    - {evnt: b}\n", "topics./odom[1].evnt"),
    ("publish:\n  - {topic: /x, type: std_msgs/msg/String}\n", "publish[0].event"),
    ("publish:\n  - {topic: /x, type: std_msgs/msg/String, event: 'a(X)^T', fields: {data: x}}\n",
     "publish[0].fields.data"),
    ("fully_updated:\n  - {topic: /done, types: [seg/x]}\n", "fully_updated[0].types[0]"),
    ("version: 2\n", "version"),
    ("tf: maybe\n", "tf"),
    ("topics: [1]\n", "topics"),
    ("topics:\n  /odom:\n    event: odom\n  bad: [\n", "robot.yaml:5"),
])
def test_bad_map_names_the_key(tmp_path, text, key):
    path = tmp_path / "robot.yaml"
    path.write_text(text)
    with pytest.raises(MappingError) as info:
        load_mapping(path)
    assert key in str(info.value)


@pytest.mark.parametrize("spec, message", [
    ({"event": "seg", "foreach": "poses", "args": ["positon.x"]},
     "topics./detections.args[0]: geometry_msgs/msg/Pose has no field 'positon' (fields: position, orientation)"),
    ({"event": "seg", "foreach": "header"}, "topics./detections.foreach: header is not a list field"),
    ({"event": "seg", "args": ["poses.position"]}, "topics./detections.args[0]"),
    ({"event": "seg", "time": "poses"}, "topics./detections.time: poses is neither a Time nor a number"),
    ({"event": "seg", "type": "std_msgs/msg/String"}, "topics./detections.type"),
])
def test_map_checked_against_the_bags_definitions(tmp_path, spec, message):
    path = make_bag.write_bag(tmp_path / "rec", "mcap", robot_items("mcap"))
    mapping = mapping_from_dict({"topics": {"/detections": spec}})
    with slr_sql.open(tmp_path / "r.db", clock=StreamClock()) as kb, pytest.raises(MappingError) as info:
        import_bag(kb, path, mapping)
    assert message in str(info.value)
    with slr_sql.open(tmp_path / "r.db", clock=StreamClock()) as kb:  # nothing was imported
        assert kb.query("aggregate_all(count, seg(_)^_, N)") == [{"N": 0}]


def test_index_paths_and_out_of_range_messages_are_rejected(tmp_path):
    items = [("/arr", "std_msgs/msg/Float64MultiArray", 1.0 + i, {"data": [float(k) for k in range(i)]})
             for i in range(4)]
    path = make_bag.write_bag(tmp_path / "rec", "mcap", items)
    mapping = mapping_from_dict({"topics": {"/arr": {"event": "second", "args": ["data[1]"]}}})
    with slr_sql.open(clock=StreamClock()) as kb:
        report = import_bag(kb, path, mapping)
        assert all_events(kb, "second", 1) == [((1.0,), 3.0, 3.0), ((1.0,), 4.0, 4.0)]
    assert [(r.topic, r.index) for r in report.rejected] == [("/arr", 1), ("/arr", 2)]
    assert "no element [1]" in report.rejected[0].reason


# ---------------------------------------------------------------------------------------------
# resuming, idempotence, rejected events
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("fmt", ["sqlite3", "ros1"])
def test_reimport_adds_nothing(tmp_path, fmt):
    path = make_bag.write_bag(bag_path(tmp_path, fmt), fmt, tf_items(fmt, 30) + robot_items(fmt))
    mapping = mapping_from_dict({"topics": {"/battery": {"event": "battery", "args": ["data"]}}})
    db = tmp_path / "r.db"
    with slr_sql.open(db, clock=StreamClock()) as kb:
        first = import_bag(kb, path, mapping, batch_size=7)
    with slr_sql.open(db, clock=StreamClock()) as kb:
        second = import_bag(kb, path, mapping, batch_size=7)
        counts = (kb.query("aggregate_all(count, tf(_,_,_)^_, N)"),
                  kb.query("aggregate_all(count, battery(_)^_, N)"))
    assert (first.events, first.skipped) == (63, 0)
    assert (second.events, second.messages, second.skipped) == (0, 0, 33)
    assert counts == ([{"N": 60}], [{"N": 3}])


def test_interrupted_import_continues_where_it_stopped(tmp_path):
    path = make_bag.write_bag(tmp_path / "rec", "mcap", tf_items("mcap", 50))

    class Interrupted(Exception):
        pass

    def stop_after_two_batches(done: int, total: int) -> None:
        if done >= 20:
            raise Interrupted()

    db = tmp_path / "r.db"
    with slr_sql.open(db, clock=StreamClock()) as kb, pytest.raises(Interrupted):
        import_bag(kb, path, progress=stop_after_two_batches, batch_size=20)
    with slr_sql.open(db, clock=StreamClock()) as kb:
        # two batches of 20 events (10 messages) each were committed with their checkpoints
        assert kb.query("aggregate_all(count, tf(_,_,_)^_, N)") == [{"N": 40}]
        checkpoint = kb.query("slr_import(B, T, N)^_")
        report = import_bag(kb, path, batch_size=20)
        assert (report.skipped, report.messages) == (20, 30)
        times = [a["T"] for a in kb.query("tf(map, base, _)^T")]
    assert [c["N"] for c in checkpoint] == [10, 20] and checkpoint[-1]["T"] == "/tf"
    assert times == [100.0 + i * 0.25 for i in range(50)]  # each transform once, in order


def test_rejected_events_are_reported_and_the_rest_stored(tmp_path):
    items = [("/battery", "std_msgs/msg/Float64", 1.0 + i, {"data": math.nan if i == 2 else float(i)})
             for i in range(5)]
    path = make_bag.write_bag(tmp_path / "rec", "mcap", items)
    mapping = mapping_from_dict({"topics": {"/battery": {"event": "battery", "args": ["data"]}}})
    with slr_sql.open(clock=StreamClock()) as kb:
        report = import_bag(kb, path, mapping)
        values = [v[0][0] for v in all_events(kb, "battery", 1)]
        again = import_bag(kb, path, mapping)
    assert values == [0.0, 1.0, 3.0, 4.0]
    assert [(r.topic, r.index, r.record_time) for r in report.rejected] == [("/battery", 3, 3.0)]
    assert "NaN" in report.rejected[0].reason and report.events == 4
    assert again.events == 0 and again.skipped == 5


def test_fully_updated_from_a_topic_marks_completeness(tmp_path):
    items = robot_items("mcap") + [("/seg_done", "std_msgs/msg/Header", 60.0,
                                    {"stamp": make_bag.stamp(52.5), "frame_id": "cam"})]
    path = make_bag.write_bag(tmp_path / "rec", "mcap", items)
    mapping = mapping_from_dict({
        "topics": {"/detections": {"event": "seg", "foreach": "poses", "args": ["position.x"]}},
        "fully_updated": [{"topic": "/seg_done", "types": "seg/1", "time": "stamp"}]})
    with slr_sql.open(clock=slr_sql.ManualClock(0.0)) as kb:
        import_bag(kb, path, mapping)
        assert kb.complete_until("seg/1") == 52.5


def test_bad_bags_are_errors_in_words(tmp_path):
    (tmp_path / "junk.bag").write_bytes(b"not a bag")
    with slr_sql.open(clock=StreamClock()) as kb:
        with pytest.raises(BagError, match="cannot read .*junk.bag"):
            import_bag(kb, tmp_path / "junk.bag")
        with pytest.raises(BagError, match="no such file"):
            import_bag(kb, tmp_path / "missing.bag")


# ---------------------------------------------------------------------------------------------
# the paper's tf example on an imported bag; the example files
# ---------------------------------------------------------------------------------------------

def test_paper_tf_interpolation_on_an_imported_bag(tmp_path):
    path = make_bag.write_bag(tmp_path / "demo", "mcap", make_bag.demo_items("mcap"))
    with slr_sql.open(clock=StreamClock()) as kb:
        import_bag(kb, path)
        kb.load_file(EXAMPLES / "tf_rules.slr")
        (answer,) = kb.query("tf(cam, base, TF)^T", args={"T": make_bag.EPOCH + 11.0})
        before = kb.query("tf(cam, base, TF)^T", args={"T": make_bag.EPOCH + 9.0})
    translation, rotation = answer["TF"].args
    assert translation == pytest.approx([0.1, 0.0, 1.3])
    half = math.radians(45) / 2
    assert rotation == pytest.approx([0.0, 0.0, math.sin(half), math.cos(half)])
    assert before == []


def test_example_script_and_map_through_the_cli(tmp_path):
    bag = tmp_path / "demo_bag"
    out = subprocess.run([sys.executable, str(EXAMPLES / "make_bag.py"), str(bag)],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    db = tmp_path / "demo.db"
    run = subprocess.run([sys.executable, "-m", "slr_sql", "ros", "import", str(bag), str(db),
                          "--map", str(EXAMPLES / "robot.yaml")],
                         capture_output=True, text=True, timeout=60, cwd=REPO)
    assert run.returncode == 0, run.stderr
    assert "imported 160 events from 160 messages" in run.stdout
    with slr_sql.open(db, clock=StreamClock()) as kb:
        assert kb.query("aggregate_all(count, seg(cup1, _)^_, N)") == [{"N": 24}]
        assert kb.query("battery(V)^T", limit=1) == [{"V": 24.0, "T": make_bag.EPOCH + 0.5}]


# ---------------------------------------------------------------------------------------------
# the command line as real processes
# ---------------------------------------------------------------------------------------------

def slr(*args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "slr_sql", *args], capture_output=True,
                          text=True, timeout=60, cwd=REPO, env=env)


def test_cli_import_all_and_again(tmp_path):
    path = make_bag.write_bag(tmp_path / "rec.bag", "ros1", tf_items("ros1", 3) + robot_items("ros1"))
    db = tmp_path / "r.db"
    first = slr("ros", "import", str(path), str(db), "--all")
    assert first.returncode == 0, first.stderr
    assert "imported 18 events from 15 messages" in first.stdout and "robot_status" in first.stdout
    again = slr("ros", "import", str(path), str(db), "--all")
    assert again.returncode == 0 and "imported 0 events from 0 messages (15 already imported)" in again.stdout
    rows = slr("sql", str(db), "SELECT count(*) AS n FROM tf", "--json")
    assert '"n": 6' in rows.stdout


def test_cli_errors_in_words(tmp_path):
    path = make_bag.write_bag(tmp_path / "rec", "mcap", robot_items("mcap"))
    bad_map = tmp_path / "bad.yaml"
    bad_map.write_text("topics:\n  /battery:\n    args: [dta]\n")
    db = tmp_path / "r.db"
    run = slr("ros", "import", str(path), str(db), "--map", str(bad_map))
    assert run.returncode == 1 and "Traceback" not in run.stderr
    assert "topics./battery.args[0]: std_msgs/msg/Float64 has no field 'dta' (fields: data)" in run.stderr
    missing = slr("ros", "import", str(tmp_path / "nope"), str(db))
    assert missing.returncode == 1 and "no such bag" in missing.stderr
    nan_items = [("/battery", "std_msgs/msg/Float64", 1.0, {"data": math.nan})]
    nan_bag = make_bag.write_bag(tmp_path / "nan", "mcap", nan_items)
    good_map = tmp_path / "good.yaml"
    good_map.write_text("topics:\n  /battery:\n    args: [data]\n")
    rejected = slr("ros", "import", str(nan_bag), str(db), "--map", str(good_map))
    assert rejected.returncode == 1 and "/battery message 1" in rejected.stderr


def test_cli_without_the_extra_says_what_to_install(tmp_path):
    code = ("import sys; sys.modules['rosbags'] = None; sys.modules['rclpy'] = None\n"
            "from slr_sql.cli import main\n"
            "main(sys.argv[1:], prog_name='slr')\n")
    for command in (["ros", "import", "x.bag", str(tmp_path / "r.db")],
                    ["ros", "bridge", str(tmp_path / "r.db")]):
        run = subprocess.run([sys.executable, "-c", code, *command], capture_output=True,
                             text=True, timeout=60, cwd=REPO)
        assert run.returncode == 1, run.stderr
        assert "pip install 'slr_sql[ros]'" in run.stderr and "Traceback" not in run.stderr
    help_run = subprocess.run([sys.executable, "-c", code, "--help"], capture_output=True,
                              text=True, timeout=60, cwd=REPO)
    assert help_run.returncode == 0 and "ros" in help_run.stdout
    assert not (tmp_path / "r.db").exists()




def test_import_uses_only_the_public_api():
    """slr_sql.ros sits above the facade: no store, sqlite3 or kb internals."""
    sources = [p.read_text() for p in (REPO / "slr_sql" / "ros").glob("*.py")]
    for text in sources:
        for forbidden in ("import sqlite3", "slr_sql.store", "from ..store", "from ..kb",
                          "slr_sql.kb", "._sync", ".store."):
            assert forbidden not in text
    assert os.path.exists(REPO / "slr_sql" / "ros" / "__init__.py")
