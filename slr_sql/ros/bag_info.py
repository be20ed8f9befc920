"""``slr ros info BAG``: what a recording holds, and a draft MAP for it.

:func:`bag_info` reads a bag once: per topic the message type, the number of messages and
the first and last record time (read from the record index, nothing decoded), and the
frames of ``/tf`` and ``/tf_static`` (those messages decoded: parent, child, how many
transforms). :func:`draft_map` writes a MAP (YAML, with comments) that maps every other
topic to an event named after it, with the message's leaf fields as arguments, for the user
to edit: it loads as it is (``slr ros import BAG DB --map draft.yaml``).

>>> info = bag_info("/no/such.bag")
Traceback (most recent call last):
...
slr_sql.ros.bag_import.BagError: cannot read /no/such.bag: no such file or directory
"""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from ..errors import SLRError
from ..terms import Atom, format_term
from .bag_import import bag_id, export_bag_id, open_bag, read_messages
from .mapping import TF_TOPICS, TF_TYPE, TIME_TYPES, normalize_topic, topic_event_name

__all__ = ["TopicInfo", "FrameEdge", "BagInfo", "bag_info", "draft_map"]

_BASE, _NAME, _ARRAY, _SEQUENCE = 1, 2, 3, 4
# leaf fields a draft lists at most per topic (the rest: edit the draft, or take $msg)
MAX_DRAFT_ARGS = 12


@dataclass
class TopicInfo:
    """One topic of a bag: record times are seconds (None when it has no messages)."""

    topic: str
    msgtype: str
    count: int
    first: float | None = None
    last: float | None = None
    undecodable: int = 0    # messages read for the frames that do not decode (/tf, export)
    read: int | None = None  # messages that could be read (the bag's count says how many
                             # there are; fewer read: the bag is damaged or cut short)


@dataclass
class FrameEdge:
    """A (parent, child) pair seen in /tf or /tf_static, how often, and its time span."""

    parent: str
    child: str
    topic: str
    count: int = 0
    first: float | None = None
    last: float | None = None


@dataclass
class BagInfo:
    """What :func:`bag_info` found; ``fields`` maps each message type to its fields (rosbags
    definitions, for :func:`draft_map`)."""

    path: str
    bag_id: str
    count: int
    start: float | None
    end: float | None
    topics: list[TopicInfo] = field(default_factory=list)
    frames: list[FrameEdge] = field(default_factory=list)
    fielddefs: dict = field(default_factory=dict, repr=False)
    export: bool = False    # an MCAP file of `slr export`: its channels are event types

    @property
    def duration(self) -> float:
        return 0.0 if self.start is None or self.end is None else self.end - self.start

    def as_json(self) -> str:
        """The summary as JSON (without the definitions)."""
        data = asdict(self)
        data.pop("fielddefs")
        data["duration"] = self.duration
        return json.dumps(data, indent=2)


def _frame_text(term: Any) -> str:
    """A frame of an exported ``tf`` event as text: an atom as it is, any other term as
    written (a string ``"map"``, a number ``1.0``).

    >>> from slr_sql.terms import Atom, String
    >>> _frame_text(Atom("map")), _frame_text(String("map")), _frame_text(1.0)
    ('map', '"map"', '1.0')
    """
    return str(term) if type(term) is Atom else format_term(term)


def _export_info(path: Path) -> BagInfo:
    """The summary of an MCAP file of ``slr export`` (its channels name their event types)."""
    from slr_sql.viz.channels import METADATA_ARITY, METADATA_EVENT
    from slr_sql.viz.channels import event_from_message
    from slr_sql.viz.mcap_export import export_messages, export_summary

    # (ExportCutShort when the file ends early); the id the import records
    exported_as = export_bag_id(export_summary(path))
    topics: dict[str, TopicInfo] = {}
    frames: dict[tuple, FrameEdge] = {}
    for schema, channel, message in export_messages(path):
        meta = channel.metadata
        # (a channel written elsewhere may lack its arity: the import refuses it, the
        # summary shows it)
        kind = (f"slr event {meta[METADATA_EVENT]}/{meta.get(METADATA_ARITY, '?')[:20]}"
                if METADATA_EVENT in meta else (schema.name if schema else ""))
        info = topics.setdefault(channel.topic, TopicInfo(channel.topic, kind, 0))
        t = message.log_time * 1e-9
        info.count += 1
        info.first = t if info.first is None else min(info.first, t)
        info.last = t if info.last is None else max(info.last, t)
        if meta.get(METADATA_EVENT) in ("tf", "tf_static") and meta.get(METADATA_ARITY) == "3":
            try:
                _, (parent_term, child_term, _), _, _ = event_from_message("tf", 3, message.data)
            except (ValueError, KeyError, TypeError, IndexError, RecursionError,
                    SLRError):   # not an slr event
                info.undecodable += 1
                continue
            # (as tf_lookup and the live view name frames: an atom as it is, a string or a
            # number as its term text, so "map" and map stay two frames)
            parent, child = _frame_text(parent_term), _frame_text(child_term)
            edge = frames.setdefault((channel.topic, parent, child),
                                     FrameEdge(parent, child, channel.topic))
            edge.count += 1
            edge.first = t if edge.first is None else min(edge.first, t)
            edge.last = t if edge.last is None else max(edge.last, t)
    firsts = [t.first for t in topics.values() if t.first is not None]
    lasts = [t.last for t in topics.values() if t.last is not None]
    return BagInfo(str(path), exported_as, sum(t.count for t in topics.values()),
                   min(firsts) if firsts else None, max(lasts) if lasts else None,
                   sorted(topics.values(), key=lambda i: i.topic),
                   sorted(frames.values(), key=lambda e: (e.topic, e.parent, e.child)),
                   {}, export=True)


