"""``slr serve DB``: the network service on uvicorn (registered on the ``slr`` group by
slr_sql/cli.py). Starlette and uvicorn are imported only when the command runs."""
from __future__ import annotations

import contextlib
import gc
import importlib.util
import logging
import signal
import sys
import threading
import warnings
from typing import Any

import click

import slr_sql

from ..log_throttle import ThrottledLogFilter
from ..store import DEFAULT_BUSY_TIMEOUT
from .background import is_loopback, listen_on, service_server, uvicorn_config

__all__ = ["serve", "run_server", "is_loopback"]

# Seconds the requests in flight get to finish after SIGINT/SIGTERM; then the server stops
# anyway. A synchronized query may wait for an hour (max_wait) and a long-poll for 30 s:
# without a bound they held the shutdown that long. Their clients see the connection close
# (a condition that passes: they retry against the next server).
SHUTDOWN_GRACE = 10.0

# Net container allocations between two young collections while serving (Python's default
# is 700): see prepare_collector_for_serving.
SERVING_GC_THRESHOLD = 20_000


def prepare_collector_for_serving() -> None:
    """Set the cyclic garbage collector up for a long-lived server process.

    What is alive now (modules, the grammar, the app) lives as long as the server: it is
    frozen, so the collector's full passes need not walk it again and again. And a young
    collection runs after ``SERVING_GC_THRESHOLD`` net allocations instead of 700: at 100
    WebSocket frames per pass (100 subscribers, 1,000 events/s) the default ran ~30 young and
    ~3 middle collections a second and a full one every ~4 s, each a pause of every request
    and subscriber (a full one 20-50 ms on a busy machine: a part of the p99 beside a
    competing load). Garbage without cycles
    is freed by reference counting at once either way; cycles now wait a little longer.

    >>> import gc
    >>> before = gc.get_threshold()
    >>> prepare_collector_for_serving(); gc.get_threshold()[0] == SERVING_GC_THRESHOLD
    True
    >>> gc.unfreeze(); gc.set_threshold(*before)
    """
    gc.collect()
    gc.freeze()
    gc.set_threshold(SERVING_GC_THRESHOLD, *gc.get_threshold()[1:])


# Seconds a thread holding the GIL runs before a thread that waits for it gets it (Python's
# default is 0.005): see prepare_switching_for_serving.
SERVING_SWITCH_INTERVAL = 0.0005


def prepare_switching_for_serving() -> None:
    """Hand the GIL over ten times as often as Python's default while serving.

    A request thread that releases the GIL (every SQLite call does) waits to take it back
    until the thread holding it lets go, at the latest after the switch interval. An add
    beside four CPU-bound queries (the interpreter holds the GIL) takes it back dozens of
    times: 0.55-0.94 s with the default 5 ms, 0.06-0.11 s with 0.5 ms (benchmarks/README.md,
    "Adds beside slow queries"); the queries lose a few per cent to the extra switches.

    >>> import sys
    >>> before = sys.getswitchinterval()
    >>> prepare_switching_for_serving(); sys.getswitchinterval() == SERVING_SWITCH_INTERVAL
    True
    >>> sys.setswitchinterval(before)
    """
    sys.setswitchinterval(SERVING_SWITCH_INTERVAL)


class _Stop(BaseException):
    """SIGINT/SIGTERM after uvicorn's graceful shutdown."""


