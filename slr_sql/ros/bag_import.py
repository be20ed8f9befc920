"""Import rosbag1, rosbag2 (sqlite3 or MCAP) and MCAP files into a knowledge base.

Messages are read and decoded with ``rosbags`` from the message definitions stored in the
bag, so no ROS installation is needed. Each mapped message becomes events (see
:mod:`slr_sql.ros.mapping`) added with ``kb.add_many`` in batches.

Resuming and idempotence: every batch also stores, for each topic it touched, the event
``slr_import(BagId, Topic, Count)^T`` — ``BagId`` identifies the bag by its contents
(topics, types, message counts, first and last record time), ``Count`` is how many of the
topic's messages (in the bag's order) are imported, ``T`` the record time of the last one.
It goes in the same ``add_many`` call, so it commits in the same transaction as the data: a
crash leaves either both or neither. Importing the same bag again skips, per topic, the
messages already counted (without decoding them), so a finished import adds nothing and an
interrupted one continues where it stopped.

Messages whose events the store rejects (a NaN in a field, a time that is not finite) or
that the mapping cannot convert are counted as imported and reported in
:attr:`ImportReport.rejected` (topic, message number, record time, reason); the other events
of the batch are stored.

>>> import slr_sql
>>> kb = slr_sql.open()
>>> import_bag(kb, "/no/such.bag")
Traceback (most recent call last):
...
slr_sql.ros.bag_import.BagError: cannot read /no/such.bag: no such file or directory
"""
from __future__ import annotations

import gc
import hashlib
import json
import math
import queue
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from slr_sql import ManualClock, SLRError
from slr_sql.api import KnowledgeBaseAPI
from slr_sql.printable import shorten

from .mapping import IMPORT_CHECKPOINT, BoundEntry, Mapping, MessageError, normalize_topic
from . import fast_tf

__all__ = ["import_bag", "ImportReport", "Rejection", "BagError", "open_bag", "bag_id",
           "ros1_typestore", "TF_MESSAGE_MSGDEF", "DEFAULT_BATCH", "read_messages",
           "reader_reason"]

DEFAULT_BATCH = 10_000  # events per add_many (one transaction, one fsync)

# tf2_msgs/msg/TFMessage as a .msg definition: the ROS 1 Noetic type store of rosbags lacks it.
TF_MESSAGE_MSGDEF = "geometry_msgs/TransformStamped[] transforms\n"


class BagError(SLRError):
    """A bag that cannot be opened or read."""


@dataclass
class Rejection:
    """A message that gave no events: ``index`` is its number on the topic (from 1)."""

    topic: str
    index: int
    record_time: float
    reason: str

    def __str__(self) -> str:
        return f"{self.topic} message {self.index} (recorded at {self.record_time:.9f}): {self.reason}"


@dataclass
class TopicReport:
    event: str            # event name(s), comma separated
    msgtype: str
    messages: int = 0     # messages imported in this run
    events: int = 0       # events stored in this run
    skipped: int = 0      # messages already imported by an earlier run


@dataclass
class ImportReport:
    """What one :func:`import_bag` call did."""

    bag_id: str
    events: int = 0
    messages: int = 0
    skipped: int = 0
    rejected: list[Rejection] = field(default_factory=list)
    topics: dict[str, TopicReport] = field(default_factory=dict)
    unmapped: list[str] = field(default_factory=list)       # topics in the bag left out
    missing: list[str] = field(default_factory=list)        # mapped topics not in the bag
    # topics of which fewer messages could be read than the bag counts: topic -> (counted,
    # read); the bag is damaged or cut short
    short: dict[str, tuple[int, int]] = field(default_factory=dict)


def ros1_typestore() -> Any:
    """The ROS 1 Noetic type store of ``rosbags`` with ``tf2_msgs/msg/TFMessage`` added (for
    writing ROS 1 bags, and for ROS 1 bags that carry no definitions).

    >>> "tf2_msgs/msg/TFMessage" in ros1_typestore().fielddefs
    True
    """
    from rosbags.typesys import Stores, get_typestore, get_types_from_msg

    store = get_typestore(Stores.ROS1_NOETIC)
    store.register(get_types_from_msg(TF_MESSAGE_MSGDEF, "tf2_msgs/msg/TFMessage"))
    return store


