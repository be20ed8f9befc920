"""The WebSocket connection of ``slr serve``: uvicorn's own (``websockets``' sans-I/O
protocol) offering the app one more ASGI extension, ``slr.websocket.frames``, through which
an answer frame already framed once is written to the socket as it is.

Why: at 100 subscribers to one pattern every answer frame goes out 100 times with the same
bytes; through ASGI each send is a coroutine chain, a UTF-8 encoding and a framing of its own
(~10 µs of the event loop per frame on the 2-core machine of benchmarks/README.md, against the
socket's own ~15). A server-to-client frame is never masked (RFC 6455 §5.1), so one framing
serves every connection. The extension is offered only where that holds: the connection
negotiated no per-message compression (``--ws-compression`` and a client asking for it).
An app run by another server finds no extension and sends through ASGI as before.
"""
from __future__ import annotations

import weakref
from typing import Any, Callable

from uvicorn.protocols.websockets.websockets_sansio_impl import WebSocketsSansIOProtocol

from .fanout import FRAMES_EXTENSION


class SocketFrameChannel:
    """What the ``slr.websocket.frames`` extension hands the app for one connection: write
    a whole frame, know whether the socket's buffer is full, and be told when it drained
    (``on_drain``, also called when the connection is lost).

    ``write`` returns False (and writes nothing) once the connection is closing or closed:
    the caller stops delivering there, as a failed ASGI send would make it. The channel
    holds its connection weakly: the connection's scope holds the channel, and a cycle
    would leave both to the cyclic collector."""

    __slots__ = ("_protocol", "on_drain")

    def __init__(self, protocol: "SubscriberWebSocketProtocol"):
        self._protocol = weakref.ref(protocol)
        self.on_drain: Callable[[], None] | None = None

    @property
    def paused(self) -> bool:
        """The transport's buffer is above its high-water mark: wait for ``on_drain``."""
        p = self._protocol()
        return p is not None and not p.writable.is_set()

    @property
    def open(self) -> bool:
        """Frames may still be written."""
        p = self._protocol()
        return p is not None and not (p.disconnected or p.close_sent or
                                      p.transport.is_closing())

    def writer(self) -> Callable[[bytes], object] | bool | None:
        """All three checks of a frame's write in one call: False once the connection is
        closing or closed, None while the buffer is full (wait for ``on_drain``), else the
        transport's own write, valid until the loop runs something else (nothing but the
        loop's thread changes the connection). The fan-out asks this once per frame: the
        properties and :meth:`write` would each look the connection up again."""
        p = self._protocol()
        if p is None or p.disconnected or p.close_sent:
            return False
        transport = p.transport
        if transport.is_closing():
            return False
        if not p.writable.is_set():
            return None
        return transport.write

    def write(self, frame: bytes) -> bool:
        """Write one whole frame (:func:`~slr_sql.service.fanout.text_frame`); False if
        the connection is closing or closed."""
        p = self._protocol()
        if p is None or p.disconnected or p.close_sent or p.transport.is_closing():
            return False
        p.transport.write(frame)
        return True


class SubscriberWebSocketProtocol(WebSocketsSansIOProtocol):
    """uvicorn's sans-I/O WebSocket protocol (what its ``ws="auto"`` picks since 0.50) plus the
    ``slr.websocket.frames`` extension in each connection's scope (see the module)."""

    def handle_connect(self, event: Any) -> None:
        super().handle_connect(event)
        scope = getattr(self, "scope", None)
        # (the handshake accepted, and no compression negotiated: a frame framed once is
        # what the client reads; with compression each connection compresses its own)
        if scope is not None and not self.conn.extensions and _tracks_flow(self):
            self.frame_channel = SocketFrameChannel(self)
            scope["extensions"][FRAMES_EXTENSION] = {"channel": self.frame_channel}

    def resume_writing(self) -> None:
        super().resume_writing()
        channel: SocketFrameChannel | None = getattr(self, "frame_channel", None)
        if channel is not None and channel.on_drain is not None:
            channel.on_drain()

    def connection_lost(self, exc: Exception | None) -> None:
        super().connection_lost(exc)
        channel: SocketFrameChannel | None = getattr(self, "frame_channel", None)
        if channel is not None and channel.on_drain is not None:
            channel.on_drain()       # a delivery parked on a full buffer learns it is gone


def _tracks_flow(protocol: WebSocketsSansIOProtocol) -> bool:
    """The protocol keeps what the channel reads (its connection state and flow control:
    uvicorn 0.52.1 on, the floor pyproject.toml sets); without it the app sends through
    ASGI."""
    return all(hasattr(protocol, name) for name in ("writable", "disconnected", "close_sent"))


def http_protocol_with_header_timeout(seconds: float) -> type:
    """uvicorn's HTTP protocol (httptools) closing a connection whose request headers did
    not arrive within ``seconds`` of its opening, or of the first byte of a later request
    on it (``slr serve --request-timeout``). uvicorn arms no timer until the headers are
    complete: a client that opened connections and sent a request's first line, or
    nothing at all, held each one for as long as it liked, and ``--max-connections`` of
    them (1000, from any one client) left every other client a 503 for as long as they
    stayed (a "slowloris"). The body has its own limit (the app's ``body_timeout``), and a
    connection idle between requests uvicorn's keep-alive timeout.

    >>> protocol = http_protocol_with_header_timeout(30.0)
    >>> protocol.header_timeout, protocol.__name__
    (30.0, 'HeaderTimeoutHttpToolsProtocol')
    """
    from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol

    class HeaderTimeoutHttpToolsProtocol(HttpToolsProtocol):
        header_timeout = seconds
        _header_timer: Any = None

        def _arm_header_timer(self) -> None:
            if self._header_timer is None:
                self._header_timer = self.loop.call_later(self.header_timeout,
                                                          self._headers_too_slow)

        def _cancel_header_timer(self) -> None:
            if self._header_timer is not None:
                self._header_timer.cancel()
                self._header_timer = None

        def _headers_too_slow(self) -> None:
            self._header_timer = None
            if not self.transport.is_closing():
                self.transport.close()    # (nothing to answer: no request was read)

        def connection_made(self, transport: Any) -> None:  # type: ignore[override]
            super().connection_made(transport)
            self._arm_header_timer()

        def on_message_begin(self) -> None:
            super().on_message_begin()
            self._arm_header_timer()

        def on_headers_complete(self) -> None:
            self._cancel_header_timer()
            super().on_headers_complete()

        def connection_lost(self, exc: Exception | None) -> None:
            self._cancel_header_timer()
            super().connection_lost(exc)

    return HeaderTimeoutHttpToolsProtocol
