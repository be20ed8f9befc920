"""The fleet store's side of shipping: storing one shipment of a robot exactly once.

A shipment is what a pusher (:mod:`slr_sql.fleet`) sends in one request: batches of stored
rows (one event type each, with their sequence numbers in the robot's store), the robot's
completeness marks, and what is still waiting on the robot. :func:`receive` stores it in one
transaction of the fleet store: rows after the robot's position for their type, the new
positions, the marks. Called in-process for a fleet store path (or URL of a database) and
by the ``/fleet/*`` endpoints of ``slr serve``.

Event rules loaded on the fleet store run over the shipped events in that transaction (their
complex events have the fleet store's robot: NULL on an unnamed fleet store); without event
rules the rows go in as they are stored on the robot (no decoding).

A robot taken out of service is retired from the fleet store (:func:`retire`, ``slr fleet
retire``): the fleet's marks stop waiting for it, and its shipments are refused until
:func:`reinstate`.
"""
from __future__ import annotations

import logging
import math
import time
from typing import Any

from .encoding import INT64_MAX, INT64_MIN, decode
from .errors import SLRError
from .host import Host
from .store import check_robot_name
from .store.checks import shown, text_problem
from .store.fleet_keys import FLEET_MARK, fleet_mark_key, names_a_type, read_fleet_mark_key

log = logging.getLogger("slr_sql.shipping")

__all__ = ["FLEET_MARK", "FleetBehind", "RobotRetired", "ShipmentRefused", "fleet_mark_key",
           "names_a_type", "positions", "prepare", "read_fleet_mark_key", "receive", "reinstate",
           "retire"]

_JSON = ("[", "{", '"')     # how a stored text that is JSON starts (slr_sql.encoding)
# slr_meta prefix of the marks kept per robot: fleet/mark/<robot, escaped>/<name>/<arity or *>.
# A robot's name and a type's name may both hold '/' ('x/seen' is an atom), so the robot is
# written with '%' and '/' as %25 and %2F: the first '/' after the prefix ends it, and robot
# r1/x's mark of seen/2 (fleet/mark/r1%2Fx/seen/2) is no longer robot r1's of 'x/seen'/2
# (fleet/mark/r1/x/seen/2). A name without either character is written as it is, so a store
# of the layout before (schema version 13) needed only its other keys rewritten (0014).


class FleetBehind(SLRError):
    """A shipment was sent after positions the fleet store no longer holds: the fleet store
    was restored from a backup or replaced while the pusher kept the positions it had asked
    for. Storing the shipment would leave the rows in between out for ever; the pusher asks
    the positions again and ships from there (``slr serve`` answers it 409 Conflict).

    >>> issubclass(FleetBehind, SLRError)
    True
    """


class ShipmentRefused(SLRError):
    """A fleet store refuses every shipment of this robot, whatever it brings: it is the
    robot's own store (pushed into itself, or served and pushed to). Sending it again
    changes nothing (a following pusher stops, see :mod:`slr_sql.fleet`); over ``slr
    serve`` it is a 400.

    >>> issubclass(ShipmentRefused, SLRError)
    True
    """


class RobotRetired(ShipmentRefused):
    """A shipment of a robot retired from the fleet store (:func:`retire`), or relaying its
    rows: the fleet's marks no longer wait for it, so its events would come in behind marks
    already moved past them. Nothing of the shipment is stored; sending it again changes
    nothing until the robot is reinstated (:func:`reinstate`, ``slr fleet reinstate``): a
    following pusher stops, over ``slr serve`` it is a 400.

    >>> issubclass(RobotRetired, ShipmentRefused)
    True
    """


def positions(kb: Host, robot: str) -> dict[tuple[str, int], int]:
    """Per event type, the last sequence of ``robot``'s store that ``kb`` (a fleet store)
    holds.

    >>> import slr_sql; positions(slr_sql.open(), "r1")
    {}
    """
    return kb.store.fleet_positions(robot)