def open_bag(path: str | Path) -> Any:
    """An opened ``rosbags`` AnyReader on a rosbag1 file (``.bag``), a rosbag2 directory
    (sqlite3 or MCAP storage), or a single ``.mcap`` / ``.db3`` file. Bags without stored
    message definitions decode with the standard types (ROS 2 Kilted, or ROS 1 Noetic plus
    tf2_msgs).

    >>> import pathlib, struct, tempfile
    >>> from rosbags.rosbag1 import Writer
    >>> from slr_sql.ros.bag_import import ros1_typestore
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "rec.bag"; types = ros1_typestore()
    >>> with Writer(path) as writer:   # three map->base transforms and a status, ROS 1 serialized
    ...     tf = writer.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=types)
    ...     status = writer.add_connection("/robot/status", "std_msgs/msg/String", typestore=types)
    ...     for i in range(3):
    ...         writer.write(tf, (50 + i) * 10**9, struct.pack("<IIIII3sI4s7d", 1, i, 50 + i, 0,
    ...                      3, b"map", 4, b"base", 0.5 * i, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0))
    ...     writer.write(status, 51 * 10**9, struct.pack("<I2s", 2, b"ok"))

    >>> reader = open_bag(path); [(c.topic, c.msgtype, c.msgcount) for c in reader.connections]
    [('/tf', 'tf2_msgs/msg/TFMessage', 3), ('/robot/status', 'std_msgs/msg/String', 1)]
    >>> reader.close()
    >>> open_bag(path.with_name("missing.bag"))
    Traceback (most recent call last):
        ...
    slr_sql.ros.bag_import.BagError: cannot read .../missing.bag: no such file or directory
    """
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError as exc:  # pragma: no cover - the extra is part of the test install
        raise BagError(f"reading bags needs rosbags ({exc}): pip install 'slr_sql[ros]'") from None
    path = Path(path)
    try:
        found = path.exists()
    except OSError as exc:   # a name too long for the file system, ...
        raise BagError(f"cannot read {shorten(str(path))}: {exc.strerror or exc}") from None
    if not found:
        raise BagError(f"cannot read {path}: no such file or directory")
    default = ros1_typestore() if path.suffix == ".bag" else get_typestore(Stores.ROS2_KILTED)
    try:
        reader = AnyReader([path], default_typestore=default)
        reader.open()
    except Exception as exc:  # rosbags raises its own errors, OSError, and a few bare ones
        raise BagError(f"cannot read {path}: {reader_reason(exc)}") from None
    return reader


_REASON_MAX = 200


def reader_reason(exc: BaseException) -> str:
    """What a bag reader's error says of the bag, in words: its own message, or for the bare
    errors a damaged file makes it raise (a failed assert, an unknown record kind, a size
    beyond memory, bytes that are no UTF-8) what they mean; at most 200 characters.

    >>> reader_reason(AssertionError())
    "a record that fails the reader's own check"
    >>> reader_reason(UnicodeDecodeError("utf-8", b"ab?", 2, 3, "invalid start byte"))
    'text that is not UTF-8 (byte 2 of a 3-byte field)'
    >>> reader_reason(TypeError("ord() expected a character, but string of length 0 found"))
    'the file ends where a record should begin (it is cut short)'
    """
    if isinstance(exc, UnicodeDecodeError):
        return f"text that is not UTF-8 (byte {exc.start} of a {len(exc.object)}-byte field)"
    if isinstance(exc, (MemoryError, OverflowError)):
        return "a record whose size is beyond memory"
    if isinstance(exc, AssertionError):
        return "a record that fails the reader's own check"
    if isinstance(exc, KeyError):
        return f"a record of a kind the reader does not know ({_short(repr(exc.args[0]))})" \
            if exc.args else "a record of a kind the reader does not know"
    if isinstance(exc, TypeError) and str(exc).startswith("ord() expected a character"):
        # (the MCAP reader reads a record's kind byte with ord(): at the end of the file
        # there is none, and the user read Python's own words about ord)
        return "the file ends where a record should begin (it is cut short)"
    text = " ".join(str(a) for a in exc.args) or type(exc).__name__
    return _short(text)


def _short(text: str) -> str:
    return text if len(text) <= _REASON_MAX else text[:_REASON_MAX] + "..."


