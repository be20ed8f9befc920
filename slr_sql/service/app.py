"""The network service: one knowledge base served over HTTP/JSON and WebSocket (starlette).

:func:`create_app` returns a plain Starlette application with explicit routes; it does not own
the knowledge base (whoever opened it closes it), so it can be mounted inside a larger ASGI
application (``Mount("/slr", app=create_app(kb))``). ``slr serve`` runs it on uvicorn
(:mod:`slr_sql.service.cli`). The endpoints, the JSON encoding of terms and the errors are
described in ``docs/service.md``; ``GET /openapi.json`` describes the same routes.

Every knowledge-base call that may block (SQLite, evaluation, a lock) runs in starlette's
thread pool; the KnowledgeBase serializes its store access with a lock and keeps no per-call
state on itself, so calls from several threads are safe. Waiting is never done on a thread:
a long-poll for a synchronized query awaits the query's future on the event loop, and a
subscription is consumed with ``async for`` on the event loop (no thread per subscriber).

>>> import slr_sql
>>> kb = slr_sql.open()
>>> app = create_app(kb, token="secret")
>>> sorted({r.path for r in app.routes})[:3]
['/add', '/add_event', '/add_many']
>>> kb.close()
"""
from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import logging
import math
import re
import time
import uuid
from dataclasses import dataclass
from typing import Any, AsyncIterator, Awaitable, Callable, Iterable

from starlette.applications import Starlette
from starlette.middleware import Middleware
from starlette.concurrency import run_in_threadpool
from starlette.convertors import Convertor, register_url_convertor
from starlette.exceptions import HTTPException
from starlette.requests import ClientDisconnect, Request
from starlette.responses import Response
from starlette.routing import Match, Route, WebSocketRoute
from starlette.types import Receive, Scope, Send
from starlette.websockets import WebSocket, WebSocketDisconnect

import slr_sql
from slr_sql import EventRejected, SLRError, SLRTimeout
from slr_sql.builtins import DiscardedOutput
from slr_sql.errors import log_failure
from slr_sql.printable import log_text
from slr_sql.kb import KnowledgeBase
from slr_sql.store.checks import format_event
from slr_sql.store.read_only import read_only_refusal

from .encoding import (decode_args, decode_arguments, decode_term, dumps, encode_answers,
                       encode_plain, loads)
from .auth import BearerToken, RobotAccess, RobotToken
from .errors import (ServiceError, ServiceForbidden, ServiceUnavailable, error_body, retry_after,
                     store_condition)
from .fanout import FRAMES_EXTENSION, GONE, FanOut, FrameChannel

__all__ = ["create_app", "Limits", "API_VERSION"]

log = logging.getLogger("slr_sql.service")

API_VERSION = "1"


@dataclass
class Limits:
    """What one request may cost the server (``slr serve`` options of the same names)."""

    max_body: int = 1 << 20          # bytes of a request body or WebSocket message (413 beyond)
    max_query_time: float = 30.0     # seconds a query may run (its timeout=, capped)
    max_wait: float = 3600.0         # seconds a synchronized query may wait (submit timeout=)
    max_poll: float = 30.0           # seconds one long-poll GET waits before "not done yet"
    body_timeout: float = 30.0       # seconds to receive a request body (408 beyond)
    result_ttl: float = 600.0        # seconds a finished submitted query's answer is kept
    max_pending: int = 10_000        # submitted queries kept at once (503 beyond)
    # bytes of the answers (as JSON) of finished submitted queries kept at once, until their
    # result_ttl or a DELETE: a new submission is 503 beyond (each kept answer holds its
    # terms in memory, ~10x its JSON: a client repeating a submission of a large answer
    # would otherwise fill the server's memory within result_ttl)
    max_held_answer_bytes: int = 32 << 20
    sql_timeout: float = 30.0        # seconds a read-only SQL statement may run
    subscribe_queue: int = 1000      # answers held in memory per WebSocket subscriber
    max_running_queries: int = 4     # queries and SQL statements evaluated at once (see below)


# -- small helpers -----------------------------------------------------------------------------

def _json(obj: Any, status: int = 200, headers: dict | None = None) -> Response:
    return Response(dumps(obj), status_code=status, media_type="application/json",
                    headers=headers)


# What a client reads of a failure whose words are the server's own (the store's location, a
# file path or a PostgreSQL URL's host and database; the database server's words; a bug's
# text), by its kind: the words go to the server's log under a request id, which the answer
# gives (public_error_body)
_GENERAL_WORDS = {
    "SLRBusy": "the store is busy (another writer held it too long); retry",
    "SLRStoreFull": "the store is full (its disk or size limit); retry once the server has "
                    "space",
    "SLRStoreGone": "the store's file was deleted or replaced while the server had it open",
    "SLRServerUnreachable": "the store's database server is not reachable; retry",
    "SLRCancelled": "the store's database server cancelled the statement; retry",
    "SLRSubscriptionInUse": "the subscription is delivered elsewhere now (open here, or held by "
                            "another process); retry once that one closes",
    "SLRStatementTimeout": "the store's database server cancelled the statement at its "
                           "statement_timeout setting (not the call's timeout=); a retry meets "
                           "it again",
    "SLRUnavailable": "the store cannot answer now, a condition that may pass; retry",
    "InternalError": "internal error",
}


def _said_in_the_log_only(exc: BaseException, status: int) -> bool:
    """Are ``exc``'s words the server's own (see :func:`public_error_body`)? The service's
    own refusals (ServiceError: a full queue of pending queries, a body too large) are
    worded by it for the client and name nothing of the server."""
    if isinstance(exc, ServiceError):
        return False
    return status >= 500 or isinstance(exc, slr_sql.SLRStatementTimeout) or \
        bool(getattr(exc, "store_failure", False))


def public_error_body(exc: BaseException) -> dict:
    """The JSON error body a client is answered with for ``exc``: :func:`error_body`, but an
    answer whose words are the server's own -- a 5xx (the store busy, full or gone, its
    database server unreachable, a bug of the server), a cancel at the database server's
    statement_timeout, a failure of the store itself (its file damaged: a 500 rather than the
    400 of a bad request) -- says its kind in general words and a ``request`` id instead. The
    store's location is not a client's business (any client could read where the server
    keeps its files); the words, with the id, are one line of the server's log (a bug's with
    its traceback), for the operator to find. Another message that starts with the store's
    location (``SLRError.store_location``: a value the store cannot hold) loses that start.

    >>> body = public_error_body(slr_sql.SLRBusy("/srv/robot.db: locked by another writer"))
    >>> body["error"]["status"], body["error"]["kind"], "/srv" in str(body)
    (503, 'SLRBusy', False)
    >>> body["error"]["message"].startswith("the store is busy")
    True
    """
    body = error_body(exc)
    err = body["error"]
    if not _said_in_the_log_only(exc, err["status"]):
        where = getattr(exc, "store_location", None)
        if where and err["message"].startswith(f"{where}: "):
            # (marked where it was raised: a request's own text is never cut here)
            err["message"] = err["message"][len(where) + 2:]
        return body
    if err["status"] < 500 and not isinstance(exc, SLRTimeout):
        err["status"] = 500        # the store failed, not the request
    request_id = uuid.uuid4().hex[:12]
    words = _GENERAL_WORDS.get(err["kind"]) or next(
        (_GENERAL_WORDS[c.__name__] for c in type(exc).__mro__ if c.__name__ in _GENERAL_WORDS),
        "the store failed")
    err["message"] = f"{words} (request {request_id}: the server's log has the details)"
    err["request"] = request_id
    for key in ("line", "column", "source_line", "filename"):
        err.pop(key, None)
    # (a template per status and kind: the log's throttle counts each apart)
    said = f"request %s answered {err['status']}: %s"
    if err["kind"] == "InternalError":
        log.error(said, request_id, log_text(exc), exc_info=exc)
    else:
        log.warning(said, request_id, log_text(exc))
    return body


def _error_response(exc: BaseException) -> Response:
    body = public_error_body(exc)
    status = body["error"]["status"]
    headers = {"WWW-Authenticate": 'Bearer realm="slr"'} if status == 401 else None
    wait = retry_after(exc)
    if wait is not None:  # a condition that may pass: the client keeps its events and retries
        headers = {"Retry-After": str(wait)}
    return _json(body, status, headers)


def _classify(exc: BaseException) -> BaseException:
    """Exceptions that escape the knowledge base without being SLRErrors become the error
    the client sees: input it could not take is the request's fault (400), a locked or busy
    file, or a full disk, the SLRUnavailable class the store raises for it (503 with its
    Retry-After), anything else an internal error (500, logged with its traceback)."""
    if isinstance(exc, SLRError):
        return exc
    condition = store_condition(exc)
    if condition is not None:
        return condition
    if type(exc).__module__ == "sqlite3":
        return exc        # (an internal error: public_error_body logs it)
    if isinstance(exc, (TypeError, ValueError, UnicodeError, OverflowError, RecursionError,
                        ArithmeticError)):
        # (one line, its text escaped and bounded: the input is a client's)
        log.warning("input the knowledge base did not take: %s", log_text(exc))
        reason = "too deeply nested" if isinstance(exc, RecursionError) else str(exc)
        return ServiceError(f"bad request: {reason}", kind="BadRequest")
    return exc            # (an internal error: public_error_body logs it)


def _field(body: dict, name: str, types: type | tuple, *, required: bool = False,
           default: Any = None) -> Any:
    value = body.get(name, default)
    if value is None:
        if required:
            raise ServiceError(f'"{name}" is required', kind="BadRequest")
        return default
    if isinstance(value, bool) and bool not in (types if isinstance(types, tuple) else (types,)):
        raise ServiceError(f'"{name}" must be {_type_words(types)}, not a boolean')
    if not isinstance(value, types):
        raise ServiceError(f'"{name}" must be {_type_words(types)}, not {type(value).__name__}')
    return value


def _type_words(types: type | tuple) -> str:
    names = {str: "a string", int: "an integer", float: "a number", bool: "true or false",
             list: "an array", dict: "an object"}
    types = types if isinstance(types, tuple) else (types,)
    return " or ".join(dict.fromkeys(names.get(t, t.__name__) for t in types))


def _number(body: dict, name: str, *, required: bool = False, minimum: float | None = None) -> Any:
    """A JSON number, or a tagged float (``{"$float": "inf"}``), as float (None if absent)."""
    value = body.get(name)
    if value is None:
        if required:
            raise ServiceError(f'"{name}" is required', kind="BadRequest")
        return None
    if isinstance(value, dict):
        value = decode_term(value, _where=name)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ServiceError(f'"{name}" must be a number', kind="BadRequest")
    try:
        number = float(value)
    except OverflowError:
        raise ServiceError(f'"{name}" is out of range', kind="BadRequest") from None
    if minimum is not None and not number >= minimum:
        raise ServiceError(f'"{name}" must be a number >= {minimum:g}', kind="BadRequest")
    return number


def _query_number(request: Request, name: str) -> float:
    """A non-negative number from the query string (0 when absent)."""
    text = request.query_params.get(name)
    if text is None:
        return 0.0
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not value >= 0:
        raise ServiceError(f'the query parameter "{name}" must be a number >= 0')
    return value


