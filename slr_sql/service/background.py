"""The network service of an open knowledge base, served by a thread of this process.

``slr serve DB`` (:func:`slr_sql.service.cli.run_server`) is the service as a program: it
opens the store, serves until a signal, and tunes the process for serving. A Python
program that holds a knowledge base already -- a robot's node that also answers remote
clients, an example, a test of code written against :func:`slr_sql.connect` -- serves it
with :class:`BackgroundServer` instead: the same application and limits, on a port of its
own, stopped when the ``with`` block ends. The caller keeps its knowledge base open and
closes it afterwards.
"""
from __future__ import annotations

import enum
import threading
from typing import TYPE_CHECKING, Any

import slr_sql

if TYPE_CHECKING:
    import socket

    from ..kb import KnowledgeBase

__all__ = ["BackgroundServer", "ServerState", "is_loopback", "listen_on", "service_server",
           "uvicorn_config"]


def is_loopback(host: str) -> bool:
    """True when every address ``host`` names is a loopback address.

    >>> is_loopback("127.0.0.1"), is_loopback("::1"), is_loopback("0.0.0.0"), is_loopback("")
    (True, True, False, False)
    """
    # socket and ipaddress are imported here and in listen_on, where used: every `slr` command
    # imports this module (its `serve` is on the group), and socket costs ~5 ms to import
    import ipaddress
    import socket

    host = host.strip().strip("[]")
    if not host:
        return False      # "" binds every interface
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        pass
    try:
        infos = socket.getaddrinfo(host, None)
    except OSError:
        return False
    return bool(infos) and all(ipaddress.ip_address(str(info[4][0]).split("%")[0]).is_loopback
                               for info in infos)


def listen_on(host: str, port: int) -> socket.socket:
    """A listening socket on host:port (port 0: any free port): listening before a server
    runs on it, so that clients may connect at once.

    >>> sock = listen_on("127.0.0.1", 0); sock.getsockname()[1] > 0
    True
    >>> sock.close()
    """
    import socket

    try:
        infos = socket.getaddrinfo(host or None, port, type=socket.SOCK_STREAM,
                                   flags=socket.AI_PASSIVE)
    except OSError as exc:
        raise slr_sql.SLRError(f"cannot listen on {host}:{port}: {exc}") from None
    last: OSError | None = None
    for family, kind, proto, _name, address in infos:
        sock = socket.socket(family, kind, proto)
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            sock.bind(address)
            sock.listen(512)
            sock.set_inheritable(True)
            return sock
        except OSError as exc:
            sock.close()
            last = exc
    raise slr_sql.SLRError(f"cannot listen on {host}:{port}: "
                           f"{getattr(last, 'strerror', None) or last}")


def uvicorn_config(app: Any, limits: Any, *, max_connections: int | None = 1000,
                   ssl_keyfile: str | None = None, ssl_certfile: str | None = None,
                   log_level: str = "warning", ws_compression: bool = False,
                   shutdown_grace: float = 10.0) -> Any:
    """The uvicorn configuration both ways of serving use: the WebSocket protocol of
    subscriptions, the C parser of HTTP with a bound on the time its headers take (the
    body's, ``limits.body_timeout``), no server header, the request body bound.

    >>> from slr_sql.service.app import Limits, create_app
    >>> with slr_sql.open() as kb:
    ...     config = uvicorn_config(create_app(kb), Limits())
    >>> config.ws_max_size == Limits().max_body, config.server_header
    (True, False)
    """
    import uvicorn

    from .ws_protocol import SubscriberWebSocketProtocol, http_protocol_with_header_timeout
    return uvicorn.Config(app, log_level=log_level, access_log=False, lifespan="off",
                          ws_max_size=limits.max_body, limit_concurrency=max_connections,
                          timeout_keep_alive=30, ssl_keyfile=ssl_keyfile,
                          ssl_certfile=ssl_certfile, server_header=False,
                          ws_per_message_deflate=ws_compression,
                          ws=SubscriberWebSocketProtocol,
                          # httptools, closing a connection whose headers do not come
                          http=http_protocol_with_header_timeout(limits.body_timeout),
                          loop="asyncio",   # what the WebSocket protocol is tested on
                          # (uvicorn waits with asyncio.wait_for: seconds as a float)
                          timeout_graceful_shutdown=shutdown_grace)  # type: ignore[arg-type]


# Seconds between two looks at the connections and tasks a stopping server waits for
# (uvicorn looks every 0.1 s: each stop of a server that had a client took 0.1-0.3 s)
SHUTDOWN_POLL = 0.005


# What the shorter stop of service_server reads of uvicorn.Server (set by its startup)
_UVICORN_SHUTDOWN_ATTRIBUTES = ("servers", "server_state", "lifespan", "force_exit", "config")


