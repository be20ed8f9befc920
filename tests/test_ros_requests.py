"""The bridge's request protocol (docs/ros.md, "Requests"): a real rclpy client node
(tests/ros_request_client.py) in a subprocess drives every request kind against a real
`slr ros bridge` subprocess, on loopback only (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and a
random ROS_DOMAIN_ID, set here for the children). Replies are matched by token; the store is
checked through its file; waits are deadline loops. Output subscriptions need kb.subscribe:
with it they are driven for real, without it the error reply is checked."""
from __future__ import annotations

import itertools
import json
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
from hypothesis import given, settings
from hypothesis import strategies as st

import slr_sql
from slr_sql.ros.control import program_name
from slr_sql.ros.mapping import mapping_from_dict
from slr_sql.ros.protocol import parse_query, read_request
from slr_sql.service.encoding import encode_answers
from slr_sql.service.errors import ServiceError

REPO = Path(__file__).resolve().parent.parent
CLIENT = Path(__file__).resolve().parent / "ros_request_client.py"
DEADLINE = 30.0   # seconds; every wait ends as soon as its condition holds
NODE = "slr_req_bridge"


class Process:
    """A subprocess whose stdout lines are read by a thread, waited for with a deadline."""

    def __init__(self, args: list[str], env: dict, stdin: bool = False):
        self.popen = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                      stdin=subprocess.PIPE if stdin else subprocess.DEVNULL,
                                      text=True, env=env, cwd=REPO)
        self.lines: queue.Queue = queue.Queue()
        self.seen: list[str] = []
        self.stderr: list[str] = []
        threading.Thread(target=self._pump, args=(self.popen.stdout, self.lines), daemon=True).start()
        threading.Thread(target=self._pump_err, daemon=True).start()

    @staticmethod
    def _pump(stream, into: queue.Queue) -> None:
        with stream:                    # closed at the end of the output: no ResourceWarning
            for line in stream:
                into.put(line.rstrip("\n"))

    def _pump_err(self) -> None:
        with self.popen.stderr:
            for line in self.popen.stderr:
                self.stderr.append(line)

    def next_line(self, deadline: float) -> str:
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise AssertionError(f"timed out; lines so far: {self.seen[-20:]}; "
                                     f"stderr: {''.join(self.stderr)[-3000:]}")
            try:
                line = self.lines.get(timeout=min(remaining, 0.5))
            except queue.Empty:
                if self.popen.poll() is not None and self.lines.empty():
                    raise AssertionError(f"process exited {self.popen.returncode}: "
                                         f"{''.join(self.stderr)[-3000:]}") from None
                continue
            self.seen.append(line)
            return line

    def wait_for(self, text: str, deadline: float) -> str:
        while True:
            line = self.next_line(deadline)
            if text in line:
                return line

    def stop(self, sig: int = signal.SIGTERM) -> int:
        if self.popen.poll() is None:
            self.popen.send_signal(sig)
            try:
                self.popen.wait(timeout=DEADLINE)
            except subprocess.TimeoutExpired:
                self.popen.kill()
                self.popen.wait()
        if self.popen.stdin is not None:
            self.popen.stdin.close()
        return self.popen.returncode