def bag_info(path: str | Path) -> BagInfo:
    """Read the bag at ``path`` (any format ``slr ros import`` reads, an ``slr export`` MCAP
    file too) and summarize it.

    >>> import pathlib, struct, tempfile
    >>> from rosbags.rosbag1 import Writer
    >>> from slr_sql.ros.bag_import import ros1_typestore
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "rec.bag"; types = ros1_typestore()
    >>> with Writer(path) as writer:   # three map->base transforms and a status, ROS 1 serialized
    ...     tf = writer.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=types)
    ...     status = writer.add_connection("/robot/status", "std_msgs/msg/String", typestore=types)
    ...     for i in range(3):
    ...         writer.write(tf, (50 + i) * 10**9, struct.pack("<IIIII3sI4s7d", 1, i, 50 + i, 0,
    ...                      3, b"map", 4, b"base", 0.5 * i, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0))
    ...     writer.write(status, 51 * 10**9, struct.pack("<I2s", 2, b"ok"))

    >>> info = bag_info(path); info.count, info.start
    (4, 50.0)
    >>> [(t.topic, t.count, t.first, t.last) for t in info.topics]
    [('/robot/status', 1, 51.0, 51.0), ('/tf', 3, 50.0, 52.0)]
    >>> [(f.parent, f.child, f.count) for f in info.frames]
    [('map', 'base', 3)]
    """
    from slr_sql.viz.mcap_export import is_slr_export

    from . import fast_tf

    if is_slr_export(path):
        return _export_info(Path(path))
    reader = open_bag(path)
    try:
        topics: dict[str, TopicInfo] = {}
        tf_conns = []
        for conn in reader.connections:
            topic = normalize_topic(conn.topic)
            info = topics.setdefault(topic, TopicInfo(topic, conn.msgtype, 0))
            info.count += conn.msgcount
            if topic in TF_TOPICS and conn.msgtype == TF_TYPE:
                tf_conns.append(conn.id)
        deserialize = reader.typestore.deserialize_cdr if reader.is2 \
            else reader.typestore.deserialize_ros1
        decode = fast_tf.decode_cdr if reader.is2 else fast_tf.decode_ros1
        standard = fast_tf.standard_tf_types(reader.typestore.fielddefs, reader.is2)
        frames: dict[tuple, FrameEdge] = {}
        for info in topics.values():
            info.read = 0
        for conn, stamp, raw in _messages(reader, path):
            t = stamp * 1e-9
            info = topics[normalize_topic(conn.topic)]
            info.read = (info.read or 0) + 1
            if info.first is None or t < info.first:
                info.first = t
            if info.last is None or t > info.last:
                info.last = t
            if conn.id not in tf_conns:
                continue
            try:
                if standard:
                    transforms = [(args[0], args[1], end) for _, args, _, end in decode(raw, t)]
                else:
                    msg = deserialize(raw, conn.msgtype)
                    transforms = [(tr.header.frame_id, tr.child_frame_id,
                                   tr.header.stamp.sec + tr.header.stamp.nanosec * 1e-9)
                                  for tr in msg.transforms]
            except Exception:  # noqa: BLE001 - bytes that do not decode: counted, said once
                info.undecodable += 1
                continue
            for parent, child, at in transforms:
                edge = frames.setdefault((info.topic, parent, child),
                                         FrameEdge(str(parent), str(child), info.topic))
                edge.count += 1
                edge.first = at if edge.first is None else min(edge.first, at)
                edge.last = at if edge.last is None else max(edge.last, at)
        count = reader.message_count
        return BagInfo(str(path), bag_id(reader), count,
                       reader.start_time * 1e-9 if count else None,
                       reader.end_time * 1e-9 if count else None,
                       sorted(topics.values(), key=lambda i: i.topic),
                       sorted(frames.values(), key=lambda e: (e.topic, e.parent, e.child)),
                       dict(reader.typestore.fielddefs))
    finally:
        reader.close()


def _messages(reader: Any, path: str | Path) -> Any:
    """The bag's messages; :class:`BagError` when its storage does not read back."""
    return read_messages(reader.messages(), path)


