"""A direct decoder for the built-in tf mapping: ``tf2_msgs/msg/TFMessage`` bytes -> tf events.

Transforms are the bulk of most recordings, and a general decoder builds a Python object for
every header, time, vector and quaternion only for the mapping to take them apart again.
This module reads the serialized bytes straight into ``tf(Parent, Child, pose([X,Y,Z],
[QX,QY,QZ,QW]))^T`` events. It is used only when the bag's own definitions of every type
involved are exactly the standard ones (checked field by field); any other bag, and any
mapping other than the built-in one, goes through ``rosbags``' decoder and the general
mapping code, which the tests check give the same events.

Both encodings are handled: CDR (ROS 2; either byte order; 4- and 8-byte alignment counted
from the end of the 4-byte encapsulation header) and the ROS 1 serialization (no alignment,
a ``seq`` field in the header, times as two unsigned 32-bit numbers).

>>> raw = bytes.fromhex("00010000" "01000000" "0500000000000000" "04000000") + b"map\\0" + (
...     bytes.fromhex("05000000") + b"base\\0" + bytes(3) + bytes(8 * 6) + bytes.fromhex("000000000000f03f"))
>>> decode_cdr(raw, 0.0)
[('tf', ('map', 'base', Struct('pose', ([0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]))), 5.0, 5.0)]
"""
from __future__ import annotations

from functools import partial
from struct import Struct as _Packing
from typing import Any, Callable

from slr_sql import Struct

__all__ = ["compile_for", "decode_cdr", "decode_ros1"]

_TF = "tf2_msgs/msg/TFMessage"

# The standard definitions, as rosbags lists them (node type 1: base type, 2: message name,
# 4: sequence), for the two serializations.
_COMMON = {
    "tf2_msgs/msg/TFMessage": [("transforms", (4, ((2, "geometry_msgs/msg/TransformStamped"), 0)))],
    "geometry_msgs/msg/TransformStamped": [
        ("header", (2, "std_msgs/msg/Header")), ("child_frame_id", (1, ("string", 0))),
        ("transform", (2, "geometry_msgs/msg/Transform"))],
    "geometry_msgs/msg/Transform": [("translation", (2, "geometry_msgs/msg/Vector3")),
                                    ("rotation", (2, "geometry_msgs/msg/Quaternion"))],
    "geometry_msgs/msg/Vector3": [(n, (1, ("float64", 0))) for n in "xyz"],
    "geometry_msgs/msg/Quaternion": [(n, (1, ("float64", 0))) for n in "xyzw"],
}
_ROS2 = {**_COMMON,
         "std_msgs/msg/Header": [("stamp", (2, "builtin_interfaces/msg/Time")),
                                 ("frame_id", (1, ("string", 0)))],
         "builtin_interfaces/msg/Time": [("sec", (1, ("int32", 0))),
                                         ("nanosec", (1, ("uint32", 0)))]}
_ROS1 = {**_COMMON,
         "std_msgs/msg/Header": [("seq", (1, ("uint32", 0))),
                                 ("stamp", (2, "builtin_interfaces/msg/Time")),
                                 ("frame_id", (1, ("string", 0)))]}

_U32 = {True: _Packing("<I"), False: _Packing(">I")}
_TIME_LEN = {True: _Packing("<iII"), False: _Packing(">iII")}
_LEN = {True: _Packing("<I"), False: _Packing(">I")}
_POSE = {True: _Packing("<7d"), False: _Packing(">7d")}
_ROS1_HEADER = _Packing("<IIII")  # seq, sec, nsec, frame_id length
_ROS1_LEN = _Packing("<I")
_ROS1_POSE = _Packing("<7d")


def _plain(node: Any) -> Any:
    """A definition node with rosbags' enums turned into plain ints/tuples for comparing."""
    if isinstance(node, tuple):
        return tuple(_plain(x) for x in node)
    if isinstance(node, list):
        return [_plain(x) for x in node]
    if hasattr(node, "value") and isinstance(getattr(node, "value"), int):
        return int(node.value)
    return node


def _matches(fielddefs: dict, expected: dict) -> bool:
    for name, fields in expected.items():
        found = fielddefs.get(name)
        if found is None or _plain(list(found[1])) != _plain(fields):
            return False
    if "builtin_interfaces/msg/Time" not in expected:  # ROS 1: time is two uint32 (any names)
        time = fielddefs.get("builtin_interfaces/msg/Time")
        if time is None or [n for n, _ in time[1]] != ["sec", "nanosec"]:
            return False
    return True


def standard_tf_types(fielddefs: dict, ros2: bool) -> bool:
    """True when a bag's (or a live graph's) message definitions ``fielddefs`` define the tf
    types the standard way (ROS 2's, or ROS 1's with ``ros2=False``), so that the direct
    decoders of this module read them exactly as the general deserializer would.

    >>> standard_tf_types({}, ros2=True)
    False
    """
    return _matches(fielddefs, _ROS2 if ros2 else _ROS1)