class Client(Process):
    """The rclpy client node: publishes requests, collects the replies by token."""

    def __init__(self, env: dict, topics: dict):
        super().__init__([sys.executable, str(CLIENT)], env, stdin=True)
        self.topics = topics
        self.replies: dict = {}        # token -> reply (both reply topics)
        self.anonymous: list = []      # replies whose token is null, in arrival order
        self.received: list = []       # (topic, data) on other topics
        self.events: list = []         # the client's own reports ({"matched": topic}, ...)
        self.tokens = itertools.count()
        self.next_line(time.monotonic() + DEADLINE)  # {"ready": true}
        for topic in (topics["answer"], topics["control_reply"]):
            self.send({"listen": topic})

    def send(self, command: dict) -> None:
        self.popen.stdin.write(json.dumps(command) + "\n")
        self.popen.stdin.flush()

    def _take(self, deadline: float) -> dict:
        event = json.loads(self.next_line(deadline))
        if event.get("topic") in (self.topics["answer"], self.topics["control_reply"]):
            reply = json.loads(event["data"])
            reply["_topic"] = event["topic"]
            if reply.get("token") is None:
                self.anonymous.append(reply)
            else:
                self.replies[reply["token"]] = reply
        elif "topic" in event:
            self.received.append((event["topic"], event["data"]))
        else:
            self.events.append(event)
        return event

    def wait(self, condition, deadline: float | None = None) -> None:
        deadline = deadline or time.monotonic() + DEADLINE
        while not condition():
            self._take(deadline)

    def publish(self, topic: str, data, kind: str = "String") -> None:
        self.send({"pub": topic, "type": kind, "data": data})

    def request(self, channel: str, body: dict | str, token: object = "auto") -> dict:
        """Send one request on the query or control topic; the reply with its token."""
        if isinstance(body, dict) and token == "auto":
            token = f"t{next(self.tokens)}"
            body = {"token": token, **body}
        self.publish(self.topics[channel], body if isinstance(body, str) else json.dumps(body))
        if token is None:
            count = len(self.anonymous)
            self.wait(lambda: len(self.anonymous) > count)
            return self.anonymous[count]
        self.wait(lambda: token in self.replies)
        return self.replies.pop(token)

    def query(self, **body) -> dict:
        return self.request("query", body)

    def control(self, op: str, **body) -> dict:
        return self.request("control", {"op": op, **body})

    def handshake(self) -> None:
        """Retry a cheap query and a list request until both reply: then the bridge's
        endpoints and ours have matched in both directions (volatile topics drop what is
        sent before)."""
        deadline = time.monotonic() + DEADLINE
        for channel, body in (("query", {"goal": "true"}), ("control", {"op": "list"})):
            tokens = []
            while not any(t in self.replies for t in tokens):
                assert time.monotonic() < deadline, "the bridge never answered"
                token = f"hello{next(self.tokens)}"
                tokens.append(token)
                self.publish(self.topics[channel], json.dumps({"token": token, **body}))
                retry = time.monotonic() + 0.25
                while time.monotonic() < retry and not any(t in self.replies for t in tokens):
                    try:
                        self._take(retry)
                    except AssertionError:
                        if self.popen.poll() is not None:
                            raise
            for t in tokens:
                self.replies.pop(t, None)

    def report(self, command: dict, key: str) -> None:
        """Send a waiting command and wait for its report ``{key: topic}``."""
        self.send(command)
        expected = {key: command[key]}
        self.wait(lambda: expected in self.events)
        self.events.remove(expected)

    def matched(self, topic: str, kind: str, count: int = 1) -> None:
        """Wait until our publisher of ``topic`` has ``count`` subscribers (0: none)."""
        self.report({"matched": topic, "type": kind, "count": count}, "matched")


def write_map(path: Path, prefix: str) -> Path:
    path.write_text(textwrap.dedent(f"""
        tf: false
        topics:
          {prefix}/battery:
            event: battery
            args: [data]
        fully_updated:
          - topic: {prefix}/done
            types: [battery/1]
        requests:
          query: {prefix}/query
          answer: {prefix}/answer
          control: {prefix}/control
          control_reply: {prefix}/control_reply
          max_query_time: 5
    """))
    return path


class Setup:
    """The store, the bridge process and the client process of this module."""

    def __init__(self, tmp: Path, env: dict, prefix: str):
        self.tmp, self.env, self.prefix = tmp, env, prefix
        self.db = tmp / "requests.db"
        self.map = write_map(tmp / "requests.yaml", prefix)
        self.topics = {k: f"{prefix}/{k}" for k in ("query", "answer", "control",
                                                    "control_reply")}
        with slr_sql.open(self.db) as kb:
            kb.load('obj(cup1, cup, red)^2.0. obj(box, box, "blue")^3.5. '
                    'obj(pt, point, p(1, [2.5, x]))^4. size(cup1, 10000000000000000000000).',
                    name="world")
        self.bridge = None
        self.start_bridge()
        self.client = Client(env, self.topics)
        self.client.handshake()

    def start_bridge(self) -> None:
        self.bridge = Process([sys.executable, "-m", "slr_sql", "ros", "bridge", str(self.db),
                               "--map", str(self.map), "--node-name", NODE], self.env)
        self.bridge.wait_for("bridge ready", time.monotonic() + DEADLINE)

    def restart_bridge(self) -> list[str]:
        status = self.bridge.stop(signal.SIGTERM)
        assert status == 0, "".join(self.bridge.stderr)
        self.bridge.wait_for("bridge stopped", time.monotonic() + DEADLINE)
        old = self.bridge.seen
        self.start_bridge()
        self.client.handshake()
        return old

    def store(self):
        return slr_sql.open(self.db)

    def close(self) -> None:
        if self.client is not None:
            self.client.send({"exit": True})
            self.client.stop()
        if self.bridge is not None:
            self.bridge.stop()


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    env = dict(os.environ)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env["ROS_DOMAIN_ID"] = str(random.SystemRandom().randint(1, 200))
    env.pop("ROS_LOCALHOST_ONLY", None)
    prefix = f"/r{random.SystemRandom().randrange(16 ** 6):06x}"
    s = Setup(tmp_path_factory.mktemp("ros_requests"), env, prefix)
    try:
        yield s
    finally:
        s.close()
    assert "Traceback" not in "".join(s.bridge.stderr), "".join(s.bridge.stderr)