def read_messages(messages: Any, path: str | Path) -> Any:
    """The items of a bag reader's ``messages`` iterator; :class:`BagError` (saying how many
    were read) when the storage does not read back: a damaged file makes the readers raise
    their own errors and bare ones (AssertionError, KeyError, sqlite3's DatabaseError, ...).

    >>> list(read_messages(iter([1, 2]), "x.bag"))
    [1, 2]
    """
    read = 0
    while True:
        try:
            item = next(messages)
        except StopIteration:
            return
        except Exception as exc:  # noqa: BLE001 - the reader's errors (damaged storage)
            raise BagError(f"cannot read {path}: the bag is damaged after {read} messages "
                           f"({reader_reason(exc)})") from None
        read += 1
        yield item


def bag_id(reader: Any) -> str:
    """A short id of a bag computed from its contents (topics, types, message counts, first
    and last record time): the same recording has the same id wherever it lies.

    >>> import pathlib, struct, tempfile
    >>> from rosbags.rosbag1 import Writer
    >>> from slr_sql.ros.bag_import import ros1_typestore
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "rec.bag"; types = ros1_typestore()
    >>> with Writer(path) as writer:   # three map->base transforms and a status, ROS 1 serialized
    ...     tf = writer.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=types)
    ...     status = writer.add_connection("/robot/status", "std_msgs/msg/String", typestore=types)
    ...     for i in range(3):
    ...         writer.write(tf, (50 + i) * 10**9, struct.pack("<IIIII3sI4s7d", 1, i, 50 + i, 0,
    ...                      3, b"map", 4, b"base", 0.5 * i, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0))
    ...     writer.write(status, 51 * 10**9, struct.pack("<I2s", 2, b"ok"))

    >>> reader = open_bag(path); bag_id(reader)
    'bag_197ecfcf09c51814'
    >>> reader.close()
    """
    summary = {
        "topics": sorted((name, info.msgtype or "", info.msgcount)
                         for name, info in reader.topics.items()),
        "start": reader.start_time if reader.message_count else 0,
        "end": reader.end_time if reader.message_count else 0,
        "count": reader.message_count,
    }
    digest = hashlib.sha256(json.dumps(summary, sort_keys=True).encode()).hexdigest()
    return "bag_" + digest[:16]


def _checkpoints(kb: KnowledgeBaseAPI, bag: str) -> dict[str, int]:
    done: dict[str, int] = {}
    for answer in kb.query(f"{IMPORT_CHECKPOINT}(B, Topic, N)^_", args={"B": bag}):
        topic, count = str(answer["Topic"]), answer["N"]
        if isinstance(count, int) and count > done.get(topic, 0):
            done[topic] = count
    return done


class _Plan:
    """What to do with the messages of one connection."""

    __slots__ = ("topic", "msgtype", "bound", "marks", "fast", "deserialize")

    def __init__(self, topic: str, msgtype: str, bound: list[BoundEntry],
                 marks: list[tuple[BoundEntry, tuple[str, ...]]], fast: Any, deserialize: Any):
        self.topic = topic
        self.msgtype = msgtype
        self.bound = bound
        self.marks = marks
        self.fast = fast
        self.deserialize = deserialize


