"""``slr ros bridge``: a live ROS 2 node (rclpy) that stores mapped topics as events.

* Topics are found on the ROS graph: a mapped topic (or, with ``all_topics``, any topic) is
  subscribed as soon as a publisher for it appears, with a QoS that matches every publisher
  (best effort if one of them is, transient local if all of them are, as ``/tf_static``
  publishers are).
* Messages arrive as serialized bytes (``raw=True``) and are decoded with ``rosbags`` from the
  standard ROS 2 definitions plus the MAP's ``definitions``: the same decoder and mapping code
  as ``slr ros import``. A topic whose message package has no Python module here (tf2_msgs
  with the ROS 2 wheels) is subscribed through a stand-in type support
  (:mod:`slr_sql.ros.foreign_types`).
* Each message becomes events at once (one ``kb.add_many`` per message, or per burst of
  messages that queued up meanwhile). The event time is
  the header stamp (or what the MAP says); the arrival time is the store's clock when the
  store receives it, so the learned maximum delays are the real latencies.
* ``fully_updated`` entries call ``kb.mark_complete`` for each message on their topic.
* ``publish`` entries: :meth:`Bridge.publish_answer` turns one answer (a dict of variable
  values, as a subscription delivers it) into a message on the entry's topic. Feeding it
  from ``kb.subscribe``: each entry is a subscription whose answers are published.

:func:`run_bridge` is the command: it runs until SIGINT or SIGTERM, then closes the node and
the store and returns 0.

>>> from slr_sql.ros.bridge import field_value
>>> field_value(1.25, "builtin_interfaces/Time", "header.stamp")
{'sec': 1, 'nanosec': 250000000}
"""
from __future__ import annotations

import functools
import importlib
import math
import signal
import sys
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable

from slr_sql import SLRError, Struct
from slr_sql.errors import SLRUnavailable
from slr_sql.log_throttle import ThrottledLog
from slr_sql.api import KnowledgeBaseAPI
from slr_sql.service.errors import ServiceOutcomeUnknown
from slr_sql.printable import shown
from slr_sql.terms import int_text

from . import fast_tf
from .foreign_types import stand_in_class
from .mapping import TF_TOPICS, Mapping, PublishEntry, normalize_topic, normalize_type

__all__ = ["Bridge", "BridgeError", "PublishError", "run_bridge", "field_value",
           "message_class", "BridgeStats"]

# Topics every ROS 2 node has; never events, even with all_topics.
_SYSTEM_TOPICS = frozenset({"/rosout", "/parameter_events"})
DISCOVERY_PERIOD = 0.2  # seconds between looks at the ROS graph for new publishers
MAX_BATCH = 1000        # messages stored in one transaction when they queued up
MAX_HELD = 100_000      # messages held while the store takes no writes; later ones dropped


class BridgeError(SLRError):
    """The bridge cannot start or run (rclpy missing, a bad MAP for the live topics, ...)."""


class PublishError(SLRError):
    """An answer that cannot become a message of the publish entry's type."""


def _rclpy() -> Any:
    try:
        import rclpy  # noqa: F401
        import rclpy.node  # noqa: F401
        import rclpy.qos  # noqa: F401
    except ImportError as exc:
        raise BridgeError(
            f"the bridge needs rclpy ({exc}): pip install 'slr_sql[ros]' (the ROS 2 wheels) "
            f"or source a ROS 2 installation") from None
    return sys.modules["rclpy"]


def message_class(msgtype: str) -> Any | None:
    """The rclpy message class of ``pkg/msg/Name``, or None when its Python package is not
    installed (tf2_msgs has no wheel, for one).

    >>> message_class("no_such_msgs/msg/Nothing") is None
    True
    """
    pkg, _, name = normalize_type(msgtype).partition("/msg/")
    try:
        module = importlib.import_module(f"{pkg}.msg")
    except ImportError:
        return None
    return getattr(module, name, None)


# ---------------------------------------------------------------------------------------------
# answers -> messages
# ---------------------------------------------------------------------------------------------

_INT_TYPES = frozenset({"byte", "char", "int8", "uint8", "int16", "uint16", "int32", "uint32",
                        "int64", "uint64", "octet"})
_FLOAT_TYPES = frozenset({"float", "double", "float32", "float64", "long double"})
_TIME_TYPES = frozenset({"builtin_interfaces/Time", "builtin_interfaces/Duration",
                         "builtin_interfaces/msg/Time", "builtin_interfaces/msg/Duration"})