def _local(setup: Setup, goal: str, **kwargs) -> list:
    with setup.store() as kb:
        return encode_answers(kb.query(goal, **kwargs))


# -- queries -----------------------------------------------------------------------------------

@pytest.mark.parametrize("request_body, local", [
    ({"goal": "obj(O, cup, C)^T"}, {}),
    ({"goal": "obj(O, K, C)^T", "at": 3.5}, {"at": 3.5}),
    ({"goal": "obj(O, K, C)^T", "limit": 1}, {"limit": 1}),
    ({"goal": "obj(O, K, C)^T", "args": {"O": "pt"}}, {"args": {"O": slr_sql.Atom("pt")}}),
    ({"goal": "size(O, N), M is N * 2.0, X = Y"}, {}),
    ({"goal": "obj(nothing, _, _)^_"}, {}),
], ids=["plain", "at", "limit", "args", "big-int-float-vars", "no-answer"])
def test_query_answers_as_the_network_service_encodes_them(setup, request_body, local):
    reply = setup.client.query(**request_body)
    assert reply["_topic"] == setup.topics["answer"]
    assert "error" not in reply, reply
    goal = request_body["goal"]
    assert reply["answers"] == _local(setup, goal, **local)
    assert set(reply) == {"token", "answers", "_topic"}


def test_synchronized_query_answers_when_complete_without_blocking_others(setup):
    client, prefix = setup.client, setup.prefix
    z = time.time() + 10_000.0   # in the future: only the mark on /done completes battery/1 there
    goal = "findall(V, battery(V)^_, L)"
    client.publish(setup.topics["query"], json.dumps(
        {"token": "sync1", "goal": goal, "at": z, "wait": True, "timeout": 25}))
    # The node keeps answering while the synchronized query waits.
    quick = client.query(goal=goal)
    assert quick["answers"] == [{"L": []}]
    assert "sync1" not in client.replies
    client.matched(f"{prefix}/battery", "Float64")
    client.publish(f"{prefix}/battery", 3.5, "Float64")
    deadline = time.monotonic() + DEADLINE
    while _local(setup, goal) != [{"L": [3.5]}]:
        assert time.monotonic() < deadline, "battery(3.5) was not stored"
        time.sleep(0.02)   # polling the store file; the deadline bounds the wait
    assert "sync1" not in client.replies  # still incomplete at z
    client.matched(f"{prefix}/done", "Header")
    client.publish(f"{prefix}/done", z, "Header")
    client.wait(lambda: "sync1" in client.replies)
    reply = client.replies.pop("sync1")
    assert reply["answers"] == [{"L": [3.5]}]


@pytest.mark.parametrize("at", [time.time() + 20_000.0, 1e12, 1e12],
                         ids=["near", "far", "far-again"])
def test_synchronized_query_times_out_with_an_error_reply(setup, at):
    # 1e12 s is beyond the platform's time_t for a timer wait: twice, so the second one
    # shows the knowledge base's timer still runs after the first
    reply = setup.client.query(goal="battery(V)^T", at=at, wait=True, timeout=0.2)
    assert reply["error"]["kind"] == "SLRTimeout" and reply["error"]["status"] == 408
    assert "answers" not in reply


def test_a_far_synchronized_query_leaves_the_timer_running():
    with slr_sql.open() as kb:
        for _ in range(2):
            with pytest.raises(slr_sql.SLRTimeout):
                kb.submit("far(V)^T", at=1e12, timeout=0.05).result(timeout=DEADLINE)


# -- bad requests ------------------------------------------------------------------------------

