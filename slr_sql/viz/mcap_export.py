"""``slr export DB FILE.mcap``: the store's channels (:mod:`.channels`) written to an MCAP file
with the ``mcap`` package, and read back by ``slr ros import``.

* One channel per exported event type (JSON messages, ``jsonschema`` schema, channel
  metadata ``slr_event`` / ``slr_arity``); each event one message whose **log time** is its
  end time (the occurrence), **publish time** its arrival time (when the store received
  it), sequence its arrival sequence number in the store.
* ``tf`` and ``tf_static`` events also as ``foxglove.FrameTransforms`` on ``/tf`` and
  ``/tf_static``, so Foxglove's 3D panel shows the frames of the file.
* The completeness marks on ``/slr/completeness`` (log time: the time they complete up to).
* Messages are written in log-time order (a merge of the types' histories, each read in store
  order a page at a time), ZSTD-compressed chunks with the message index.

:func:`export_batches` reads such a file back (``slr ros import`` uses it): every event of
the ``slr_event`` channels with its type, arguments, start and end (the arrival is the
importing store's), and the marks.
"""
from __future__ import annotations

import heapq
import json
import math
import os
import secrets
import stat
from dataclasses import dataclass, field
from itertools import chain, repeat
from operator import itemgetter
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator

from ..errors import SLRError
from ..printable import printable_name
from .channels import (JSON_SCHEMA_ENCODING, MARKS_SCHEMA, MARKS_TOPIC, METADATA_EVENT,
                       TF_TOPICS, TRANSFORMS_SCHEMA, TRANSFORMS_SCHEMA_NAME,
                       channel_type, event_channel, event_from_message, mark_message, time_ns,
                       transform_message)

__all__ = ["export_mcap", "ExportReport", "McapUnavailable", "ExportRefused", "ExportCutShort",
           "ExportDamaged", "is_slr_export", "export_messages", "export_summary", "export_batches", "select_types"]

PAGE = 20_000   # rows read per statement
PAGE_BYTES = 32 << 20   # and at most these bytes of their values (one row at least): an
# export holds a bounded page however large a type's events are


class McapUnavailable(SLRError):
    """The mcap package is not installed (``pip install 'slr_sql[mcap]'``)."""


class ExportRefused(SLRError):
    """The output path cannot take an export: the store itself, another SQLite database, a
    directory. Nothing is written."""


class ExportCutShort(SLRError):
    """An MCAP file of ``slr export`` that ends early: it has no summary (the export did not
    finish, or the file is a partial copy). Nothing is read from it."""


class ExportDamaged(SLRError):
    """An MCAP file of ``slr export`` whose records do not read back (changed bytes: a bad
    disk, a bad copy): a chunk that does not decompress, a CRC that does not match."""


@dataclass
class ExportReport:
    path: str
    messages: int = 0
    per_type: dict = field(default_factory=dict)


def _writer_module() -> Any:
    try:
        from mcap import writer
    except ImportError as exc:
        raise McapUnavailable(f"MCAP export needs the mcap package ({exc}): "
                              f"pip install 'slr_sql[mcap]'") from None
    return writer


def select_types(available: Iterable[tuple[str, int]], wanted: Iterable[str]) -> list:
    """The event types named by ``wanted`` (``name/arity``, or ``name`` for every arity);
    all of ``available`` when ``wanted`` is empty. An unknown name is an error.

    >>> select_types([("seg", 2), ("tf", 3), ("seg", 3)], ["seg"])
    [('seg', 2), ('seg', 3)]
    >>> select_types([("a/b", 1), ("a", 2)], ["a/b/1", "a"])
    [('a/b', 1), ('a', 2)]
    >>> select_types([("a/b", 1), ("a", 2)], ["'a/b'/1"])    # quoted as Prolog writes it
    [('a/b', 1)]
    """
    from ..parser import parse_indicator

    available = sorted(available)
    wanted = list(wanted)
    if not wanted:
        return available
    out: list = []
    for spec in wanted:
        # ``name/arity`` (cut at the last slash: a name may hold slashes, 'a/b'), or a name;
        # a quoted name read as Prolog reads it ('a/b'/1)
        name, arity = parse_indicator(spec)
        whole = not spec.startswith("'")
        found = [k for k in available
                 if (whole and k[0] == spec) or (k[0] == name and arity in (None, k[1]))]
        if not found:
            # (names as the summary prints them: a name's line break was a line of the
            # message of its own)
            raise SLRError(f"no event type {printable_name(spec)} in the store (it has: "
                           f"{', '.join(f'{printable_name(n)}/{a}' for n, a in available) or 'none'})")
        out += [k for k in found if k not in out]
    return out


