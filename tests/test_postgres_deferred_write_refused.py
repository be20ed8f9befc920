"""A decision round on PostgreSQL whose deferred write the server refuses midway.

A rule's writes nobody reads (the used rows of a ``chronological`` decision, the provenance
rows, the deletes of decided pending rows) wait and go with its next read; when the server
refuses one, the error surfaces at that later read, after the rule had already found the
next matches in Python. The round is an SLRError and its transaction rolls back wholly; what
the rule found but had not sent belonged to that transaction and must not reach the next
one, and a rule whose decisions were rolled back must make them again. The refusal is a
CHECK constraint another session adds to a rule's used-rows table (the server refusing a
value), dropped again before the next round.
"""
from __future__ import annotations

import psycopg
import pytest

import slr_sql
from slr_sql import ManualClock
from slr_sql.errors import SLRError

CHRONO = ":- consumption(chronological).\nc(X) <- a(X) seq b(X).\n"
EVENTS = ["a(1)^1", "b(1)^2", "a(2)^3", "b(2)^4"]


def _other(url: str) -> psycopg.Connection:
    conn = psycopg.connect(url, autocommit=True)
    conn.execute("SET search_path = slr")
    return conn


def _used_table(other: psycopg.Connection, head: str) -> str:
    key = other.execute("SELECT key FROM slr_cep_rules WHERE head = %s", (head,)).fetchone()[0]
    return f"slr_cep_u_{key}"


def _refuse(other: psycopg.Connection, table: str, tbl: str, seq: int) -> None:
    """The server refuses the used row (tbl, seq) of ``table`` from now on."""
    other.execute(f'ALTER TABLE "{table}" ADD CONSTRAINT refuse '
                  f"CHECK (NOT (tbl = '{tbl}' AND seq = {int(seq)}))")


def _derived(kb, head: str) -> list:
    return sorted((r["X"], r["S"], r["E"]) for r in kb.query(f"{head}(X)^[S, E]"))


def test_a_decision_refused_midway_stores_nothing_and_is_made_once_later(postgres_url):
    """Two chronological terminators decided in one round: the first decision's used rows
    go with the second decision's read and are refused there. The round raises, leaves
    both terminators pending and no complex event; the next round derives each complex
    event once (the first match found by the failed round is not written a second time)."""
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as kb, _other(postgres_url) as other:
        kb.load(CHRONO)
        assert kb.add_many(EVENTS) == []
        used = _used_table(other, "c/1")
        _refuse(other, used, "a", 1)
        kb.mark_complete("a/1", 10)
        with pytest.raises(SLRError, match="refuse"):
            kb.mark_complete("b/1", 10)
        assert other.execute("SELECT count(*) FROM slr_cep_pending").fetchone()[0] == 2
        assert other.execute("SELECT count(*) FROM c").fetchone()[0] == 0
        assert other.execute(f'SELECT count(*) FROM "{used}"').fetchone()[0] == 0
        other.execute(f'ALTER TABLE "{used}" DROP CONSTRAINT refuse')
        kb.mark_complete("b/1", 11)
        assert _derived(kb, "c") == [(1, 1.0, 2.0), (2, 3.0, 4.0)]
        assert other.execute("SELECT count(*) FROM slr_cep_pending").fetchone()[0] == 0


def test_a_rule_whose_decisions_were_rolled_back_makes_them_again(postgres_url):
    """One mark makes two rules' decisions in one round: the first rule decides its
    terminators, the second's deferred write is refused and the round rolls back. The first
    rule's pending rows are back, so it must decide them again at the next round (it had
    taken its pending summary from the rolled-back transaction: nothing pending)."""
    program = CHRONO + "d(X) <- a(X) seq e(X).\n"
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as kb, _other(postgres_url) as other:
        kb.load(program)
        assert kb.add_many(EVENTS + ["e(1)^2", "e(2)^4"]) == []
        _refuse(other, _used_table(other, "d/1"), "e", 1)
        kb.mark_complete("b/1", 10)
        kb.mark_complete("e/1", 10)
        with pytest.raises(SLRError, match="refuse"):
            kb.mark_complete("a/1", 10)   # (both rules' terminators become decidable)
        assert other.execute("SELECT count(*) FROM slr_cep_pending").fetchone()[0] == 4
        assert other.execute("SELECT count(*) FROM c").fetchone()[0] == 0
        other.execute(f'ALTER TABLE "{_used_table(other, "d/1")}" DROP CONSTRAINT refuse')
        kb.mark_complete("a/1", 11)
        assert _derived(kb, "c") == [(1, 1.0, 2.0), (2, 3.0, 4.0)]
        assert _derived(kb, "d") == [(1, 1.0, 2.0), (2, 3.0, 4.0)]
        assert other.execute("SELECT count(*) FROM slr_cep_pending").fetchone()[0] == 0
