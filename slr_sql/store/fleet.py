"""Robots and fleets in one store: the store's robot name, the robots it holds events of,
reading a robot's events for shipping and storing a shipped batch exactly once.

A robot store names itself (``slr_meta`` key ``robot``); its event rows carry that name in
their ``robot`` column. A fleet store receives batches: the rows of one event type from one
robot with their sequence numbers in the robot's store. :meth:`Fleet.receive` stores the
rows after the robot's recorded position for that type and moves the position, in one
transaction: a batch sent twice (a pusher killed after the fleet committed) is stored once,
and a batch the fleet never committed is sent again.
"""
from __future__ import annotations

import math
import time
import unicodedata
from typing import Any

from ..encoding import encode
from ..errors import SLRBusy, SLRError
from ..terms import Atom
from .checks import BadEvent, shown, text_problem
from .dialect import POSTGRES
from .connection import Database
from .sqltext import joined_balanced
from .events import EventWriter
from .tables import EventTables

__all__ = ["Fleet", "ROBOT_NAME_MAX", "RouteConflict", "ShipmentConflict", "WriterInFlight",
           "check_robot_name"]

# Unicode categories a robot's name may not hold: characters that are not drawn but change
# how the text around them is drawn (direction overrides and isolates, the marks U+200E/F,
# zero-width joiners and spaces, soft hyphens) or where lines break
_UNSEEN = {"Cc": "a control character", "Cf": "a format character",
           "Zl": "a line separator", "Zp": "a paragraph separator"}
# characters of a robot's name at most: a name is a key of rows, marks, routes and positions
# and is shown in tables and logs (a 500,000-character name was stored, and a PostgreSQL
# index refuses a key of more than about 2,700 bytes); 255 characters of any script stay
# within that (at most 4 bytes each)
ROBOT_NAME_MAX = 255

# (an upsert both engines take)
_ADD_ROBOT = "INSERT INTO slr_robots (name) VALUES (?) ON CONFLICT (name) DO NOTHING"
# a robot's route: the row is taken (locked on a server until the commit, so two shipments
# bringing one robot's rows by two routes at once cannot both pass) and its via returned
_ADD_ROUTE = ("INSERT INTO slr_fleet_routes (robot, via, shipped) VALUES (?, ?, ?) "
              "ON CONFLICT (robot) DO UPDATE SET shipped = slr_fleet_routes.shipped + "
              "excluded.shipped")
_TAKE_ROUTE = _ADD_ROUTE + " RETURNING via"
# the advisory lock of the retirements on a server (b"slr_reti": apart from the others'
# keys): a shipment holds it shared from its start, a retirement exclusively, so that a
# shipment that read no retirement of its robot commits before a retirement of it reads
# the marks, and one after it reads the retirement (on SQLite one writer at a time does it)
_RETIRE_LOCK = int.from_bytes(b"slr_reti", "big")