def _cap(requested: float | None, limit: float) -> float:
    return limit if requested is None else min(requested, limit)


def _plain(value: Any) -> Any:
    """Library values (dataclasses, tuples) as plain JSON values."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        value = dataclasses.asdict(value)
    elif isinstance(value, list):
        value = [_plain(v) for v in value]
    elif isinstance(value, dict):
        value = {k: _plain(v) for k, v in value.items()}
    return encode_plain(value)


class _AnswerOnce:
    """ASGI middleware: an answer that can no longer be sent is dropped without a word; and a
    request for a route without parameters goes straight to its endpoint (``direct``: see
    :func:`_direct_routes`).

    When the HTTP server finds a request body malformed (a broken chunked encoding, say), it
    answers 400 itself and closes the connection while the endpoint may be running already
    (an unauthenticated request is refused before its body is read): the endpoint's own
    answer then fails to send (uvicorn's h11 protocol raises). The client has its 400 and
    the server logged its one line; the failed send is not an error of the service, so it
    is dropped (a debug line), and the middleware waits (briefly) until the server has seen
    the connection close, so that it does not report an unfinished response either."""

    def __init__(self, app: Any, direct: dict | None = None,
                 stopping: asyncio.Event | None = None):
        self.app = app
        self.direct = direct or {}
        self.stopping = stopping

    async def __call__(self, scope: dict, receive: Callable, send: Callable) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        failed: list[BaseException] = []
        started: list[bool] = []

        async def send_once(message: Any) -> None:
            if failed:
                return
            if message.get("type") == "http.response.start":
                started.append(True)
            try:
                await send(message)
            except Exception as exc:  # noqa: BLE001 - whatever the server raises: it is gone
                failed.append(exc)
                log.debug("an answer to %s %s could not be sent (%s): the connection is "
                          "closed", scope.get("method"), scope.get("path"), type(exc).__name__)

        endpoint = None if scope.get("root_path") else \
            self.direct.get((scope["method"], scope["path"]))
        try:
            if endpoint is None:
                await self.app(scope, receive, send_once)
            else:
                response = await endpoint(Request(scope, receive, send_once))
                await response(scope, receive, send_once)
        except asyncio.CancelledError:
            if self.stopping is None or not self.stopping.is_set():
                raise
            # the stopping server's grace is over and it cancels what still runs: the
            # client is answered as for any condition that passes (uncaught, uvicorn logs the
            # cancelled request with a traceback); a write it cut is the store's to undo
            log.warning("%s %s was still running when the server stopped; answered 503",
                     log_text(str(scope.get("method"))), log_text(str(scope.get("path"))))
            if not started:
                await _error_response(ServiceUnavailable(
                    "the server stopped before the answer was ready: ask again (another "
                    "server, or this one once it is back)"))(scope, receive, send_once)
            return
        if failed:
            try:
                await asyncio.wait_for(_disconnected(receive), 5.0)
            except (TimeoutError, asyncio.TimeoutError, Exception):  # noqa: BLE001
                pass        # the server closes the connection on its own


def _direct_routes(routes: list) -> dict[tuple[str, str], Callable]:
    """``(method, path)`` -> endpoint, for each route without parameters and each of its
    methods, where starlette's router would pick that route (the first that matches): the
    request can skip the routing and starlette's exception layers (five coroutines, and a
    match against every route before it). Only for the service's own endpoints
    (:meth:`_Service._dispatch`), which turn every Exception into the service's JSON error
    themselves, as those layers would have; a method a route does not take, an unknown path
    or a redirect still go the whole way.

    >>> async def endpoint(request): ...
    >>> table = _direct_routes([Route("/a/{x}", endpoint), Route("/a/b", endpoint,
    ...                         methods=["POST"]), Route("/c", endpoint)])
    >>> sorted(table)
    [('GET', '/c'), ('HEAD', '/c'), ('POST', '/a/b')]
    """
    table: dict[tuple[str, str], Callable] = {}
    for route in routes:
        if type(route) is not Route or route.param_convertors:
            continue
        for method in route.methods or ():
            scope = {"type": "http", "path": route.path, "root_path": "", "method": method}
            first = next((i for i, r in enumerate(routes) if r.matches(scope)[0] is Match.FULL),
                         None)
            if first is not None and routes[first] is route:
                table[(method, route.path)] = route.endpoint
    return table


async def _disconnected(receive: Callable) -> None:
    while (await receive())["type"] != "http.disconnect":
        pass


async def _unless_the_client_leaves(svc: "_Service", request: Request, pending: Any) -> Any:
    """The answer of ``pending`` (a synchronized query of this request, whose body was
    read); when the client leaves first, the query is cancelled (nobody would read its
    answer: a wait of up to max_wait would hold a task and a place of --max-connections)
    and :class:`ClientDisconnect` raised. When the server begins to stop first, the query
    is cancelled and answered 503: the client asks again, of the next server."""
    waiting = asyncio.wrap_future(pending)
    await svc.hold(waiting, request.receive)
    if not waiting.done():
        waiting.cancel()          # (cancels the query too)
        pending.cancel()
        if svc.stopping.is_set():
            raise ServiceUnavailable("the server is stopping: ask again (another server, "
                                     "or this one once it is back)")
        raise ClientDisconnect()
    return waiting.result()


class _AnswerTexts:
    """The JSON text of each delivered answer, made once for every WebSocket subscriber that
    receives the same answer. The subscription hub computes the answers of one pattern,
    condition and window once and queues the same dict for each of their subscriptions
    (``next_answers(copy=False)``), so the text is keyed by the dict's identity; an entry
    holds its dict, so the identity cannot be reused while the entry lives. At most ``size``
    entries (then the cache starts over): a subscriber that reads far behind the others, or
    alone, encodes its own answers. Used on the event loop only (no lock).

    >>> texts = _AnswerTexts()
    >>> a = {"X": "s", "T": 1.0}
    >>> texts.frame(1, [a]), texts.frame(7, [a, a])
    ('{"type":"answer","seq":1,"answer":{"X":{"$string":"s"},"T":1.0}}', \
'{"type":"answers","seq":7,"answers":[{"X":{"$string":"s"},"T":1.0},{"X":{"$string":"s"},"T":1.0}]}')
    """

    def __init__(self, size: int = 4096):
        self.size = size
        self._texts: dict[int, tuple[dict, str]] = {}
        self.encoded = 0                  # answers encoded (the rest came from the cache)
        # the answers of the last frame of several and their joined texts: the subscribers of
        # one pattern, condition and window are woken together and most take the same batch
        self._last: tuple[int, dict, dict, dict] | None = None
        self._last_body = ""
        self.joined = 0                   # frames of several answers whose texts were joined

    def text(self, answer: dict) -> str:
        hit = self._texts.get(id(answer))
        if hit is not None and hit[0] is answer:
            return hit[1]
        text = dumps(encode_answers([answer])[0]).decode("utf-8")
        if len(self._texts) >= self.size:
            self._texts.clear()
        self._texts[id(answer)] = (answer, text)
        self.encoded += 1
        return text

    def frame(self, seq: int, answers: list[dict]) -> str:
        """An ``answer`` frame (one answer) or an ``answers`` frame, numbered from ``seq``."""
        n = len(answers)
        if n == 1:
            return f'{{"type":"answer","seq":{seq},"answer":{self.text(answers[0])}}}'
        first, middle, last = answers[0], answers[n >> 1], answers[-1]
        cached = self._last
        # the same first, middle and last dict and as many: the same answers (a dict is made
        # for one event and one pattern, condition and window, whose subscriptions queue
        # every answer in journal order); the entry holds the dicts, so no id is reused
        if cached is not None and cached[0] == n and cached[1] is first and \
                cached[2] is middle and cached[3] is last:
            body = self._last_body
        else:
            text = self.text
            body = ",".join([text(a) for a in answers])
            self._last, self._last_body = (n, first, middle, last), body
            self.joined += 1
        return f'{{"type":"answers","seq":{seq},"answers":[{body}]}}'


# -- the route table (routes and the OpenAPI description come from it) ------------------------

@dataclass
class _Endpoint:
    method: str
    path: str
    handler: Callable[..., Awaitable[Any]]
    summary: str
    body: dict | None = None      # field -> (schema name, required)
    query: dict | None = None     # query parameter -> (schema name, required)
    response: dict | None = None  # field -> schema name
    auth: bool = True
    robot: bool = False           # a robot's token may use it too (--robot-tokens)


_ROUTE_PARAM = re.compile(r"\{(\w+)(?::\w+)?\}")


class _IdConvertor(Convertor):
    """A path's integer id (``{name:slr_id}``), as starlette's ``int`` but of 64 digits at most.
    The router converts a parameter while it matches the path, before any endpoint or token
    check; int() refuses more than 4,300 digits, and that exception would reach the client
    as a 500 and the log as a traceback. A longer path is no route (404)."""

    regex = "-?[0-9]{1,64}"   # (-1 is no buffer's id: BufferNotFound, as locally)

    def convert(self, value: str) -> int:
        return int(value)

    def to_string(self, value: int) -> str:
        return str(value)


register_url_convertor("slr_id", _IdConvertor())


class _Service:
    """State shared by the endpoints: the knowledge base, the tokens, the limits and the
    submitted queries (handle -> _Submitted)."""

    def __init__(self, kb: KnowledgeBase, token: str | None, limits: Limits,
                 robot_tokens: Iterable[RobotToken] = ()):
        self.kb = kb
        self.check_token = BearerToken(token, robot_tokens)
        self.limits = limits
        self._query_slots: tuple[Any, asyncio.Semaphore] | None = None   # (its loop, it)
        self.queries_running = 0      # holding a slot (query_slot)
        self.queries_waiting = 0      # waiting for one
        self.submitted: dict[str, _Submitted] = {}
        # set when the server begins to stop: the requests that wait (a poll, a synchronized
        # query) end at once instead of holding the shutdown for its whole grace
        self.stopping = asyncio.Event()
        self.requests_held = 0        # waiting for an answer: synchronized queries, polls
        self.solutions_open = 0       # /solutions connections (a query open on each)
        self.answer_texts = _AnswerTexts()
        self.fanout: FanOut | None = None
        self.endpoints = _ENDPOINTS
        # other processes write the store too (another `slr serve`, `slr add DB`, a
        # bridge): while synchronized queries wait, the store is checked for their commits
        # (the synchronizer's poll), so their marks and events answer a long-poll. Without
        # it a waiting query saw them only at this server's next store call, and a client
        # that only long-polled waited until its query's timeout
        synchronizer = getattr(kb, "synchronizer", None)
        if synchronizer is not None:
            synchronizer.watch_external()
        # What a query writes (write/1, format/2, print_message/2, user_error) would go to
        # the server's stdout and stderr, its operator's logs: any client that may query
        # could write text of its choice there. The answer has no place for it (SPEC §8:
        # the client returns what the local knowledge base returns), so it is dropped, for
        # every query the served knowledge base runs (requests, synchronized queries, rules
        # and subscriptions run by an add); with_output_to/2 and format/3 still give the
        # text to the query as a binding
        engine = getattr(kb, "engine", None)
        if engine is not None:
            engine.out = engine.err = DiscardedOutput()

    # -- plumbing -----------------------------------------------------------------------------
    def check_websocket_token(self, websocket: WebSocket, request: dict, what: str) -> None:
        """The token of a WebSocket's first message (its ``Authorization`` header, or the
        message's ``token``) checked; a robot's token is refused ``what`` (a fleet robot
        may only ship)."""
        robot = self.check_token(
            websocket.headers.get("authorization")
            or (f"Bearer {request['token']}" if isinstance(request.get("token"), str)
                else None))
        if robot is not None:
            raise _robot_may_not(robot, what)

    async def body(self, request: Request) -> dict:
        """The request's JSON object, read within the size and time limits."""
        limit = self.limits.max_body
        length = request.headers.get("content-length")
        if length is not None:
            try:
                declared = int(length)
            except ValueError:
                raise ServiceError("bad Content-Length header") from None
            if declared > limit:
                await self._discard(request, declared)
                raise ServiceError(f"request body of {declared} bytes is larger than the "
                                   f"limit of {limit} bytes", kind="PayloadTooLarge")
        chunks: list[bytes] = []

        async def read() -> None:
            size = 0
            async for chunk in request.stream():
                size += len(chunk)
                if size > limit:
                    raise ServiceError(f"request body larger than the limit of {limit} bytes",
                                       kind="PayloadTooLarge")
                chunks.append(chunk)
        try:
            # (a timeout of this task: wait_for would run read() as a task of its own, a
            # cost of every request)
            async with asyncio.timeout(self.limits.body_timeout):
                await read()
        except TimeoutError:
            raise ServiceError(f"the request body did not arrive within "
                               f"{self.limits.body_timeout:g} s", kind="RequestTimeout") from None
        data = b"".join(chunks)
        request.state.body = data
        if not data.strip():
            return {}
        try:
            obj = loads(data)
        except (ValueError, UnicodeDecodeError) as exc:
            raise ServiceError(f"the body is not valid JSON: {exc}") from None
        if type(obj) is not dict:
            raise ServiceError("the body must be a JSON object")
        return obj

    async def _discard(self, request: Request, declared: int) -> None:
        """Read (and drop) a body that is too large but not absurdly so, so the client reads
        the 413 instead of a connection reset; a larger one is cut off."""
        if declared > 64 * self.limits.max_body:
            return

        async def drain() -> None:
            async for _ in request.stream():
                pass
        try:
            await asyncio.wait_for(drain(), self.limits.body_timeout)
        except (asyncio.TimeoutError, Exception):
            pass

    def starlette_routes(self) -> list:
        routes: dict[str, list[_Endpoint]] = {}
        for e in self.endpoints:
            routes.setdefault(e.path, []).append(e)
        out: list = []
        for path, endpoints in routes.items():
            out.append(Route(path, self._dispatch(endpoints),
                             methods=[e.method for e in endpoints]))
        # an ASGI app, not a function: its delivery loop sends each frame without starlette's
        # WebSocket layers
        out.append(WebSocketRoute("/subscribe", _SubscribeEndpoint(self)))
        out.append(WebSocketRoute("/solutions", self.solutions))
        return out

    def _dispatch(self, endpoints: list[_Endpoint]) -> Callable:
        by_method = {e.method: e for e in endpoints}

        async def handle(request: Request) -> Response:
            try:
                # a route answers only its endpoints' methods (HEAD as GET)
                e = by_method.get(request.method) or by_method["GET"]
                if e.auth:
                    robot = self.check_token(request.headers.get("authorization"))
                    if robot is not None:
                        if not e.robot:
                            raise _robot_may_not(robot, f"{request.method} {request.url.path}")
                        request.state.robot = robot
                result = await e.handler(self, request)
                status = 200
                if isinstance(result, tuple):
                    status, result = result
                return _json(result, status)
            except ClientDisconnect:
                # the client left (or the server refused its malformed body and closed the
                # connection): nobody reads an answer, and there is nothing to log
                return Response(status_code=400)
            except Exception as exc:  # every failure is an error response, never a crash
                return _error_response(_classify(exc))
        return handle

    async def call(self, fn: Callable, *args: Any, **kwargs: Any) -> Any:
        """Run a blocking knowledge-base call on the thread pool."""
        return await run_in_threadpool(fn, *args, **kwargs)

    @contextlib.asynccontextmanager
    async def query_slot(self, wait: float) -> AsyncIterator[float]:
        """Hold one of the ``max_running_queries`` slots for the body (a query or a SQL
        statement evaluated on the thread pool); yields the seconds waited for it, for the
        caller to take off the query's own timeout. A query evaluated by the interpreter
        holds the GIL: 40 of them at once (the pool's size) left an add 1/41 of the
        interpreter, and no thread at all, so ingestion stood still for as long as they ran
        (an add waited 46 s beside 60 queries of 1.5 s). Beyond the slots a query waits
        here, without a thread, ``wait`` seconds at most, then is answered 503 with
        ``Retry-After`` (the ones before it may be done by then); adds, marks and loads
        never take a slot."""
        loop = asyncio.get_running_loop()
        if self._query_slots is None or self._query_slots[0] is not loop:
            # (one per loop: an app served by one loop after another, as tests do)
            self._query_slots = (loop, asyncio.Semaphore(self.limits.max_running_queries))
        slots = self._query_slots[1]
        started = time.monotonic()
        # (a free slot is no wait: the microseconds of taking it would be taken off the
        # query's timeout, and its SLRTimeout say 0.19998... s for the 0.2 s asked)
        free = not slots.locked()
        self.queries_waiting += 1
        try:
            async with asyncio.timeout(wait):
                await slots.acquire()
        except TimeoutError:
            running = self.limits.max_running_queries
            raise ServiceUnavailable(
                f"the server is busy: {running} quer{'y' if running == 1 else 'ies'} (its "
                f"max_running_queries) ran all the {wait:g} s this one could wait; try "
                f"again") from None
        finally:
            self.queries_waiting -= 1
        self.queries_running += 1
        try:
            yield 0.0 if free else time.monotonic() - started
        finally:
            self.queries_running -= 1
            slots.release()

    # -- submitted queries ----------------------------------------------------------------------
    def _entry(self, request: Request) -> "_Submitted":
        handle = request.path_params["handle"]
        entry = self.submitted.get(handle)
        if entry is None:
            raise ServiceError(f"no submitted query {handle!r} (unknown, cancelled, or its "
                               f"answer expired after {self.limits.result_ttl:g} s)",
                               kind="NotFound")
        return entry

    async def hold(self, answer: "asyncio.Future[Any]", receive: Callable,
                   timeout: float | None = None) -> bool:
        """Wait for ``answer`` (a synchronized query's) up to ``timeout`` seconds, or until
        the client leaves or the server begins to stop, counted in /health's "held"
        meanwhile; whether the client left."""
        leaving = asyncio.ensure_future(_disconnected(receive))
        stopping = asyncio.ensure_future(self.stopping.wait())
        self.requests_held += 1
        try:
            await asyncio.wait({answer, leaving, stopping}, timeout=timeout,
                               return_when=asyncio.FIRST_COMPLETED)
        finally:
            self.requests_held -= 1
            leaving.cancel()
            stopping.cancel()
        return leaving.done() and not leaving.cancelled()

    async def _poll(self, entry: "_Submitted", wait: float, receive: Callable) -> Any:
        """The state of ``entry`` once answered or after ``wait`` seconds; a client that
        leaves first (a closed client, a stopping program) is :class:`ClientDisconnect`:
        its poll held a task and a place of --max-connections for up to max_poll, and a
        server stopping meanwhile waited its grace for it, then cancelled it."""
        wait = min(wait, self.limits.max_poll)
        if wait > 0 and not entry.pending.done():
            # (a stopping server answers the state as it is: the client polls again, at the
            # next server)
            if await self.hold(entry.waiter, receive, wait) and not entry.pending.done():
                raise ClientDisconnect()
        pending = entry.pending
        state: dict[str, Any] = {"handle": entry.handle, "id": pending.id,
                                 "done": pending.done()}
        if not pending.done():
            state["waiting_for"] = [
                {"type": w.type, "time": encode_plain(float(w.time)), "reason": w.reason,
                 "kind": w.kind} for w in list(getattr(pending, "waiting_for", ()))]
            state["waiting"] = pending.timeout_message(None)
            return 202, state
        if pending.cancelled():
            state["cancelled"] = True
            return state
        if hasattr(pending, "explain"):
            try:
                state["explain"] = pending.explain()
            except Exception as failure:  # an explanation is a courtesy; the answer matters
                log_failure(log, "PendingQuery.explain", failure)
        exc = pending.exception()
        if exc is not None:
            body = public_error_body(_classify(exc))
            body.update(state)
            return body["error"]["status"], body
        state["answers"] = encode_answers(pending.result())
        return state

    def _expire(self) -> None:
        now = time.monotonic()
        ttl = self.limits.result_ttl
        for handle in [h for h, s in self.submitted.items()
                       if s.finished_at is not None and now - s.finished_at > ttl]:
            del self.submitted[handle]

    # -- subscriptions over WebSocket --------------------------------------------------------
    async def subscribe(self, websocket: WebSocket, send: Send) -> None:
        """``/subscribe``: see docs/service.md, "Subscriptions". One subscription per
        connection; answers are delivered in order with a sequence number.

        ``send`` is the connection's ASGI send (``websocket``'s own): the answer frames go
        through it directly, the other messages through ``websocket``.

        The subscription is consumed with ``async for`` on the event loop (the knowledge
        base's hub thread wakes it through ``call_soon_threadsafe``), so a subscriber costs
        no thread. Each send awaits the socket's drain: a slow client holds back only its
        own subscription, whose bounded queue (``subscribe_queue``) then makes it read the
        store at its own pace and, too far behind, end with an overflow error."""
        try:
            await websocket.accept()
        except OSError:     # the client left during the handshake: nobody to answer
            return
        sub = None
        watcher = None
        closing: list = []
        try:
            request = await self._first_message(websocket)
            self.check_websocket_token(websocket, request, "a subscription")
            pattern, kwargs = _subscribe_request(request)
            batch = _batch_size(request)
            kwargs["max_queue"] = max(min(kwargs.get("max_queue", self.limits.subscribe_queue),
                                          self.limits.subscribe_queue), batch)
            acks = _Acks(max(self.limits.subscribe_queue, batch)) \
                if _ack_flag(request) else None
            sub = await self.call(self.kb.subscribe, pattern, **kwargs)
            subscribed = {"type": "subscribed", "pattern": pattern, "id": kwargs.get("id")}
            if acks is not None:
                subscribed["ack_window"] = acks.bound
            await websocket.send_text(dumps(subscribed).decode("utf-8"))
            watcher = asyncio.create_task(self._watch_client(websocket, sub, closing, acks))
            channel = _frame_channel(websocket.scope) if acks is None else None
            if channel is not None:
                # delivered with the loop's other subscribers, frames written as framed once
                delivery = self._fanout().start(sub, channel, batch)
                if await delivery.finished == GONE:
                    raise WebSocketDisconnect(1006)
                if not closing:
                    await websocket.send_text('{"type":"end"}')
                    await websocket.close(1000)
                return
            texts = self.answer_texts
            seq = 0
            while True:
                # what is queued goes along (batch at most); the error that ended the
                # subscription is raised by the call after the answers queued before it
                if acks is None:
                    answers = await sub.next_answers(batch, copy=False)
                else:
                    # at most acks.bound answers unacknowledged: wait for acks beyond that
                    room = await acks.room()
                    if room <= 0:
                        break
                    answers = await sub.next_answers(min(batch, room), copy=False,
                                                     handled=False)
                if not answers:
                    break
                if acks is not None:
                    acks.sent = seq + len(answers)   # before the send: an ack may come back
                try:
                    await send({"type": "websocket.send", "text": texts.frame(seq + 1, answers)})
                except OSError:       # the client is gone (what starlette's send_text raises)
                    raise WebSocketDisconnect(1006) from None
                seq += len(answers)
            if acks is not None and acks.error is not None:
                await _send_error(websocket, acks.error)
            elif not closing:
                await websocket.send_text('{"type":"end"}')
                await websocket.close(1000)
        except WebSocketDisconnect:
            pass
        except Exception as exc:
            if not closing:
                await _send_error(websocket, _classify(exc))
        finally:
            if watcher is not None:
                watcher.cancel()
            if sub is not None and not closing:
                await self._close_subscription(sub)
            elif closing:
                await closing[0]

    def _fanout(self) -> FanOut:
        fanout = self.fanout
        if fanout is None or fanout.loop is not asyncio.get_running_loop():
            fanout = self.fanout = FanOut(asyncio.get_running_loop(), self.answer_texts.frame)
        return fanout

    async def _watch_client(self, websocket: WebSocket, sub: Any, closing: list,
                            acks: "_Acks | None" = None) -> None:
        """Read what the client sends after subscribing: acknowledgements (``{"op": "ack",
        "seq": N}`` when it subscribed with ``"ack": true``); when it closes (close frame,
        ``{"op": "close"}``, a vanished peer, or a bad ack) close the subscription, which ends
        the loop that delivers it. Answers not acknowledged then stay unhandled."""
        try:
            while True:
                message = await websocket.receive()
                if message["type"] == "websocket.disconnect":
                    break
                text = message.get("text")
                if not text:
                    continue
                if acks is not None and '"ack"' in text:
                    seq = acks.parse(text)
                    if seq is None:
                        break                # a bad ack: acks.error says why
                    if seq > acks.acked:
                        sub.acknowledge(seq - acks.acked)
                        acks.acked = seq
                        acks.changed()
                elif '"close"' in text:
                    break
        except Exception:  # the peer vanished
            pass
        finally:
            closing.append(asyncio.ensure_future(self._close_subscription(sub)))
            if acks is not None:
                acks.stop()

    async def _close_subscription(self, sub: Any) -> None:
        try:
            await self.call(sub.close)
        except Exception as exc:   # the client left whatever happens here
            log_failure(log, "closing a subscription", exc)

    async def _first_message(self, websocket: WebSocket, op: str = "subscribe",
                             example: str = '"pattern": ...') -> dict:
        """The first message of a WebSocket connection: ``{"op": op, ...}``."""
        try:
            message = await asyncio.wait_for(websocket.receive(), self.limits.body_timeout)
        except asyncio.TimeoutError:
            raise ServiceError(f"no {op} message within {self.limits.body_timeout:g} s",
                               kind="RequestTimeout") from None
        if message["type"] == "websocket.disconnect":
            raise WebSocketDisconnect(message.get("code", 1000))
        data = message.get("text")
        if data is None:
            data = message.get("bytes") or b""
        try:
            request = loads(data)
        except (ValueError, UnicodeDecodeError) as exc:
            raise ServiceError(f"the {op} message is not valid JSON: {exc}") from None
        if type(request) is not dict or request.get("op") != op:
            raise ServiceError(f'the first message must be {{"op": "{op}", {example}}}')
        return request

    # -- answers one at a time over WebSocket -------------------------------------------------
    async def solutions(self, websocket: WebSocket) -> None:
        """``/solutions``: a goal's answers one at a time, each computed when the client asks
        for it (docs/service.md, "Answers one at a time"): the first message asks for the
        first answer, ``{"op": "next"}`` for each next one; ``{"op": "close"}``, or closing
        the connection, ends the query -- also while it looks for an answer
        (:meth:`Solutions.stop <slr_sql.kb.Solutions.stop>`), so nothing of it goes on
        running. The query's time (its ``timeout``, capped by ``max_query_time``) counts
        from the first message to the end, the waits for the client's next request
        included. Each answer is computed on the thread pool holding a query slot; none is
        computed ahead, and none while the client reads."""
        try:
            await websocket.accept()
        except OSError:     # the client left during the handshake: nobody to answer
            return
        asks = _Asks()
        reader: asyncio.Task | None = None
        query: _StreamedQuery | None = None
        self.solutions_open += 1
        try:
            request = await self._first_message(websocket, "solutions", '"goal": ...')
            self.check_websocket_token(websocket, request, "a query")
            goal, options, timeout = _solutions_request(request)
            budget = _cap(timeout, self.limits.max_query_time)
            query = _StreamedQuery(self, goal, options, budget)
            reader = asyncio.create_task(asks.read(websocket))
            seq = 0
            while True:
                # one answer, while the client's end is watched (a stopping server closes
                # the connection: its end too)
                step = asyncio.ensure_future(query.next_answer())
                ended = asyncio.ensure_future(asks.ended.wait())
                try:
                    await asyncio.wait({step, ended}, return_when=asyncio.FIRST_COMPLETED)
                finally:
                    ended.cancel()
                if not step.done():
                    await query.abandon(step)
                    if asks.error is not None:
                        raise asks.error
                    await _close_quietly(websocket)
                    break
                answer = step.result()             # (the query's error is raised here)
                if answer is _NO_MORE:
                    await websocket.send_text('{"type":"end"}')
                    await websocket.close(1000)
                    break
                seq += 1
                await websocket.send_text(dumps({"type": "answer", "seq": seq,
                                                 "answer": encode_answers([answer])[0]})
                                          .decode("utf-8"))
                try:
                    asked = await asks.next_request(query.time_left())
                except TimeoutError:
                    raise SLRTimeout(f"query timed out after {budget:g} s (its time counts "
                                     f"from the first request, the waits for the next "
                                     f"request included; {seq} answer{'s' if seq != 1 else ''}"
                                     f" sent)") from None
                if not asked:
                    if asks.error is not None:
                        raise asks.error
                    await _close_quietly(websocket)
                    break
        except WebSocketDisconnect:
            pass                   # the client is gone: nobody to answer
        except Exception as exc:
            # (an OSError that is no SLRError -- SLRTimeout is a TimeoutError -- is a send
            # to a client that is gone)
            gone = isinstance(exc, OSError) and not isinstance(exc, SLRError)
            if not gone and (not asks.ended.is_set() or asks.error is not None):
                await _send_error(websocket, _classify(exc))
        finally:
            if reader is not None:
                reader.cancel()
            if query is not None:
                await query.close()
            self.solutions_open -= 1

    # -- OpenAPI ----------------------------------------------------------------------------
    def openapi(self) -> dict:
        paths: dict[str, dict] = {}
        for e in self.endpoints:
            path = _ROUTE_PARAM.sub(r"{\1}", e.path)
            op: dict[str, Any] = {"summary": e.summary, "operationId": f"{e.method.lower()}"
                                  f"{path.replace('/', '_').replace('{', '').replace('}', '')}",
                                  "responses": _responses(e)}
            params = [{"name": name, "in": "path", "required": True,
                       "schema": {"type": "integer" if ":slr_id}" in e.path else "string"}}
                      for name in _ROUTE_PARAM.findall(e.path)]
            params += [{"name": name, "in": "query", "required": req, "schema": _ref(kind)}
                       for name, (kind, req) in (e.query or {}).items()]
            if params:
                op["parameters"] = params
            if e.body:
                op["requestBody"] = {"required": True, "content": {"application/json": {
                    "schema": _object_schema({k: v[0] for k, v in e.body.items()},
                                             [k for k, v in e.body.items() if v[1]])}}}
            if not e.auth:
                op["security"] = []
            paths.setdefault(path, {})[e.method.lower()] = op
        paths["/subscribe"] = {"get": {
            "summary": "WebSocket: subscribe to events matching a pattern (kb.subscribe); "
                       "send {\"op\": \"subscribe\", \"pattern\", \"where\", \"since\", "
                       "\"until\", \"id\", \"batch\", \"ack\"}, receive subscribed / answer(s) / "
                       "end / error messages; with \"ack\": true send {\"op\": \"ack\", "
                       "\"seq\": N} for the answers handled (docs/service.md).",
            "operationId": "subscribe",
            "responses": {"101": {"description": "Switching to the WebSocket protocol"}}}}
        paths["/solutions"] = {"get": {
            "summary": "WebSocket: a goal's answers one at a time (kb.solutions); send {\"op\": "
                       "\"solutions\", \"goal\", \"args\", \"at\", \"timeout\", \"robot\"} "
                       "for the first answer and {\"op\": \"next\"} for each next one, "
                       "receive answer / end / error messages; closing the WebSocket or "
                       "{\"op\": \"close\"} ends the query (docs/service.md).",
            "operationId": "solutions",
            "responses": {"101": {"description": "Switching to the WebSocket protocol"}}}}
        return {"openapi": "3.1.0",
                "info": {"title": "slr_sql service", "version": slr_sql.__version__,
                         "description": "One SLR knowledge base over HTTP/JSON. Terms use the "
                                        "JSON term encoding (components/schemas/Term)."},
                "paths": paths,
                "components": {"schemas": _SCHEMAS,
                               "securitySchemes": {"bearer": {"type": "http",
                                                              "scheme": "bearer"}}},
                "security": [{"bearer": []}]}


