"""The WebSocket connection of ``slr serve``: uvicorn's own (``websockets``' sans-I/O
protocol) offering the app one more ASGI extension, ``slr.websocket.frames``, through which
an answer frame already framed once is written to the socket as it is.

Why: at 100 subscribers to one pattern every answer frame goes out 100 times with the same
bytes; through ASGI each send is a coroutine chain, a UTF-8 encoding and a framing of its own
(~10 µs of the event loop per frame on the 2-core machine of benchmarks/README.md, against the
socket's own ~15). A server-to-client frame is never masked (RFC 6455 §5.1), so one framing
serves every connection. The extension is offered only where that holds: no per-message
compression was negotiated (``--ws-compression`` off). An app run by another server finds no
extension and sends through ASGI as before.
"""
from __future__ import annotations

from typing import Any, Callable

from uvicorn.protocols.websockets.websockets_sansio_impl import WebSocketsSansIOProtocol

from .fanout import FRAMES_EXTENSION


class SocketFrameChannel:
    """What the ``slr.websocket.frames`` extension hands the app for one connection: write
    a whole frame, know whether the socket's buffer is full, and be told when it drained.

    ``write`` returns False (and writes nothing) once the connection is closing or closed:
    the caller stops delivering there, as a failed ASGI send would make it."""

    __slots__ = ("_protocol", "on_drain")

    def __init__(self, protocol: "SubscriberWebSocketProtocol"):
        self._protocol = protocol
        self.on_drain: Callable[[], None] | None = None

    @property
    def paused(self) -> bool:
        """The transport's buffer is above its high-water mark: wait for ``on_drain``."""
        return not self._protocol.writable.is_set()

    @property
    def open(self) -> bool:
        p = self._protocol
        return not (p.disconnected or p.close_sent or p.transport.is_closing())

    def write(self, frame: bytes) -> bool:
        p = self._protocol
        if p.disconnected or p.close_sent or p.transport.is_closing():
            return False
        p.transport.write(frame)
        return True


class SubscriberWebSocketProtocol(WebSocketsSansIOProtocol):
    """uvicorn's sans-I/O WebSocket protocol (what its ``ws="auto"`` picks here) plus the
    ``slr.websocket.frames`` extension in each connection's scope (see the module)."""

    def handle_connect(self, event: Any) -> None:
        super().handle_connect(event)
        scope = getattr(self, "scope", None)
        if scope is not None and not self.conn.extensions and \
                not self.config.ws_per_message_deflate:
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
