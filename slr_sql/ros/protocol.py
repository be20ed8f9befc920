"""The request protocol of ``slr ros bridge`` on the wire (docs/ros.md, "Requests").

Requests and replies are JSON objects carried as the ``data`` of ``std_msgs/String``
messages. Terms, answers and errors use the encoding of the network service
(:mod:`slr_sql.service.encoding`, :mod:`slr_sql.service.errors`), so a query sent over ROS
and the same query sent to ``slr serve`` get the same JSON back — plus the request's
``token``, which tells the replies on a shared topic apart.

This module only reads and writes those objects; it knows nothing of rclpy.

>>> token, body = read_request('{"token": "q1", "goal": "p(X)"}')
>>> token, parse_query(body).goal
('q1', 'p(X)')
>>> dumps_reply(error_reply("q1", ServiceError("no goal")))
'{"token":"q1","error":{"kind":"BadRequest","status":400,"message":"no goal"}}'
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from slr_sql import SLRError

from ..service.encoding import decode_args, decode_term, dumps, encode_answers, loads
from ..service.errors import ServiceError, error_body

__all__ = ["ServiceError", "QueryRequest", "read_request", "parse_query", "check_keys",
           "number_field", "string_field", "answers_reply", "error_reply", "dumps_reply",
           "MAX_REQUEST", "QUERY_KEYS"]

MAX_REQUEST = 1 << 20   # bytes of one request (the service's default body limit)
QUERY_KEYS = ("token", "op", "goal", "at", "args", "wait", "timeout", "limit")


@dataclass(frozen=True)
class QueryRequest:
    """One query: ``kb.query(goal, at=, args=, timeout=, limit=)``, or with ``wait``
    ``kb.submit(goal, at=, args=, timeout=)``."""

    goal: str
    at: float | None = None
    args: dict | None = None
    wait: bool = False
    timeout: float | None = None
    limit: int | None = None


def read_request(data: str | bytes, limit: int = MAX_REQUEST) -> tuple[Any, dict]:
    """``(token, body)`` of one request text. Raises :class:`ServiceError` for text that is
    not a JSON object, or that has no token; the error's ``token`` attribute is the token
    when one could be read (None otherwise), so the error reply can carry it.

    >>> read_request('[1]')
    Traceback (most recent call last):
    ...
    slr_sql.service.errors.ServiceError: a request is a JSON object, not list
    """
    size = len(data.encode("utf-8", "surrogatepass") if isinstance(data, str) else data)
    if size > limit:
        raise _with_token(ServiceError(f"a request of {size} bytes is larger than the limit "
                                       f"of {limit} bytes", kind="PayloadTooLarge"), None)
    try:
        body = loads(data)
    except (ValueError, UnicodeDecodeError) as exc:
        raise _with_token(ServiceError(f"a request is a JSON object; this is not valid JSON: "
                                       f"{exc}"), None) from None
    if type(body) is not dict:
        raise _with_token(ServiceError(f"a request is a JSON object, not "
                                       f"{type(body).__name__}"), None)
    token = body.get("token")
    if token is None:
        raise _with_token(ServiceError('"token" is required: a string or a number that the '
                                       'reply carries back'), None)
    if isinstance(token, bool) or not isinstance(token, (str, int, float)):
        raise _with_token(ServiceError('"token" must be a string or a number'), None)
    return token, body


def _with_token(exc: ServiceError, token: Any) -> ServiceError:
    exc.token = token
    return exc


def check_keys(body: dict, allowed: tuple, what: str) -> None:
    """Refuse keys a request of this kind does not have (a misspelt ``"gaol"`` is an error,
    not a silently ignored field).

    >>> check_keys({"goal": "p(X)", "at": 5}, ("goal", "at", "token"), "query")
    >>> check_keys({"gaol": "p(X)"}, ("goal", "at", "token"), "query")
    Traceback (most recent call last):
        ...
    slr_sql.service.errors.ServiceError: query: unknown key 'gaol' (expected one of goal, at, token)
    """
    for key in body:
        if key not in allowed:
            raise ServiceError(f"{what}: unknown key {key!r} (expected one of "
                               f"{', '.join(allowed)})")


def number_field(body: dict, name: str, *, minimum: float | None = None) -> float | None:
    """A JSON number, or a tagged float (``{"$float": "inf"}``), as float; None if absent.

    >>> number_field({"at": 5}, "at"), number_field({"at": {"$float": "inf"}}, "at"), number_field({}, "at")
    (5.0, inf, None)
    >>> number_field({"timeout": -1}, "timeout", minimum=0)
    Traceback (most recent call last):
        ...
    slr_sql.service.errors.ServiceError: "timeout" must be a number >= 0
    """
    value = body.get(name)
    if value is None:
        return None
    if isinstance(value, dict):
        value = decode_term(value, _where=name)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ServiceError(f'"{name}" must be a number')
    try:
        number = float(value)
    except OverflowError:
        raise ServiceError(f'"{name}" is out of range') from None
    if math.isnan(number) or (minimum is not None and not number >= minimum):
        raise ServiceError(f'"{name}" must be a number' + (f" >= {minimum:g}"
                                                          if minimum is not None else ""))
    return number


def string_field(body: dict, name: str, *, required: bool = False) -> str | None:
    """A non-empty JSON string (None if absent and not required).

    >>> string_field({"goal": "p(X)"}, "goal"), string_field({}, "id")
    ('p(X)', None)
    >>> string_field({}, "goal", required=True)
    Traceback (most recent call last):
        ...
    slr_sql.service.errors.ServiceError: "goal" is required
    """
    value = body.get(name)
    if value is None:
        if required:
            raise ServiceError(f'"{name}" is required')
        return None
    if not isinstance(value, str) or not value.strip():
        raise ServiceError(f'"{name}" must be a non-empty string')
    return value


def parse_query(body: dict) -> QueryRequest:
    """The query of a request body (keys :data:`QUERY_KEYS`). Raises ServiceError.

    >>> parse_query({"token": 1, "goal": "p(X)", "args": {"X": "a"}, "wait": True, "at": 5})
    QueryRequest(goal='p(X)', at=5.0, args={'X': Atom('a')}, wait=True, timeout=None, limit=None)
    """
    check_keys(body, QUERY_KEYS, "query request")
    op = body.get("op", "query")
    if op != "query":
        raise ServiceError(f"unknown request kind {op!r} on the query topic (only \"query\"; "
                           f"control requests go to the control topic)")
    goal = string_field(body, "goal", required=True)
    wait = body.get("wait", False)
    if not isinstance(wait, bool):
        raise ServiceError('"wait" must be true or false')
    limit = body.get("limit")
    if limit is not None and (isinstance(limit, bool) or not isinstance(limit, int) or limit < 1):
        raise ServiceError('"limit" must be a positive integer')
    if limit is not None and wait:
        raise ServiceError('"limit" is for queries without "wait"')
    return QueryRequest(goal, number_field(body, "at"), decode_args(body.get("args")), wait,
                        number_field(body, "timeout", minimum=0), limit)


def answers_reply(token: Any, answers: list[dict]) -> dict:
    """``{"token": ..., "answers": [...]}``: the answers in the service's term encoding.

    >>> from slr_sql import Atom, String
    >>> dumps_reply(answers_reply(7, [{"X": Atom("cup1"), "S": String("hi"), "T": 1.0}]))
    '{"token":7,"answers":[{"X":"cup1","S":{"$string":"hi"},"T":1.0}]}'
    """
    return {"token": token, "answers": encode_answers(answers)}


def error_reply(token: Any, exc: BaseException, **extra: Any) -> dict:
    """``{"token": ..., "error": {"kind", "status", "message", ...}}``: the service's error
    object (a syntax error has ``line`` and ``column``). ``extra`` keys come before it.

    >>> error_reply("t1", SLRError("no such program: tea"), id="q1")
    {'token': 't1', 'id': 'q1', 'error': {'kind': 'SLRError', 'status': 400, 'message': 'no such program: tea'}}
    """
    return {"token": token, **extra, **error_body(exc)}


def dumps_reply(reply: dict) -> str:
    """The reply as the text of a ``std_msgs/String``.

    >>> dumps_reply({"token": 7, "answers": [{"X": 1.5}]})
    '{"token":7,"answers":[{"X":1.5}]}'
    """
    return dumps(reply).decode("utf-8")


def is_client_error(exc: BaseException) -> bool:
    """True for failures that are the request's fault or the knowledge base's refusal (an
    SLRError), False for a bug.

    >>> is_client_error(SLRError("unknown key 'gaol'")), is_client_error(KeyError("goal"))
    (True, False)
    """
    return isinstance(exc, SLRError)