def import_bag(kb: KnowledgeBaseAPI, path: str | Path, mapping: Mapping | None = None,
               all_topics: bool = False,
               progress: Callable[[int, int], None] | None = None,
               batch_size: int = DEFAULT_BATCH, clock: ManualClock | None = None
               ) -> ImportReport:
    """Import the bag at ``path`` into ``kb`` as events, by ``mapping`` (default: the
    built-in /tf and /tf_static mapping only); ``all_topics`` adds every other topic as an
    event named after the topic with the message as a term. ``progress(done, total)`` is
    called after each batch with message counts. Importing the same bag again adds nothing.

    ``clock``: the ManualClock ``kb`` was opened with, moved (forward only) to each batch's
    last record time before the batch is stored (for an export of ``slr export``: its
    greatest end time), so that the events arrive in the recording's own time, as
    ``slr ros import`` does (it also opens the store with ``max_learned_delay=0``: a batch's
    arrival is no message's latency, so the import learns no delays).

    >>> import slr_sql, tempfile, os
    >>> from slr_sql.ros.bag_import import import_bag
    >>> report = import_bag(slr_sql.open(), os.devnull)
    Traceback (most recent call last):
    ...
    slr_sql.ros.bag_import.BagError: cannot read /dev/null: Unrecognized storage format ''
    """
    mapping = mapping if mapping is not None else Mapping()
    from slr_sql.viz.mcap_export import is_slr_export

    if is_slr_export(path):
        return _import_export(kb, Path(path), progress, max(1, int(batch_size)), clock)
    reader = open_bag(path)
    # A batch is tens of thousands of young objects without cycles; the cyclic collector
    # would walk them again and again while they wait for add_many (measured: 10-30 % of
    # the import's time). Reference counting still frees everything.
    collecting = gc.isenabled()
    gc.disable()
    try:
        return _import(kb, reader, mapping, all_topics, progress, max(1, int(batch_size)),
                       clock, path)
    finally:
        if collecting:
            gc.enable()
        try:
            reader.close()
        except Exception:  # noqa: BLE001 - closing a reader must not hide the real error
            pass


def _follow(clock: ManualClock | None, t: float) -> None:
    """Move ``clock`` forward to ``t`` (the time the batch about to be stored was recorded)."""
    if clock is not None and math.isfinite(t) and t > clock.now():
        clock.set(t)


def export_bag_id(summary: Any) -> str:
    """The id an MCAP file of ``slr export`` is imported under (``slr_import`` records it,
    ``slr ros info`` shows it), from its summary: each channel's topic, event type, arity
    and message count.

    >>> import pathlib, tempfile, slr_sql
    >>> from slr_sql.viz.mcap_export import export_mcap, export_summary
    >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0)); kb.add("seen(a)^1")
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "x.mcap"; _ = export_mcap(kb.store, path)
    >>> export_bag_id(export_summary(path)).startswith("export_")
    True
    """
    counts = summary.statistics.channel_message_counts if summary.statistics else {}
    channels = sorted((c.topic, c.metadata.get("slr_event", ""), c.metadata.get("slr_arity", ""),
                       counts.get(c.id, 0)) for c in summary.channels.values())
    return "export_" + hashlib.sha256(json.dumps(channels).encode()).hexdigest()[:16]


def _import_export(kb: KnowledgeBaseAPI, path: Path, progress: Callable[[int, int], None] | None,
                   batch_size: int, clock: ManualClock | None) -> ImportReport:
    """An MCAP file of ``slr export``: its events as they were stored (no mapping: its
    channels name their event types), with the same checkpoints as a bag."""
    from slr_sql.viz.channels import channel_type
    from slr_sql.viz.mcap_export import export_batches, export_summary

    summary = export_summary(path)   # (ExportCutShort when the file ends early)
    # every channel's event type before any event is stored: a channel whose metadata
    # names none (a file written elsewhere) stops the import with nothing stored
    types = {c.id: channel_type(path, c.topic, c.metadata) for c in summary.channels.values()}
    channels = sorted((c.topic, c.metadata.get("slr_event", ""), c.metadata.get("slr_arity", ""),
                       (summary.statistics.channel_message_counts.get(c.id, 0)
                        if summary.statistics else 0), types[c.id] is not None)
                      for c in summary.channels.values())
    report = ImportReport(export_bag_id(summary))
    total = sum(c[3] for c in channels if c[4])
    for topic, event, arity, count, is_event in channels:
        if is_event:
            report.topics[topic] = TopicReport(f"{event}/{arity}", "slr event (JSON)")
    done = _checkpoints(kb, report.bag_id)
    for topic, n in done.items():
        if topic in report.topics:
            report.topics[topic].skipped = n
            report.skipped += n
    stored: dict[str, int] = dict(done)
    read = report.skipped
    for events, counts, marks in export_batches(path, done, batch_size):
        checkpoints = [(IMPORT_CHECKPOINT, (report.bag_id, topic, n), 0.0, 0.0)
                       for topic, n in counts.items() if n > stored.get(topic, 0)]
        if events:
            _follow(clock, max(float(event[3]) for event in events))
        rejected = kb.add_many(events + checkpoints) if events or checkpoints else []
        if rejected:
            raise SLRError(f"{path}: the store refused events of the export: {rejected[0]}")
        for topic, n in counts.items():
            new = n - stored.get(topic, 0)
            if new > 0 and topic in report.topics:
                report.topics[topic].messages += new
                report.topics[topic].events += new
                report.messages += new
                report.events += new
                read += new
            stored[topic] = max(stored.get(topic, 0), n)
        for type_text, until in marks:
            kb.mark_complete(type_text, until)
        if progress is not None:
            progress(read, total)
    return report