def receive(kb: Host, robot: str, batches: list, marks: dict | None = None,
            pending: int | None = None, head_arrival: float | None = None, *,
            check: bool = True, after: list | None = None,
            resync: list | None = None, relayed: dict | None = None) -> int:
    """Store one shipment of ``robot`` in the fleet store ``kb``; returns the number of rows
    stored (rows already held are skipped). ``batches``: ``[(name, arity, rows)]`` with rows
    as :meth:`slr_sql.store.EventStore.fleet_read_after` gives them (or as :func:`prepare`
    gives a batch); ``marks``: ``{"p/1": t}`` (the robot's completeness marks, ``p/*`` for every arity); ``pending``,
    ``head_arrival``: what the robot still holds unshipped (for ``slr fleet status``).
    ``check=False`` skips checking the shipment's shape (rows this process read from a store).
    ``after``: ``[(name, arity, position)]``, the positions the sender read the batches after
    (what it was told the fleet store holds); a position the fleet store holds no longer
    (restored or replaced since) raises :class:`FleetBehind` and stores nothing.
    ``resync``: ``[(name, arity)]``, types whose batches ship the type again from its first
    row (``slr fleet push --resync``, after the robot's store was restored from an older
    backup): a row the fleet store holds identically is skipped, every other one stored.
    ``relayed``: ``{robot: {"p/1": t}}``, the marks the sending store holds of other robots
    (a store that received their shipments and relays their rows), kept as theirs.

    A robot's mark is kept per robot; the fleet store's own mark of a type is the least mark
    of the robots it knows, once every one of them has marked it (a history of the fleet is
    complete up to t when each robot's is). The robots it knows are those it holds rows or
    marks of and those whose last contact said events wait on them (``pending`` above 0); a
    contact alone makes no robot one the mark waits for. The store's own name is not among
    them: its own events are complete as far as its own marks say; nor are the robots
    retired from the store (:func:`retire`), whose shipments, and rows of them relayed, are
    refused with :class:`RobotRetired`.

    >>> import slr_sql
    >>> fleet = slr_sql.open()
    >>> receive(fleet, "r1", [("seen", 1, [(1, "pallet7", 10.0, 10.0, 3.0, "r1")])])
    1
    >>> fleet.query("origin(R, seen(P)^T)")
    [{'R': Atom('r1'), 'P': Atom('pallet7'), 'T': 10.0}]
    """
    store = kb.store
    if check:
        check_robot_name(robot)   # (also for a shipment of marks or a contact alone)
        _check_shipment(batches, marks, pending, head_arrival)
        _check_after(after)
        _check_relayed(relayed)
        if resync is not None and not (isinstance(resync, list) and all(
                isinstance(r, (list, tuple)) and len(r) == 2 and isinstance(r[0], str)
                and type(r[1]) is int for r in resync)):
            raise SLRError("a shipment's resync is a list of [name, arity]")
    again = {(r[0], r[1]) for r in resync or ()}
    if store.robot is not None and store.robot == robot:
        # the robot's own store (pushed into itself, or served and pushed to over the
        # service), or another store shipping under this store's name: each event would be
        # stored a second time
        raise ShipmentRefused(f"this fleet store is the store of robot {robot!r} itself: a robot "
                       "does not ship to its own store (name the fleet store otherwise, or "
                       "leave it unnamed)")
    kb.loader.refresh()
    cep = kb.event_rule_engine
    store_events = None
    if cep is not None and cep.active:
        def store_events(events: list) -> list:
            token = cep.before_add(events)
            errors = cep.store_events(events, False)
            cep.after_add(token)
            return errors
    stored = 0
    retired: dict[str, float] = {}

    def take_retired(held: dict[str, float]) -> None:
        retired.update(held)
        if held:
            _refuse_retired(robot, batches, held)
    # the retirements are read first, their lock held shared to the commit: a retirement
    # of a robot of this shipment waits for it, or it for the retirement. With the first
    # batch's position when that is the first read (one statement, no round trip more)
    first = None if after else next((i for i, b in enumerate(batches) if b[2]), None)
    with store.transaction():
        if first is None:
            take_retired(store.fleet_retired(hold="shared"))
        if after:
            held = store.fleet_positions(robot)
            for name, arity, position in after:
                if held.get((name, arity), 0) < position:
                    raise FleetBehind(
                        f"the fleet store holds {name}/{arity} of robot {robot!r} up to seq "
                        f"{held.get((name, arity), 0)}, not {position} as it did: it was "
                        "restored or replaced; shipping again from what it holds")
        for i, batch in enumerate(batches):
            name, arity, rows = batch[:3]
            if rows and type(rows[0]) is not tuple:
                rows = [tuple(r) for r in rows]
            columns = batch[3] if len(batch) > 3 else None   # (from prepare)
            stored += store.fleet_receive(robot, name, arity, rows, store_events, columns,
                                          (name, arity) in again,
                                          take_retired if i == first else None)
        if marks or relayed:
            given = {robot: marks or {}, **{r: m for r, m in (relayed or {}).items()
                                            if r != robot}}
            # (the robot's own marks too, sent with no rows or with rows the route check
            # of the rows did not see: held already, or none)
            _check_mark_routes(store, robot, given)
            for who, its_marks in given.items():
                for mk, t in its_marks.items():
                    store.meta_raise(fleet_mark_key(who, mk), float(t))
            # the robots the fleet knows: those it holds events of (relayed ones included),
            # those that made contact and have a history here or on the way (a robot whose
            # store has marks and no event yet counts from its first mark), and this one --
            # not the store itself, whose own events are complete as far as its own marks
            # say (they raise the same mark)
            robots = _counted_robots(store, retired) | {robot}
            _raise_fleet_marks(store, robots, {mk for its_marks in given.values()
                                               for mk in its_marks})
            _tell_progress_after_commit(kb)
        if pending is not None:
            store.fleet_record_contact(robot, int(pending), head_arrival)
    return stored