def check_robot_name(name: Any) -> str:
    """``name`` if it can name a robot (a non-empty text of at most :data:`ROBOT_NAME_MAX`
    characters, not only white space, without control, format or line-separating
    characters), else an :class:`SLRError` saying why -- the one check of every way a robot's
    name comes in (naming a store, a push, a shipment, a query).

    >>> check_robot_name("r1")
    'r1'
    >>> check_robot_name("r1\u202eevil")
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: robot name 'r1\u202eevil' has U+202E RIGHT-TO-LEFT OVERRIDE at position 3 (a format character: it would change how the name and what follows it read in logs, tables and plots); name robots with plain words (r1, forklift-2, ...)
    >>> check_robot_name(" ")
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: robot name ' ' is only white space; name robots with plain words (r1, forklift-2, ...)
    """
    if not isinstance(name, str) or not name:
        raise SLRError(f"a robot's name is a non-empty text, not {shown(name)}")
    if len(name) > ROBOT_NAME_MAX:   # (first: the checks below read every character)
        raise SLRError(f"robot name {shown(name)} is longer than {ROBOT_NAME_MAX} characters; "
                       "name robots with plain words (r1, forklift-2, ...)")
    # (the name quoted cut short: a 100 KB name refused must not make a 100 KB message)
    problem = text_problem(name)
    if problem:
        raise SLRError(f"robot name {shown(name)} cannot be stored: {problem}")
    for position, char in enumerate(name, 1):
        kind = _UNSEEN.get(unicodedata.category(char))
        if kind is not None:
            label = unicodedata.name(char, "")
            raise SLRError(
                f"robot name {shown(name)} has U+{ord(char):04X}{' ' + label if label else ''} at "
                f"position {position} ({kind}: it would change how the name and what follows "
                "it read in logs, tables and plots); name robots with plain words (r1, "
                "forklift-2, ...)")
    if not name.strip():
        # shown in a table or log as nothing at all, and a name nobody could tell or type
        raise SLRError(f"robot name {shown(name)} is only white space; name robots with plain "
                       "words (r1, forklift-2, ...)")
    if encode(Atom(name)) != name:  # the column holds the atom's stored form: the name itself
        raise SLRError(f"robot name {shown(name)} reads as a compound term or string when stored; "
                       "name robots with plain words (r1, forklift-2, ...)")
    if POSTGRES.to_column(name) != name:
        # a name that reads as a number is stored tagged on PostgreSQL (docs/postgres.md), so
        # a robot column could not hold it as itself there: refused on every backend, so that
        # any store may ship to any fleet
        raise SLRError(f"robot name {shown(name)} reads as a number when stored; name robots with "
                       "plain words (r1, forklift-2, ...)")
    return name


class WriterInFlight(SLRBusy):
    """A read for shipping waited longer than the store's busy timeout for a transaction
    that holds a writer's lock on the table (its sequences may lie below the rows read):
    the robot's own store is busy, not the fleet. Retrying later is safe.

    >>> issubclass(WriterInFlight, SLRBusy)
    True
    """


class RouteConflict(SLRError):
    """A shipment brings rows of a robot whose rows reach the fleet store through another
    shipping robot already (a robot pushing both to the fleet store and to a site store that
    relays to it; two site stores relaying one robot): the fleet store keeps its positions
    per shipping robot, so it would store each row twice. Nothing of the shipment is stored.

    >>> issubclass(RouteConflict, SLRError)
    True
    """


class ShipmentConflict(SLRError):
    """A shipment sends again a sequence of a robot that the fleet store holds already
    (at or below its position for the type), with content the fleet store holds no row of
    the robot with: two stores ship as one robot, or the robot's store was replaced. Its
    rows would be skipped as held and lost without a word; nothing of the shipment is
    stored. Rows sent again as they are held are skipped (stored once).

    >>> issubclass(ShipmentConflict, SLRError)
    True
    """


