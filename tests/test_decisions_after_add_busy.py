"""An add whose events completed other decisions, when those decisions meet a busy store.

Stage 2 of the event pipeline commits the add's events (and its own rule round); stage 4
then makes, each round in a transaction of its own, the pending decisions the add made
possible. When that later round is SLRBusy (another session holds ``slr_cep_pending``) the
add has stored its events already: raising SLRBusy from it invites a retry that stores them
twice. The add returns; the decisions stay pending and are made at the next progress.
"""
from __future__ import annotations

import psycopg

import slr_sql
from slr_sql import ManualClock

PROGRAM = (":- consumption(recent).\n:- in_order(a/1).\n:- max_delay(a/1, 1000).\n"
           ":- max_delay(b/1, 0).\n"
           "c(X) <- a(X) seq b(X).\n")


def test_an_add_is_not_failed_by_the_decisions_it_made_possible(postgres_url):
    clock = ManualClock(10.0)
    with slr_sql.open(postgres_url, clock=clock, busy_timeout=0.3) as kb:
        kb.load(PROGRAM)
        heard: list = []
        kb.add_listeners.append(lambda batch: heard.append([e[0] for e in batch]))
        assert kb.add_many(["a(1)^1", "b(1)^2"]) == []   # (b waits: a is in order)
        assert kb.query("c(X)^[S, E]") == []
        with psycopg.connect(postgres_url) as other:
            other.execute("LOCK TABLE slr.slr_cep_pending IN SHARE MODE")
            assert kb.add("a(5)^5") is None     # completes a up to 2: the round is busy
            other.rollback()
        assert kb.store.count("a", 1) == 2
        assert heard[-1] == ["a"]               # (the listeners heard the add)
        clock.set(11.0)                         # the next progress decides
        assert kb.query("c(X)^[S, E]") == [{"X": 1, "S": 1.0, "E": 2.0}]