def _tell_progress_after_commit(kb: Host) -> None:
    # synchronized queries waiting on this knowledge base (a served fleet store's clients'):
    # the fleet's marks moved under them on its own connection, which its change check does
    # not see, so they waited for their timeout. Told once committed (inside a caller's
    # transaction the store's lock is held, and the synchronizer's lock comes before it).
    # Then the decisions of the fleet store's event rules the marks allow (a recent or
    # chronological rule, a cnot, a where reading the store): no mark was added here, whose
    # pipeline would have made them -- they waited for the next add or clock move. The
    # decisions pending, also those other connections left (shipments of other pushers),
    # are read first: they hold the complex types back, and the queries on those must not
    # be released by the marks alone.
    # What fails here is logged, not raised: the shipment or retirement is committed, and
    # an error would tell its caller (a robot's pusher, which cannot mend the fleet store's
    # listeners or rules) that it failed -- and skip the shipment's record of contact. A
    # decision left unmade is made at the next add, mark or clock move.
    def tell() -> None:
        cep, sync = kb.event_rule_engine, kb.synchronizer
        deciding = cep is not None and cep.active and sync is not None
        try:
            if deciding:
                cep.reread_pending(now=True)
        except Exception as exc:   # (its queries are not released by the marks alone then)
            _told_failed("reading its event rules' pending decisions", exc)
            return
        for listener in kb.progress_listeners:
            try:
                listener()
            except Exception as exc:
                _told_failed("a progress listener", exc)
        if deciding:
            try:
                sync.run_decisions()
            except Exception as exc:
                _told_failed("its event rules' decisions", exc)
    kb.store.after_commit(tell)


def _told_failed(what: str, exc: Exception) -> None:
    """Log (no traceback: a listener's text is the user's) what failed after a fleet
    store's marks moved."""
    log.warning("the fleet store's marks moved (committed), but %s failed (%s: %s)",
                what, type(exc).__name__, exc)