def compile_for(bound: Any, conn: Any, reader: Any) -> Callable[[Any, float], list] | None:
    """The direct decoder for ``conn`` when ``bound`` is the built-in tf mapping and the bag
    defines the tf types the standard way; else None (use the general path).

    >>> from types import SimpleNamespace
    >>> from slr_sql.ros.bag_import import ros1_typestore
    >>> from slr_sql.ros.mapping import TF_TYPE, mapping_from_dict, tf_entry
    >>> bag = SimpleNamespace(typestore=ros1_typestore(), is2=False)  # a ROS 1 bag's reader
    >>> builtin = tf_entry("/tf_static").bind(TF_TYPE, bag.typestore.fielddefs)
    >>> compile_for(builtin, SimpleNamespace(msgtype=TF_TYPE), bag).func is decode_ros1
    True
    >>> own = mapping_from_dict({"topics": {"/tf": {"event": "mytf", "args": ["$msg"]}}})
    >>> compile_for(own.entries_for("/tf")[0].bind(TF_TYPE, None), SimpleNamespace(msgtype=TF_TYPE), bag)
    """
    if not bound.entry.where.startswith("built-in") or conn.msgtype != _TF:
        return None
    fielddefs = reader.typestore.fielddefs
    decode = decode_cdr if reader.is2 else decode_ros1
    if not standard_tf_types(fielddefs, reader.is2):
        return None
    event = bound.entry.event
    return decode if event == "tf" else partial(decode, event=event)


def decode_cdr(raw: Any, record: float, event: str = "tf") -> list:
    """The tf events of one CDR-serialized TFMessage (``record`` is unused: tf events take
    the header stamp of each transform); ``event`` names them (``tf_static`` for
    /tf_static).

    >>> import struct
    >>> raw = struct.pack("<4sIiII4sI5s3x7d", bytes.fromhex("00010000"), 1, 12, 500000000,
    ...                   4, b"map", 5, b"base", 1.0, 2.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    >>> decode_cdr(raw, 0.0, event="tf_static")
    [('tf_static', ('map', 'base', Struct('pose', ([1.0, 2.0, 0.0], [0.0, 0.0, 0.0, 1.0]))), 12.5, 12.5)]
    """
    little = raw[1] == 1
    u32, time_len, length, pose = _U32[little], _TIME_LEN[little], _LEN[little], _POSE[little]
    (count,) = u32.unpack_from(raw, 4)
    pos = 8
    out = []
    append = out.append
    for _ in range(count):
        pos += (-pos) & 3
        sec, nanosec, n = time_len.unpack_from(raw, pos)
        pos += 12
        parent = str(raw[pos:pos + n - 1], "utf-8")
        pos += n
        pos += (-pos) & 3
        (n,) = length.unpack_from(raw, pos)
        pos += 4
        child = str(raw[pos:pos + n - 1], "utf-8")
        pos += n
        pos += (4 - pos) & 7  # 8-byte alignment counted from offset 4
        tx, ty, tz, qx, qy, qz, qw = pose.unpack_from(raw, pos)
        pos += 56
        t = sec + nanosec * 1e-9
        append((event, (parent, child, Struct("pose", ([tx, ty, tz], [qx, qy, qz, qw]))), t, t))
    return out


def decode_ros1(raw: Any, record: float, event: str = "tf") -> list:
    """The tf events of one ROS 1-serialized TFMessage.

    >>> import struct
    >>> raw = struct.pack("<IIIII3sI4s7d", 1, 0, 12, 500000000, 3, b"map", 4, b"base",
    ...                   1.0, 2.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    >>> decode_ros1(raw, 0.0)
    [('tf', ('map', 'base', Struct('pose', ([1.0, 2.0, 0.0], [0.0, 0.0, 0.0, 1.0]))), 12.5, 12.5)]
    """
    (count,) = _ROS1_LEN.unpack_from(raw, 0)
    pos = 4
    out = []
    append = out.append
    for _ in range(count):
        _seq, sec, nanosec, n = _ROS1_HEADER.unpack_from(raw, pos)
        pos += 16
        parent = str(raw[pos:pos + n], "utf-8")
        pos += n
        (n,) = _ROS1_LEN.unpack_from(raw, pos)
        pos += 4
        child = str(raw[pos:pos + n], "utf-8")
        pos += n
        tx, ty, tz, qx, qy, qz, qw = _ROS1_POSE.unpack_from(raw, pos)
        pos += 56
        t = sec + nanosec * 1e-9
        append((event, (parent, child, Struct("pose", ([tx, ty, tz], [qx, qy, qz, qw]))), t, t))
    return out
