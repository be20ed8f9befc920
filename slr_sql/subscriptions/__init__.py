"""Subscriptions: deliver each stored event matching a pattern, once, in arrival order, to an
iterator, an async iterator or a callback (docs/subscriptions.md).

``sub = kb.subscribe("face(F, R)^T", where="R > 60", since=0)`` is the event-processing
paper's ``register(ID, s_win(since, until, ⟨face(F, R), R > 60⟩))``.

The parts
---------

* :mod:`.queue` — one subscription: its bounded queue of answers, its position, and its
  state (:class:`SubscriptionState`: history, live, lagging, ended, finished, closed), whose
  changes are checked against :data:`TRANSITIONS`.
* :mod:`.hub` — the hub: one thread per knowledge base that reads journals and histories (on
  a connection of its own), matches rows and queues the answers, and wakes the consumers.
* :mod:`.registry` — the durable registry: each subscription's row in ``slr_subscriptions``
  (definition, position, claim of the delivering process) and the journals of the
  subscribed types.
* :mod:`.matching` — patterns and conditions compiled, answers as JSON.

How it works
------------

* **Journal.** While some subscription (of any process) subscribes to event type p/N, an
  ``AFTER INSERT`` trigger on p/N's table copies every new row into ``slr_subj_<table>``,
  whose ``jid`` (never reused) is the arrival order. Events stored by any process, by event
  rules, or by ``INSERT`` statements are journaled in the transaction that stores them, so a
  buffer that prunes an event right after it arrived (``cBuffer(.., 1)``) cannot take it
  away from a subscriber that has not read it yet.
* **Registration** runs in one write transaction: install the trigger, read the type's
  greatest ``seq`` (the history is the stored rows up to it) and the journal's greatest
  ``jid`` (live events are the rows after it). Nothing committed can fall between the two:
  no gap and no duplicate at the seam between history and live.
* **Delivery.** The hub reads the journal of each subscribed type once for all its live
  subscriptions (woken by the last stage of ``kb.add``'s event pipeline, and every
  ``poll_interval`` seconds to see rows other processes committed), matches each row against
  each pattern and condition, and appends the answers to each subscription's bounded queue.
  ``add`` never waits for a subscriber.
* **Slow subscribers.** A subscription whose queue is full becomes *lagging*: it leaves the
  shared read and later reads the journal at its own pace (together with the others behind):
  nothing is dropped. One that falls more than ``max_lag`` events behind ends with
  :class:`SubscriptionOverflow` after its queued answers (the journal would otherwise grow
  without bound).
* **Durable** subscriptions (``id=``) keep their definition and position in
  ``slr_subscriptions``; the position moves when the consumer has taken the next answer (or
  the callback returned), so a restart resumes after the last answer handled, at least once.
* **until** ends a subscription once the type's history is complete up to ``until``
  (completeness as for synchronized queries: a pending ``kb.submit`` of
  ``prev(p(_..)^_, until)`` at ``until`` tells when) and everything stored by then was
  delivered.

This package sits beside sync and buffers: it gets the knowledge base as an object and uses
its public methods (``query``, ``submit``; and the synchronizer's
``watch_external``, so that marks other processes write end an ``until``) and the store's.

>>> import slr_sql
>>> kb = slr_sql.open(clock=slr_sql.ManualClock(0)); sub = kb.subscribe("p(X)^T", since=0)
>>> kb.add("p(a)^1"); sub.get(timeout=5), sub.state
({'X': Atom('a'), 'T': 1.0}, <SubscriptionState.LIVE: 'live'>)
>>> sub.close(); kb.close()
"""
from __future__ import annotations

from ..host import Host
from .hub import DEFAULT_MAX_LAG, DEFAULT_MAX_QUEUE, SubscriptionHub
from .matching import Matcher, answer_json
from .queue import TRANSITIONS, IllegalTransition, Subscription, SubscriptionOverflow, \
    SubscriptionState
from .registry import SubscriptionRegistry, journal_table

__all__ = ["Subscription", "SubscriptionOverflow", "SubscriptionHub", "SubscriptionState",
           "SubscriptionRegistry", "TRANSITIONS", "IllegalTransition", "Matcher", "attach",
           "answer_json", "journal_table", "DEFAULT_MAX_QUEUE", "DEFAULT_MAX_LAG"]


def attach(kb: Host) -> SubscriptionHub:
    """Create the subscription hub of ``kb`` and hook it into its store (the event pipeline
    wakes it after adds).

    >>> import slr_sql
    >>> kb = slr_sql.open(); type(kb._subscriptions).__name__
    'SubscriptionHub'
    >>> kb.close()
    """
    hub = SubscriptionHub(kb)
    kb.store.table_created_hooks.append(hub.on_table_created)
    return hub
