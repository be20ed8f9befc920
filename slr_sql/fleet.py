"""Fleets: a robot ships its events, complex events and completeness marks to a fleet store
(``slr fleet push``), and the fleet store says what it holds of each robot
(``slr fleet status``); a robot taken out of service is retired from the fleet store (``slr
fleet retire``), so that the fleet's marks stop waiting for it. See docs/fleet.md.

Shipping is append-only and exactly once: the pusher asks the fleet store for the robot's
positions (per event type, the last sequence of the robot's store it holds), reads the rows
after them from the robot's store in sequence order, and sends them in batches; the fleet
store stores a batch's rows and moves the position in one transaction
(:func:`slr_sql.shipping.receive`). Whichever side is killed, the next push starts from the
positions the fleet store committed: nothing is lost and nothing stored twice.

The pusher only reads the robot's store (a WAL reader never blocks a writer): the robot's
own adds never wait for the fleet. With ``follow`` it keeps shipping as events arrive,
woken by the robot store's change counter (``PRAGMA data_version``, read with a backoff
while nothing changes), and while the fleet cannot be reached it retries with backoff and
says so once per outage; a refusal that waiting does not change (a bad token, a robot
token that may not ship as this robot, a shipment the fleet never takes) stops it with
:class:`FleetRefused`.
"""
from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any, Protocol, TypeVar

from .errors import SLRError
from .printable import printable_name, printable_text
from .arguments import refuse_memory_store
from .store import EventStore, WriterInFlight, check_robot_name, refuse_no_store, \
    shown_location

__all__ = ["FleetRefused", "FleetTarget", "PushReport", "RobotStoreRestored", "open_target", "parse_type_spec",
           "push", "reinstate", "retire", "status"]

BATCH = 5000                 # rows per batch (one fleet transaction)
MAX_BATCH = 2 ** 31 - 1      # (a count SQLite's LIMIT and every backend take)
WAKE_MIN, WAKE_MAX = 0.005, 0.25    # s between change checks of the robot store (backoff)
RETRY_MIN, RETRY_MAX = 0.1, 5.0     # s between attempts while the fleet is unreachable
HEARTBEAT = 5.0              # s between contacts of a following pusher that has nothing new
# s from the start of one round of a following pusher to the next: a robot adding every few
# ms would otherwise cost the fleet a transaction each time (and a fleet file has one write
# lock for every pusher); events wait at most this long to be gathered
ROUND_GAP = 0.05


class RobotStoreRestored(SLRError):
    """The fleet store holds sequences of the robot's store beyond the last one that store
    handed out: the robot's store was restored from an older backup (or another store ships
    under its name), so its new events reuse sequences the fleet holds and would be skipped.
    Nothing is shipped; ``push(..., resync=True)`` (``slr fleet push --resync``) ships the
    types again from their first row, the fleet skipping the rows it holds identically.

    >>> issubclass(RobotStoreRestored, SLRError)
    True
    """


class _StoreUnreadable(Exception):
    """A read of the robot's own store failed (the file damaged, busy past its timeout, a disk
    error): told apart from the fleet's failures, which drop the connection to the fleet.
    ``error`` is the store's SLRError."""

    def __init__(self, error: SLRError):
        super().__init__(str(error))
        self.error = error


_T = TypeVar("_T")


class FleetTarget(Protocol):
    """Where a pusher ships to: a fleet store opened in this process, or `slr serve`."""

    def positions(self, robot: str) -> dict[tuple[str, int], int]: ...

    def prepare(self, robot: str, batch: tuple) -> tuple: ...

    def receive(self, robot: str, batches: list, marks: dict | None, pending: int | None,
                head_arrival: float | None, after: dict | None = None,
                resync: list | None = None, relayed: dict | None = None) -> int: ...

    def close(self) -> None: ...


class _LocalTarget:
    """A fleet store opened with :func:`slr_sql.open` (a path, or a database URL)."""

    def __init__(self, where: str):
        from .kb import KnowledgeBase
        self.kb = KnowledgeBase(where)

    def positions(self, robot: str) -> dict[tuple[str, int], int]:
        from .shipping import positions
        return positions(self.kb, robot)

    def prepare(self, robot: str, batch: tuple) -> tuple:
        """``batch`` with its rows' values as the fleet store's columns hold them (no
        connection needed: called in the pusher's reading thread)."""
        from .shipping import prepare
        return prepare(self.kb, robot, batch)

    def receive(self, robot: str, batches: list, marks: dict | None, pending: int | None,
                head_arrival: float | None, after: dict | None = None,
                resync: list | None = None, relayed: dict | None = None) -> int:
        # (``after`` is not needed: a store replaced under an open connection is not seen
        # through it, and a server's restore ends the connection, which asks again)
        from .shipping import receive
        # (rows read from a store by this process: no need to check them as the service does)
        return receive(self.kb, robot, batches, marks, pending, head_arrival, check=False,
                       resync=resync, relayed=relayed)

    def close(self) -> None:
        self.kb.close()