class Fleet:
    """The robot name of a store and the shipping tables (``slr_robots``,
    ``slr_fleet_positions``, ``slr_fleet_robots``, migration 0006; ``slr_fleet_routes``,
    migration 0010; ``slr_fleet_retired``, migration 0015).

    >>> from slr_sql.store import EventStore
    >>> s = EventStore(None, robot="r1"); s.robot, s.robots()
    ('r1', ['r1'])
    """

    def __init__(self, db: Database, tables: EventTables, writer: EventWriter):
        self.db = db
        self.tables = tables
        self.writer = writer
        rows = db.execute("SELECT value FROM slr_meta WHERE key = 'robot'")
        self.robot: str | None = _json_text(rows[0][0]) if rows else None
        writer.robot = self.robot
        # routes this store committed (robot -> via): a route is never changed nor dropped,
        # so a batch of a robot along its known route needs no answer about it
        self._routes: dict[str, str] = {}

    def name(self, robot: str) -> None:
        """Name the store's robot (kept in the store). A store has one name for life:
        naming it again with another name is an error; events stored before it was named
        keep robot NULL."""
        robot = check_robot_name(robot)
        if self.robot == robot:
            return
        if self.robot is not None:
            raise SLRError(f"{self.db.path or ':memory:'} is the store of robot "
                           f"{self.robot!r}, not {robot!r}")
        import json
        with self.db.transaction():
            rows = self.db.execute("SELECT value FROM slr_meta WHERE key = 'robot'")
            if rows and _json_text(rows[0][0]) != robot:  # another process named it
                raise SLRError(f"{self.db.path or ':memory:'} is the store of robot "
                               f"{_json_text(rows[0][0])!r}, not {robot!r}")
            self.db.execute("INSERT INTO slr_meta (key, value) VALUES ('robot', ?) "
                            f"ON CONFLICT ({self.db.dialect.key('key')}) "
                            "DO UPDATE SET value = excluded.value",
                            (json.dumps(robot),))
            self.db.execute(_ADD_ROBOT, (robot,))
        self.robot = robot
        self.writer.robot = robot

    def robots(self) -> list[str]:
        """The robots whose events the store holds (its own name, and every robot that
        shipped to it), in name order."""
        return [r[0] for r in self.db.execute("SELECT name FROM slr_robots ORDER BY name")]

    # ------------------------------------------------------------------ the robot's side

    def heads(self) -> dict[tuple[str, int], int]:
        """Per event type, the greatest sequence stored (0 for an empty table)."""
        with self.db.lock:
            self.db.check_open()
            self.tables.reload()
            out = {}
            for key, event_type in self.tables.types.items():
                out[key] = self.db.execute(
                    f"SELECT max(seq) FROM {event_type.quoted}")[0][0] or 0
            return out

    def counters(self) -> dict[tuple[str, int], int]:
        """Per event type, the last sequence the store handed out (0: none yet): its
        AUTOINCREMENT counter (``sqlite_sequence``) or identity sequence, which a buffer
        that empties the table does not lower and a restore from an older backup does."""
        with self.db.lock:
            self.db.check_open()
            self.tables.reload()
            execute = self.db.execute
            if self.db.dialect.name == "sqlite":
                found = dict(execute("SELECT name, seq FROM sqlite_sequence"))
                return {key: int(found.get(t.table) or 0) for key, t in self.tables.types.items()}
            out = {}
            for key, event_type in self.tables.types.items():
                [(last,)] = execute("SELECT pg_sequence_last_value(pg_get_serial_sequence("
                                    "?, 'seq'))", (event_type.quoted,))
                out[key] = int(last or 0)
            return out

    def read_after(self, name: str, arity: int, position: int, limit: int) -> list[tuple]:
        """Up to ``limit`` stored rows of name/arity with ``seq > position`` in sequence
        order, as ``(seq, *encoded arguments, start, end, arrival, robot)`` (arrival None when
        it is not a finite time). On a server, the read waits for the writers of the table
        that are in flight (sequences are handed out at the insert, not at the commit), so
        that a later read from the last seq returned misses nothing."""
        with self.db.lock:
            self.db.check_open()
            event_type = self.tables.lookup(name, arity)
            if event_type is None:
                return []
            args = "".join(f"arg{i}, " for i in range(1, arity + 1))
            dialect = self.db.dialect
            select = (f"SELECT seq, {args}t_start, t_end, arrival, robot FROM "
                      f"{event_type.quoted} WHERE seq > ? ORDER BY seq LIMIT ?")
            rows = self.db.execute(select, (position, limit))
            in_flight = dialect.writers_in_flight()
            if rows and in_flight is not None:
                # the fleet's position becomes the last seq shipped, so no lower seq may
                # still be in flight: a writer that inserts after the read above draws a
                # higher seq than every row it saw, and one in flight then holds its lock
                # now. Once those are done, the same range read again is final.
                self._wait_for(in_flight, event_type.quoted)
                rows = self.db.execute(
                    select.replace("WHERE seq > ?", "WHERE seq > ? AND seq <= ?"),
                    (position, rows[-1][0], limit))
            if dialect.name != "sqlite" and arity:  # shipped as SQLite stores them
                from_column: Any = dialect.from_column
                rows = [(r[0], *map(from_column, r[1:1 + arity]), *r[1 + arity:]) for r in rows]
            at = 3 + arity
            arrivals = [r[at] for r in rows]   # REAL NOT NULL: the extremes tell
            if rows and not (_finite(min(arrivals)) and _finite(max(arrivals))):
                # a StreamClock's arrival before its first event is -inf: not sent (JSON)
                rows = [r[:at] + (r[at] if _finite(r[at]) else None, r[-1]) for r in rows]
            return rows

    def _wait_for(self, in_flight: str, table: str) -> None:
        """Until the transactions that hold a writer's lock on ``table`` now are done (the
        server has no statement that waits for another transaction without also blocking
        later writers); SLRBusy past the store's busy timeout."""
        execute = self.db.execute
        holders = {r[0] for r in execute(in_flight, (table,))}
        timeout = getattr(self.db, "busy_timeout", 5.0)
        deadline = time.monotonic() + timeout
        pause = 0.0005
        while holders:
            if time.monotonic() > deadline:
                raise WriterInFlight(f"{self.db.path}: a writer of {table} stayed in flight for more "
                              f"than {timeout:g} s; the rows after it are shipped later")
            time.sleep(pause)
            pause = min(pause * 2, 0.02)
            holders &= {r[0] for r in execute(in_flight, (table,))}

    def backlog(self, name: str, arity: int, position: int) -> tuple[int, float | None]:
        """The number of rows of name/arity after ``position`` and the arrival time of the
        latest row (None for an empty table): what is left to ship, and how recent."""
        with self.db.lock:
            self.db.check_open()
            event_type = self.tables.lookup(name, arity)
            if event_type is None:
                return 0, None
            left = self.db.execute(f"SELECT count(*) FROM {event_type.quoted} "
                                   "WHERE seq > ?", (position,))[0][0]
            latest = self.db.execute(f"SELECT arrival FROM {event_type.quoted} "
                                     "ORDER BY seq DESC LIMIT 1")
            return left, latest[0][0] if latest and _finite(latest[0][0]) else None

    # ------------------------------------------------------------------ the fleet's side

    def positions(self, robot: str) -> dict[tuple[str, int], int]:
        """What the fleet store holds of ``robot``: per event type, the last sequence (in the
        robot's store) stored."""
        return {(n, a): p for n, a, p in self.db.execute(
            "SELECT type_name, type_arity, position FROM slr_fleet_positions "
            "WHERE robot = ?", (robot,))}

    def column_values(self, arity: int, rows: list[tuple], robot: str) -> list[tuple]:
        """Per row of a batch of an arity-``arity`` type that ``robot`` ships (rows as
        :meth:`read_after` gives them): its arguments as this store's columns hold them,
        its start, its end and its robot (``robot`` when it has none) -- the columns
        :meth:`receive` writes but the arrival. The part of its work that needs no
        connection, which a pusher does in the thread that reads its next batch while the
        one before is stored.

        >>> from slr_sql.store import EventStore
        >>> EventStore(None).fleet_column_values(1, [(7, "pallet7", 1.0, 2.0, 3.0, None)], "r1")
        [('pallet7', 1.0, 2.0, 'r1')]
        """
        to_column: Any = self.db.dialect.to_column
        # column by column: one map per argument instead of a tuple unpacked per row
        columns: list[Any] = [[r[i] for r in rows] for i in range(1, 1 + arity)]
        if to_column is not None:   # rows come as SQLite stores them
            columns = [list(map(to_column, column)) for column in columns]
        columns.append([r[1 + arity] for r in rows])
        columns.append([r[2 + arity] for r in rows])
        columns.append([r[-1] or robot for r in rows])   # (a robot's name is never empty)
        return list(zip(*columns))

    def receive(self, robot: str, name: str, arity: int, rows: list[tuple],
                store_events: Any = None, columns: list[tuple] | None = None,
                resync: bool = False, take_retired: Any = None) -> int:
        """Store a shipped batch of ``robot`` (rows as :meth:`read_after` gives them, one
        type, in sequence order) exactly once: the rows after the robot's position for the
        type go in and the position moves to the last row's sequence, in one transaction
        (which the caller may have opened). ``store_events(events)``, when given, stores
        decoded ``(name, args, start, end)`` events instead of the raw rows (the path that
        runs the fleet's event rules); the rows keep the robot they were stored with
        (``robot`` when NULL). ``columns``: the rows' :meth:`column_values`, when the
        caller has them already. ``resync``: the batch is part of the type shipped again
        from its first row (the robot's store was restored from an older backup, so its
        sequences no longer match what this store holds): a row is stored unless this store
        holds an identical one of the robot (same arguments, start, end and robot), and
        the position becomes the batch's last sequence, lower than before as it may be
        (0 for a resync batch without rows: the robot holds none of the type).
        ``take_retired``: called with :meth:`retired` (its lock held shared) before anything
        is stored, read with the robot's position in one statement (the first batch of a
        shipment: the retirements are read without a round trip of their own).
        Returns the number of rows stored."""
        robot = check_robot_name(robot)
        if not rows:
            if resync:   # the robot holds no row of the type: the fleet holds none after 0
                with self.db.transaction():
                    self._set_position(robot, name, arity, 0)
            return 0
        with self.db.transaction():
            conn = self.db.conn   # (a server's connection: its own statements, below)
            held = "SELECT position FROM slr_fleet_positions WHERE robot = ? AND type_name = ? " \
                "AND type_arity = ?"
            if take_retired is None:
                held_at = self.db.execute(held, (robot, name, arity))
            else:
                self._hold_retirements("shared")
                both = self.db.execute("SELECT robot, retired_at, NULL FROM slr_fleet_retired "
                                       f"UNION ALL SELECT NULL, NULL, position FROM ({held}) AS p",
                                       (robot, name, arity))
                held_at = [(r[2],) for r in both if r[0] is None]
                take_retired({r[0]: float(r[1]) for r in both if r[0] is not None})
            position = held_at[0][0] if held_at else 0
            # (sequences ascend: what the fleet holds already is a head of the batch)
            if resync:
                position = rows[0][0] - 1
                held = self._held_identically(name, arity, robot, rows)
                fresh = [r for r, h in zip(rows, held) if not h]
                columns = None
                if not fresh:
                    self._set_position(robot, name, arity, rows[-1][0])
                    return 0
            elif rows[0][0] > position:
                fresh = rows
            else:
                fresh = [r for r in rows if r[0] > position]
                # rows sent again must be held as they are sent: else another store ships
                # as this robot (or its store was replaced) and they would be lost unsaid
                self._refuse_other_content(robot, name, arity, position,
                                           rows[:len(rows) - len(fresh)])
            if not fresh:
                return 0
            along = self._take_routes(robot, fresh)
            others = {r[-1] for r in fresh if r[-1] is not None and r[-1] != robot}
            dialect = self.db.dialect
            server = dialect.to_column is not None
            if store_events is not None:
                for who in (robot, *others):
                    self.db.execute(_ADD_ROBOT, (who,))
                self._store_decoded(robot, name, arity, fresh, store_events)
            else:
                # as an add: the fleet store's clock is the rows' arrival (and its "now"
                # for the buffer triggers); on a server, as an add there, only while a
                # tBuffer may be active (the change check of this receive just read whether
                # one is): the clock's one row, locked until the commit, would otherwise
                # make the pushers of every robot wait for each other
                arrival = float(self.db.clock.now())
                if not server or self.db.tbuffers_active is not False:
                    self.writer.record_now(arrival)
                try:
                    event_type = self.writer.type_for_new_event(name, arity)
                except BadEvent as exc:
                    raise SLRError(f"the fleet store refused {name}/{arity} of robot "
                                   f"{robot!r}: {exc}") from None
                if columns is None or len(columns) != len(rows):
                    columns = self.column_values(arity, fresh, robot)
                elif len(fresh) < len(rows):
                    columns = columns[len(rows) - len(fresh):]
                # (the arrival last: one tuple joined per row)
                arrival_column = (arrival,)
                values = [v + arrival_column for v in columns]
                insert = _shipped_insert(event_type.quoted, arity)
                if server:
                    # arguments and robot are text, the times numbers: many rows go in
                    # binary form
                    conn.executemany(insert, values, ("text",) * arity + ("float8",) * 2
                                     + ("text", "float8"))
                else:
                    self.db.executemany(insert, values)
            # the arrival column sits after the arguments and the two times
            latest = max((r[3 + arity] for r in fresh if r[3 + arity] is not None),
                         default=None)
            # statements nobody reads an answer of: on a server they go with the
            # transaction's next statement or its COMMIT (one round trip, not one each)
            unanswered = conn.execute_unanswered if server else self.db.execute
            for params in along:
                unanswered(_ADD_ROUTE, params)
            if store_events is None:
                for who in (robot, *others):
                    unanswered(_ADD_ROBOT, (who,))
            unanswered("INSERT INTO slr_fleet_robots (robot, shipped, last_arrival) VALUES "
                       "(?, ?, ?) ON CONFLICT (robot) DO UPDATE SET shipped = "
                       "slr_fleet_robots.shipped + excluded.shipped, last_arrival = CASE WHEN "
                       "slr_fleet_robots.last_arrival IS NULL OR excluded.last_arrival > "
                       "slr_fleet_robots.last_arrival THEN excluded.last_arrival ELSE "
                       "slr_fleet_robots.last_arrival END", (robot, len(fresh), latest))
            unanswered(_position_upsert(self.db.dialect),
                       (robot, name, arity, rows[-1][0] if resync else fresh[-1][0]))
            return len(fresh)

    def _take_routes(self, robot: str, rows: list[tuple]) -> list[tuple]:
        """Note that the rows of each robot of ``rows`` come through ``robot`` (the robot
        itself, or a store relaying them), or raise :class:`RouteConflict` when a robot's
        rows come through another one already (inside the receiving transaction). Returns
        the parameters of :data:`_ADD_ROUTE` for the robots whose route this store
        committed before (no answer needed: the caller sends them with its last
        statements)."""
        counts: dict[str, int] = {}
        for r in rows:
            who = r[-1] or robot
            counts[who] = counts.get(who, 0) + 1
        execute = self.db.execute
        taken = []
        along = []
        for who in sorted(counts):   # (one order: two shipments never wait on each other)
            if self._routes.get(who) == robot:
                along.append((who, robot, counts[who]))
                continue
            twice = ("would store each of them twice (a fleet store keeps its positions per "
                     f"shipping robot): push {who} to one of the two stores only")
            if who == self.robot:   # (its own rows, shipped back: a cycle)
                raise RouteConflict(f"the rows of robot {who!r} are this store's own; "
                                    f"{robot!r} relaying them back would store each of them "
                                    "twice: a store's rows must not come back to it through "
                                    "the stores it pushes to")
            held = execute(_TAKE_ROUTE, (who, robot, counts[who]))[0][0]
            if held == robot:
                taken.append(who)
                continue
            if held == who:
                raise RouteConflict(f"robot {who!r} ships to this store directly; {robot!r} "
                                    f"relaying its rows too {twice}")
            raise RouteConflict(
                f"the rows of robot {who!r} reach this store relayed by {held!r}; "
                + (f"{who} shipping them here directly too " if robot == who
                   else f"{robot!r} relaying them too ") + twice)
        if taken:
            routes = self._routes
            self.db.after_commit(lambda: routes.update(dict.fromkeys(taken, robot)))
        return along

    def _refuse_other_content(self, robot: str, name: str, arity: int, position: int,
                              rows: list[tuple]) -> None:
        """Raise :class:`ShipmentConflict` unless this store holds each of ``rows`` (rows
        of ``robot`` at or below its ``position`` for name/arity, sent again) identically.
        This store keeps no robot's sequence per row: a row is compared with every row of
        its robot (same arguments, start and end)."""
        for values, held in zip(rows, self._held_identically(name, arity, robot, rows)):
            if not held:
                raise ShipmentConflict(
                    f"robot {robot!r} shipped {name}/{arity} seq {values[0]} again (this store "
                    f"holds {name}/{arity} of {robot!r} up to seq {position}) with other "
                    f"content: it holds no event {shown(_shipped_event(name, arity, values))} "
                    f"of robot {values[-1] or robot!r}; two stores ship as {robot!r}, or its "
                    "store was replaced (after a restore from a backup, push with --resync); "
                    "nothing of the shipment is stored")

    def _set_position(self, robot: str, name: str, arity: int, position: int) -> None:
        self.db.execute(_position_upsert(self.db.dialect), (robot, name, arity, position))

    def _held_identically(self, name: str, arity: int, robot: str,
                          rows: list[tuple]) -> list[bool]:
        """Per shipped row of ``robot``: whether this store holds a row of name/arity with
        the same arguments, start, end and robot (a resync's rows shipped before)."""
        event_type = self.tables.lookup(name, arity)
        if event_type is None:
            return [False] * len(rows)
        # an argument is the same value of the same type (1 is not 1.0): SQLite's columns
        # keep the type given and compare numbers by value; a server's spell the type
        typed = self.db.dialect.to_column is None
        args = [f"arg{i} = ? AND typeof(arg{i}) = typeof(?)" if typed else f"arg{i} = ?"
                for i in range(1, arity + 1)]
        select = (f"SELECT 1 FROM {event_type.quoted} WHERE "
                  + joined_balanced(args + ["t_start = ?", "t_end = ?", "robot = ?"], "AND")
                  + " LIMIT 1")
        execute = self.db.execute
        return [bool(execute(select, [v for value in values[:arity]
                                      for v in ((value, value) if typed else (value,))]
                             + list(values[arity:])))
                for values in self.column_values(arity, rows, robot)]

    def _store_decoded(self, robot: str, name: str, arity: int, rows: list[tuple],
                       store_events: Any) -> None:
        from ..encoding import decode
        saved = self.writer.robot
        try:
            # runs of one robot (a robot store may hold rows it received from others)
            start = 0
            while start < len(rows):
                who = rows[start][-1] if rows[start][-1] is not None else robot
                end = start
                while end < len(rows) and (rows[end][-1] if rows[end][-1] is not None
                                           else robot) == who:
                    end += 1
                self.writer.robot = who
                events = [(name, tuple(decode(v) for v in r[1:1 + arity]),
                           float(r[1 + arity]), float(r[2 + arity])) for r in rows[start:end]]
                errors = store_events(events)
                if errors:
                    raise SLRError(f"the fleet store refused a shipped event of robot "
                                   f"{robot!r}: {errors[0]}")
                start = end
        finally:
            self.writer.robot = saved

    def record_contact(self, robot: str, pending: int, head_arrival: float | None) -> None:
        """Note what ``robot``'s pusher reported at a contact (for ``slr fleet status``):
        the events its store holds that are not shipped yet and the arrival of its latest."""
        with self.db.transaction():
            self.db.execute(
                "INSERT INTO slr_fleet_robots (robot, pending, head_arrival, contact_at) "
                "VALUES (?, ?, ?, ?) ON CONFLICT (robot) DO UPDATE SET pending = "
                "excluded.pending, head_arrival = coalesce(excluded.head_arrival, "
                "slr_fleet_robots.head_arrival), contact_at = excluded.contact_at",
                (robot, pending, head_arrival, time.time()))

    def retired(self, hold: str | None = None) -> dict[str, float]:
        """The robots retired from this fleet store (``slr fleet retire``), each with the
        time of its retirement (seconds since the epoch). ``hold``, inside a transaction:
        ``"shared"`` (a shipment) or ``"exclusive"`` (a retirement or reinstatement) takes
        the retirements' lock on a server first, until the transaction ends.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.fleet_retire("r1", 100.0), s.fleet_retired()
        (True, {'r1': 100.0})
        """
        if hold is not None:
            self._hold_retirements(hold)
        return {robot: float(at) for robot, at in self.db.execute(
            "SELECT robot, retired_at FROM slr_fleet_retired")}

    def _hold_retirements(self, hold: str) -> None:
        """On a server, the retirements' lock (``"shared"`` or ``"exclusive"``) until the
        transaction ends, taken before the next statement."""
        if self.db.dialect.name != "sqlite":
            # (sent with the next statement, in its round trip -- with the transaction's
            # BEGIN when it is still pending: a statement of its own before it, so that
            # statement's snapshot is taken once the lock is held)
            self.db.conn.lock_later(_RETIRE_LOCK, shared=hold == "shared")

    def retire(self, robot: str, at: float) -> bool:
        """Note ``robot`` retired at ``at`` (seconds since the epoch); False when it was
        retired already (its first time kept)."""
        with self.db.transaction():
            return bool(self.db.execute(
                "INSERT INTO slr_fleet_retired (robot, retired_at) VALUES (?, ?) "
                "ON CONFLICT (robot) DO NOTHING RETURNING 1", (robot, float(at))))

    def reinstate(self, robot: str) -> bool:
        """Forget the retirement of ``robot``; False when it was not retired."""
        with self.db.transaction():
            return bool(self.db.execute(
                "DELETE FROM slr_fleet_retired WHERE robot = ? RETURNING 1", (robot,)))

    def contacts(self) -> list[dict[str, Any]]:
        """Per robot that shipped: its ``slr_fleet_robots`` row as a dict, and per robot whose
        rows another store relays here (``slr_fleet_routes``): the rows stored of it, no
        contact; ``via`` is the relaying store's robot (None for a robot shipping here
        itself); ``retired_at`` the time it was retired (``slr fleet retire``), else None;
        in name order."""
        with self.db.lock:
            self.db.check_open()
            cols = ["robot", "shipped", "last_arrival", "pending", "head_arrival", "contact_at"]
            rows = {r[0]: {**dict(zip(cols, r)), "via": None} for r in self.db.execute(
                f"SELECT {', '.join(cols)} FROM slr_fleet_robots ORDER BY robot")}
            for who, via, shipped in self.db.execute(
                    "SELECT robot, via, shipped FROM slr_fleet_routes WHERE via <> robot"):
                known = rows.get(who)
                if known is not None:   # (it made contact itself, shipping no row)
                    known.update(via=via, shipped=shipped)
                    continue
                rows[who] = {"robot": who, "shipped": shipped, "last_arrival": None,
                             "pending": None, "head_arrival": None, "contact_at": None,
                             "via": via}
            for row in rows.values():
                row["retired_at"] = None
            for who, at in self.retired().items():
                if who not in rows:   # (a robot known by its events alone: listed too)
                    rows[who] = {"robot": who, "shipped": 0, "last_arrival": None,
                                 "pending": None, "head_arrival": None, "contact_at": None,
                                 "via": None}
                rows[who]["retired_at"] = at
            return [rows[who] for who in sorted(rows)]


