"""MAP files: which ROS topics become which events (docs/ros.md, "Mapping reference").

A mapping is read from YAML (``load_mapping("robot.yaml")``) or from the ROS 1 bridge
configuration of the SLR paper's implementation (``pub_sub.xml``, ``subscribe_to`` /
``publish_to`` elements). It is checked in full when it is read: every error is a
:class:`MappingError` that names the offending key (``topics./odom.args[1]: ...``). Field
paths are checked again against the message definitions once the message type of a topic is
known (from the bag or from the ROS graph), so a misspelt field is reported before anything
is imported, with the fields that do exist.

This module knows nothing of ROS itself: messages are any objects with attributes (the
``rosbags`` dataclasses), and message definitions are ``rosbags``-style field lists.

>>> m = mapping_from_dict({"topics": {"/odom": {"event": "odom",
...     "args": ["child_frame_id", ["pose.pose.position.x", "pose.pose.position.y"]]}}})
>>> [(e.topic, e.event) for e in m.entries_for("/odom")]
[('/odom', 'odom')]
"""
from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass, field
from operator import attrgetter
from pathlib import Path
from typing import Any, Callable, Iterable

from slr_sql import Atom, SLRError, String, Struct

__all__ = [
    "MappingError", "MessageError", "Mapping", "TopicEntry", "PublishEntry", "FullyUpdatedEntry",
    "BoundEntry", "load_mapping", "mapping_from_dict", "mapping_from_pub_sub_xml",
    "topic_event_name", "normalize_topic", "normalize_type", "message_term", "TF_TOPICS",
    "IMPORT_CHECKPOINT", "RequestTopics",
]

TF_TOPICS = ("/tf", "/tf_static")
TF_TYPE = "tf2_msgs/msg/TFMessage"
# The reserved event type that records how far an import got (docs/ros.md, "Resuming").
IMPORT_CHECKPOINT = "slr_import"

TIME_TYPES = ("builtin_interfaces/msg/Time", "builtin_interfaces/msg/Duration")
HEADER_TYPE = "std_msgs/msg/Header"
# Time sources that are not fields: when the message was recorded (bags) or received (bridge).
ARRIVAL_TIME_SOURCES = ("record", "receive")

# rosbags' node types in message definitions (rosbags.typesys.base.Nodetype).
_BASE, _NAME, _ARRAY, _SEQUENCE = 1, 2, 3, 4
_NUMERIC_BASES = frozenset({"bool", "byte", "char", "int8", "int16", "int32", "int64", "uint8",
                            "uint16", "uint32", "uint64", "float32", "float64"})

_TOP_KEYS = ("version", "tf", "topics", "publish", "fully_updated", "definitions", "requests")
_REQUEST_KEYS = ("enabled", "query", "answer", "control", "control_reply", "max_query_time",
                 "max_wait")
_TOPIC_KEYS = ("event", "args", "time", "foreach", "type")
_PUBLISH_KEYS = ("topic", "type", "event", "where", "fields")
_FULLY_UPDATED_KEYS = ("topic", "types", "time", "type")
_SEGMENT = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*)((?:\[-?\d+\])*)$")
_INDEX = re.compile(r"\[(-?\d+)\]")
_EVENT_NAME = re.compile(r"^[a-z][A-Za-z0-9_]*$")
_TYPE_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*/(?:msg/)?[A-Za-z][A-Za-z0-9_]*$")
_VARIABLE = re.compile(r"^[A-Z_][A-Za-z0-9_]*$")
_INDICATOR = re.compile(r"^([a-z][A-Za-z0-9_]*)(?:/(\d+))?$")


class MappingError(SLRError):
    """A MAP file (or dict) that does not describe a mapping; the message names the key."""


class MessageError(SLRError):
    """One message that its mapping cannot turn into events (an index out of range, a time
    that is not a number, ...). Import reports it and goes on with the next message."""


# ---------------------------------------------------------------------------------------------
# names
# ---------------------------------------------------------------------------------------------

def normalize_topic(topic: str) -> str:
    """Topic names are absolute: ``odom`` and ``/odom`` are the same topic.

    >>> normalize_topic("odom"), normalize_topic("/robot/odom")
    ('/odom', '/robot/odom')
    """
    return topic if topic.startswith("/") else "/" + topic


def normalize_type(msgtype: str) -> str:
    """``pkg/Name`` (ROS 1 style) and ``pkg/msg/Name`` name the same message type.

    >>> normalize_type("geometry_msgs/PoseStamped")
    'geometry_msgs/msg/PoseStamped'
    """
    parts = msgtype.split("/")
    return f"{parts[0]}/msg/{parts[1]}" if len(parts) == 2 else msgtype