class _RemoteTarget:
    """The fleet store of a running ``slr serve`` (its ``/fleet/*`` endpoints)."""

    def __init__(self, url: str, token: str | None):
        from .service.client import connect
        self.client = connect(url, token=token)

    def positions(self, robot: str) -> dict[tuple[str, int], int]:
        return self.client.fleet_positions(robot)

    def prepare(self, robot: str, batch: tuple) -> tuple:
        return batch

    def receive(self, robot: str, batches: list, marks: dict | None, pending: int | None,
                head_arrival: float | None, after: dict | None = None,
                resync: list | None = None, relayed: dict | None = None) -> int:
        # ``after``: over HTTP a restarted server is reached again without a word, so each
        # batch says which position it follows and the server checks it still holds it
        return self.client.fleet_receive(robot, batches, marks, pending, head_arrival, after,
                                         resync, relayed)

    def close(self) -> None:
        self.client.close()


def open_target(fleet: str, token: str | None = None) -> FleetTarget:
    """The fleet store ``fleet`` names: the URL of an `slr serve` (http://, https://), else
    a store path or database URL opened in this process.

    >>> import tempfile, os; target = open_target(os.path.join(tempfile.mkdtemp(), "f.db"))
    >>> target.positions("r1"); target.close()
    {}
    """
    if fleet.startswith(("http://", "https://")):
        return _RemoteTarget(fleet, token)
    return _LocalTarget(fleet)


def parse_type_spec(spec: str) -> tuple[str, int]:
    """``"seen/2"`` -> ``("seen", 2)``; a quoted name is read as Prolog reads it.

    >>> parse_type_spec("seen/2"), parse_type_spec("'x/seen'/2"), parse_type_spec("x/seen/2")
    (('seen', 2), ('x/seen', 2), ('x/seen', 2))
    """
    from .parser import parse_indicator

    name, arity = parse_indicator(spec)   # (a malformed quoted name: its SLRError)
    if arity is None:
        raise SLRError(f"an event type is name/arity (seen/2), not {spec!r}")
    return name, arity


@dataclass
class PushReport:
    """What a push did: rows shipped (stored by the fleet), batches sent, rounds, and the
    outages it lived through."""

    robot: str
    shipped: int = 0
    batches: int = 0
    rounds: int = 0
    outages: int = 0
    per_type: dict = field(default_factory=dict)


