"""The path of an event through a knowledge base, in fixed stages (docs/architecture.md).

Every way something new reaches a knowledge base -- ``kb.add`` / ``add_event`` /
``add_many``, ``kb.mark_complete``, the clock moving, a timer of the synchronizer firing,
the decisions left over in a reopened file -- goes through :class:`EventPipeline`, always in
this order:

1. **marks**: ``fullyUpdated(p/N)^t`` / ``fullyUpdated(p)^t`` are split out of the batch
   (they are completeness marks, not events);
2. **store** (insert and rule rounds): one transaction stores the events and runs the
   event rules' delta statements over the new rows (a batch a count buffer cuts is stored
   in consecutive rounds of that one transaction); the complex events it derives, and the
   batch's marks, are stored before it commits (a batch is stored whole or not at all);
3. **completeness**: the synchronizer learns delays and moves in-order horizons from what
   was stored, then holds the batch's marks in memory; waiting synchronized queries it
   completes are released;
4. **decisions until nothing changes**: the event rules' pending decisions whose histories
   are complete now are made, each round in a transaction of its own; the complex events a
   round derives go through stage 3 and the next round runs, until a round derives nothing
   and nothing asked for another one; then synchronized queries waiting on complex event
   types are re-checked. After an add, a round that fails (``SLRBusy``, a lost connection)
   ends the stage without failing the add, whose events are committed: those decisions
   stay pending for the next add, mark, clock move or timer. So does a round the
   synchronizer's timer started (its thread has no caller to raise to). With a wall clock
   such a failure also asks for a retry timer (:data:`RETRY_DELAYS`), so that the decisions
   are made without another add; a clock that tells when it moves calls at its next move;
5. **buffers**: a clock move that came during the run (a ``StreamClock`` moved by stage 3)
   prunes the tBuffers now, after the decisions it allowed; space the buffers' pruning
   freed is reclaimed, without waiting for another writer's lock (a busy reclaim is left to
   the next add: the add's events are committed);
6. **wake**: ``kb.add_listeners`` are called and the subscription hub is woken, once per
   batch, in the order the batches were stored (the add's events with the complex events
   its transaction derived, then each decision round's).

An add, mark or clock move made inside a transaction the calling thread holds
(``with kb.store.transaction(): kb.add_many(...)``: several adds stored together or not at
all) runs stages 1 and 2 in that transaction, as a savepoint (a batch that fails is taken
back alone), and stages 3-6 once the outermost transaction committed and let go of the
store's lock: the locks ordered before the store's (docs/architecture.md) are never taken
inside it, listeners and subscribers hear only committed events, and a transaction that
rolls back leaves nothing to observe. The program is the one this knowledge base last
read (what other processes loaded since is read at the next call after the commit).

No stage calls back into an earlier one. A request for decisions that arrives while this
thread is already running the pipeline (a ``StreamClock`` moving while stage 3 observes
the events, a listener of stage 6 setting a ``ManualClock``) does not start a second run
inside the first: it joins the run under way, which goes back to stage 4 before it ends.
An add made by a listener in stage 6 is a new batch: it runs a pipeline of its own, then
the interrupted run goes on. Other threads run the pipeline side by side; the store's
transactions order their writes.

>>> import slr_sql
>>> kb = slr_sql.open(clock=slr_sql.ManualClock(0)); kb.load("c(X) <- a(X) seq b(X).")
>>> seen = []; kb.add_listeners.append(lambda batch: seen.append([e[0] for e in batch]))
>>> kb.add_many(["a(1)^1", "b(1)^2"]); seen
[]
[['a', 'b', 'c']]
"""
from __future__ import annotations

import threading
from collections.abc import Callable
from contextlib import nullcontext
from operator import itemgetter
from typing import TYPE_CHECKING, Any

from .errors import EventRejected, SLRError
from .store import EventBatch, EventStore

if TYPE_CHECKING:
    from .buffers import BufferManager
    from .cep import EventRules
    from .subscriptions import SubscriptionHub
    from .sync import Synchronizer

__all__ = ["EventPipeline", "STAGES", "RETRY_DELAYS", "with_derived"]

Batch = list[Any]   # (name, args, start, end) events, or an EventBatch of them

_first, _second, _fourth = itemgetter(0), itemgetter(1), itemgetter(3)

STAGES = ("marks", "store", "completeness", "decisions", "buffers", "wake")