def topic_event_name(topic: str) -> str:
    """The event name of an unmapped topic (``--all``, ``pub_sub.xml``): the topic without its
    leading ``/``, every other character that may not appear in an unquoted atom (``/``, ``~``,
    ``-``, ...) replaced by ``_``; a name that would not start with a lower-case letter gets
    the prefix ``topic_``.

    >>> topic_event_name("/robot/odom"), topic_event_name("/Camera/image_raw")
    ('robot_odom', 'topic_Camera_image_raw')
    """
    name = re.sub(r"[^A-Za-z0-9_]", "_", topic.lstrip("/"))
    return name if _EVENT_NAME.match(name) else "topic_" + name


# ---------------------------------------------------------------------------------------------
# message values -> terms
# ---------------------------------------------------------------------------------------------

_FIELD_NAMES: dict[type, tuple[str, ...]] = {}


def _fields_of(cls: type) -> tuple[str, ...]:
    names = _FIELD_NAMES.get(cls)
    if names is None:
        names = tuple(n for n in getattr(cls, "__dataclass_fields__", ()) if n != "__msgtype__")
        _FIELD_NAMES[cls] = names
    return names


def message_term(value: Any) -> Any:
    """A message value as a term (the encoding of ``--all``, ``$msg``/``$item`` templates
    and ``pub_sub.xml`` events): a message is the compound named by its full type whose
    arguments are its fields as ``Name: Value`` pairs, in declaration order (stored as a
    JSON object of fields, see :mod:`slr_sql.encoding`; read in SLR with ``get_field/3`` or
    by unification); a message without fields is the atom of its type;
    ``builtin_interfaces`` Time and Duration are float seconds; strings are atoms; ``bool``
    is ``true``/``false``; arrays and sequences are lists.

    >>> from dataclasses import dataclass
    >>> @dataclass
    ... class Point:
    ...     x: float; y: float; z: float
    ...     __msgtype__ = "geometry_msgs/msg/Point"
    >>> str(message_term(Point(1.0, 2.0, 0.5)))
    "'geometry_msgs/msg/Point'(x:1.0,y:2.0,z:0.5)"
    """
    kind = type(value)
    if kind is float or kind is int or kind is str:
        return value
    if kind is bool:
        return "true" if value else "false"
    msgtype = getattr(kind, "__msgtype__", None)
    if msgtype is not None:
        if msgtype in TIME_TYPES:
            return value.sec + value.nanosec * 1e-9
        names = _fields_of(kind)
        if not names:
            return Atom(msgtype)
        return Struct(msgtype, [Struct(":", (Atom(n), message_term(getattr(value, n))))
                                for n in names])
    tolist = getattr(value, "tolist", None)
    if tolist is not None:  # numpy arrays and scalars (rosbags decodes numeric arrays so)
        items = tolist()
        return [message_term(x) for x in items] if type(items) is list else message_term(items)
    if kind is list or kind is tuple:
        return [message_term(x) for x in value]
    if kind is bytes or kind is bytearray:
        return list(value)
    if isinstance(value, str):
        return str(value)
    if isinstance(value, (int, float)):
        return value
    raise MessageError(f"no term for the {kind.__name__} value {value!r}")


def _to_seconds(value: Any) -> float:
    if getattr(type(value), "__msgtype__", None) in TIME_TYPES:
        return value.sec + value.nanosec * 1e-9
    if type(value) in (int, float) or hasattr(value, "__float__"):
        return float(value)
    raise MessageError(f"a time must be a builtin_interfaces Time or a number, not {value!r}")


# ---------------------------------------------------------------------------------------------
# templates (argument descriptions)
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class FieldPath:
    """A field path: ``root`` is ``"item"`` (the message, or the foreach element) or
    ``"msg"`` (the whole message, written ``$msg.``); steps are names and list indexes."""

    root: str
    steps: tuple  # of str (field names) and int (indexes)
    text: str


def _parse_path(text: str, where: str) -> FieldPath:
    root = "item"
    body = text
    if text == "$msg" or text.startswith("$msg."):
        root, body = "msg", text[len("$msg."):] if text != "$msg" else ""
    elif text == "$item" or text.startswith("$item."):
        body = text[len("$item."):] if text != "$item" else ""
    elif text.startswith("$"):
        raise MappingError(f"{where}: unknown name {text.split('.')[0]!r} (a field path, $msg or "
                           f"$item)")
    steps: list = []
    if body:
        for segment in body.split("."):
            m = _SEGMENT.match(segment)
            if not m:
                raise MappingError(f"{where}: {text!r} is not a field path (names separated by "
                                   f"'.', optionally indexed like data[0])")
            steps.append(m.group(1))
            steps.extend(int(i) for i in _INDEX.findall(m.group(2)))
    return FieldPath(root, tuple(steps), text)


@dataclass(frozen=True)
class Template:
    """One argument description. ``kind``: ``path`` (a field's value as a term), ``const``
    (a constant), ``list`` (a list of templates), ``struct`` (``name(templates...)``),
    ``string`` (a field as an SLR string)."""

    kind: str
    value: Any
    where: str
    args: tuple = ()


