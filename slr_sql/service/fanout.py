"""Delivering the WebSocket subscribers of one event loop together: when the hub's pass
queued answers, one callback of the loop takes each caught-up subscriber's batch and writes its
frame, instead of resuming one coroutine per subscriber (its wait, its send through ASGI).

A subscriber is delivered this way when its connection offers a :class:`FrameChannel`
(``slr serve``'s own WebSocket protocol, service/ws_protocol.py) and it did not ask to
acknowledge; otherwise the service's coroutine loop delivers it, frame by frame, as before.
What a subscriber sees is the same either way: ``answer``/``answers`` frames numbered by
``seq``, at most ``batch`` answers each, in order, then its end or error (sent by its
coroutine, which waits on :attr:`Delivery.finished`).

Flow control is the socket's: a connection whose buffer is above its high-water mark is not
taken from until it drains, so its answers stay in its bounded queue and, beyond it, in the
store (the hub's lagging path), as when an ASGI send waits for the drain.
"""
from __future__ import annotations

import asyncio
from typing import Any, Callable, Protocol

FRAMES_EXTENSION = "slr.websocket.frames"   # the ASGI scope extension offering a channel
GONE = "gone"   # what ``finished`` holds when the client's connection closed first


class FrameChannel(Protocol):
    """A WebSocket connection that takes whole frames (``slr serve``'s: service/ws_protocol.py)."""

    on_drain: Callable[[], None] | None

    @property
    def paused(self) -> bool: ...

    @property
    def open(self) -> bool: ...

    def write(self, frame: bytes) -> bool: ...

    def writer(self) -> Callable[[bytes], object] | bool | None:
        """False once the connection is closing or closed, None while ``paused``, else a
        function that writes one whole frame now (until the loop runs something else)."""


def text_frame(payload: bytes) -> bytes:
    """One unmasked, final WebSocket text frame (RFC 6455 §5.2) holding ``payload`` (UTF-8):
    a server's frame is never masked, so one framing serves every connection.

    >>> text_frame(b'{"a":1}')
    b'\\x81\\x07{"a":1}'
    """
    n = len(payload)
    if n < 126:
        return bytes((0x81, n)) + payload
    if n < 65536:
        return bytes((0x81, 126)) + n.to_bytes(2, "big") + payload
    return bytes((0x81, 127)) + n.to_bytes(8, "big") + payload


class Delivery:
    """One WebSocket subscriber delivered by a :class:`FanOut`. Its ``finished`` future ends
    with ``None`` (the subscription ended: send the end), :data:`GONE` (the connection closed:
    nothing more to send) or the subscription's error."""

    __slots__ = ("sub", "channel", "batch", "seq", "finished", "_fanout", "_marked", "_over")

    def __init__(self, fanout: "FanOut", sub: Any, channel: FrameChannel, batch: int):
        self.sub = sub
        self.channel = channel
        self.batch = batch
        self.seq = 0
        self.finished: asyncio.Future = fanout.loop.create_future()
        self._fanout = fanout
        self._marked = False
        self._over = False

    # the hub wakes a subscriber through (loop, obj) with obj.done() / obj.set_result(None)
    def done(self) -> bool:
        return self._over

    def set_result(self, _: Any) -> None:
        self._fanout.mark(self)

    def _finish(self, outcome: Any = None, error: BaseException | None = None) -> None:
        self._over = True
        self.channel.on_drain = None
        # (nothing of the connection or the subscription stays reachable from the other:
        # reference counting frees both, as it does the coroutine path's)
        self.sub = self.channel = _ENDED
        if self.finished.done():     # its coroutine was cancelled (the server stops)
            return
        if error is not None:
            self.finished.set_exception(error)
        else:
            self.finished.set_result(outcome)

    def pump(self) -> None:
        """Write every frame this subscriber can take now (on the loop's thread): until its
        queue is empty (its waker then registered), its socket's buffer is full (the drain
        marks it again), or it ended."""
        self._marked = False
        if self._over:
            return
        channel, sub, fanout = self.channel, self.sub, self._fanout
        waker = (fanout.loop, self)
        while True:
            write = channel.writer()
            if write is None:
                return                  # its buffer is full: the drain marks it again
            if write is False:
                self._finish(GONE)
                return
            try:
                answers = sub.take_answers(self.batch, waker)
            except Exception as exc:  # noqa: BLE001 - the error that ended it: its coroutine sends it
                self._finish(error=exc)
                return
            if answers is None:
                self._finish(None)
                return
            if not answers:
                return                  # the waker is registered: the hub marks it again
            seq = self.seq + 1
            self.seq += len(answers)
            write(fanout.frame(seq, answers))     # (the take left the connection as it was)
            if len(answers) < self.batch and sub.waits_with(waker):
                return                  # the batch emptied the queue; what comes next wakes it