def service_server(config: Any) -> Any:
    """The uvicorn ``Server`` of ``config`` (see :func:`uvicorn_config`), which tells the
    service it begins to stop before it waits for the requests in flight: a poll answers
    the state as it is and a synchronized query 503 at once, instead of holding the stop
    for its whole grace.

    Its ``request_exit()`` (from any thread, or a signal) wakes the serving loop at once:
    uvicorn's loop looks at ``should_exit`` every 0.1 s, and its shutdown then slept 0.1 s
    and looked for the connections' end every 0.1 s. The stop does what uvicorn's does
    (listening ends, idle connections close, the requests in flight get the grace, then
    what still runs is cancelled), looking every :data:`SHUTDOWN_POLL` seconds instead.

    >>> from slr_sql.service.app import Limits, create_app
    >>> with slr_sql.open() as kb:
    ...     server = service_server(uvicorn_config(create_app(kb), Limits()))
    ...     sock = listen_on("127.0.0.1", 0)
    ...     serving = threading.Thread(target=server.run, kwargs={"sockets": [sock]})
    ...     serving.start(); server.request_exit(); serving.join(30)
    >>> serving.is_alive(); sock.close()
    False
    """
    import asyncio
    import logging

    import uvicorn

    class ServiceServer(uvicorn.Server):
        _wake: asyncio.Event | None = None
        _loop: asyncio.AbstractEventLoop | None = None

        def request_exit(self) -> None:
            """Stop serving, now rather than at the loop's next tick (thread-safe)."""
            self.should_exit = True
            loop, wake = self._loop, self._wake
            if loop is not None and wake is not None:
                try:
                    loop.call_soon_threadsafe(wake.set)
                except RuntimeError:     # the loop has ended already
                    pass

        def handle_exit(self, sig: int, frame: Any) -> None:
            super().handle_exit(sig, frame)        # (SIGINT, SIGTERM of `slr serve`)
            self.request_exit()

        async def main_loop(self) -> None:
            self._wake = asyncio.Event()
            self._loop = asyncio.get_running_loop()
            counter = 0
            should_exit = await self.on_tick(counter)
            while not should_exit:
                counter = (counter + 1) % 864000
                if not self.should_exit:      # (set before the wake existed: no wait)
                    try:
                        await asyncio.wait_for(self._wake.wait(), 0.1)
                    except asyncio.TimeoutError:
                        pass
                should_exit = await self.on_tick(counter)

        async def shutdown(self, sockets: Any = None) -> None:
            service = getattr(getattr(self.config.app, "state", None), "service", None)
            if service is not None:
                service.stopping.set()
            if not self.knows_uvicorn_shutdown():
                # a uvicorn whose internals moved: its own stop, slower but its own
                await super().shutdown(sockets)
                return
            # uvicorn's shutdown (0.54), its fixed pause and 0.1 s looks made shorter
            for server in self.servers:
                server.close()
            for sock in sockets or []:
                sock.close()
            for connection in list(self.server_state.connections):
                connection.shutdown()
            try:
                await asyncio.wait_for(self._wait_for_requests(),
                                       timeout=self.config.timeout_graceful_shutdown)
            except asyncio.TimeoutError:
                logging.getLogger("uvicorn.error").error(
                    "stopping: %s request(s) still running after the %s s grace are cancelled",
                    len(self.server_state.tasks), self.config.timeout_graceful_shutdown)
                for task in self.server_state.tasks:
                    task.cancel(msg="the server's stop grace ended")
            if not self.force_exit:
                await self.lifespan.shutdown()

        def knows_uvicorn_shutdown(self) -> bool:
            """Whether this uvicorn keeps the state the shorter stop reads (0.52-0.54 do);
            a later one that moved it gets its own stop instead of an AttributeError."""
            state = getattr(self, "server_state", None)
            return (all(hasattr(self, name) for name in _UVICORN_SHUTDOWN_ATTRIBUTES)
                    and hasattr(state, "connections") and hasattr(state, "tasks"))

        async def _wait_for_requests(self) -> None:
            state = self.server_state
            while (state.connections or state.tasks) and not self.force_exit:
                await asyncio.sleep(SHUTDOWN_POLL)
            for server in self.servers:
                await server.wait_closed()

    return ServiceServer(config)


class ServerState(enum.Enum):
    """Where a :class:`BackgroundServer` is in its life: made, serving, or stopped (a
    stopped server does not start again: make another).

    >>> with slr_sql.open() as kb:
    ...     server = BackgroundServer(kb); made = server.state
    ...     with server: serving = server.state
    >>> made, serving, server.state
    (<ServerState.MADE: 'made'>, <ServerState.SERVING: 'serving'>, <ServerState.STOPPED: 'stopped'>)
    """

    MADE = "made"
    SERVING = "serving"
    STOPPED = "stopped"


