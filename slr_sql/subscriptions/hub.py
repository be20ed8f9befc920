"""The hub: the subscriptions of one knowledge base and the thread that delivers them.

Woken by ``kb.add`` (and every ``poll_interval`` seconds, for rows other processes
committed), one delivery pass reads each subscribed type's journal once for every
subscription that keeps up (the shared read), matches each row once per distinct pattern,
condition and window, and queues the answers (:class:`~.queue.Subscription`); subscriptions
behind it (new, lagging) are read together at their own pace, histories by seq. Its reads
run on a connection of its own (:meth:`slr_sql.store.EventStore.journal_reader`), so they
never wait for a writer's commit and a lagging subscriber never holds the writer's
connection. Housekeeping (durable positions, leases, journal trimming: writes on the
store's connection) runs on a second thread, so it never holds up a delivery either. Rows
and journals are the registry's (:mod:`.registry`).
"""
from __future__ import annotations

import itertools
import logging
import math
import threading
import time
import warnings
from typing import Any, Callable

from ..arguments import check_callable, check_time_option
from ..clocks import DEFAULT_MAX_LEARNED_DELAY, LearnedDelayWarning
from ..encoding import NullArgument, decode
from ..errors import NotAnEvent, SLRError, SLRSubscriptionInUse, log_failure
from ..lockorder import ordered_lock
from ..host import Host
from ..store import null_argument_text
from ..store.checks import shown
from ..terms import format_atom
from .matching import Matcher
from .queue import HISTORY_PHASE, LIVE_PHASE, Subscription, SubscriptionOverflow, \
    SubscriptionState, resolve_threadsafe
from .registry import SubscriptionRegistry, journal_table, no_subscription

__all__ = ["SubscriptionHub", "check_subscription", "DEFAULT_MAX_QUEUE", "DEFAULT_MAX_LAG", "POLL_INTERVAL"]

log = logging.getLogger("slr_sql.subscriptions")

DEFAULT_MAX_QUEUE = 10_000     # answers held in memory per subscription
DEFAULT_MAX_LAG = 1_000_000    # journal rows a subscription may fall behind before it ends
CHUNK = 512                    # rows per read
FEW_HISTORY = 4096             # a history window this small is read by end time
POLL_INTERVAL = 0.05           # s between journal polls (rows other processes committed)
PERSIST_INTERVAL = 0.2         # s between writes of durable positions
CLEANUP_INTERVAL = 1.0         # s between journal trims (when something was delivered)

_INF = math.inf
_HISTORY = SubscriptionState.HISTORY


class _TypeInfo:
    """The table and journal of one subscribed event type."""

    __slots__ = ("table", "journal", "name", "arity")

    def __init__(self, table: str, key: tuple[str, int]):
        self.table = table
        self.journal = journal_table(table)
        self.name, self.arity = key

    def no_event(self, seq: int, values: Any) -> NotAnEvent:
        """The end of a subscription that met the stored row ``seq`` whose ``values`` (its
        arguments as stored) hold a NULL: no event (docs/schema.md), refused in the words a
        goal that reads it gets."""
        argument = next((i for i, v in enumerate(values, 1) if v is None), 1)
        return NotAnEvent("subscribe: " + null_argument_text(self.name, self.arity, self.table,
                                                             argument, seq))


def check_subscription(pattern: Any, where: Any, since: Any, until: Any, id: Any,
                       callback: Any, max_queue: Any, max_lag: Any,
                       now: Callable[[], float] | None = None
                       ) -> tuple[str | None, float | None, float | None]:
    """The arguments of ``subscribe`` (see :meth:`slr_sql.KnowledgeBase.subscribe`) as
    ``(where, since, until)`` (``where`` None when blank, ``until`` None when unbounded),
    else an SLRError in words. ``now``: the clock's ``now``, for ``since="now"``; without
    it (the client of ``slr serve``, which runs these checks too before sending) that
    ``since`` is None and ``until`` is compared with it where the store's clock is.

    >>> check_subscription("p(X)^T", " ", 0, 5, None, None, 10, None)
    (None, 0.0, 5.0)
    >>> check_subscription("p(X)^T", None, "now", None, None, None, 0, None)
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: subscribe: max_queue must be a positive integer, not 0
    """
    if not isinstance(pattern, str):
        raise SLRError(f"subscribe: the pattern must be text such as 'face(F, R)^T', "
                       f"not {shown(pattern)}")
    if where is not None and not isinstance(where, str):
        raise SLRError(f"subscribe: where must be a goal as text, not {shown(where)}")
    if where is not None and not where.strip():
        where = None
    if isinstance(since, str) and since.strip() == "now":
        since_value = None if now is None else float(now())
    else:
        check_time_option("subscribe: since", since, required=True)
        since_value = float(since)
    check_time_option("subscribe: until", until)
    until_value = None if until is None else float(until)
    if until_value == _INF:
        until_value = None
    if until_value is not None and since_value is not None and until_value < since_value:
        raise SLRError(f"subscribe: until ({until_value:g}) is before since "
                       f"({since_value:g})")
    if id is not None and (not isinstance(id, str) or not id):
        raise SLRError(f"subscribe: id must be a non-empty string, not {shown(id)}")
    if callback is not None:
        check_callable("subscribe: callback", callback)
    if isinstance(max_queue, bool) or not isinstance(max_queue, int) or max_queue < 1:
        raise SLRError(f"subscribe: max_queue must be a positive integer, not {shown(max_queue)}")
    if max_lag is not None and (isinstance(max_lag, bool) or not isinstance(max_lag, int)
                                or max_lag < 1):
        raise SLRError(f"subscribe: max_lag must be a positive integer or None, "
                       f"not {shown(max_lag)}")
    return where, since_value, until_value