def _position_upsert(dialect: Any) -> str:
    """The upsert of a robot's position in one event type (the type's name is a key of any
    length: the dialect's key of it)."""
    return ("INSERT INTO slr_fleet_positions (robot, type_name, type_arity, position) "
            f"VALUES (?, ?, ?, ?) ON CONFLICT (robot, {dialect.key('type_name')}, type_arity) "
            "DO UPDATE SET position = excluded.position")


def _shipped_insert(table: str, arity: int) -> str:
    """The INSERT of shipped rows: :meth:`Fleet.column_values` and the arrival.

    >>> _shipped_insert('"seen"', 1)
    'INSERT INTO "seen" (arg1, t_start, t_end, robot, arrival) VALUES (?, ?, ?, ?, ?)'
    """
    columns = [f"arg{i}" for i in range(1, arity + 1)] + ["t_start", "t_end", "robot", "arrival"]
    return (f"INSERT INTO {table} ({', '.join(columns)}) "
            f"VALUES ({', '.join('?' * len(columns))})")


def _shipped_event(name: str, arity: int, row: tuple) -> str:
    """A shipped row as an event's text for a message (arguments in their stored form).

    >>> _shipped_event("seen", 1, (2, "pallet7", 1.0, 2.0, 3.0, None))
    'seen(pallet7)^[1.0, 2.0]'
    """
    args = ", ".join(str(v) for v in row[1:1 + arity])
    return f"{name}({args})^[{row[1 + arity]!r}, {row[2 + arity]!r}]"


def _finite(value: Any) -> bool:
    return type(value) in (int, float) and math.isfinite(value)


def _json_text(value: str) -> str:
    import json
    try:
        decoded = json.loads(value)
    except ValueError:
        return value
    return decoded if isinstance(decoded, str) else str(decoded)