class _Pusher:
    def __init__(self, store: EventStore, target_factory: Callable[[], FleetTarget],
                 robot: str, types: set | None, batch: int, say: Callable[[str], None],
                 fleet_name: str, resync: bool = False):
        self.store = store
        # ship every type again from its first row, once (the robot's store was restored)
        self.resync = resync
        self.resynced: set = set()
        self.target_factory = target_factory
        self.target: FleetTarget | None = None
        self.robot = robot
        self.types = types
        self.batch = batch
        self.say = say
        self.fleet_name = fleet_name
        self.report = PushReport(robot)
        self.outage: str | None = None   # why the fleet is unreachable, while it is
        self.refused = False                # ... and whether it answered with a refusal
        self.in_flight: str | None = None   # why the robot's store made a round wait, while so
        self.unreadable: str | None = None  # why the robot's store cannot be read, while so
        # the fleet's positions (asked once per connection), the last contact sent and when
        self.positions: dict | None = None
        self.last_contact: tuple | None = None
        self.contact_at = -math.inf

    def reached(self) -> None:
        """A request to the fleet succeeded: an outage, if any, is over."""
        if self.outage is not None:
            self.outage = None
            if self.refused:
                self.say(f"fleet {self.fleet_name} took the shipment; shipping resumed")
            else:
                self.say(f"fleet {self.fleet_name} reachable again; shipping resumed")

    def unreachable(self, exc: BaseException) -> None:
        """A request to the fleet failed: say so if an outage begins -- as an outage when
        it may pass (no answer, busy, 5xx), as a refusal when the fleet answered no (a bad
        request: it will not pass by waiting, someone has to look)."""
        if self.outage is None:
            reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            self.outage = reason
            self.refused = not _may_pass(exc)
            self.report.outages += 1
            if self.refused:
                self.say(f"fleet {self.fleet_name} refused the shipment ({reason}); retrying "
                         "with backoff, the robot's store is not affected")
            else:
                self.say(f"fleet {self.fleet_name} unreachable ({reason}); retrying with "
                         "backoff, the robot's store is not affected")

    def store_waits(self, exc: WriterInFlight) -> None:
        """A round ended waiting for a writer of the robot's own store: say so once, as
        that store's condition (the fleet stays reachable, its connection kept)."""
        if self.in_flight is None:
            self.in_flight = str(exc).splitlines()[0]
            self.say(f"{self.in_flight}; retrying with backoff")

    def store_ready(self) -> None:
        """A round ran through: a wait for the robot's store's writers, or a failure to read
        it, if any, is over."""
        if self.in_flight is not None:
            self.in_flight = None
            self.say("the robot's store's writers are done; shipping resumed")
        if self.unreadable is not None:
            self.unreadable = None
            self.say("the robot's store reads again; shipping resumed")

    def read(self, call: Callable[..., _T], *args: Any) -> _T:
        """``call(*args)``, a read of the robot's store: its failure is raised as
        :class:`_StoreUnreadable` (a writer in flight as it is: a wait of its own)."""
        try:
            return call(*args)
        except WriterInFlight:
            raise
        except SLRError as exc:
            raise _StoreUnreadable(exc) from None

    def store_fails(self, exc: SLRError) -> None:
        """A read of the robot's store failed: say so once while it fails for one reason
        (the connection to the fleet is kept)."""
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        if self.unreadable != reason:
            self.unreadable = reason
            self.say(f"the robot's store cannot be read ({reason}); retrying with backoff")

    def connect(self) -> FleetTarget:
        if self.target is None:
            self.target = self.target_factory()
        return self.target

    def drop(self) -> None:
        self.positions = None
        target, self.target = self.target, None
        if target is not None:
            try:
                target.close()
            except Exception:  # noqa: BLE001 - a broken connection closes as it can
                pass

    def round(self, stop: threading.Event, heartbeat: float | None = None) -> int:
        """:meth:`ship`; when the fleet store no longer holds a position this pusher was
        told (restored or replaced behind it, answered 409 Conflict), ask its positions
        again and ship from there: the rows it lost are shipped again, none is left out."""
        try:
            return self.ship(stop, heartbeat)
        except SLRError as exc:
            if getattr(exc, "kind", None) != "Conflict":
                raise
            self.say(f"fleet {self.fleet_name}: {str(exc).splitlines()[0]}")
            self.positions = None
            return self.ship(stop, heartbeat)

    def ship(self, stop: threading.Event, heartbeat: float | None = None) -> int:
        """Ship everything the robot's store holds beyond the fleet's positions (stopping
        early when ``stop`` is set); returns the rows the fleet stored.

        The marks and the contact (what is left, for ``slr fleet status``) go with the last
        batch, in its transaction; a round that has no batch sends them alone when they
        changed, or when ``heartbeat`` seconds passed since the last contact (None: always).
        The fleet's positions are asked once per connection: every batch carries its
        sequences, and the fleet skips what it holds already."""
        target = self.connect()
        if self.positions is None:
            self.positions = target.positions(self.robot)
            self.reached()
        positions = self.positions
        # the marks before the types: a type whose first row came with its mark after the
        # types were read would go unshipped this round, and its mark with it
        read = self.read
        marks = {k[len("sync/mark/"):]: v
                 for k, v in read(self.store.meta_items, "sync/mark/").items() if _is_mark(v)}
        relayed = read(_relayed_marks, self.store, self.robot)
        heads = read(self.store.fleet_heads)
        shipped = 0
        keys = sorted(k for k in heads if self.types is None or k in self.types)
        if self.types is not None:   # (the marks of the types left out speak of rows not shipped)
            marks = _marks_of(self.types, heads, marks)
            relayed = {r: m for r, m in ((r, _marks_of(self.types, heads, m))
                                         for r, m in relayed.items()) if m}
        again = [k for k in keys if self.resync and k not in self.resynced]
        counters = read(self.store.fleet_counters)
        for key in keys:
            if key not in again and counters.get(key, 0) < positions.get(key, 0):
                raise RobotStoreRestored(
                    f"the fleet {self.fleet_name} holds {key[0]}/{key[1]} of robot "
                    f"{self.robot!r} up to seq {positions[key]}, but the robot's store has "
                    f"handed out sequences only up to {counters.get(key, 0)}: the store was "
                    "restored from an older backup (or another store ships under this "
                    "robot's name), and its new events reuse sequences the fleet holds. "
                    "Nothing was shipped; ship again with 'slr fleet push DB FLEET --resync' "
                    "(each type from its first row, the fleet skipping the rows it holds "
                    "identically)")
        held: tuple | None = None     # the batch read last, sent once the next one is read
        held_after: dict | None = None   # the position it was read after
        held_resync: list | None = None  # [(name, arity)] when it ships its type again

        def record(batch: tuple, stored: int) -> None:
            nonlocal shipped
            name, arity, rows = batch[:3]
            positions[(name, arity)] = rows[-1][0]
            shipped += stored
            self.report.shipped += stored
            self.report.batches += 1
            key = f"{name}/{arity}"
            self.report.per_type[key] = self.report.per_type.get(key, 0) + stored

        def send(batch: tuple | None, contact: tuple = (None, None, None, None)) -> None:
            stored = target.receive(self.robot, [batch] if batch else [], *contact[:3],
                                    held_after if batch else None,
                                    held_resync if batch else None, contact[3])
            self.reached()
            if batch is not None:
                record(batch, stored)

        # All batches but the last go through a sender thread: the fleet stores batch k
        # (psycopg, sqlite3 and the network wait without the GIL) while this thread reads
        # batch k + 1 from the robot's store. One batch queued, one in flight.
        sender: _Sender | None = None
        emptied = []     # types shipped again that the robot holds no row of
        cut = False      # stopped before every row was read: the marks wait for the next round
        try:
            for name, arity in keys:
                position = 0 if (name, arity) in again else positions.get((name, arity), 0)
                while True:
                    if stop.is_set():
                        cut = True
                        break
                    rows = read(self.store.fleet_read_after, name, arity, position, self.batch)
                    if not rows:
                        if position == 0 and (name, arity) in again \
                                and positions.get((name, arity), 0) > 0:
                            emptied.append((name, arity))
                        break
                    if held is not None:
                        if sender is None:
                            sender = _Sender(target, self.robot, record)
                        sender.put(held, held_after, held_resync)
                    # the batch's own work that needs no connection, done here while the
                    # sender waits on the fleet for the batch before
                    held = target.prepare(self.robot, (name, arity, rows))
                    held_after = {(name, arity): position}
                    held_resync = [(name, arity)] if (name, arity) in again else None
                    position = rows[-1][0]
                    if len(rows) < self.batch:
                        break
            if sender is not None:
                sender.finish()
            for key in emptied:
                # the fleet's position goes back to 0, or the next push would take it for
                # a restore again
                target.receive(self.robot, [(*key, [])], None, None, None, None, [key])
                positions[key] = 0
        finally:
            if sender is not None:
                sender.abandon()
        if sender is not None:
            self.reached()
        pending = 0
        head_arrival = None
        for name, arity in keys:
            position = positions.get((name, arity), 0)
            if held is not None and held[:2] == (name, arity):
                position = held[2][-1][0]
            left, latest = read(self.store.fleet_backlog, name, arity, position)
            pending += left
            if latest is not None:
                head_arrival = latest if head_arrival is None else max(head_arrival, latest)
        # (a round cut short sends no marks: they speak of rows it did not ship)
        contact = (None if cut else marks or None, pending, head_arrival,
                   None if cut else relayed or None)
        now = time.monotonic()
        if held is not None or heartbeat is None or contact != self.last_contact \
                or now - self.contact_at >= heartbeat:
            # marks and what is left, with the last batch (after the events they speak of)
            send(held, contact)
            self.last_contact, self.contact_at = contact, now
        if not stop.is_set():
            self.resynced.update(again)
        self.report.rounds += 1
        return shipped


