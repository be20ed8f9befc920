"""Errors on the wire: one JSON shape, one HTTP status per kind, rebuilt as the same
exception class by the client.

``{"error": {"kind": "SLRSyntaxError", "status": 400, "message": "...", "line": 1,
"column": 5, "source_line": "foo(", "filename": "<query>"}}``

>>> from slr_sql import SLRTimeout
>>> body = error_body(SLRTimeout("the query ran out of its 1 s"))
>>> body["error"]["kind"], body["error"]["status"]
('SLRTimeout', 408)
>>> type(error_from_body(body, 408)).__name__
'SLRTimeout'
"""
from __future__ import annotations

import time
from datetime import timezone
from email.utils import parsedate_to_datetime
from typing import Any

import slr_sql
from slr_sql import BufferNotFound, EventRejected, SLRCancelled, SLREvaluationError, SLRError, SLRSyntaxError, \
    SLRTimeout, SLRUnavailable

from .encoding import TermError, decode_term, encode_term

__all__ = ["ServiceError", "ServiceForbidden", "ServiceUnavailable", "ServiceOutcomeUnknown",
           "error_body",
           "error_status", "error_from_body", "retry_after", "parse_retry_after",
           "store_condition", "STATUS_KINDS"]

# kind of a ServiceError -> its HTTP status
STATUS_KINDS = {
    "BadRequest": 400, "Unauthorized": 401, "Forbidden": 403, "NotFound": 404, "MethodNotAllowed": 405,
    "RequestTimeout": 408, "Conflict": 409, "PayloadTooLarge": 413, "InternalError": 500,
    "NotImplemented": 501, "Unavailable": 503,
}


class ServiceError(SLRError):
    """A failure of the service itself rather than of the knowledge base: a bad request, a
    wrong token, an unknown resource, a body too large, an unreachable server. ``status`` is
    the HTTP status (0 when no answer came), ``kind`` the name in the error JSON.

    >>> e = ServiceError("no such buffer #9", kind="NotFound"); e.status
    404
    """

    def __init__(self, message: str, kind: str = "BadRequest", status: int | None = None):
        self.kind = kind
        self.status = STATUS_KINDS.get(kind, 400) if status is None else status
        super().__init__(message)


class ServiceForbidden(ServiceError):
    """The token is valid but does not allow the request: a robot's token (``slr serve
    --robot-tokens``) used for anything but shipping as its robot -- another endpoint than
    the ``/fleet/*`` ones a pusher needs, or a shipment or positions under another robot's
    name, or rows and marks of a robot it does not relay. ``kind`` ``"Forbidden"``,
    ``status`` 403; nothing of the request was done. Retrying does not help: the robot's
    token decides it.

    >>> e = ServiceForbidden("the token of robot 'r1' ships as 'r1' only, not as 'r2'")
    >>> e.kind, e.status, isinstance(e, ServiceError)
    ('Forbidden', 403, True)
    """

    def __init__(self, message: str):
        super().__init__(message, kind="Forbidden")


class ServiceUnavailable(ServiceError, SLRUnavailable):
    """The service cannot answer now, a condition that may pass: no server listens at the
    URL (or the connection failed or broke), or it answered 503 (too many connections or
    pending queries; the store busy or full when no slr_sql class says which). Both a
    :class:`ServiceError` (``kind`` ``"Unavailable"``, ``status`` 503, or 0 when no answer
    came) and an :class:`~slr_sql.SLRUnavailable`, so a caller retrying on the latter
    retries a server that is down too. A refused connection or a 503 wrote nothing, nor
    did a request that changes nothing; a request that may change the store and was sent
    in full before the connection broke is a :class:`ServiceOutcomeUnknown` instead.
    ``kind``: another name when a 503 said one this client has no class for.

    ``retry_after``: the seconds the server's ``Retry-After`` asked to wait, else the
    class's default (1).

    >>> from slr_sql import SLRUnavailable
    >>> e = ServiceUnavailable("cannot reach slr serve at http://127.0.0.1:1", status=0)
    >>> isinstance(e, SLRUnavailable), e.kind, e.status, e.retry_after
    (True, 'Unavailable', 0, 1)
    """

    def __init__(self, message: str, status: int | None = None, kind: str = "Unavailable",
                 retry_after: float | None = None):
        super().__init__(message, kind=kind, status=503 if status is None else status)
        if retry_after is not None:
            self.retry_after = retry_after