class SubscriptionHub:
    """The subscriptions of one knowledge base and the thread that delivers them (created by
    :func:`slr_sql.subscriptions.attach`; ``kb.subscribe`` / ``kb.unsubscribe`` delegate
    here)."""

    def __init__(self, kb: Host):
        self.kb = kb
        self.store = kb.store
        # the store's columns: encoded terms as they are (SQLite) or as a server holds them
        from_column = self.store.dialect.from_column
        self._decode: Any = decode if from_column is None else \
            (lambda v: decode(from_column(v)))
        self.clock = kb.clock
        self.registry = SubscriptionRegistry(self.store, self.clock)
        self.owner = self.registry.owner
        self.lock = ordered_lock("subscriptions.hub")
        self.cond = threading.Condition(self.lock)
        self.poll_interval = POLL_INTERVAL
        self.persist_interval = PERSIST_INTERVAL
        self.cleanup_interval = CLEANUP_INTERVAL
        self._subs: dict[str, Subscription] = {}
        self._by_type: dict[tuple[str, int], list[Subscription]] = {}
        self._type_pos: dict[tuple[str, int], int] = {}
        self._types: dict[tuple[str, int], _TypeInfo] = {}
        self._matchers: dict[tuple[str, str | None], Matcher] = {}
        self._ids = itertools.count(1)
        self._dirty = False
        self._closed = False
        self._thread: threading.Thread | None = None
        self._stop_listening: Callable[[], None] | None = None
        self._last_persist = 0.0
        self._last_lease = time.monotonic()   # registration writes a fresh lease
        self._last_cleanup = 0.0
        # housekeeping (positions, leases, journal trimming: writes on the store's connection)
        # runs on a thread of its own, so a write waiting for a writer's commit, or its own
        # commit, never holds up a delivery pass
        self._housekeeper: threading.Thread | None = None
        self._hk_cond = threading.Condition(ordered_lock("subscriptions.hub"))
        self._hk_asked = False
        self._hk_started = 0
        self._hk_done = 0
        self._hk_last_failure = ""
        self._subscribed_types: set[tuple[str, int]] = set()   # ever, in this process
        self._journaled: set[tuple[str, int]] = set()   # types whose trigger was seen
        self._last_failure = ""
        self._passes_started = 0
        self._passes_done = 0
        self._cleaned_at_pass = -1
        # the reads of delivery: on the hub thread's own connection (None: in memory, or not
        # started), which never waits for the store's lock (held by a writer through its
        # commit), so a lagging subscriber's reads never delay the writers; and on the
        # store's connection, for a pass woken from inside a transaction not committed yet
        self._own_reads: Any = None
        self._store_reads = self.store.journal_reader(own_connection=False)
        self._max_jids: dict[str, int] = {}   # per type and pass: max(jid) of each journal
        self._through_store = False
        self._pass_through_store = False

    @property
    def lease_seconds(self) -> float:
        """Wall-clock seconds a claim of this process on its subscriptions lasts."""
        return self.registry.lease_seconds

    @lease_seconds.setter
    def lease_seconds(self, value: float) -> None:
        self.registry.lease_seconds = value

    # -- wiring -------------------------------------------------------------------------------
    def notify(self, through_store: bool = False) -> None:
        """Something may be new: wake the hub thread (never waits on delivery).
        ``through_store``: called inside a transaction, so the next pass must read through
        the store's connection (which waits for its commit)."""
        with self.cond:
            self._dirty = True
            self._through_store = self._through_store or through_store
            self.cond.notify()

    def on_add(self, stored: list) -> None:
        """Events were stored (the event pipeline's wake stage): wake the hub if some are of
        subscribed types."""
        if not self._by_type or not stored:
            return
        keys = self._by_type
        for ev in stored:
            try:
                if (ev[0], len(ev[1])) in keys:
                    # only the adding thread's own transaction hides the rows from the hub's
                    # connection; another thread's (the hub's housekeeping, another writer)
                    # does not, and reading through the store would queue behind it
                    self.notify(through_store=self.store.in_transaction_here)
                    return
            except (TypeError, IndexError):
                continue

    def on_table_created(self, name: str, arity: int, table: str) -> None:
        """Store hook, inside the transaction creating an event table: journal it from its
        first row if some subscription (of any process) wants that type."""
        if self.registry.wanted(name, arity):
            self.registry.ensure_journal(table, arity)

    # -- subscribe / unsubscribe ----------------------------------------------------------------
    def subscribe(self, pattern: str, where: str | None = None, since: Any = "now",
                  until: Any = None, id: str | None = None,
                  callback: Callable[[dict], Any] | None = None,
                  max_queue: int = DEFAULT_MAX_QUEUE,
                  max_lag: int | None = DEFAULT_MAX_LAG) -> Subscription:
        """Register a subscription (see :meth:`slr_sql.KnowledgeBase.subscribe`): validate,
        register in one write transaction, start delivering.

        >>> import slr_sql
        >>> kb = slr_sql.open(); sub = kb._subscriptions.subscribe("p(X)^T", since=0)
        >>> sub.durable, sub.since
        (False, 0.0)
        >>> kb.close()
        """
        if self._closed:
            raise SLRError("the knowledge base is closed")
        where, since_value, until_value = check_subscription(
            pattern, where, since, until, id, callback, max_queue, max_lag, now=self.clock.now)
        assert since_value is not None
        pattern = pattern.strip()
        matcher = Matcher(self.kb.query, pattern, where)   # SLRSyntaxError for bad texts
        if isinstance(since, str):
            self._warn_if_stamped_long_before(matcher.key, since_value)
        durable = id is not None
        with self.lock:
            if durable and id in self._subs:
                raise SLRSubscriptionInUse(f"subscription {id!r} is already open in this process")
            sub_id = id if durable else f"~{self.owner}:{next(self._ids)}"
        sub = Subscription(self, matcher, sub_id, durable, since_value, until_value,
                           max_queue, max_lag, callback)
        table = self.registry.register(sub)
        if table is not None:
            self._types.setdefault(sub.key, _TypeInfo(table, sub.key))
        with self.lock:
            if durable and id in self._subs:   # a concurrent subscribe with the same id
                self.registry.unclaim(sub)
                raise SLRSubscriptionInUse(f"subscription {id!r} is already open in this process")
            key = (matcher.pattern, matcher.where)
            sub.matcher = self._matchers.setdefault(key, matcher)
            sub.cohort_key = (sub.matcher, sub.since, sub.until)   # shared answers
            self._subs[sub.id] = sub
            self._by_type.setdefault(sub.key, []).append(sub)
            self._subscribed_types.add(sub.key)
            self._dirty = True
            if self._thread is None:
                self._thread = threading.Thread(target=self._loop, name="slr-subscriptions",
                                                daemon=True)
                self._thread.start()
                self._housekeeper = threading.Thread(target=self._housekeeping_loop,
                                                     name="slr-subscriptions-housekeeping",
                                                     daemon=True)
                self._housekeeper.start()
                # a server tells when other processes stored events of journaled types
                self._stop_listening = self.store.listen(self.notify)
            self.cond.notify()
        if sub.until is not None and not sub.is_over:
            try:
                self._watch_until(sub)
            except BaseException:
                sub.close(ack=False)
                raise
        if callback is not None:
            sub.start_callback()
        return sub

    def _warn_if_stamped_long_before(self, key: tuple[str, int], now: float) -> None:
        """``since="now"`` on a type whose events end long before the clock's now (robot or
        recorded times on a store with a wall clock): the new events will most likely be
        stamped the same way, end before ``since`` and never be delivered. Say so."""
        latest = self.store.max_end(*key)
        gap = getattr(self.kb, "max_learned_delay", None) or DEFAULT_MAX_LEARNED_DELAY
        if latest is None or now - latest <= gap:
            return
        name = f"{format_atom(key[0])}/{key[1]}"   # (quoted: a line break stays an escape)
        warnings.warn(LearnedDelayWarning(
            f"subscribe(since=\"now\") on {name}: its latest event ends at {latest:g}, "
            f"{now - latest:.6g} s before the clock's now ({type(self.clock).__name__}); "
            f"events stamped like it end before since and are not delivered. Subscribe "
            f"since=0 (history first, then live), or give the store a ManualClock or a "
            f"StreamClock for simulated or recorded times"), stacklevel=3)

    def unsubscribe(self, sub_id: str) -> None:
        """Remove the subscription ``sub_id`` (closing it if it is open here).

        >>> import slr_sql
        >>> kb = slr_sql.open(); sub = kb.subscribe("p(X)^T", id="log"); sub.close()
        >>> kb.unsubscribe("log"); kb._subscriptions.subscriptions()
        []
        >>> kb.close()
        """
        if not isinstance(sub_id, str):   # (no id: a list, unhashable, is none either)
            raise no_subscription(sub_id)
        with self.lock:
            sub = self._subs.get(sub_id)
        if sub is not None:
            sub.close(forget=True)
            return
        self.registry.forget(sub_id)
        self.cleanup()

    def subscriptions(self) -> list[dict[str, Any]]:
        """Every registered subscription of the store (all processes), as dicts.

        >>> import slr_sql
        >>> kb = slr_sql.open(); sub = kb.subscribe("p(X)^T", id="log")
        >>> [(r["id"], r["pattern"], r["durable"]) for r in kb._subscriptions.subscriptions()]
        [('log', 'p(X)^T', 1)]
        >>> kb.close()
        """
        return self.registry.rows()

    def _type_info(self, key: tuple[str, int]) -> _TypeInfo | None:
        """The table and journal of ``key``; None while it has no table. A type without
        one is looked up again on every pass, on the pass's connection: never waiting for
        a writer's transaction (as the store's lookup would) before serving the others."""
        info = self._types.get(key)
        if info is None:
            table = self._reads().event_table(*key)
            if table is None:
                return None
            info = self._types[key] = _TypeInfo(table, key)
        return info

    def _watch_until(self, sub: Subscription) -> None:
        """Ask the synchronizer to tell when the type is complete up to ``until``."""
        name, arity = sub.key
        until = sub.until
        assert until is not None
        atom = format_atom(name) + (f"({', '.join('_' * arity)})" if arity else "")
        sync = self.kb.synchronizer
        if self.store.path is not None and sync is not None and \
                getattr(sync, "external_poll", 1) is None:
            sync.watch_external(self.poll_interval)   # marks written by other processes
        pending = self.kb.submit(f"prev({atom}^_, U)", at=until, args={"U": until},
                                 id=f"subscription {sub.id} until {until:g}")
        sub.pending = pending

        def reached(future: Any) -> None:
            if future.cancelled() or self._closed:
                return
            error = future.exception()
            if error is not None:
                if sub.state is not SubscriptionState.CLOSED:
                    sub.end(SLRError(f"subscription {sub.id!r}: waiting for its history to be "
                                     f"complete up to until={until:g} failed: {error}"))
                    self._wake({sub})
                return
            sub.until_reached = True
            self.notify()

        pending.add_done_callback(reached)

    # -- closing ------------------------------------------------------------------------------------
    def release(self, sub: Subscription, forget: bool) -> None:
        """``sub`` was closed: unregister it, write its position (or remove its row)."""
        with self.lock:
            registered = self._subs.get(sub.id) is sub
            if registered:
                del self._subs[sub.id]
                subs = self._by_type.get(sub.key, [])
                if sub in subs:
                    subs.remove(sub)
                if not subs:
                    self._by_type.pop(sub.key, None)
                    self._type_pos.pop(sub.key, None)
                key = (sub.matcher.pattern, sub.matcher.where)
                if self._matchers.get(key) is sub.matcher and not any(
                        s.matcher is sub.matcher for s in subs):
                    del self._matchers[key]      # kept only while some subscription uses it
        pending = sub.pending
        if pending is not None and not pending.done():
            pending.cancel()
        if registered or forget:
            self.registry.unclaim(sub, forget)
            if (forget or not sub.durable) and sub.key not in self._by_type:
                try:                    # the last one of its type here: drop what is unused
                    self.cleanup()
                except SLRError as exc:
                    log.warning("subscriptions: journal cleanup failed: %s", exc)

    def taken_end(self, sub: Subscription) -> None:
        """The consumer took the end of ``sub``: record it as finished, unregister."""
        if sub.state is not SubscriptionState.CLOSED:
            sub.close(forget=False)

    def close(self) -> None:
        """Close every subscription (durable ones keep their position) and stop the thread."""
        with self.cond:
            if self._closed:
                return
            subs = list(self._subs.values())
        for sub in subs:
            # their waits for an `until` end first, outside the transaction below: cancelling
            # one takes the synchronizer's lock, which comes before the store's (and the
            # synchronizer's timer thread takes them in that order)
            pending = sub.pending
            if pending is not None and not pending.done():
                pending.cancel()
        if subs and not self.store.closed:
            try:
                with self.store.transaction():   # one commit for every position
                    for sub in subs:
                        sub.close(join=False)
            except SLRError as exc:
                log.warning("subscriptions: could not record positions at close: %s", exc)
        for sub in subs:
            sub.close(join=False)                # (if the transaction above failed)
            sub.join_callback()                  # callback threads, outside the transaction
        with self.cond:
            self._closed = True
            self.cond.notify_all()
        with self._hk_cond:
            self._hk_cond.notify_all()
        if self._stop_listening is not None:
            self._stop_listening()
        for thread in (self._thread, self._housekeeper):
            if thread is not None and thread is not threading.current_thread():
                thread.join(timeout=10.0)
        if self._subscribed_types and not self.store.closed:
            try:
                self.cleanup()
            except SLRError:
                pass

    # -- the hub thread ------------------------------------------------------------------------
    def _reads(self) -> Any:
        """The reads of this pass: on the hub's own connection when it has one."""
        own = self._own_reads
        return self._store_reads if own is None or self._pass_through_store else own

    def _journal_rows(self, info: _TypeInfo, after_jid: int, limit: int) -> list[tuple]:
        return self._reads().journal_rows(info.journal, info.arity, after_jid, limit)

    def _loop(self) -> None:
        """Run a delivery pass whenever ``kb.add`` (or a consumer making room, or ``until``)
        wakes the hub, and at least every ``poll_interval`` seconds: the pass compares each
        journal's greatest jid with what was read, which is how events stored by other
        connections (processes) or by statements on this one are seen."""
        try:
            self._own_reads = self.store.journal_reader(own_connection=True)
        except SLRError as exc:   # (too many open files, ...): read on the store's connection
            log.warning("subscriptions: no connection of their own (%s); reading on the "
                        "store's", exc)
        try:
            self._run_passes()
        finally:
            reads, self._own_reads = self._own_reads, None
            if reads is not None:
                reads.close()

    def _run_passes(self) -> None:
        while True:
            with self.cond:
                if not self._dirty and not self._closed:
                    self.cond.wait(self.poll_interval if self._subs else None)
                if self._closed:
                    return
                self._dirty = False
                self._pass_through_store, self._through_store = self._through_store, False
                if not self._subs:
                    continue
                self._passes_started += 1
                number = self._passes_started
            try:
                self._pass()
            except Exception as exc:  # a busy store, a closing kb: try again on the next tick
                if self._closed or self.store.closed:
                    return
                if str(exc) != self._last_failure:   # once per distinct failure, not per tick
                    self._last_failure = str(exc)
                    log_failure(log, "subscriptions: a delivery pass", exc, "retrying")
            finally:
                with self.cond:
                    self._passes_done = number
                    self.cond.notify_all()

    def drain(self, timeout: float | None = None) -> bool:
        """Wait until a whole delivery pass has run after this call (tests, benchmarks): every
        event stored before the call has then been matched and queued, or left for a lagging
        subscription to read later. True if it did within ``timeout`` seconds."""
        end = None if timeout is None else time.monotonic() + timeout
        with self.cond:
            if not self._subs or self._thread is None:
                return True
            want = self._passes_started + 1
            self._dirty = True
            self.cond.notify_all()
            while self._passes_done < want and not self._closed:
                left = None if end is None else end - time.monotonic()
                if left is not None and left <= 0:
                    return False
                self.cond.wait(left)
        return True

    def _snapshot(self) -> dict[tuple[str, int], list[Subscription]]:
        with self.lock:
            return {key: list(subs) for key, subs in self._by_type.items()}

    def _pass(self) -> None:
        for key, subs in self._snapshot().items():
            try:
                self._serve_type(key, subs)
            except Exception:
                if any(s.state is not SubscriptionState.CLOSED for s in subs):
                    raise
                # every subscription of the type closed meanwhile (its journal may be gone)

    def _serve_type(self, key: tuple[str, int], subs: list[Subscription]) -> None:
        """One round for the subscriptions of one event type: the shared read of the journal
        for those that keep up, then each one that reads at its own pace (history, lagging),
        then the ends (``until`` reached, too far behind)."""
        touched: set = set()
        loops: dict = {}    # the shared read's async consumers, woken with the touched ones
        try:
            self._serve_type_into(key, subs, touched, loops)
        finally:
            # also when a read fails half-way (a busy store: the pass is retried): what was
            # queued is not read again, and a consumer handed over to ``loops`` is no longer
            # registered with its subscription, so nothing else would ever wake it
            self._wake(touched, loops)

    def _serve_type_into(self, key: tuple[str, int], subs: list[Subscription], touched: set,
                         loops: dict) -> None:
        """:meth:`_serve_type`'s round; the consumers to wake are collected in ``touched``
        and ``loops``."""
        info = self._type_info(key)
        self._max_jids.clear()
        if info is None:   # no event of this type yet: nothing to read; until may still end it
            ending = [s for s in subs if s.until_reached and not s.is_over]
            # looked up again after reading the flags: events stored (creating the table) before
            # `until` was reached must be delivered first, by the reading below
            if ending and self._type_info(key) is None:
                for s in ending:
                    s.go_live()
                    s.end(completed=True)
                    touched.add(s)
                return
            info = self._type_info(key)
            if info is None:
                return
        self._check_journal(key, info)
        for s in subs:
            if s.until_reached and s.end_jid is None:
                s.end_jid = self._max_jid(info)
        pos = self._type_pos.get(key)
        live = SubscriptionState.LIVE
        group = [s for s in subs if s.state is live and (pos is None or s.scanned >= pos)]
        if group:
            if pos is None:
                pos = min(s.scanned for s in group)
            while True:
                rows = self._journal_rows(info, pos, CHUNK)
                if not rows:
                    break
                self._deliver_rows(key, rows, group, touched, loops=loops)
                pos = rows[-1][0]
                self._type_pos[key] = pos
                if len(rows) < CHUNK:
                    break
                group = [s for s in group if s.state is live]
                self._wake(touched, loops)     # a long backlog: let consumers start
                touched.clear()
                loops.clear()
        rest = []
        behind = []
        for s in subs:
            state = s.state
            if not state.running or (state is live and pos is not None and s.scanned >= pos
                                     and not s.until_reached):
                continue                 # served by the shared read: nothing else to do
            rest.append(s)
            if state is _HISTORY:
                self._serve_history(info, s, touched)
            if s.phase == LIVE_PHASE and (s.lagging or pos is None or s.scanned < pos):
                behind.append(s)         # not (yet) in the shared read
        if behind:
            self._serve_behind(key, info, behind, touched)
        for s in rest:
            self._check_end(key, info, s, touched)

    def _deliver_rows(self, key: tuple[str, int], rows: list, group: list[Subscription],
                      touched: set, own_pace: bool = False, loops: dict | None = None) -> None:
        """Match journal rows ``(jid, seq, args.., start, end)`` for ``group``: the answers of
        each distinct (pattern, condition, since, until) are computed once, then given to each
        subscription in one batch; one whose queue fills up falls behind (lagging) at the
        first answer it cannot take. ``loops``: the async consumers of the batches queued
        whole are handed over there (:meth:`Subscription.offer_all`), for :meth:`_wake`."""
        arity = key[1]
        decode = self._decode
        try:
            events = [(row[0], tuple([decode(v) for v in row[2:2 + arity]]), row[2 + arity],
                       row[3 + arity]) for row in rows]
        except NullArgument:
            # a row that is no event (another client wrote it): in its place the error that
            # ends the subscriptions that meet it
            info = self._types[key]
            events = []
            for row in rows:
                try:
                    args: Any = tuple([decode(v) for v in row[2:2 + arity]])
                except NullArgument:
                    args = info.no_event(row[1], row[2:2 + arity])
                events.append((row[0], args, row[2 + arity], row[3 + arity]))
        first_jid, last_jid = events[0][0], events[-1][0]
        cohorts: dict = {}
        for s in group:
            scanned = s.scanned
            if scanned >= last_jid or s.lagging or s.is_over:
                continue
            cohort = cohorts.get(s.cohort_key)
            if cohort is None:
                cohort = cohorts[s.cohort_key] = self._cohort(s, events)
            items, error, error_jid, flat = cohort
            if scanned < first_jid and error is None and s.offer_all(flat, len(items),
                                                                      last_jid, loops):
                if items:                # the common case: every answer of the batch fits
                    touched.add(s)
                continue
            if scanned >= first_jid:
                items = [item for item in items if item[0] > scanned]
                if error is not None and error_jid <= scanned:
                    error = None
            if error is None:
                end_pos = last_jid
            else:
                end_pos = items[-1][0] if items else scanned
            if s.offer_batch(LIVE_PHASE, items, end_pos):
                if error is not None:
                    s.end(error)
                if items or error is not None:
                    touched.add(s)
            else:
                s.fall_behind()
                touched.add(s)
                if not own_pace:
                    s.overflows += 1

    def _cohort(self, s: Subscription, events: list) -> tuple[list, Any, int, list]:
        """``s``'s answers among ``events``: ([(jid, answer)], the first error, its jid, and
        the answers as queue entries ``[jid, answer, ...]``)."""
        m = s.matcher
        since = s.since
        until = _INF if s.until is None else s.until
        items = []
        for jid, args, start, end in events:
            if end < since or end > until:
                continue
            if type(args) is NotAnEvent:
                return items, args, jid, []
            answer = m.match_or_error(args, start, end)
            if answer is None:
                continue
            if type(answer) is not dict:
                return items, answer, jid, []
            items.append((jid, answer))
        return items, None, 0, [x for item in items for x in item]

    def _serve_history(self, info: _TypeInfo, s: Subscription, touched: set) -> None:
        """Deliver stored events (seq <= history_top, end in [since, until]) in seq order, as
        far as ``s``'s queue has room; then switch ``s`` to the journal."""
        arity = info.arity
        m = s.matcher
        until = _INF if s.until is None else s.until
        reads = self._reads()
        if s.history_by_end is None:
            few = reads.window_count(info.table, s.since, until, FEW_HISTORY + 1)
            s.history_by_end = few <= FEW_HISTORY
        while s.state is _HISTORY:
            room = s.room()
            if room <= 0:
                return
            limit = max(min(room, CHUNK), 16)
            rows = reads.history_rows(info.table, info.journal, arity, s.history_pos,
                                      s.history_top, s.since, until, s.live_start, limit,
                                      s.history_by_end)
            batch = []
            error = None
            for row in rows:
                try:
                    args = tuple([self._decode(v) for v in row[1:1 + arity]])
                except NullArgument:
                    error = info.no_event(row[0], row[1:1 + arity])
                    break
                answer = m.match_or_error(args, row[1 + arity], row[2 + arity])
                if answer is None:
                    continue
                if type(answer) is not dict:
                    error = answer
                    break
                batch.append((row[0], answer))
            done = error is None and len(rows) < limit
            if error is None:
                end_pos = s.history_top if done else (rows[-1][0] if rows else s.history_pos)
            else:
                end_pos = batch[-1][0] if batch else s.history_pos
            if batch or error is not None:
                touched.add(s)
            if not s.offer_batch(HISTORY_PHASE, batch, end_pos):
                return
            if error is not None:
                s.end(error)
                return
            if done:
                s.go_live()

    def _serve_behind(self, key: tuple[str, int], info: _TypeInfo, behind: list[Subscription],
                      touched: set) -> None:
        """Read the journal for the live subscriptions behind the shared read (lagging ones,
        new ones) together, from the earliest position among them: each chunk is read,
        decoded and matched once for all of them (once per distinct pattern, condition and
        window, as in the shared read), and each takes the answers after its own position
        that its queue has room for. One whose queue is full stays lagging until its consumer
        makes room. So the work per event does not grow with the number of subscriptions
        behind, nor with how far behind they are."""
        active = behind
        while True:
            room = 0
            going = []
            for s in active:
                if s.is_over:
                    continue
                free = s.room()
                if free <= 0:
                    s.fall_behind()
                    continue
                going.append(s)
                room = max(room, free)
            if not going:
                return
            limit = max(min(room, CHUNK), 16)
            rows = self._journal_rows(info, min(s.scanned for s in going), limit)
            for s in going:
                s.catch_up()
            if rows:
                self._deliver_rows(key, rows, going, touched, own_pace=True)
            if len(rows) < limit:
                return                   # the end of the journal: all caught up
            active = [s for s in going if not s.lagging]

    def _serve_lagging(self, key: tuple[str, int], info: _TypeInfo, s: Subscription,
                       touched: set) -> None:
        """Read the journal after ``s.scanned`` at ``s``'s own pace, until its queue is full or
        it reaches the end of the journal (and so rejoins the shared read)."""
        while not s.is_over:
            room = s.room()
            if room <= 0:
                s.fall_behind()
                return
            limit = max(min(room, CHUNK), 16)
            rows = self._journal_rows(info, s.scanned, limit)
            s.catch_up()
            if rows:
                self._deliver_rows(key, rows, [s], touched, own_pace=True)
            if s.lagging or len(rows) < limit:
                return

    def _check_end(self, key: tuple[str, int], info: _TypeInfo, s: Subscription,
                   touched: set) -> None:
        if s.is_over:
            return
        if s.max_lag is not None and (s.lagging or s.state is _HISTORY):
            base = s.scanned if s.phase == LIVE_PHASE else s.live_start
            behind = self._max_jid(info) - base
            if behind > s.max_lag:
                s.end(SubscriptionOverflow(
                    f"subscription {s.id!r} ({s.pattern}) fell {behind} events behind "
                    f"(max_lag {s.max_lag}): its consumer is slower than the events arrive; "
                    f"it was ended after its last queued answer"
                    + (f"; subscribe again with id={s.id!r} to resume there" if s.durable
                       else ""), behind, s.id))
                touched.add(s)
                return
        if s.until_reached and s.phase == LIVE_PHASE and s.end_jid is not None:
            if s.scanned < s.end_jid and not s.lagging:
                self._serve_lagging(key, info, s, touched)   # read up to the end
            if s.scanned >= s.end_jid and not s.lagging:
                s.end(completed=True)
                touched.add(s)

    def _max_jid(self, info: _TypeInfo) -> int:
        """The journal's greatest jid, read once per type and pass (every lagging subscription
        of the type compares its position with it)."""
        value = self._max_jids.get(info.journal)
        if value is None:
            value = self._reads().max_jid(info.journal)
            self._max_jids[info.journal] = value
        return value

    def _check_journal(self, key: tuple[str, int], info: _TypeInfo) -> None:
        """A table created by a program without this module (raw SQL) has no journal yet."""
        if key in self._journaled:
            return
        if not self.registry.has_journal(info.table):
            with self.store.transaction():
                self.registry.ensure_journal(info.table, key[1])
        self._journaled.add(key)

    def _wake(self, touched: set, loops: dict | None = None) -> None:
        """Wake the consumers of ``touched`` and resolve the async ones handed over already
        (``loops``: futures per loop): one call into each loop."""
        if not touched and not loops:
            return
        loops = {} if loops is None else loops
        for s in touched:
            s.wake(loops)
        for loop, futures in loops.items():
            resolve_threadsafe(loop, futures)

    # -- housekeeping: durable positions, leases, journal trimming --------------------------------
    def _housekeeping_loop(self) -> None:
        """The housekeeping thread: a round every ``persist_interval / 2`` seconds at most (or
        when :meth:`housekeeping_round` asks), beside the delivery passes."""
        while True:
            with self._hk_cond:
                if not self._hk_asked and not self._closed:
                    self._hk_cond.wait(max(min(self.persist_interval,
                                               self.cleanup_interval) / 2, 0.001))
                if self._closed:
                    return
                self._hk_asked = False
                self._hk_started += 1
                number = self._hk_started
            try:
                if self._subs:
                    self._housekeeping()
            except Exception as exc:  # a busy store, a closing kb: try again on the next round
                if self._closed or self.store.closed:
                    return
                if str(exc) != self._hk_last_failure:   # once per distinct failure
                    self._hk_last_failure = str(exc)
                    log_failure(log, "subscriptions: housekeeping", exc, "retrying")
            finally:
                with self._hk_cond:
                    self._hk_done = number
                    self._hk_cond.notify_all()

    def housekeeping_round(self, timeout: float | None = None) -> bool:
        """Wait until a whole housekeeping round has run after this call (tests): the
        positions, leases and trims due then are written. True if it did within ``timeout``
        seconds (at once when nothing is subscribed here).

        >>> import slr_sql
        >>> kb = slr_sql.open(); sub = kb.subscribe("p(X)^T", since=0)
        >>> kb._subscriptions.housekeeping_round(10)
        True
        >>> sub.close(); kb.close()
        """
        end = None if timeout is None else time.monotonic() + timeout
        with self._hk_cond:
            if self._housekeeper is None:
                return True
            want = self._hk_started + 1
            self._hk_asked = True
            self._hk_cond.notify_all()
            while self._hk_done < want and not self._closed:
                left = None if end is None else end - time.monotonic()
                if left is not None and left <= 0:
                    return False
                self._hk_cond.wait(left)
        return True

    def _housekeeping(self) -> None:
        """Write the positions of durable subscriptions that moved (every persist_interval),
        renew this process's claims (every lease/3), trim journals (every cleanup_interval,
        when something was delivered). Each is one short write transaction on the store's
        connection, on the housekeeping thread: one that waits for a writer's transaction
        (fsync included), or for its own commit, delays no delivery."""
        now = time.monotonic()
        persist_due = now - self._last_persist >= self.persist_interval
        cleanup_due = now - self._last_cleanup >= self.cleanup_interval and \
            self._passes_done != self._cleaned_at_pass
        if persist_due or cleanup_due:
            self._write_housekeeping(now, persist_due, cleanup_due)

    def _write_housekeeping(self, now: float, persist_due: bool, cleanup_due: bool) -> None:
        """The writes of :meth:`_housekeeping` that are due."""
        if persist_due:
            self._last_persist = now
            with self.lock:
                subs = list(self._subs.values())
            renew = now - self._last_lease >= self.lease_seconds / 3
            mine = self.registry.persist(subs, renew)
            if mine is not None:
                self._last_lease = now
                for s in subs:
                    if s.id not in mine and s.state.running:
                        s.end(SLRError(
                            f"subscription {s.id!r} was removed from the store "
                            f"(kb.unsubscribe elsewhere, or this process did not renew "
                            f"its claim for {self.lease_seconds:g} s); events after its "
                            f"position may be missing"))
                        self._wake({s})
        if cleanup_due:
            self._last_cleanup = now
            self._cleaned_at_pass = self._passes_done
            self.cleanup()

    def _local_positions(self) -> dict[str, int]:
        """The journal position each open subscription of this process still needs (in memory:
        never behind what it wrote to the store)."""
        with self.lock:
            subs = list(self._subs.values())
        out = {}
        for s in subs:
            phase, pos = s.position()
            out[s.id] = pos if phase == LIVE_PHASE else s.live_start
        return out

    def cleanup(self) -> None:
        """Remove expired claims, trim each journal to what some subscription still needs (this
        process's from memory, the others' as written), and drop the journal and trigger of
        types no subscription wants any more."""
        if self.store.closed:
            return
        with self.lock:
            local = set(self._by_type)
        for key in self.registry.trim(local, self._local_positions()):
            self._types.pop(key, None)
            self._journaled.discard(key)
            self._type_pos.pop(key, None)