# -- the endpoints -----------------------------------------------------------------------------

_ENDPOINTS: list[_Endpoint] = []


def _route(method: str, path: str, summary: str, *, body: dict | None = None,
           query: dict | None = None, response: dict | None = None,
           auth: bool = True, robot: bool = False) -> Callable:
    """Register an endpoint: its handler, and what the OpenAPI description says of it;
    ``robot``: a robot's token may use it (the endpoints a pusher needs)."""
    def register(handler: Callable) -> Callable:
        _ENDPOINTS.append(_Endpoint(method, path, handler, summary, body, query, response,
                                    auth, robot))
        return handler
    return register


@_route("GET", "/health", "Liveness, version, limits, the queries running and "
        "waiting for a slot, and the requests held waiting for an answer (synchronized "
        "queries, polls) (no token needed).",
        auth=False, response={"status": "string", "version": "string",
                              "api": "string", "limits": "object", "queries": "object"})
async def _health(svc: "_Service", request: Request) -> Any:
    return {"status": "ok", "version": slr_sql.__version__, "api": API_VERSION,
            "limits": dataclasses.asdict(svc.limits),
            "queries": {"running": svc.queries_running, "waiting": svc.queries_waiting,
                        "held": svc.requests_held, "solutions": svc.solutions_open}}