class ServiceOutcomeUnknown(ServiceError):
    """A request that may change the store (an add, a load, a mark, ...) was sent in full,
    and the connection broke before its answer came (the server was killed, a network
    failure): the server may or may not have applied it. ``kind`` ``"OutcomeUnknown"``,
    ``status`` 0. Unlike :class:`ServiceUnavailable` it is no
    :class:`~slr_sql.SLRUnavailable`, whose promise is that nothing was written: sending
    the same add again may store it twice. Read what the store holds first, or send again
    only what a second copy does not change (a completeness mark, a fleet shipment, whose
    rows the fleet stores once). A request that changes nothing (a query) gets a
    ServiceUnavailable instead: retrying it is safe.

    ``carried``: for an ``add_many`` (sent in several requests above the server's body
    limit), the indexes ``(first, end)`` of the events the broken request carried: those
    before ``first`` were stored (or rejected), those from ``end`` on never sent; None for
    other calls.

    >>> from slr_sql import SLRUnavailable
    >>> e = ServiceOutcomeUnknown("POST /add: no answer")
    >>> e.kind, e.status, isinstance(e, SLRUnavailable)
    ('OutcomeUnknown', 0, False)
    """

    carried: tuple[int, int] | None = None

    def __init__(self, message: str):
        super().__init__(message, kind="OutcomeUnknown", status=0)


def error_status(exc: BaseException) -> int:
    """The HTTP status an exception is answered with.

    >>> from slr_sql import SLRTimeout, SLRBusy
    >>> error_status(SLRError("bad goal")), error_status(SLRTimeout("slow")), error_status(SLRBusy("locked"))
    (400, 408, 503)
    >>> error_status(BufferNotFound("no active buffer #7"))
    404
    """
    if isinstance(exc, ServiceError):
        return exc.status
    if isinstance(exc, BufferNotFound):
        return 404
    if isinstance(exc, SLRTimeout):
        return 408
    if isinstance(exc, SLRUnavailable):   # a lock wait ran out, the disk is full: try again
        return 503
    return 400  # syntax, evaluation, rejected events, bad terms: the request's fault


def retry_after(exc: BaseException) -> int | None:
    """Seconds for the ``Retry-After`` header of a 503 answer (None for other statuses).

    >>> from slr_sql import SLRStoreFull
    >>> retry_after(SLRStoreFull("robot.db: the disk is full")), retry_after(SLRTimeout("x"))
    (10, None)
    """
    if error_status(exc) != 503:
        return None
    return max(1, int(getattr(exc, "retry_after", 1)))


def store_condition(exc: BaseException) -> SLRError | None:
    """The SLRUnavailable class of a raw sqlite3 error that says the store is busy (locked)
    or its disk full, for an answer that may pass (503 with its ``Retry-After``); None for
    any other exception.

    >>> import sqlite3
    >>> type(store_condition(sqlite3.OperationalError("database is locked"))).__name__
    'SLRBusy'
    >>> store_condition(ValueError("database is locked")) is None
    True
    """
    if type(exc).__module__ != "sqlite3":
        return None
    text = str(exc)
    if "locked" in text or "busy" in text:
        return slr_sql.SLRBusy(f"the store is busy: {text}")
    if "disk is full" in text:
        return slr_sql.SLRStoreFull(f"the store is full: {text}")
    return None


MAX_RETRY_AFTER = 86400   # seconds: a longer Retry-After is read as this (a day)


def parse_retry_after(value: Any, now: float | None = None) -> float | None:
    """The seconds a ``Retry-After`` header's ``value`` asks to wait: delay-seconds
    (``"10"``), or an HTTP date (the seconds from ``now``, default the time now, to it; 0
    once past); at most a day. None when ``value`` is absent or neither (a client keeps
    its class's default then).

    >>> parse_retry_after("10"), parse_retry_after(" 3 "), parse_retry_after(None)
    (10, 3, None)
    >>> parse_retry_after("Wed, 21 Oct 2015 07:28:30 GMT", now=1445412480.0)
    30.0
    >>> parse_retry_after("soon"), parse_retry_after("-5"), parse_retry_after("1.5")
    (None, None, None)
    """
    if not isinstance(value, str):
        return None
    text = value.strip()
    if text.isascii() and text.isdigit():
        digits = text.lstrip("0") or "0"
        return min(int(digits), MAX_RETRY_AFTER) if len(digits) <= 12 else MAX_RETRY_AFTER
    try:
        when = parsedate_to_datetime(text)
        if when.tzinfo is None:          # ("-0000": a time in UTC, its zone unsaid)
            when = when.replace(tzinfo=timezone.utc)
        seconds = when.timestamp() - (time.time() if now is None else now)
    except (TypeError, ValueError, IndexError, OverflowError, OSError):
        return None
    return max(0.0, min(seconds, float(MAX_RETRY_AFTER)))