class _Sender:
    """Sends batches to the fleet in a thread of its own, in order, while the pusher reads
    the next ones; the first failure stops it and is raised by :meth:`put` or
    :meth:`finish` in the pusher's thread."""

    def __init__(self, target: FleetTarget, robot: str, record: Callable[[tuple, int], None]):
        import queue
        self.target = target
        self.robot = robot
        self.record = record
        self.queue: Any = queue.Queue(maxsize=1)
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._run, name="slr-fleet-sender", daemon=True)
        self.thread.start()

    def _run(self) -> None:
        while True:
            batch = self.queue.get()
            if batch is None or self.error is not None:
                if batch is None:
                    return
                continue   # after a failure: drain what was queued, send nothing more
            batch, after, resync = batch
            try:
                self.record(batch, self.target.receive(self.robot, [batch], None, None, None,
                                                       after, resync))
            except BaseException as exc:  # noqa: BLE001 - raised again in the pusher's thread
                self.error = exc

    def _raise(self) -> None:
        if self.error is not None:
            raise self.error

    def put(self, batch: tuple, after: dict | None = None,
            resync: list | None = None) -> None:
        """Queue ``batch``, read after the positions ``after`` (waiting while one is queued
        already)."""
        import queue
        while True:
            self._raise()
            try:
                self.queue.put((batch, after, resync), timeout=0.05)
                return
            except queue.Full:
                continue

    def finish(self) -> None:
        """Wait until every queued batch is stored; raise the first failure."""
        self.queue.put(None)
        self.thread.join()
        self._raise()

    def abandon(self) -> None:
        """End the thread without waiting for more than the batch in flight (after a
        failure in the pusher's thread)."""
        if self.thread.is_alive():
            self.error = self.error or SLRError("push abandoned")
            try:
                self.queue.put_nowait(None)
            except Exception:  # noqa: BLE001 - full: the thread drains and sees None next
                self.queue.put(None)
            self.thread.join()


def push(db: str, fleet: str, *, robot: str | None = None,
         types: Iterable[str | tuple[str, int]] | None = None, follow: bool = False,
         batch: int = BATCH, stop: threading.Event | None = None,
         say: Callable[[str], None] | None = None, token: str | None = None,
         resync: bool = False) -> PushReport:
    """Ship the events (incoming and complex) and completeness marks of the robot store
    ``db`` to the fleet store ``fleet`` (a store path, a database URL, or the URL of `slr
    serve`), each event once. ``robot``: the name to ship as (default: the store's name;
    a store without one needs it, and is named so by the push); ``types``: only these event types (``"seen/2"``);
    ``follow``: keep shipping as events arrive until ``stop`` is set (retrying with backoff
    while the fleet is unreachable, ``say`` telling once per outage; a refusal that waiting
    does not change raises :class:`FleetRefused`); ``batch``: rows per
    fleet transaction; ``resync``: ship every type again from its first row, the fleet
    skipping the rows it holds identically (after the robot's store was restored from an
    older backup, which a push otherwise refuses with :class:`RobotStoreRestored`).

    >>> import os, tempfile, slr_sql
    >>> folder = tempfile.mkdtemp()
    >>> with slr_sql.open(os.path.join(folder, "r1.db"), robot="r1",
    ...                   clock=slr_sql.ManualClock(0)) as kb:
    ...     kb.add("seen(pallet7, dock)^10")
    >>> push(os.path.join(folder, "r1.db"), os.path.join(folder, "fleet.db")).shipped
    1
    >>> push(os.path.join(folder, "r1.db"), os.path.join(folder, "fleet.db")).shipped
    0
    """
    if type(batch) is not int or not 1 <= batch <= MAX_BATCH:
        raise SLRError(f"batch must be a count of rows from 1 to {MAX_BATCH}, not {batch!r}")
    say = say if say is not None else (lambda message: None)
    stop = stop if stop is not None else threading.Event()
    wanted = None if types is None else {
        t if isinstance(t, tuple) else parse_type_spec(t) for t in types}
    store = EventStore(db)
    try:
        named = store.robot
        if robot is not None:
            check_robot_name(robot)
            if named is not None and named != robot:
                raise SLRError(f"{shown_location(db)} is the store of robot {named!r}, not {robot!r}")
        name = robot if robot is not None else named
        if name is None:
            raise SLRError(f"{shown_location(db)} has no robot name: open it with robot=NAME once, or "
                           "push with --robot NAME")
        check_robot_name(name)   # (a store named before a check it would fail existed)
        if _same_file(db, fleet):
            raise SLRError(f"{shown_location(fleet)} is the robot's store {shown_location(db)} itself: a robot does not ship "
                           "to its own store")
        if named is None:
            # shipped as the robot, the store is the robot's from now on (as `slr fleet
            # name`): it ships as no other, and knows the robot's rows relayed back to it for
            # its own (a cycle, refused); its new events carry the name. (After the checks:
            # a push refused names nothing.)
            store.name_robot(name)
        pusher = _Pusher(store, lambda: open_target(fleet, token), name, wanted, batch, say,
                         fleet, resync)
        try:
            if not follow:
                try:
                    pusher.round(stop)
                except _StoreUnreadable as exc:
                    raise exc.error from None
                return pusher.report
            _follow(pusher, stop)
            return pusher.report
        finally:
            pusher.drop()
    finally:
        store.close()