@_route("GET", "/openapi.json", "This API's OpenAPI 3.1 description.",
        auth=False)
async def _openapi(svc: "_Service", request: Request) -> Any:
    return svc.openapi()


@_route("POST", "/add", "Add one event written in SLR syntax (kb.add).",
        body={"event": ("string", True)}, response={"added": "integer"})
async def _add(svc: "_Service", request: Request) -> Any:
    b = await svc.body(request)
    await svc.call(svc.kb.add, _field(b, "event", str, required=True))
    return {"added": 1}


@_route("POST", "/add_event", "Add one event from terms (kb.add_event).",
        body={"name": ("string", True), "args": ("TermList", False),
              "start": ("Number", True), "end": ("Number", False)},
        response={"added": "integer"})
async def _add_event(svc: "_Service", request: Request) -> Any:
    b = await svc.body(request)
    name, args, start, end = _event_tuple(b)
    await svc.call(svc.kb.add_event, name, args, start=start, end=end)
    return {"added": 1}


@_route("POST", "/add_many", "Add many events in one transaction "
        "(kb.add_many); returns the rejected ones with their index.",
        body={"events": ("EventList", True), "atomic": ("boolean", False)},
        response={"accepted": "integer", "rejected": "RejectedList"})
async def _add_many(svc: "_Service", request: Request) -> Any:
    b = await svc.body(request)
    events = _field(b, "events", list, required=True)
    atomic = _field(b, "atomic", bool, default=False)
    plain = _plain_arguments(request.state.body, events, b.get("atomic"))
    prepared: list[Any] = []   # SLR texts and (name, args, start, end) tuples
    positions: list[int] = []
    rejected: list[dict[str, Any]] = []
    for i, ev in enumerate(events):
        if plain and type(ev) is dict:
            # the common case inline (what _event_tuple does for it): a plain event with a
            # name, an array of arguments and float times
            name, args, start = ev.get("name"), ev.get("args"), ev.get("start")
            end = ev.get("end", start)
            if type(start) is float and type(end) is float and type(name) is str and name \
                    and type(args) is list:
                prepared.append((name, args, start, end))
                positions.append(i)
                continue
        try:
            if isinstance(ev, str):
                prepared.append(ev)
            elif isinstance(ev, dict):
                prepared.append(_event_tuple(ev, plain))
            else:
                raise ServiceError(f"events[{i}]: an event is SLR text or an object "
                                   f'{{"name", "args", "start", "end"}}')
            positions.append(i)
        except SLRError as exc:
            if atomic:
                raise
            rejected.append(_rejection(exc, i))
    kb_rejected = await svc.call(svc.kb.add_many, prepared, atomic=atomic)
    for refused in kb_rejected or ():
        index = getattr(refused, "index", None)
        original = positions[index] if isinstance(index, int) and \
            0 <= index < len(positions) else None
        if plain and original is not None and type(events[original]) is dict:
            refused = _as_decoded(refused, events[original])
        rejected.append(_rejection(refused, original))
    rejected.sort(key=lambda r: (r["index"] is None, r["index"] or 0))
    return {"accepted": len(events) - len(rejected), "rejected": rejected}