@contextlib.contextmanager
def _stop_on_signals() -> Any:
    """uvicorn shuts down on SIGINT/SIGTERM, then raises the signal again for the previous
    handler; this handler turns it into :class:`_Stop` so the store is closed and the
    process exits with status 0."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def stop(signum: int, frame: Any) -> None:
        raise _Stop()
    previous = {sig: signal.signal(sig, stop) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def foxglove_logger() -> logging.Logger:
    """The log of ``slr serve --foxglove``'s live view (``slr_sql.service.foxglove``): lines
    on stderr as uvicorn writes its own (``INFO:     foxglove: client 127.0.0.1:40028
    connected``), at INFO and above: the view's start, clients connecting and leaving, what
    a client sent that the protocol refuses, a type whose rows cannot be read. Each is one
    line in words, never a traceback (a client can make some of them happen).

    >>> foxglove_logger().name
    'slr_sql.service.foxglove'
    """
    log = logging.getLogger("slr_sql.service.foxglove")
    if not log.handlers:
        from uvicorn.logging import DefaultFormatter

        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(DefaultFormatter("%(levelprefix)s %(message)s", use_colors=False))
        log.addHandler(handler)
        log.setLevel(logging.INFO)
        log.propagate = False
    return log


# the loggers whose lines a client can cause: uvicorn's about bytes that are no HTTP or no
# UTF-8 and about too many connections, the service's about input it refused, the live view's
STRANGER_LOGGERS = ("uvicorn.error", "slr_sql.service", "slr_sql.service.foxglove")


def throttle_stranger_logs(clock: Any = None) -> None:
    """Make each line of :data:`STRANGER_LOGGERS` one safe line of bounded length, without
    the traceback of a client's bytes, and at most :data:`~slr_sql.log_throttle.BURST` lines
    of a kind a minute (:class:`~slr_sql.log_throttle.ThrottledLogFilter`); once per
    process.

    >>> throttle_stranger_logs(); throttle_stranger_logs()
    >>> sum(isinstance(f, ThrottledLogFilter) for f in logging.getLogger("uvicorn.error").filters)
    1
    """
    for name in STRANGER_LOGGERS:
        logger = logging.getLogger(name)
        if not any(isinstance(f, ThrottledLogFilter) for f in logger.filters):
            logger.addFilter(ThrottledLogFilter(clock))


@contextlib.contextmanager
def _warnings_as_stranger_lines():
    """The library's warnings while the server runs, as lines of the ``slr_sql.service``
    logger (one of :data:`STRANGER_LOGGERS`): a client causes them -- the learned-delay
    warning of each new event type it adds with old times, the warning of each stored text
    that is no UTF-8 a ``/sql`` reads -- so they are bounded as its other lines are: cut after
    :data:`~slr_sql.printable.LOG_TEXT_LIMIT` characters and at most
    :data:`~slr_sql.log_throttle.BURST` a minute. (Printed whole, a client adding events of
    a thousand types named by 10,000 characters each wrote a thousand lines of 30,000.)"""
    log = logging.getLogger("slr_sql.service")
    before = warnings.showwarning

    def show(message: Any, category: Any, filename: str, lineno: int, file: Any = None,
             line: str | None = None) -> None:
        log.warning("warning: %s", message)

    warnings.showwarning = show
    try:
        yield
    finally:
        warnings.showwarning = before


def run_server(db: str, host: str = "127.0.0.1", port: int = 8765, token: str | None = None,
               *, limits: Any = None, max_connections: int | None = 1000,
               ssl_keyfile: str | None = None, ssl_certfile: str | None = None,
               log_level: str = "warning", ws_compression: bool = False,
               cache_mib: float | None = None, foxglove: tuple[str, int] | None = None,
               foxglove_message_max: int = 64 * 1024,
               shutdown_grace: float = SHUTDOWN_GRACE,
               busy_timeout: float | None = None, robot_tokens: Any = ()) -> None:
    """Open ``db`` and serve it until SIGINT/SIGTERM; then close it.

    Refuses (SLRError) to listen on a non-loopback address without a token. Prints
    ``slr serve: DB on http://HOST:PORT`` on stdout once listening. ``ws_compression``:
    accept WebSocket clients' offer of permessage-deflate (off by default: compressing every
    frame for every subscriber costs more CPU than loopback or a LAN saves). ``cache_mib``:
    the store's SQLite page cache (default 64 MiB), the part of the server's memory that
    grows with the store until it is full. ``foxglove``: ``(host, port)`` of a live Foxglove
    view of the store beside the service (:mod:`slr_sql.viz.foxglove_live`; it has no token:
    keep it on loopback unless the network is yours); ``foxglove_message_max``: its largest
    message in bytes (``FoxgloveView``'s ``message_max_bytes``). ``shutdown_grace``: seconds the
    requests in flight get after SIGINT/SIGTERM (a synchronized query may wait for an hour)
    before the server stops anyway. ``busy_timeout``: seconds a request waits for another
    process's lock before it is answered 503 (retryable; default
    :data:`~slr_sql.store.DEFAULT_BUSY_TIMEOUT`). ``robot_tokens``: the tokens of robots
    (:class:`~slr_sql.service.auth.RobotToken`, ``--robot-tokens FILE``), each of which may
    only ship to the fleet store as its robot; they need ``token`` beside them.

    A server runs until it is stopped (``slr serve DB`` calls this); what it refuses, it
    refuses before it opens anything:

    >>> run_server("robot.db", host="0.0.0.0")
    Traceback (most recent call last):
        ...
    slr_sql.errors.SLRError: refusing to serve on 0.0.0.0 without a token: anyone who can reach it could read and change the store. Give --token TOKEN (or set SLR_TOKEN), or bind to 127.0.0.1
    """
    token = token or None
    if token is None and not is_loopback(host):
        raise slr_sql.SLRError(
            f"refusing to serve on {host or 'every interface'} without a token: anyone who can "
            f"reach it could read and change the store. Give --token TOKEN (or set SLR_TOKEN), "
            f"or bind to 127.0.0.1")
    if bool(ssl_keyfile) != bool(ssl_certfile):
        raise slr_sql.SLRError("TLS needs both --ssl-keyfile and --ssl-certfile")
    robot_tokens = list(robot_tokens)
    from .auth import BearerToken
    BearerToken(token, robot_tokens)   # (refused before anything opens: the same check)
    try:
        import uvicorn  # noqa: F401 - (missing: said here, before anything opens)

        from .app import Limits, create_app
        # (the subscriptions' WebSocket protocol imports websockets: missing, it is said here)
        from .ws_protocol import SubscriberWebSocketProtocol  # noqa: F401
        # uvicorn's C parser of HTTP (~10% less server CPU than h11), which uvicorn imports
        # only once it serves
        if importlib.util.find_spec("httptools") is None:
            raise ImportError(name="httptools")
    except ImportError as exc:
        raise slr_sql.SLRError(f"slr serve needs the service extra ({exc.name} is missing): "
                               f"pip install 'slr_sql[service]'") from None
    if foxglove is not None and db == ":memory:":
        # (the view reads the store through a connection of its own: a second store in memory)
        raise slr_sql.SLRError("slr serve --foxglove needs the store's file: a store in memory "
                               "(':memory:') is seen by the server's own connection only")
    limits = limits or Limits()
    sock = listen_on(host, port)
    try:
        options: dict[str, Any] = {} if cache_mib is None else {"cache_mib": cache_mib}
        if busy_timeout is not None:
            options["busy_timeout"] = busy_timeout
        kb = slr_sql.open(db, checkpoint="background", **options)  # no add waits for a checkpoint
    except BaseException:
        sock.close()
        raise
    view = view_kb = None
    try:
        if foxglove is not None:
            from ..viz.foxglove_live import FoxgloveView, forward_sdk_log

            view_log = foxglove_logger()
            forward_sdk_log(lambda level, text: view_log.log(level, "foxglove: %s", text))
            view_kb = slr_sql.open(db)   # a connection of its own: it reads while others write
            try:
                view = FoxgloveView(view_kb.store, host=foxglove[0], port=foxglove[1],
                                    message_max_bytes=foxglove_message_max,
                                    log=lambda text: view_log.warning("%s", text)).start()
            except OSError as exc:
                raise slr_sql.SLRError(f"cannot listen on {foxglove[0]}:{foxglove[1]} for "
                                       f"Foxglove: {exc}") from None
        app = create_app(kb, token=token, limits=limits, robot_tokens=robot_tokens)
        config = uvicorn_config(app, limits, max_connections=max_connections,
                                ssl_keyfile=ssl_keyfile, ssl_certfile=ssl_certfile,
                                log_level=log_level, ws_compression=ws_compression,
                                shutdown_grace=shutdown_grace)
        server = service_server(config)
        throttle_stranger_logs()   # (after uvicorn.Config, which sets up uvicorn's loggers)
        bound_host, bound_port = sock.getsockname()[:2]
        shown = f"[{bound_host}]" if ":" in bound_host else bound_host
        scheme = "https" if ssl_certfile else "http"
        prepare_collector_for_serving()
        prepare_switching_for_serving()
        if view is not None:
            print(f"slr serve: foxglove on ws://{foxglove[0]}:{view.port}", flush=True)
        # (kb.path: a PostgreSQL URL without its password, as every message shows it)
        print(f"slr serve: {kb.path or db} on {scheme}://{shown}:{bound_port}", flush=True)
        with _stop_on_signals(), _warnings_as_stranger_lines():
            server.run(sockets=[sock])
    except _Stop:
        pass   # uvicorn shut down gracefully and re-raised SIGINT/SIGTERM: a normal exit
    finally:
        sock.close()
        if view is not None:
            view.close()
        if view_kb is not None:
            view_kb.close()
        kb.close()


@click.command("serve")
@click.argument("db", type=click.Path(dir_okay=False))
@click.option("--host", default="127.0.0.1", show_default=True,
              help="Address to listen on; anything but loopback needs a token.")
@click.option("--port", default=8765, type=click.IntRange(0, 65535), show_default=True,
              help="Port (0: any free port; the URL is printed).")
@click.option("--token", envvar="SLR_TOKEN", default=None,
              help="Clients must send it (Authorization: Bearer TOKEN). Default: $SLR_TOKEN.")
@click.option("--robot-tokens", "robot_tokens_file", default=None, metavar="FILE",
              help="Tokens of robots, a line 'ROBOT TOKEN' each (or 'ROBOT TOKEN relays "
                   "ROBOT...'): a robot's token may only ship to the fleet store as that "
                   "robot (slr fleet push). Read once, at the start; needs --token.")
@click.option("--max-body", default=1 << 20, type=click.IntRange(1024), show_default=True,
              help="Largest request body, bytes (larger: HTTP 413).")
@click.option("--max-query-time", default=30.0, type=click.FloatRange(0.001),
              show_default=True, help="Seconds a query may run (the cap of timeout=).")
@click.option("--max-wait", default=3600.0, type=click.FloatRange(0.001), show_default=True,
              help="Seconds a synchronized query may wait.")
@click.option("--max-running-queries", default=4, type=click.IntRange(1), show_default=True,
              help="Queries and SQL statements evaluated at once; the others wait for a "
                   "slot (HTTP 503 after --max-query-time). Adds never wait for one.")
@click.option("--max-connections", default=1000, type=click.IntRange(1), show_default=True,
              help="Open connections at once (beyond: HTTP 503).")
@click.option("--ssl-keyfile", type=click.Path(exists=True, dir_okay=False), default=None,
              help="TLS private key (with --ssl-certfile); or put a TLS proxy in front.")
@click.option("--ssl-certfile", type=click.Path(exists=True, dir_okay=False), default=None,
              help="TLS certificate chain.")
@click.option("--ws-compression/--no-ws-compression", default=False, show_default=True,
              help="Compress WebSocket frames (permessage-deflate) for clients that offer it.")
@click.option("--cache-mib", default=64.0, type=click.FloatRange(0.0625, 1 << 20),
              show_default=True,
              help="SQLite page cache of the store (the memory that grows with the store until "
                   "full).")
@click.option("--foxglove", "foxglove", is_flag=True,
              help="Also serve a live Foxglove view of DB (WebSocket; slr foxglove).")
@click.option("--foxglove-host", default="127.0.0.1", show_default=True,
              help="Address of the Foxglove view (it has no token).")
@click.option("--foxglove-port", default=8766, type=click.IntRange(0, 65535), show_default=True,
              help="Port of the Foxglove view.")
@click.option("--foxglove-message-max", default=64 * 1024, type=click.IntRange(1024, 1 << 30),
              show_default=True, metavar="BYTES",
              help="Largest message of the Foxglove view (slr foxglove --message-max).")
@click.option("--shutdown-grace", default=SHUTDOWN_GRACE, type=click.FloatRange(0.0),
              show_default=True, metavar="SECONDS",
              help="On SIGINT/SIGTERM, how long requests in flight (a waiting synchronized "
                   "query) may finish before the server stops.")
@click.option("--request-timeout", default=30.0, type=click.FloatRange(0.001),
              show_default=True, metavar="SECONDS",
              help="How long a client may take to send a request's headers, and then its "
                   "body (HTTP 408); a connection that sends no request is closed after it.")
@click.option("--busy-timeout", default=DEFAULT_BUSY_TIMEOUT, type=click.FloatRange(0.0),
              show_default=True, metavar="SECONDS",
              help="How long a request waits for another process's lock on DB before it is "
                   "answered 503 with Retry-After.")
def serve(db: str, host: str, port: int, token: str | None, max_body: int,
          max_query_time: float, max_wait: float, max_running_queries: int,
          max_connections: int,
          ssl_keyfile: str | None, ssl_certfile: str | None, ws_compression: bool,
          cache_mib: float, foxglove: bool, foxglove_host: str, foxglove_port: int,
          foxglove_message_max: int,
          shutdown_grace: float, request_timeout: float, busy_timeout: float,
          robot_tokens_file: str | None) -> None:
    """Serve DB to other processes over HTTP/JSON and WebSocket (docs/service.md).

    Clients: slr_sql.connect(URL, token=...) or any slr command with the URL in place of DB.
    """
    try:
        from .app import Limits
    except ImportError as exc:
        raise slr_sql.SLRError(f"slr serve needs the service extra ({exc.name} is missing): "
                               f"pip install 'slr_sql[service]'") from None
    from .auth import read_robot_tokens
    robot_tokens = [] if robot_tokens_file is None else read_robot_tokens(robot_tokens_file)
    limits = Limits(max_body=max_body, max_query_time=max_query_time, max_wait=max_wait,
                    max_running_queries=max_running_queries, body_timeout=request_timeout)
    run_server(db, host, port, token, limits=limits, max_connections=max_connections,
               ssl_keyfile=ssl_keyfile, ssl_certfile=ssl_certfile,
               ws_compression=ws_compression, cache_mib=cache_mib,
               foxglove=(foxglove_host, foxglove_port) if foxglove else None,
               foxglove_message_max=foxglove_message_max, shutdown_grace=shutdown_grace,
               busy_timeout=busy_timeout, robot_tokens=robot_tokens)
    sys.stdout.flush()