def _is_mark(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) \
        and math.isfinite(value)


def _marks_of(types: set, held: Iterable[tuple[str, int]], marks: dict[str, Any]) -> dict:
    """The marks (``{"p/N": t}``) that speak only of ``types``: ``p/N`` of one of them,
    ``p/*`` when ``types`` hold ``p`` of every arity ``held`` (the types a store holds).

    >>> _marks_of({("p", 1)}, [("p", 1), ("p", 2), ("q", 1)], {"p/1": 5, "p/*": 5, "q/1": 5})
    {'p/1': 5}
    """
    out = {}
    for key, t in marks.items():
        name, _, arity = key.rpartition("/")
        if arity == "*":
            covered = any(n == name for n, _ in types) and all(
                (n, a) in types for n, a in held if n == name)
        else:
            covered = arity.isdigit() and (name, int(arity)) in types
        if covered:
            out[key] = t
    return out


def _relayed_marks(store: EventStore, robot: str) -> dict[str, dict[str, float]]:
    """The marks ``store`` holds of robots other than ``robot`` (``fleet/mark/<r>/p/N``,
    kept when they shipped to it): ``{r: {"p/N": t}}``, shipped with the store's own so
    that a fleet store holding their rows, relayed by this one, knows how far each robot's
    history is complete.

    >>> from slr_sql.store import EventStore
    >>> _relayed_marks(EventStore(None), "hub")
    {}
    """
    from .shipping import FLEET_MARK, read_fleet_mark_key
    out: dict[str, dict[str, float]] = {}
    for key, value in store.meta_items(FLEET_MARK).items():
        read = read_fleet_mark_key(key)
        if read is None or read[0] == robot or not _is_mark(value):
            continue
        out.setdefault(read[0], {})[read[1]] = float(value)
    return out


def _may_pass(exc: BaseException) -> bool:
    """Whether a failed request to the fleet may succeed later as it is: no answer, a
    timeout, a busy or full store, a server error -- not a refusal of the shipment.

    >>> from slr_sql.errors import SLRBusy
    >>> _may_pass(SLRBusy("locked")), _may_pass(OSError()), _may_pass(SLRError("refused"))
    (True, True, False)
    """
    from .errors import SLRTimeout, SLRUnavailable
    if isinstance(exc, (OSError, SLRUnavailable, SLRTimeout)):
        return True
    status = getattr(exc, "status", None)
    return isinstance(status, int) and (status == 0 or status >= 500 or status == 408)


# statuses of a fleet's answer that waiting does not change, though they are 4xx: a timeout,
# a store restored behind the pusher (409: it asks the positions again), a rate limit
RETRIED_4XX = (408, 409, 429)


def _refused_for_good(exc: BaseException) -> bool:
    """Whether the fleet refused a request in a way no retry of this pusher changes: over
    ``slr serve`` an answer 4xx but 408, 409 and 429 (a bad token 401, a robot token that
    may not ship as this robot 403, an unknown endpoint 404, a shipment the fleet will not
    take 400, a body beyond its limit 413); from a fleet store opened here, the refusals
    that are a 400 over ``slr serve`` (the robot's own store, a shipment conflict, a robot
    reaching the fleet by two routes).

    >>> from slr_sql.service.errors import ServiceError, ServiceUnavailable
    >>> [_refused_for_good(ServiceError("x", kind=k)) for k in ("Unauthorized", "Conflict")]
    [True, False]
    >>> _refused_for_good(ServiceUnavailable("down", status=0)), _refused_for_good(OSError())
    (False, False)
    """
    from .shipping import ShipmentRefused
    from .store.fleet import RouteConflict, ShipmentConflict
    if isinstance(exc, (ShipmentRefused, ShipmentConflict, RouteConflict)):
        return True
    status = getattr(exc, "status", None)
    return isinstance(exc, SLRError) and isinstance(status, int) \
        and 400 <= status < 500 and status not in RETRIED_4XX


class FleetRefused(SLRError):
    """A following pusher (``push(..., follow=True)``, ``slr fleet push --follow``) stopped:
    the fleet refused it in a way waiting does not change (see ``docs/fleet.md``). The
    message names the fleet, the HTTP status when it came over ``slr serve``, and the
    fleet's reason; ``status`` is that status (None from a fleet store opened in the
    pusher), ``__cause__`` the fleet's error.

    >>> FleetRefused("fleet F refused ...", status=401).status
    401
    """

    def __init__(self, message: str, status: int | None = None):
        super().__init__(message)
        self.status = status


