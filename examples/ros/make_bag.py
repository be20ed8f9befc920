"""Write a small robot recording to try `slr ros import` on, without ROS.

    python examples/ros/make_bag.py demo_bag                 # rosbag2, MCAP storage
    python examples/ros/make_bag.py demo.bag --format ros1   # rosbag1
    python examples/ros/make_bag.py demo_bag --format sqlite3

The recording (12 s of a robot looking at a cup):

* /tf_static  base -> cam: the camera on the head, 1.2 m up (one message at t=0);
* /tf         map -> base at 10 Hz (the robot drives along x at 0.1 m/s), and cam -> base
              at t=10 and t=12, the head rising 0.2 m and turning 90 degrees about z
              (the interpolation example of the SLR paper, examples/tf_interpolation.slr);
* /detections geometry_msgs/PoseArray at 2 Hz: the cup seen by the camera, one pose each;
* /battery    std_msgs/Float64 at 1 Hz, no header: timed by when it was recorded.

`write_bag(path, fmt, items)` writes any list of (topic, type, record time in seconds,
message as nested dicts) with rosbags; the tests use it too.
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any, Iterable

EPOCH = 1_700_000_000  # recordings carry wall-clock stamps; the times below are offsets


def typestore(fmt: str) -> Any:
    """The rosbags type store for the format (ROS 1 Noetic needs tf2_msgs added)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    if fmt == "ros1":
        store = get_typestore(Stores.ROS1_NOETIC)
        store.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms\n",
                                          "tf2_msgs/msg/TFMessage"))
        return store
    return get_typestore(Stores.ROS2_KILTED)


def message(store: Any, msgtype: str, values: dict) -> Any:
    """A rosbags message of ``msgtype`` from nested dicts; missing fields are zero/empty."""
    import numpy

    cls = store.types[msgtype]
    kwargs = {}
    for name, (kind, detail) in store.fielddefs[msgtype][1]:
        given = values.get(name)
        if kind == 2:  # a nested message
            kwargs[name] = message(store, detail, given or {})
        elif kind == 1:  # a base type
            base = detail[0]
            default = "" if base == "string" else (False if base == "bool" else 0)
            kwargs[name] = given if given is not None else default
        else:  # arrays and sequences
            element = detail[0]
            items = given or []
            if element[0] == 2:
                kwargs[name] = [message(store, element[1], v) for v in items]
            elif element[1][0] == "string":
                kwargs[name] = list(items)
            else:
                dtype = {"float64": numpy.float64, "float32": numpy.float32}.get(element[1][0],
                                                                                 numpy.int64)
                if element[1][0] in ("uint8", "char", "byte"):
                    dtype = numpy.uint8
                kwargs[name] = numpy.array(items, dtype=dtype)
    return cls(**kwargs)


def stamp(t: float) -> dict:
    sec = math.floor(t)
    return {"sec": sec, "nanosec": int(round((t - sec) * 1e9))}


def header(fmt: str, t: float, frame: str) -> dict:
    h = {"stamp": stamp(t), "frame_id": frame}
    if fmt == "ros1":
        h["seq"] = 0
    return h


def transform(fmt: str, t: float, parent: str, child: str, xyz: Iterable[float],
              quaternion: Iterable[float]) -> dict:
    x, y, z = xyz
    qx, qy, qz, qw = quaternion
    return {"header": header(fmt, t, parent), "child_frame_id": child,
            "transform": {"translation": {"x": x, "y": y, "z": z},
                          "rotation": {"x": qx, "y": qy, "z": qz, "w": qw}}}


def write_bag(path: str | Path, fmt: str, items: list) -> Path:
    """Write ``items`` — (topic, msgtype, record time in s, values dict) — as a bag:
    ``fmt`` is ``mcap`` / ``sqlite3`` (rosbag2 directory), ``mcap-file`` (one .mcap file)
    or ``ros1`` (a .bag file)."""
    path = Path(path)
    store = typestore(fmt)
    if fmt == "ros1":
        from rosbags.rosbag1 import Writer as Writer1

        writer: Any = Writer1(path)
        serialize = store.serialize_ros1
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer

        target = path
        if fmt == "mcap-file":
            target = path.with_suffix("")
        writer = Writer(target, version=9, storage_plugin=StoragePlugin.SQLITE3 if fmt == "sqlite3"
                        else StoragePlugin.MCAP)
        serialize = store.serialize_cdr
    connections: dict = {}
    with writer:
        for topic, msgtype, t, values in sorted(items, key=lambda item: item[2]):
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, msgtype, typestore=store)
            raw = serialize(message(store, msgtype, values), msgtype)
            writer.write(connections[topic], int(round(t * 1e9)), raw)
    if fmt == "mcap-file":  # keep only the storage file: a plain MCAP file
        (mcap,) = target.glob("*.mcap")
        mcap.rename(path)
        for leftover in target.iterdir():
            leftover.unlink()
        target.rmdir()
    return path


def demo_items(fmt: str) -> list:
    """The recording described in the module docstring."""
    items: list = []
    tf_type = "tf2_msgs/msg/TFMessage"
    items.append(("/tf_static", tf_type, EPOCH + 0.0, {"transforms": [
        transform(fmt, EPOCH + 0.0, "base", "cam_mount", (0.0, 0.0, 1.0), (0.0, 0.0, 0.0, 1.0))]}))
    for i in range(121):
        t = EPOCH + i * 0.1
        items.append(("/tf", tf_type, t + 0.004, {"transforms": [
            transform(fmt, t, "map", "base", (0.01 * i, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))]}))
    s = math.sqrt(0.5)
    for t, z, q in ((10.0, 1.2, (0.0, 0.0, 0.0, 1.0)), (12.0, 1.4, (0.0, 0.0, s, s))):
        items.append(("/tf", tf_type, EPOCH + t + 0.002, {"transforms": [
            transform(fmt, EPOCH + t, "cam", "base", (0.1, 0.0, z), q)]}))
    for i in range(24):
        t = EPOCH + i * 0.5
        items.append(("/detections", "geometry_msgs/msg/PoseArray", t + 0.03, {
            "header": header(fmt, t, "cam"),
            "poses": [{"position": {"x": 0.4, "y": 0.1, "z": 0.9},
                       "orientation": {"w": 1.0}}]}))
    for i in range(12):
        items.append(("/battery", "std_msgs/msg/Float64", EPOCH + i + 0.5,
                      {"data": 24.0 - 0.05 * i}))
    return items


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("path", help="the bag to write (a directory for rosbag2)")
    parser.add_argument("--format", default="mcap", choices=["mcap", "sqlite3", "mcap-file", "ros1"])
    args = parser.parse_args()
    path = write_bag(args.path, args.format, demo_items(args.format))
    print(f"wrote {path} ({args.format})")


if __name__ == "__main__":
    main()