def _pages(store: Any, key: tuple, start: float | None, end: float | None) -> Iterator[list]:
    """The pages of a type's rows in store order (end, start, seq)."""
    after = None
    n = key[1]
    while True:
        page = store.raw_page(key[0], key[1], end_from=start, end_to=end, rows=PAGE,
                              max_bytes=PAGE_BYTES, after_key=after)
        if not page.rows:
            return
        more, last = page.more, page.rows[-1]
        yield page.rows
        if not more:
            return
        after = (last[n + 1], last[n], last[n + 3])


def _keyed(store: Any, key: tuple, start: float | None, end: float | None,
           index: int) -> Iterator[tuple]:
    """``(end, start, type index, seq, row)`` of each row of a type, a page at a time (each
    page's tuples made by C's loops: no Python frame per row)."""
    n = key[1]
    end_of, start_of, seq_of = itemgetter(n + 1), itemgetter(n), itemgetter(n + 3)
    return chain.from_iterable(
        zip(map(end_of, rows), map(start_of, rows), repeat(index), map(seq_of, rows), rows)
        for rows in _pages(store, key, start, end))


def export_mcap(store: Any, path: str | Path, start: float | None = None,
                end: float | None = None, types: Iterable[str] = (),
                progress: Callable[[int], None] | None = None) -> ExportReport:
    """Write the events of ``store`` (an :class:`slr_sql.store.EventStore`) with
    ``start <= end time <= end`` of the chosen ``types`` (all by default) to ``path``.

    >>> import pathlib, tempfile, slr_sql
    >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0))
    >>> kb.add_many(["seg(cup1, [0.4, 0.1])^1.5", "seg(cup2, [0.9, 0.2])^2", "bump(r1)^3"])
    []
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "run.mcap"
    >>> report = export_mcap(kb.store, path, start=1.8); report.messages, report.per_type
    (2, {('bump', 1): 1, ('seg', 2): 1})
    """
    writer_module = _writer_module()
    if start is not None and end is not None and start > end:
        raise SLRError(f"empty time window: --from {start:g} is after --to {end:g}")
    keys = select_types(store.event_types(), types)
    stream = _check_overwrite(store, path)
    report = ExportReport(str(path))
    if stream:
        # a pipe or a terminal (/dev/stdout, a FIFO): written into, as it is (renaming a
        # file over it replaced the device or the link itself: as root, /dev/full or
        # /dev/stdout of the whole machine)
        with open(path, "wb") as out:
            _write(writer_module, _Counted(out), store, keys, start, end, progress, report)
            out.flush()
        return report
    # Written beside ``path`` under a name of its own and renamed over it once whole: an
    # export that stops half way (an error, Ctrl-C, a full disk) leaves no half MCAP file and
    # an older export of that name as it was. A symbolic link's target takes the export, the
    # link stays.
    real = Path(os.path.realpath(path))
    part = _part_path(real)
    path = real
    try:
        with open(part, "xb") as out:
            _write(writer_module, out, store, keys, start, end, progress, report)
            out.flush()
            os.fsync(out.fileno())   # whole on disk before it takes the name
        os.replace(part, path)
    except BaseException:
        try:
            os.unlink(part)
        except OSError:
            pass
        raise
    return report


class _Counted:
    """A pipe or terminal as the MCAP writer's stream: the writer asks where it is
    (``tell``), which a pipe cannot say (``Illegal seek``); here, the bytes written so far.

    >>> import io
    >>> out = _Counted(io.BytesIO()); _ = out.write(b"MCAP"); out.tell()
    4
    """

    def __init__(self, raw: Any):
        self.raw = raw
        self.written = 0

    def write(self, data: bytes) -> int:
        self.raw.write(data)
        self.written += len(data)
        return len(data)

    def tell(self) -> int:
        return self.written

    def flush(self) -> None:
        self.raw.flush()

    def close(self) -> None:
        self.raw.close()