def _element_type(ftype: str) -> str | None:
    if ftype.startswith("sequence<"):
        inner = ftype[len("sequence<"):-1]
        return inner.split(",")[0].strip()
    if ftype.endswith("]") and "[" in ftype:
        return ftype[:ftype.index("[")]
    return None


def field_value(value: Any, ftype: str, path: str) -> Any:
    """An answer value as the Python value of a message field of rclpy type ``ftype``
    (``double``, ``string``, ``sequence<double>``, ``geometry_msgs/Point``, ...). Nested
    messages come back as dicts of field values; :func:`_fill` sets them.

    >>> field_value([1, 2.5], "sequence<double>", "data")
    [1.0, 2.5]
    """
    element = _element_type(ftype)
    if element is not None:
        if not isinstance(value, list):
            raise PublishError(f"{path}: expects a list for {ftype}, not {shown(value)}")
        return [field_value(v, element, f"{path}[{i}]") for i, v in enumerate(value)]
    base = ftype.split("<")[0]
    if base == "boolean":
        if value in ("true", "false") or isinstance(value, bool):
            return value is True or value == "true"
        raise PublishError(f"{path}: expects true or false, not {shown(value)}")
    if base in _INT_TYPES:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
        raise PublishError(f"{path}: expects an integer for {ftype}, not {shown(value)}")
    if base in _FLOAT_TYPES:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            try:
                return float(value)
            except OverflowError:
                raise PublishError(f"{path}: {shown(value)} is beyond any {ftype}") from None
        raise PublishError(f"{path}: expects a number for {ftype}, not {shown(value)}")
    if base in ("string", "wstring"):
        if isinstance(value, str):
            return str(value)
        if type(value) is int:
            return int_text(value)   # (str() refuses more than 4,300 digits)
        return str(value)  # a float, a compound or a list: its Prolog text
    if base in _TIME_TYPES:
        if isinstance(value, (int, float)) and not isinstance(value, bool) \
                and abs(value) < 2 ** 62:   # (isfinite raises on an integer beyond floats)
            sec = math.floor(value)
            nanosec = int(round((value - sec) * 1e9))
            if nanosec >= 1_000_000_000:
                sec, nanosec = sec + 1, nanosec - 1_000_000_000
            return {"sec": int(sec), "nanosec": nanosec}
        if isinstance(value, Struct) and len(value.args) == 2:
            return {"sec": value.args[0], "nanosec": value.args[1]}
        raise PublishError(f"{path}: expects a time in seconds, not {shown(value)}")
    if "/" in ftype:  # a nested message: a compound named by its type, fields in order
        if isinstance(value, Struct):
            return ("struct", normalize_type(ftype), value)
        raise PublishError(f"{path}: expects a {ftype} message as a term, not {shown(value)}")
    raise PublishError(f"{path}: unsupported field type {ftype}")


def _fill(msg: Any, values: dict, path: str) -> None:
    """Set fields of the rclpy message ``msg`` from ``{field: value}`` (values as
    :func:`field_value` returns them)."""
    for name, value in values.items():
        _set(msg, name, value, f"{path}{name}")


def _set(msg: Any, name: str, value: Any, path: str) -> None:
    if isinstance(value, dict):
        _fill(getattr(msg, name), value, f"{path}.")
    elif isinstance(value, tuple) and value and value[0] == "struct":
        _fill_from_term(getattr(msg, name), value[2], path)
    elif isinstance(value, list) and value and isinstance(value[0], tuple):
        items = []
        for i, (_, msgtype, term) in enumerate(value):  # nested messages, as compounds
            cls = message_class(msgtype)
            if cls is None:
                raise PublishError(f"{path}[{i}]: no Python module for {msgtype}")
            item = cls()
            _fill_from_term(item, term, f"{path}[{i}]")
            items.append(item)
        setattr(msg, name, items)
    else:
        try:
            setattr(msg, name, value)
        except (AssertionError, TypeError, ValueError) as exc:
            raise PublishError(f"{path}: {exc or 'value out of range'}") from None


def _named_fields(term: Any) -> list | None:
    """``[(name, value)]`` of a message term whose arguments are ``Name: Value`` pairs."""
    if not isinstance(term, Struct) or not term.args:
        return None
    out = []
    for arg in term.args:
        if not (isinstance(arg, Struct) and arg.name == ":" and len(arg.args) == 2
                and isinstance(arg.args[0], str)):
            return None
        out.append((str(arg.args[0]), arg.args[1]))
    return out


