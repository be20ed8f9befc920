"""The bridge's request protocol (docs/ros.md, "Requests") answers a condition that may
pass -- too many queries in flight, the bridge stopping, the store busy -- with the error
object of the network service's 503: the SLRUnavailable class the client raises for it
(``ServiceUnavailable``, kind ``Unavailable``; ``SLRBusy``), status 503. A topic reply has no
headers: the wait is the class's ``retry_after``.

A real bridge node and request server in this process, and a real rclpy node of the test
subscribed to the answer topic (loopback discovery on a random domain, as
tests/test_ros_bridge.py sets up)."""
from __future__ import annotations

import json
import sqlite3

import pytest

import slr_sql
from slr_sql import SLRBusy
from slr_sql.ros.bridge import Bridge
from slr_sql.ros.mapping import Mapping, RequestTopics
from slr_sql.ros.requests import RequestServer
from slr_sql.service.errors import ServiceUnavailable, error_from_body
import test_ros_bridge
from bridge_helpers import spinner

ros_env, prefix, ros_node = test_ros_bridge.ros_env, test_ros_bridge.prefix, test_ros_bridge.ros_node
DEADLINE = test_ros_bridge.DEADLINE


@pytest.fixture
def requests(tmp_path, ros_node, prefix):
    """``start(**options)``: a request server on a started bridge, its answers collected in
    ``replies`` by the test's node; ``spin_until(condition)``."""
    from std_msgs.msg import String

    node, executor = ros_node
    topics = RequestTopics(query=f"{prefix}/query", answer=f"{prefix}/answer",
                           control=f"{prefix}/control", control_reply=f"{prefix}/reply")
    replies: list[dict] = []
    node.create_subscription(String, topics.answer, lambda m: replies.append(json.loads(m.data)),
                             100)
    lines: list[str] = []
    kb = slr_sql.open(tmp_path / "requests.db", clock=slr_sql.ManualClock(0))
    bridge = Bridge(kb, Mapping(tf=False), node_name="test_requests_bridge",
                    log=lines.append).start()
    servers: list[RequestServer] = []
    spin_until = spinner(bridge, executor, lambda: f"replies {replies}, log {lines}")

    def start(**options) -> RequestServer:
        server = RequestServer(bridge, topics, **options).start()
        servers.append(server)
        spin_until(lambda: server._answer.get_subscription_count() > 0)
        return server

    class Requests:
        pass
    r = Requests()
    r.start, r.spin_until, r.replies, r.kb = start, spin_until, replies, kb
    try:
        yield r
    finally:
        for server in servers:
            server.close()
        bridge.close()
        kb.close()


def _unavailable(reply: dict, token, cls: type, words: str) -> None:
    assert reply["token"] == token and reply["error"]["status"] == 503, reply
    assert words in reply["error"]["message"], reply
    exc = error_from_body(reply, 503)          # what the service's client makes of it
    assert type(exc) is cls and exc.retry_after == 1, repr(exc)


def test_a_query_beyond_the_queries_in_flight_is_unavailable(requests):
    server = requests.start(max_in_flight=0)
    server.handle_query('{"token": 1, "goal": "X = 1"}')
    requests.spin_until(lambda: requests.replies)
    _unavailable(requests.replies[0], 1, ServiceUnavailable, "being answered already")
    assert requests.replies[0]["error"]["kind"] == "Unavailable"


def test_a_query_to_a_stopping_bridge_is_unavailable(requests):
    server = requests.start()
    server._pool.shutdown(wait=True)           # what close() does first
    server.handle_query('{"token": 2, "goal": "X = 1"}')
    requests.spin_until(lambda: requests.replies)
    _unavailable(requests.replies[0], 2, ServiceUnavailable, "the bridge is stopping")


def test_a_synchronized_query_cancelled_by_the_stopping_bridge_is_unavailable(requests):
    server = requests.start()
    server.handle_query('{"token": 3, "goal": "p(X)^T", "at": 100, "wait": true}')
    requests.spin_until(lambda: server._pending)
    for pending in list(server._pending):      # what close() does to the waiting ones
        pending.cancel()
    requests.spin_until(lambda: requests.replies)
    _unavailable(requests.replies[0], 3, ServiceUnavailable,
                 "the query was cancelled: the bridge is stopping")


def test_a_raw_sqlite_lock_error_is_answered_as_slr_busy(requests, tmp_path):
    """(The store turns its own lock waits into SLRBusy; a SQLite error no layer turned into
    an SLRError is answered as the same class.)"""
    server = requests.start()
    db = str(tmp_path / "locked.db")
    holder = sqlite3.connect(db, isolation_level=None)
    other = sqlite3.connect(db, isolation_level=None, timeout=0)
    try:
        holder.execute("BEGIN IMMEDIATE")
        with pytest.raises(sqlite3.OperationalError) as caught:
            other.execute("BEGIN IMMEDIATE")
    finally:
        other.close()
        holder.close()
    reply = server._error(4, caught.value)
    _unavailable(reply, 4, SLRBusy, "the store is busy: database is locked")
    assert reply["error"]["kind"] == "SLRBusy"