def _parse_template(spec: Any, where: str) -> Template:
    if isinstance(spec, bool):
        return Template("const", "true" if spec else "false", where)
    if isinstance(spec, (int, float)):
        if isinstance(spec, float) and not math.isfinite(spec):
            raise MappingError(f"{where}: {spec!r} cannot be stored")
        return Template("const", spec, where)
    if isinstance(spec, str):
        return Template("path", _parse_path(spec.strip(), where), where)
    if isinstance(spec, list):
        return Template("list", None, where,
                        tuple(_parse_template(s, f"{where}[{i}]") for i, s in enumerate(spec)))
    if isinstance(spec, dict):
        if len(spec) != 1:
            raise MappingError(f"{where}: a compound template has exactly one key (its name), "
                               f"not {sorted(map(str, spec))}")
        (key, value), = spec.items()
        key = str(key)
        if key == "$const":
            if isinstance(value, str):
                return Template("const", value, where)
            return _constant(value, f"{where}.$const")
        if key == "$string":
            if not isinstance(value, str):
                raise MappingError(f"{where}.$string: expects a field path")
            return Template("string", _parse_path(value, f"{where}.$string"), where)
        if key.startswith("$"):
            raise MappingError(f"{where}: unknown template key {key!r} (use $const, $string or a "
                               f"compound name)")
        if not re.match(r"^[a-z][A-Za-z0-9_]*$", key):
            raise MappingError(f"{where}: {key!r} is not a compound name (an atom starting with "
                               f"a lower-case letter)")
        if not isinstance(value, list):
            raise MappingError(f"{where}.{key}: the arguments of a compound are a list")
        return Template("struct", key, where,
                        tuple(_parse_template(s, f"{where}.{key}[{i}]") for i, s in enumerate(value)))
    raise MappingError(f"{where}: {spec!r} is not a template (a field path, a number, a list or "
                       f"a compound)")


def _constant(value: Any, where: str) -> Template:
    if isinstance(value, list):
        return Template("list", None, where,
                        tuple(_constant(v, f"{where}[{i}]") for i, v in enumerate(value)))
    if isinstance(value, str):
        return Template("const", value, where)
    return _parse_template(value, where)


def _template_paths(t: Template) -> Iterable[tuple[FieldPath, str]]:
    if t.kind in ("path", "string"):
        yield t.value, t.where
    for a in t.args:
        yield from _template_paths(a)


# ---------------------------------------------------------------------------------------------
# entries
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class TopicEntry:
    """One topic -> event mapping. ``time``: ``None`` (header.stamp when the message or the
    foreach element has a header, else the record/receive time), ``record``/``receive``, or a
    field path."""

    topic: str
    event: str
    args: tuple[Template, ...]
    time: FieldPath | str | None
    foreach: FieldPath | None
    msgtype: str | None
    where: str
    whole_message: bool = False  # args are [$msg]: the --all / pub_sub.xml encoding

    def bind(self, msgtype: str, fielddefs: dict | None) -> "BoundEntry":
        """Check the entry against the message definitions and compile it for ``msgtype``."""
        return BoundEntry(self, normalize_type(msgtype), fielddefs)


@dataclass(frozen=True)
class PublishEntry:
    """Complex events or subscription answers to a ROS topic: answers of the subscription
    ``event`` (``where`` its condition) become messages of ``msgtype`` on ``topic``; ``fields``
    maps message field paths to answer variables (a str) or constants; without ``fields`` the
    answer's only variable holds the whole message as a term (the ``--all`` encoding)."""

    topic: str
    msgtype: str
    event: str
    where_goal: str | None
    fields: tuple[tuple[str, Any], ...] | None
    where: str


@dataclass(frozen=True)
class FullyUpdatedEntry:
    """Each message on ``topic`` marks the histories of ``types`` complete up to its time."""

    topic: str
    types: tuple[str, ...]
    time: FieldPath | str | None
    msgtype: str | None
    where: str

    def as_topic_entry(self) -> TopicEntry:
        """A topic entry with one event per message, at the mark's time: binding it checks
        the time source against the message type, and its events give the times."""
        return TopicEntry(self.topic, "fullyUpdated", (Template("const", None, self.where),),
                          self.time, None, self.msgtype, self.where)


@dataclass(frozen=True)
class RequestTopics:
    """The topics of the bridge's request protocol (docs/ros.md, "Requests"): queries
    arrive on ``query`` and are answered on ``answer``; control requests arrive on
    ``control`` and are acknowledged on ``control_reply``. ``enabled=False`` (``requests:
    false`` in a MAP) turns the protocol off. Query times are capped by ``max_query_time``,
    synchronized waits by ``max_wait`` (seconds), as ``slr serve`` caps them."""

    enabled: bool = True
    query: str = "/slr/query"
    answer: str = "/slr/answer"
    control: str = "/slr/control"
    control_reply: str = "/slr/control_reply"
    max_query_time: float = 30.0
    max_wait: float = 3600.0

    def topics(self) -> tuple[str, str, str, str]:
        """The four topic names."""
        return (self.query, self.answer, self.control, self.control_reply)