def _refusal(fleet: str, exc: BaseException) -> FleetRefused:
    """The FleetRefused a following pusher stops with on the refusal ``exc``.

    >>> from slr_sql.service.errors import ServiceForbidden
    >>> str(_refusal("http://f", ServiceForbidden("the token of robot 'r1' ships as 'r1' only")))
    "fleet http://f refused the push for good (HTTP 403 Forbidden: the token of robot 'r1' ships as 'r1' only); the push stopped, nothing more is shipped until it is started again"
    """
    reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    status = getattr(exc, "status", None)
    status = status if isinstance(status, int) and 400 <= status < 500 else None
    kind = getattr(exc, "kind", None)
    said = f"HTTP {status} {kind}: {reason}" if status is not None and kind else reason
    return FleetRefused(f"fleet {fleet} refused the push for good ({said}); the push stopped, "
                        "nothing more is shipped until it is started again", status)


def _retry_wait(exc: BaseException, backoff: float) -> float:
    """Seconds to wait after a failed request to the fleet before the next: the backoff, or
    the wait the failure asks for when longer (an SLRUnavailable's ``retry_after``: what the
    fleet server's ``Retry-After`` said, else its class's default), at most RETRY_MAX.

    >>> from slr_sql.errors import SLRStoreFull
    >>> _retry_wait(SLRStoreFull("full"), 0.1), _retry_wait(OSError(), 0.4)
    (5.0, 0.4)
    """
    from .errors import SLRUnavailable
    told = getattr(exc, "retry_after", None) if isinstance(exc, SLRUnavailable) else None
    if isinstance(told, (int, float)) and told > backoff:
        return min(float(told), RETRY_MAX)
    return backoff


def _same_file(db: str, fleet: str) -> bool:
    """Whether the fleet store path ``fleet`` is the file ``db`` (another spelling, a link).

    >>> import os, tempfile; f = os.path.join(tempfile.mkdtemp(), "r.db"); open(f, "w").close()
    >>> _same_file(f, os.path.join(os.path.dirname(f), ".", "r.db")), _same_file(f, f + "x")
    (True, False)
    """
    import os
    if "://" in fleet or "://" in db:
        return False
    try:
        return os.path.samefile(db, fleet)
    except (OSError, ValueError):   # the fleet file does not exist yet: another file
        return False


def _follow(pusher: _Pusher, stop: threading.Event) -> None:
    """Rounds until ``stop``: after a round that left nothing, wait for the robot's store to
    change (its data_version, read with a backoff); while the fleet is unreachable, or the
    robot's store cannot be read (damaged, replaced, busy, for a while), retry with a
    backoff, saying so once per outage."""
    store = pusher.store
    retry = RETRY_MIN
    while not stop.is_set():
        began = time.monotonic()
        try:
            seen = pusher.read(store.data_version)
            pusher.round(stop, HEARTBEAT)
        except RobotStoreRestored:   # waiting would not cure it: it would ship with a hole
            raise
        except WriterInFlight as exc:   # the robot's store, not the fleet: try again later
            pusher.store_waits(exc)
            stop.wait(retry)
            retry = min(retry * 2, RETRY_MAX)
            continue
        except _StoreUnreadable as exc:   # the same, and the fleet connection is kept
            pusher.store_fails(exc.error)
            stop.wait(retry)
            retry = min(retry * 2, RETRY_MAX)
            continue
        except (SLRError, OSError) as exc:  # unreachable, busy, refused: try again later
            pusher.drop()
            if _refused_for_good(exc):   # (waiting would only hide it from whoever runs us)
                raise _refusal(printable_name(shown_location(pusher.fleet_name)), exc) from exc
            pusher.unreachable(exc)
            stop.wait(_retry_wait(exc, retry))
            retry = min(retry * 2, RETRY_MAX)
            continue
        retry = RETRY_MIN
        pusher.store_ready()
        gap = began + ROUND_GAP - time.monotonic()
        if gap > 0:
            stop.wait(gap)
        wait = WAKE_MIN
        beat = time.monotonic() + HEARTBEAT   # an idle robot's contact stays fresh too
        while not stop.is_set() and time.monotonic() < beat:
            try:
                if store.data_version() != seen:
                    break
            except SLRError:
                break   # (the round reads it again, and says why if it still fails)
            stop.wait(wait)
            wait = min(wait * 2, WAKE_MAX)