def error_body(exc: BaseException) -> dict[str, Any]:
    """The JSON body of an error response for ``exc``.

    >>> error_body(SLRError("no such program: tea"))
    {'error': {'kind': 'SLRError', 'status': 400, 'message': 'no such program: tea'}}
    >>> error_body(KeyError("secret"))   # an unexpected error: no detail to the client
    {'error': {'kind': 'InternalError', 'status': 500, 'message': 'internal error (KeyError); the server log has the details'}}
    """
    if isinstance(exc, ServiceError):
        kind = exc.kind
    elif isinstance(exc, SLRError):
        kind = type(exc).__name__ if not isinstance(exc, TermError) else "BadRequest"
    else:
        kind = "InternalError"
    err: dict[str, Any] = {"kind": kind, "status": error_status(exc) if kind != "InternalError"
                           else 500}
    if isinstance(exc, SLRSyntaxError):
        err.update(message=exc.message, line=exc.line, column=exc.column,
                   source_line=exc.source_line, filename=exc.filename)
    else:
        err["message"] = str(exc) if kind != "InternalError" else \
            f"internal error ({type(exc).__name__}); the server log has the details"
    if isinstance(exc, SLREvaluationError):
        try:
            err["term"] = encode_term(exc.term)
        except SLRError:
            pass
    index = getattr(exc, "index", None)
    if isinstance(exc, EventRejected) and isinstance(index, int):
        err["index"] = index
    if isinstance(exc, SLRCancelled) and exc.reason:
        err["reason"] = exc.reason   # the database server's words
    return {"error": err}


def error_from_body(body: Any, status: int) -> SLRError:
    """The exception an error response stands for, of the class the server raised when it is
    an slr_sql error class (``SLRSyntaxError`` with its line and column, ...), else a
    :class:`ServiceError` (a :class:`ServiceUnavailable` for a 503).

    >>> type(error_from_body({"error": {"kind": "Unavailable", "message": "x"}}, 503)).__name__
    'ServiceUnavailable'
    """
    err = body.get("error") if isinstance(body, dict) else None
    if not isinstance(err, dict):
        message = f"HTTP {status} without an error description"
        return ServiceUnavailable(message, status) if status == 503 else \
            ServiceError(message, kind="BadRequest", status=status)
    kind = str(err.get("kind", "SLRError"))
    message = str(err.get("message", ""))
    if kind == "SLRSyntaxError":
        return SLRSyntaxError(message, line=_int(err.get("line")), column=_int(err.get("column")),
                              source_line=str(err.get("source_line") or ""),
                              filename=str(err.get("filename") or "<string>"))
    if kind == "SLREvaluationError":
        term = None
        if "term" in err:
            try:
                term = decode_term(err["term"])
            except SLRError:
                term = None
        return SLREvaluationError(term, message)
    cls = getattr(slr_sql, kind, None)
    if isinstance(cls, type) and issubclass(cls, SLRError) and kind not in ("TermError",):
        try:
            exc = cls(message)
        except TypeError:
            exc = None
        if exc is not None:
            if isinstance(exc, EventRejected) and isinstance(err.get("index"), int):
                exc.index = err["index"]
            if isinstance(exc, SLRCancelled) and isinstance(err.get("reason"), str):
                exc.reason = err["reason"]
            return exc
    if kind == "Unavailable" or status == 503:
        return ServiceUnavailable(message, status, kind)
    if kind == "Forbidden":
        return ServiceForbidden(message)
    return ServiceError(message, kind=kind, status=status)


def _int(value: Any) -> int:
    return value if isinstance(value, int) and not isinstance(value, bool) else 0