class _Ended:
    """What a finished delivery holds instead of its subscription and channel."""

    on_drain = None
    open = False


_ENDED: Any = _Ended()


class FanOut:
    """The WebSocket subscribers delivered on one event loop (see the module).

    >>> import asyncio, slr_sql
    >>> class Socket:                       # a connection's frame channel, in memory
    ...     on_drain, paused, open, frames = None, False, True, []
    ...     def write(self, frame): self.frames.append(frame); return True
    ...     def writer(self): return self.write
    >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0)); loop = asyncio.new_event_loop()
    >>> fanout = FanOut(loop, lambda seq, answers: f'{{"seq":{seq},"n":{len(answers)}}}')
    >>> socket = Socket(); delivery = fanout.start(kb.subscribe("p(X)^T", since=0), socket, 256)
    >>> rejected = kb.add_many(["p(a)^1", "p(b)^2"])
    >>> async def written():
    ...     while not socket.frames: await asyncio.sleep(0.001)
    >>> loop.run_until_complete(written()); socket.frames
    [b'\\x81\\x0f{"seq":1,"n":2}']
    >>> delivery.sub.close(); loop.run_until_complete(delivery.finished) is None
    True
    >>> loop.close(); kb.close()
    """

    def __init__(self, loop: asyncio.AbstractEventLoop,
                 frame_text: Callable[[int, list[dict]], str]):
        self.loop = loop
        self._frame_text = frame_text
        self._ready: list[Delivery] = []
        self._scheduled = False
        self._last: tuple | None = None
        self._last_frame = b""

    def start(self, sub: Any, channel: FrameChannel, batch: int) -> Delivery:
        """Deliver ``sub`` through ``channel`` from now on; await the result's ``finished``."""
        delivery = Delivery(self, sub, channel, batch)
        channel.on_drain = lambda: self.mark(delivery)
        self.mark(delivery)
        return delivery

    def mark(self, delivery: Delivery) -> None:
        """``delivery`` may take answers: pump it in this loop's next flush (one callback for
        every delivery marked meanwhile). On the loop's thread."""
        if delivery._marked or delivery._over:
            return
        delivery._marked = True
        self._ready.append(delivery)
        if not self._scheduled:
            self._scheduled = True
            self.loop.call_soon(self._flush)

    def _flush(self) -> None:
        self._scheduled = False
        ready, self._ready = self._ready, []
        for delivery in ready:
            try:
                delivery.pump()
            except Exception as exc:  # noqa: BLE001 - one connection's failure ends only it
                delivery._finish(error=exc)
            except BaseException:
                # (a KeyboardInterrupt, a cancel) the ones after it are still marked, so no
                # wake of the hub would queue them again: they go to the next flush
                rest = ready[ready.index(delivery) + 1:]
                if rest:
                    self._ready[:0] = rest
                    if not self._scheduled:
                        self._scheduled = True
                        self.loop.call_soon(self._flush)
                raise

    def frame(self, seq: int, answers: list[dict]) -> bytes:
        """The framed bytes of an answer frame; the subscribers of one pattern that are at the
        same place get the same answer dicts in the same order, so the last frame is kept."""
        n = len(answers)
        first, middle, last = answers[0], answers[n >> 1], answers[-1]
        cached = self._last
        if cached is not None and cached[0] == seq and cached[1] == n and \
                cached[2] is first and cached[3] is middle and cached[4] is last:
            return self._last_frame
        frame = text_frame(self._frame_text(seq, answers).encode())
        self._last, self._last_frame = (seq, n, first, middle, last), frame
        return frame