def status(fleet: str, token: str | None = None, now: float | None = None) -> list[dict[str, Any]]:
    """Per robot that shipped to the fleet store ``fleet``: ``robot``, ``shipped`` (events
    stored from it), ``pending`` (events its store held unshipped at the last contact),
    ``lag_seconds`` (arrival of its latest event less arrival of the latest shipped, at the
    last contact; 0 when nothing was pending), ``last_contact`` (seconds since the epoch)
    and ``since_contact`` (seconds), ``via`` None (``pending``, ``lag_seconds``,
    ``last_contact`` None while its pusher never reported: killed in its first round); and
    per robot whose rows another store
    relays there: ``shipped`` (its rows stored), ``via`` (the relaying store's robot),
    ``pending``, ``lag_seconds`` and ``last_contact`` None (its pusher reports to the
    relaying store); in name order.

    >>> import os, tempfile; status(os.path.join(tempfile.mkdtemp(), "f.db"))
    []
    """
    now = time.time() if now is None else now
    if fleet.startswith(("http://", "https://")):
        from .service.client import connect
        with connect(fleet, token=token) as client:
            rows = client.fleet_status()
    else:
        from .kb import KnowledgeBase
        with KnowledgeBase(fleet) as kb:
            rows = kb.store.fleet_contacts()
    out = []
    for r in rows:
        via = r.get("via")   # (a server of an older slr_sql does not say)
        # a robot whose pusher has not reported yet (killed in its first round, which
        # reports with its last batch) has no known lag: not a lag of 0
        unknown = via is not None or r["contact_at"] is None
        lag: float | None = None if unknown else 0.0
        if not unknown and r["pending"] and r["head_arrival"] is not None:
            lag = max(0.0, r["head_arrival"] - (r["last_arrival"] if r["last_arrival"]
                                                is not None else r["head_arrival"]))
        out.append({"robot": r["robot"], "shipped": r["shipped"],
                    "pending": None if unknown else r["pending"],
                    "lag_seconds": lag, "last_contact": r["contact_at"],
                    "since_contact": None if r["contact_at"] is None
                    else max(0.0, now - r["contact_at"]), "via": via,
                    "retired_at": r.get("retired_at")})
    return out


def _utc(seconds: float) -> str:
    """A time of ``slr fleet``'s output: seconds since the epoch as UTC, to the second."""
    return time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime(seconds))


def _status_cells(r: dict[str, Any]) -> tuple[str, ...]:
    """The cells of one robot's line of ``slr fleet status``: a retired robot's, a relayed
    robot's (no contact of its own), or one that ships here itself."""
    # (names checked when they came in; a fleet file edited by hand may hold others)
    name, shipped = printable_name(r["robot"]), str(r["shipped"])
    via = None if r.get("via") is None else f"relayed via {printable_name(r['via'])}"
    if r.get("retired_at") is not None:
        return (name, shipped, "-", "-",
                f"retired {_utc(r['retired_at'])}" + ("" if via is None else f", {via}"))
    if via is not None:
        return (name, shipped, "-", "-", via)
    return (name, shipped,
            "-" if r["pending"] is None else str(r["pending"]),
            "-" if r["lag_seconds"] is None else f"{r['lag_seconds']:.3f}",
            "never" if r["last_contact"] is None else
            f"{_utc(r['last_contact'])} ({r['since_contact']:.0f} s ago)")


def _on_fleet_store(fleet: str, token: str | None, local: Callable[[Any], _T],
                    remote: Callable[[Any], _T]) -> _T:
    """``remote(client)`` when ``fleet`` is the URL of `slr serve`, else ``local(kb)`` on the
    fleet store opened here (a path that holds no store is refused, not created)."""
    if fleet.startswith(("http://", "https://")):
        from .service.client import connect
        with connect(fleet, token=token) as client:
            return remote(client)
    refuse_no_store(fleet)
    from .kb import KnowledgeBase
    with KnowledgeBase(fleet) as kb:
        return local(kb)


def retire(fleet: str, robot: str, token: str | None = None) -> dict[str, Any]:
    """Retire ``robot`` from the fleet store ``fleet`` (a store path, a database URL, or the
    URL of `slr serve`, where ``token`` must be the server's own): the fleet's marks stop
    waiting for it and may rise (never fall), its events stay, and shipments of it are
    refused until :func:`reinstate` (see :func:`slr_sql.shipping.retire`). Returns
    ``{"robot", "retired_at", "already", "raised"}``.

    >>> import os, tempfile, slr_sql
    >>> folder = tempfile.mkdtemp()
    >>> with slr_sql.open(os.path.join(folder, "r1.db"), robot="r1",
    ...                   clock=slr_sql.ManualClock(0)) as kb:
    ...     kb.add("seen(pallet7, dock)^10")
    >>> push(os.path.join(folder, "r1.db"), os.path.join(folder, "fleet.db")).shipped
    1
    >>> retire(os.path.join(folder, "fleet.db"), "r1")["already"]
    False
    >>> [r["retired_at"] is not None for r in status(os.path.join(folder, "fleet.db"))]
    [True]
    """
    from . import shipping
    return _on_fleet_store(fleet, token, lambda kb: shipping.retire(kb, robot),
                           lambda client: client.fleet_retire(robot))


def reinstate(fleet: str, robot: str, token: str | None = None) -> dict[str, Any]:
    """Take back the retirement of ``robot`` on the fleet store ``fleet`` (as :func:`retire`
    takes it): it ships again and the fleet's marks wait for it again, from where they are.
    Returns ``{"robot", "reinstated"}`` (False: it was not retired).

    >>> import os, tempfile; fleet = os.path.join(tempfile.mkdtemp(), "f.db")
    >>> reinstate(fleet, "r1")
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: no such store: ...f.db
    """
    from . import shipping
    return _on_fleet_store(fleet, token, lambda kb: shipping.reinstate(kb, robot),
                           lambda client: client.fleet_reinstate(robot))


# -- the command line: `slr fleet push`, `slr fleet status` (registered by slr_sql.cli) --------

