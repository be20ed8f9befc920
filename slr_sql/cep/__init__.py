"""Event rules: complex event processing over the event store (docs/events.md).

``Head <- Pattern`` derives a complex event -- stored in Head's own event table like any
added event -- whenever stored events match Pattern, a tree of the operators of the
event-processing library (ETALIS): ``seq and par or equals meets during starts finishes``,
``cnot``, ``within`` and ``where``. Each rule is compiled to SQL over the event tables
(:mod:`.sqlgen`) and run in the transaction that stores its completing event
(:mod:`.runtime`); a rule that must read a history (``cnot``, a ``where`` goal reading the
store, the ``recent`` and ``chronological`` policies) decides once that history is complete,
with the completeness of synchronized queries (:mod:`slr_sql.sync`).

* :mod:`.rules` -- reading and checking rules (alternatives, positions, intervals);
* :mod:`.sqlgen` -- the SQL of an alternative (delta statements, policies, negation);
* :mod:`.where` -- ``where`` goals SQL cannot take, run per candidate match;
* :mod:`.runtime` -- rounds, pending decisions, the completeness of complex event types.

>>> import slr_sql
>>> kb = slr_sql.open(clock=slr_sql.ManualClock(0))
>>> kb.load("c(X) <- a(X) seq b(X).")
>>> kb.add_many(["a(1)^1", "b(1)^2", "b(2)^3"])
[]
>>> kb.query("c(X)^[S, E]")
[{'X': 1, 'S': 1.0, 'E': 2.0}]
"""
from __future__ import annotations

import dataclasses
from typing import Any

from ..host import Host
from ..terms import Struct
from .rules import (IGNORED_FACTS, POLICIES, EventRule, check_size, compile_rule,
                    consumption_directive, is_event_rule, is_ignored_fact, order_rules)
from .runtime import EventRules

__all__ = ["attach", "prepare", "check_size", "compile_rule", "consumption_directive", "is_event_rule",
           "is_ignored_fact", "EventRule", "EventRules", "POLICIES", "IGNORED_FACTS"]


def prepare(rules: list[EventRule], consumption: dict, program: Any) -> list[EventRule]:
    """The rules of a program with their policies resolved, in dependency order; raises an
    SLRError for cyclic definitions. ``consumption`` maps a named program to its directives
    (a head name/arity, or None for the program's default, to a policy); each rule takes
    its own program's (:func:`~slr_sql.cep.rules.order_rules`). The rules given are not
    changed (a failed load must leave the loaded program as it was).

    >>> from slr_sql.parser import parse_program
    >>> from slr_sql.program import Program
    >>> rs = [compile_rule(c) for c in parse_program("c(X) <- a(X) seq b(X).")]
    >>> rs[0].program = "main"
    >>> [r.policy for r in prepare(rs, {"main": {None: "recent"}}, Program())]
    ['recent']
    >>> [r.policy for r in prepare(rs, {"other": {None: "recent"}}, Program())]
    ['unrestricted']
    """
    from ..analysis import goal_set

    copies = [dataclasses.replace(rule) for rule in rules]
    reads: dict = {}
    for rule in copies:
        types: set = set()
        for alt in rule.alternatives:
            if not alt.goals:
                continue
            goal = alt.goals[-1]
            for g in reversed(alt.goals[:-1]):
                goal = Struct(",", (g, goal))
            gs = goal_set(program, goal)
            if not gs.unknown:
                types |= set(gs)
        reads[id(rule)] = types
    ordered = order_rules(copies, consumption, reads)
    # the same rule (same text up to variable names, same policy) loaded twice is one rule
    seen: set = set()
    unique = []
    for rule in ordered:
        if rule.key not in seen:
            seen.add(rule.key)
            unique.append(rule)
    return unique


def attach(kb: Host) -> EventRules:
    """Install event rules on a knowledge base (called by KnowledgeBase.__init__, after the
    synchronizer and the planner): the load listener, the hook on new tables, and the rules
    of the program restored from the file (the event pipeline then makes the decisions that
    became possible while the file was closed). Their SQL calls ``slr_cep_cmp`` and
    ``slr_cep_arith`` of :data:`slr_sql.sql_functions.SQL_FUNCTIONS`.

    >>> import slr_sql
    >>> kb = slr_sql.open(); kb.load("c <- a seq b."); type(kb._cep).__name__
    'EventRules'
    """
    eng = EventRules(kb)
    kb.load_listeners.append(eng.on_load)
    kb.store.table_created_hooks.append(eng.on_table)
    eng.sync_rules()
    return eng

