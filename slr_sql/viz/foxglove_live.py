"""A live Foxglove view of a store: ``slr foxglove DB`` and ``slr serve --foxglove``.

:class:`FoxgloveView` runs a Foxglove WebSocket server (the ``foxglove-sdk`` package,
protocol ``foxglove.websocket.v1``) and a thread that follows the store through a connection
of its own:

* every ``poll`` seconds it asks SQLite whether anyone committed (``PRAGMA data_version``:
  any process, any thread, the bridge, an import, event rules deriving complex events);
* if so, it advertises a channel for each event type it has not seen (:mod:`.channels`),
  reads the rows stored since the last look (by arrival sequence, per type) and logs each as
  one message, its log time the event's end time; ``tf`` and ``tf_static`` rows also go to
  ``/tf`` and ``/tf_static`` as ``foxglove.FrameTransforms`` (the 3D panel's frames);
* completeness marks that moved go to ``/slr/completeness``.

Only events stored after the view started are sent, except the static transforms: the last
one of each edge is sent again when a client subscribes to ``/tf_static`` (at most every
:data:`STATIC_GAP` seconds, however many subscribe; and every ``static_every`` seconds), as
ROS's latched ``/tf_static`` would, so the 3D panel knows the static frames however late it
connects.
"""
from __future__ import annotations

import logging
import re
import threading
import time
from typing import Any, Callable

from ..errors import SLRError
from ..frames import frame_key
from ..log_throttle import LogThrottle, ThrottledLog, line_kind, with_left_out
from ..printable import log_text
from .channels import (JSON_SCHEMA_ENCODING, MARKS_SCHEMA, MARKS_TOPIC, TF_TOPICS,
                       TRANSFORMS_SCHEMA, TRANSFORMS_SCHEMA_NAME, event_channel, mark_message,
                       time_ns, transform_message)

__all__ = ["FoxgloveView", "FoxgloveUnavailable", "FoxgloveCannotListen", "forward_sdk_log",
           "BACKLOG_BYTES", "BACKLOG_MESSAGES", "MESSAGE_MAX_BYTES", "PAGE_BYTES", "PAGE_ROWS"]

_MARK_PREFIX = "sync/mark/"
_TF_STATIC = ("tf_static", 3)
_UNREADABLE = "its rows cannot be read"
_MARK_SOURCE = "sync/marksrc/"
STATIC_GAP = 0.25   # seconds: the least time between two latched /tf_static messages asked for
PAGE_ROWS = 10_000  # rows of one type read in one pass; a full page makes another pass
PAGE_BYTES = 16 << 20   # and at most these bytes of their values (one row at least): the
# view holds a bounded page however large a type's events are
# What the view's server holds for one client that reads too slowly: the foxglove-sdk queues
# at most BACKLOG_MESSAGES messages per client (dropping the oldest beyond), whatever their
# size, so the view sends no message larger than MESSAGE_MAX_BYTES: a client holds at most
# BACKLOG_BYTES (64 MiB) of messages, where 1,024 messages of an event type with megabyte
# arguments held a gigabyte per slow client
BACKLOG_MESSAGES = 1024
MESSAGE_MAX_BYTES = 64 * 1024    # the default; ``message_max_bytes=`` / --message-max
BACKLOG_BYTES = BACKLOG_MESSAGES * MESSAGE_MAX_BYTES


