"""The client of ``slr serve``: :func:`connect` gives an object with the methods of a local
KnowledgeBase, returning the same Python values and raising the same SLRError classes.

>>> import slr_sql
>>> from slr_sql.service.background import BackgroundServer
>>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
>>> kb = slr_sql.connect(server.url)      # e.g. slr_sql.connect("http://127.0.0.1:8765")
>>> kb.add("obj(cup1, cup, red)^2.0")
>>> kb.query("obj(O, cup, C)^T")
[{'O': Atom('cup1'), 'C': Atom('red'), 'T': 2.0}]
>>> kb.close(); server.stop(); server.kb.close()

``server`` is a :class:`~slr_sql.service.background.BackgroundServer`: the service of a
knowledge base this program holds, here a memory store on a manual clock (the examples of
this module use one). ``slr serve DB`` is the service as a program.

What differs from a local knowledge base:

* ``add_many`` of more events than fit in one request body (the server's ``max_body``) sends
  several requests, each one transaction; ``atomic=True`` sends one request or fails.
* ``submit`` returns a :class:`RemotePendingQuery`, a ``concurrent.futures.Future`` that one
  background thread per pending query completes by long-polling the server.
* ``define`` raises :class:`~slr_sql.service.errors.ServiceError` (Python predicates run in
  the server's process); ``sql(write=True)`` is refused (the service runs read-only SQL).
* ``pending()`` lists the queries this client submitted that are still waiting.
* ``subscribe(max_queue=)`` is capped by the server's ``subscribe_queue``; answers travel
  in frames of up to ``subscribe_batch`` answers (an attribute of the client, 256).
* Failures to reach the server, and its 503 answers that no slr_sql class names, are
  :class:`~slr_sql.service.errors.ServiceUnavailable`: a ``ServiceError`` (``kind``
  ``"Unavailable"``, ``status`` 0 when no answer came) and an :class:`~slr_sql.SLRUnavailable`
  (retry later), for requests and subscriptions alike. But a connection that broke after a
  request that may change the store (an add, a load, a mark) was sent in full, or that
  got no answer within the timeout once sent, is a
  :class:`~slr_sql.service.errors.ServiceOutcomeUnknown`: no SLRUnavailable, since the
  server may have applied it. An https:// server whose certificate
  the client refuses is a ``ServiceError`` of ``kind`` ``"CertificateNotTrusted"`` (it trusts
  ``$SSL_CERT_FILE`` and ``$SSL_CERT_DIR``, else certifi's bundle; docs/service.md, TLS).

Both this client and a local knowledge base implement :class:`slr_sql.KnowledgeBaseAPI`.
"""
from __future__ import annotations

import collections
import functools
import inspect
import logging
import math
import numbers
import os
import ssl
import threading
import time
import weakref
from concurrent.futures import Future, InvalidStateError
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Mapping
from urllib.parse import quote, urlsplit

import slr_sql  # noqa: F401  (the examples' slr_sql.open and slr_sql.connect)
from slr_sql import EventRejected, SLRError, SLRTimeout, SLRUnavailable
from slr_sql.errors import STOPPED_BY_CALLER
from slr_sql.api import PendingQueryAPI, ProgramInfo, SolutionsAPI, SubscriptionAPI

from .encoding import (TermError, decode_answers, decode_plain, dumps, encode_args,
                       encode_arguments, encode_term, loads)
from ..kb import (check_define, check_event_type, check_load, check_mark, check_program_name,
                  check_query_options, check_sql, not_event_text, read_program_file,
                  unbindable_parameter, unforeseen_failure)
from ..arguments import check_callable, check_flag, wait_seconds
from ..buffers import analyze, check_buffer_policy
from ..terms import format_term
from ..plans import argument_term, check_goal, not_a_variable
from ..subscriptions.hub import DEFAULT_MAX_QUEUE, check_subscription
from ..encoding import Unencodable
from ..encoding import encode as encode_stored
from ..store.checks import BadEvent, check_times, event_arguments, event_rejection, shown
from ..subscriptions.registry import no_subscription
from .auth import check_token_text
# (the server of this module's examples: a knowledge base served from a thread)
from .background import BackgroundServer  # noqa: F401
from .errors import (ServiceError, ServiceOutcomeUnknown, ServiceUnavailable, error_from_body,
                     parse_retry_after)
from .http_pool import AnswerLost, AnswerTimeout, HttpPool, RequestInvalid, RequestNotSent

__all__ = ["connect", "RemoteKnowledgeBase", "RemotePendingQuery", "RemoteSolutions",
           "RemoteSubscription", "RemoteWait"]

log = logging.getLogger("slr_sql.service.client")

POLL_WAIT = 25.0          # seconds one long-poll asks the server to wait
# the POSTs that change nothing in the store (every GET changes nothing either): a connection
# that broke after one was sent leaves nothing to doubt, so it is a ServiceUnavailable
# (retry at will); a POST or DELETE not listed may have been applied (ServiceOutcomeUnknown)
_CHANGES_NOTHING = frozenset({"/query", "/explain", "/warnings", "/sql", "/submit"})
DEFAULT_MAX_BODY = 1 << 20
FLEET_ROWS = 1000         # shipped rows per request (well within the default body limit)


def connect(url: str, token: str | None = None, *, timeout: float = 60.0) -> "RemoteKnowledgeBase":
    """A client for the ``slr serve`` at ``url``; ``token`` defaults to ``$SLR_TOKEN``.
    ``timeout`` bounds how long one request may take beyond the query's own timeout.

    >>> local = slr_sql.open(clock=slr_sql.ManualClock(10))
    >>> server = BackgroundServer(local, token="secret").start()
    >>> kb = connect(server.url, token="secret"); kb.add("p(1)^1"); kb.query("p(X)^T")
    [{'X': 1, 'T': 1.0}]
    >>> with connect(server.url, token="wrong") as stranger: stranger.query("p(X)^T")
    Traceback (most recent call last):
    ...
    slr_sql.service.errors.ServiceError: a valid token is required (Authorization: Bearer TOKEN; the server's --token or SLR_TOKEN)
    >>> kb.close(); server.stop(); local.close()
    """
    return RemoteKnowledgeBase(url, token=token, timeout=timeout)


# the keyword options of connect() after its url and token (slr_sql.connect checks them)
CONNECT_OPTIONS = tuple(name for name, parameter in inspect.signature(connect).parameters.items()
                        if parameter.kind is inspect.Parameter.KEYWORD_ONLY)


def _reads_answer(method: Callable) -> Callable:
    """A client method that reads the server's answer: an answer that is not what slr serve
    answers (another service at the URL, a proxy's page, another version) is a
    :class:`ServiceError` saying so, never a KeyError or TypeError from reading it, and
    never taken for a success (an add that stored nothing). Errors raised before the server
    answered (the arguments) are left as they are."""
    @functools.wraps(method)
    def reading(self: "RemoteKnowledgeBase", *args: Any, **kwargs: Any) -> Any:
        self._answered.path = None
        try:
            return method(self, *args, **kwargs)
        except (KeyError, TypeError, ValueError, AttributeError, IndexError, TermError) as exc:
            path = getattr(self._answered, "path", None)
            if path is None:
                raise
            what = f"no {exc.args[0]!r}" if isinstance(exc, KeyError) and exc.args else \
                str(exc).splitlines()[0] if str(exc) else "an unexpected shape"
            raise ServiceError(f"{path}: the answer of {self.url} is not what slr serve answers "
                               f"({what}); is the URL that of an slr serve of this version?",
                               kind="InternalError", status=0) from None
    return reading


def _expect(reply: Any, key: str, kind: type | tuple) -> Any:
    """``reply[key]`` when it is of ``kind`` (else the error :func:`_reads_answer` words)."""
    value = reply[key]
    if not isinstance(value, kind) or (isinstance(value, bool) and kind in (int, float)):
        raise TypeError(f"{key!r} is {type(value).__name__}")
    return value


def _service_url(url: Any, httpx: Any) -> str:
    """``url`` if it can name an ``slr serve`` (http:// or https://, a host, a port that is a
    number from 0 to 65535), else an :class:`SLRError` saying what is wrong with it.

    >>> import httpx; _service_url("http://127.0.0.1:8765", httpx)
    'http://127.0.0.1:8765'
    >>> _service_url("http://127.0.0.1:port", httpx)
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: not a service URL (http://HOST:PORT or https://...): http://127.0.0.1:port (Port could not be cast to integer value as 'port')
    """
    shape = "not a service URL (http://HOST:PORT or https://...)"
    if not isinstance(url, str) or not url.startswith(("http://", "https://")):
        raise SLRError(f"{shape}: {url}")
    try:
        parts = urlsplit(url)
        parts.port   # (raises for a port that is not a number in range)
        httpx.URL(url)
    except (ValueError, httpx.InvalidURL) as exc:
        raise SLRError(f"{shape}: {url} ({exc})") from None
    if not parts.hostname:
        raise SLRError(f"{shape}: {url} (no host)")
    if parts.username is not None or parts.password is not None:
        # (they would not be sent: the service's credential is a token)
        raise SLRError(f"{shape}: {parts.scheme}://...@{parts.hostname} (a user or password "
                       f"in the URL is not sent; give the server's token as token= or "
                       f"$SLR_TOKEN)")
    return url


def _tls_context() -> "ssl.SSLContext":
    """The TLS context of a client of an https:// URL, for its requests (its connection
    pool) and its subscriptions (websockets), so that both trust the same CAs: the CAs of
    ``$SSL_CERT_FILE`` (a PEM file) and ``$SSL_CERT_DIR`` (a folder named by ``openssl
    rehash``), both when both are set, as OpenSSL does; with neither, certifi's bundle (what
    the client trusted when httpx made its requests).

    >>> _tls_context().verify_mode == ssl.CERT_REQUIRED
    True
    """
    cafile = os.environ.get("SSL_CERT_FILE") or None
    capath = os.environ.get("SSL_CERT_DIR") or None
    if cafile is None and capath is None:
        import certifi
        return ssl.create_default_context(cafile=certifi.where())
    try:
        return ssl.create_default_context(cafile=cafile, capath=capath)
    except (OSError, ssl.SSLError) as exc:
        named = " and ".join(f"{name}={value}" for name, value in
                             (("SSL_CERT_FILE", cafile), ("SSL_CERT_DIR", capath)) if value)
        raise SLRError(f"cannot read the CA certificates of {named}: "
                       f"{exc.strerror or exc}") from None


