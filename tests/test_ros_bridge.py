"""slr ros bridge: a real rclpy publisher and the bridge in subprocesses, isolated on loopback
(ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, a random ROS_DOMAIN_ID set here); publishing
answers through Bridge.publish_answer to a real rclpy subscriber."""
from __future__ import annotations

import os
import queue
import random
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest

import slr_sql
from slr_sql import Atom, Struct
from slr_sql.ros.bridge import Bridge, PublishError
from slr_sql.ros.mapping import mapping_from_dict, mapping_from_pub_sub_xml

REPO = Path(__file__).resolve().parent.parent
DEADLINE = 30.0  # seconds; every wait below ends as soon as its condition holds


@pytest.fixture
def ros_env(monkeypatch):
    """Loopback-only discovery on a random domain, for this process and its children."""
    domain = str(random.SystemRandom().randint(1, 200))
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.setenv("ROS_DOMAIN_ID", domain)
    monkeypatch.delenv("ROS_LOCALHOST_ONLY", raising=False)
    return dict(os.environ)


@pytest.fixture
def prefix():
    """A topic prefix of this test run, so that two runs on one domain never mix."""
    return f"/t{random.SystemRandom().randrange(16 ** 6):06x}"


class Lines:
    """The stdout lines of a process, readable with a deadline."""

    def __init__(self, process: subprocess.Popen):
        self.lines: queue.Queue = queue.Queue()
        self.seen: list[str] = []
        threading.Thread(target=self._pump, args=(process.stdout,), daemon=True).start()

    def _pump(self, stream) -> None:
        with stream:                    # closed at the end of the output: no ResourceWarning
            for line in stream:
                self.lines.put(line.rstrip("\n"))

    def wait_for(self, text: str, deadline: float) -> str:
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise AssertionError(f"no line with {text!r}; got {self.seen}")
            try:
                line = self.lines.get(timeout=remaining)
            except queue.Empty:
                continue
            self.seen.append(line)
            if text in line:
                return line


PUBLISHER = textwrap.dedent("""
    import sys, time
    import rclpy
    from rclpy.node import Node
    from geometry_msgs.msg import PoseStamped
    from std_msgs.msg import Header
    prefix, count, done_at = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
    rclpy.init()
    node = Node("test_publisher")
    poses = node.create_publisher(PoseStamped, prefix + "/pose", 100)
    done = node.create_publisher(Header, prefix + "/done", 10)
    deadline = time.monotonic() + 30
    while (poses.get_subscription_count() == 0 or done.get_subscription_count() == 0):
        if time.monotonic() > deadline:
            sys.exit("no subscriber")
        rclpy.spin_once(node, timeout_sec=0.02)
    for i in range(count):
        msg = PoseStamped()
        now = time.time()
        msg.header.stamp.sec, msg.header.stamp.nanosec = int(now), int((now % 1) * 1e9)
        msg.header.frame_id = "map"
        msg.pose.position.x = float(i)
        poses.publish(msg)
    mark = Header()
    mark.stamp.sec, mark.stamp.nanosec = int(done_at), int(round((done_at % 1) * 1e9))
    done.publish(mark)
    print("published", flush=True)
    # stay until the bridge has taken everything (the test stops us)
    while True:
        rclpy.spin_once(node, timeout_sec=0.1)
""")


def write_map(tmp_path: Path, prefix: str) -> Path:
    path = tmp_path / "live.yaml"
    path.write_text(textwrap.dedent(f"""
        topics:
          {prefix}/pose:
            event: pose
            args: [header.frame_id, [pose.position.x, pose.position.y]]
        fully_updated:
          - topic: {prefix}/done
            types: [pose/2]
        publish:
          - topic: {prefix}/alarm
            type: std_msgs/msg/String
            event: "alarm(D)^T"
            fields: {{data: D}}
    """))
    return path


def count_events(db: Path) -> int:
    with slr_sql.open(db) as kb:
        return kb.query("aggregate_all(count, pose(_, _)^_, N)")[0]["N"]