QUERY_ERRORS = [
    ("not json {", None, "BadRequest", "not valid JSON"),
    ('["a", "list"]', None, "BadRequest", "a request is a JSON object"),
    ('{"goal": "true"}', None, "BadRequest", '"token" is required'),
    ('{"token": true, "goal": "true"}', None, "BadRequest", '"token" must be'),
    ('{"token": "e1"}', "e1", "BadRequest", '"goal" is required'),
    ('{"token": "e2", "gaol": "true"}', "e2", "BadRequest", "unknown key 'gaol'"),
    ('{"token": "e3", "goal": "p(X"}', "e3", "SLRSyntaxError", ""),
    ('{"token": "e4", "goal": "nosuch(X)"}', "e4", "SLREvaluationError", "nosuch/1"),
    ('{"token": "e5", "goal": "p(X)", "args": {"X": null}}', "e5", "BadRequest", "not a term"),
    ('{"token": 6, "goal": "true", "wait": "yes"}', 6, "BadRequest", '"wait" must be'),
    ('{"token": "e7", "op": "subscribe", "goal": "true"}', "e7", "BadRequest",
     "unknown request kind 'subscribe' on the query topic"),
    ('{"token": "e8", "goal": "X is 1/0"}', "e8", "SLREvaluationError", ""),
    ('{"token": "e9", "goal": "true", "at": {"$float": "zz"}}', "e9", "BadRequest", "$float"),
]


@pytest.mark.parametrize("text, token, kind, words", QUERY_ERRORS,
                         ids=[f"q{i}" for i in range(len(QUERY_ERRORS))])
def test_bad_query_requests_get_an_error_reply_with_their_token(setup, text, token, kind, words):
    reply = setup.client.request("query", text, token=token)
    assert reply["token"] == token
    assert reply["error"]["kind"] == kind, reply
    assert words in reply["error"]["message"]
    if kind == "SLRSyntaxError":
        assert (reply["error"]["line"], reply["error"]["column"]) == (1, 4)
    assert setup.bridge.popen.poll() is None


CONTROL_ERRORS = [
    ('{"token": "c1"}', "c1", "BadRequest", '"op" is required'),
    ('{"token": "c2", "op": "explode"}', "c2", "BadRequest", "unknown request kind 'explode'"),
    ('{"token": "c3", "op": "list", "extra": 1}', "c3", "BadRequest", "unknown key 'extra'"),
    ('{"op": "list"}', None, "BadRequest", '"token" is required'),
    ('{"token": "c4", "op": "remove_input", "topic": "/nowhere"}', "c4", "NotFound",
     "no input topic /nowhere"),
    ('{"token": "c5", "op": "unsubscribe", "id": "nobody"}', "c5", "NotFound",
     "no subscription 'nobody'"),
    ('{"token": "c6", "op": "remove_buffer", "id": 999}', "c6", "NotFound", "no active buffer #999"),
    ('{"token": "c7", "op": "add_input", "topic": "/x", "mapping": {"evnt": "x"}}', "c7",
     "MappingError", "mapping.evnt: unknown key"),
    ('{"token": "c8", "op": "add_input", "topic": "PREFIX/query", "mapping": {"event": "q"}}',
     "c8", "BadRequest", "is a topic of the request protocol"),
    ('{"token": "c9", "op": "add_input", "topic": "PREFIX/battery", "mapping": {"event": "b"}}',
     "c9", "BadRequest", "is mapped by the MAP file"),
    ('{"token": "c10", "op": "add_buffer", "pattern": "p(X", "keep_last": 1}', "c10",
     "SLRSyntaxError", ""),
    ('{"token": "c11", "op": "add_buffer", "pattern": "p(_)"}', "c11", "SLRError",
     "exactly one of"),
    ('{"token": "c12", "op": "add_memory", "pattern": "p(_)", "keep_last": 1.5}', "c12",
     "BadRequest", '"keep_last" must be an integer'),
    ('{"token": "c13", "op": "subscribe", "topic": "/out", "type": "no_msgs/msg/Nope", '
     '"pattern": "p(X)^T"}', "c13", None, ""),
    ('{"token": "c14", "op": "subscribe", "topic": "PREFIX/battery", '
     '"type": "std_msgs/msg/String", "pattern": "p(X)^T", "fields": {"data": "X"}}', "c14",
     "BadRequest", "is an input topic"),
]


