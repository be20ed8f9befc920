"""Runtime control of ``slr ros bridge`` from ROS (docs/ros.md, "Control requests").

The SLR paper's implementation offered these as ROS services (add_output_subscription,
delete_output_subscription, add_input_subscription, add_memory, delete_memory); here each is
a request on the control topic, acknowledged on the reply topic with the request's token:

* ``subscribe`` / ``unsubscribe`` — the paper's ``register(ID, s_win(...))``: the events
  matching a pattern (``kb.subscribe``) published as messages on an output topic, built as a
  MAP ``publish:`` entry builds them;
* ``add_input`` / ``remove_input`` — a topic and its mapping (a MAP ``topics:`` entry);
* ``add_buffer`` / ``remove_buffer`` — the three history policies (``kb.add_buffer``);
* ``list`` — what is active.

**Durable.** Output subscriptions and input topics are kept in the store as the named
program ``slr_ros_control:NODE`` (NODE: the bridge's node name), one fact per item::

    slr_ros_control('slr_bridge', input, '/odom', "{\\"mapping\\":{...},\\"topic\\":\\"/odom\\"}").
    slr_ros_control('slr_bridge', subscription, alarms, "{\\"id\\":\\"alarms\\",...}").

The last argument is the request that made the item (its JSON, without token and op). Each
change replaces the program in one transaction (``kb.load(text, name=, replace=True)``;
``kb.unload`` when nothing is left), before the reply is sent; a bridge of the same node
name started on the store later makes the same items again (:meth:`Controller.resume`).
Runtime buffers need nothing of this: the knowledge base keeps them itself. An output
subscription is made with the durable id ``ros:NODE:ID``, so a restarted bridge resumes it
after the last event it delivered.

>>> OPERATIONS["add_memory"], OPERATIONS["subscribe"]
('add_buffer', 'subscribe')
"""
from __future__ import annotations

import json
import uuid
from dataclasses import dataclass, field
from typing import Any, Callable

from slr_sql import Atom, SLRError, String, Struct

from ..service.encoding import encode_plain
from .mapping import PublishEntry, TopicEntry, publish_entry, topic_entry, normalize_topic
from .protocol import ServiceError, check_keys, number_field, string_field

__all__ = ["Controller", "OPERATIONS", "CONTROL_FACT", "program_name"]

CONTROL_FACT = "slr_ros_control"
NOT_AVAILABLE = "subscriptions are not available in this build"

# request kind -> the operation; the paper's service names are accepted too
OPERATIONS = {
    "subscribe": "subscribe", "unsubscribe": "unsubscribe",
    "add_input": "add_input", "remove_input": "remove_input",
    "add_buffer": "add_buffer", "remove_buffer": "remove_buffer", "list": "list",
    "add_output_subscription": "subscribe", "delete_output_subscription": "unsubscribe",
    "add_input_subscription": "add_input", "delete_input_subscription": "remove_input",
    "add_memory": "add_buffer", "delete_memory": "remove_buffer",
}
_KEYS = {
    "subscribe": ("token", "op", "id", "topic", "type", "pattern", "event", "where", "fields",
                  "since", "until"),
    "unsubscribe": ("token", "op", "id"),
    "add_input": ("token", "op", "topic", "mapping"),
    "remove_input": ("token", "op", "topic"),
    "add_buffer": ("token", "op", "pattern", "keep_last", "keep_seconds", "keep_between"),
    "remove_buffer": ("token", "op", "id"),
    "list": ("token", "op"),
}


def program_name(node_name: str) -> str:
    """The named program holding a bridge's control state.

    >>> program_name("slr_bridge")
    'slr_ros_control:slr_bridge'
    """
    return f"{CONTROL_FACT}:{node_name}"


@dataclass
class _Output:
    id: str
    spec: dict                 # the request (no token, no op): what is stored
    entry: PublishEntry
    handle: Any = None         # the knowledge base's subscription
    error: str | None = None   # why it is not active (after a restart)


@dataclass
class _Input:
    topic: str
    spec: dict
    entries: list[TopicEntry] = field(default_factory=list)
    error: str | None = None