def backlog_messages(message_max_bytes: int) -> int:
    """The messages the SDK may queue for one slow client when none is larger than
    ``message_max_bytes``: as many as make BACKLOG_BYTES (one at least), so a larger cap
    (a camera topic's images) queues fewer of them and the bytes held stay bounded.

    >>> backlog_messages(MESSAGE_MAX_BYTES), backlog_messages(1 << 20), backlog_messages(1 << 30)
    (1024, 64, 1)
    """
    return max(1, BACKLOG_BYTES // message_max_bytes)


class FoxgloveUnavailable(SLRError):
    """The foxglove-sdk package is not installed (``pip install 'slr_sql[foxglove]'``)."""


class FoxgloveCannotListen(SLRError):
    """The view's server cannot listen: the port is taken, the host does not resolve or is
    not an address of this machine."""


# the foxglove-sdk's own lines that say what a reader of the log looks for, in words
_SDK_WORDS = [(re.compile(r"Started server on (\S+)\Z"), "listening on ws://{}"),
              (re.compile(r"Registered client (\S+)\Z"), "client {} connected"),
              (re.compile(r"Unregistered client (\S+)\Z"), "client {} left")]
_SDK_QUIET = re.compile(r"Connection closed by client \S+\Z")   # (said by "left")
_sdk_log_lock = threading.Lock()
_sdk_log_handler: logging.Handler | None = None


def forward_sdk_log(emit: Callable[[int, str], None]) -> None:
    """Send the foxglove-sdk's log at INFO and above -- the server's start, each client
    connecting and leaving, what a client sent that the protocol refuses -- to ``emit(level,
    text)``, each line in words (:func:`~slr_sql.printable.log_text`, no traceback), a kind
    of line (a client connecting, leaving) at most :data:`~slr_sql.log_throttle.BURST` times
    a minute, the next one let through saying how many were left out (a client that connects
    and leaves in a loop). The SDK takes its log level once per process, before its first
    server: call this before starting a view. A later call replaces ``emit``.

    >>> forward_sdk_log(lambda level, text: None)
    """
    global _sdk_log_handler
    try:
        import foxglove
    except ImportError:
        return   # the view says how to install it

    throttle = LogThrottle()

    class Forward(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            try:
                text = record.getMessage()
            except Exception:  # noqa: BLE001 - a line that cannot be made is left out
                return
            if _SDK_QUIET.match(text):
                return
            for pattern, words in _SDK_WORDS:
                found = pattern.match(text)
                if found:
                    text = words.format(found.group(1))
                    break
            left_out = throttle.admit((record.levelno, line_kind(text)))
            if left_out is not None:
                emit(record.levelno, with_left_out(log_text(text), left_out))

    with _sdk_log_lock:
        sdk_logger = logging.getLogger("foxglove")
        if _sdk_log_handler is None:
            # the SDK calls logging.basicConfig when the root logger has no handler: a
            # placeholder keeps the process's logging as it is
            root = logging.getLogger()
            placeholder = logging.NullHandler()
            root.addHandler(placeholder)
            try:
                foxglove.set_log_level("INFO")
            finally:
                root.removeHandler(placeholder)
            sdk_logger.setLevel(logging.INFO)
            sdk_logger.propagate = False
        else:
            sdk_logger.removeHandler(_sdk_log_handler)
        _sdk_log_handler = Forward()
        sdk_logger.addHandler(_sdk_log_handler)


def _schema(name: str, schema: dict) -> Any:
    import json

    import foxglove

    return foxglove.Schema(name=name, encoding=JSON_SCHEMA_ENCODING,
                           data=json.dumps(schema).encode())


class FoxgloveView:
    """The Foxglove server of one store. ``store`` is an :class:`slr_sql.store.EventStore`
    the view may use from its own thread (open one for it: the view reads while others
    write). ``port`` 0 picks a free port (:attr:`port` says which).
    """

    def __init__(self, store: Any, host: str = "127.0.0.1", port: int = 8765,
                 poll: float = 0.002, static_every: float = 5.0, name: str = "slr_sql",
                 log: Callable[[str], None] | None = None,
                 message_max_bytes: int = MESSAGE_MAX_BYTES):
        try:
            import foxglove
        except ImportError as exc:
            raise FoxgloveUnavailable(
                f"the Foxglove view needs the foxglove-sdk package ({exc}): "
                f"pip install 'slr_sql[foxglove]'") from None
        if isinstance(message_max_bytes, bool) or not isinstance(message_max_bytes, int) or \
                message_max_bytes < 1024:
            raise SLRError(f"foxglove: message_max_bytes must be an integer of at least 1024, "
                           f"not {message_max_bytes!r}")
        self.store = store
        self.poll = poll
        self.message_max = message_max_bytes
        self.backlog = backlog_messages(message_max_bytes)
        self._too_large_text = (
            f"messages larger than {message_max_bytes:,} bytes are left out (the view's "
            f"limit, so that a slow client holds at most "
            f"{self.backlog * message_max_bytes / 2 ** 20:g} MiB)")
        self.static_every = static_every
        # (a store's names are in some lines, and a broken store would say so at every poll)
        self.log = ThrottledLog(log or (lambda text: None))
        self.context = foxglove.Context()
        self.channels: dict[tuple[str, int], Any] = {}   # event type -> (EventChannel, Channel)
        self.seen: dict[tuple[str, int], int] = {}       # event type -> arrival sequence read
        self.marks: dict[str, float] = {}
        self.sent = 0
        self._static_due = threading.Event()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._tf: dict[str, Any] = {}
        # the last row of each tf_static edge (parent, child), kept as rows are read: the
        # latched /tf_static message is made from it without reading the history again
        self._static_last: dict[tuple, tuple] = {}
        self._troubles: dict[tuple[str, int], str] = {}   # what was said of a type
        self._too_large: set[str] = set()   # topics whose messages too large were said
        for key, topic in TF_TOPICS.items():
            self._tf[key[0]] = foxglove.Channel(
                topic, schema=_schema(TRANSFORMS_SCHEMA_NAME, TRANSFORMS_SCHEMA),
                message_encoding="json", context=self.context)
        self._marks_channel = foxglove.Channel(
            MARKS_TOPIC, schema=_schema(MARKS_SCHEMA["title"], MARKS_SCHEMA),
            message_encoding="json", context=self.context)
        view = self

        class Listener(foxglove.ServerListener):
            def on_subscribe(self, client: Any, channel: Any) -> None:
                if channel.topic == TF_TOPICS[("tf_static", 3)]:
                    view._static_due.set()

        # the channels of what is stored now, before any client sees the server
        self._follow(initial=True)
        self._load_static()
        try:
            self.server = foxglove.start_server(name=name, host=host, port=port,
                                                context=self.context,
                                                server_listener=Listener(),
                                                message_backlog_size=self.backlog)
        except (RuntimeError, OSError) as exc:   # the SDK's bind errors are RuntimeErrors
            reason = str(exc).removeprefix("FoxgloveError: ")
            raise FoxgloveCannotListen(f"cannot listen on {host}:{port}: {reason}") from None

    @property
    def port(self) -> int:
        return int(self.server.port)

    def start(self) -> "FoxgloveView":
        """Follow the store on a thread of its own until :meth:`close`."""
        self._thread = threading.Thread(target=self._run, name="slr-foxglove", daemon=True)
        self._thread.start()
        return self

    def close(self, wait: float = 2.0) -> None:
        """Stop following the store and stop the server, waiting at most ``wait`` seconds
        for the clients to take their close frames. The foxglove-sdk's ``stop()`` waits for
        every client to take its close frame; a client that never reads (its socket buffers
        full of messages) would hold it forever, so it runs on a thread of its own and a
        client still holding it after ``wait`` is left behind, said once on the log (the
        process may exit; the port is given back when that client goes)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        stopping = threading.Thread(target=self.server.stop, name="slr-foxglove-stop",
                                    daemon=True)
        stopping.start()
        stopping.join(wait)
        if stopping.is_alive():
            self.log(f"foxglove: a client did not read for {wait:g} s; stopped without "
                     f"waiting for it")

    # -- following the store ---------------------------------------------------------------------
    def _run(self) -> None:
        version = None
        next_static = 0.0
        next_static_asked = 0.0
        next_catalog = 0.0
        while not self._stop.is_set():
            try:
                now = time.monotonic()
                current = self.store.data_version()
                if current != version:
                    version = current
                    # new types and moved marks are looked for every 50 ms at most; the
                    # rows of the known types at every change
                    catalog = now >= next_catalog
                    if catalog:
                        next_catalog = now + 0.05
                    more = self._follow(catalog=catalog)
                elif now >= next_catalog and next_catalog:
                    next_catalog = 0.0
                    more = self._follow(catalog=True)
                else:
                    more = False
                if more:   # a page was full: the rows after it, at the next pass (they
                    version = None   # waited for the store's next change, maybe for ever)
                # a subscription to /tf_static asks for the latched message, but at most
                # every STATIC_GAP seconds: each one goes to every subscriber, and a client
                # subscribing in a loop made the view build and send it at every pass (a
                # core busy, every client's live events late, megabytes a second to each)
                if (self._static_due.is_set() and now >= next_static_asked) \
                        or now >= next_static:
                    self._static_due.clear()
                    next_static = now + self.static_every
                    next_static_asked = now + STATIC_GAP
                    self._send_static()
            except Exception as exc:  # noqa: BLE001 - a bad moment of the store: try again
                self.log(f"foxglove: {type(exc).__name__}: {exc}")
            self._stop.wait(self.poll)

    def _channel(self, key: tuple[str, int], sample: tuple | None) -> Any:
        import foxglove

        event = event_channel(key[0], key[1], sample)
        channel = foxglove.Channel(event.topic, schema=_schema(event.schema_name, event.schema),
                                   message_encoding="json", context=self.context,
                                   metadata=event.metadata)
        self.channels[key] = (event, channel)
        return self.channels[key]

    def _follow(self, initial: bool = False, catalog: bool = True) -> bool:
        """Read and send what the store holds beyond what was read; whether a type may
        hold more (its page was full)."""
        store = self.store
        more = False
        for key in (store.event_types() if catalog or initial else ()):
            if key not in self.channels:
                latest = store.max_seq(*key)
                sample = store.raw_rows(key[0], key[1], after_seq=latest - 1, limit=1) \
                    if latest else []
                self._channel(key, sample[0] if sample else None)
                # a type seen at start: only what comes later; a new type: all of it
                self.seen[key] = latest if initial else 0
        for key, (event, channel) in self.channels.items():
            # one type that cannot be read (its table dropped by hand, a row that is no
            # term) must not stop the others: it is said once, and tried again next time
            try:
                more = self._follow_type(key, event, channel, initial) or more
            except Exception as exc:  # noqa: BLE001 - this type's trouble, not the view's
                self._trouble(key, f"{_UNREADABLE} ({exc})")
            else:   # readable again: a later failure to read is said again
                if self._troubles.get(key, "").startswith(_UNREADABLE):
                    del self._troubles[key]
        if catalog or initial:
            self._send_marks(initial)
        return more

    def _follow_type(self, key: tuple[str, int], event: Any, channel: Any,
                     initial: bool) -> bool:
        """Send a page of a type's rows beyond those read; whether the page was full."""
        page = self.store.raw_page(key[0], key[1], after_seq=self.seen[key], rows=PAGE_ROWS,
                                   max_bytes=PAGE_BYTES)
        rows = page.rows
        if not rows:
            return False
        self.seen[key] = rows[-1][-1]
        full = page.more
        if key == _TF_STATIC:
            self._keep_static(rows)
        if initial:
            return full
        end = key[1] + 1
        for row in rows:
            try:
                data = event.message(row)
            except (ValueError, TypeError) as exc:   # a row written by hand, not a term
                self._trouble(key, f"rows that are not events are left out ({exc})")
                continue
            if len(data) > self.message_max:
                self._left_out(event.topic)
                continue
            channel.log(data, log_time=time_ns(row[end]))
            self.sent += 1
        tf = self._tf.get(key[0]) if key[1] == 3 else None
        if tf is not None:
            for row in rows:
                data = transform_message([row])
                if data is None:
                    continue
                if len(data) > self.message_max:
                    self._left_out(TF_TOPICS[key])
                    continue
                tf.log(data, log_time=time_ns(row[4]))
        return full

    def _left_out(self, topic: str) -> None:
        """Say once per topic that its messages larger than MESSAGE_MAX_BYTES are left
        out (a type may hold a few such events among many that are sent)."""
        if topic not in self._too_large:
            self._too_large.add(topic)
            self.log(f"foxglove: {topic}: {self._too_large_text}")

    def _trouble(self, key: tuple[str, int], text: str) -> None:
        """Say a type's trouble once (again only once it was gone in between)."""
        if self._troubles.get(key) != text:
            self._troubles[key] = text
            self.log(f"foxglove: {key[0]}/{key[1]}: {text}")

    def _send_marks(self, initial: bool) -> None:
        items = self.store.meta_items(_MARK_PREFIX)
        for meta_key, value in items.items():
            try:
                until = float(value)
            except (TypeError, ValueError):
                continue
            type_text = meta_key[len(_MARK_PREFIX):]
            if self.marks.get(type_text) == until:
                continue
            self.marks[type_text] = until
            if initial:
                continue
            source = self.store.meta_get(_MARK_SOURCE + type_text, "") or ""
            data = mark_message(type_text, until, str(source))
            if len(data) > self.message_max:
                self._left_out(MARKS_TOPIC)
                continue
            self._marks_channel.log(data, log_time=time_ns(time.time()))

    def _load_static(self) -> None:
        """Read the tf_static rows stored before the view started, once, a page at a time
        (the rows stored later come through :meth:`_follow`)."""
        after, upto = 0, self.seen.get(_TF_STATIC, 0)
        while after < upto:
            rows = self.store.raw_page(*_TF_STATIC, after_seq=after, rows=PAGE_ROWS,
                                       max_bytes=PAGE_BYTES).rows
            if not rows:
                break
            self._keep_static([row for row in rows if row[-1] <= upto])
            after = rows[-1][-1]

    def _keep_static(self, rows: list) -> None:
        """Keep the last row of each edge in store order (end, start, arrival sequence), as
        tf_lookup takes a static edge's value; edges keyed as tf_lookup keys frames (1 and
        1.0, -0.0 and 0.0 are equal as values, not as names)."""
        last = self._static_last
        for row in rows:
            edge = (frame_key(row[0]), frame_key(row[1]))
            kept = last.get(edge)
            if kept is None or (row[4], row[3], row[6]) > (kept[4], kept[3], kept[6]):
                last[edge] = row

    def _send_static(self) -> None:
        """The last value of each tf_static edge, on /tf_static: in one message, or in
        several of at most MESSAGE_MAX_BYTES each when the edges make a larger one (each
        message's transforms are latched apart, as those of ROS's several /tf_static
        publishers are)."""
        log_time = time_ns(time.time())
        parts = [list(self._static_last.values())] if self._static_last else []
        while parts:
            rows = parts.pop()
            data = transform_message(rows)
            if data is None:
                continue
            if len(data) <= self.message_max:
                self._tf["tf_static"].log(data, log_time=log_time)
            elif len(rows) > 1:
                half = len(rows) // 2
                parts += [rows[half:], rows[:half]]   # (the first half sent first)
            else:   # (an edge whose frame names alone are larger)
                self._left_out(TF_TOPICS[_TF_STATIC])