@_route("POST", "/load", "Load program text (kb.load); name= and replace= "
        "need a knowledge base with named programs.",
        body={"text": ("string", True), "filename": ("string", False),
              "name": ("string", False), "replace": ("boolean", False)},
        response={"loaded": "boolean"})
async def _load(svc: "_Service", request: Request) -> Any:
    b = await svc.body(request)
    text = _field(b, "text", str, required=True)
    filename = _field(b, "filename", str)
    name = _field(b, "name", str)
    replace = _field(b, "replace", bool, default=False)
    kwargs: dict[str, Any] = {"replace": replace}
    if filename is not None:
        kwargs["filename"] = filename
    if name is not None:
        kwargs["name"] = name
    await svc.call(svc.kb.load, text, **kwargs)
    return {"loaded": True}


@_route("POST", "/unload", "Remove a named program (kb.unload).",
        body={"name": ("string", True)}, response={"unloaded": "string"})
async def _unload(svc: "_Service", request: Request) -> Any:
    b = await svc.body(request)
    name = _field(b, "name", str, required=True)
    await svc.call(svc.kb.unload, name)
    return {"unloaded": name}


@_route("GET", "/programs", "The loaded named programs (kb.programs): name -> "
        "{name, source, texts, filenames, loaded_at}, in load order.",
        response={"programs": "ProgramMap"})
async def _programs(svc: "_Service", request: Request) -> Any:
    return {"programs": _plain(await svc.call(svc.kb.programs))}


@_route("GET", "/event_rules", "The event rules in force, in the order they run "
        "(kb.event_rules).", response={"event_rules": "array"})
async def _event_rules(svc: "_Service", request: Request) -> Any:
    return {"event_rules": _plain(await svc.call(svc.kb.event_rules))}


@_route("POST", "/query", "Answer a goal (kb.query); wait=true makes it "
        "synchronized. timeout is capped by the server's max_query_time "
        "(max_wait when synchronized).",
        body={"goal": ("string", True), "args": ("Args", False),
              "at": ("Number", False), "timeout": ("Number", False),
              "max_steps": ("integer", False), "limit": ("integer", False),
              "wait": ("boolean", False), "robot": ("string", False)},
        response={"answers": "AnswerList"})
async def _query(svc: "_Service", request: Request) -> Any:
    b = await svc.body(request)
    goal = _field(b, "goal", str, required=True)
    args = decode_args(b.get("args"))
    at = _number(b, "at")
    timeout = _number(b, "timeout", minimum=0)
    limit = _field(b, "limit", int)
    max_steps = _field(b, "max_steps", int)
    robot = _field(b, "robot", str)
    if _field(b, "wait", bool, default=False):
        async with svc.query_slot(svc.limits.max_query_time):
            pending = await svc.call(svc.kb.submit, goal, at=at, args=args,
                                     timeout=_cap(timeout, svc.limits.max_wait),
                                     **({"robot": robot} if robot is not None else {}))
        answers = await _unless_the_client_leaves(svc, request, pending)
    else:
        budget = _cap(timeout, svc.limits.max_query_time)
        async with svc.query_slot(budget) as waited:
            answers = await svc.call(svc.kb.query, goal, at=at, args=args, limit=limit,
                                     timeout=max(budget - waited, 0.0), max_steps=max_steps,
                                     **({"robot": robot} if robot is not None else {}))
    return {"answers": encode_answers(answers)}


@_route("POST", "/submit", "Submit a synchronized query (kb.submit); returns "
        "a handle to poll. wait= (s) waits for the answer first.",
        body={"goal": ("string", True), "args": ("Args", False),
              "at": ("Number", False), "id": ("string", False),
              "timeout": ("Number", False), "wait": ("Number", False),
              "robot": ("string", False)},
        response={"handle": "string", "id": "string", "done": "boolean",
                  "answers": "AnswerList"})
async def _submit(svc: "_Service", request: Request) -> Any:
    b = await svc.body(request)
    goal = _field(b, "goal", str, required=True)
    args = decode_args(b.get("args"))
    at = _number(b, "at")
    qid = _field(b, "id", str)
    timeout = _number(b, "timeout", minimum=0)
    wait = _number(b, "wait", minimum=0) or 0.0
    robot = _field(b, "robot", str)
    svc._expire()
    if sum(1 for s in svc.submitted.values() if not s.pending.done()) >= svc.limits.max_pending:
        raise ServiceUnavailable(f"{svc.limits.max_pending} submitted queries are pending "
                                 f"already")
    held = sum(s.held for s in svc.submitted.values())
    if held >= svc.limits.max_held_answer_bytes:
        raise ServiceUnavailable(
            f"the answers of finished submitted queries kept for their clients take "
            f"{held} bytes (at most {svc.limits.max_held_answer_bytes}): each is kept "
            f"{svc.limits.result_ttl:g} s after its query finished, or until DELETE "
            f"/submit/HANDLE")
    async with svc.query_slot(svc.limits.max_query_time):
        pending = await svc.call(svc.kb.submit, goal, at=at, id=qid, args=args,
                                 timeout=_cap(timeout, svc.limits.max_wait),
                                 **({"robot": robot} if robot is not None else {}))
    handle = uuid.uuid4().hex
    entry = _Submitted(handle, pending, asyncio.wrap_future(pending))
    pending.add_done_callback(entry.finished)
    svc.submitted[handle] = entry
    return await svc._poll(entry, wait, request.receive)


@_route("GET", "/submit/{handle}", "The state of a submitted query; waits up "
        "to wait= s (capped by max_poll) for its answer.",
        query={"wait": ("Number", False)},
        response={"handle": "string", "id": "string", "done": "boolean",
                  "answers": "AnswerList", "explain": "string"})
async def _poll(svc: "_Service", request: Request) -> Any:
    entry = svc._entry(request)
    wait = _query_number(request, "wait")
    return await svc._poll(entry, wait, request.receive)


@_route("DELETE", "/submit/{handle}", "Cancel a submitted query and forget it.",
        response={"handle": "string", "cancelled": "boolean"})
async def _cancel(svc: "_Service", request: Request) -> Any:
    entry = svc._entry(request)
    cancelled = entry.pending.cancel()
    svc.submitted.pop(entry.handle, None)
    return {"handle": entry.handle, "cancelled": cancelled}


@_route("POST", "/explain", "How a goal would run (kb.explain).",
        body={"goal": ("string", True)}, response={"explain": "string"})
async def _explain(svc: "_Service", request: Request) -> Any:
    b = await svc.body(request)
    return {"explain": await svc.call(svc.kb.explain, _field(b, "goal", str, required=True))}


@_route("POST", "/warnings", "Warnings about a goal that do not change its answer: a "
        "predicate with no events, rules or declaration and the nearest known names "
        "(kb.goal_warnings).",
        body={"goal": ("string", True)}, response={"warnings": "array"})
async def _warnings(svc: "_Service", request: Request) -> Any:
    b = await svc.body(request)
    goal = _field(b, "goal", str, required=True)
    return {"warnings": await svc.call(svc.kb.goal_warnings, goal)}


@_route("POST", "/mark_complete", "Declare a history complete up to a time "
        "(kb.mark_complete).",
        body={"type": ("string", True), "time": ("Number", True)},
        response={"type": "string", "time": "Number"})
async def _mark_complete(svc: "_Service", request: Request) -> Any:
    b = await svc.body(request)
    event_type = _field(b, "type", str, required=True)
    t = _number(b, "time", required=True)
    await svc.call(svc.kb.mark_complete, event_type, t)
    return {"type": event_type, "time": encode_plain(t)}


@_route("GET", "/complete_until", "The time up to which a history is complete "
        "(kb.complete_until).", query={"type": ("string", True)},
        response={"type": "string", "time": "Number"})
async def _complete_until(svc: "_Service", request: Request) -> Any:
    event_type = request.query_params.get("type")
    if event_type is None:      # ("": the knowledge base's words say what it is not)
        raise ServiceError('the query parameter "type" (p/N) is required')
    t = await svc.call(svc.kb.complete_until, event_type)
    return {"type": event_type, "time": encode_plain(float(t))}