def _part_path(path: Path) -> Path:
    """A file name beside ``path`` for the export being written (hidden, unique)."""
    return path.with_name(f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.part")


def _write(writer_module: Any, out: Any, store: Any, keys: list, start: float | None,
           end: float | None, progress: Callable[[int], None] | None,
           report: ExportReport) -> None:
    writer = writer_module.Writer(out, compression=writer_module.CompressionType.ZSTD)
    writer.start(profile="", library="slr_sql")
    channels = {}
    for key in keys:
        sample = store.raw_rows(key[0], key[1], limit=1)
        event = event_channel(key[0], key[1], sample[0] if sample else None)
        schema_id = writer.register_schema(event.schema_name, JSON_SCHEMA_ENCODING,
                                           json.dumps(event.schema).encode())
        channels[key] = (event, writer.register_channel(event.topic, "json", schema_id,
                                                        event.metadata))
    tf_channels = {}
    tf_schema = None
    for key, topic in TF_TOPICS.items():
        if key in channels:
            if tf_schema is None:
                tf_schema = writer.register_schema(TRANSFORMS_SCHEMA_NAME, JSON_SCHEMA_ENCODING,
                                                   json.dumps(TRANSFORMS_SCHEMA).encode())
            tf_channels[key] = writer.register_channel(topic, "json", tf_schema, {})
    # merge the types' histories by end time (then start, then the type, then seq)
    streams = [_keyed(store, key, start, end, index) for index, key in enumerate(keys)]
    add = writer.add_message
    count = 0
    info = [(channels[key][0].message, channels[key][1], key[1] + 2, tf_channels.get(key))
            for key in keys]
    per_index = [0] * len(keys)
    merged = heapq.merge(*streams) if len(streams) > 1 else (streams[0] if streams else ())
    for end_time, _, index, seq, row in merged:
        message, channel_id, arrival_at, tf = info[index]
        # (time_ns, inline for the common times: after 1970, before 2540)
        log_time = round(end_time * 1e9) if 0.0 < end_time < 1.8e10 else time_ns(end_time)
        arrival = row[arrival_at]
        publish_time = round(arrival * 1e9) if 0.0 < arrival < 1.8e10 else time_ns(arrival)
        try:
            data = message(row)
        except (ValueError, TypeError) as exc:   # a row written by hand, not a term
            name, arity = keys[index]
            raise SLRError(f"{name}/{arity}: the row of seq {seq} is not an event ({exc}); "
                           f"fix or delete it, or leave {name}/{arity} out") from None
        seq &= 0xFFFFFFFF
        add(channel_id, log_time, data, publish_time, seq)
        if tf is not None:
            data = transform_message([row])
            if data is not None:
                add(tf, log_time, data, publish_time, seq)
        per_index[index] += 1
        count += 1
        if progress is not None and count % 10_000 == 0:
            progress(count)
    report.per_type = {key: per_index[i] for i, key in enumerate(keys) if per_index[i]}
    marks = {k[len("sync/mark/"):]: v for k, v in store.meta_items("sync/mark/").items()}
    if marks:
        schema_id = writer.register_schema(MARKS_SCHEMA["title"], JSON_SCHEMA_ENCODING,
                                           json.dumps(MARKS_SCHEMA).encode())
        channel_id = writer.register_channel(MARKS_TOPIC, "json", schema_id, {})
        for type_text, until in sorted(marks.items()):
            try:
                until = float(until)
            except (TypeError, ValueError):
                continue
            source = store.meta_get("sync/marksrc/" + type_text, "") or ""
            add(channel_id, time_ns(until), mark_message(type_text, until, str(source)),
                time_ns(until))
    writer.add_metadata("slr_sql", {"from": "" if start is None else repr(float(start)),
                                    "to": "" if end is None else repr(float(end)),
                                    "types": ",".join(f"{n}/{a}" for n, a in keys)})
    writer.finish()
    report.messages = count


SQLITE_MAGIC = b"SQLite format 3\x00"


def _check_overwrite(store: Any, path: str | Path) -> bool:
    """Refuse (SLRError) to write the MCAP over the store being exported (its file, or the
    file's WAL or journal; opening it for writing truncates the store), over any other
    SQLite database (another store, named where an export was not meant to go), or over
    what is no file, pipe or terminal (a disk's device, a socket). True when ``path`` is a
    pipe or a character device (a terminal, ``/dev/stdout``), which the export is written
    into rather than replaced; it is not read here (a pipe's read would wait for a writer
    that never comes)."""
    target = Path(path)
    if target.is_dir():
        raise ExportRefused(f"{path} is a directory: an export is an MCAP file; name a file "
                            f"in it, e.g. {target / 'export.mcap'}")
    own = getattr(store, "path", None)
    if own is not None and "://" not in str(own):
        # by name too: a side file SQLite has not made yet is where it will write, and an
        # export written there was deleted by the store's next open
        real = os.path.realpath(target)
        for suffix in ("", "-wal", "-shm", "-journal"):
            if real == os.path.realpath(own) + suffix and suffix:
                raise ExportRefused(f"{path} is the name of a file SQLite keeps beside the "
                                    f"store being exported ({own}{suffix}): it would "
                                    "destroy the export, or the export the store; name "
                                    "another file")
            if real == os.path.realpath(own):
                raise ExportRefused(f"{path} is the store being exported ({own}) itself: "
                                    "writing the export there would destroy the store")
    try:
        mode = os.stat(target).st_mode
    except OSError:
        return False             # (no such file: made; another reason: writing says why)
    if stat.S_ISFIFO(mode) or stat.S_ISCHR(mode):
        return True
    if not stat.S_ISREG(mode):
        raise ExportRefused(f"{path} is not a file (a block device or a socket): an export is "
                            f"an MCAP file; name a file")
    own = getattr(store, "path", None)
    if own is not None and "://" not in str(own):
        for suffix in ("", "-wal", "-shm", "-journal"):
            try:
                if os.path.samefile(str(own) + suffix, target):
                    raise ExportRefused(f"{path} is the store being exported ({own}) itself: "
                                   "writing the export there would destroy the store")
            except OSError:      # (that file does not exist)
                continue
    try:
        with open(target, "rb") as existing:
            head = existing.read(len(SQLITE_MAGIC))
    except OSError:
        return                   # (unreadable: writing it says why)
    if head == SQLITE_MAGIC:
        raise ExportRefused(f"{path} is an SQLite database (a store?), not an export: an export is "
                       "an MCAP file; remove the file first or choose another name")
    return False


def is_slr_export(path: str | Path) -> bool:
    """True when ``path`` is an MCAP file with at least one slr event channel.

    >>> import pathlib, tempfile, slr_sql
    >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0))
    >>> kb.add_many(["seg(cup1, [0.4, 0.1])^1.5", "seg(cup2, [0.9, 0.2])^2", "bump(r1)^3"])
    []
    >>> kb.mark_complete("seg/2", 2)
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "run.mcap"; _ = export_mcap(kb.store, path)

    >>> is_slr_export(path), is_slr_export(path.with_name("other.mcap"))
    (True, False)
    """
    path = Path(path)
    try:
        if not path.is_file() or path.suffix != ".mcap":
            return False
    except OSError:   # (a name too long: the bag reader says why)
        return False
    try:
        from mcap.reader import make_reader
    except ImportError:
        return False
    try:
        with open(path, "rb") as stream:
            try:
                summary = make_reader(stream).get_summary()
            except Exception:  # noqa: BLE001 - no footer to read: a file cut short?
                summary = None
            if summary is None:   # cut short? its first channel says whose it is
                stream.seek(0)
                return _first_channel_is_an_event(stream)
    except OSError:   # unreadable: the bag reader says why
        return False
    return any(METADATA_EVENT in c.metadata for c in summary.channels.values())


def _first_channel_is_an_event(stream: Any) -> bool:
    """Whether the first channel record of an MCAP stream (read from its start, as far as
    it goes) is an slr event channel."""
    from mcap.records import Channel, Message
    from mcap.stream_reader import StreamReader

    try:
        for record in StreamReader(stream).records:
            if isinstance(record, Channel):
                return METADATA_EVENT in record.metadata
            if isinstance(record, Message):
                return False
    except Exception:  # noqa: BLE001 - the file ends (or breaks) before a channel
        return False
    return False


def export_summary(path: str | Path) -> Any:
    """The summary of an MCAP file of ``slr export`` (:func:`is_slr_export`); raises
    :class:`ExportCutShort` when the file has none.

    >>> import pathlib, tempfile, slr_sql
    >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0))
    >>> kb.add_many(["seg(cup1, [0.4, 0.1])^1.5", "seg(cup2, [0.9, 0.2])^2", "bump(r1)^3"])
    []
    >>> kb.mark_complete("seg/2", 2)
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "run.mcap"; _ = export_mcap(kb.store, path)

    >>> summary = export_summary(path)
    >>> sorted(c.topic for c in summary.channels.values()), summary.statistics.message_count
    (['/bump/1', '/seg/2', '/slr/completeness'], 4)
    """
    from mcap.reader import make_reader

    with open(path, "rb") as stream:
        try:
            summary = make_reader(stream).get_summary()
        except Exception:  # noqa: BLE001 - the end of the file is not a footer
            summary = None
    if summary is None:
        raise ExportCutShort(f"cannot read {path}: an slr export cut short (no summary at its "
                             f"end: the export did not finish, or the file is a partial copy); "
                             f"export it again")
    return summary


def _mark(path: str | Path, topic: str, n: int, data: bytes) -> tuple[str, float]:
    """``(type, until)`` of a completeness mark message (:func:`mark_message`)."""
    try:
        mark = json.loads(data)
        until = float(mark["until"])
        if not isinstance(mark["type"], str) or isinstance(mark["until"], bool) \
                or math.isnan(until):
            raise ValueError(f"type {mark['type']!r}, until {mark['until']!r}")
        return mark["type"], until
    except (ValueError, KeyError, TypeError, IndexError) as exc:
        raise SLRError(f"{path}: {topic}: message {n} is not a completeness mark "
                       f'({{"type": "p/1", "until": 5.0}}): {exc}') from None


def export_messages(path: str | Path) -> Iterator[tuple[Any, Any, Any]]:
    """``(schema, channel, message)`` of each message of an MCAP file, in file order;
    :class:`ExportDamaged` when its records do not read back.

    >>> import pathlib, tempfile, slr_sql
    >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0))
    >>> kb.add_many(["seg(cup1, [0.4, 0.1])^1.5", "seg(cup2, [0.9, 0.2])^2", "bump(r1)^3"])
    []
    >>> kb.mark_complete("seg/2", 2)
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "run.mcap"; _ = export_mcap(kb.store, path)

    >>> for _schema, channel, message in export_messages(path):
    ...     print(channel.topic, message.log_time, message.data.decode())
    /seg/2 1500000000 {"arg1":"cup1","arg2":[0.4,0.1],"start":1.5,"end":1.5,"arrival":0.0}
    /seg/2 2000000000 {"arg1":"cup2","arg2":[0.9,0.2],"start":2.0,"end":2.0,"arrival":0.0}
    /bump/1 3000000000 {"arg1":"r1","start":3.0,"end":3.0,"arrival":0.0}
    /slr/completeness 2000000000 {"type":"seg/2","until":2.0,"source":"kb.mark_complete('seg/2', 2)"}
    """
    from mcap.reader import make_reader

    read = 0
    with open(path, "rb") as stream:
        messages = make_reader(stream).iter_messages(log_time_order=False)
        while True:
            try:
                item = next(messages)
            except StopIteration:
                return
            except Exception as exc:  # noqa: BLE001 - mcap's, zstd's, lz4's own errors
                raise ExportDamaged(f"cannot read {path}: the MCAP file is damaged after "
                                    f"{read} messages ({exc or type(exc).__name__})") from None
            read += 1
            yield item


def export_batches(path: str | Path, done: dict | None = None, batch_size: int = 10_000
                   ) -> Iterator[tuple[list, dict, list]]:
    """The events of an MCAP file :func:`export_mcap` wrote, in file order, in batches:
    ``(events, counts, marks)`` -- ``counts`` maps each topic to the number of its messages
    read so far (for checkpoints), ``marks`` the completeness marks ``(type, until)`` (with
    the last batch). ``done`` skips the first so many messages of a topic (an import that
    already took them).

    >>> import pathlib, tempfile, slr_sql
    >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0))
    >>> kb.add_many(["seg(cup1, [0.4, 0.1])^1.5", "seg(cup2, [0.9, 0.2])^2", "bump(r1)^3"])
    []
    >>> kb.mark_complete("seg/2", 2)
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "run.mcap"; _ = export_mcap(kb.store, path)

    >>> for events, counts, marks in export_batches(path, done={"/seg/2": 1}):  # seg: 1 taken
    ...     print([(name, len(args), end) for name, args, start, end in events], counts, marks)
    [('seg', 2, 2.0), ('bump', 1, 3.0)] {'/seg/2': 2, '/bump/1': 1} [('seg/2', 2.0)]
    """
    done = done or {}
    counts: dict = {}
    batch: list = []
    marks: list = []
    types: dict[int, tuple[str, int] | None] = {}   # each channel's event type, read once
    for _schema, channel, message in export_messages(path):
        topic = channel.topic
        if channel.id not in types:
            types[channel.id] = channel_type(path, topic, channel.metadata)
        event_type = types[channel.id]
        if event_type is not None:
            n = counts[topic] = counts.get(topic, 0) + 1
            if n <= done.get(topic, 0):
                continue
            try:
                batch.append(event_from_message(*event_type, message.data))
            except (ValueError, KeyError, TypeError, RecursionError) as exc:
                reason = ("nested too deeply" if isinstance(exc, RecursionError)
                          # (Python's words for it are advice to a programmer)
                          else "an integer of more than 4300 digits"
                          if "int_max_str_digits" in str(exc) else str(exc)[:200])
                raise SLRError(f"{path}: {topic}: message {n} is not an slr event: "
                               f"{reason}") from None
            if len(batch) >= batch_size:
                yield batch, dict(counts), []
                batch = []
        elif topic == MARKS_TOPIC:
            marks.append(_mark(path, topic, len(marks) + 1, message.data))
    yield batch, dict(counts), marks