def _fill_from_term(msg: Any, term: Any, path: str) -> None:
    """Set the fields of ``msg`` from a message term: ``Name: Value`` arguments (the
    ``--all`` encoding; the fields it names, the others keep their defaults), or a compound
    whose arguments are all the fields in order."""
    fields = msg.get_fields_and_field_types()
    named = _named_fields(term)
    if named is not None:
        for name, arg in named:
            ftype = fields.get(name)
            where = f"{path}.{name}" if path else name
            if ftype is None:
                raise PublishError(f"{path or 'message'}: no field {name!r} (fields: "
                                   f"{', '.join(fields)})")
            _set(msg, name, field_value(arg, ftype, where), where)
        return
    if not isinstance(term, Struct) or len(term.args) != len(fields):
        raise PublishError(f"{path or 'message'}: expects a compound with {len(fields)} "
                           f"arguments ({', '.join(fields)}), not {term!s}")
    for (name, ftype), arg in zip(fields.items(), term.args):
        _set(msg, name, field_value(arg, ftype, f"{path}.{name}" if path else name),
             f"{path}.{name}" if path else name)


def build_message(entry: PublishEntry, cls: Any, answer: dict) -> Any:
    """The rclpy message of ``entry`` for one answer.

    >>> from slr_sql import Atom
    >>> from slr_sql.ros.mapping import mapping_from_dict
    >>> entry = mapping_from_dict({"topics": {}, "publish": [{"topic": "/alerts",
    ...     "type": "std_msgs/msg/String", "event": "alert(Text)", "fields": {"data": "Text"}}]}).publish[0]
    >>> build_message(entry, message_class(entry.msgtype), {"Text": Atom("battery low"), "T": 3.0})
    std_msgs.msg.String(data='battery low')
    """
    msg = cls()
    if entry.fields is None:
        values = [v for k, v in answer.items() if k not in ("T", "S", "E")] or list(answer.values())
        if len(values) != 1:
            raise PublishError(f"{entry.where}: without fields, the answer must have one "
                               f"variable holding the message; it has {sorted(answer)}")
        _fill_from_term(msg, values[0], "")
        return msg
    for path, (kind, value) in entry.fields:
        if kind == "var":
            if value not in answer:
                raise PublishError(f"{entry.where}.fields.{path}: the answer has no variable "
                                   f"{value} (it has {', '.join(sorted(answer)) or 'none'})")
            value = answer[value]
        target, name = _walk(msg, path, entry.where)
        ftypes = target.get_fields_and_field_types()
        if name not in ftypes:
            raise PublishError(f"{entry.where}.fields.{path}: {type(target).__name__} has no "
                               f"field {name!r} (fields: {', '.join(ftypes)})")
        _set(target, name, field_value(value, ftypes[name], path), path)
    return msg


def _walk(msg: Any, path: str, where: str) -> tuple[Any, str]:
    parts = path.split(".")
    target = msg
    for part in parts[:-1]:
        if not hasattr(target, part):
            raise PublishError(f"{where}.fields.{path}: no field {part!r}")
        target = getattr(target, part)
    return target, parts[-1]


# ---------------------------------------------------------------------------------------------
# the node
# ---------------------------------------------------------------------------------------------

@dataclass
class BridgeStats:
    messages: int = 0
    events: int = 0
    rejected: int = 0
    marks: int = 0
    published: int = 0
    dropped: int = 0   # messages beyond MAX_HELD while the store took no writes
    uncertain: int = 0  # events whose add's answer was lost (a served store): not sent again
    subscribed: dict = field(default_factory=dict)  # topic -> message type


@dataclass
class _Subscription:
    topic: str
    msgtype: str
    bound: list
    marks: list
    fast: Callable | None
    handle: Any = None