@_route("GET", "/buffers", "The active buffers with their counters "
        "(kb.buffers).", response={"buffers": "array"})
async def _buffers(svc: "_Service", request: Request) -> Any:
    return {"buffers": _plain(await svc.call(svc.kb.buffers))}


@_route("POST", "/buffers", "Keep a history (kb.add_buffer): exactly one of "
        "keep_last (N most recent per key), keep_seconds (the last l s), "
        "keep_between ([t1, t2]).",
        body={"pattern": ("string", True), "keep_last": ("integer", False),
              "keep_seconds": ("Number", False),
              "keep_between": ("NumberPair", False)},
        response={"id": "integer"})
async def _add_buffer(svc: "_Service", request: Request) -> Any:
    b = await svc.body(request)
    pattern = _field(b, "pattern", str, required=True)
    kwargs: dict[str, Any] = {}
    if b.get("keep_last") is not None:
        kwargs["keep_last"] = _field(b, "keep_last", int)
    if b.get("keep_seconds") is not None:
        kwargs["keep_seconds"] = _number(b, "keep_seconds")
    if b.get("keep_between") is not None:
        pair = _field(b, "keep_between", list)
        if len(pair) != 2:
            raise ServiceError('"keep_between" must be [t1, t2]')
        kwargs["keep_between"] = (_number({"t1": pair[0]}, "t1", required=True),
                                  _number({"t2": pair[1]}, "t2", required=True))
    buffer_id = await svc.call(svc.kb.add_buffer, pattern, **kwargs)
    return {"id": buffer_id}


@_route("DELETE", "/buffers/{buffer_id:slr_id}", "Remove a runtime buffer "
        "(kb.remove_buffer); the events it kept stay.",
        response={"removed": "integer"})
async def _remove_buffer(svc: "_Service", request: Request) -> Any:
    buffer_id = request.path_params["buffer_id"]

    # (an unknown id is the knowledge base's BufferNotFound: 404, as error_status says)
    await svc.call(svc.kb.remove_buffer, buffer_id)
    return {"removed": buffer_id}


@_route("POST", "/unsubscribe", "Remove a durable subscription and its position "
        "(kb.unsubscribe).", body={"id": ("string", True)}, response={"unsubscribed": "string"})
async def _unsubscribe(svc: "_Service", request: Request) -> Any:
    b = await svc.body(request)
    sid = _field(b, "id", str, required=True)
    await svc.call(svc.kb.unsubscribe, sid)
    return {"unsubscribed": sid}


@_route("POST", "/sql", "Run one read-only SQL statement on the store "
        "(SELECT, WITH, VALUES, EXPLAIN, introspection PRAGMAs).",
        body={"query": ("string", True), "params": ("SqlParams", False),
              "timeout": ("Number", False)},
        response={"columns": "array", "rows": "array"})
async def _sql(svc: "_Service", request: Request) -> Any:
    b = await svc.body(request)
    statement = _field(b, "query", str, required=True)
    # (an array for ? placeholders, an object for :name ones, as kb.sql takes them)
    params = _field(b, "params", (list, dict), default=[])
    timeout = _cap(_number(b, "timeout", minimum=0), svc.limits.sql_timeout)
    for i, p in params.items() if isinstance(params, dict) else enumerate(params):
        if p is not None and type(p) not in (int, float, str, bool):   # (True binds 1)
            raise ServiceError(f"params[{i!r}]: a SQL parameter is a number, a string, "
                               f"true, false or null")
    async with svc.query_slot(timeout) as waited:
        columns, rows = await svc.call(_read_only_sql, svc.kb, statement, params,
                                       max(timeout - waited, 0.0))
    return {"columns": list(columns), "rows": encode_plain([list(r) for r in rows])}


@_route("GET", "/stats", "File size, events per type, buffers and their "
        "counters (what slr stats prints, as data and as text; not where the store is).",
        response={"rows": "array", "space": "object",
                  "buffers": "array", "now": "Number", "text": "string"})
async def _stats(svc: "_Service", request: Request) -> Any:
    return await svc.call(_stats_of, svc.kb)



@_route("GET", "/fleet/positions", "What this fleet store holds of a robot: per event "
        "type, the last sequence of the robot's store stored here (slr fleet push).",
        query={"robot": ("string", True)}, response={"positions": "array"}, robot=True)
async def _fleet_positions(svc: "_Service", request: Request) -> Any:
    from slr_sql.shipping import positions
    from slr_sql.store import check_robot_name
    robot = request.query_params.get("robot")
    if not robot:
        raise SLRError("robot= names the robot")
    check_robot_name(robot)
    _ships_as(request, robot)
    found = await svc.call(positions, svc.kb, robot)
    return {"positions": [[n, a, p] for (n, a), p in sorted(found.items())]}


@_route("POST", "/fleet/receive", "Store a robot's shipment exactly once (slr fleet "
        "push): batches of [name, arity, rows], its marks, what it holds unshipped.",
        body={"robot": ("string", True), "batches": ("array", True),
              "marks": ("object", False), "pending": ("integer", False),
              "head_arrival": ("Number", False), "after": ("array", False),
              "resync": ("array", False), "relayed": ("object", False)},
        response={"stored": "integer"}, robot=True)
async def _fleet_receive(svc: "_Service", request: Request) -> Any:
    from slr_sql.shipping import FleetBehind, receive
    b = await svc.body(request)
    robot = _field(b, "robot", str, required=True)
    access = _ships_as(request, robot)
    if access is not None:
        _brings_only_its_robots(access, b.get("batches"), b.get("relayed"))
    try:
        stored = await svc.call(receive, svc.kb, robot,
                                _field(b, "batches", list, required=True),
                                _field(b, "marks", dict), _field(b, "pending", int),
                                _number(b, "head_arrival"), after=_field(b, "after", list),
                                resync=_field(b, "resync", list),
                                relayed=_field(b, "relayed", dict))
    except FleetBehind as exc:   # the pusher asks the positions again (slr_sql.fleet)
        raise ServiceError(str(exc), kind="Conflict") from None
    return {"stored": stored}


def _robot_may_not(access: RobotAccess, what: str) -> ServiceForbidden:
    return ServiceForbidden(
        f"the token of robot {access.robot!r} (--robot-tokens) ships to the fleet "
        f"store as {access.robot!r} (GET /fleet/positions, POST /fleet/receive) and may not "
        f"use {what}; the server's own token may")


def _ships_as(request: Request, robot: str) -> RobotAccess | None:
    """The robot token's access of ``request`` (None: the server's own token, or none
    needed), once it is sure the request ships as ``robot``: a robot's token ships as its
    robot only (a shipment under another name could hold the fleet's marks back, or take
    another robot's route)."""
    access = getattr(request.state, "robot", None)
    if access is not None and robot != access.robot:
        raise ServiceForbidden(f"the token of robot {access.robot!r} (--robot-tokens) "
                               f"ships as {access.robot!r} only, not as {robot!r}")
    return access


def _brings_only_its_robots(access: RobotAccess, batches: Any, relayed: Any) -> None:
    """Refuse a shipment of a robot's token that brings rows or marks of a robot it does not
    relay (its line of --robot-tokens names those it does). What is not of a shipment's
    shape is left to the shipment's own check (400)."""
    def refuse(who: str, what: str) -> ServiceForbidden:
        return ServiceForbidden(
            f"the token of robot {access.robot!r} (--robot-tokens) ships no "
            f"{what} of robot {who!r}: it does not relay that robot (a store that relays the "
            f"rows of other robots names them after 'relays' on its line)")
    for batch in batches if type(batches) is list else ():
        rows = batch[2] if type(batch) is list and len(batch) == 3 else None
        for row in rows if type(rows) is list else ():
            who = row[-1] if type(row) is list and row else None
            if type(who) is str and not access.may_bring(who):
                raise refuse(who, "rows")
    for who in relayed if type(relayed) is dict else ():
        if type(who) is str and not access.may_bring(who):
            raise refuse(who, "marks")


@_route("GET", "/fleet/status", "Per robot that shipped here: events stored, what it "
        "held unshipped and its last contact (slr fleet status).",
        response={"robots": "array"})
async def _fleet_status(svc: "_Service", request: Request) -> Any:
    return {"robots": await svc.call(svc.kb.store.fleet_contacts)}


@_route("POST", "/fleet/retire", "Retire a robot from this fleet store (slr fleet retire): "
        "the fleet's marks stop waiting for it, its shipments are refused; the server's own "
        "token only.", body={"robot": ("string", True)},
        response={"robot": "string", "retired_at": "Number", "already": "boolean",
                  "raised": "object"})
async def _fleet_retire(svc: "_Service", request: Request) -> Any:
    from slr_sql.shipping import retire
    b = await svc.body(request)
    return encode_plain(await svc.call(retire, svc.kb, _field(b, "robot", str, required=True)))


@_route("POST", "/fleet/reinstate", "Take back a robot's retirement (slr fleet reinstate); "
        "the server's own token only.", body={"robot": ("string", True)},
        response={"robot": "string", "reinstated": "boolean"})
async def _fleet_reinstate(svc: "_Service", request: Request) -> Any:
    from slr_sql.shipping import reinstate
    b = await svc.body(request)
    return await svc.call(reinstate, svc.kb, _field(b, "robot", str, required=True))


@dataclass
class _Submitted:
    handle: str
    pending: Any                      # the kb's PendingQuery (a concurrent.futures.Future)
    waiter: Any                       # the same as an asyncio future, for long-polls
    finished_at: float | None = None
    held: int = 0                     # bytes of its answers as JSON, once finished

    def finished(self, future: Any) -> None:
        """(On the knowledge base's thread, as the query finishes.)"""
        if not future.cancelled() and future.exception() is None:
            try:
                self.held = len(dumps(encode_answers(future.result())))
            except Exception:  # noqa: BLE001 - its poll says what is wrong with the answer
                self.held = 0
        self.finished_at = time.monotonic()


# -- request pieces ----------------------------------------------------------------------------

def _plain_arguments(body: bytes, events: list, atomic: bool | None = None) -> bool:
    """True when no event argument in this body holds an object, ``true``, ``false`` or
    ``null``: then every argument is already the Python value the knowledge base takes (a JSON
    string is an atom, as a ``str`` is for ``kb.add_many``; numbers and arrays are themselves)
    and decoding can be skipped. Checked on the bytes, at C speed: the body's only ``{`` are
    the outer object's and one per event object, its only ``true``/``false`` the value of
    ``"atomic"`` (``atomic``: that value, None when absent); a ``{`` or a ``true`` inside a
    string only makes this say False, which is always safe."""
    objects = sum(1 for ev in events if type(ev) is dict)
    return body.count(b"{") == 1 + objects and body.count(b"true") == (atomic is True) \
        and body.count(b"false") == (atomic is False) and b"null" not in body