@dataclass
class Mapping:
    """A whole MAP: topic entries (several per topic allowed), publish and fully_updated
    entries, and whether the built-in /tf and /tf_static mapping is on."""

    topics: dict[str, list[TopicEntry]] = field(default_factory=dict)
    publish: list[PublishEntry] = field(default_factory=list)
    fully_updated: list[FullyUpdatedEntry] = field(default_factory=list)
    tf: bool = True
    definitions: dict[str, str] = field(default_factory=dict)
    source: str = "<mapping>"
    requests: RequestTopics = field(default_factory=RequestTopics)

    def entries_for(self, topic: str, all_topics: bool = False) -> list[TopicEntry]:
        """The entries that turn ``topic`` into events: the MAP's own, else the built-in tf
        mapping for /tf and /tf_static, else (``all_topics``) the whole message as one event
        named after the topic.

        >>> [e.event for e in Mapping().entries_for("/tf")], Mapping().entries_for("/odom")
        (['tf'], [])
        """
        topic = normalize_topic(topic)
        if topic in self.topics:
            return self.topics[topic]
        if self.tf and topic in TF_TOPICS:
            return [tf_entry(topic)]
        if all_topics:
            return [whole_message_entry(topic, "--all")]
        return []

    def fully_updated_for(self, topic: str) -> list[FullyUpdatedEntry]:
        topic = normalize_topic(topic)
        return [e for e in self.fully_updated if e.topic == topic]

    def topic_names(self) -> list[str]:
        """Every topic the mapping reads (events and fully_updated marks)."""
        names = list(self.topics)
        names += [e.topic for e in self.fully_updated if e.topic not in names]
        return names


def tf_entry(topic: str) -> TopicEntry:
    """The built-in mapping of /tf and /tf_static, as if written in a MAP:
    ``tf(Parent, Child, pose([X,Y,Z],[QX,QY,QZ,QW]))^T``, one event per transform, T its
    header stamp; /tf_static gives ``tf_static(..)^T`` events, which ``tf_lookup`` takes as
    valid for all time.

    >>> tf_entry("/tf_static").event
    'tf_static'
    """
    spec = {"event": "tf_static" if topic == "/tf_static" else "tf", "foreach": "transforms", "type": TF_TYPE, "args": [
        "header.frame_id", "child_frame_id",
        {"pose": [["transform.translation.x", "transform.translation.y",
                   "transform.translation.z"],
                  ["transform.rotation.x", "transform.rotation.y", "transform.rotation.z",
                   "transform.rotation.w"]]}]}
    return topic_entry(topic, spec, f"built-in {topic}")


def whole_message_entry(topic: str, why: str) -> TopicEntry:
    """``topic_event_name(topic)(Message)^T`` with the message as a term (``--all``).

    >>> entry = whole_message_entry("/robot/status", "--all")
    >>> entry.event, [a.value.text for a in entry.args], entry.whole_message, entry.where
    ('robot_status', ['$msg'], True, '--all /robot/status')
    """
    entry = topic_entry(topic, {"event": topic_event_name(topic), "args": ["$msg"]},
                         f"{why} {topic}")
    return TopicEntry(**{**entry.__dict__, "whole_message": True})


def topic_entry(topic: str, spec: Any, where: str) -> TopicEntry:
    """The checked entry of one subscribed topic from its mapping ``spec`` (``where`` names
    the place in messages); a :class:`MappingError` says what is wrong.

    >>> topic_entry("/odom", {"event": "odom", "args": ["$msg"]}, "mapping").event
    'odom'
    """
    if not isinstance(spec, dict):
        raise MappingError(f"{where}: a topic entry is a mapping with the keys "
                           f"{', '.join(_TOPIC_KEYS)}")
    _check_keys(spec, _TOPIC_KEYS, where)
    event = spec.get("event", topic_event_name(topic))
    if not isinstance(event, str) or not _EVENT_NAME.match(event):
        raise MappingError(f"{where}.event: {event!r} is not an event name (an atom starting "
                           f"with a lower-case letter)")
    if event == IMPORT_CHECKPOINT:
        raise MappingError(f"{where}.event: {IMPORT_CHECKPOINT} is reserved for import "
                           f"checkpoints")
    foreach = spec.get("foreach")
    if foreach is not None:
        if not isinstance(foreach, str):
            raise MappingError(f"{where}.foreach: expects the path of a list field")
        foreach = _parse_path(foreach, f"{where}.foreach")
        if foreach.root == "item" and not foreach.steps:
            raise MappingError(f"{where}.foreach: expects the path of a list field")
        foreach = FieldPath("msg", foreach.steps, foreach.text)  # foreach is always over the message
    args_spec = spec.get("args", ["$item" if foreach is not None else "$msg"])
    if not isinstance(args_spec, list):
        raise MappingError(f"{where}.args: expects a list of argument templates")
    args = tuple(_parse_template(a, f"{where}.args[{i}]") for i, a in enumerate(args_spec))
    msgtype = spec.get("type")
    if msgtype is not None:
        if not isinstance(msgtype, str) or not _TYPE_NAME.match(msgtype):
            raise MappingError(f"{where}.type: {msgtype!r} is not a message type (pkg/msg/Name)")
        msgtype = normalize_type(msgtype)
    return TopicEntry(topic, event, args, _time_source(spec.get("time"), f"{where}.time"),
                      foreach, msgtype, where)


