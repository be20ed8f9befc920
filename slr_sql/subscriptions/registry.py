"""The durable registry of subscriptions: their rows in ``slr_subscriptions`` (definition,
position, which process delivers them and until when), and the journals of the types they
read (created while some subscription wants a type, trimmed to what they still need, dropped
when none does). Every statement is a method of the store (:mod:`slr_sql.store.journals`).
"""
from __future__ import annotations

import functools
import logging
import os
import socket
import time
import uuid
from typing import Any, Iterable

from ..errors import SLRError, SLRSubscriptionInUse
from ..store.checks import shown
from .queue import HISTORY_PHASE, LIVE_PHASE, Subscription, SubscriptionState


def no_subscription(sub_id: Any) -> SLRError:
    """The error of ``unsubscribe`` of an id no subscription has (the client of ``slr
    serve`` raises it too for an id that is no str, which names none).

    >>> print(no_subscription("watcher"))
    no subscription with id 'watcher'
    """
    return SLRError(f"no subscription with id {shown(sub_id)}")

__all__ = ["SubscriptionRegistry", "journal_table", "owner_alive", "JOURNAL_PREFIX",
           "TRIGGER_PREFIX", "LEASE_SECONDS"]

log = logging.getLogger("slr_sql.subscriptions")

JOURNAL_PREFIX = "slr_subj_"
TRIGGER_PREFIX = "slr_subt_"
LEASE_SECONDS = 30.0           # wall-clock s a process's claim on its subscriptions lasts


def journal_table(table: str) -> str:
    """The journal of an event table: ``slr_subj_<table>``.

    >>> journal_table("face")
    'slr_subj_face'
    """
    return JOURNAL_PREFIX + table


def owner_alive(owner: str | None, lease_until: float | None, now_wall: float,
                me: str) -> bool:
    """Does another process than ``me`` hold a live claim on a subscription row?

    >>> owner_alive("host:1:ab", None, 0.0, "me"), owner_alive("me", 10.0, 0.0, "me")
    (False, False)
    """
    if not owner or owner == me:
        return False
    if lease_until is None or lease_until < now_wall:
        return False
    host, _, rest = owner.partition(":")
    pid_text = rest.partition(":")[0]
    if host == socket.gethostname() and pid_text.isdigit():
        try:
            os.kill(int(pid_text), 0)
        except ProcessLookupError:
            return False        # the owner died (SIGKILL, crash): its claim is void
        except (PermissionError, OSError):
            return True
    return True


def _note_persisted(sub: Subscription, position: tuple[int, int]) -> None:
    sub.persisted = position