def _leaves(fielddefs: dict, msgtype: str, prefix: str = "", depth: int = 0) -> list[str]:
    """Field paths of the numbers, strings and times of ``msgtype`` (lists whole), in
    declaration order; a header's stamp and seq are left out (the event time takes it)."""
    found = fielddefs.get(msgtype)
    if found is None or depth > 8:
        return [prefix.rstrip(".")] if prefix else []
    out: list[str] = []
    for name, (kind, detail) in found[1]:
        path = prefix + name
        if kind == _NAME:
            if detail in TIME_TYPES:
                if not (name == "stamp" and msgtype == "std_msgs/msg/Header"):
                    out.append(path)
                continue
            out += _leaves(fielddefs, detail, path + ".", depth + 1)
        elif kind == _BASE:
            if msgtype == "std_msgs/msg/Header" and name == "seq":
                continue
            out.append(path)
        else:   # arrays and sequences: the whole list (or foreach, by hand)
            out.append(path)
    return out


def _has_header(fielddefs: dict, msgtype: str) -> bool:
    found = fielddefs.get(msgtype)
    return found is not None and any(
        name == "header" and kind == _NAME and detail == "std_msgs/msg/Header"
        for name, (kind, detail) in found[1])


def _yaml_text(value: str) -> str:
    return json.dumps(value)  # a JSON string is a YAML string


def draft_map(info: BagInfo) -> str:
    """A MAP (YAML) for every topic of ``info`` except /tf and /tf_static (the built-in
    mapping takes them): an event named after the topic whose arguments are the message's
    leaf fields (at most :data:`MAX_DRAFT_ARGS`; a message with more, or with none, is taken
    whole as ``$msg``), timed by ``header.stamp`` when the message has one.

    >>> import pathlib, struct, tempfile
    >>> from rosbags.rosbag1 import Writer
    >>> from slr_sql.ros.bag_import import ros1_typestore
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "rec.bag"; types = ros1_typestore()
    >>> with Writer(path) as writer:   # three map->base transforms and a status, ROS 1 serialized
    ...     tf = writer.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=types)
    ...     status = writer.add_connection("/robot/status", "std_msgs/msg/String", typestore=types)
    ...     for i in range(3):
    ...         writer.write(tf, (50 + i) * 10**9, struct.pack("<IIIII3sI4s7d", 1, i, 50 + i, 0,
    ...                      3, b"map", 4, b"base", 0.5 * i, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0))
    ...     writer.write(status, 51 * 10**9, struct.pack("<I2s", 2, b"ok"))

    >>> print(draft_map(bag_info(path)))
    # Draft MAP for .../rec.bag (bag_197ecfcf09c51814), written by `slr ros info`.
    ...
    version: 1
    topics:
      "/robot/status":
        # 1 messages, 51.000 .. 51.000
        event: robot_status
        type: std_msgs/msg/String
        args:
          - "data"
        time: record
    <BLANKLINE>
    """
    if info.export:
        return (f"# {info.path} is an MCAP file of `slr export`: its channels name their event\n"
                f"# types, so `slr ros import` reads it without a MAP.\nversion: 1\ntopics: {{}}\n")
    lines = [f"# Draft MAP for {info.path} ({info.bag_id}), written by `slr ros info`.",
             "# Edit the event names and arguments, then: slr ros import BAG DB --map THIS_FILE",
             "# /tf and /tf_static need no entry: the built-in mapping makes",
             "#   tf(Parent, Child, pose([X,Y,Z],[QX,QY,QZ,QW]))^T and tf_static(...)^T",
             "version: 1"]
    entries = [t for t in info.topics if t.topic not in TF_TOPICS]
    if not entries:
        lines.append("topics: {}")
        return "\n".join(lines) + "\n"
    lines.append("topics:")
    used: dict[str, str] = {}
    for t in entries:
        name = topic_event_name(t.topic)
        if name in used:   # two topics with one name: number the second
            n = 2
            while f"{name}_{n}" in used:
                n += 1
            name = f"{name}_{n}"
        used[name] = t.topic
        leaves = _leaves(info.fielddefs, t.msgtype)
        lines.append(f"  {_yaml_text(t.topic)}:")
        lines.append(f"    # {t.count} messages" + (
            f", {t.first:.3f} .. {t.last:.3f}" if t.first is not None else ""))
        lines.append(f"    event: {name}")
        lines.append(f"    type: {t.msgtype}")
        if 0 < len(leaves) <= MAX_DRAFT_ARGS:
            lines.append("    args:")
            lines += [f"      - {_yaml_text(p)}" for p in leaves]
        else:
            lines.append(f"    # {len(leaves)} fields: the whole message as one argument")
            lines.append("    args: [\"$msg\"]")
        timing = "header.stamp" if _has_header(info.fielddefs, t.msgtype) else "record"
        lines.append(f"    time: {timing}")
    return "\n".join(lines) + "\n"