def retire(kb: Host, robot: str) -> dict[str, Any]:
    """Retire ``robot`` from the fleet store ``kb`` (a robot scrapped, renamed, or one that
    only ever made contact): the fleet's own marks stop waiting for it and are computed again
    from the robots it still counts, so they may rise (never fall: marks only grow); its
    events and marks stay (queries with ``robot=`` or ``origin/2`` still see them), and
    ``slr fleet status`` lists it as retired. A later shipment of it, or relaying its rows,
    is refused with :class:`RobotRetired` until :func:`reinstate`. With no robot left to
    count, the fleet's marks stay where they are.

    Returns ``{"robot", "retired_at", "already", "raised"}``: ``retired_at`` in seconds
    since the epoch, ``already`` True when it was retired before (nothing changed),
    ``raised`` the fleet's marks that rose (``{"p/N": t}``). A robot the store does not
    know, its own name, or a store no robot shipped to is an :class:`SLRError`, nothing
    changed.

    >>> import slr_sql
    >>> fleet = slr_sql.open()
    >>> receive(fleet, "r2", [], {"seen/1": 5.0}, pending=0)
    0
    >>> receive(fleet, "r1", [], {"seen/1": 20.0}, pending=0)
    0
    >>> fleet.store.meta_get("sync/mark/seen/1")
    5.0
    >>> retire(fleet, "r2")["raised"], fleet.store.meta_get("sync/mark/seen/1")
    ({'seen/1': 20.0}, 20.0)
    >>> receive(fleet, "r2", [], {"seen/1": 30.0})
    Traceback (most recent call last):
    ...
    slr_sql.shipping.RobotRetired: robot 'r2' was retired from this fleet store ... nothing of the shipment is stored
    """
    store = kb.store
    robot = _known_robot(store, robot, "retired")
    kb.loader.refresh()
    raised: dict[str, float] = {}
    with store.transaction():
        retired = store.fleet_retired(hold="exclusive")
        _refuse_unknown(store, robot, "retired")
        if robot in retired:
            return {"robot": robot, "retired_at": retired[robot], "already": True,
                    "raised": {}}
        at = time.time()
        store.fleet_retire(robot, at)
        retired[robot] = at
        robots = _counted_robots(store, retired)
        marks = {read[1] for read in map(read_fleet_mark_key, store.meta_items(FLEET_MARK))
                 if read is not None}
        before = {mk: store.meta_get(f"sync/mark/{mk}") for mk in marks}
        _raise_fleet_marks(store, robots, marks)
        for mk in sorted(marks):
            now = store.meta_get(f"sync/mark/{mk}")
            if now is not None and now != before[mk]:
                raised[mk] = float(now)
        if raised:
            _tell_progress_after_commit(kb)
    return {"robot": robot, "retired_at": at, "already": False, "raised": raised}


def reinstate(kb: Host, robot: str) -> dict[str, Any]:
    """Take back the retirement of ``robot`` (:func:`retire`) on the fleet store ``kb``: it
    ships again, and the fleet's marks wait for it again -- from where they are: a mark that
    rose while it was retired stays (marks only grow), so its events shipped now below that
    mark come in late for the synchronized queries answered meanwhile. Returns
    ``{"robot", "reinstated"}`` (``reinstated`` False when it was not retired: nothing
    changed). A robot the store does not know, its own name, or a store no robot shipped to
    is an :class:`SLRError`.

    >>> import slr_sql
    >>> fleet = slr_sql.open(); receive(fleet, "r1", [], {"seen/1": 20.0}, pending=0)
    0
    >>> retire(fleet, "r1")["already"], reinstate(fleet, "r1"), reinstate(fleet, "r1")
    (False, {'robot': 'r1', 'reinstated': True}, {'robot': 'r1', 'reinstated': False})
    """
    store = kb.store
    robot = _known_robot(store, robot, "reinstated")
    with store.transaction():
        store.fleet_retired(hold="exclusive")
        _refuse_unknown(store, robot, "reinstated")
        done = store.fleet_reinstate(robot)
    return {"robot": robot, "reinstated": done}