@pytest.mark.parametrize("stop_signal", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_bridge_stores_published_messages_and_stops_cleanly(tmp_path, ros_env, prefix,
                                                          stop_signal):
    db = tmp_path / "live.db"
    count = 25
    done_at = time.time() + 1000.0  # in the future: only the mark can make pose/2 complete there
    bridge = subprocess.Popen(
        [sys.executable, "-m", "slr_sql", "ros", "bridge", str(db), "--map",
         str(write_map(tmp_path, prefix))],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ros_env, cwd=REPO)
    publisher = None
    try:
        deadline = time.monotonic() + DEADLINE
        out = Lines(bridge)
        out.wait_for("bridge ready", deadline)
        publisher = subprocess.Popen([sys.executable, "-c", PUBLISHER, prefix, str(count),
                                      repr(done_at)], stdout=subprocess.PIPE, text=True,
                                     env=ros_env)
        Lines(publisher).wait_for("published", deadline)
        while count_events(db) < count or _complete_until(db) < done_at:
            assert time.monotonic() < deadline, f"stored {count_events(db)} of {count}"
            assert bridge.poll() is None, bridge.stderr.read()
            time.sleep(0.02)  # polling the store file; the deadline bounds the wait
        bridge.send_signal(stop_signal)
        status = bridge.wait(timeout=DEADLINE)
        stderr = bridge.stderr.read()
        assert status == 0, stderr
        assert "Traceback" not in stderr
        out.wait_for("bridge stopped: 25 events from 26 messages, 1 completeness marks",
                     time.monotonic() + DEADLINE)
    finally:
        for process in (publisher, bridge):
            if process is not None and process.poll() is None:
                process.kill()
                process.wait()
            if process is not None and process.stderr is not None:
                process.stderr.close()
    with slr_sql.open(db) as kb:  # the store is intact after the signal
        answers = kb.query("pose(F, [X, Y])^T")
        delay = kb.sql("SELECT max(arrival - t_end) AS d FROM pose")[1][0][0]
    assert [a["X"] for a in answers] == [float(i) for i in range(count)]
    assert {a["F"] for a in answers} == {Atom("map")}
    assert 0 <= delay < 10  # stamps from the header, arrival from the store's clock


def _complete_until(db: Path) -> float:
    with slr_sql.open(db) as kb:
        return kb.complete_until("pose/2")


def _spin_until(bridge: Bridge, node, executor, condition, deadline: float) -> None:
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        bridge.spin_once(0.01)
        executor.spin_once(timeout_sec=0.01)


@pytest.fixture
def ros_node(ros_env):
    """A real rclpy node of the test (own context), to subscribe to what the bridge publishes."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node

    context = rclpy.Context()
    rclpy.init(context=context)
    node = Node("test_subscriber", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    yield node, executor
    executor.remove_node(node)
    node.destroy_node()
    executor.shutdown(timeout_sec=1.0)
    context.try_shutdown()


def test_publish_answer_to_a_real_subscriber(tmp_path, ros_node, prefix):
    from geometry_msgs.msg import PoseArray, PoseStamped
    from std_msgs.msg import String

    node, executor = ros_node
    mapping = mapping_from_dict({"tf": False, "publish": [
        {"topic": f"{prefix}/alarm", "type": "std_msgs/msg/String", "event": "alarm(D)^T",
         "fields": {"data": "D"}},
        {"topic": f"{prefix}/goal", "type": "geometry_msgs/msg/PoseStamped",
         "event": "goal(F, P)^T",
         "fields": {"header.frame_id": "F", "header.stamp": "T", "pose.position.x": "X",
                    "pose.orientation.w": {"$const": 1.0}}}]})
    xml = mapping_from_pub_sub_xml(
        f'<publish_subscribe><publish_to name="{prefix.lstrip("/")}/marker1" '
        f'msg_type="geometry_msgs/PoseStamped"/><publish_to name="{prefix.lstrip("/")}/poses" '
        f'msg_type="geometry_msgs/PoseArray"/></publish_subscribe>')
    mapping.publish += xml.publish
    received: dict[str, list] = {"alarm": [], "goal": [], "marker": [], "poses": []}
    node.create_subscription(String, f"{prefix}/alarm", received["alarm"].append, 10)
    node.create_subscription(PoseStamped, f"{prefix}/goal", received["goal"].append, 10)
    node.create_subscription(PoseStamped, f"{prefix}/marker1", received["marker"].append, 10)
    node.create_subscription(PoseArray, f"{prefix}/poses", received["poses"].append, 10)
    with slr_sql.open(tmp_path / "r.db") as kb:
        bridge = Bridge(kb, mapping, node_name="test_bridge").start()
        try:
            alarm, goal, marker, poses = bridge.mapping.publish
            deadline = time.monotonic() + DEADLINE
            _spin_until(bridge, node, executor,
                        lambda: all(bridge._publishers[e.topic].get_subscription_count() > 0
                                    for e in (alarm, goal, marker, poses)), deadline)
            bridge.publish_answer(alarm, {"D": Atom("door3"), "T": 12.5})
            bridge.publish_answer(goal, {"F": Atom("map"), "T": 7.25, "X": 1.5,
                                         "P": Struct("p", ())})
            header = Struct("std_msgs/msg/Header", (3.5, Atom("cam")))
            pose = Struct("geometry_msgs/msg/Pose", (
                Struct("geometry_msgs/msg/Point", (1.0, 2.0, 3.0)),
                Struct("geometry_msgs/msg/Quaternion", (0.0, 0.0, 0.0, 1.0))))
            bridge.publish_answer(marker, {"Msg": Struct("geometry_msgs/msg/PoseStamped",
                                                         (header, pose)), "T": 3.5})
            # a message term with field names (how --all stores messages): the fields it
            # names are set, in any order; the others keep their defaults
            def named(msgtype, **fields):
                return Struct(msgtype, tuple(Struct(":", (Atom(k), v)) for k, v in fields.items()))
            named_pose = named("geometry_msgs/msg/Pose",
                               position=named("geometry_msgs/msg/Point", z=3.0, x=1.0))
            bridge.publish_answer(poses, {"Msg": named(
                "geometry_msgs/msg/PoseArray", poses=[pose, named_pose],
                header=named("std_msgs/msg/Header", frame_id=Atom("cam"))), "T": 3.5})
            with pytest.raises(PublishError, match="no field 'nope'"):
                bridge.publish_answer(poses, {"Msg": named("geometry_msgs/msg/PoseArray",
                                                           nope=1)})
            _spin_until(bridge, node, executor,
                        lambda: all(received.values()), deadline)
            with pytest.raises(PublishError, match="fields.data: the answer has no variable D"):
                bridge.publish_answer(alarm, {"X": 1})
            with pytest.raises(PublishError, match="pose.position.x: expects a number"):
                bridge.publish_answer(goal, {"F": Atom("map"), "T": 1.0, "X": Atom("far")})
        finally:
            bridge.close()
    assert [m.data for m in received["alarm"]] == ["door3"]
    (g,) = received["goal"]
    assert (g.header.frame_id, g.header.stamp.sec, g.header.stamp.nanosec) == ("map", 7, 250000000)
    assert (g.pose.position.x, g.pose.orientation.w) == (1.5, 1.0)
    (m,) = received["marker"]
    assert (m.header.frame_id, m.header.stamp.sec, m.header.stamp.nanosec) == ("cam", 3, 500000000)
    assert (m.pose.position.x, m.pose.position.y, m.pose.position.z, m.pose.orientation.w) == \
        (1.0, 2.0, 3.0, 1.0)
    (array,) = received["poses"]
    assert [p.position.z for p in array.poses] == [3.0, 3.0]
    assert array.header.frame_id == "cam" and array.poses[1].orientation.w == 1.0
    assert bridge.stats.published == 4


def test_publish_entries_of_the_map_publish_what_the_store_derives(tmp_path, ros_node, prefix):
    """A MAP publish entry is a subscription of the knowledge base: events added after the
    bridge started (matching the entry's event and where) reach the ROS topic, others not."""
    from std_msgs.msg import String

    node, executor = ros_node
    mapping = mapping_from_dict({"tf": False, "publish": [
        {"topic": f"{prefix}/alarm", "type": "std_msgs/msg/String", "event": "alarm(D)^T",
         "where": "D \\== quiet", "fields": {"data": "D"}}]})
    received: list = []
    node.create_subscription(String, f"{prefix}/alarm", received.append, 10)
    # "now" when the bridge starts is 1.5: the entry publishes what ends from then on
    with slr_sql.open(tmp_path / "r.db", clock=slr_sql.ManualClock(1.5)) as kb:
        kb.add("alarm(before_start)^1")
        bridge = Bridge(kb, mapping, node_name="test_bridge_feed").start()
        try:
            (alarm,) = bridge.mapping.publish
            deadline = time.monotonic() + DEADLINE
            _spin_until(bridge, node, executor,
                        lambda: bridge._publishers[alarm.topic].get_subscription_count() > 0,
                        deadline)
            kb.add_many(["alarm(quiet)^2", "alarm(door3)^3", "other(door4)^4", "alarm(door5)^5"])
            _spin_until(bridge, node, executor, lambda: len(received) >= 2, deadline)
        finally:
            bridge.close()
    assert [m.data for m in received] == ["door3", "door5"]
    assert bridge.stats.published == 2


TF_PUBLISHER = textwrap.dedent("""
    import sys, time
    import rclpy
    from rclpy.node import Node
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from rosbags.typesys import Stores, get_typestore
    from slr_sql.ros.foreign_types import stand_in_class
    store = get_typestore(Stores.ROS2_KILTED)
    TF = "tf2_msgs/msg/TFMessage"
    t = store.types
    def message(stamp, parent, child, x):
        sec = int(stamp)
        return bytes(store.serialize_cdr(t[TF](transforms=[t["geometry_msgs/msg/TransformStamped"](
            header=t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](
                sec=sec, nanosec=int(round((stamp - sec) * 1e9))), frame_id=parent),
            child_frame_id=child,
            transform=t["geometry_msgs/msg/Transform"](
                translation=t["geometry_msgs/msg/Vector3"](x=x, y=0.0, z=0.0),
                rotation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)))]), TF))
    rclpy.init()
    node = Node("test_tf_publisher")
    stand_in = stand_in_class(TF, store)
    dynamic = node.create_publisher(stand_in, "/tf", 100)
    latched = node.create_publisher(stand_in, "/tf_static", QoSProfile(
        depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL))
    latched.publish(message(5.0, "base", "cam", 0.1))  # before the bridge is there: latched
    deadline = time.monotonic() + 30
    while dynamic.get_subscription_count() == 0 or latched.get_subscription_count() == 0:
        if time.monotonic() > deadline:
            sys.exit("no subscriber")
        rclpy.spin_once(node, timeout_sec=0.02)
    for i in range(10):
        dynamic.publish(message(10.0 + i, "map", "base", float(i)))
    print("published", flush=True)
    while True:
        rclpy.spin_once(node, timeout_sec=0.1)
""")


def test_bridge_tf_without_a_tf2_msgs_package(tmp_path, ros_env):
    """/tf and /tf_static (tf2_msgs has no wheel) through the built-in mapping, live."""
    from slr_sql.ros.bridge import message_class

    # With the ROS 2 wheels there is no tf2_msgs package: the stand-in type support is used.
    # (With a sourced ROS 2 that has tf2_msgs, the same test runs through the real one.)
    assert message_class("tf2_msgs/msg/TFMessage") is None or os.environ.get("AMENT_PREFIX_PATH")
    db = tmp_path / "tf.db"
    bridge = subprocess.Popen([sys.executable, "-m", "slr_sql", "ros", "bridge", str(db)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                              env=ros_env, cwd=REPO)
    publisher = None
    try:
        deadline = time.monotonic() + DEADLINE
        out = Lines(bridge)
        out.wait_for("bridge ready", deadline)
        publisher = subprocess.Popen([sys.executable, "-c", TF_PUBLISHER], stdout=subprocess.PIPE,
                                     text=True, env=ros_env)
        Lines(publisher).wait_for("published", deadline)
        while True:
            with slr_sql.open(db) as kb:
                stored = kb.query("aggregate_all(count, (tf(_, _, _)^_ ; tf_static(_, _, _)^_), N)"
                                  )[0]["N"]
            if stored >= 11:
                break
            assert time.monotonic() < deadline, f"stored {stored} of 11"
            assert bridge.poll() is None, bridge.stderr.read()
            time.sleep(0.02)
        bridge.send_signal(signal.SIGINT)
        assert bridge.wait(timeout=DEADLINE) == 0
    finally:
        for process in (publisher, bridge):
            if process is not None and process.poll() is None:
                process.kill()
                process.wait()
            if process is not None and process.stderr is not None:
                process.stderr.close()
    with slr_sql.open(db) as kb:
        static = kb.query("tf_static(base, cam, P)^T")
        moving = kb.query("tf(map, base, pose([X, _, _], _))^T")
    assert static == [{"P": Struct("pose", ([0.1, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])), "T": 5.0}]
    assert [(a["X"], a["T"]) for a in moving] == [(float(i), 10.0 + i) for i in range(10)]


def _bridge_stores_five_published(command: list[str], db: Path, node: str, prefix: str,
                                  env: dict) -> None:
    """Run a bridge `command`, publish five poses to it, and see them in the store."""
    bridge = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True, env=env, cwd=REPO)
    publisher = None
    try:
        deadline = time.monotonic() + DEADLINE
        out = Lines(bridge)
        ready = out.wait_for("bridge ready", deadline)
        assert f"node {node}" in ready and f"{prefix}/pose" in ready
        publisher = subprocess.Popen([sys.executable, "-c", PUBLISHER, prefix, "5",
                                      repr(time.time())], stdout=subprocess.PIPE, text=True,
                                     env=env)
        Lines(publisher).wait_for("published", deadline)
        while count_events(db) < 5:
            assert time.monotonic() < deadline, f"stored {count_events(db)} of 5"
            assert bridge.poll() is None, bridge.stderr.read()
            time.sleep(0.02)  # polling the store file; the deadline bounds the wait
        bridge.send_signal(signal.SIGINT)
        assert bridge.wait(timeout=DEADLINE) == 0
    finally:
        for process in (publisher, bridge):
            if process is not None and process.poll() is None:
                process.kill()
                process.wait()
            if process is not None and process.stderr is not None:
                process.stderr.close()


def test_bridge_takes_its_map_and_name_as_ros_arguments(tmp_path, ros_env, prefix):
    """`slr ros bridge DB --ros-args -p map:=FILE -r __node:=NAME --params-file F`: the MAP
    from the node's parameter, the node renamed, other parameters from a file."""
    db = tmp_path / "live.db"
    params = tmp_path / "params.yaml"
    params.write_text("my_bridge:\n  ros__parameters:\n    all_topics: false\n")
    _bridge_stores_five_published(
        [sys.executable, "-m", "slr_sql", "ros", "bridge", str(db), "--ros-args",
         "-p", f"map:={write_map(tmp_path, prefix)}", "-r", "__node:=my_bridge",
         "--params-file", str(params)], db, "my_bridge", prefix, ros_env)


@pytest.mark.parametrize("args, message", [
    (["--ros-args", "-p", "nonsense:=1"], "unknown ROS parameter(s) nonsense"),
    (["--ros-args", "-p", "all_topics:=maybe"], "all_topics: true or false"),
    (["extra"], "unexpected argument 'extra'"),
])
def test_bad_ros_arguments_are_clear_errors(tmp_path, ros_env, args, message):
    out = subprocess.run([sys.executable, "-m", "slr_sql", "ros", "bridge",
                          str(tmp_path / "x.db"), *args], capture_output=True, text=True,
                         env=ros_env, cwd=REPO, timeout=DEADLINE)
    assert out.returncode == 1 and message in out.stderr and "Traceback" not in out.stderr


def test_the_launch_file_runs_a_bridge_that_stores_what_is_published(tmp_path, ros_env,
                                                                      prefix):
    """examples/ros/bridge.launch.py's command, exactly as the launch description builds it
    (launch arguments substituted; ROS 2's `launch` package itself has no wheel), run with a
    real ROS publisher: the bridge takes the MAP and the node name from its ROS arguments."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "bridge_launch", REPO / "examples" / "ros" / "bridge.launch.py")
    launch_file = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(launch_file)
    db = tmp_path / "launched.db"
    command = launch_file.bridge_command(str(db), str(write_map(tmp_path, prefix)), "false",
                                         "launched_bridge")
    # A substitution list is concatenated, as launch does; `slr` is this checkout's CLI.
    argv = ["".join(a) if isinstance(a, list) else a for a in command]
    assert argv[0] == "slr"
    _bridge_stores_five_published([sys.executable, "-m", "slr_sql", *argv[1:]], db,
                                  "launched_bridge", prefix, ros_env)


def test_an_answer_beyond_floats_is_refused_and_the_feed_goes_on(tmp_path, ros_node, prefix):
    """An integer beyond any float in a float64 field raised OverflowError out of the
    subscription's callback (logged as a bug, not the one-line refusal of a
    PublishError); the answers after it still reach the topic."""
    from std_msgs.msg import Float64

    node, executor = ros_node
    mapping = mapping_from_dict({"tf": False, "publish": [
        {"topic": f"{prefix}/level", "type": "std_msgs/msg/Float64", "event": "level(V)^T",
         "fields": {"data": "V"}}]})
    levels: list = []
    logged: list = []
    node.create_subscription(Float64, f"{prefix}/level", levels.append, 10)
    with slr_sql.open(tmp_path / "r.db", clock=slr_sql.ManualClock(1.0)) as kb:
        bridge = Bridge(kb, mapping, node_name="test_bridge_huge", log=logged.append).start()
        try:
            (level,) = bridge.mapping.publish
            deadline = time.monotonic() + DEADLINE
            _spin_until(bridge, node, executor,
                        lambda: bridge._publishers[level.topic].get_subscription_count() > 0,
                        deadline)
            kb.add_many([("level", (10 ** 400,), 2.0, 2.0), ("level", (2.5,), 3.0, 3.0)])
            _spin_until(bridge, node, executor, lambda: levels, deadline)
        finally:
            bridge.close()
    assert [m.data for m in levels] == [2.5], logged
    assert any("is beyond any double" in line for line in logged), logged