def _plans(reader: Any, mapping: Mapping, all_topics: bool, report: ImportReport) -> dict:
    fielddefs = reader.typestore.fielddefs
    plans: dict[int, _Plan] = {}  # by connection id (one bag: ids are unique)
    seen_names: dict[str, str] = {}
    deserialize = reader.typestore.deserialize_cdr if reader.is2 else \
        reader.typestore.deserialize_ros1
    for conn in reader.connections:
        topic = normalize_topic(conn.topic)
        entries = mapping.entries_for(topic, all_topics)
        marks = mapping.fully_updated_for(topic)
        if not entries and not marks:
            if topic not in report.unmapped:
                report.unmapped.append(topic)
            continue
        bound = [e.bind(conn.msgtype, fielddefs) for e in entries]
        for b in bound:
            if b.entry.whole_message:
                other = seen_names.setdefault(b.name, topic)
                if other != topic:
                    raise SLRError(f"the topics {other} and {topic} would both become events named "
                                   f"{b.name}; map one of them in the MAP file")
        bound_marks = [(m.as_topic_entry().bind(conn.msgtype, fielddefs), m.types) for m in marks]
        fast = None
        if len(bound) == 1 and not bound_marks:
            fast = fast_tf.compile_for(bound[0], conn, reader)
        plans[conn.id] = _Plan(topic, conn.msgtype, bound, bound_marks, fast, deserialize)
        names = ", ".join(dict.fromkeys(b.name for b in bound)) or "fullyUpdated"
        report.topics.setdefault(topic, TopicReport(names, conn.msgtype))
    mapped = set(mapping.topic_names())
    present = {normalize_topic(c.topic) for c in reader.connections}
    report.missing = sorted(mapped - present)
    return plans


@dataclass
class _Batch:
    """What the reading thread hands to the storing one."""

    events: list = field(default_factory=list)
    owners: list = field(default_factory=list)    # owners[i]: (topic, number, record time)
    checkpoints: list = field(default_factory=list)  # (topic, count, record time)
    marks: list = field(default_factory=list)     # (event type, time)
    rejected: list = field(default_factory=list)  # messages the mapping could not convert
    per_topic: dict = field(default_factory=dict)  # topic -> events in this batch
    read: int = 0                                 # messages read so far (for progress)
    recorded: float = -math.inf                   # the latest record time read into it


_END = object()


def _import(kb: KnowledgeBaseAPI, reader: Any, mapping: Mapping, all_topics: bool,
            progress: Callable[[int, int], None] | None, batch_size: int,
            clock: ManualClock | None, path: str | Path) -> ImportReport:
    """Reading and decoding run in a second thread while this one stores the previous batch:
    SQLite releases the GIL while it writes, so on a free core both proceed at once. Batches
    are stored in order, each with its checkpoints, by the calling thread only."""
    report = ImportReport(bag_id(reader))
    plans = _plans(reader, mapping, all_topics, report)
    if not plans:
        return report
    selected = [c for c in reader.connections if c.id in plans]
    total = sum(c.msgcount for c in selected)
    done = _checkpoints(kb, report.bag_id)
    handoff: queue.Queue = queue.Queue(maxsize=2)
    stop = threading.Event()

    def hand(item: Any) -> bool:
        while not stop.is_set():
            try:
                handoff.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def produce() -> None:
        try:
            for batch in _batches(reader, selected, plans, done, report, batch_size, path):
                if not hand(batch):
                    return
            hand(_END)
        except BaseException as exc:  # noqa: BLE001 - re-raised in the storing thread
            hand(exc)

    reading = threading.Thread(target=produce, name="slr-bag-reader", daemon=True)
    reading.start()
    try:
        while True:
            item = handoff.get()
            if item is _END:
                break
            if isinstance(item, BaseException):
                raise item
            _follow(clock, item.recorded)
            _store(kb, report, item)
            if progress is not None:
                progress(item.read, total)
    finally:
        stop.set()
        reading.join()
    return report


