"""Queries and control of the store over ROS topics, on the bridge's node (docs/ros.md,
"Requests").

:class:`RequestServer` adds four endpoints to a started :class:`~slr_sql.ros.bridge.Bridge`
(names from the MAP's ``requests:`` section, :class:`~slr_sql.ros.mapping.RequestTopics`):

* the **query** topic (``std_msgs/String``, JSON ``{"token", "goal", "at", "args", "wait",
  "timeout", "limit"}``) and the **answer** topic (``{"token", "answers"}`` or ``{"token",
  "error"}``, in the network service's JSON encoding);
* the **control** topic and its **reply** topic (:mod:`slr_sql.ros.control`).

The executor thread never waits for a query: it parses the request and hands it to a small
thread pool; a synchronized query (``"wait": true``) is a ``kb.submit`` whose future answers
by a done-callback when the histories it reads are complete, so any number of them wait
without holding a thread. Control requests are short and run on the executor thread, which
owns the node's subscriptions and publishers. Every failure becomes an error reply with the
request's token (``null`` when none could be read); nothing a client sends stops the node.

No ROS 2 *service* is offered: the message packages the ROS 2 wheels install have no service
type whose request and response are one string each (``std_srvs`` has none either), and a
message package without a wheel is not an option; the topic protocol is the same payload.

A server that is not started publishes nothing, but still returns control replies:

>>> import slr_sql
>>> from slr_sql.ros.bridge import Bridge
>>> from slr_sql.ros.mapping import Mapping
>>> server = RequestServer(Bridge(slr_sql.open(), Mapping()))
>>> server.handle_control('{"token": 1, "op": "add_buffer", "pattern": "p(_)", "keep_last": 2}')
{'token': 1, 'op': 'add_buffer', 'ok': True, 'id': 1}
"""
from __future__ import annotations

import threading
import traceback
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Callable

from slr_sql import SLRError
from slr_sql.service.errors import ServiceUnavailable, store_condition

from .control import Controller
from .mapping import RequestTopics
from .protocol import (ServiceError, answers_reply, dumps_reply, error_reply, parse_query,
                       read_request)

__all__ = ["RequestServer", "QUEUE_DEPTH"]

QUEUE_DEPTH = 100        # messages kept per request/reply topic (reliable QoS)
WORKERS = 4              # threads answering unsynchronized queries
MAX_IN_FLIGHT = 10_000   # queries accepted and not yet answered (beyond: Unavailable)


