"""ROS import and bridge figures (benchmarks/README.md, "ROS import").

    python benchmarks/bench_ros_import.py                 # import vs rosbags alone
    python benchmarks/bench_ros_import.py --bridge        # also the live bridge latency

Import: a rosbag2 (MCAP) bag of N TFMessages (one transform each, as a robot's /tf at high
rate) is read and deserialized with rosbags' AnyReader alone (the baseline: the least any
import must do), then imported into a new file store with `import_bag` (default durability,
synchronous=FULL), both in the same process, runs alternated; best of --repeat. Also the
import through the general decoder+mapping path (the same events, without the direct tf
decoder) for comparison.

Bridge: a publisher process sends geometry_msgs/PoseStamped at --rate Hz with the header
stamp set to the wall clock just before publishing; the bridge process stores each message
as it arrives; latency = arrival (the store's wall clock when the event is stored) - stamp,
read back from the store. Loopback only, a random ROS domain.
"""
from __future__ import annotations

import argparse
import gc
import os
import random
import shutil
import statistics
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

import slr_sql  # noqa: E402
from slr_sql.ros import fast_tf  # noqa: E402
from slr_sql.ros.bag_import import import_bag, open_bag  # noqa: E402


def write_tf_bag(path: Path, n: int) -> None:
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_KILTED)
    types = store.types
    TF, TS = types["tf2_msgs/msg/TFMessage"], types["geometry_msgs/msg/TransformStamped"]
    H, T = types["std_msgs/msg/Header"], types["builtin_interfaces/msg/Time"]
    Tr, V, Q = (types["geometry_msgs/msg/Transform"], types["geometry_msgs/msg/Vector3"],
                types["geometry_msgs/msg/Quaternion"])
    rng = random.Random(1)
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/tf", TF.__msgtype__, typestore=store)
        for i in range(n):
            t = 1_700_000_000 + i * 0.001
            sec = int(t)
            yaw = rng.uniform(-1, 1)
            msg = TF(transforms=[TS(
                header=H(stamp=T(sec=sec, nanosec=int((t - sec) * 1e9)), frame_id="odom"),
                child_frame_id="base_link",
                transform=Tr(translation=V(x=rng.uniform(-50, 50), y=rng.uniform(-50, 50), z=0.0),
                             rotation=Q(x=0.0, y=0.0, z=yaw / 2, w=(1 - yaw * yaw / 4) ** 0.5)))])
            writer.write(conn, int(t * 1e9), store.serialize_cdr(msg, TF.__msgtype__))


def rosbags_alone(path: Path) -> tuple[float, int]:
    start = time.perf_counter()
    transforms = 0
    reader = open_bag(path)
    try:
        for conn, _, raw in reader.messages():
            transforms += len(reader.deserialize(raw, conn.msgtype).transforms)
    finally:
        reader.close()
    return time.perf_counter() - start, transforms


def slr_import(path: Path, workdir: Path, direct: bool) -> tuple[float, int]:
    db = workdir / "import.db"
    for suffix in ("", "-wal", "-shm"):
        Path(str(db) + suffix).unlink(missing_ok=True)
    original = fast_tf.compile_for
    if not direct:
        fast_tf.compile_for = lambda *args: None
    try:
        with slr_sql.open(db) as kb:
            start = time.perf_counter()
            report = import_bag(kb, path)
            elapsed = time.perf_counter() - start
    finally:
        fast_tf.compile_for = original
    return elapsed, report.events


def bench_import(n: int, repeat: int) -> None:
    workdir = Path(tempfile.mkdtemp(prefix="bench_ros_"))
    try:
        bag = workdir / "tf_bag"
        write_tf_bag(bag, n)
        best = {"rosbags": float("inf"), "import": float("inf"), "general": float("inf")}
        for run in range(repeat):
            gc.collect()
            for name in (["rosbags", "import", "general"] if run % 2 == 0
                         else ["general", "import", "rosbags"]):
                if name == "rosbags":
                    elapsed, count = rosbags_alone(bag)
                else:
                    elapsed, count = slr_import(bag, workdir, direct=(name == "import"))
                assert count == n, (name, count)
                best[name] = min(best[name], elapsed)
                print(f"  run {run + 1} {name:8s} {n / elapsed:10,.0f} transforms/s", flush=True)
        rate = {k: n / v for k, v in best.items()}
        print(f"\n{n:,} TFMessages (1 transform each), best of {repeat}:")
        print("| path | transforms/s | / rosbags alone |")
        print("|---|---:|---:|")
        for name, label in (("rosbags", "rosbags AnyReader: read + deserialize"),
                            ("import", "`import_bag` (direct tf decoder)"),
                            ("general", "`import_bag`, general decoder + mapping")):
            print(f"| {label} | {rate[name]:,.0f} | {rate[name] / rate['rosbags']:.2f} |")
    finally:
        shutil.rmtree(workdir, ignore_errors=True)