class Controller:
    """The control state of one bridge: output subscriptions and input topics made at
    runtime. :meth:`handle` runs one request (on the node's executor thread) and returns
    the reply's fields, or raises an SLRError that becomes the error reply."""

    def __init__(self, bridge: Any, node_name: str, log: Callable[[str], None] | None = None):
        self.bridge = bridge
        self.kb = bridge.kb
        self.node_name = node_name
        self.program = program_name(node_name)
        self.log = log or bridge.log
        self.outputs: dict[str, _Output] = {}
        self.inputs: dict[str, _Input] = {}
        self.map_topics = frozenset(bridge.mapping.topics)  # the MAP file's own: not ours
        self.map_publish = frozenset(e.topic for e in bridge.mapping.publish)
        self.closed = False

    # -- requests -----------------------------------------------------------------------------
    def handle(self, op: Any, body: dict) -> dict:
        """Run the control request ``body`` of kind ``op``; returns the reply's fields."""
        if not isinstance(op, str) or op not in OPERATIONS:
            raise ServiceError(f"unknown request kind {op!r} (expected one of "
                               f"{', '.join(sorted(set(OPERATIONS.values())))})" if op is not None
                               else '"op" is required: the kind of control request (one of '
                               f"{', '.join(sorted(set(OPERATIONS.values())))})")
        operation = OPERATIONS[op]
        check_keys(body, _KEYS[operation], f"{op} request")
        return getattr(self, f"_{operation}")(body)

    def _subscribe(self, body: dict, persist: bool = True) -> dict:
        spec = {k: v for k, v in body.items() if k not in ("token", "op")}
        sub_id = string_field(body, "id") or f"sub{uuid.uuid4().hex[:8]}"
        spec["id"] = sub_id
        pattern = body.get("pattern", body.get("event"))
        if "pattern" in body and "event" in body:
            raise ServiceError('give "pattern" or "event" (the same thing), not both')
        entry = publish_entry({"topic": body.get("topic"), "type": body.get("type"),
                                "event": pattern, **{k: body[k] for k in ("where", "fields")
                                                     if k in body}},
                               f"subscription {sub_id}")
        since = body.get("since", "now")
        if since != "now":
            since = number_field(body, "since")
        until = number_field(body, "until")
        existing = self.outputs.get(sub_id)
        if existing is not None and persist:
            if existing.handle is not None:
                if existing.spec == spec:
                    return {"id": sub_id, "topic": entry.topic}  # the same request again
                raise ServiceError(f"a subscription with the id {sub_id!r} exists already "
                                   f"(unsubscribe it first)")
            del self.outputs[sub_id]  # stored but not active (see resume): made anew
        self._check_output_topic(entry.topic)
        output = _Output(sub_id, spec, entry)
        self.outputs[sub_id] = output
        try:
            self._activate(output, since, until)
            if persist:
                self._persist()
        except BaseException:
            if persist:
                self._deactivate(output)
                del self.outputs[sub_id]
                if existing is not None:
                    self.outputs[sub_id] = existing
            raise
        return {"id": sub_id, "topic": entry.topic}

    def _activate(self, output: _Output, since: Any, until: float | None) -> None:
        subscribe = getattr(self.kb, "subscribe", None)
        if subscribe is None:
            raise ServiceError(f"{NOT_AVAILABLE} (the knowledge base has no subscribe())",
                               kind="NotImplemented")
        entry = output.entry
        self.bridge.add_publisher(entry)
        try:
            output.handle = subscribe(entry.event, where=entry.where_goal, since=since,
                                      until=until, id=f"ros:{self.node_name}:{output.id}",
                                      callback=lambda answer: self._deliver(output, answer))
        except BaseException:
            self._release_publisher(entry.topic, output)
            raise
        output.error = None

    def _deliver(self, output: _Output, answer: dict) -> None:
        """Called by the subscription (its delivery thread) for each answer."""
        if self.closed or output.handle is None:
            return
        try:
            self.bridge.publish_answer(output.entry, answer)
        except SLRError as exc:
            self.log(f"warning: subscription {output.id}: answer not published: {exc}")
        except Exception as exc:  # noqa: BLE001 - a node shutting down; never kill delivery
            self.log(f"warning: subscription {output.id}: answer not published: "
                     f"{type(exc).__name__}: {exc}")

    def _deactivate(self, output: _Output) -> None:
        handle, output.handle = output.handle, None
        if handle is not None:
            try:
                handle.close()
            finally:
                self._release_publisher(output.entry.topic, output)

    def _release_publisher(self, topic: str, leaving: _Output) -> None:
        if topic in self.map_publish:
            return
        if any(o is not leaving and o.handle is not None and o.entry.topic == topic
               for o in self.outputs.values()):
            return
        self.bridge.remove_publisher(topic)

    def _check_output_topic(self, topic: str) -> None:
        if topic in self.bridge.reserved_topics:
            raise ServiceError(f"{topic} is a topic of the request protocol")
        if topic in self.inputs or topic in self.map_topics:
            raise ServiceError(f"{topic} is an input topic of the bridge; publishing to it "
                               f"would store the answers again")

    def _unsubscribe(self, body: dict) -> dict:
        sub_id = string_field(body, "id", required=True)
        output = self.outputs.get(sub_id)
        if output is None:
            raise ServiceError(f"no subscription {sub_id!r} (subscriptions: "
                               f"{', '.join(map(repr, self.outputs)) or 'none'})",
                               kind="NotFound")
        del self.outputs[sub_id]
        try:
            self._persist()
        except BaseException:
            self.outputs[sub_id] = output
            raise
        self._deactivate(output)
        return {"removed": sub_id}

    def _add_input(self, body: dict, persist: bool = True) -> dict:
        topic = string_field(body, "topic", required=True)
        topic = normalize_topic(topic)
        spec_mapping = body.get("mapping")
        if not isinstance(spec_mapping, (dict, list)) or not spec_mapping:
            raise ServiceError('"mapping" is required: a MAP topic entry (an object with '
                               'event, args, time, foreach, type) or a list of them')
        if topic in self.map_topics:
            raise ServiceError(f"{topic} is mapped by the MAP file; change it there")
        if topic in self.bridge.reserved_topics:
            raise ServiceError(f"{topic} is a topic of the request protocol")
        if any(o.entry.topic == topic for o in self.outputs.values()) \
                or topic in self.map_publish:
            raise ServiceError(f"{topic} is an output topic of the bridge")
        specs = spec_mapping if isinstance(spec_mapping, list) else [spec_mapping]
        entries = [topic_entry(topic, s, "mapping" if isinstance(spec_mapping, dict)
                                else f"mapping[{i}]") for i, s in enumerate(specs)]
        previous = self.inputs.get(topic)
        record = _Input(topic, {"topic": topic, "mapping": spec_mapping}, entries)
        subscribed = self.bridge.remap_topic(topic, entries)
        self.inputs[topic] = record
        if persist:
            try:
                self._persist()
            except BaseException:
                if previous is None:
                    del self.inputs[topic]
                    self.bridge.remap_topic(topic, None)
                else:
                    self.inputs[topic] = previous
                    self.bridge.remap_topic(topic, previous.entries)
                raise
        return {"topic": topic, "events": sorted({e.event for e in entries}),
                "subscribed": subscribed}

    def _remove_input(self, body: dict) -> dict:
        topic = normalize_topic(string_field(body, "topic", required=True))
        record = self.inputs.get(topic)
        if record is None:
            if topic in self.map_topics:
                raise ServiceError(f"{topic} is mapped by the MAP file; change it there")
            raise ServiceError(f"no input topic {topic} added at runtime (added: "
                               f"{', '.join(self.inputs) or 'none'})", kind="NotFound")
        del self.inputs[topic]
        try:
            self._persist()
        except BaseException:
            self.inputs[topic] = record
            raise
        if record.error is None:  # it was mapped (a stored one that failed to resume was not)
            self.bridge.remap_topic(topic, None)
        return {"removed": topic}

    def _add_buffer(self, body: dict) -> dict:
        pattern = string_field(body, "pattern", required=True)
        kwargs: dict[str, Any] = {}
        if body.get("keep_last") is not None:
            keep_last = body["keep_last"]
            if isinstance(keep_last, bool) or not isinstance(keep_last, int):
                raise ServiceError('"keep_last" must be an integer')
            kwargs["keep_last"] = keep_last
        if body.get("keep_seconds") is not None:
            kwargs["keep_seconds"] = number_field(body, "keep_seconds")
        if body.get("keep_between") is not None:
            pair = body["keep_between"]
            if not isinstance(pair, list) or len(pair) != 2:
                raise ServiceError('"keep_between" must be [t1, t2]')
            kwargs["keep_between"] = (number_field({"t1": pair[0]}, "t1"),
                                      number_field({"t2": pair[1]}, "t2"))
        return {"id": self.kb.add_buffer(pattern, **kwargs)}

    def _remove_buffer(self, body: dict) -> dict:
        buffer_id = body.get("id")
        if isinstance(buffer_id, bool) or not isinstance(buffer_id, int):
            raise ServiceError('"id" must be the integer id of a buffer')
        if not any(getattr(info, "id", None) == buffer_id for info in self.kb.buffers()):
            raise ServiceError(f"no active buffer #{buffer_id}", kind="NotFound")
        self.kb.remove_buffer(buffer_id)
        return {"removed": buffer_id}

    def _list(self, body: dict) -> dict:
        import dataclasses

        subscriptions = []
        for o in self.outputs.values():
            item = {**o.spec, "active": o.handle is not None}
            if o.error:
                item["error"] = o.error
            subscriptions.append(item)
        inputs = []
        for record in self.inputs.values():
            item = {**record.spec, "subscribed": record.topic in self.bridge.stats.subscribed}
            if record.error:
                item["error"] = record.error
            inputs.append(item)
        buffers = [encode_plain(dataclasses.asdict(b) if dataclasses.is_dataclass(b) else b)
                   for b in self.kb.buffers()]
        return {"subscriptions": subscriptions, "inputs": inputs, "buffers": buffers}

    # -- the store ----------------------------------------------------------------------------
    def _persist(self) -> None:
        """Write the control state as the program ``slr_ros_control:NODE`` (replacing it)."""
        node = Atom(self.node_name)
        facts = [Struct(CONTROL_FACT, (node, Atom("input"), Atom(r.topic), String(_json(r.spec))))
                 for r in self.inputs.values()]
        facts += [Struct(CONTROL_FACT, (node, Atom("subscription"), Atom(o.id),
                                        String(_json(o.spec))))
                  for o in self.outputs.values()]
        if not facts:
            if self.program in self.kb.programs():
                self.kb.unload(self.program)
            return
        text = "\n".join([f"% written by slr ros bridge {self.node_name}: its runtime "
                          f"subscriptions and input topics (docs/ros.md)"]
                         + [f"{fact}." for fact in facts]) + "\n"
        self.kb.load(text, name=self.program, replace=True)

    def resume(self) -> list[str]:
        """Make again the input topics and output subscriptions stored for this node (by an
        earlier run); returns one line per item. An item that cannot be made now (its
        message package is missing, the MAP maps its topic, ...) stays stored and is listed
        with its error."""
        if self.program not in self.kb.programs():
            return []
        answers = self.kb.query(f"{CONTROL_FACT}(N, K, Key, Spec)",
                                args={"N": Atom(self.node_name)})
        lines = []
        for answer in answers:
            kind, key = str(answer["K"]), str(answer["Key"])
            try:
                spec = json.loads(str(answer["Spec"]))
                if not isinstance(spec, dict):
                    raise ValueError("not an object")
            except ValueError as exc:
                self.log(f"warning: stored {kind} {key}: unreadable ({exc}); skipped")
                continue
            if kind == "input":
                lines.append(self._resume_input(key, spec))
            elif kind == "subscription":
                lines.append(self._resume_output(key, spec))
        return lines

    def _resume_input(self, topic: str, spec: dict) -> str:
        try:
            self._add_input(spec, persist=False)
            return f"resumed input {topic}"
        except SLRError as exc:
            self.inputs[topic] = _Input(topic, spec, error=str(exc))
            self.log(f"warning: stored input {topic} not resumed: {exc}")
            return f"input {topic} not resumed: {exc}"

    def _resume_output(self, sub_id: str, spec: dict) -> str:
        try:
            self._subscribe(spec, persist=False)
            return f"resumed subscription {sub_id}"
        except SLRError as exc:
            output = self.outputs.get(sub_id)
            if output is None:  # the spec itself no longer reads: keep it as stored
                output = self.outputs[sub_id] = _Output(sub_id, spec, _placeholder(spec))
            output.error = str(exc)
            self.log(f"warning: stored subscription {sub_id} not resumed: {exc}")
            return f"subscription {sub_id} not resumed: {exc}"

    def close(self) -> None:
        """Close the knowledge-base subscriptions (their stored state stays: a later bridge
        resumes them). Idempotent."""
        self.closed = True
        for output in list(self.outputs.values()):
            handle, output.handle = output.handle, None
            if handle is not None:
                try:
                    handle.close()
                except Exception as exc:  # noqa: BLE001 - closing is best effort
                    self.log(f"warning: subscription {output.id}: close failed: {exc}")


def _json(spec: dict) -> str:
    return json.dumps(spec, sort_keys=True, ensure_ascii=True, separators=(",", ":"),
                      allow_nan=False)


def _placeholder(spec: dict) -> PublishEntry:
    topic = spec.get("topic")
    return PublishEntry(normalize_topic(topic) if isinstance(topic, str) and topic else "/",
                        str(spec.get("type")), str(spec.get("pattern", spec.get("event"))),
                        None, None, f"subscription {spec.get('id')}")