def _time_source(spec: Any, where: str) -> FieldPath | str | None:
    if spec is None:
        return None
    if not isinstance(spec, str):
        raise MappingError(f"{where}: expects header.stamp, record, receive or a field path")
    if spec in ARRIVAL_TIME_SOURCES:
        return "record"
    return _parse_path(spec, where)


def _check_keys(spec: dict, allowed: tuple, where: str) -> None:
    for key in spec:
        if key not in allowed:
            name = f"{where}.{key}" if where else str(key)
            raise MappingError(f"{name}: unknown key (expected one of {', '.join(allowed)})")


def mapping_from_dict(data: Any, source: str = "<mapping>") -> Mapping:
    """Check and build a mapping from the parsed YAML document.

    >>> mapping_from_dict({"topics": {"/odom": {"evnt": "odom"}}})
    Traceback (most recent call last):
    ...
    slr_sql.ros.mapping.MappingError: topics./odom.evnt: unknown key (expected one of event, args, time, foreach, type)
    """
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise MappingError(f"{source}: a MAP is a YAML mapping with the keys "
                           f"{', '.join(_TOP_KEYS)}")
    _check_keys(data, _TOP_KEYS, "")
    version = data.get("version", 1)
    if version != 1:
        raise MappingError(f"version: {version!r} is not a supported MAP version (1)")
    tf = data.get("tf", True)
    if not isinstance(tf, bool):
        raise MappingError("tf: expects true or false")
    mapping = Mapping(tf=tf, source=source)
    topics = data.get("topics") or {}
    if not isinstance(topics, dict):
        raise MappingError("topics: expects a mapping from topic names to entries")
    for topic, spec in topics.items():
        if not isinstance(topic, str) or not topic.strip("/"):
            raise MappingError(f"topics: {topic!r} is not a topic name")
        name = normalize_topic(topic)
        specs = spec if isinstance(spec, list) else [spec]
        where = f"topics.{topic}"
        mapping.topics[name] = [
            topic_entry(name, s, where if len(specs) == 1 and not isinstance(spec, list)
                         else f"{where}[{i}]")
            for i, s in enumerate(specs)]
    publish = data.get("publish") or []
    if not isinstance(publish, list):
        raise MappingError("publish: expects a list of publish entries")
    mapping.publish = [publish_entry(p, f"publish[{i}]") for i, p in enumerate(publish)]
    fully = data.get("fully_updated") or []
    if not isinstance(fully, list):
        raise MappingError("fully_updated: expects a list of entries")
    mapping.fully_updated = [_fully_updated_entry(f, f"fully_updated[{i}]")
                             for i, f in enumerate(fully)]
    definitions = data.get("definitions") or {}
    if not isinstance(definitions, dict) or not all(
            isinstance(k, str) and isinstance(v, str) for k, v in definitions.items()):
        raise MappingError("definitions: expects a mapping from message types to .msg text")
    for name in definitions:
        if not _TYPE_NAME.match(name):
            raise MappingError(f"definitions.{name}: not a message type (pkg/msg/Name)")
    mapping.definitions = {normalize_type(k): v for k, v in definitions.items()}
    mapping.requests = _request_topics(data.get("requests", True))
    if mapping.requests.enabled:
        used = {**{t: f"topics.{t}" for t in mapping.topics},
                **{e.topic: e.where for e in mapping.publish + mapping.fully_updated}}
        for topic in mapping.requests.topics():
            if topic in used:
                raise MappingError(f"{used[topic]}: {topic} is a topic of the request protocol "
                                   f"(requests:); choose other names there or here")
    return mapping