class Bridge:
    """The bridge node. ``start()`` creates it; ``spin_once(timeout)`` serves callbacks;
    ``close()`` destroys it (the knowledge base stays open: its owner closes it).

    ``on_ready(topic, msgtype)`` is called after each subscription is made;
    ``log(text)`` receives warnings (a topic that cannot be subscribed, a rejected message).
    """

    def __init__(self, kb: KnowledgeBaseAPI, mapping: Mapping, all_topics: bool = False,
                 node_name: str = "slr_bridge", log: Callable[[str], None] | None = None,
                 on_ready: Callable[[str, str], None] | None = None,
                 ros_args: list[str] | None = None, mapping_given: bool = True):
        self.kb = kb
        self.mapping = mapping
        # ROS command-line arguments (``--ros-args -p map:=robot.yaml -r __node:=name``): the
        # node's parameters ``map`` (a MAP file, used when no mapping was given) and
        # ``all_topics``, remappings, a ``--params-file``
        self.ros_args = list(ros_args or [])
        self.mapping_given = mapping_given
        self.all_topics = all_topics
        self.node_name = node_name
        self.log = log or (lambda text: print(text, file=sys.stderr, flush=True))
        # the lines any publisher's messages make, one per message: each one safe, bounded
        # line, and at most BURST of a kind a minute (docs/printed_text.md)
        self.message_log = ThrottledLog(self.log)
        self.on_ready = on_ready
        self.stats = BridgeStats()
        self._subs: dict[str, _Subscription] = {}
        self._refused: set[str] = set()
        self._publishers: dict[str, Any] = {}
        self._publish_classes: dict[str, Any] = {}
        self._answer_feeds: list = []  # the kb subscriptions feeding the MAP's publish entries
        # topics that are never events, even with all_topics (the request protocol's own)
        self.reserved_topics: set[str] = set()
        # rclpy's context, node and executor and the message types, made by start()
        self._context: Any = None
        self._node: Any = None
        self._executor: Any = None
        self._typestore: Any = None
        # What is taken but not stored yet: the events of the messages taken since the last
        # add_many that succeeded (``_pending_messages`` of them), and the marks still to
        # store, one list per message that has any, in order. A message is held while its
        # events or any of its marks are not stored; ``_marked_pending`` of the mark lists
        # (the last ones) belong to messages whose events are not stored either.
        self._pending_events: list = []
        self._pending_messages = 0
        self._pending_marks: list[list] = []
        self._marked_pending = 0
        # why the store took no writes (SLRBusy, SLRStoreFull, ...) while events are held
        self._unavailable: SLRError | None = None
        clock = getattr(kb, "clock", None)
        self._now = clock.now if clock is not None and hasattr(clock, "now") else time.time

    # -- lifecycle ------------------------------------------------------------------------
    def start(self) -> "Bridge":
        rclpy = _rclpy()
        from rclpy.executors import SingleThreadedExecutor
        from rosbags.typesys import Stores, get_typestore, get_types_from_msg

        self._context = rclpy.Context()
        args = ["slr_bridge"] + self.ros_args if self.ros_args else None
        try:
            # Our own SIGINT/SIGTERM handling (run_bridge) closes the store cleanly.
            from rclpy.signals import SignalHandlerOptions
            rclpy.init(args=args, context=self._context,
                       signal_handler_options=SignalHandlerOptions.NO)
        except ImportError:  # pragma: no cover - older rclpy
            rclpy.init(args=args, context=self._context)
        except Exception as exc:  # noqa: BLE001 - rcl's parse errors of --ros-args
            raise BridgeError(f"--ros-args: {exc}") from None
        from rclpy.node import Node

        self._node = Node(self.node_name, context=self._context,
                          automatically_declare_parameters_from_overrides=True)
        self._apply_parameters()
        store = get_typestore(Stores.ROS2_KILTED)
        for name, text in self.mapping.definitions.items():
            try:
                store.register(get_types_from_msg(text, name))
            except Exception as exc:  # noqa: BLE001 - rosbags' parse errors
                raise BridgeError(f"definitions.{name}: {exc}") from None
        self._typestore = store
        for entry in self.mapping.publish:
            cls = message_class(entry.msgtype)
            if cls is None:
                raise BridgeError(f"{entry.where}.type: no Python module for {entry.msgtype} "
                                  f"(install its package or source a ROS 2 installation)")
            self._publish_classes[entry.topic] = cls
        if self.mapping.requests.enabled:  # never stored as events, not even at discovery
            self.reserved_topics.update(self.mapping.requests.topics())
        self._executor = _executor(self._context, SingleThreadedExecutor)
        self._executor.add_node(self._node)
        for entry in self.mapping.publish:
            self._publishers[entry.topic] = self._node.create_publisher(
                self._publish_classes[entry.topic], entry.topic, 10)
        for entry in self.mapping.publish:
            self._answer_feeds.append(self._feed(entry))
        self._discover()
        self._node.create_timer(DISCOVERY_PERIOD, self._discover)
        return self

    def _apply_parameters(self) -> None:
        """The node's ROS parameters: ``map`` (a MAP file; only when no mapping was given
        otherwise, ``--map`` wins) and ``all_topics`` (bool)."""
        node = self._node
        names = set(node._parameters) if hasattr(node, "_parameters") else set()
        # what the command line and parameter files gave (rclpy's own parameters aside)
        given = set(getattr(node, "_parameter_overrides", {}) or {})
        unknown = sorted(n for n in given if n not in ("map", "all_topics", "use_sim_time",
                                                       "start_type_description_service"))
        if unknown:
            raise BridgeError(f"unknown ROS parameter(s) {', '.join(unknown)} (the bridge "
                              f"takes map and all_topics)")
        if "map" in names:
            value = node.get_parameter("map").value
            if not isinstance(value, str) or not value:
                raise BridgeError(f"ROS parameter map: a MAP file name, not {shown(value)}")
            if not self.mapping_given:
                from .mapping import load_mapping

                self.mapping = load_mapping(value)
        if "all_topics" in names:
            value = node.get_parameter("all_topics").value
            if not isinstance(value, bool):
                raise BridgeError(f"ROS parameter all_topics: true or false, not {shown(value)}")
            self.all_topics = self.all_topics or value

    def spin_once(self, timeout: float = 0.1) -> None:
        """Serve what arrives within ``timeout`` seconds, then store it. A message that finds
        the node idle is stored alone, at once; messages that queued up meanwhile (a burst,
        a slow disk) are taken together and stored in one transaction, so a backlog shrinks
        instead of growing."""
        executor = self._executor
        executor.spin_once(timeout_sec=timeout)
        while self._pending_messages and self._pending_messages < MAX_BATCH:
            before = self._pending_messages
            executor.spin_once(timeout_sec=0)
            if self._pending_messages == before:
                break
        self._flush()

    def _flush(self) -> None:
        """Store the pending events and marks. When the store takes no writes for a reason
        that may pass (another process holds its lock past ``busy_timeout``, the disk is
        full: :class:`SLRUnavailable`), what was not stored stays pending, in order, and is
        tried again at the next spin; said once when it starts and once when it ends. The
        events go first, in one ``add_many``, then the marks one by one: a flush can store
        the events and not (all) the marks, and then holds only the messages whose marks
        are not all stored.

        A knowledge base served by ``slr serve`` whose connection broke after an add was
        sent (:class:`~slr_sql.service.errors.ServiceOutcomeUnknown`) may or may not have
        stored its events: they are not sent again (a second copy of each would be stored),
        said with their number and counted in ``stats.uncertain``; the events no request
        carried yet (an add_many above the server's body limit is sent in several) stay
        pending (as one message). A mark is sent again (a second one
        changes nothing)."""
        if not self._pending_messages and not self._pending_marks:
            return
        events, messages = self._pending_events, self._pending_messages
        marks, marked_pending = self._pending_marks, self._marked_pending
        self._pending_events, self._pending_messages = [], 0
        self._pending_marks, self._marked_pending = [], 0
        try:
            if events:
                try:
                    rejected = self.kb.add_many(events)
                except ServiceOutcomeUnknown as exc:
                    events, messages = self._answer_lost(events, exc), 1
                    if events:   # held, and the marks with them (never before their events)
                        raise
                    rejected = []
                self.stats.events += len(events) - len(rejected)
                for error in rejected:
                    self.stats.rejected += 1
                    self.message_log(f"warning: event rejected: {error}")
            events, messages, marked_pending = [], 0, 0
            while marks:
                message_marks = marks[0]
                while message_marks:
                    event_type, t = message_marks[0]
                    self.kb.mark_complete(event_type, t)
                    message_marks.pop(0)
                    self.stats.marks += 1
                marks.pop(0)
        except (SLRUnavailable, ServiceOutcomeUnknown) as exc:   # (the latter: of a mark)
            self._pending_events = events + self._pending_events
            self._pending_messages += messages
            self._pending_marks = marks + self._pending_marks
            self._marked_pending += marked_pending
            if self._unavailable is None:
                self.log(f"warning: the store takes no writes now ({exc}); "
                         f"{self.held} message(s) held, stored once it does")
            self._unavailable = exc
            return
        if self._unavailable is not None:
            self._unavailable = None
            self.log("the store takes writes again: the held messages are stored")

    def _answer_lost(self, events: list, exc: ServiceOutcomeUnknown) -> list:
        """An add_many of ``events`` whose answer was lost: the events of the request that
        broke are not sent again (said, and counted); those of the requests answered before
        it count as stored; returns those no request carried."""
        first, end = exc.carried if exc.carried is not None and \
            0 <= exc.carried[0] <= exc.carried[1] <= len(events) else (0, len(events))
        self.stats.events += first
        self.stats.uncertain += end - first
        self.log(f"warning: {exc}; {end - first} event(s) may or may not be stored: not "
                 f"sent again, so that none is stored twice")
        return events[end:]

    def _feed(self, entry: PublishEntry) -> Any:
        """Subscribe the MAP's publish entry to the knowledge base: every answer of its
        ``event`` (and ``where``) from now on, incoming or complex, becomes a message."""
        subscribe = getattr(self.kb, "subscribe", None)
        if subscribe is None:
            raise BridgeError(f"{entry.where}: publishing needs subscriptions, which this "
                              f"knowledge base does not offer")

        def deliver(answer: dict) -> None:  # the subscription's delivery thread
            if self._node is None:
                return
            try:
                self.publish_answer(entry, answer)
            except PublishError as exc:  # one bad answer must not stop the others
                self.log(f"publish {entry.topic}: {exc}")

        return subscribe(entry.event, where=entry.where_goal, since="now", callback=deliver)

    def close(self) -> None:
        """Stop the publish feeds, destroy the node and its context (idempotent)."""
        feeds, self._answer_feeds = self._answer_feeds, []
        for feed in feeds:
            feed.close()
        if self._node is not None:
            try:
                if self._executor is not None:   # None: start() failed before it
                    self._executor.remove_node(self._node)
                self._node.destroy_node()
                if self._executor is not None:
                    self._executor.shutdown(timeout_sec=1.0)
            finally:
                self._node = None
                try:
                    self._context.try_shutdown()
                except Exception:  # noqa: BLE001 - already shut down
                    pass

    @property
    def held(self) -> int:
        """Messages taken but not stored yet (held while the store takes no writes): those
        whose events are not stored, and those whose events are stored but not all of
        their completeness marks."""
        return self._pending_messages + len(self._pending_marks) - self._marked_pending

    @property
    def node(self) -> Any:
        """The rclpy node (None before ``start()`` and after ``close()``)."""
        return self._node

    # -- subscriptions --------------------------------------------------------------------
    def remap_topic(self, topic: str, entries: list | None) -> bool:
        """Map ``topic`` to ``entries`` at runtime (``None``: stop mapping it). A current
        subscription of the topic is dropped and, when the topic is still wanted and has a
        publisher, made again with the new entries; returns whether it is subscribed now.
        Raises MappingError when the entries do not fit the topic's message type."""
        topic = normalize_topic(topic)
        old = self.mapping.topics.get(topic)
        if entries is None:
            self.mapping.topics.pop(topic, None)
        else:
            self.mapping.topics[topic] = list(entries)
        self._refused.discard(topic)
        sub = self._subs.pop(topic, None)
        if sub is not None:
            self.stats.subscribed.pop(topic, None)
            self._node.destroy_subscription(sub.handle)
        try:
            self._discover_topics(only=topic, strict=True)
        except SLRError:
            if old is None:
                self.mapping.topics.pop(topic, None)
            else:
                self.mapping.topics[topic] = old
            self._discover_topics(only=topic)
            raise
        return topic in self._subs

    def _wanted(self, topic: str) -> bool:
        if topic in _SYSTEM_TOPICS or topic in self._publishers or topic in self.reserved_topics:
            return False
        return bool(self.mapping.entries_for(topic, self.all_topics)
                    or self.mapping.fully_updated_for(topic))

    def _discover(self) -> None:
        # (no parameters: rclpy passes a TimerInfo to a timer callback that takes one)
        self._discover_topics()

    def _discover_topics(self, only: str | None = None, strict: bool = False) -> None:
        node = self._node
        if node is None:
            return
        for topic, types in node.get_topic_names_and_types():
            topic = normalize_topic(topic)
            if only is not None and topic != only:
                continue
            if topic in self._subs or topic in self._refused or not self._wanted(topic):
                continue
            publishers = node.get_publishers_info_by_topic(topic)
            if not publishers:
                continue
            try:
                self._subscribe(topic, normalize_type(types[0]), publishers)
            except SLRError as exc:  # a mapping that does not fit the topic's message type
                if strict:
                    raise
                self._refused.add(topic)
                self.log(f"warning: {topic}: not subscribed: {exc}")

    def _qos(self, publishers: list) -> Any:
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

        offered = [p.qos_profile for p in publishers]
        reliable = all(q.reliability == ReliabilityPolicy.RELIABLE for q in offered)
        latched = all(q.durability == DurabilityPolicy.TRANSIENT_LOCAL for q in offered)
        return QoSProfile(
            depth=1000,
            reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
            durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)

    def _subscribe(self, topic: str, msgtype: str, publishers: list) -> None:
        fielddefs = self._typestore.fielddefs
        if msgtype not in fielddefs:
            self._refused.add(topic)
            self.log(f"warning: {topic}: no definition of {msgtype}; add it under definitions: "
                     f"in the MAP")
            return
        cls = message_class(msgtype) or stand_in_class(msgtype, self._typestore)
        if cls is None:
            self._refused.add(topic)
            self.log(f"warning: {topic}: cannot subscribe: no Python type support for {msgtype} "
                     f"here (install its package or source a ROS 2 installation)")
            return
        entries = self.mapping.entries_for(topic, self.all_topics)
        bound = [e.bind(msgtype, fielddefs) for e in entries]
        marks = [(m.as_topic_entry().bind(msgtype, fielddefs), m.types)
                 for m in self.mapping.fully_updated_for(topic)]
        fast = None
        if len(bound) == 1 and not marks and bound[0].entry.where.startswith("built-in") \
                and fast_tf.standard_tf_types(fielddefs, ros2=True) and topic in TF_TOPICS:
            fast = functools.partial(fast_tf.decode_cdr, event=bound[0].entry.event)
        sub = _Subscription(topic, msgtype, bound, marks, fast)
        sub.handle = self._node.create_subscription(
            cls, topic, lambda raw, s=sub: self._on_message(s, raw), self._qos(publishers),
            raw=True)
        self._subs[topic] = sub
        self.stats.subscribed[topic] = msgtype
        if self.on_ready is not None:
            self.on_ready(topic, msgtype)

    def _on_message(self, sub: _Subscription, raw: bytes) -> None:
        arrival = float(self._now())
        self.stats.messages += 1
        if self._unavailable is not None and self.held >= MAX_HELD:
            if not self.stats.dropped:
                self.log(f"warning: {MAX_HELD} messages held while the store takes no writes: "
                         f"later ones are dropped (counted at the end) until it does")
            self.stats.dropped += 1
            return
        try:
            if sub.fast is not None:
                events = sub.fast(raw, arrival)
                marks = []
            else:
                msg = self._typestore.deserialize_cdr(raw, sub.msgtype)
                events = []
                for bound in sub.bound:
                    events += bound.events(msg, arrival)
                marks = [(t, e[2]) for bound, types in sub.marks
                         for e in bound.events(msg, arrival) for t in types]
        except Exception as exc:  # noqa: BLE001 - a message that does not decode or map
            self.stats.rejected += 1
            self.message_log(f"warning: {sub.topic}: message rejected: {exc}")
            return
        self._pending_events += events
        self._pending_messages += 1
        if marks:
            self._pending_marks.append(marks)
            self._marked_pending += 1

    # -- publishing -----------------------------------------------------------------------
    def add_publisher(self, entry: PublishEntry) -> None:
        """Create the publisher of a publish entry made at runtime (one per topic; a second
        entry on the topic must have the same message type). Raises BridgeError."""
        cls = message_class(entry.msgtype)
        if cls is None:
            raise BridgeError(f"{entry.where}.type: no Python module for {entry.msgtype} "
                              f"(install its package or source a ROS 2 installation)")
        current = self._publish_classes.get(entry.topic)
        if current is not None:
            if current is not cls:
                raise BridgeError(f"{entry.where}.topic: {entry.topic} is published already "
                                  f"with another message type")
            return
        self._publish_classes[entry.topic] = cls
        self._publishers[entry.topic] = self._node.create_publisher(cls, entry.topic, 10)

    def remove_publisher(self, topic: str) -> None:
        """Destroy the publisher of ``topic`` made by :meth:`add_publisher`."""
        publisher = self._publishers.pop(topic, None)
        self._publish_classes.pop(topic, None)
        if publisher is not None and self._node is not None:
            self._node.destroy_publisher(publisher)

    def publish_answer(self, entry: PublishEntry, answer: dict) -> Any:
        """Publish one answer of ``entry``'s subscription as a message on ``entry.topic``;
        returns the message. This is the one hook a subscription (``kb.subscribe``)
        calls for each delivered answer.

        Raises :class:`PublishError` when the answer does not fit the message type.
        """
        publisher = self._publishers.get(entry.topic)
        if publisher is None:
            raise PublishError(f"{entry.where}: the bridge has no publisher for {entry.topic} "
                               f"(not started, or not an entry of its MAP)")
        msg = build_message(entry, self._publish_classes[entry.topic], answer)
        publisher.publish(msg)
        self.stats.published += 1
        return msg