# Seconds of a wall clock after which a decision round that failed and was not raised is
# tried again: the first, doubled at each failure in a row up to the last (a lock another
# session holds for a minute costs a round a second, not a busy loop).
RETRY_DELAYS = (0.05, 1.0)


class _Run:
    """One pass of the pipeline on one thread: the stage it is in, and whether a request
    for decisions arrived since its decision stage last looked."""

    __slots__ = ("stage", "again", "outer", "stored", "timer", "prune_at")

    def __init__(self, outer: _Run | None, timer: bool = False) -> None:
        self.stage = STAGES[0]
        self.again = False
        self.outer = outer   # the run a listener's own add interrupted on this thread
        self.stored = False  # an add whose events are committed (stage 2 is behind it)
        self.timer = timer   # started by the synchronizer's timer thread
        self.prune_at: float | None = None   # a clock move's tBuffer pruning, for stage 5


def with_derived(stored: Batch, derived: Batch) -> Batch:
    """The events of an add and the complex events it derived, in one batch for stage 6;
    described like the store's EventBatch (each type's earliest and latest end) when the
    add's events were, so that later stages need not walk the whole batch again.

    >>> both = with_derived(EventBatch([("a", (1,), 1.0, 1.0)]), [("c", (1,), 1.0, 2.0)])
    >>> both.ends is None, len(both)
    (True, 2)
    """
    both = EventBatch(stored)
    both.extend(derived)
    ends = getattr(stored, "ends", None)
    if ends is not None:
        ends = dict(ends)
        # column-wise (C loops): one rule round may derive 100,000 events of one type
        names = set(map(_first, derived))
        arities = set(map(len, map(_second, derived)))
        if len(names) == 1 and len(arities) == 1:
            times = list(map(_fourth, derived))
            spans = {(names.pop(), arities.pop()): (min(times), max(times))}
        else:
            spans = {}
            for name, args, _start, end in derived:
                key = (name, len(args))
                span = spans.get(key)
                spans[key] = (end, end) if span is None else (min(span[0], end),
                                                              max(span[1], end))
        for key, (low, high) in spans.items():
            span = ends.get(key)
            ends[key] = (low, high) if span is None else (min(span[0], low), max(span[1], high))
        both.ends = ends
    return both


