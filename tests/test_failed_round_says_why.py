"""A decision round that fails after an add says why, though the add returns.

The add's events are committed before the decision rounds they make possible (stage 4);
such a round that fails leaves its decisions pending and the add returns (a retried add
would store its events twice). Nothing raises, so the failure must show where a user looks
for a rule's trouble: ``kb.event_rules()``'s ``last_error`` -- else a rule whose statements
keep failing (here the server refuses its used rows) would stay silent for ever.
"""
from __future__ import annotations

import psycopg

import slr_sql
from slr_sql import ManualClock

CHRONO = ":- consumption(chronological).\nc(X) <- a(X) seq b(X).\n"


def test_a_round_that_fails_after_an_add_leaves_its_reason_on_the_rule(postgres_url):
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as kb, \
            psycopg.connect(postgres_url, autocommit=True) as other:
        other.execute("SET search_path = slr")
        kb.load(CHRONO)
        assert kb.add_many(["a(1)^1", "b(1)^2"]) == []
        key = other.execute("SELECT key FROM slr_cep_rules WHERE head = 'c/1'").fetchone()[0]
        used = f"slr_cep_u_{key}"
        other.execute(f'ALTER TABLE "{used}" ADD CONSTRAINT refuse CHECK (tbl <> \'a\')')
        kb.mark_complete("a/1", 10)
        assert kb.event_rules()[0]["last_error"] is None
        assert kb.add_many(["fullyUpdated(b/1)^10"]) == []   # (its round is refused)
        assert other.execute("SELECT count(*) FROM slr_cep_pending").fetchone()[0] == 1
        assert "refuse" in (kb.event_rules()[0]["last_error"] or "")
        other.execute(f'ALTER TABLE "{used}" DROP CONSTRAINT refuse')
        kb.mark_complete("b/1", 11)
        assert [(r["X"], r["S"], r["E"]) for r in kb.query("c(X)^[S, E]")] == [(1, 1.0, 2.0)]