def _executor(context: Any, fallback: Any) -> Any:
    """rclpy's events executor (C++, a fraction of the per-message cost of the Python one)
    where this rclpy has it; the single-threaded executor otherwise."""
    try:
        from rclpy.experimental import EventsExecutor
    except ImportError:
        return fallback(context=context)
    return EventsExecutor(context=context)


def run_bridge(db: str, mapping: Mapping, all_topics: bool = False,
               node_name: str = "slr_bridge", synchronous: str = "NORMAL",
               echo: Callable[[str], None] | None = None, ros_args: list[str] | None = None,
               mapping_given: bool = True) -> int:
    """Open the store at ``db``, run the bridge until SIGINT or SIGTERM, then close the node
    and the store; returns the exit status (0). ``ros_args``: ROS command-line arguments
    (parameters ``map`` and ``all_topics``, remappings; see :class:`Bridge`).

    It runs until stopped (``slr ros bridge DB`` calls it); a store it cannot open is an error
    before anything starts:

    >>> from slr_sql.ros.mapping import mapping_from_dict
    >>> run_bridge("/no/such/dir/robot.db", mapping_from_dict({"topics": {}}))
    Traceback (most recent call last):
        ...
    slr_sql.errors.SLRError: /no/such/dir/robot.db: no such directory: /no/such/dir
    """
    import slr_sql

    echo = echo or (lambda text: print(text, flush=True))
    _rclpy()
    stop = threading.Event()

    def request_stop(signum: int, frame: Any) -> None:
        stop.set()

    kb = slr_sql.open(db, synchronous=synchronous, checkpoint="background")
    bridge = Bridge(kb, mapping, all_topics=all_topics, node_name=node_name,
                    on_ready=lambda topic, msgtype: echo(f"subscribed {topic} ({msgtype})"),
                    ros_args=ros_args, mapping_given=mapping_given)
    # only now, right before the try whose finally restores them: a store that fails to
    # open must leave the caller's handlers (Ctrl-C) as they were
    previous = {s: signal.signal(s, request_stop) for s in (signal.SIGINT, signal.SIGTERM)}
    server = None
    try:
        bridge.start()
        mapping, all_topics = bridge.mapping, bridge.all_topics   # ROS parameters applied
        node_name = bridge._node.get_name() if bridge._node is not None else node_name
        requests = mapping.requests
        if requests.enabled:  # queries and control over ROS (docs/ros.md, "Requests")
            from .requests import RequestServer

            server = RequestServer(bridge, requests, node_name=node_name).start()
            for line in server.resumed:
                echo(line)
            echo(f"requests: queries on {requests.query} (answers on {requests.answer}), "
                 f"control on {requests.control} (replies on {requests.control_reply})")
        wanted = ", ".join(mapping.topic_names() + [t for t in TF_TOPICS if mapping.tf]) or "-"
        echo(f"bridge ready: node {node_name}, waiting for publishers on {wanted}"
             + (" and every other topic" if all_topics else "")
             + (f"; publishing to {', '.join(e.topic for e in mapping.publish)}"
                if mapping.publish else ""))
        while not stop.is_set():
            bridge.spin_once(0.1)
    finally:
        if server is not None:
            server.close()
        if bridge.held:
            try:
                bridge._flush()   # a last try at what the store did not take yet
            except SLRError as exc:
                echo(f"warning: {exc}")
        held = bridge.held
        bridge.close()
        kb.close()
        for s, handler in previous.items():
            signal.signal(s, handler)
    stats = bridge.stats
    echo(f"bridge stopped: {stats.events} events from {stats.messages} messages"
         + (f", {stats.rejected} rejected" if stats.rejected else "")
         + (f", {stats.dropped} dropped while the store took no writes" if stats.dropped else "")
         + (f", {held} not stored: the store took no writes" if held else "")
         + (f", {stats.uncertain} events of adds whose answer was lost" if stats.uncertain
            else "")
         + (f", {stats.marks} completeness marks" if stats.marks else ""))
    return 0