class SubscriptionRegistry:
    """The rows of one process's subscriptions in the store, and the journals they read.
    ``owner`` names this process in the rows it claims.

    >>> from slr_sql.store import EventStore
    >>> registry = SubscriptionRegistry(EventStore(None), clock=None)
    >>> registry.rows()
    []
    """

    def __init__(self, store: Any, clock: Any):
        self.store = store
        self.clock = clock
        self.owner = f"{socket.gethostname()}:{os.getpid()}:{uuid.uuid4().hex[:12]}"
        self.lease_seconds = LEASE_SECONDS

    # -- journals -----------------------------------------------------------------------------
    def ensure_journal(self, table: str, arity: int) -> None:
        """Create the journal of ``table`` and its trigger (inside the caller's transaction)."""
        self.store.create_journal(table, arity, journal_table(table), TRIGGER_PREFIX + table)

    def has_journal(self, table: str) -> bool:
        """Is ``table`` journaled (its trigger installed)?"""
        return TRIGGER_PREFIX + table in self.store.triggers(table)

    def wanted(self, name: str, arity: int) -> bool:
        """Does an unfinished subscription of any process want name/arity?"""
        return self.store.subscription_wanted(name, arity)

    # -- registration -------------------------------------------------------------------------
    def register(self, sub: Subscription) -> str | None:
        """In one write transaction: journal the type, then resume ``sub`` from its row (a
        durable one registered before) or write a new row whose history is the type's rows
        stored so far and whose live events the journal's rows after its head. Returns the
        type's table (None while it has none)."""
        store = self.store
        name, arity = sub.key
        now_wall = time.time()
        with store.transaction():
            record = store.subscription_record(sub.id) if sub.durable else None
            table = store.table_for(name, arity)
            if table is not None:
                self.ensure_journal(table, arity)
            if record is not None:
                if record.pattern != sub.pattern or record.where_goal != sub.where or \
                        record.until != sub.until:
                    where, until = record.where_goal, record.until
                    raise SLRError(
                        f"subscription {sub.id!r} exists with pattern {record.pattern!r}"
                        f"{', where ' + repr(where) if where else ''}"
                        f"{', until ' + format(until, 'g') if until is not None else ''}; "
                        f"resume it with the same definition, or kb.unsubscribe({sub.id!r}) "
                        f"first")
                if owner_alive(record.owner, record.lease_until, now_wall, self.owner):
                    raise SLRSubscriptionInUse(f"subscription {sub.id!r} is being delivered "
                                               f"by another process ({record.owner})")
                sub.since = record.since
                sub.start_at(LIVE_PHASE if record.history_done else HISTORY_PHASE,
                             record.history_top, record.history_pos, record.live_start,
                             record.live_pos)
                store.claim_subscription(sub.id, self.owner, now_wall + self.lease_seconds)
                if record.finished:
                    sub.end()
                return table
            top = start = 0
            if table is not None:
                top, start = store.journal_start(table, journal_table(table))
            sub.start_at(HISTORY_PHASE if top > 0 else LIVE_PHASE, top, 0, start, start)
            store.insert_subscription(
                sub.id, sub.durable, sub.pattern, sub.where, sub.since, sub.until, name, arity,
                top, start, self.owner, now_wall + self.lease_seconds,
                float(self.clock.now()))
            return table

    def unclaim(self, sub: Subscription, forget: bool = False) -> None:
        """Write ``sub``'s final position and release (or remove) its row."""
        if self.store.closed:
            return
        try:
            with self.store.transaction():
                if forget:
                    self.store.delete_subscription(sub.id)
                elif not sub.durable:
                    self.store.delete_subscription(sub.id, owner=self.owner)
                else:
                    self.write_position(sub, release=True)
        except SLRError as exc:
            log.warning("subscription %r: could not record its position: %s", sub.id, exc)

    def forget(self, sub_id: str) -> None:
        """Remove the row of ``sub_id`` (not open in this process)."""
        with self.store.transaction():
            if not self.store.delete_subscription(sub_id):
                raise no_subscription(sub_id)

    def write_position(self, sub: Subscription, release: bool = False) -> None:
        """Move ``sub``'s stored position to where it is (``release``: and let go of it)."""
        phase, pos = sub.position()
        if phase == HISTORY_PHASE:
            hdone, hpos, lpos = 0, pos, sub.live_start
        else:
            hdone, hpos, lpos = 1, sub.history_top, pos
        self.store.write_subscription_position(
            sub.id, self.owner, hdone, hpos, lpos, sub.completed,
            None if release else time.time() + self.lease_seconds,
            None if release else self.owner)

    def persist(self, subs: Iterable[Subscription], renew: bool) -> set[str] | None:
        """One write transaction: the positions of ``subs`` that moved since written (all of
        them when ``renew``: a row's lease is renewed with its position), and (``renew``) every
        claim of this process extended. Returns the ids this process still holds when
        ``renew``, else None."""
        todo = []
        for s in subs:
            position = s.position()
            if position != s.persisted and (s.durable or renew):
                todo.append((s, position))
        if not todo and not renew:
            return None
        mine = None
        with self.store.transaction():
            for s, position in todo:
                if s.state is not SubscriptionState.CLOSED:
                    self.write_position(s)
                    # noted once stored: a commit that fails (a full disk) leaves the
                    # position due, to be written on the next round
                    self.store.after_commit(functools.partial(_note_persisted, s, position))
            if renew:
                mine = self.store.renew_subscriptions(self.owner,
                                                      time.time() + self.lease_seconds)
        return mine

    def rows(self) -> list[dict[str, Any]]:
        """Every registered subscription of the store (all processes), as dicts."""
        return self.store.subscription_rows()

    # -- trimming -----------------------------------------------------------------------------
    def trim(self, local_types: set[tuple[str, int]],
             local_positions: dict[str, int]) -> set[tuple[str, int]]:
        """Remove expired claims, trim each journal to what some subscription still needs
        (``local_positions``: this process's, from memory; the others' as written), and drop
        the journal and trigger of types no subscription wants any more (none of
        ``local_types`` either). Returns the types whose journal was dropped."""
        store = self.store
        dropped: set[tuple[str, int]] = set()
        if store.closed:
            return dropped
        journals = sorted(name for name in store.table_names()
                          if name.startswith(JOURNAL_PREFIX))
        tables = {table: key for key, table in store.event_types().items()}
        with store.transaction():
            store.expire_subscriptions(time.time())
            for journal in journals:
                table = journal[len(JOURNAL_PREFIX):]
                key = tables.get(table)
                if key is None:
                    continue
                rows = store.live_positions(*key)
                if not rows and key not in local_types:
                    store.drop_journal(table, journal, TRIGGER_PREFIX + table)
                    dropped.add(key)
                elif rows:
                    low = min(local_positions.get(sid, pos) if owner == self.owner else pos
                              for sid, owner, pos in rows)
                    store.trim_journal(journal, low)
        return dropped