def _request_topics(spec: Any) -> RequestTopics:
    """The ``requests:`` section: ``true``/``false``, or a mapping of the RequestTopics
    fields; topics must be distinct."""
    if isinstance(spec, bool):
        return RequestTopics(enabled=spec)
    if not isinstance(spec, dict):
        raise MappingError(f"requests: expects true, false or a mapping with the keys "
                           f"{', '.join(_REQUEST_KEYS)}")
    _check_keys(spec, _REQUEST_KEYS, "requests")
    values: dict[str, Any] = {}
    if "enabled" in spec:
        if not isinstance(spec["enabled"], bool):
            raise MappingError("requests.enabled: expects true or false")
        values["enabled"] = spec["enabled"]
    for key in ("query", "answer", "control", "control_reply"):
        if key in spec:
            topic = spec[key]
            if not isinstance(topic, str) or not topic.strip("/") or any(c.isspace() for c in topic):
                raise MappingError(f"requests.{key}: {topic!r} is not a topic name")
            values[key] = normalize_topic(topic)
    for key in ("max_query_time", "max_wait"):
        if key in spec:
            number = spec[key]
            try:
                seconds = float(number) if type(number) in (int, float) else math.nan
            except OverflowError:      # an integer beyond any float
                seconds = math.inf
            if not 0 < seconds < math.inf:
                raise MappingError(f"requests.{key}: expects a positive number of seconds")
            values[key] = seconds
    topics = RequestTopics(**values)
    names = topics.topics()
    if len(set(names)) != len(names):
        raise MappingError(f"requests: the four topics must differ ({', '.join(names)})")
    return topics


def publish_entry(spec: Any, where: str) -> PublishEntry:
    """The checked entry of one published topic (``topic``, ``type``, ``event``, ...) from
    its mapping ``spec``; a :class:`MappingError` says what is wrong.

    >>> publish_entry({"topic": "/alarm", "type": "std_msgs/msg/String",
    ...                "event": "alarm"}, "publish").topic
    '/alarm'
    """
    if not isinstance(spec, dict):
        raise MappingError(f"{where}: a publish entry is a mapping with the keys "
                           f"{', '.join(_PUBLISH_KEYS)}")
    _check_keys(spec, _PUBLISH_KEYS, where)
    for key in ("topic", "type", "event"):
        if not isinstance(spec.get(key), str) or not spec[key].strip():
            raise MappingError(f"{where}.{key}: required (a non-empty string)")
    if not _TYPE_NAME.match(spec["type"]):
        raise MappingError(f"{where}.type: {spec['type']!r} is not a message type (pkg/msg/Name)")
    where_goal = spec.get("where")
    if where_goal is not None and not isinstance(where_goal, str):
        raise MappingError(f"{where}.where: expects a goal (text)")
    fields = spec.get("fields")
    if fields is not None:
        if not isinstance(fields, dict) or not fields:
            raise MappingError(f"{where}.fields: expects a mapping from message field paths to "
                               f"answer variables or constants")
        checked = []
        for path, value in fields.items():
            _parse_path(str(path), f"{where}.fields.{path}")
            if isinstance(value, dict):
                if set(value) != {"$const"}:
                    raise MappingError(f"{where}.fields.{path}: a constant is written "
                                       f"{{$const: value}}")
                checked.append((str(path), ("const", value["$const"])))
            elif isinstance(value, str):
                if not _VARIABLE.match(value):
                    raise MappingError(f"{where}.fields.{path}: {value!r} is not a variable of "
                                       f"the answer (write {{$const: {value}}} for a constant)")
                checked.append((str(path), ("var", value)))
            else:
                checked.append((str(path), ("const", value)))
        fields = tuple(checked)
    return PublishEntry(normalize_topic(spec["topic"]), normalize_type(spec["type"]),
                        spec["event"].strip(), where_goal, fields, where)


def _fully_updated_entry(spec: Any, where: str) -> FullyUpdatedEntry:
    if not isinstance(spec, dict):
        raise MappingError(f"{where}: a fully_updated entry is a mapping with the keys "
                           f"{', '.join(_FULLY_UPDATED_KEYS)}")
    _check_keys(spec, _FULLY_UPDATED_KEYS, where)
    topic = spec.get("topic")
    if not isinstance(topic, str) or not topic.strip("/"):
        raise MappingError(f"{where}.topic: required (a topic name)")
    types = spec.get("types")
    types = [types] if isinstance(types, str) else types
    if not isinstance(types, list) or not types:
        raise MappingError(f"{where}.types: required (event types such as seg/2)")
    for i, t in enumerate(types):
        if not isinstance(t, str) or not _INDICATOR.match(t):
            raise MappingError(f"{where}.types[{i}]: {t!r} is not an event type (name/arity or "
                               f"name)")
    msgtype = spec.get("type")
    if msgtype is not None and (not isinstance(msgtype, str) or not _TYPE_NAME.match(msgtype)):
        raise MappingError(f"{where}.type: {msgtype!r} is not a message type (pkg/msg/Name)")
    return FullyUpdatedEntry(normalize_topic(topic), tuple(types),
                             _time_source(spec.get("time"), f"{where}.time"),
                             normalize_type(msgtype) if msgtype else None, where)