PUBLISHER = textwrap.dedent("""
    import sys, time
    import rclpy
    from rclpy.node import Node
    from geometry_msgs.msg import PoseStamped
    count, rate = int(sys.argv[1]), float(sys.argv[2])
    rclpy.init()
    node = Node("bench_publisher")
    pub = node.create_publisher(PoseStamped, "/bench_pose", 1000)
    while pub.get_subscription_count() == 0:
        rclpy.spin_once(node, timeout_sec=0.01)
    time.sleep(0.5)
    period = 1.0 / rate
    next_at = time.monotonic()
    msg = PoseStamped()
    msg.header.frame_id = "map"
    for i in range(count):
        next_at += period
        delay = next_at - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        now = time.time()
        msg.header.stamp.sec, msg.header.stamp.nanosec = int(now), int((now % 1) * 1e9)
        msg.pose.position.x = float(i)
        pub.publish(msg)
    print("published", flush=True)
    time.sleep(1.0)
""")


def _cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process so far (Linux)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def bench_bridge(count: int, rate: float) -> None:
    workdir = Path(tempfile.mkdtemp(prefix="bench_bridge_"))
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               ROS_DOMAIN_ID=str(random.SystemRandom().randint(1, 200)))
    env.pop("ROS_LOCALHOST_ONLY", None)
    mapfile = workdir / "bench.yaml"
    mapfile.write_text("tf: false\ntopics:\n  /bench_pose:\n    event: pose\n"
                       "    args: [pose.position.x]\n")
    db = workdir / "bridge.db"
    bridge = subprocess.Popen([sys.executable, "-m", "slr_sql", "ros", "bridge", str(db),
                               "--map", str(mapfile)], stdout=subprocess.PIPE, text=True, env=env,
                              cwd=REPO)
    try:
        for line in bridge.stdout:  # (it says first which request topics it serves)
            if "bridge ready" in line:
                break
        else:
            raise SystemExit("the bridge stopped before it was ready")
        publisher = subprocess.run([sys.executable, "-c", PUBLISHER, str(count), str(rate)],
                                   env=env, capture_output=True, text=True, timeout=600)
        assert publisher.returncode == 0, publisher.stderr
        deadline = time.monotonic() + 60
        stored, previous = 0, -1
        while stored < count and time.monotonic() < deadline:
            time.sleep(0.5)
            with slr_sql.open(db) as kb:
                stored = kb.query("aggregate_all(count, pose(_)^_, N)")[0]["N"]
            if stored == previous:  # nothing more is coming
                break
            previous = stored
        cpu = _cpu_seconds(bridge.pid)
        bridge.terminate()
        bridge.wait(timeout=30)
        with slr_sql.open(db) as kb:
            rows = kb.sql("SELECT arrival - t_end FROM pose")[1] if stored else []
        latencies = sorted(r[0] * 1000 for r in rows)
        if len(latencies) < 2:
            print("bridge: no events stored")
            return
        q = statistics.quantiles(latencies, n=100)
        print(f"\nbridge, {len(latencies):,} of {count:,} PoseStamped at {rate:g} Hz stored, "
              f"publish -> stored (ms): p50 {q[49]:.2f}  p90 {q[89]:.2f}  p99 {q[98]:.2f}  "
              f"max {latencies[-1]:.2f}; bridge CPU {cpu * 1e6 / max(stored, 1):.0f} µs/message "
              f"(start-up included)")
    finally:
        if bridge.poll() is None:
            bridge.kill()
        shutil.rmtree(workdir, ignore_errors=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=100_000, help="TFMessages in the bag")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--bridge", action="store_true", help="also measure the live bridge")
    parser.add_argument("--bridge-only", action="store_true")
    parser.add_argument("--count", type=int, default=10_000, help="bridge: messages")
    parser.add_argument("--rate", type=float, default=1000.0, help="bridge: messages per second")
    args = parser.parse_args()
    if not args.bridge_only:
        bench_import(args.n, args.repeat)
    if args.bridge or args.bridge_only:
        bench_bridge(args.count, args.rate)


if __name__ == "__main__":
    main()