class BackgroundServer:
    """Serve the knowledge base ``kb`` on ``host:port`` (port 0: a free one) from a thread
    of this process until :meth:`stop` or the end of the ``with`` block; :attr:`url` is
    where :func:`slr_sql.connect` reaches it. The socket listens before :meth:`start`
    returns, so a client may connect at once. ``token``, ``robot_tokens`` (a list of
    :class:`~slr_sql.service.auth.RobotToken`) and ``limits`` as for ``slr serve``; a
    non-loopback host needs a token.

    >>> import slr_sql
    >>> with slr_sql.open(clock=slr_sql.ManualClock(10)) as local:
    ...     with BackgroundServer(local) as server, slr_sql.connect(server.url) as kb:
    ...         kb.add("seen(cup1)^2")
    ...         [answer["X"] for answer in kb.query("seen(X)^T")]
    [Atom('cup1')]
    """

    def __init__(self, kb: KnowledgeBase, host: str = "127.0.0.1", port: int = 0,
                 token: str | None = None, *, limits: Any = None,
                 max_connections: int | None = 1000, stop_grace: float = 5.0,
                 robot_tokens: Any = ()) -> None:
        if not token and not is_loopback(host):
            raise slr_sql.SLRError(f"refusing to serve on {host or 'every interface'} "
                                   f"without a token: give token=...")
        self.kb = kb
        self.host, self.port = host, port
        self.token = token or None
        self.robot_tokens = list(robot_tokens)
        from .auth import BearerToken
        BearerToken(self.token, self.robot_tokens)   # (refused here, before any socket)
        self.limits = limits
        self.max_connections = max_connections
        self.stop_grace = stop_grace
        self.state = ServerState.MADE
        self._server: Any = None
        self._thread: threading.Thread | None = None
        self._socket: Any = None

    @property
    def url(self) -> str:
        """``http://HOST:PORT`` of the serving server.

        >>> with slr_sql.open() as kb, BackgroundServer(kb, port=0) as server:
        ...     server.url == f"http://127.0.0.1:{server.port}" and server.port > 0
        True
        """
        if self.state is not ServerState.SERVING:
            raise slr_sql.SLRError(f"the server is {self.state.value}, not serving")
        shown = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{shown}:{self.port}"

    def start(self) -> "BackgroundServer":
        """Listen and serve from a thread; returns the server (serving).

        >>> kb = slr_sql.open(); server = BackgroundServer(kb).start()
        >>> with slr_sql.connect(server.url) as remote: remote.health()["status"]
        'ok'
        >>> server.stop(); kb.close()
        """
        if self.state is not ServerState.MADE:
            raise slr_sql.SLRError(f"the server is {self.state.value}: make another to "
                                   f"serve again")
        try:
            import uvicorn  # noqa: F401 - (missing: said here, before anything opens)

            from .app import Limits, create_app
        except ImportError as exc:
            raise slr_sql.SLRError(f"serving needs the service extra ({exc.name} is "
                                   f"missing): pip install 'slr_sql[service]'") from None
        limits = self.limits or Limits()
        sock = listen_on(self.host, self.port)
        app = create_app(self.kb, token=self.token, limits=limits,
                         robot_tokens=self.robot_tokens)
        server = service_server(uvicorn_config(app, limits,
                                               max_connections=self.max_connections,
                                               shutdown_grace=self.stop_grace))
        self.host, self.port = sock.getsockname()[:2]
        self._socket, self._server = sock, server
        # (uvicorn leaves signals alone outside the main thread: they stay the program's)
        self._thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]},
                                        name=f"slr-serve:{self.port}", daemon=True)
        self._thread.start()
        self.state = ServerState.SERVING
        return self

    def stop(self) -> None:
        """Stop serving: requests in flight get ``stop_grace`` seconds, then the thread ends
        and the socket closes. The knowledge base stays open (it is the caller's). Prompt
        once nothing is in flight (see :func:`service_server`); stopping again does nothing.

        >>> kb = slr_sql.open(); server = BackgroundServer(kb).start(); server.stop()
        >>> server.state, kb.query("true"); server.stop()
        (<ServerState.STOPPED: 'stopped'>, [{}])
        >>> kb.close()
        """
        if self.state is not ServerState.SERVING:
            self.state = ServerState.STOPPED
            return
        self.state = ServerState.STOPPED
        self._server.request_exit()
        if self._thread is not None:
            self._thread.join(self.stop_grace + 5.0)
        self._socket.close()

    def __enter__(self) -> "BackgroundServer":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