def click_group() -> Any:
    """The ``slr fleet`` command group (``name``, ``push``, ``status``, ``retire``,
    ``reinstate``), built on use so
    that importing this module does not import click.

    >>> click_group().name
    'fleet'
    """
    import click

    def token_of(ctx: click.Context) -> str | None:
        return (ctx.find_root().obj or {}).get("token")

    @click.group("fleet")
    def fleet_group() -> None:
        """Ship a robot's store to a fleet store, and see what the fleet holds."""

    @fleet_group.command("name")
    @click.argument("db", type=click.Path(dir_okay=False))
    @click.argument("robot")
    def name_command(db: str, robot: str) -> None:
        """Name the robot the store DB belongs to (kept in the store; once for life). Its
        events from now on carry the name; ``slr_sql.open(DB, robot=NAME)`` does the same."""
        refuse_memory_store(db, "slr fleet name")
        with EventStore(db, robot=robot):
            pass
        click.echo(f"{printable_name(shown_location(db))} is the store of robot {printable_name(robot)}")

    @fleet_group.command("push")
    @click.argument("db", type=click.Path(dir_okay=False))
    @click.argument("fleet")
    @click.option("--robot", default=None, help="Ship as this robot (default: the store's name); names a store that "
                       "has none.")
    @click.option("--follow", is_flag=True,
                  help="Keep shipping as events arrive, until SIGINT/SIGTERM.")
    @click.option("--type", "types", multiple=True, metavar="NAME/N",
                  help="Ship only this event type (repeatable).")
    @click.option("--batch", type=int, default=BATCH, show_default=True,
                  help="Events per fleet transaction.")
    @click.option("--resync", is_flag=True,
                  help="Ship every type again from its first row, the fleet skipping rows "
                       "it holds identically (after restoring DB from an older backup).")
    @click.pass_context
    def push_command(ctx: click.Context, db: str, fleet: str, robot: str | None,
                     follow: bool, types: tuple, batch: int, resync: bool) -> None:
        """Ship DB's events, complex events and completeness marks to FLEET (a store path,
        or the URL of `slr serve`), each once; resumable after a crash of either side."""
        import signal

        refuse_no_store(db)
        refuse_memory_store(fleet, "slr fleet push")
        stop = threading.Event()
        if follow:
            def on_signal(signum: int, frame: Any) -> None:
                stop.set()
            signal.signal(signal.SIGINT, on_signal)
            signal.signal(signal.SIGTERM, on_signal)
            click.echo(f"following {printable_name(shown_location(db))}: shipping to "
                       f"{printable_name(shown_location(fleet))} (SIGINT or SIGTERM stops)",
                       err=True)

        def say(message: str) -> None:
            click.echo(printable_text(message), err=True)

        report = push(db, fleet, robot=robot, types=types or None, follow=follow, batch=batch,
                      stop=stop, say=say, token=token_of(ctx), resync=resync)
        click.echo(f"robot {printable_name(report.robot)}: shipped {report.shipped} events in "
                   f"{report.batches} batches")

    @fleet_group.command("status")
    @click.argument("fleet")
    @click.option("--json", "as_json", is_flag=True, help="Print a JSON list of robots.")
    @click.pass_context
    def status_command(ctx: click.Context, fleet: str, as_json: bool) -> None:
        """Per robot: events shipped, lag (events and seconds) and last contact; a robot
        whose rows another store relays here: the store they come through."""
        import json

        if not fleet.startswith(("http://", "https://", "postgresql://", "postgres://")):
            refuse_no_store(fleet)
        rows = status(fleet, token=token_of(ctx))
        if as_json:
            from .service.encoding import encode_plain
            # (a time that is not finite, from a fleet file edited by hand or a server of
            # another make, as the rest of the command line writes one: JSON has no Infinity)
            click.echo(json.dumps(encode_plain(rows), indent=2, allow_nan=False))
            return
        if not rows:
            click.echo("no robot has shipped to this store")
            return
        header = ("robot", "shipped", "lag events", "lag s", "last contact")
        table = [header] + [_status_cells(r) for r in rows]
        widths = [max(len(row[i]) for row in table) for i in range(len(header))]
        for row in table:
            click.echo("  ".join(cell.ljust(w) for cell, w in zip(row, widths)).rstrip())

    @fleet_group.command("retire")
    @click.argument("fleet")
    @click.argument("robot")
    @click.pass_context
    def retire_command(ctx: click.Context, fleet: str, robot: str) -> None:
        """Retire ROBOT from the fleet store FLEET (a robot scrapped or renamed): the fleet's
        marks stop waiting for it and may rise; its events stay; its shipments are refused
        until `slr fleet reinstate`. Over `slr serve`, with the server's own token."""
        done = retire(fleet, robot, token=token_of(ctx))
        when = _utc(done["retired_at"])
        name = printable_name(done["robot"])
        if done["already"]:
            click.echo(f"robot {name} was retired already ({when}); nothing changed")
            return
        raised = ", ".join(f"{printable_name(mk)} to {t:g}"
                           for mk, t in sorted(done["raised"].items()))
        click.echo(f"robot {name} retired ({when}); the fleet's marks "
                   + (f"rose: {raised}" if raised else "did not move"))

    @fleet_group.command("reinstate")
    @click.argument("fleet")
    @click.argument("robot")
    @click.pass_context
    def reinstate_command(ctx: click.Context, fleet: str, robot: str) -> None:
        """Take back the retirement of ROBOT on FLEET: it ships again, and the fleet's marks
        wait for it again (from where they are: marks never fall)."""
        done = reinstate(fleet, robot, token=token_of(ctx))
        name = printable_name(done["robot"])
        click.echo(f"robot {name} reinstated: it ships again" if done["reinstated"]
                   else f"robot {name} was not retired; nothing changed")

    return fleet_group