def _known_robot(store: Any, robot: Any, what: str) -> str:
    """``robot``, once it is a robot's name and not the store's own (the checks that need
    no read of the store)."""
    check_robot_name(robot)
    if store.robot is not None and robot == store.robot:
        raise SLRError(f"robot {robot!r} is this fleet store's own name: the fleet's marks "
                       "never wait for the store's own events (its own marks say how far they "
                       f"are complete); nothing {what}")
    return robot


def _refuse_unknown(store: Any, robot: str, what: str) -> None:
    """An SLRError unless ``robot`` is one this fleet store knows: it holds its events, or
    it shipped, made contact or has its rows relayed here (or it was retired)."""
    known = {r["robot"] for r in store.fleet_contacts()} | set(store.robots())
    known.discard(store.robot)
    if not known:
        raise SLRError(f"this store is no fleet store: no robot has shipped to it, so there "
                       f"is no robot {robot!r} to retire or reinstate; nothing {what}")
    if robot not in known:
        names = sorted(known)
        listed = ", ".join(repr(n) for n in names[:10]) + (", ..." if len(names) > 10 else "")
        raise SLRError(f"this fleet store knows no robot {robot!r} (it knows {listed}); "
                       f"nothing {what}")


def _refuse_retired(robot: str, batches: list, retired: dict[str, float]) -> None:
    """Raise :class:`RobotRetired` when ``robot`` is retired, or a row of ``batches`` is of
    a retired robot (relayed)."""
    def when(who: str) -> str:
        return time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime(retired[who]))

    if robot in retired:
        raise RobotRetired(
            f"robot {robot!r} was retired from this fleet store ({when(robot)}, slr fleet "
            "retire): the fleet's marks no longer wait for it, and it ships here no more; "
            f"back in service, it is reinstated with 'slr fleet reinstate FLEET {robot}'; "
            "nothing of the shipment is stored")
    for batch in batches:
        for row in batch[2]:
            who = row[-1]
            if who is not None and who in retired:
                raise RobotRetired(
                    f"robot {who!r} was retired from this fleet store ({when(who)}, slr fleet "
                    f"retire): {robot!r} relaying its rows is refused, the fleet's marks no "
                    "longer wait for them; reinstate it with 'slr fleet reinstate FLEET "
                    f"{who}', or retire it on the relaying store too; nothing of the shipment "
                    "is stored")


def _counted_robots(store: Any, retired: dict[str, float]) -> set[str]:
    """The robots the fleet's marks wait for: those it holds events of (relayed ones
    included), and those that made contact with a history here or on the way -- not the
    store itself (its own events are complete as far as its own marks say, and those raise
    the same marks), nor the robots retired from it."""
    robots = set(store.robots()) | {r["robot"] for r in store.fleet_contacts()
                                    if _holds_marks_back(store, r)}
    robots.discard(store.robot)
    return robots - set(retired)


def _raise_fleet_marks(store: Any, robots: set[str], marks: set[str]) -> None:
    """Raise the fleet's own mark of each of ``marks`` (``p/N``, ``p/*``) to the least of
    the marks of ``robots``, once every one of them has one (none: the marks stay)."""
    if not robots:
        return
    for mk in sorted(marks):
        known = [store.meta_get(fleet_mark_key(r, mk)) for r in robots]
        if all(v is not None for v in known):
            store.meta_raise(f"sync/mark/{mk}", min(float(v) for v in known))


def prepare(kb: Host, robot: str, batch: tuple) -> tuple:
    """``batch`` (``(name, arity, rows)``) of ``robot`` with the rows' values in the
    columns' form of the fleet store ``kb`` as a fourth part, for :func:`receive` of the
    same robot: the work of a batch that needs no connection, done by a pusher in its
    reading thread while the batch before is stored.

    >>> import slr_sql
    >>> prepare(slr_sql.open(), "r1", ("seen", 1, [(1, "pallet7", 10.0, 10.0, 3.0, None)]))[3]
    [('pallet7', 10.0, 10.0, 'r1')]
    """
    name, arity, rows = batch
    return name, arity, rows, kb.store.fleet_column_values(arity, rows, robot)