@pytest.mark.parametrize("text, token, kind, words", CONTROL_ERRORS,
                         ids=[f"c{i}" for i in range(len(CONTROL_ERRORS))])
def test_bad_control_requests_get_an_error_reply_with_their_token(setup, text, token, kind,
                                                                  words):
    reply = setup.client.request("control", text.replace("PREFIX", setup.prefix), token=token)
    assert reply["_topic"] == setup.topics["control_reply"]
    assert reply["token"] == token and "ok" not in reply
    if kind is None:   # a subscription of a type without a Python module
        kind, words = "BridgeError", "no Python module for no_msgs/msg/Nope"
    assert reply["error"]["kind"] == kind, reply
    assert words in reply["error"]["message"]
    assert setup.bridge.popen.poll() is None


def test_the_node_still_answers_after_bad_requests(setup):
    for text in ("\x00\x01", "{" * 5000, json.dumps({"token": "x" * 10, "goal": "p(" * 3000})):
        setup.client.request("query", text, token=None if text[0] != "{" or "token" not in text
                             else "x" * 10)
    assert setup.client.query(goal="X = 1")["answers"] == [{"X": 1}]


# -- control -----------------------------------------------------------------------------------

def _stored_control(setup: Setup) -> list[tuple]:
    with setup.store() as kb:
        if program_name(NODE) not in kb.programs():
            return []
        return [(str(a["K"]), str(a["Key"]), json.loads(a["S"]))
                for a in kb.query("slr_ros_control(N, K, Key, S)", args={"N": slr_sql.Atom(NODE)})]


def test_history_policies_from_ros(setup):
    client = setup.client
    ids = [client.control("add_buffer", pattern="hist_a(_)", keep_last=2),
           client.control("add_memory", pattern="hist_b(_)", keep_seconds=30),
           client.control("add_buffer", pattern="hist_c(_)", keep_between=[1.0, 2.5])]
    assert all(r["ok"] for r in ids), ids
    with setup.store() as kb:
        buffers = {b.id: b for b in kb.buffers()}
    got = [(buffers[r["id"]].kind, buffers[r["id"]].pattern) for r in ids]
    assert got == [("cBuffer", "hist_a(_)"), ("tBuffer", "hist_b(_)"), ("window", "hist_c(_)")]
    assert buffers[ids[0]["id"]].amount == 2 and buffers[ids[2]["id"]].keep_between == (1.0, 2.5)
    listed = client.control("list")["buffers"]
    assert {b["id"] for b in listed} >= {r["id"] for r in ids}
    removed = client.control("delete_memory", id=ids[1]["id"])
    assert removed == {"token": removed["token"], "op": "delete_memory", "ok": True,
                       "removed": ids[1]["id"], "_topic": setup.topics["control_reply"]}
    with setup.store() as kb:
        assert ids[1]["id"] not in {b.id for b in kb.buffers()}
    conflict = client.control("add_buffer", pattern="hist_a(X)", keep_last=5)
    assert conflict["error"]["kind"] == "SLRError"
    assert "conflicting buffers" in conflict["error"]["message"]


def test_input_topics_added_and_removed_from_ros(setup):
    client, prefix = setup.client, setup.prefix
    topic = f"{prefix}/speed"
    client.send({"advertise": topic, "type": "Float64"})
    reply = client.control("add_input", topic=topic, mapping={"event": "speed", "args": ["data"]})
    assert reply["ok"] and reply["events"] == ["speed"], reply
    assert ("input", topic, {"topic": topic, "mapping": {"event": "speed", "args": ["data"]}}) \
        in _stored_control(setup)
    client.matched(topic, "Float64")           # the bridge subscribed
    client.publish(topic, 1.5, "Float64")
    deadline = time.monotonic() + DEADLINE
    while _local(setup, "speed(V)^_") != [{"V": 1.5}]:
        assert time.monotonic() < deadline, "speed(1.5) was not stored"
        time.sleep(0.02)   # polling the store file
    # the same mapping again is a replacement, not a second subscription
    again = client.control("add_input_subscription", topic=topic,
                           mapping=[{"event": "speed", "args": ["data"]},
                                    {"event": "speed_seen", "args": []}])
    assert again["events"] == ["speed", "speed_seen"]
    inputs = client.control("list")["inputs"]
    assert [i["topic"] for i in inputs].count(topic) == 1
    wrong = client.control("add_input", topic=topic, mapping={"event": "speed", "args": ["dta"]})
    assert wrong["error"]["kind"] == "MappingError" and "no field 'dta'" in wrong["error"]["message"]
    removed = client.control("remove_input", topic=topic)
    assert removed["removed"] == topic
    client.matched(topic, "Float64", count=0)  # the bridge no longer listens
    assert all(key != topic for _, key, _ in _stored_control(setup))