def mapping_from_pub_sub_xml(text: str, source: str = "pub_sub.xml") -> Mapping:
    """The ROS 1 bridge configuration of the SLR paper's implementation as a mapping:
    ``<subscribe_to name= msg_type=/>`` is a topic whose whole message becomes an event named
    after the topic (the built-in tf mapping for tf and tf_static); ``<publish_to name=
    msg_type=/>`` publishes the events named after that topic, whose one argument is the
    message as a term.

    >>> m = mapping_from_pub_sub_xml('<publish_subscribe><subscribe_to name="odom" '
    ...     'msg_type="nav_msgs/Odometry"/><publish_to name="marker1" '
    ...     'msg_type="geometry_msgs/PoseStamped"/></publish_subscribe>')
    >>> [e.event for e in m.entries_for("/odom")], m.publish[0].event
    (['odom'], 'marker1(Msg)^T')
    """
    try:
        root = ElementTree.fromstring(text)
    except ElementTree.ParseError as exc:
        raise MappingError(f"{source}: not well-formed XML: {exc}") from None
    mapping = Mapping(source=source)
    for i, element in enumerate(root.iter()):
        if element.tag not in ("subscribe_to", "publish_to"):
            continue
        where = f"{source}: <{element.tag}> #{i}"
        name, msgtype = element.get("name"), element.get("msg_type")
        if not name or not name.strip("/"):
            raise MappingError(f"{where}: the attribute name (a topic) is required")
        if not msgtype or not _TYPE_NAME.match(msgtype):
            raise MappingError(f"{where} ({name}): msg_type {msgtype!r} is not a message type")
        topic = normalize_topic(name)
        if element.tag == "subscribe_to":
            if topic in TF_TOPICS:
                continue  # the built-in mapping (ROS 1's tf/tfMessage has the same layout)
            mapping.topics[topic] = [whole_message_entry(topic, where)]
        else:
            mapping.publish.append(PublishEntry(topic, normalize_type(msgtype),
                                                f"{topic_event_name(topic)}(Msg)^T", None, None,
                                                where))
    return mapping