class EventPipeline:
    """The stages an event goes through (module docstring), over the parts of one knowledge
    base: its store, synchronizer, event rules, buffers, subscription hub, and the
    ``add_listeners`` list of outside observers (called in stage 6)."""

    def __init__(self, store: EventStore, sync: Synchronizer, cep: EventRules,
                 buffers: BufferManager, hub: SubscriptionHub,
                 listeners: list[Callable[[Batch], None]]):
        self.store = store
        self.sync = sync
        self.cep = cep
        self.buffers = buffers
        self.hub = hub
        self.listeners = listeners
        # the run under way on each thread (an entry lives only while its run does)
        self._runs: dict[int, _Run] = {}
        self._retry_delay = 0.0   # the last retry's (0: the last round did not fail)
        sync.progress_hook = self.progress
        buffers.prune_hook = self.prune_after_decisions

    # -- entries ---------------------------------------------------------------------------
    def add(self, events: Batch, atomic: bool,
            on_stored: Callable[[], None] | None = None) -> list[EventRejected]:
        """Stages 1-6 for a batch of ``(name, args, start, end)`` events; returns the
        rejected ones (the marks' first), raises the first when ``atomic``. Inside a
        transaction this thread holds (``kb.store.transaction()``), stages 1 and 2 run in
        it (a savepoint) and stages 3-6 once it committed (module docstring). ``on_stored``
        is called between stages 2 and 3 (outside a transaction: the knowledge base takes
        what its change check read with the add's statement)."""
        inside = self.store.in_transaction_here
        run = self._enter()
        try:
            run.stage = "marks"
            events, marks, mark_errors = self.sync.take_marks(events, atomic)
            run.stage = "store"
            if type(events) is not EventBatch:  # (the store notes each type's end times in it)
                events = EventBatch(events)
            # a batch's marks are stored with its events: the batch whole or not at all
            with self.store.transaction() if marks or inside else nullcontext():
                errors, derived = self._insert(events, atomic)
                if atomic and errors:
                    raise errors[0]
                written = self.sync.store_marks(marks) if marks else None
            rejected = {id(e.event) for e in errors if hasattr(e, "event")}
            stored = [ev for ev in events if id(ev) not in rejected] if rejected else events
            if derived:   # the complex events of this add, with its events
                stored = with_derived(stored, derived)
            if inside:
                self.store.after_commit(lambda: self._committed(stored, written))
            else:
                run.stored = True
                if on_stored is not None:
                    on_stored()
                self._observe(run, stored, written)
        finally:
            self._leave(run)
        return mark_errors + errors if mark_errors else errors

    def _observe(self, run: _Run, stored: Batch, written: Any) -> None:
        """Stages 3-6 of an add whose events (and marks) are committed. A close on another
        thread meanwhile ends them quietly: the add is done (raising would have its caller
        retry it and store the events twice); what is left to decide is decided when the
        store is opened again."""
        try:
            self._observe_committed(run, stored, written)
        except SLRError:
            if not self.store.closed:
                raise

    def _observe_committed(self, run: _Run, stored: Batch, written: Any) -> None:
        run.stage = "completeness"
        self.sync.on_add(stored)
        if written is not None:   # after the events of the same batch are observed
            self.sync.apply_marks(written)
            self.cep.reread_pending()
        self._settle(run, [stored])   # (even empty: the listeners hear every add)

    def _committed(self, stored: Batch, written: Any) -> None:
        """Stages 3-6 of an add made inside a caller's transaction, once it committed."""
        run = self._enter()
        try:
            run.stored = True
            self._observe(run, stored, written)
        finally:
            self._leave(run)

    def mark(self, event_type: Any, t: float) -> None:
        """Stages 3-6 for ``kb.mark_complete(event_type, t)``. Inside a transaction this
        thread holds, the mark is written in it and applied once it committed."""
        if self.store.in_transaction_here:
            written = self.sync.write_mark(event_type, t)
            self.store.after_commit(lambda: self._marked(written))
            return
        run = self._enter()
        try:
            run.stage = "completeness"
            self.sync.mark(event_type, t)
            self.cep.reread_pending()
            self._settle(run, [])
        finally:
            self._leave(run)

    def _marked(self, written: Any) -> None:
        """Stages 3-6 of a mark written inside a caller's transaction, once it committed."""
        run = self._enter()
        try:
            run.stage = "completeness"
            self.sync.apply_marks(written)
            self.cep.reread_pending()
            self._settle(run, [])
        finally:
            self._leave(run)

    def progress(self, timer: bool = False) -> None:
        """Stages 4-6: completeness may have advanced (the clock moved, a timer fired, a
        file was reopened). On a thread already running the pipeline, the request joins
        that run; inside a transaction this thread holds, it runs once that committed.
        ``timer``: the synchronizer's timer thread calls (a round that fails is not raised,
        but tried again later)."""
        run = self._runs.get(threading.get_ident())
        if run is not None:
            run.again = True
            return
        if self.store.in_transaction_here:
            # (also after a rollback: it does not take back the clock's move)
            self.store.after_commit(lambda: self.progress(timer), always=True)
            return
        run = self._enter(timer)
        try:
            self._settle(run, [])
        finally:
            self._leave(run)

    def prune_after_decisions(self, now: float) -> bool:
        """The clock moved to ``now`` while this thread runs the pipeline (a
        ``StreamClock`` moved by the events stage 3 observes, a listener of stage 6 setting
        a ``ManualClock``): the tBuffers' pruning at ``now`` waits for stage 5, after the
        decisions the move allows -- a decision that became possible before the move's end
        chooses among the events it would have found then, as when the clock moves in
        small steps. False when no run is under way here (the clock's listeners then run
        the decisions first: the synchronizer's comes before the buffers').

        >>> import slr_sql
        >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0)); kb._pipeline.prune_after_decisions(1.0)
        False
        """
        run = self._runs.get(threading.get_ident())
        if run is None:
            return False
        run.prune_at = now if run.prune_at is None else max(run.prune_at, now)
        run.again = True
        return True

    def loaded(self) -> None:
        """After a load or unload committed: the timers of the pending decisions of the
        rules it installed (not asked for inside its transaction: the synchronizer's lock
        comes before the store's)."""
        self.cep.wake_if_due()

    def stage(self) -> str | None:
        """The stage this thread's run is in, or None outside the pipeline.

        >>> import slr_sql
        >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0)); seen = []
        >>> kb.add_listeners.append(lambda batch: seen.append(kb._pipeline.stage()))
        >>> kb.add("p(1)^1"); seen, kb._pipeline.stage()
        (['wake'], None)
        """
        run = self._runs.get(threading.get_ident())
        return None if run is None else run.stage

    # -- stages ----------------------------------------------------------------------------
    def _enter(self, timer: bool = False) -> _Run:
        ident = threading.get_ident()
        run = self._runs[ident] = _Run(self._runs.get(ident), timer)
        return run

    def _leave(self, run: _Run) -> None:
        ident = threading.get_ident()
        if run.outer is None:
            self._runs.pop(ident, None)
        else:
            self._runs[ident] = run.outer

    def _insert(self, events: EventBatch, atomic: bool) -> tuple[list[Any], Batch]:
        """Stage 2: store the batch; with event rules, detect in the same transaction."""
        cep = self.cep
        if not (cep.active and events):
            return self.store.add_events(events, atomic=atomic), []
        # the tables the batch and its complex events make: the views made again once
        with self.store.transaction(), self.store.table_batch():
            rounds = cep.rounds(events)
            if len(rounds) == 1:
                token = cep.before_add(events)
                errors = cep.store_events(events, atomic)
                return errors, cep.after_add(token)
            return self._insert_in_rounds(events, rounds, atomic)

    def _insert_in_rounds(self, events: EventBatch, rounds: list[tuple[int, int]],
                          atomic: bool) -> tuple[list[Any], Batch]:
        """Store a batch in consecutive rounds of event-rule detection, inside the caller's
        transaction: a count buffer that a rule's events meet prunes between rounds just as
        between single adds. The batch's errors keep their indices, its ``ends`` cover all."""
        cep = self.cep
        errors: list[Any] = []
        derived: Batch = []
        ends: dict[Any, tuple[float, float]] = {}
        for start, stop in rounds:
            part = EventBatch(events[start:stop])
            token = cep.before_add(part)
            part_errors = cep.store_events(part, atomic)
            for error in part_errors:
                if getattr(error, "index", None) is not None:
                    error.index += start
            if atomic and part_errors:
                raise part_errors[0]   # (rolls the whole batch back)
            errors += part_errors
            derived += cep.after_add(token)
            for key, (lo, hi) in (part.ends or {}).items():
                old = ends.get(key)
                ends[key] = (lo, hi) if old is None else (min(old[0], lo), max(old[1], hi))
        events.ends = ends
        return errors, derived

    def _retry_later(self) -> None:
        """Ask the synchronizer for a retry timer, each failure in a row waiting longer."""
        first, most = RETRY_DELAYS
        delay = min(most, self._retry_delay * 2) if self._retry_delay else first
        self._retry_delay = delay
        self.sync.wake_after(delay)

    def _settle(self, run: _Run, batches: list[Batch]) -> None:
        """Stages 4, 5 and 6; back to 4 when a request for decisions arrived meanwhile."""
        while True:
            run.stage = "decisions"
            self._decide(run, batches)
            run.stage = "buffers"
            if run.prune_at is not None:
                now, run.prune_at = run.prune_at, None
                self.buffers.prune_at(now)
            if batches:
                self.buffers.on_add(batches[0])
            run.stage = "wake"
            listeners = self.listeners
            for batch in batches:
                if listeners:   # (before the hub: a listener may hold up its wake-up)
                    for listener in list(listeners):
                        listener(batch)
                self.hub.on_add(batch)
            if not run.again:
                return
            batches = []

    def _decide(self, run: _Run, batches: list[Batch]) -> None:
        """Stage 4: decision rounds until one derives nothing and nothing asked for another;
        each round's complex events go through stage 3 and join ``batches``."""
        cep = self.cep
        if cep.closed or not cep.active:   # (active: the rules of the stored program)
            run.again = False
            return
        while True:
            run.again = False
            try:
                if not cep.ready(float(cep.clock.now()), run.stored):
                    self._retry_delay = 0.0
                    cep.wake_timers()
                    cep.recheck()
                    return
                derived = cep.decide()
                self._retry_delay = 0.0
                if derived:
                    run.stage = "completeness"
                    self.sync.on_add(derived)
                    run.stage = "decisions"
                    batches.append(derived)
                cep.wake_timers()
                if not derived and not run.again:
                    cep.recheck()
                    return
            except SLRError:
                if self.store.closed:
                    return
                if run.stored or run.timer:
                    # an add whose events are committed: a round it made possible that
                    # fails (busy, a lost connection), or the timers and waiting queries'
                    # reads after it, is not the add's failure -- a retried add would store
                    # them twice. Its decisions stay pending (rolled back whole), made at the
                    # next add, mark, clock move or timer -- and, with a wall clock, by the
                    # retry asked for here (the timer thread's own round, which has no
                    # caller to raise to, too).
                    self._retry_later()
                    return
                raise