def test_output_subscriptions_from_ros(setup):
    client, prefix = setup.client, setup.prefix
    source, out = f"{prefix}/door_in", f"{prefix}/alarms"
    subscribe = {"id": "alarms", "topic": out, "type": "std_msgs/msg/String",
                 "pattern": "alarm(D)^T", "where": "D \\= door0", "fields": {"data": "D"}}
    client.send({"listen": out})
    client.send({"advertise": source, "type": "String"})
    assert client.control("add_input", topic=source,
                          mapping={"event": "alarm", "args": ["data"]})["ok"]
    reply = client.control("add_output_subscription", **subscribe)
    assert reply["ok"] and reply["id"] == "alarms", reply
    client.report({"publishers": out, "count": 1}, "publishers")  # the bridge publishes
    client.matched(source, "String")
    for door in ("door0", "door3"):
        client.publish(source, door)
    client.wait(lambda: (out, "door3") in client.received)
    assert (out, "door0") not in client.received
    assert ("subscription", "alarms", subscribe) in _stored_control(setup)
    assert client.control("unsubscribe", id="alarms")["removed"] == "alarms"
    assert all(key != "alarms" for _, key, _ in _stored_control(setup))
    assert client.control("remove_input", topic=source)["ok"]


def test_a_restarted_bridge_resumes_the_control_state(setup):
    client, prefix = setup.client, setup.prefix
    topic = f"{prefix}/level"
    client.send({"advertise": topic, "type": "Float64"})
    assert client.control("add_input", topic=topic,
                          mapping={"event": "level", "args": ["data"], "time": "receive"})["ok"]
    buffer_id = client.control("add_buffer", pattern="level(_)", keep_last=3)["id"]
    subscribed = client.control("subscribe", id="levels", topic=f"{prefix}/levels",
                                type="std_msgs/msg/String", pattern="level(V)^T",
                                fields={"data": "V"})
    assert subscribed["ok"], subscribed
    client.send({"listen": f"{prefix}/levels"})
    before = client.control("list")
    old_lines = setup.restart_bridge()
    assert any("bridge stopped" in line for line in old_lines)
    assert f"resumed input {topic}" in setup.bridge.seen
    after = client.control("list")
    assert [i["topic"] for i in after["inputs"]] == [i["topic"] for i in before["inputs"]]
    assert [i["mapping"] for i in after["inputs"]] == [i["mapping"] for i in before["inputs"]]
    assert [s["id"] for s in after["subscriptions"]] == [s["id"] for s in before["subscriptions"]]
    assert buffer_id in {b["id"] for b in after["buffers"]}
    client.matched(topic, "Float64")          # the new bridge subscribed again
    for value in (1.0, 2.0, 3.0, 4.0):
        client.publish(topic, value, "Float64")
    deadline = time.monotonic() + DEADLINE
    while _local(setup, "findall(V, level(V)^_, L)") != [{"L": [2.0, 3.0, 4.0]}]:
        assert time.monotonic() < deadline, _local(setup, "findall(V, level(V)^_, L)")
        time.sleep(0.02)   # polling the store file: the resumed buffer keeps the last 3
    client.wait(lambda: (f"{prefix}/levels", "4.0") in client.received)


# -- the protocol without ROS ------------------------------------------------------------------

def test_requests_section_of_the_map():
    m = mapping_from_dict({"requests": {"query": "q", "answer": "/a", "max_wait": 5}})
    assert m.requests.topics() == ("/q", "/a", "/slr/control", "/slr/control_reply")
    assert mapping_from_dict({}).requests.topics() == (
        "/slr/query", "/slr/answer", "/slr/control", "/slr/control_reply")
    assert not mapping_from_dict({"requests": False}).requests.enabled
    with pytest.raises(slr_sql.SLRError, match="requests.qury: unknown key"):
        mapping_from_dict({"requests": {"qury": "/q"}})
    with pytest.raises(slr_sql.SLRError, match="must differ"):
        mapping_from_dict({"requests": {"query": "/slr/answer"}})
    with pytest.raises(slr_sql.SLRError, match="is a topic of the request protocol"):
        mapping_from_dict({"topics": {"/slr/control": {"event": "c"}}})