def load_mapping(path: str | Path) -> Mapping:
    """Read a MAP file: YAML, or a Retalis-style ``pub_sub.xml`` (``.xml`` or text starting
    with ``<``).

    >>> load_mapping("/no/such/map.yaml")
    Traceback (most recent call last):
    ...
    slr_sql.ros.mapping.MappingError: cannot read the MAP file /no/such/map.yaml: No such file or directory
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        raise MappingError(f"cannot read the MAP file {path}: {reason}") from None
    if path.suffix.lower() == ".xml" or text.lstrip().startswith("<"):
        return mapping_from_pub_sub_xml(text, str(path))
    import yaml

    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        at = f":{mark.line + 1}:{mark.column + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc)
        raise MappingError(f"{path}{at}: not valid YAML: {problem}") from None
    return mapping_from_dict(data, str(path))


# ---------------------------------------------------------------------------------------------
# checking against message definitions, and compiling
# ---------------------------------------------------------------------------------------------

def _field_list(fielddefs: dict, msgtype: str) -> list:
    return fielddefs[msgtype][1]


def _resolve(fielddefs: dict | None, node: Any, path: FieldPath, where: str) -> Any:
    """The definition node a path ends on, starting from ``node`` (``("msg", type)``,
    ``("base", name)``, ``("seq", node)``), or None without definitions. Raises MappingError
    naming ``where``."""
    if fielddefs is None or node is None:
        return None
    walked = path.text.split(".")[0] if path.text.startswith("$") else ""
    for step in path.steps:
        if isinstance(step, int):
            if node[0] != "seq":
                raise MappingError(f"{where}: {walked or 'the message'} is not a list; [{step}] "
                                   f"cannot index it")
            node = node[1]
            walked += f"[{step}]"
            continue
        if node[0] != "msg" or node[1] in TIME_TYPES:
            raise MappingError(f"{where}: {walked or 'the value'} has no fields ({step!r} asked)")
        if node[1] not in fielddefs:
            return None  # no definition known: checked per message
        fields = _field_list(fielddefs, node[1])
        found = next((d for n, d in fields if n == step), None)
        if found is None:
            names = ", ".join(n for n, _ in fields)
            raise MappingError(f"{where}: {node[1]} has no field {step!r} (fields: {names})")
        node = _node(found)
        walked = f"{walked}.{step}" if walked else step
    return node


def _node(definition: tuple) -> tuple:
    kind, detail = definition
    if kind == _BASE:
        return ("base", detail[0])
    if kind == _NAME:
        return ("msg", detail)
    if kind in (_ARRAY, _SEQUENCE):
        return ("seq", _node(detail[0]))
    return ("unknown", detail)


def _has_header(fielddefs: dict | None, node: Any) -> bool:
    if fielddefs is None or node is None or node[0] != "msg" or node[1] not in fielddefs:
        return False
    return any(n == "header" and d == (_NAME, HEADER_TYPE)
               for n, d in _field_list(fielddefs, node[1]))


def _getter(path: FieldPath) -> Callable[[Any, Any], Any]:
    """``f(msg, item)`` -> the raw value at the path (MessageError when an index is missing)."""
    steps = path.steps
    from_msg = path.root == "msg"
    if not steps:
        return (lambda msg, item: msg) if from_msg else (lambda msg, item: item)
    if all(isinstance(s, str) for s in steps):
        get = attrgetter(".".join(steps))
        if from_msg:
            return lambda msg, item: get(msg)
        return lambda msg, item: get(item)

    def walk(msg: Any, item: Any) -> Any:
        value = msg if from_msg else item
        for step in steps:
            if isinstance(step, int):
                try:
                    value = value[step]
                except (IndexError, TypeError):
                    raise MessageError(f"{path.text}: no element [{step}]") from None
            else:
                value = getattr(value, step)
        return value
    return walk


def _compile(t: Template) -> Callable[[Any, Any], Any]:
    """``f(msg, item)`` -> the term of one template."""
    if t.kind == "const":
        value = t.value
        return lambda msg, item: value
    if t.kind == "path":
        get = _getter(t.value)
        convert = message_term
        return lambda msg, item: convert(get(msg, item))
    if t.kind == "string":
        get = _getter(t.value)
        return lambda msg, item: String(str(get(msg, item)))
    parts = [_compile(a) for a in t.args]
    if t.kind == "list":
        return lambda msg, item: [p(msg, item) for p in parts]
    name = t.value
    return lambda msg, item: Struct(name, [p(msg, item) for p in parts])


class BoundEntry:
    """A topic entry checked against and compiled for one message type:
    ``events(msg, arrival_seconds)`` -> ``[(name, args, start, end), ...]``."""

    def __init__(self, entry: TopicEntry, msgtype: str, fielddefs: dict | None):
        self.entry = entry
        self.msgtype = msgtype
        where = entry.where
        if entry.msgtype is not None and entry.msgtype != msgtype:
            raise MappingError(f"{where}.type: the mapping says {entry.msgtype} but the topic "
                               f"carries {msgtype}")
        if fielddefs is not None and msgtype not in fielddefs:
            fielddefs = None  # no definition for this type: paths are checked per message
        item_node: Any = ("msg", msgtype)
        if entry.foreach is not None:
            node = _resolve(fielddefs, ("msg", msgtype), entry.foreach, f"{where}.foreach")
            if node is not None and node[0] != "seq":
                raise MappingError(f"{where}.foreach: {entry.foreach.text} is not a list field")
            item_node = node[1] if node is not None else None
        for template in entry.args:
            for path, at in _template_paths(template):
                self._check(fielddefs, msgtype, item_node, path, at)
        time = entry.time
        if time is None:  # the default: the header stamp of the element, then of the message
            if _has_header(fielddefs, item_node) and entry.foreach is not None:
                time = FieldPath("item", ("header", "stamp"), "header.stamp")
            elif _has_header(fielddefs, ("msg", msgtype)):
                time = FieldPath("msg", ("header", "stamp"), "$msg.header.stamp")
            elif msgtype == HEADER_TYPE and entry.foreach is None:  # the message is a header
                time = FieldPath("msg", ("stamp",), "$msg.stamp")
            elif fielddefs is None and entry.foreach is None:
                time = "header_or_record"
            else:
                time = "record"
        elif isinstance(time, FieldPath):
            node = self._check(fielddefs, msgtype, item_node, time, f"{where}.time")
            if node is not None and not (node == ("msg", TIME_TYPES[0]) or node == ("msg", TIME_TYPES[1])
                                         or (node[0] == "base" and node[1] in _NUMERIC_BASES)):
                raise MappingError(f"{where}.time: {time.text} is neither a Time nor a number")
        self.time = time
        self._args = [_compile(t) for t in entry.args]
        self._foreach = _getter(entry.foreach) if entry.foreach is not None else None
        self._time = _getter(time) if isinstance(time, FieldPath) else None
        self.name = entry.event

    @staticmethod
    def _check(fielddefs: dict | None, msgtype: str, item_node: Any, path: FieldPath,
               where: str) -> Any:
        start = ("msg", msgtype) if path.root == "msg" else item_node
        return _resolve(fielddefs, start, path, where)

    def events(self, msg: Any, arrival: float) -> list[tuple]:
        """The events of one message; ``arrival`` (seconds) is its record or receive time."""
        name, args = self.name, self._args
        items = self._foreach(msg, msg) if self._foreach is not None else (msg,)
        out = []
        try:
            for item in items:
                if self._time is not None:
                    t = _to_seconds(self._time(msg, item))
                elif self.time == "header_or_record":
                    header = getattr(msg, "header", None)
                    t = _to_seconds(header.stamp) if header is not None else arrival
                else:
                    t = arrival
                out.append((name, tuple(a(msg, item) for a in args), t, t))
        except AttributeError as exc:
            raise MessageError(f"{self.entry.where}: {exc}") from None
        return out