def _as_decoded(exc: BaseException, obj: dict) -> BaseException:
    """A rejection of an event whose arguments were passed as parsed (``plain``), worded as
    for the same event decoded: its atoms written as atoms (``cup4``), not as the strings
    the knowledge base printed (``"cup4"``)."""
    event = getattr(exc, "event", None)
    if type(event) is not tuple or len(event) != 4:
        return exc
    name, args, start, end = event
    message = str(exc)
    head = format_event(name, args, start, end)
    if not message.startswith(head):
        return exc
    try:
        decoded = decode_arguments(args)
    except SLRError:
        return exc
    out = EventRejected(format_event(name, decoded, start, end) + message[len(head):])
    out.index, out.event = getattr(exc, "index", None), (name, decoded, start, end)
    return out


def _event_tuple(obj: dict, plain: bool = False) -> tuple:
    """``{"name", "args", "start", "end"}`` (or ``"time"``) -> ``(name, args, start, end)``.
    ``plain``: the arguments need no decoding (:func:`_plain_arguments`). In a batch, the
    index of the event says which one a message is about."""
    name = obj.get("name")
    if type(name) is not str:   # ("" is an atom: the knowledge base decides, as locally)
        raise ServiceError('"name" must be a string')
    args = obj.get("args", [])
    if type(args) is not list:
        raise ServiceError('"args" must be an array of terms')
    terms = args if plain else decode_arguments(args)
    if "start" in obj or "time" not in obj:
        start = _event_time(obj, "start")
        end = _event_time(obj, "end") if obj.get("end") is not None else start
    else:
        start = end = _event_time(obj, "time")
    return (name, terms, start, end)


def _event_time(obj: dict, key: str) -> Any:
    value = obj.get(key)
    if type(value) is float:
        return value
    if value is None:
        raise ServiceError(f'"{key}" is required')
    value = decode_term(value, _where=key) if isinstance(value, dict) else value
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise EventRejected(f"{key}: event times must be numbers (got {value!r})")
    try:
        return float(value)
    except OverflowError:
        raise EventRejected(f"{key}: event time out of range") from None


def _rejection(exc: BaseException, index: int | None) -> dict:
    err = public_error_body(exc)["error"]
    err["kind"] = "EventRejected"
    err["index"] = index
    if "line" in err:  # a syntax error inside one event: keep the words and where
        err["message"] = str(exc)
        for key in ("line", "column", "source_line", "filename"):
            err.pop(key, None)
    return err


def _subscribe_request(request: dict) -> tuple[str, dict]:
    pattern = _field(request, "pattern", str, required=True)
    kwargs: dict[str, Any] = {}
    where = _field(request, "where", str)
    if where is not None:
        kwargs["where"] = where
    since = request.get("since", "now")
    kwargs["since"] = "now" if since == "now" else _number(request, "since")
    if request.get("until") is not None:
        kwargs["until"] = _number(request, "until")
    sid = _field(request, "id", str)
    if sid is not None:
        kwargs["id"] = sid
    max_queue = _field(request, "max_queue", int)
    if max_queue is not None:
        if max_queue < 1:
            raise ServiceError('"max_queue" must be a positive integer')
        kwargs["max_queue"] = max_queue
    if "max_lag" in request:     # null: never ends for lagging (the store keeps its place)
        max_lag = _field(request, "max_lag", int)
        if max_lag is not None and max_lag < 1:
            raise ServiceError('"max_lag" must be a positive integer or null')
        kwargs["max_lag"] = max_lag
    return pattern, kwargs


# -- answers one at a time (WebSocket /solutions) ---------------------------------------------

_NO_MORE = object()     # a query's answers are all given


def _solutions_request(request: dict) -> tuple[str, dict, float | None]:
    """The goal, the options of ``kb.solutions`` and the timeout asked in a ``solutions``
    message."""
    goal = _field(request, "goal", str, required=True)
    options: dict[str, Any] = {"at": _number(request, "at"),
                               "args": decode_args(request.get("args"))}
    robot = _field(request, "robot", str)
    if robot is not None:
        options["robot"] = robot
    return goal, options, _number(request, "timeout", minimum=0)


class _StreamedQuery:
    """One query of ``/solutions``: its answers taken one at a time on the thread pool, each
    while holding a query slot; ``deadline`` ends the whole query (``time_left``). Used on
    the event loop only."""

    def __init__(self, service: "_Service", goal: str, options: dict, budget: float):
        self.service = service
        self.goal = goal
        self.options = options
        self.budget = budget
        self.deadline = time.monotonic() + budget
        self.answers: Any = None        # kb.solutions' iterator, made with the first answer
        self.computing = False          # a thread of the pool is in next(answers)

    def time_left(self) -> float:
        return max(self.deadline - time.monotonic(), 0.0)

    async def next_answer(self) -> Any:
        """The next answer, or ``_NO_MORE``; the query's error."""
        svc = self.service
        async with svc.query_slot(self.time_left()) as waited:
            if self.answers is None:
                # its time: what is left after the first slot's wait (none when one was
                # free: the timeout the client asked, as /query's)
                timeout = max(self.budget - waited, 0.0)
                self.deadline = time.monotonic() + timeout
                self.answers = svc.kb.solutions(self.goal, timeout=timeout, **self.options)
            self.computing = True
            try:
                return await svc.call(next, self.answers, _NO_MORE)
            finally:
                self.computing = False

    async def abandon(self, step: "asyncio.Future[Any]") -> None:
        """End ``step`` (a :meth:`next_answer` under way): the search is stopped and its
        thread waited for (it ends at the interpreter's next check); a step still waiting
        for its slot is cancelled."""
        if self.answers is not None:
            self.answers.stop()
        if not self.computing:
            step.cancel()
        await asyncio.wait({step})
        if not step.cancelled():
            step.exception()          # (retrieved: the query's error goes nowhere now)

    async def close(self) -> None:
        answers, self.answers = self.answers, None
        if answers is None:
            return
        if self.computing:            # (the connection's task was cancelled: a server's
            answers.stop()            # grace over) its thread ends at its next check
            return
        try:
            await self.service.call(answers.close)
        except Exception as exc:  # the client has what it asked for whatever happens here
            log_failure(log, "closing a query's answers", exc)


class _Asks:
    """What the client of ``/solutions`` sends after its first message: requests for the
    next answer (``{"op": "next"}``, counted) and its end (``{"op": "close"}``, a closed
    connection, or a message that is neither: ``error``). Used on the event loop only."""

    def __init__(self) -> None:
        self.asked = 0
        self.ended = asyncio.Event()
        self.error: ServiceError | None = None
        self._changed = asyncio.Event()

    async def read(self, websocket: WebSocket) -> None:
        try:
            while True:
                message = await websocket.receive()
                if message["type"] == "websocket.disconnect":
                    break
                text = message.get("text")
                if text is None:
                    text = (message.get("bytes") or b"").decode("utf-8", "replace")
                try:
                    op = loads(text)
                except (ValueError, UnicodeDecodeError):
                    op = None
                op = op.get("op") if type(op) is dict else None
                if op == "next":
                    self.asked += 1
                    self._changed.set()
                    continue
                if op != "close":
                    self.error = ServiceError(f'expected {{"op": "next"}} or {{"op": '
                                              f'"close"}}, got {text[:100]!r}')
                break
        except Exception:  # noqa: BLE001 - the peer vanished
            pass
        finally:
            self.ended.set()
            self._changed.set()

    async def next_request(self, timeout: float) -> bool:
        """True once the client asked for the next answer; False when it ended;
        TimeoutError after ``timeout`` seconds."""
        async with asyncio.timeout(timeout):
            while not self.asked and not self.ended.is_set():
                self._changed.clear()
                await self._changed.wait()
        if self.ended.is_set():
            return False
        self.asked -= 1
        return True


# -- subscriptions ------------------------------------------------------------------------------

MAX_BATCH = 1000


def _batch_size(request: dict) -> int:
    """``"batch": N`` in the subscribe message: up to N answers already queued go in one
    ``answers`` frame (1, the default, sends each in an ``answer`` frame of its own)."""
    batch = request.get("batch", 1)
    if isinstance(batch, bool) or not isinstance(batch, int) or not 1 <= batch <= MAX_BATCH:
        raise ServiceError(f'"batch" must be an integer from 1 to {MAX_BATCH}')
    return batch


def _ack_flag(request: dict) -> bool:
    """``"ack": true`` in the subscribe message: the client acknowledges what it handled."""
    ack = request.get("ack", False)
    if type(ack) is not bool:
        raise ServiceError(f'"ack" must be true or false, not {ack!r}')
    return ack


class _Acks:
    """The acknowledgements of one WebSocket subscriber that asked for them: ``sent`` answers
    went out (numbered 1..sent on the connection), ``acked`` were acknowledged (``{"op":
    "ack", "seq": N}``: every answer up to N). The sender waits in :meth:`room` while
    ``bound`` answers are unacknowledged. Used on the event loop only.

    >>> acks = _Acks(10); acks.sent = 5
    >>> acks.parse('{"op": "ack", "seq": 3}'), acks.parse('{"op": "ack", "seq": 9}')
    (3, None)
    >>> acks.error
    ServiceError('bad ack: seq 9 is beyond the last answer sent (5)')
    """

    def __init__(self, bound: int):
        self.bound = bound
        self.sent = 0
        self.acked = 0
        self.error: ServiceError | None = None
        self._stopped = False
        self._event = asyncio.Event()

    def parse(self, text: str) -> int | None:
        """The ``seq`` of an ack message; None (and ``error`` set) when it is not a valid
        ack: not JSON, ``seq`` not an integer, beyond what was sent, or going backwards."""
        try:
            message = loads(text)
        except (ValueError, UnicodeDecodeError) as exc:
            self.error = ServiceError(f"bad ack: not valid JSON: {exc}")
            return None
        seq = message.get("seq") if type(message) is dict else None
        if type(message) is not dict or message.get("op") != "ack" or type(seq) is not int:
            self.error = ServiceError(f'bad ack: expected {{"op": "ack", "seq": N}} with an '
                                      f'integer N, got {text[:100]!r}')
        elif seq > self.sent:
            self.error = ServiceError(f"bad ack: seq {seq} is beyond the last answer sent "
                                      f"({self.sent})")
        elif seq < self.acked:
            self.error = ServiceError(f"bad ack: seq {seq} goes backwards (answers up to "
                                      f"{self.acked} were acknowledged)")
        else:
            return seq
        return None

    def changed(self) -> None:
        self._event.set()

    def stop(self) -> None:
        self._stopped = True
        self._event.set()

    async def room(self) -> int:
        """Wait until fewer than ``bound`` answers are unacknowledged; how many more may go
        (0 once the client left or sent a bad ack)."""
        while not self._stopped and self.sent - self.acked >= self.bound:
            self._event.clear()
            await self._event.wait()
        return 0 if self._stopped else self.bound - (self.sent - self.acked)


async def _close_quietly(websocket: WebSocket) -> None:
    """Close with 1000 (the client asked to stop), unless the client closed already."""
    try:
        await websocket.close(1000)
    except Exception:  # noqa: BLE001 - the client is gone already
        pass


async def _send_error(websocket: WebSocket, exc: BaseException) -> None:
    body = public_error_body(exc)
    body["type"] = "error"
    try:
        await websocket.send_text(dumps(body).decode("utf-8"))
        await websocket.close(4000 + body["error"]["status"])
    except Exception:  # the client is gone already
        pass