def _refused_certificate(exc: BaseException | None) -> "ssl.SSLCertVerificationError | None":
    """The refusal of the server's certificate that ``exc`` is or was raised from, if any."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, ssl.SSLCertVerificationError):
            return exc
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return None


def _not_trusted(url: str, refused: "ssl.SSLCertVerificationError") -> ServiceError:
    """A certificate this client refuses: a ServiceError with status 0 like every failure to
    reach the server, but not ``Unavailable`` (which says the same call may succeed later):
    no retry makes it pass, only trusting the CA (or a certificate for the URL's host)."""
    reason = str(refused.verify_message or refused.reason or refused).rstrip(".")
    hint = "it names another host" if refused.verify_code in (62, 64) else \
        "give the CA that signed it in $SSL_CERT_FILE or $SSL_CERT_DIR"   # 62, 64: a mismatch
    return ServiceError(f"the TLS certificate of {url} is not trusted ({reason}): {hint}",
                        kind="CertificateNotTrusted", status=0)


def _not_subscribed(url: str, exc: BaseException, doing: str = "subscribe") -> ServiceError:
    """The error of a WebSocket to ``url`` that could not be opened (``exc``): a
    :class:`ServiceUnavailable` when no server answered or it answered 503, as for a request;
    another HTTP status refusing the handshake (a server that is no slr serve, a proxy) is a
    :class:`ServiceError` with that status, which a retry would meet again. ``doing``: what
    the WebSocket was for, in the message.

    >>> print(_not_subscribed("ws://127.0.0.1:1/subscribe", ConnectionRefusedError(111, "refused")))
    cannot subscribe at ws://127.0.0.1:1/subscribe: [Errno 111] refused
    """
    response = getattr(exc, "response", None)
    status = getattr(response, "status_code", None)
    message = f"cannot {doing} at {url}: {exc}"
    if isinstance(status, int) and status != 503:
        return ServiceError(message, kind="BadRequest", status=status)
    headers = getattr(response, "headers", None)
    told = parse_retry_after(headers.get("Retry-After")) if headers is not None else None
    return ServiceUnavailable(message, status=status or 0, retry_after=told)


class RemoteKnowledgeBase:
    """A knowledge base served by ``slr serve``; see :func:`connect`.

    >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
    >>> with RemoteKnowledgeBase(server.url) as kb:
    ...     kb.add("p(1)^1"); kb.query("p(X)^T"), kb.url == server.url
    ([{'X': 1, 'T': 1.0}], True)
    >>> kb.closed
    True
    >>> server.stop(); server.kb.close()
    """

    def __init__(self, url: str, token: str | None = None, *, timeout: float = 60.0):
        try:
            import httpx
        except ImportError:  # pragma: no cover - the service extra is missing
            raise SLRError("slr_sql.connect needs the service extra: "
                           "pip install 'slr_sql[service]'") from None
        self.url = _service_url(url, httpx).rstrip("/")
        if token is None:
            token = os.environ.get("SLR_TOKEN") or None
        if token is not None and not isinstance(token, str):   # (a secret: not shown)
            raise SLRError(f"connect: token must be text (a str), not of type "
                           f"{type(token).__name__}")
        if token:
            check_token_text(token)
        self._token = token
        self._headers = {"Content-Type": "application/json"}
        if token:
            # the header's bytes (a token beyond ASCII as UTF-8), each byte one character
            # as HTTP libraries write a header's text (ISO-8859-1)
            self._headers["Authorization"] = f"Bearer {token}".encode("utf-8").decode("latin-1")
        try:
            self.timeout = float(timeout)
        except (TypeError, ValueError):
            self.timeout = math.nan
        if not 0 < self.timeout < math.inf:
            raise SLRError(f"timeout must be a positive number of seconds, not {timeout!r}")
        # TLS only for https://: for http:// the client would still load the CA bundle
        # (~50-70 ms of CPU per connect). One context for requests and subscriptions alike.
        self._tls = _tls_context() if self.url.startswith("https://") else None
        self._pool = HttpPool(self.url, self._headers, tls=self._tls, timeout=self.timeout,
                              connect_timeout=min(10.0, self.timeout))
        self._limits: dict | None = None
        self._answered = threading.local()   # .path: the request the last answer was of
        self.subscribe_batch = 256        # answers per WebSocket frame at most (1..1000)
        self._pending: dict[RemotePendingQuery, None] = {}   # waiting, in submission order
        # the answers of solutions() not ended yet: their WebSockets hold queries on the
        # server, which close() ends (the ones a program dropped are closed as collected)
        self._solutions: weakref.WeakSet[RemoteSolutions] = weakref.WeakSet()
        self._lock = threading.Lock()
        self.closed = False

    def __repr__(self) -> str:
        return f"<RemoteKnowledgeBase {self.url}>"

    # -- transport ------------------------------------------------------------------------------
    def _request(self, method: str, path: str, body: Any = None, *,
                 params: dict | None = None, timeout: float | None = None,
                 ok: tuple = (200,), content: bytes | None = None) -> tuple[int, Any]:
        if self.closed:
            raise SLRError("the connection to the knowledge base is closed")
        if body is not None:
            content = dumps(body)
        try:
            response = self._pool.request(method, path, content, params=params, timeout=timeout)
        except AnswerTimeout as exc:
            if not exc.sent:      # (no connection in time: nothing reached the server)
                raise ServiceUnavailable(f"cannot reach slr serve at {self.url}: {exc}",
                                         status=0) from None
            waited = timeout if timeout is not None else self.timeout
            if method != "GET" and path not in _CHANGES_NOTHING:
                # (sent whole: the server may be applying it right now)
                raise ServiceOutcomeUnknown(
                    f"{method} {path}: no answer from {self.url} within {waited:g} s after the "
                    f"request was sent: the server may or may not have applied it (sending "
                    f"it again may apply it twice)") from None
            raise ServiceError(f"no answer from {self.url} within {waited:g} s",
                               kind="RequestTimeout", status=0) from None
        except (RequestNotSent, AnswerLost) as exc:
            refused = _refused_certificate(exc)
            if refused is not None:
                raise _not_trusted(self.url, refused) from None
            if isinstance(exc, AnswerLost) and method != "GET" and \
                    path not in _CHANGES_NOTHING:   # (sent whole, and it may change the store)
                raise ServiceOutcomeUnknown(
                    f"{method} {path}: the connection to {self.url} broke after the request "
                    f"was sent, before its answer ({exc}): the server may or may not have "
                    f"applied it (sending it again may apply it twice)") from None
            raise ServiceUnavailable(f"cannot reach slr serve at {self.url}: {exc}",
                                     status=0) from None
        except RequestInvalid as exc:
            raise ServiceError(f"{method} {path}: {exc}", kind="BadRequest", status=0) from None
        except RuntimeError as exc:  # the client was closed by another thread
            raise SLRError(f"the connection to {self.url} is closed ({exc})") from None
        try:
            data = loads(response.content) if response.content else None
        except (ValueError, UnicodeDecodeError):
            data = None
        if response.status in ok:
            if not isinstance(data, dict):
                raise ServiceError(f"{method} {path}: the server's answer is not JSON "
                                   f"(HTTP {response.status})", kind="InternalError",
                                   status=response.status)
            self._answered.path = f"{method} {path}"
            return response.status, data
        # (a 503's wait, if it says one: else the class's default)
        told = parse_retry_after(response.headers.get("retry-after")) \
            if response.status == 503 else None
        if data is None:   # (not the server's words: a proxy's, or the server's own limit)
            text = response.text[:200].strip()
            message = f"HTTP {response.status} from {self.url}{path}" + \
                (f": {text}" if text else "")
            if response.status == 503:   # (beyond --max-connections: may pass)
                raise ServiceUnavailable(message, 503, retry_after=told)
            raise ServiceError(message, kind="BadRequest", status=response.status)
        error = error_from_body(data, response.status)
        if told is not None and isinstance(error, SLRUnavailable):
            error.retry_after = told
        raise error

    def _post(self, path: str, body: dict, timeout: float | None = None) -> dict:
        return self._request("POST", path, body, timeout=timeout)[1]

    def _get(self, path: str, params: dict | None = None) -> dict:
        return self._request("GET", path, params=params)[1]

    def _read_timeout(self, query_timeout: float | None) -> float:
        # (float(): a numpy float32 timeout would keep its type, which a socket refuses)
        return self.timeout + (0.0 if query_timeout is None else float(query_timeout))

    def limits(self) -> dict:
        """The server's limits (``GET /health``), fetched once.

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url)
        >>> kb.limits()["max_body"], kb.limits()["max_query_time"]
        (1048576, 30.0)
        >>> kb.close(); server.stop(); server.kb.close()
        """
        if self._limits is None:
            limits = self.health().get("limits")
            self._limits = limits if isinstance(limits, dict) else {}
        return self._limits

    def health(self) -> dict:
        """``{"status": "ok", "version", "api", "limits"}`` of the server.

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url)
        >>> health = kb.health(); health["status"], health["api"]
        ('ok', '1')
        >>> kb.close(); server.stop(); server.kb.close()
        """
        return self._get("/health")

    # -- lifecycle ------------------------------------------------------------------------------
    def close(self) -> None:
        """Close the connection; submitted queries still waiting fail with SLRError.

        >>> kb = slr_sql.connect("http://127.0.0.1:8765"); kb.close()
        >>> kb.query("true")       # (refused here: nothing is sent)
        Traceback (most recent call last):
        ...
        slr_sql.errors.SLRError: the connection to the knowledge base is closed
        """
        if self.closed:
            return
        self.closed = True
        with self._lock:
            pending = list(self._pending)
        for p in pending:
            p._fail(SLRError("the connection to the knowledge base was closed"))
        with self._lock:
            solutions = list(self._solutions)
        for answers in solutions:
            answers._shut(SLRError("the connection to the knowledge base was closed"))
        self._pool.close()

    def __enter__(self) -> "RemoteKnowledgeBase":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # -- events ---------------------------------------------------------------------------------
    @_reads_answer
    def add(self, text: str) -> None:
        """Add one event written in SLR syntax (``p(..)^T`` or ``p(..)^[S,E]``).

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url)
        >>> kb.add("seen(cup1)^2"); kb.query("seen(X)^T")
        [{'X': Atom('cup1'), 'T': 2.0}]
        >>> kb.close(); server.stop(); server.kb.close()
        """
        if not isinstance(text, str):
            raise not_event_text(text)
        _expect(self._post("/add", {"event": text}), "added", int)

    @_reads_answer
    def add_event(self, name: str, args: Iterable[Any], start: float,
                  end: float | None = None) -> None:
        """Add one event from Python values (``str`` is an atom, ``String`` a string).

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url)
        >>> kb.add_event("seg", ["cup1", [0.4, 0.1, 0.9]], start=3.0, end=3.5)
        >>> kb.query("seg(O, L)^[S, E]")
        [{'O': Atom('cup1'), 'L': [0.4, 0.1, 0.9], 'S': 3.0, 'E': 3.5}]
        >>> kb.close(); server.stop(); server.kb.close()
        """
        if end is None:
            end = start
        if not isinstance(name, str):     # (refused in a local knowledge base's words)
            raise EventRejected(f"add_event: event name must be an atom (a str), not "
                                f"{shown(name)}")
        _expect(self._post("/add_event", _event_object(name, args, start, end, "")), "added",
                int)

    @_reads_answer
    def add_many(self, events: Iterable[Any], atomic: bool = False) -> list[EventRejected]:
        """Add many events (SLR strings or ``(name, args, start, end)`` tuples); returns the
        rejected ones, each with ``.index``. Batches larger than the server's body limit go in
        several requests (one transaction each) unless ``atomic``.

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url)
        >>> rejected = kb.add_many(["p(1)^1", ("p", [2], 2.0, 2.0), "p(^3"])
        >>> [e.index for e in rejected], kb.query("p(X)^T")
        ([2], [{'X': 1, 'T': 1.0}, {'X': 2, 'T': 2.0}])
        >>> kb.close(); server.stop(); server.kb.close()
        """
        check_flag("add_many: atomic", atomic)
        _iterable(events, "add_many")
        items: list = []
        given: list = []                # the caller's events (a rejection's .event)
        rejected: list[EventRejected] = []
        for i, ev in enumerate(events):
            given.append(ev)
            if isinstance(ev, str):
                items.append(ev)
                continue
            try:
                items.append(_tuple_object(ev, i))
            except SLRError as exc:
                if atomic:
                    raise
                rejected.append(_rejected(exc, i))
                items.append(None)          # a hole keeps the indexes of the others
        budget = int(self.limits().get("max_body", DEFAULT_MAX_BODY)) - 1024
        carried = [0, 0]    # the items [first, end) of the request in flight
        try:
            rejected += self._send_events(items, 0, atomic, budget, carried)
        except ServiceOutcomeUnknown as exc:
            exc.carried = (carried[0], carried[1])
            raise
        rejected.sort(key=lambda e: e.index if isinstance(e.index, int) else len(items))
        for rejection in rejected:      # (as a local knowledge base sets it)
            rejection.event = given[rejection.index] \
                if isinstance(rejection.index, int) else None
        return rejected

    def _send_events(self, items: list, offset: int, atomic: bool, budget: int,
                     carried: list[int]) -> list[EventRejected]:
        """POST /add_many for ``items`` (None: a hole), halving what does not fit;
        ``carried``: set to the [first, end) indexes of the items of each request sent."""
        present = [i for i, item in enumerate(items) if item is not None]
        if not present:
            return []
        request: dict[str, Any] = {"events": [items[i] for i in present]}
        if atomic:                  # absent is false (and keeps the body free of booleans)
            request["atomic"] = True
        body = dumps(request)
        if len(body) > budget and not atomic and len(present) > 1:
            half = len(items) // 2
            return (self._send_events(items[:half], offset, atomic, budget, carried)
                    + self._send_events(items[half:], offset + half, atomic, budget, carried))
        carried[:] = offset, offset + len(items)
        reply = self._request("POST", "/add_many", content=body)[1]
        _expect(reply, "accepted", int)
        out = []
        for r in _expect(reply, "rejected", list):
            exc = EventRejected(str(r.get("message", "")))
            index = r.get("index")
            exc.index = offset + present[index] if isinstance(index, int) and \
                0 <= index < len(present) else None
            out.append(exc)
        return out

    # -- program ----------------------------------------------------------------------------------
    @_reads_answer
    def load(self, text: str, filename: str = "<string>", *, name: str = "main",
             replace: bool = False) -> None:
        """Add program text to the program ``name`` (all or nothing); ``replace=True`` swaps
        that program for ``text``.

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url)
        >>> kb.load("color(O,C)^T :- prev(obj(O,_,C)^Z, T)."); kb.add("obj(cup1, cup, red)^2.0")
        >>> kb.query("color(cup1, C)^5")
        [{'C': Atom('red')}]
        >>> kb.close(); server.stop(); server.kb.close()
        """
        body: dict[str, Any] = {"text": text,
                                "name": check_load(text, filename, name, replace)}
        if filename != "<string>":
            body["filename"] = filename
        if replace:
            body["replace"] = True
        _expect(self._post("/load", body), "loaded", bool)

    def load_file(self, path: str | Path, *, name: str = "main",
                  replace: bool = False) -> None:
        """Read a program file here and load its text on the server.

        >>> import pathlib, tempfile
        >>> rules = pathlib.Path(tempfile.mkdtemp()) / "rules.slr"
        >>> _ = rules.write_text("big(X) :- size(X, S)^_, S > 2.")
        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url); kb.load_file(rules); kb.add("size(box, 3)^1")
        >>> kb.query("big(X)"), kb.programs()["main"].filenames == (str(rules),)
        ([{'X': Atom('box')}], True)
        >>> kb.close(); server.stop(); server.kb.close()
        """
        self.load(read_program_file(path), str(path), name=name, replace=replace)

    @_reads_answer
    def unload(self, name: str) -> None:
        """Remove the program loaded under ``name``.

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url)
        >>> kb.load("tea(green).", name="tea"); list(kb.programs())
        ['tea']
        >>> kb.unload("tea"); kb.programs()
        {}
        >>> kb.close(); server.stop(); server.kb.close()
        """
        _expect(self._post("/unload", {"name": check_program_name(name)}), "unloaded", str)

    @_reads_answer
    def programs(self) -> dict[str, ProgramInfo]:
        """The named programs stored in the file, in load order of their first text.

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url)
        >>> kb.load("tea(green).", name="tea"); info = kb.programs()["tea"]; info.source, info.texts
        ('tea(green).', 1)
        >>> kb.close(); server.stop(); server.kb.close()
        """
        out: dict[str, ProgramInfo] = {}
        for name, info in decode_plain(_expect(self._get("/programs"), "programs",
                                               dict)).items():
            try:
                out[name] = ProgramInfo(str(info["name"]), str(info["source"]),
                                        int(info["texts"]), tuple(info["filenames"]),
                                        info["loaded_at"])
            except (KeyError, TypeError, ValueError):
                raise ServiceError(f"GET /programs: not a program description: {info!r}",
                                   kind="InternalError", status=0) from None
        return out

    @_reads_answer
    def event_rules(self) -> list[dict[str, Any]]:
        """The event rules in force on the server, in the order they run.

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url)
        >>> kb.load("c(X) <- a(X) seq b(X)."); kb.add_many(["a(1)^1", "b(1)^2"])
        []
        >>> [(rule["head"], rule["detections"]) for rule in kb.event_rules()]
        [('c/1', 1)]
        >>> kb.close(); server.stop(); server.kb.close()
        """
        return decode_plain(_expect(self._get("/event_rules"), "event_rules", list))

    def define(self, name: str, arity: int, fn: Callable) -> None:
        """Not available remotely: Python predicates must run in the server's process.

        >>> kb = slr_sql.connect("http://127.0.0.1:8765")   # (refused here: nothing is sent)
        >>> kb.define("double", 2, lambda x, y: (x, 2 * x))
        Traceback (most recent call last):
        ...
        slr_sql.service.errors.ServiceError: define() is not available over the network: register Python predicates in the process that runs the server
        >>> kb.close()
        """
        check_define(name, arity, fn)   # (the arguments a local knowledge base refuses first)
        raise ServiceError("define() is not available over the network: register Python "
                           "predicates in the process that runs the server",
                           kind="NotImplemented")

    # -- queries --------------------------------------------------------------------------------
    @_reads_answer
    def query(self, goal: str, at: float | None = None, args: dict | None = None,
              timeout: float | None = None, max_steps: int | None = None,
              limit: int | None = None, wait: bool = False,
              robot: str | None = None) -> list[dict[str, Any]]:
        """Answer ``goal`` on the server (see ``KnowledgeBase.query``); ``timeout`` is
        capped by the server's ``max_query_time``.

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url); kb.add_many(["p(1)^1", "p(2)^2", "p(3)^3"])
        []
        >>> kb.query("p(X)^T, X >= 2"), kb.query("between(1, inf, X)", limit=2)
        ([{'X': 2, 'T': 2.0}, {'X': 3, 'T': 3.0}], [{'X': 1}, {'X': 2}])
        >>> kb.close(); server.stop(); server.kb.close()
        """
        check_query_options(at=at, timeout=timeout, limit=limit, robot=robot, args=args,
                            max_steps=max_steps, wait=wait)
        if wait:  # synchronized: long-polls, however long the wait (as kb.query does it)
            return self.submit(goal, at=at, args=args, timeout=timeout, robot=robot).result()
        body = _goal_body(goal, at, args, timeout)
        if limit is not None:
            body["limit"] = limit
        if max_steps is not None:
            body["max_steps"] = max_steps
        if robot is not None:
            body["robot"] = robot
        reply = self._post("/query", body, timeout=self._read_timeout(timeout))
        return decode_answers(_expect(reply, "answers", list))

    # -- fleets (slr fleet push / status to an `slr serve` fleet store) -------------------------
    @_reads_answer
    def fleet_positions(self, robot: str) -> dict[tuple[str, int], int]:
        """Per event type, the last sequence of ``robot``'s store the server's store holds.

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url); kb.fleet_positions("r1")
        {}
        >>> robot = slr_sql.open(clock=slr_sql.ManualClock(10)); robot.add("seen(pallet7)^3")
        >>> kb.fleet_receive("r1", [("seen", 1, robot.store.fleet_read_after("seen", 1, 0, 100))])
        1
        >>> kb.fleet_positions("r1")
        {('seen', 1): 1}
        >>> robot.close(); kb.close(); server.stop(); server.kb.close()
        """
        reply = self._request("GET", "/fleet/positions", params={"robot": robot})[1]
        return {(str(n), int(a)): int(p) for n, a, p in _expect(reply, "positions", list)}

    @_reads_answer
    def fleet_receive(self, robot: str, batches: list, marks: dict | None = None,
                      pending: int | None = None, head_arrival: float | None = None,
                      after: dict | None = None, resync: list | None = None,
                      relayed: dict | None = None) -> int:
        """Send one shipment of ``robot`` (see :func:`slr_sql.shipping.receive`); returns
        the rows the server stored. Rows go in requests of at most FLEET_ROWS (each stored
        exactly once with its position), within the server's body limit. ``after``:
        ``{(name, arity): position}``, the positions the batches were read after (a
        ``Conflict`` error when the server's store holds less: restored or replaced).
        ``relayed``: ``{robot: {"p/N": t}}``, the marks of robots whose rows the sender
        relays.

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url)
        >>> robot = slr_sql.open(clock=slr_sql.ManualClock(10)); robot.add("seen(pallet7)^3")
        >>> rows = robot.store.fleet_read_after("seen", 1, 0, 100); kb.fleet_receive("r1", [("seen", 1, rows)])
        1
        >>> kb.fleet_receive("r1", [("seen", 1, rows)]), kb.query("origin(R, seen(P)^T)")
        (0, [{'R': Atom('r1'), 'P': Atom('pallet7'), 'T': 3.0}])
        >>> robot.close(); kb.close(); server.stop(); server.kb.close()
        """
        stored = 0
        # (piece, the position its rows were read after: the previous piece's last seq)
        pieces: list[tuple[list, list | None]] = []
        for n, a, rows in batches:
            for i in range(0, max(len(rows), 1), FLEET_ROWS):
                since = None if after is None else                     after.get((n, a), 0) if i == 0 else rows[i - 1][0]
                pieces.append(([[n, a, rows[i:i + FLEET_ROWS]]],
                               None if since is None else [[n, a, since]]))
        pieces = pieces or [([], None)]     # (a contact with marks alone: one request)
        for k, (piece, piece_after) in enumerate(pieces):
            body: dict[str, Any] = {"robot": robot, "batches": piece}
            if piece_after is not None:
                body["after"] = piece_after
            if resync:
                body["resync"] = [list(r) for r in resync]
            if k == len(pieces) - 1:
                if marks:
                    body["marks"] = marks
                if relayed:
                    body["relayed"] = relayed
                if pending is not None:
                    body["pending"] = pending
                if head_arrival is not None:
                    body["head_arrival"] = head_arrival
            stored += _expect(self._post("/fleet/receive", body), "stored", int)
        return stored

    @_reads_answer
    def fleet_status(self) -> list[dict[str, Any]]:
        """Per robot that shipped to the server's store: its contact row.

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url)
        >>> robot = slr_sql.open(clock=slr_sql.ManualClock(10)); robot.add("seen(pallet7)^3")
        >>> kb.fleet_receive("r1", [("seen", 1, robot.store.fleet_read_after("seen", 1, 0, 100))], pending=0)
        1
        >>> [(row["robot"], row["shipped"], row["pending"]) for row in kb.fleet_status()]
        [('r1', 1, 0)]
        >>> robot.close(); kb.close(); server.stop(); server.kb.close()
        """
        return [dict(r) for r in _expect(self._get("/fleet/status"), "robots", list)]

    @_reads_answer
    def fleet_retire(self, robot: str) -> dict[str, Any]:
        """Retire ``robot`` from the server's fleet store (see
        :func:`slr_sql.shipping.retire`; the server's own token only).

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url); kb.fleet_receive("r1", [], {"seen/1": 5.0}, pending=0)
        0
        >>> done = kb.fleet_retire("r1"); done["already"], [r["retired_at"] is not None for r in kb.fleet_status()]
        (False, [True])
        >>> kb.fleet_reinstate("r1")
        {'robot': 'r1', 'reinstated': True}
        >>> kb.close(); server.stop(); server.kb.close()
        """
        reply = self._post("/fleet/retire", {"robot": robot})
        return {"robot": _expect(reply, "robot", str),
                "retired_at": float(_expect(reply, "retired_at", (int, float))),
                "already": _expect(reply, "already", bool),
                "raised": dict(_expect(reply, "raised", dict))}

    @_reads_answer
    def fleet_reinstate(self, robot: str) -> dict[str, Any]:
        """Take back the retirement of ``robot`` on the server's fleet store (see
        :func:`slr_sql.shipping.reinstate`; the server's own token only).

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url); kb.fleet_receive("r1", [], {"seen/1": 5.0}, pending=0)
        0
        >>> kb.fleet_reinstate("r1")      # (not retired: nothing changes)
        {'robot': 'r1', 'reinstated': False}
        >>> kb.close(); server.stop(); server.kb.close()
        """
        reply = self._post("/fleet/reinstate", {"robot": robot})
        return {"robot": _expect(reply, "robot", str),
                "reinstated": _expect(reply, "reinstated", bool)}

    @_reads_answer
    def submit(self, goal: str, at: float | None = None, id: str | None = None,
               args: dict | None = None, timeout: float | None = None,
               callback: Callable[[Any], Any] | None = None,
               robot: str | None = None) -> PendingQueryAPI:
        """A synchronized query on the server: a Future answered with the answer list.

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url); kb.add("p(a)^11")
        >>> p = kb.submit("findall(X, p(X)^_, L)", at=12); p.done()
        False
        >>> kb.mark_complete("p/1", 12); p.result(timeout=5)
        [{'L': [Atom('a')]}]
        >>> kb.close(); server.stop(); server.kb.close()
        """
        check_query_options(at=at, timeout=timeout, robot=robot, args=args, id=id,
                            callback=callback)
        body = _goal_body(goal, at, args, timeout)
        if id is not None:
            body["id"] = id
        if robot is not None:
            body["robot"] = robot
        status, reply = self._request("POST", "/submit", body, ok=(200, 202))
        pending = RemotePendingQuery(self, _expect(reply, "handle", str), reply.get("id"),
                                     goal, at)
        if callback is not None:
            pending.add_done_callback(callback)
        pending._settle(status, reply)
        if not pending.done():
            pending._start()
        return pending

    async def ask(self, goal: str, at: float | None = None, id: str | None = None,
                  args: dict | None = None, timeout: float | None = None,
                  robot: str | None = None) -> list[dict[str, Any]]:
        """``await kb.ask(goal, at=z)``: :meth:`submit` for asyncio code.

        >>> import asyncio
        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url); kb.add("p(1)^1"); kb.mark_complete("p/1", 5)
        >>> asyncio.run(kb.ask("p(X)^T", at=5))
        [{'X': 1, 'T': 1.0}]
        >>> kb.close(); server.stop(); server.kb.close()
        """
        import asyncio

        from concurrent.futures import Future

        pending = self.submit(goal, at=at, id=id, args=args, timeout=timeout, robot=robot)
        assert isinstance(pending, Future)   # a PendingQueryAPI here is a Future
        return await asyncio.wrap_future(pending)

    @_reads_answer
    def explain(self, goal: str) -> str:
        """How ``goal`` would run on the server: which engine, and why.

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url); kb.add("obj(cup1, cup, red)^2")
        >>> print(kb.explain("obj(O, cup, C)^T").splitlines()[1])
        engine: sql (one prepared statement; rows decoded into answers)
        >>> kb.close(); server.stop(); server.kb.close()
        """
        check_goal(goal)
        return _expect(self._post("/explain", {"goal": goal}), "explain", str)

    def solutions(self, goal: str, at: float | None = None, args: dict | None = None,
                  timeout: float | None = None,
                  robot: str | None = None) -> SolutionsAPI:
        """The answers of ``goal`` one at a time (see ``KnowledgeBase.solutions``), each
        computed by the server when it is asked for (WebSocket ``/solutions``): a goal with
        endless answers gives its first at once. ``close()`` ends the query on the server
        (a :class:`RemoteSolutions`); its time, ``timeout`` capped by the server's
        ``max_query_time``, counts from the first answer asked to the last, the time between
        two ``next()`` included.

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url)
        >>> for answer in kb.solutions("member(X, [a, b])"): print(answer)
        {'X': Atom('a')}
        {'X': Atom('b')}
        >>> answers = kb.solutions("between(1, inf, X)")
        >>> next(answers), next(answers), answers.close()
        ({'X': 1}, {'X': 2}, None)
        >>> kb.close(); server.stop(); server.kb.close()
        """
        check_query_options(at=at, timeout=timeout, robot=robot, args=args)
        request = _goal_body(goal, at, args, timeout)
        request["op"] = "solutions"
        if robot is not None:
            request["robot"] = robot
        answers = RemoteSolutions(self, request)
        with self._lock:
            self._solutions.add(answers)
        return answers

    @_reads_answer
    def goal_warnings(self, goal: str) -> list[str]:
        """The server's warnings about ``goal`` that do not change its answer (likely typos:
        see ``KnowledgeBase.goal_warnings``).

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url); kb.load("color(O,C)^T :- prev(obj(O,_,C)^Z, T).")
        >>> kb.goal_warnings("colour(cup2, C)^20")
        ['no events or rules of colour/2; did you mean color/2?']
        >>> kb.close(); server.stop(); server.kb.close()
        """
        check_goal(goal)
        return list(_expect(self._post("/warnings", {"goal": goal}),
                            "warnings", list))

    def pending(self) -> list[PendingQueryAPI]:
        """The synchronized queries this client submitted that are still waiting (each
        with ``waiting_for`` as of its latest poll).

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url); waiting = kb.submit("p(X)^T", at=20)
        >>> [p.goal for p in kb.pending()]
        ['p(X)^T']
        >>> kb.mark_complete("p/1", 20); waiting.result(timeout=5), kb.pending()
        ([], [])
        >>> kb.close(); server.stop(); server.kb.close()
        """
        with self._lock:
            return [p for p in self._pending if not p.done()]

    @_reads_answer
    def mark_complete(self, event_type: str, t: float) -> None:
        """Declare the history of ``"p/N"`` complete up to ``t``.

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url)
        >>> kb.complete_until("p/1"), kb.mark_complete("p/1", 15), kb.complete_until("p/1")
        (10.0, None, 15.0)
        >>> kb.close(); server.stop(); server.kb.close()
        """
        check_mark(event_type, t)
        _expect(self._post("/mark_complete", {"type": event_type, "time": _number(t, "t")}),
                "type", str)

    @_reads_answer
    def complete_until(self, event_type: str) -> float:
        """The time up to which the history of ``"p/N"`` is complete now.

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url); kb.load(":- max_delay(p/1, 4).")
        >>> kb.complete_until("p/1")     # now (10) less the delay the events of p/1 may have
        6.0
        >>> kb.close(); server.stop(); server.kb.close()
        """
        check_event_type("complete_until", event_type)
        return float(decode_plain(self._get("/complete_until", {"type": event_type})["time"]))

    # -- buffers --------------------------------------------------------------------------------
    @_reads_answer
    def add_buffer(self, pattern: str, *, keep_last: int | None = None,
                   keep_seconds: float | None = None,
                   keep_between: tuple[float, float] | None = None) -> int:
        """Keep a history of the events matching ``pattern``: the ``keep_last`` most recent
        per key, the last ``keep_seconds``, or those inside ``keep_between=(t1, t2)``.

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url); kb.add_buffer("pos(R, _)", keep_last=1)
        1
        >>> kb.add_many(["pos(r1, 1)^1", "pos(r1, 2)^2", "pos(r2, 5)^2"]); kb.query("pos(R, X)^T")
        []
        [{'R': Atom('r1'), 'X': 2, 'T': 2.0}, {'R': Atom('r2'), 'X': 5, 'T': 2.0}]
        >>> kb.close(); server.stop(); server.kb.close()
        """
        # (the policy checked as a local knowledge base checks it, and sent as it reads it:
        # a duration written "500ms" travels as 0.5)
        kind, amount, t1, t2 = check_buffer_policy(keep_last, keep_seconds, keep_between)
        if not isinstance(pattern, str):
            analyze(pattern)                # (a local knowledge base's words for no pattern)
            pattern = format_term(pattern)  # (a term it takes: sent as its text)
        body: dict[str, Any] = {"pattern": pattern}
        if kind == "cBuffer":
            body["keep_last"] = amount
        elif kind == "tBuffer":
            body["keep_seconds"] = encode_term(amount)
        else:
            body["keep_between"] = [encode_term(t1), encode_term(t2)]
        return _expect(self._post("/buffers", body), "id", int)

    @_reads_answer
    def remove_buffer(self, buffer_id: int) -> None:
        """Remove a runtime buffer (the events it kept stay).

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url); buffer = kb.add_buffer("p(_)", keep_last=1)
        >>> kb.remove_buffer(buffer); kb.buffers()
        []
        >>> kb.remove_buffer(buffer)       # (the class a local knowledge base raises)
        Traceback (most recent call last):
        ...
        slr_sql.errors.BufferNotFound: no active buffer #1
        >>> kb.close(); server.stop(); server.kb.close()
        """
        if type(buffer_id) is not int:     # (refused in a local knowledge base's words)
            raise SLRError(f"remove_buffer: a buffer id is an integer (kb.buffers() lists "
                           f"them), not {shown(buffer_id)}")
        _expect(self._request("DELETE", f"/buffers/{buffer_id}")[1], "removed", int)

    @_reads_answer
    def buffers(self) -> list:
        """The active buffers with their counters (``BufferInfo`` objects).

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url); _ = kb.add_buffer("p(_)", keep_last=1)
        >>> kb.add_many(["p(a)^1", "p(b)^2"]); [(info.pattern, info.pruned) for info in kb.buffers()]
        []
        [('p(_)', 1)]
        >>> kb.close(); server.stop(); server.kb.close()
        """
        infos = decode_plain(_expect(self._get("/buffers"), "buffers", list))
        try:
            from slr_sql.buffers import BufferInfo
        except ImportError:  # pragma: no cover
            return infos
        names = {f for f in BufferInfo.__dataclass_fields__}
        out = []
        for info in infos:
            if isinstance(info, dict) and names <= set(info):
                fields = {k: info[k] for k in names}
                if isinstance(fields.get("keep_between"), list):
                    fields["keep_between"] = tuple(fields["keep_between"])
                out.append(BufferInfo(**fields))
            else:
                out.append(info)
        return out

    # -- SQL and stats --------------------------------------------------------------------------
    @_reads_answer
    def sql(self, query: str, params: Iterable[Any] = (), write: bool = False,
            timeout: float | None = None) -> tuple[list[str], list[tuple]]:
        """Run one read-only SQL statement on the server's store: (column names, rows).
        ``params``: values for ``?`` placeholders (a sequence) or ``:name`` ones (a
        mapping), numbers, strings, booleans or None. ``timeout`` is capped by the server's ``sql_timeout``; ``write=True`` is refused
        (the service runs read-only SQL only: write in the server's process).

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url); kb.add_many(["p(a)^1", "p(b)^4"])
        []
        >>> kb.sql("SELECT arg1, t_end FROM p WHERE t_end < :t", {"t": 3})
        (['arg1', 't_end'], [('a', 1.0)])
        >>> kb.sql("DELETE FROM p")
        Traceback (most recent call last):
        ...
        slr_sql.service.errors.ServiceError: sql over the service is read-only: DELETE statements are not allowed (SELECT, WITH, VALUES, EXPLAIN)
        >>> kb.close(); server.stop(); server.kb.close()
        """
        check_sql(query, timeout, write)
        if write:
            raise ServiceError("sql(write=True) is not available over the network: the "
                               "service runs read-only SQL only (write with `slr sql DB "
                               "--write` in the server's machine)", kind="BadRequest",
                               status=0)
        # (a mapping names :name placeholders: list() of it would send its keys as values)
        try:
            sent = dict(params) if isinstance(params, Mapping) else list(params)
        except (TypeError, ValueError) as exc:
            raise unbindable_parameter(exc) from None
        for key, value in sent.items() if isinstance(sent, dict) else enumerate(sent):
            if value is not None and type(value) not in (bool, int, str) and not (
                    type(value) is float and math.isfinite(value)):
                # (a value JSON cannot carry: bytes, NaN, ... -- a local store may bind them)
                raise SLRError(f"sql: parameter {key!r} = {shown(value)} cannot be sent to slr "
                               f"serve (parameters over the network are None, bool, int, "
                               f"finite float or str)")
        body: dict[str, Any] = {"query": query, "params": sent}
        if timeout is not None:
            body["timeout"] = _number(timeout, "timeout")
        reply = self._post("/sql", body, timeout=self._read_timeout(timeout))
        return (list(_expect(reply, "columns", list)),
                [tuple(row) for row in decode_plain(_expect(reply, "rows", list))])

    @_reads_answer
    def stats(self) -> dict:
        """File size, events per type, buffers and counters; ``["text"]`` is what
        ``slr stats`` prints, but for where the store is, which the server does not say.

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url); kb.add_many(["p(a)^1", "p(b)^2", "q(1)^1"])
        []
        >>> kb.stats()["rows"]
        [{'type': 'p/1', 'count': 2}, {'type': 'q/1', 'count': 1}]
        >>> print(kb.stats()["text"].splitlines()[0])
        store file: ... bytes (... MiB) = ... bytes database + 0 bytes WAL; ... pages of ... bytes, 0 free
        >>> kb.close(); server.stop(); server.kb.close()
        """
        reply = self._get("/stats")
        _expect(reply, "text", str)
        return decode_plain(reply)

    def plot(self, types: Iterable[str] | str | None = None, **options: Any) -> Any:
        """A timeline of the server's event histories as a matplotlib Figure (read through
        :meth:`sql`); options as for ``KnowledgeBase.plot``.

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url); kb.add("move(r1)^[2, 8]")
        >>> kb.plot(start=0, end=10, size=(600, 120)).get_size_inches().tolist()
        [6.0, 1.2]
        >>> kb.close(); server.stop(); server.kb.close()
        """
        from slr_sql.plot import timeline  # deferred: matplotlib is the extra slr_sql[plot]
        try:
            return timeline(self, types, **options)
        except SLRError:
            raise
        except Exception as exc:  # noqa: BLE001 - as a local knowledge base's boundary words it
            raise unforeseen_failure("plot", exc) from exc

    # -- subscriptions --------------------------------------------------------------------------
    def subscribe(self, pattern: str, where: str | None = None, since: Any = "now",
                  until: float | None = None, id: str | None = None,
                  callback: Callable[[dict], Any] | None = None, max_queue: int = 10_000,
                  max_lag: int | None = 1_000_000) -> SubscriptionAPI:
        """Events matching ``pattern`` (and ``where``) as they arrive, over a WebSocket:
        ``for answer in sub`` or ``sub.get(timeout)`` (ends when ``until`` is complete), or
        ``callback(answer)`` on a thread of the client; ``sub.close()``, from any thread,
        ends it. ``max_queue`` is capped by the server's ``subscribe_queue``; up to
        ``subscribe_batch`` answers already waiting on the server travel in one frame.

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url); sub = kb.subscribe("p(X)^T", where="X > 1", since=0)
        >>> kb.add_many(["p(1)^1", "p(2)^2"]); sub.get(timeout=5)
        []
        {'X': 2, 'T': 2.0}
        >>> sub.close(); kb.close(); server.stop(); server.kb.close()
        """
        return RemoteSubscription(self, pattern, where=where, since=since, until=until, id=id,
                                  batch=self.subscribe_batch, callback=callback,
                                  max_queue=max_queue, max_lag=max_lag)

    def unsubscribe(self, id: str) -> None:
        """Remove the durable subscription ``id`` and its position on the server.

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url); sub = kb.subscribe("p(X)^T", id="watcher")
        >>> kb.unsubscribe("watcher"); sub.get(timeout=5) is None    # (it has ended)
        True
        >>> kb.close(); server.stop(); server.kb.close()
        """
        if not isinstance(id, str):   # (no subscription's id: sent, it would be its str)
            raise no_subscription(id)
        self._post("/unsubscribe", {"id": id})


class RemoteWait:
    """One condition a remote synchronized query waits for (``waiting_for``): event type
    ``type`` (name/arity) complete up to ``time``, and why (``reason``); printed as the
    local ``Wait`` is.

    >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
    >>> kb = slr_sql.connect(server.url); p = kb.submit("p(X)^T", at=20)
    >>> p.waiting_for
    [RemoteWait(p/1, 20, 'goal set')]
    >>> wait = p.waiting_for[0]; print(wait); wait.type, wait.time
    p/1 complete up to 20 (goal set)
    ('p/1', 20.0)
    >>> kb.close(); server.stop(); server.kb.close()
    """

    __slots__ = ("type", "time", "reason", "kind")

    def __init__(self, type: str, time: float, reason: str, kind: str = "complete"):
        self.type, self.time, self.reason, self.kind = type, time, reason, kind

    @classmethod
    def from_json(cls, obj: dict) -> "RemoteWait":
        """The condition of one item of the server's ``waiting_for`` (a time that is no
        number is NaN).

        >>> print(RemoteWait.from_json({"type": "obj/3", "time": 12.5, "reason": "goal set"}))
        obj/3 complete up to 12.5 (goal set)
        """
        t = decode_plain(obj.get("time"))
        return cls(str(obj.get("type", "")), float(t) if isinstance(t, (int, float)) else
                   float("nan"), str(obj.get("reason", "")), str(obj.get("kind", "complete")))

    def __str__(self) -> str:
        what = f"{self.type} complete up to {_time_text(self.time)}"
        if self.kind == "arrival":
            what += " (or a matching in-order event)"
        return f"{what} ({self.reason})"

    def __repr__(self) -> str:
        return f"RemoteWait({self.type}, {_time_text(self.time)}, {self.reason!r})"


def _time_text(t: float) -> str:
    """A time for messages, as the local knowledge base prints it (no exponent, no noise)."""
    if t != t or t in (float("inf"), float("-inf")):
        return str(t)
    text = f"{t:.6f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


class RemotePendingQuery(Future):
    """A synchronized query submitted to the server: a ``concurrent.futures.Future`` whose
    result is the answer list. ``id``, ``goal``, ``at``, ``handle``; ``explain()`` says what
    it waited for (once answered). ``cancel()`` cancels it on the server too.

    >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
    >>> kb = slr_sql.connect(server.url); kb.add("p(1)^11")
    >>> p = kb.submit("p(X)^T", at=20, id="q1"); p, p.done()
    (<RemotePendingQuery 'q1' 'p(X)^T': waiting>, False)
    >>> kb.mark_complete("p/1", 20); p.result(timeout=5), p
    ([{'X': 1, 'T': 11.0}], <RemotePendingQuery 'q1' 'p(X)^T': answered>)
    >>> kb.close(); server.stop(); server.kb.close()
    """

    def __init__(self, client: RemoteKnowledgeBase, handle: str, id: str | None, goal: str,
                 at: float | None):
        super().__init__()
        self.client = client
        self.handle = handle
        self.id = id
        self.goal = goal
        self.at = at
        self.waiting_for: list[RemoteWait] = []   # as of the latest reply
        self._waiting = ""                        # the server's words for it
        self._explanation: str | None = None
        # set by cancel() before its DELETE: the poller's GET in flight then meets the
        # handle already gone (404), which is the cancel's outcome, not the query's
        self._cancelling = False

    def __repr__(self) -> str:
        state = "answered" if self.done() else "waiting"
        return f"<RemotePendingQuery {self.id!r} {self.goal!r}: {state}>"

    def result(self, timeout: float | None = None) -> list[dict[str, Any]]:
        """The answer list, waiting up to ``timeout`` seconds (None: for ever). When the
        wait runs out first: :class:`~slr_sql.SLRTimeout` saying what the query waits for
        on the server (it goes on waiting: call ``result`` again, or ``cancel()``).

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url); p = kb.submit("p(X)^T", at=20, id="q1")
        >>> p.result(timeout=0.01)
        Traceback (most recent call last):
        ...
        slr_sql.errors.SLRTimeout: synchronized query 'q1' (p(X)^T at 20) was not answerable within 0.01 s: p/1 (goal set) would require its history up to 20, but it is complete only up to 10 (now 10; ...); it is still waiting (call result() again, or cancel())
        >>> kb.add("p(1)^12"); kb.mark_complete("p/1", 20); p.result(timeout=5)
        [{'X': 1, 'T': 12.0}]
        >>> kb.close(); server.stop(); server.kb.close()
        """
        wait = wait_seconds("result: timeout", timeout)   # (as a local PendingQuery's)
        try:
            return super().result(wait)
        except TimeoutError:
            if self.done():      # answered (or failed with its own SLRTimeout) meanwhile
                return super().result(0)
        error = self._waited_out(timeout, "result")
        if error is None:
            return super().result(0)
        raise error

    def exception(self, timeout: float | None = None) -> BaseException | None:
        """The query's error (None when it was answered), waiting up to ``timeout`` seconds
        as :meth:`result` does (its SLRTimeout included).

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url); p = kb.submit("p(X)^T", at=20)
        >>> kb.mark_complete("p/1", 20); p.exception(timeout=5) is None
        True
        >>> kb.close(); server.stop(); server.kb.close()
        """
        wait = wait_seconds("exception: timeout", timeout)
        try:
            return super().exception(wait)
        except TimeoutError:
            if self.done():
                return super().exception(0)
        error = self._waited_out(timeout, "exception")
        if error is None:
            return super().exception(0)
        raise error

    def _waited_out(self, timeout: float | None, method: str) -> SLRTimeout | None:
        """After a wait of ``method`` ran out: None if the server has the answer now, else
        the SLRTimeout saying what the query waits for."""
        try:                     # what it waits for now, in the server's words
            status, reply = self.client._request("GET", f"/submit/{quote(self.handle)}",
                                                 params={"wait": 0}, ok=(200, 202))
            self._settle(status, reply)
        except SLRError:
            pass
        if self.done():
            return None
        still = f"it is still waiting (call {method}() again, or cancel())"
        # the server's words are the local knowledge base's without the wait: "synchronized
        # query ID (GOAL at T) was not answerable: WHAT"; the wait goes where the local puts it
        head, answerable, what = self._waiting.partition(" was not answerable: ")
        if answerable:
            return SLRTimeout(f"{head} was not answerable within {timeout:g} s: {what}; {still}")
        what = ", ".join(map(str, self.waiting_for)) or "its answer"
        at = "now" if self.at is None else _time_text(float(self.at))
        return SLRTimeout(f"synchronized query {self.id!r} ({self.goal} at {at}) was not "
                          f"answered within {timeout:g} s: {what}; {still}")

    def add_done_callback(self, fn: Callable[[Any], Any]) -> None:
        """Call ``fn(pending)`` once the query is answered, failed or cancelled; ``fn``
        that is not callable is an :class:`SLRError` here, as on a local PendingQuery.

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url); p = kb.submit("p(X)^T", at=20)
        >>> import threading; done = threading.Event()
        >>> p.add_done_callback(lambda pending: done.set())
        >>> p.add_done_callback("print")
        Traceback (most recent call last):
        ...
        slr_sql.errors.SLRError: add_done_callback: fn must be callable (a function), not 'print'
        >>> kb.mark_complete("p/1", 20); done.wait(5)
        True
        >>> kb.close(); server.stop(); server.kb.close()
        """
        super().add_done_callback(check_callable("add_done_callback: fn", fn))

    def explain(self) -> str:
        """What the query waited for and what released it (the server's explanation).

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url); p = kb.submit("p(X)^T", at=20); p.explain()
        'waiting (the explanation comes with the answer)'
        >>> kb.mark_complete("p/1", 20); p.result(timeout=5); print(p.explain())
        []
        waited 0 s for p/1 complete up to 20 (goal set); released by kb.mark_complete('p/1', 20)
        answered at clock 10 (0 s after submission, 1 evaluation, by sql)
        >>> kb.close(); server.stop(); server.kb.close()
        """
        if self._explanation is not None:
            return self._explanation
        return "answered" if self.done() else "waiting (the explanation comes with the answer)"

    def cancel(self) -> bool:
        """Stop waiting, here and on the server; False if it was answered already.

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url); p = kb.submit("p(X)^T", at=20)
        >>> p.cancel(), p.cancelled(), kb.pending(), server.kb.pending()
        (True, True, [], [])
        >>> kb.close(); server.stop(); server.kb.close()
        """
        if self.done():
            return False
        self._cancelling = True
        try:
            self.client._request("DELETE", f"/submit/{quote(self.handle)}", ok=(200, 404))
        except SLRError:
            pass
        return super().cancel()

    # the result, from a reply of POST /submit or GET /submit/{handle}
    def _settle(self, status: int, reply: dict) -> None:
        if not reply.get("done"):
            waits = reply.get("waiting_for")
            if isinstance(waits, list):
                self.waiting_for = [RemoteWait.from_json(w) for w in waits
                                    if isinstance(w, dict)]
            if isinstance(reply.get("waiting"), str):
                self._waiting = reply["waiting"]
            return
        self.waiting_for = []
        if isinstance(reply.get("explain"), str):
            self._explanation = reply["explain"]
        if reply.get("cancelled"):
            super().cancel()
            return
        try:
            if "error" in reply:
                self.set_exception(error_from_body(reply, status))
            else:
                self.set_result(decode_answers(reply.get("answers", [])))
        except InvalidStateError:  # cancelled meanwhile
            pass

    def _fail(self, exc: BaseException) -> None:
        try:
            self.set_exception(exc)
        except InvalidStateError:
            pass

    def _start(self) -> None:
        with self.client._lock:
            self.client._pending[self] = None
        threading.Thread(target=self._poll, name=f"slr-remote-query-{self.id}",
                         daemon=True).start()

    def _poll(self) -> None:
        client = self.client
        path = f"/submit/{quote(self.handle)}"
        try:
            while not self.done() and not client.closed:
                try:
                    status, reply = client._request("GET", path, params={"wait": POLL_WAIT},
                                                    timeout=POLL_WAIT + client.timeout,
                                                    ok=(200, 202))
                except SLRError as exc:  # the query's own error, or the server is gone
                    if not self._cancelling:
                        self._fail(exc)
                    return
                self._settle(status, reply)
        finally:
            with client._lock:
                client._pending.pop(self, None)


class RemoteSubscription:
    """A subscription on the server (WebSocket ``/subscribe``): ``for answer in sub`` blocks
    for the next answer and ends when the subscription ends (``until``); ``close()``.

    It subscribes with acknowledgements: an answer counts as handled on the server (a durable
    subscription's position moves past it) when the consumer comes back for the next one, or
    at a normal ``close()``, as with a local subscription. Acknowledgements are batched: sent
    once half the server's window (``ack_window`` answers may be unacknowledged) was handled,
    or when the consumer waits for answers and none came within ``ack_delay`` seconds, or at
    ``close()``.

    >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
    >>> kb = slr_sql.connect(server.url); sub = kb.subscribe("p(X)^T", since=0, until=12)
    >>> kb.add_many(["p(1)^11", "p(2)^11.5"]); kb.mark_complete("p/1", 12)
    []
    >>> [answer["X"] for answer in sub], sub.closed
    ([1, 2], True)
    >>> kb.close(); server.stop(); server.kb.close()
    """

    ack_delay = 0.05
    _join_timeout = 30.0       # close() waits this long for a callback that is running

    def __init__(self, client: RemoteKnowledgeBase, pattern: str, *, where: str | None,
                 since: Any, until: float | None, id: str | None, batch: int = 1,
                 callback: Callable[[dict], Any] | None = None,
                 max_queue: int = DEFAULT_MAX_QUEUE,
                 max_lag: int | None = 1_000_000):
        try:
            from websockets.exceptions import WebSocketException
            from websockets.sync.client import connect as ws_connect
        except ImportError:  # pragma: no cover
            raise SLRError("subscriptions over the network need the service extra: "
                           "pip install 'slr_sql[service]'") from None
        # (checked as a local knowledge base checks them, before anything is sent)
        where, since_value, until_value = check_subscription(
            pattern, where, since, until, id, callback, max_queue, max_lag)
        self._closed_exc = WebSocketException
        url = "ws" + client.url[len("http"):] + "/subscribe"
        headers = {"Authorization": client._headers["Authorization"]} \
            if "Authorization" in client._headers else None
        request: dict[str, Any] = {"op": "subscribe", "pattern": pattern, "since":
                                   "now" if since_value is None else encode_term(since_value)}
        if where is not None:
            request["where"] = where
        if until_value is not None:
            request["until"] = encode_term(until_value)
        if id is not None:
            request["id"] = id
        if batch != 1:
            request["batch"] = batch
        request["max_queue"] = max_queue
        request["max_lag"] = max_lag
        request["ack"] = True
        self.pattern = pattern
        self.id = id
        self.callback = callback
        self.error: BaseException | None = None   # what ended a callback subscription
        self._thread: threading.Thread | None = None
        self._done = False
        self._ready: collections.deque = collections.deque()   # answers of the last frame
        self._returned = 0          # seq of the last answer given to the consumer
        self._handled = 0           # seq of the last answer handled (the consumer came back)
        self._acked = 0             # seq of the last answer acknowledged to the server
        self._ack_every = 1
        self.acks_sent = 0          # acknowledgement messages sent (they are batched)
        try:
            # entered as a context manager (what websockets >= 17 asks); closed by close()
            # (proxy=None: straight to the URL, as the client's requests go)
            self._ws = ws_connect(url, additional_headers=headers, open_timeout=client.timeout,
                                  max_size=None, ssl=client._tls, proxy=None).__enter__()
            self._ws.send(dumps(request).decode("utf-8"))
        except (OSError, WebSocketException) as exc:
            refused = _refused_certificate(exc)
            if refused is not None:
                raise _not_trusted(client.url, refused) from None
            raise _not_subscribed(url, exc) from None
        first = self._receive()
        if first.get("type") != "subscribed":
            self.close()
            raise ServiceError(f"unexpected first message from the server: {first!r}",
                               kind="InternalError", status=0)
        window = first.get("ack_window")
        self._ack_every = max(1, window // 2) if type(window) is int else 1
        if callback is not None:
            self._thread = threading.Thread(target=self._run_callback, daemon=True,
                                            name=f"slr-remote-subscription-{id or pattern}")
            self._thread.start()

    def _run_callback(self) -> None:
        fn = self.callback
        assert fn is not None
        try:
            while True:
                try:
                    answer = self._next(None)
                except StopIteration:
                    return
                try:
                    fn(answer)
                except BaseException as exc:  # the callback's failure ends its subscription
                    log.exception("subscription %r: the callback raised; the subscription "
                                  "ends", self.id or self.pattern)
                    self.error = exc
                    self.close(ack=False)
                    return
        except SLRError as exc:          # the connection or the server ended it
            if not self._done or self.error is None:
                self.error = exc
            log.warning("subscription %r ended: %s", self.id or self.pattern, exc)

    def _ack(self, seq: int) -> None:
        """Tell the server that every answer up to ``seq`` was handled."""
        if seq > self._acked:
            self._acked = seq
            self.acks_sent += 1
            try:
                self._ws.send(f'{{"op":"ack","seq":{seq}}}')
            except (OSError, self._closed_exc):
                pass                   # the connection is gone: the next receive says so

    def _receive_frame(self, timeout: float | None = None) -> dict:
        """The next message; answers handled and not acknowledged are acknowledged before
        waiting (after ``ack_delay`` without a message, so a stream of answers costs one
        acknowledgement per ``ack_delay`` or per half window, not one per answer).
        ``timeout``: SLRTimeout when no message came within it."""
        deadline = None if timeout is None else time.monotonic() + timeout
        if self._handled > self._acked:
            try:
                return self._receive(self.ack_delay if timeout is None
                                     else min(self.ack_delay, timeout))
            except TimeoutError:
                self._ack(self._handled)
        try:
            return self._receive(None if deadline is None
                                 else max(0.0, deadline - time.monotonic()))
        except TimeoutError:
            raise SLRTimeout(f"subscription {self.id or self.pattern!r}: no event within "
                             f"{timeout:g} s") from None

    def _receive(self, timeout: float | None = None) -> dict:
        try:
            data = self._ws.recv(timeout)
        except self._closed_exc as exc:
            if self._done:             # close() was called (maybe from another thread)
                return {"type": "end"}
            self._done = True
            raise ServiceUnavailable(f"the subscription's connection closed: "
                                     f"{_closed_words(exc)}", status=0) from None
        message = _server_message(data)
        if not isinstance(message, dict):
            raise ServiceError("the server sent a message that is not an object",
                               kind="InternalError", status=0)
        if message.get("type") == "error":
            self._done = True
            self._close_socket()
            raise error_from_body(message, int(message.get("error", {}).get("status", 400)))
        return message

    @property
    def closed(self) -> bool:
        """True once closed, or ended (``until`` reached, an error) and every answer taken:
        as a local subscription's ``closed``.

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url); sub = kb.subscribe("p(X)^T")
        >>> sub.closed, sub.close(), sub.closed
        (False, None, True)
        >>> kb.close(); server.stop(); server.kb.close()
        """
        return self._done

    def __iter__(self) -> "RemoteSubscription":
        return self

    def __next__(self) -> dict[str, Any]:
        self._check_pull()
        return self._next(None)

    def get(self, timeout: float | None = None) -> dict | None:
        """The next answer; None once the subscription has ended (``until`` reached or
        closed). Raises SLRTimeout when none came within ``timeout`` seconds, and the error
        that ended the subscription on the server.

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url); sub = kb.subscribe("p(X)^T", since=0, until=12)
        >>> kb.add("p(1)^11"); kb.mark_complete("p/1", 12); sub.get(timeout=5), sub.get(timeout=5)
        ({'X': 1, 'T': 11.0}, None)
        >>> kb.close(); server.stop(); server.kb.close()
        """
        wait = wait_seconds("get: timeout", timeout)   # (as a local subscription's)
        self._check_pull()
        try:
            return self._next(wait)
        except StopIteration:
            return None

    def _check_pull(self) -> None:
        if self.callback is not None:
            raise SLRError(f"subscription {self.id or self.pattern!r} delivers to its "
                           f"callback; it cannot also be iterated")

    def _next(self, timeout: float | None) -> dict[str, Any]:
        self._handled = self._returned          # the consumer is back: the last one is done
        if self._handled - self._acked >= self._ack_every:
            self._ack(self._handled)
        if self._ready:
            self._returned += 1
            return self._ready.popleft()
        if self._done:
            raise StopIteration
        message = self._receive_frame(timeout)
        kind = message.get("type")
        if kind == "answer":
            answer = decode_answers([message.get("answer", {})])[0]
            self._returned += 1
            return answer
        if kind == "answers":
            self._ready.extend(decode_answers(message.get("answers", [])))
            if self._ready:
                self._returned += 1
                return self._ready.popleft()
            return self._next(timeout)
        if kind == "end":
            self._done = True
            self._close_socket()
            raise StopIteration
        raise ServiceError(f"unexpected message from the server: {message!r}",
                           kind="InternalError", status=0)

    def _close_socket(self) -> None:
        try:
            self._ws.close()
        except Exception:
            pass

    def close(self, ack: bool = True) -> None:
        """Unsubscribe (closes the WebSocket); an iteration blocked in another thread
        ends. The last answer given out counts as handled unless ``ack=False``; answers
        received but not iterated yet are dropped (unhandled: a durable subscription
        delivers them again).

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url); sub = kb.subscribe("p(X)^T")
        >>> sub.close(ack="no")       # (the flag checked as a local subscription checks it)
        Traceback (most recent call last):
        ...
        slr_sql.errors.SLRError: close: ack must be True or False, not 'no'
        >>> sub.close(); kb.add("p(1)^11"); sub.get(timeout=5) is None
        True
        >>> kb.close(); server.stop(); server.kb.close()
        """
        check_flag("close: ack", ack)
        if not self._done:
            self._ack(self._returned if ack else self._handled)
        self._done = True
        self._ready.clear()
        self._close_socket()
        thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(self._join_timeout)

    def __enter__(self) -> "RemoteSubscription":
        return self

    def __exit__(self, exc_type: Any, *rest: Any) -> None:
        self.close(ack=exc_type is None)


# What a WebSocket close code of the server means, in words (RFC 6455 and IANA's codes; the
# service closes with 1000 when done, 1012 when it stops, 4000 + status after an error)
_CLOSE_CODE_WORDS = {
    1000: "the server ended it",
    1001: "the server went away",
    1002: "the server found an error in the WebSocket protocol",
    1003: "the server refused data of that kind",
    1007: "the server refused data that was not valid",
    1008: "the server refused it by its policy",
    1009: "the server refused a message too large",
    1011: "the server failed (an internal error)",
    1012: "the server stopped or restarted; ask again once it is back",
    1013: "the server is overloaded; try again later",
    1014: "a gateway in front of the server got no valid answer from it",
}


def _closed_words(exc: BaseException) -> str:
    """Why a WebSocket to the server closed, in words (``exc``: what websockets raised),
    its close code kept in parentheses; not websockets' "received 1012 (service restart);
    then sent 1012 (service restart)".

    >>> from websockets.exceptions import ConnectionClosedError, ConnectionClosedOK
    >>> from websockets.frames import Close
    >>> print(_closed_words(ConnectionClosedError(Close(1012, ""), Close(1012, ""), True)))
    the server stopped or restarted; ask again once it is back (WebSocket close code 1012)
    >>> print(_closed_words(ConnectionClosedError(None, None)))
    the connection to the server broke without a closing handshake (the server was killed, or the network failed)
    >>> print(_closed_words(ConnectionClosedOK(Close(4503, "busy"), None)))
    the server closed it with code 4503 (its reason: 'busy')
    """
    from websockets.exceptions import ConnectionClosed

    if not isinstance(exc, ConnectionClosed):
        return str(exc)
    received = exc.rcvd
    if received is None:
        return ("the connection to the server broke without a closing handshake (the "
                "server was killed, or the network failed)")
    code, reason = received.code, received.reason
    words = _CLOSE_CODE_WORDS.get(code)
    if words is None:
        return f"the server closed it with code {code}" + (
            f" (its reason: {shown(reason)})" if reason else "")
    return f"{words} (WebSocket close code {code}" + (
        f"; its reason: {shown(reason)})" if reason else ")")


def _server_message(data: str | bytes) -> Any:
    """A WebSocket message of the server, parsed (a ServiceError for one that is no JSON)."""
    try:
        return loads(data)
    except (ValueError, UnicodeDecodeError) as exc:
        raise ServiceError(f"the server sent a message that is not JSON ({exc}): is the "
                           "URL that of an slr serve?", kind="InternalError",
                           status=0) from None


class RemoteSolutions:
    """The answers of a goal on the server, one at a time (what
    :meth:`RemoteKnowledgeBase.solutions` returns): the first ``next()`` opens a WebSocket to
    ``/solutions`` and sends the goal, each later one sends ``{"op": "next"}``; the server
    computes one answer per request, none ahead. ``close()`` closes the WebSocket, which ends
    the query on the server, also while it looks for an answer; so does the end of the
    answers, an error, or an interrupted ``next()`` (Ctrl-C). A server without
    ``/solutions`` (an older ``slr serve``) is asked with one :meth:`~RemoteKnowledgeBase.query`
    instead, whose answers come all at once.

    >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
    >>> kb = slr_sql.connect(server.url)
    >>> answers = kb.solutions("member(X, [1, 2]), Y is 1 / (2 - X)")
    >>> next(answers)
    {'X': 1, 'Y': 1}
    >>> next(answers)
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLREvaluationError: error(evaluation_error(zero_divisor),context((/)/2,_))
    >>> list(answers), answers.closed
    ([], True)
    >>> kb.close(); server.stop(); server.kb.close()
    """

    def __init__(self, client: RemoteKnowledgeBase, request: dict):
        self._client = client
        self._request = request
        self._ws: Any = None
        self._answers: Iterator[dict[str, Any]] | None = None   # an older server's
        self.closed = False
        self._stopped = False
        self._failure: SLRError | None = None   # why it was ended from outside (_shut)
        from websockets.exceptions import WebSocketException   # (the service extra's)
        self._closed_exc: type[Exception] = WebSocketException

    def __iter__(self) -> "RemoteSolutions":
        return self

    def __next__(self) -> dict[str, Any]:
        if self._failure is not None:
            raise self._failure
        if self._stopped:
            raise SLRError(STOPPED_BY_CALLER)
        if self.closed:
            raise StopIteration
        if self._client.closed:
            raise SLRError("the connection to the knowledge base is closed")
        if self._answers is not None:
            return next(self._answers)
        try:
            # (the connection read once: stop() from another thread sets self._ws to None)
            ws = self._ws
            if ws is None:
                ws = self._open()
                if ws is None:
                    return next(self)
            else:
                try:
                    ws.send('{"op":"next"}')
                except self._closed_exc:
                    pass   # the server ended the query (its time ran out): its last word says why
            return self._receive(ws)
        except BaseException as exc:
            closed_under_it = self.closed   # (by stop() or close() from another thread)
            self.close()   # (an error, Ctrl-C: the query ends on the server too)
            if self._failure is not None and not isinstance(exc, KeyboardInterrupt):
                raise self._failure from None   # (the knowledge base closed under this call)
            if closed_under_it and not isinstance(exc, (SLRError, StopIteration,
                                                        KeyboardInterrupt)):
                # (what a connection closed by stop() under this call raised)
                raise SLRError(STOPPED_BY_CALLER) from None
            raise

    def _open(self) -> Any:
        """Connect and send the goal: the WebSocket; None when the server has no
        ``/solutions``, or when :meth:`stop` or :meth:`close` came while it connected (the
        connection closed again; then the next ``next()`` says so)."""
        from websockets.exceptions import InvalidStatus, WebSocketException
        from websockets.sync.client import connect as ws_connect

        client = self._client
        url = "ws" + client.url[len("http"):] + "/solutions"
        headers = {"Authorization": client._headers["Authorization"]} \
            if "Authorization" in client._headers else None
        try:
            ws = ws_connect(url, additional_headers=headers, open_timeout=client.timeout,
                            max_size=None, ssl=client._tls, proxy=None).__enter__()
            if self.closed:
                # stop() or close() from another thread while this connected: it saw no
                # connection to close, so the query would have run on the server unasked
                ws.close()
                return None
            self._ws = ws
            ws.send(dumps(self._request).decode("utf-8"))
        except InvalidStatus as exc:
            if exc.response.status_code not in (403, 404):   # no such WebSocket route
                raise _not_subscribed(url, exc, "ask") from None
            body = {k: v for k, v in self._request.items() if k != "op"}
            self._answers = iter(decode_answers(_expect(client._post(
                "/query", body, timeout=client._read_timeout(body.get("timeout"))),
                "answers", list)))
            return None
        except (OSError, WebSocketException) as exc:
            refused = _refused_certificate(exc)
            if refused is not None:
                raise _not_trusted(client.url, refused) from None
            if isinstance(exc, OSError):   # no server answered: as for a request
                raise ServiceUnavailable(f"cannot reach slr serve at {client.url}: {exc}",
                                         status=0) from None
            raise _not_subscribed(url, exc, "ask") from None
        return ws

    def _receive(self, ws: Any) -> dict[str, Any]:
        from websockets.exceptions import WebSocketException

        wait = self._client._read_timeout(self._request.get("timeout"))
        try:
            data = ws.recv(wait)
        except TimeoutError:
            raise ServiceUnavailable(f"the server sent no answer within {wait:g} s",
                                     status=0) from None
        except WebSocketException as exc:
            if self._failure is not None:
                raise self._failure from None    # (the knowledge base closed meanwhile)
            if self._stopped or self.closed:     # (stop() or close() from another thread)
                raise SLRError(STOPPED_BY_CALLER) from None
            raise ServiceUnavailable(f"the query's connection closed: {_closed_words(exc)}",
                                     status=0) from None
        message = _server_message(data)
        kind = message.get("type") if isinstance(message, dict) else None
        if kind == "answer":
            return decode_answers([message.get("answer", {})])[0]
        if kind == "end":
            self.close()
            raise StopIteration
        if kind == "error":
            raise error_from_body(message, int(message.get("error", {}).get("status", 400)))
        raise ServiceError(f"unexpected message from the server: {str(message)[:200]}",
                           kind="InternalError", status=0)

    def stop(self) -> None:
        """End the query from another thread, also while a ``next()`` waits for the server
        to find an answer: the connection closes (the server stops its search), and that
        ``next()`` and the later ones raise SLRError, as a local ``Solutions.stop()``.

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url); answers = kb.solutions("repeat")
        >>> next(answers), answers.stop()
        ({}, None)
        >>> next(answers)
        Traceback (most recent call last):
        ...
        slr_sql.errors.SLRError: the query was stopped while it looked for its next answer
        >>> kb.close(); server.stop(); server.kb.close()
        """
        self._stopped = True
        self.close()

    def _shut(self, failure: SLRError) -> None:
        # the knowledge base closed: a query still open ends on the server, and this and
        # every later next() raise ``failure`` (one that ended before is left as it is)
        if not self.closed:
            self._failure = failure
            self.close()

    def close(self) -> None:
        """End the query (on the server too); later ``next()`` calls end the iteration.

        >>> server = BackgroundServer(slr_sql.open(clock=slr_sql.ManualClock(10))).start()
        >>> kb = slr_sql.connect(server.url); answers = kb.solutions("between(1, inf, X)")
        >>> next(answers), answers.close(), list(answers)
        ({'X': 1}, None, [])
        >>> kb.close(); server.stop(); server.kb.close()
        """
        self.closed = True
        self._answers = None
        ws, self._ws = self._ws, None
        if ws is not None:
            try:
                ws.close()
            except Exception:  # noqa: BLE001 - the connection is gone already
                pass


# -- request bodies ----------------------------------------------------------------------------

def _text(value: Any, what: str) -> str:
    if not isinstance(value, str):
        raise SLRError(f"{what} must be a string of SLR text, not {type(value).__name__}")
    return str(value)


def _iterable(value: Any, where: str) -> None:
    """Refuse ``value`` that no ``for`` can go through (``where``: the method), in the words
    of a local knowledge base.

    >>> _iterable(5, "add_many")
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: add_many takes an iterable of events (SLR text or (name, args, start, end) tuples), not 5
    """
    try:
        iter(value)
    except TypeError:
        raise SLRError(f"{where} takes an iterable of events (SLR text or (name, args, start, "
                       f"end) tuples), not {shown(value)}") from None


def _number(value: Any, what: str) -> Any:
    # any real number, as the checks before sending take it (numpy's, Fraction): an integer
    # travels as one, any other as a float
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise SLRError(f"{what} must be a number, not {shown(value)}")
    return encode_term(int(value) if isinstance(value, numbers.Integral) else float(value))


def _goal_body(goal: str, at: Any, args: dict | None, timeout: Any) -> dict:
    check_goal(goal)
    body: dict[str, Any] = {"goal": goal}
    if args:
        for name in args:
            if not isinstance(name, str):   # (no variable's name: sent, it would be its str)
                raise not_a_variable(name, goal)
        body["args"] = _encoded_args(args)
    if at is not None:
        body["at"] = _number(at, "at")
    if timeout is not None:
        body["timeout"] = _number(timeout, "timeout")
    return body


def _encoded_args(args: dict) -> dict:
    """``args`` of a query as JSON; a value that is no term is refused as a local knowledge
    base refuses it (:func:`slr_sql.plans.argument_term`, its check), in its words.

    >>> _encoded_args({"X": object()})
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: args['X'] = <object object at ...> is not a term: ...
    """
    try:
        encoded = encode_args(args)
    except TermError:
        for name, value in args.items():
            argument_term(name, value)
        raise       # (a term the wire cannot carry)
    assert encoded is not None
    return encoded


def _event_object(name: Any, args: Iterable[Any], start: Any, end: Any, where: str) -> dict:
    # (arguments that are no list or tuple are refused as a local knowledge base refuses
    # them: a str or a generator is no argument list)
    arguments = event_arguments(name, args, start, end)
    arg_list = arguments if type(arguments) is list else list(arguments)
    # (times and arguments a local store refuses are refused in its words: the order of its
    # checks, the times first)
    try:
        check_times(start, end)
    except BadEvent as exc:
        raise event_rejection((name, arguments, start, end), exc) from None
    if not isinstance(name, str):   # (not sent as its text: a local store refuses it too)
        raise EventRejected(f"{where}event name must be an atom, not {shown(name)}")
    try:
        encoded = encode_arguments(arg_list, f"{where}args")
    except TermError:
        for arg in arg_list:
            try:
                encode_stored(arg)
            except Unencodable as exc:
                raise event_rejection((name, arguments, start, end), exc) from None
        raise       # (a term the wire cannot carry)
    obj: dict[str, Any] = {"name": name, "args": encoded,
                           "start": _time(start, f"{where}start")}
    if end is not None:
        obj["end"] = _time(end, f"{where}end")
    return obj


def _time(t: Any, where: str) -> Any:
    return t if type(t) is float and t - t == 0.0 else encode_term(t, _where=where)


def _tuple_object(ev: Any, index: int) -> dict:
    """The JSON object of the event tuple ``ev`` (item ``index`` of a batch), or the
    EventRejected that names it."""
    try:
        name, args, start, end = ev
    except (TypeError, ValueError):   # (in the words of a local knowledge base)
        raise EventRejected(f"event #{index} is neither SLR text nor a (name, args, start, "
                            f"end) tuple: {shown(ev)}") from None
    arguments = event_arguments(name, args, start, end)   # (its EventRejected as it is)
    try:
        return _event_object(name, arguments, start, end, "")
    except EventRejected:
        raise       # (in a local knowledge base's words already)
    except (TermError, SLRError) as exc:
        raise EventRejected(f"{shown(ev)}: {exc}") from None


def _rejected(exc: SLRError, index: int) -> EventRejected:
    out = exc if isinstance(exc, EventRejected) else EventRejected(str(exc))
    out.index = index
    return out