class RequestServer:
    """The request protocol on ``bridge``'s node. ``start()`` after ``bridge.start()``;
    ``close()`` before ``bridge.close()``.

    ``handle_query(text)`` and ``handle_control(text)`` are what the topic callbacks call;
    tests and embedding programs may call them directly (replies still go to the topics).
    """

    def __init__(self, bridge: Any, topics: RequestTopics | None = None,
                 node_name: str | None = None, log: Callable[[str], None] | None = None,
                 workers: int = WORKERS, max_in_flight: int = MAX_IN_FLIGHT):
        self.bridge = bridge
        self.kb = bridge.kb
        self.topics = topics or RequestTopics()
        self.log = log or bridge.log
        self.controller = Controller(bridge, node_name or bridge.node_name, log=self.log)
        self.resumed: list[str] = []
        self._workers = workers
        self._max_in_flight = max_in_flight
        self._in_flight = 0
        self._lock = threading.Lock()           # the in-flight count and the pending set
        self._publish_lock = threading.Lock()   # publishers are used from several threads
        self._pending: set = set()
        self._pool: ThreadPoolExecutor | None = None
        self._answer = self._reply = None
        self._handles: list = []
        self.closed = False

    def start(self) -> "RequestServer":
        """Create the four endpoints and resume the stored control state."""
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
        from std_msgs.msg import String

        node = self.bridge.node
        if node is None:
            raise SLRError("RequestServer.start(): start the bridge first")
        topics = self.topics
        self.bridge.reserved_topics.update(topics.topics())
        for topic in topics.topics():  # stored as events before (all_topics)? not any more
            if topic in self.bridge.stats.subscribed:
                self.bridge.remap_topic(topic, None)
        qos = QoSProfile(depth=QUEUE_DEPTH, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)
        self._string = String
        self._pool = ThreadPoolExecutor(max_workers=self._workers,
                                        thread_name_prefix="slr-ros-query")
        self._answer = node.create_publisher(String, topics.answer, qos)
        self._reply = node.create_publisher(String, topics.control_reply, qos)
        self._handles = [
            node.create_subscription(String, topics.query,
                                     lambda msg: self.handle_query(msg.data), qos),
            node.create_subscription(String, topics.control,
                                     lambda msg: self.handle_control(msg.data), qos)]
        self.resumed = self.controller.resume()
        return self

    # -- queries ----------------------------------------------------------------------------
    def handle_query(self, text: str) -> None:
        """Take one query request; its answer is published later, on the answer topic."""
        token = None
        try:
            token, body = read_request(text)
            request = parse_query(body)
            with self._lock:
                if self._in_flight >= self._max_in_flight:
                    raise ServiceUnavailable(f"{self._max_in_flight} queries are being "
                                             f"answered already; try again later")
                self._in_flight += 1
            try:
                self._pool.submit(self._run, token, request)
            except RuntimeError:  # the pool is shut down: the bridge is stopping
                self._done()
                raise ServiceUnavailable("the bridge is stopping") from None
        except Exception as exc:  # noqa: BLE001 - every failure is a reply, never a crash
            self._publish(self._answer, self._error(getattr(exc, "token", token), exc))

    def _run(self, token: Any, request: Any) -> None:
        """On a pool thread: answer an unsynchronized query, or submit a synchronized one."""
        try:
            if request.wait:
                pending = self.kb.submit(request.goal, at=request.at, args=request.args,
                                         timeout=_cap(request.timeout, self.topics.max_wait))
                with self._lock:
                    self._pending.add(pending)
                pending.add_done_callback(lambda p: self._finish(token, p))
                return
            answers = self.kb.query(request.goal, at=request.at, args=request.args,
                                    timeout=_cap(request.timeout, self.topics.max_query_time),
                                    limit=request.limit)
            reply = self._answers(token, answers)
        except Exception as exc:  # noqa: BLE001
            reply = self._error(token, exc)
        self._done()
        self._publish(self._answer, reply)

    def _finish(self, token: Any, pending: Any) -> None:
        """The done-callback of a synchronized query (on whichever thread completed it)."""
        with self._lock:
            self._pending.discard(pending)
        if pending.cancelled():
            reply = self._error(token, ServiceUnavailable("the query was cancelled: the "
                                                          "bridge is stopping"))
        else:
            exc = pending.exception()
            reply = self._error(token, exc) if exc is not None \
                else self._answers(token, pending.result())
        self._done()
        self._publish(self._answer, reply)

    def _answers(self, token: Any, answers: list) -> dict:
        try:
            return answers_reply(token, answers)
        except Exception as exc:  # noqa: BLE001 - an answer the encoding cannot carry
            return self._error(token, exc)

    def _done(self) -> None:
        with self._lock:
            self._in_flight -= 1

    # -- control ----------------------------------------------------------------------------
    def handle_control(self, text: str) -> dict:
        """Run one control request (on the executor thread) and publish its reply; returns
        the reply."""
        token = op = None
        try:
            token, body = read_request(text)
            op = body.get("op")
            reply = {"token": token, "op": op, "ok": True, **self.controller.handle(op, body)}
        except Exception as exc:  # noqa: BLE001 - every failure is a reply, never a crash
            reply = self._error(getattr(exc, "token", token), exc, op=op)
        self._publish(self._reply, reply)
        return reply

    # -- replies ----------------------------------------------------------------------------
    def _error(self, token: Any, exc: BaseException, **extra: Any) -> dict:
        if not isinstance(exc, SLRError):
            if isinstance(exc, (TypeError, ValueError, UnicodeError, OverflowError,
                                RecursionError, ArithmeticError)):
                reason = "too deeply nested" if isinstance(exc, RecursionError) else str(exc)
                exc = ServiceError(f"bad request: {reason}")
            elif (condition := store_condition(exc)) is not None:
                exc = condition
            else:  # a bug: say so in the reply, keep the traceback in the log
                self.log("error: request failed:\n" + "".join(
                    traceback.format_exception(type(exc), exc, exc.__traceback__)))
        return error_reply(token, exc, **extra)

    def _publish(self, publisher: Any, reply: dict) -> None:
        if self.closed or publisher is None:
            return
        try:
            text = dumps_reply(reply)
        except Exception as exc:  # noqa: BLE001 - a reply that is not JSON: say why instead
            text = dumps_reply(self._error(reply.get("token"), exc))
        try:
            with self._publish_lock:
                publisher.publish(self._string(data=text))
        except Exception as exc:  # noqa: BLE001 - the node is going down
            if not self.closed:
                self.log(f"warning: reply not published: {type(exc).__name__}: {exc}")

    def close(self) -> None:
        """Stop taking requests: close the runtime subscriptions, cancel waiting queries and
        stop the pool (queries running finish in the background). Idempotent."""
        if self.closed:
            return
        self.controller.close()
        with self._lock:
            pending, self._pending = list(self._pending), set()
        for p in pending:  # their callbacks reply "the bridge is stopping" while we still can
            p.cancel()
        self.closed = True
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)
        node = self.bridge.node
        if node is not None:
            for handle in self._handles:
                node.destroy_subscription(handle)
            for publisher in (self._answer, self._reply):
                if publisher is not None:
                    node.destroy_publisher(publisher)
        self._handles, self._answer, self._reply = [], None, None


def _cap(requested: float | None, limit: float) -> float:
    return limit if requested is None else min(requested, limit)