@pytest.mark.parametrize("seconds", [10 ** 400, float("inf"), 0, -1, True, "5"])
def test_a_request_limit_that_is_no_positive_number_of_seconds_is_refused(seconds):
    """An integer beyond any float raised OverflowError out of math.isfinite."""
    with pytest.raises(slr_sql.SLRError, match="requests.max_wait: expects a positive number"):
        mapping_from_dict({"requests": {"max_wait": seconds}})


@pytest.mark.parametrize("body", [
    {"token": "a", "goal": "p(X)"},
    {"token": 7, "goal": "p(X)", "at": 1, "wait": True, "timeout": {"$float": "inf"}},
    {"token": "b", "goal": "q(X, Y)", "args": {"X": {"f": ["a", {"$string": "s"}, 1.0]}},
     "limit": 3},
])
def test_query_requests_read_back(body):
    token, read = read_request(json.dumps(body))
    request = parse_query(read)
    assert token == body["token"] and request.goal == body["goal"]
    assert request.wait == body.get("wait", False) and request.limit == body.get("limit")
    if "args" in body:
        assert encode_answers([request.args]) == [body["args"]]
    with pytest.raises(ServiceError):
        parse_query({**read, "limit": 0})


JSON = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False, allow_infinity=False)
    | st.text(),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(), inner, max_size=4),
    max_leaves=12)


@settings(max_examples=40, deadline=None)
@given(topic=st.text(min_size=1, max_size=20), mapping=JSON,
       sub_id=st.text(min_size=1, max_size=20), node=st.text(min_size=1, max_size=12))
def test_the_stored_control_state_reads_back(topic, mapping, sub_id, node):
    """What _persist writes as facts of the named program reads back as the same JSON,
    whatever the characters in topics, ids, node names and mappings."""
    from slr_sql.ros.bridge import Bridge
    from slr_sql.ros.control import Controller, _Input, _Output, _placeholder
    from slr_sql.ros.mapping import Mapping

    with slr_sql.open() as kb:
        controller = Controller(Bridge(kb, Mapping()), node)
        topic = "/" + topic
        controller.inputs[topic] = _Input(topic, {"topic": topic, "mapping": mapping})
        spec = {"id": sub_id, "pattern": "p(X)^T", "extra": mapping}
        controller.outputs[sub_id] = _Output(sub_id, spec, _placeholder(spec))
        controller._persist()
        stored = {(str(a["K"]), str(a["Key"])): json.loads(a["S"])
                  for a in kb.query("slr_ros_control(N, K, Key, S)", args={"N": slr_sql.Atom(node)})}
        assert stored == {("input", topic): {"topic": topic, "mapping": mapping},
                          ("subscription", sub_id): spec}
        controller.inputs.clear()
        controller.outputs.clear()
        controller._persist()
        assert program_name(node) not in kb.programs()


def test_a_stored_input_the_map_now_maps_is_listed_and_removable():
    """A stored input topic that cannot be made again (here: the MAP file took the topic
    over) stays stored and listed with its error; removing it leaves the MAP's mapping."""
    from slr_sql.ros.bridge import Bridge
    from slr_sql.ros.control import Controller

    with slr_sql.open() as kb:
        first = Controller(Bridge(kb, mapping_from_dict({})), "n1")
        made = first.handle("add_input", {"op": "add_input", "topic": "/odom",
                                          "mapping": {"event": "odom", "args": ["data"]}})
        assert made["events"] == ["odom"]
        taken = mapping_from_dict({"topics": {"/odom": {"event": "odometry"}}})
        second = Controller(Bridge(kb, taken), "n1")
        (line,) = second.resume()
        assert line.startswith("input /odom not resumed") and "MAP file" in line
        listed = second.handle("list", {"op": "list"})["inputs"]
        assert [(i["topic"], "MAP file" in i["error"]) for i in listed] == [("/odom", True)]
        assert second.handle("remove_input", {"op": "remove_input", "topic": "/odom"}) == \
            {"removed": "/odom"}
        assert [e.event for e in taken.topics["/odom"]] == ["odometry"]
        assert program_name("n1") not in kb.programs()
        assert Controller(Bridge(kb, taken), "n1").resume() == []