def _store(kb: KnowledgeBaseAPI, report: ImportReport, batch: _Batch) -> None:
    events = batch.events + [(IMPORT_CHECKPOINT, (report.bag_id, topic, count), at, at)
                             for topic, count, at in batch.checkpoints]
    for topic, n in batch.per_topic.items():
        report.topics[topic].events += n
    report.rejected += batch.rejected
    rejected = kb.add_many(events) if events else []
    for error in rejected:
        position = getattr(error, "index", None)
        if not isinstance(position, int) or position >= len(batch.events):
            raise SLRError(f"the import checkpoint was rejected: {error}")
        topic, index, at = batch.owners[position]
        report.rejected.append(Rejection(topic, index, at, str(error)))
        report.topics[topic].events -= 1
    report.events += len(batch.events) - len(rejected)
    for event_type, t in batch.marks:
        kb.mark_complete(event_type, t)


def _batches(reader: Any, selected: list, plans: dict, done: dict, report: ImportReport,
             batch_size: int, path: str | Path) -> Any:
    """Read, decode and map the selected messages; yields :class:`_Batch` es of about
    ``batch_size`` events (the last one possibly with none, to carry checkpoints)."""
    counts: dict[str, int] = {}
    last_time: dict[str, float] = {}
    touched: dict[str, None] = {}
    batch = _Batch()
    read = 0
    latest = -math.inf   # the latest record time read (a bag's messages are in its order)

    def close(b: _Batch) -> _Batch:
        b.checkpoints = [(t, counts[t], last_time[t]) for t in touched]
        b.read = read
        b.recorded = latest
        touched.clear()
        return b

    # One bag file: read its reader directly (AnyReader merges several bag files through a
    # heap, a cost per message that a single file does not need).
    readers: Any = getattr(reader, "readers", ())
    source = (readers[0].messages(connections=selected) if len(readers) == 1
              else reader.messages(connections=selected))
    for conn, stamp, raw in read_messages(source, path):
        plan = plans[conn.id]
        topic = plan.topic
        index = counts.get(topic, 0) + 1
        counts[topic] = index
        read += 1
        topic_report = report.topics[topic]
        record = stamp * 1e-9
        if record > latest:
            latest = record
        if index <= done.get(topic, 0):
            report.skipped += 1
            topic_report.skipped += 1
            continue
        report.messages += 1
        topic_report.messages += 1
        last_time[topic] = record
        touched[topic] = None
        try:
            if plan.fast is not None:
                events = plan.fast(raw, record)
            else:
                msg = plan.deserialize(raw, plan.msgtype)
                events = []
                for bound in plan.bound:
                    events += bound.events(msg, record)
                for bound, types in plan.marks:
                    for (_, _, t, _) in bound.events(msg, record):
                        batch.marks.extend((event_type, t) for event_type in types)
        except (MessageError, ValueError, TypeError, AttributeError, IndexError) as exc:
            batch.rejected.append(Rejection(topic, index, record, _reason(exc)))
            continue
        except Exception as exc:  # rosbags' SerdeError and friends: a message that does not decode
            batch.rejected.append(Rejection(topic, index, record,
                                            f"cannot decode the message: {_reason(exc)}"))
            continue
        batch.owners += [(topic, index, record)] * len(events)
        batch.events += events
        batch.per_topic[topic] = batch.per_topic.get(topic, 0) + len(events)
        if len(batch.events) >= batch_size:
            yield close(batch)
            batch = _Batch()
    counted: dict[str, int] = {}
    for conn in selected:
        topic = normalize_topic(conn.topic)
        counted[topic] = counted.get(topic, 0) + int(conn.msgcount or 0)
    for topic, n in counted.items():
        if counts.get(topic, 0) < n:
            report.short[topic] = (n, counts.get(topic, 0))
    yield close(batch)


def _reason(exc: BaseException) -> str:
    if isinstance(exc, UnicodeDecodeError):   # (its args hold the field's bytes, all of them)
        return reader_reason(exc)
    text = " ".join(str(a) for a in exc.args) if exc.args else ""
    return _short(text) if text else type(exc).__name__