def _check_shipment(batches: Any, marks: Any, pending: Any = None,
                    head_arrival: Any = None) -> None:
    """A shipment from the network is checked before anything is stored: its rows go into
    the columns as they come, so a row must be one a store could have written -- every
    argument text a stored term (a text that starts as JSON and does not read as JSON would
    make every later query over the type fail), every robot a robot's name -- and the marks
    must name event types."""
    if not isinstance(batches, list):
        raise SLRError("a shipment's batches are a list of [name, arity, rows]")
    robots: set = set()    # the robot names checked already
    # per type, the last sequence of the batches before: a type's rows in two batches of
    # one shipment ascend across them too (rows below the position the first batch moved
    # to would be taken as held, and skipped)
    lasts: dict[tuple[str, int], int] = {}
    for batch in batches:
        if not (isinstance(batch, (list, tuple)) and len(batch) == 3
                and isinstance(batch[0], str) and type(batch[1]) is int and batch[1] >= 0
                and isinstance(batch[2], list)):
            raise SLRError("a shipment's batch is [name, arity, rows]")
        name, arity, rows = batch
        last = lasts.get((name, arity), 0)
        for row in rows:
            if not (isinstance(row, (list, tuple)) and len(row) == arity + 5
                    and type(row[0]) is int and row[0] > last
                    and all(type(v) in (int, float, str) or v is None for v in row)
                    and all(type(v) in (int, float) for v in row[arity + 1:arity + 3])
                    and (row[arity + 3] is None or type(row[arity + 3]) in (int, float))):
                raise SLRError(f"a shipped row of {name}/{arity} is [seq, arg1..arg{arity}, "
                               "start, end, arrival or null, robot or null] with sequences "
                               "ascending")
            if not all(INT64_MIN <= v <= INT64_MAX for v in row if type(v) is int):
                # (no store holds one: its columns' integers stop there, as PostgreSQL's)
                raise SLRError(f"a shipped row of {name}/{arity}, seq {shown(row[0])}: an "
                               "integer beyond 64 bits, which no store holds")
            if not all(math.isfinite(v) for v in row[arity + 1:arity + 4] if v is not None):
                raise SLRError(f"a shipped row of {name}/{arity} has a time that is not finite")
            if row[arity + 1] > row[arity + 2]:
                raise SLRError(f"a shipped row of {name}/{arity}, seq {row[0]}: the event "
                               f"starts after it ends ({row[arity + 1]!r} > {row[arity + 2]!r})")
            for i in range(1, arity + 1):
                value = row[i]
                if type(value) is str and not (value.isascii() and value[:1] not in _JSON):
                    problem = _stored_term_problem(value)
                    if problem is not None:
                        raise SLRError(f"a shipped row of {name}/{arity}, seq {row[0]}: "
                                       f"argument {i} is not a stored term ({problem})")
            who = row[-1]
            if who is not None and who not in robots:
                try:
                    robots.add(check_robot_name(who))
                except SLRError as exc:
                    raise SLRError(f"a shipped row of {name}/{arity}, seq {row[0]}: its robot "
                                   f"column: {exc}") from None
            last = row[0]
        lasts[(name, arity)] = last
    if marks is not None:
        if not isinstance(marks, dict) or not all(
                isinstance(k, str) and names_a_type(k) and type(v) in (int, float)
                and not math.isnan(v) for k, v in marks.items()):
            raise SLRError("a shipment's marks are {\"name/arity\": time} (name/* for every "
                           "arity)")
    if pending is not None and (type(pending) is not int or not 0 <= pending <= INT64_MAX):
        raise SLRError(f"a shipment's pending is a count of events (>= 0, 64 bits), not "
                       f"{shown(pending)}")
    if head_arrival is not None and not (
            type(head_arrival) is float and math.isfinite(head_arrival)
            or type(head_arrival) is int and INT64_MIN <= head_arrival <= INT64_MAX):
        raise SLRError(f"a shipment's head_arrival is a finite time, not {shown(head_arrival)}")