def _frame_channel(scope: Scope) -> FrameChannel | None:
    """The connection's frame channel, when the server offers one (``slr serve`` does)."""
    offered = (scope.get("extensions") or {}).get(FRAMES_EXTENSION)
    return offered.get("channel") if isinstance(offered, dict) else None


class _SubscribeEndpoint:
    """``/subscribe`` as an ASGI app (:meth:`_Service.subscribe`), which starlette calls with
    the send of the server (through its exception middleware's thin wrapper) rather than
    through the layers of its WebSocket session: each answer frame is one call of it.

    The subscription is served by a task of its own, which this app awaits (a cancellation
    reaches it, and what it raises comes out here): a frame's wake-up then resumes that task's
    two coroutines, not the dozen of the middleware and routing that called this one, which
    every resumption (a frame each) would otherwise pass through, in and out."""

    def __init__(self, service: _Service):
        self.service = service

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        await asyncio.ensure_future(self.service.subscribe(WebSocket(scope, receive, send),
                                                           send))


# -- read-only SQL and stats (run on the thread pool) ------------------------------------------

def _read_only_sql(kb: KnowledgeBase, statement: str, params: list | dict,
                   timeout: float) -> tuple:
    """One statement that cannot change the store: the first keyword must read, and the
    store runs it read-only (``kb.sql`` without ``write``); a statement that runs longer
    than ``timeout`` seconds is interrupted."""
    refusal = read_only_refusal(statement, getattr(kb.store.dialect, "name", "sqlite"))
    if refusal is not None:
        raise ServiceError(f"sql over the service is read-only: {refusal}")
    try:
        return kb.sql(statement, params, timeout=timeout)
    except SLRTimeout as exc:
        if type(exc) is not SLRTimeout:   # (SLRStatementTimeout keeps its kind and words)
            raise
        # the class kb.sql raises locally (408 all the same), in the service's words
        raise SLRTimeout(f"sql: the statement ran longer than {timeout:g} s") from None
    except SLRError as exc:
        # SLRBusy and the like keep their kind, a message naming the store its mark (the
        # answer drops or hides the location): the class of kb.sql's error locally
        if type(exc) is not SLRError or exc.store_location is not None or \
                str(exc).startswith("sql: "):
            raise
        raise SLRError(f"sql: {exc}") from None


def _stats_of(kb: KnowledgeBase) -> dict:
    if hasattr(kb, "stats"):
        return encode_plain(_plain(kb.stats()))
    from slr_sql import buffers as history   # the same figures `slr stats` prints

    data = history.stats(kb.store)
    # where the server keeps its store (a file path, a PostgreSQL host and database) is not
    # said to a client, as a 5xx answer does not say it: any holder of the token could read
    # it here, and it is the operator's business (`slr stats DB` on the server names it)
    return {"rows": [{"type": f"{name}/{arity}", "count": count}
                     for (name, arity), count in data["rows"].items()],
            "space": encode_plain(data["space"]),
            "buffers": encode_plain(data["buffers"]),
            "now": encode_plain(float(data["now"])),
            "text": history.format_stats(kb.store, str(kb.path or ""), named=False)}


# -- OpenAPI schemas -----------------------------------------------------------------------

_SCHEMAS: dict[str, Any] = {
    "Term": {"description": "An SLR term in the JSON term encoding: atom = JSON string; "
                            "string = {\"$string\": text}; integer = JSON integer (beyond 64 "
                            "bits {\"$int\": digits}); float = JSON number with . or exponent, "
                            "{\"$float\": \"inf\"|\"-inf\"|\"nan\"}; list = array; compound "
                            "f(..) = {\"f\": [args]}; variable = {\"$var\": name}.",
             "anyOf": [{"type": "string"}, {"type": "number"}, {"type": "array"},
                       {"type": "object", "minProperties": 1, "maxProperties": 1}]},
    "SqlParams": {"description": "values of the ? placeholders (an array) or of the :name "
                                 "ones (an object)",
                  "anyOf": [{"type": "array"}, {"type": "object"}]},
    "TermList": {"type": "array", "items": {"$ref": "#/components/schemas/Term"}},
    "Number": {"anyOf": [{"type": "number"}, {"type": "object", "properties": {
        "$float": {"enum": ["inf", "-inf", "nan"]}}}]},
    "NumberPair": {"type": "array", "items": {"$ref": "#/components/schemas/Number"},
                   "minItems": 2, "maxItems": 2},
    "Args": {"type": "object", "additionalProperties": {"$ref": "#/components/schemas/Term"},
             "description": "Goal variables bound from values (no text splicing)."},
    "Answer": {"type": "object", "additionalProperties": {"$ref": "#/components/schemas/Term"}},
    "AnswerList": {"type": "array", "items": {"$ref": "#/components/schemas/Answer"}},
    "Event": {"anyOf": [{"type": "string", "description": "SLR text, p(..)^T or p(..)^[S,E]"},
                        {"type": "object", "required": ["name"], "properties": {
                            "name": {"type": "string"},
                            "args": {"$ref": "#/components/schemas/TermList"},
                            "start": {"$ref": "#/components/schemas/Number"},
                            "end": {"$ref": "#/components/schemas/Number"},
                            "time": {"$ref": "#/components/schemas/Number"}}}]},
    "EventList": {"type": "array", "items": {"$ref": "#/components/schemas/Event"}},
    "ProgramInfo": {"type": "object", "required": ["name", "source", "texts", "filenames",
                                                   "loaded_at"], "properties": {
        "name": {"type": "string"}, "source": {"type": "string"},
        "texts": {"type": "integer"}, "filenames": {"type": "array",
                                                    "items": {"type": "string"}},
        "loaded_at": {"anyOf": [{"type": "number"}, {"type": "null"}]}}},
    "ProgramMap": {"type": "object", "description": "program name -> ProgramInfo, in load "
                   "order of each program's first text",
                   "additionalProperties": {"$ref": "#/components/schemas/ProgramInfo"}},
    "WaitList": {"type": "array", "items": {"type": "object", "properties": {
        "type": {"type": "string", "description": "name/arity"},
        "time": {"$ref": "#/components/schemas/Number"},
        "reason": {"type": "string"}, "kind": {"type": "string"}}}},
    "RejectedList": {"type": "array", "items": {"type": "object", "properties": {
        "index": {"type": ["integer", "null"]}, "kind": {"type": "string"},
        "message": {"type": "string"}}}},
    "Error": {"type": "object", "required": ["error"], "properties": {"error": {
        "type": "object", "required": ["kind", "status", "message"], "properties": {
            "kind": {"type": "string", "description": "SLRSyntaxError, SLREvaluationError, "
                     "SLRTimeout, EventRejected, SLRError, BufferNotFound, BadRequest, "
                     "Unauthorized, Forbidden, NotFound, "
                     "MethodNotAllowed, RequestTimeout, PayloadTooLarge, Unavailable"},
            "status": {"type": "integer"}, "message": {"type": "string"},
            "line": {"type": "integer"}, "column": {"type": "integer"},
            "source_line": {"type": "string"}, "filename": {"type": "string"},
            "term": {"$ref": "#/components/schemas/Term"},
            "index": {"type": "integer"}}}}},
}

_BASIC = {"string", "integer", "number", "boolean", "array", "object"}


def _ref(kind: str) -> dict:
    return {"type": kind} if kind in _BASIC else {"$ref": f"#/components/schemas/{kind}"}


def _object_schema(fields: dict[str, str], required: list[str]) -> dict:
    schema: dict[str, Any] = {"type": "object",
                              "properties": {k: _ref(v) for k, v in fields.items()}}
    if required:
        schema["required"] = required
    return schema


def _responses(e: _Endpoint) -> dict:
    """Every status the endpoint may answer with (a method the path does not take gets 405
    with ``Allow``; a path that is not here, 404)."""
    error = {"description": "an error", "content": {"application/json": {
        "schema": {"$ref": "#/components/schemas/Error"}}}}
    ok: dict[str, Any] = {"description": "success"}
    if e.response:
        ok["content"] = {"application/json": {"schema": _object_schema(e.response, [])}}
    out: dict[str, Any] = {"200": ok, "400": error}
    if e.auth:
        out["401"] = error
        out["403"] = dict(error, description="a robot's token (--robot-tokens) used beyond "
                                             "shipping as its robot")
    if e.body:                     # the body's time and size limits
        out["408"] = dict(error, description="the body did not arrive in time, or the "
                                             "query ran out of its time")
        out["413"] = dict(error, description="the body is larger than max_body")
    if e.path.startswith("/submit"):
        out["202"] = {"description": "not answered yet (done: false): waiting_for lists "
                                     "what it waits for, waiting says it in words",
                      "content": {"application/json": {"schema": _object_schema(
                          {"handle": "string", "id": "string", "done": "boolean",
                           "waiting_for": "WaitList", "waiting": "string"}, [])}}}
        out["408"] = dict(error, description="the synchronized query timed out")
    if "{" in e.path:
        out["404"] = dict(error, description="no such resource")
    if e.auth:                     # the store busy or out of space: retry later
        out["503"] = dict(error, description="a condition that may pass (the store busy, "
                                             "the disk full, too many pending queries); "
                                             "retry after Retry-After")
    return out


# -- the application -----------------------------------------------------------------------

def create_app(kb: KnowledgeBase, *, token: str | None = None, limits: Limits | None = None,
               robot_tokens: Iterable[RobotToken] = ()) -> Starlette:
    """The Starlette application serving ``kb`` (which the caller keeps and closes).

    ``token``: when given, every request but ``/health`` and ``/openapi.json`` must carry
    ``Authorization: Bearer TOKEN`` (compared in constant time). ``robot_tokens``: tokens
    of robots (:class:`~slr_sql.service.auth.RobotToken`, ``slr serve --robot-tokens``),
    each of which may only ship to the fleet store as its robot (403 ``Forbidden`` beyond);
    they need ``token`` beside them. ``limits``: see :class:`Limits`.

    >>> import slr_sql
    >>> with slr_sql.open() as kb:
    ...     app = create_app(kb)
    ...     "/query" in {r.path for r in app.routes}
    True
    """
    service = _Service(kb, token or None, limits or Limits(), robot_tokens)

    async def http_error(request: Request, exc: Exception) -> Response:
        assert isinstance(exc, HTTPException)
        kind = {404: "NotFound", 405: "MethodNotAllowed"}.get(exc.status_code, "BadRequest")
        message = {404: f"no such endpoint: {request.url.path} (GET /openapi.json lists them)",
                   405: f"{request.method} is not allowed on {request.url.path}"}.get(
            exc.status_code, str(exc.detail))
        response = _error_response(ServiceError(message, kind=kind, status=exc.status_code))
        if exc.headers:             # 405: Allow lists the methods the path takes
            response.headers.update(exc.headers)
        return response

    async def internal_error(request: Request, exc: Exception) -> Response:
        return _error_response(exc)    # (which logs it)

    routes = service.starlette_routes()
    app = Starlette(routes=routes,
                    middleware=[Middleware(_AnswerOnce, direct=_direct_routes(routes),
                                               stopping=service.stopping)],
                    exception_handlers={HTTPException: http_error, Exception: internal_error})
    app.state.service = service
    return app