def _check_relayed(relayed: Any) -> None:
    """``{robot: {"p/N": t}}``: every key a robot's name, every mark one of an event type."""
    if relayed is None:
        return
    if not isinstance(relayed, dict) or not all(
            isinstance(m, dict) and all(isinstance(k, str) and names_a_type(k)
                                        and type(v) in (int, float) and not math.isnan(v)
                                        for k, v in m.items())
            for m in relayed.values()):
        raise SLRError("a shipment's relayed marks are {robot: {\"name/arity\": time}} "
                       "(name/* for every arity)")
    for who in relayed:
        try:
            check_robot_name(who)
        except SLRError as exc:
            raise SLRError(f"a shipment's relayed marks: {exc}") from None


def _holds_marks_back(store: Any, contact: dict) -> bool:
    """Whether a robot of ``slr fleet status`` (``contact``, a row of ``fleet_contacts``) is
    one the fleet's marks wait for: one whose rows this store holds (relayed, or shipped
    by itself), one whose pusher said at its last contact that events wait on it, one with
    a mark kept here. A contact alone (pending 0, no rows, no marks: a robot whose store
    holds nothing yet, or anyone using a new name with the fleet's token) is not: there is
    no history of it to wait for, and waiting for its mark would hold every synchronized
    query on the fleet back until that name shipped one.

    >>> import slr_sql; fleet = slr_sql.open()
    >>> _holds_marks_back(fleet.store, {"robot": "r9", "shipped": 0, "pending": 0, "via": None})
    False
    >>> _holds_marks_back(fleet.store, {"robot": "r9", "shipped": 0, "pending": 2, "via": None})
    True
    """
    if contact["via"] is not None or contact["shipped"] or contact["pending"]:
        return True
    prefix = fleet_mark_key(contact["robot"], "")
    return any(names_a_type(key[len(prefix):]) for key in store.meta_items(prefix))


def _check_mark_routes(store: Any, robot: str, given: dict) -> None:
    """Refuse marks that ``robot`` sends of a robot whose rows reach this store by another
    route: marks it relays of a robot shipping here directly or relayed by another store,
    and its own marks when its rows come relayed by a store (sent by the robot itself, or
    by anyone in its name): those marks are the route's to give, and one raised here would
    move the fleet's mark past events still on their way. (Marks of a robot this store
    does not know yet go in: a robot may have marks and no events.)"""
    from .store.fleet import RouteConflict

    routes = {r["robot"]: r["via"] or r["robot"] for r in store.fleet_contacts()}
    for who in given:
        via = routes.get(who)
        if via is None or via == robot:
            continue
        if who == robot:
            raise RouteConflict(f"the marks of robot {who!r} cannot come from it directly: "
                                f"its rows reach this store relayed by {via!r}, so its marks "
                                "come that way too")
        how = "directly" if via == who else f"relayed by {via!r}"
        raise RouteConflict(f"the marks of robot {who!r} cannot come from {robot!r}: its "
                            f"rows reach this store {how}, so its marks come that way too")


def _check_after(after: Any) -> None:
    if after is not None and not (isinstance(after, list) and all(
            isinstance(a, (list, tuple)) and len(a) == 3 and isinstance(a[0], str)
            and type(a[1]) is int and a[1] >= 0 and type(a[2]) is int and a[2] >= 0
            for a in after)):
        raise SLRError("a shipment's after is a list of [name, arity, position]")


def _stored_term_problem(value: Any) -> str | None:
    """Why ``value`` (a shipped argument column) is not a term's stored form, or None.
    Numbers and atom texts always are; a text that starts with ``[``, ``{`` or ``"`` must read
    as the JSON of a term.

    >>> _stored_term_problem('["a",1]'), _stored_term_problem("cup1")
    (None, None)
    >>> _stored_term_problem("[1,")
    'it starts as JSON but does not read as a term'
    """
    if type(value) is not str:
        return None
    problem = text_problem(value)
    if problem is not None:
        return problem
    if value[:1] in _JSON:
        try:
            decode(value)
        except Exception:  # noqa: BLE001 - whatever the reader met, the text is no term
            return "it starts as JSON but does not read as a term"
    return None
