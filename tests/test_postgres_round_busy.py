"""PostgreSQL: an event-rule round whose later statements meet another session's locks, or
lose the connection, after the add's rows and the rule's first writes were sent.

The writer group's lock and the watermarks go first; the rule's copy into the complex type's
table, and a decision round's writes to ``slr_cep_pending``, go later in the same
transaction. Another session holding those tables (a lock another tool takes) makes that
later statement wait ``busy_timeout`` and the add SLRBusy -- retryable, nothing of it
stored -- and the same call, once the lock is gone, stores and derives once. A connection
lost inside the rule's statements is an SLRError with nothing half-stored; the next add
works on a new connection.
"""
from __future__ import annotations

import psycopg
import pytest

import slr_sql
from slr_sql import ManualClock
from slr_sql.errors import SLRBusy, SLRError


def _program(policy: str) -> str:
    return f":- consumption({policy}).\n:- max_delay(a/1, 0).\n:- max_delay(b/1, 0).\n" \
           "c(X) <- a(X) seq b(X).\n"


def _other(url: str, autocommit: bool = False) -> psycopg.Connection:
    conn = psycopg.connect(url, autocommit=autocommit)
    conn.execute("SET search_path = slr")
    return conn


def _counts(url: str) -> tuple:
    with _other(url, autocommit=True) as conn:
        return tuple(conn.execute(f"SELECT count(*) FROM {t}").fetchone()[0]
                     for t in ("a", "b", "c", "slr_cep_pending"))


@pytest.mark.parametrize("policy", ["unrestricted", "recent", "chronological"])
def test_a_copy_into_a_locked_complex_table_is_busy_and_stores_nothing(postgres_url, policy):
    with slr_sql.open(postgres_url, clock=ManualClock(10.0), busy_timeout=0.3) as kb:
        kb.load(_program(policy))
        kb.add_many(["a(1)^1", "b(1)^2"])
        assert _counts(postgres_url) == (1, 1, 1, 0)
        with _other(postgres_url) as other:
            other.execute("LOCK TABLE c IN SHARE MODE")   # (reads go on, writes wait)
            with pytest.raises(SLRBusy, match="locked"):
                kb.add_many(["a(2)^3", "b(2)^4"])
            assert _counts(postgres_url) == (1, 1, 1, 0)
            other.rollback()
        kb.add_many(["a(2)^3", "b(2)^4"])
        assert _counts(postgres_url) == (2, 2, 2, 0)
        assert sorted((r["X"], r["S"], r["E"]) for r in kb.query("c(X)^[S, E]")) == \
            [(1, 1.0, 2.0), (2, 3.0, 4.0)]


def _pending_table(other: psycopg.Connection) -> str:
    return "slr_cep_pending"


def _used_rows_table(other: psycopg.Connection) -> str:
    key = other.execute("SELECT key FROM slr_cep_rules").fetchone()[0]
    return f'"slr_cep_u_{key}"'


@pytest.mark.parametrize("policy, locked", [("recent", _pending_table),
                                            ("chronological", _pending_table),
                                            ("chronological", _used_rows_table)])
def test_a_decision_round_meeting_a_locked_table_is_busy_then_decides_once(postgres_url,
                                                                          policy, locked):
    """Terminators kept pending (the clock behind them); the clock's move decides them, but
    another session holds a table the round writes: ``slr_cep_pending``, or (chronological)
    the used-rows table, whose rows from the first decision wait and go with the second
    decision's read. The round is SLRBusy and stores nothing; the next move of the clock
    derives each complex event once (the match the busy round had found is not written
    again)."""
    clock = ManualClock(0.0)
    with slr_sql.open(postgres_url, clock=clock, busy_timeout=0.3) as kb:
        kb.load(_program(policy))
        kb.add_many(["a(1)^1", "b(1)^2", "a(2)^3", "b(2)^4"])
        # (recent keeps an add's terminators, none complete yet, as one span)
        kept = (2, 2, 0, 1 if policy == "recent" else 2)
        assert _counts(postgres_url) == kept
        with _other(postgres_url) as other:
            other.execute(f"LOCK TABLE {locked(other)} IN SHARE MODE")
            with pytest.raises(SLRBusy, match="locked"):
                clock.set(10.0)
            assert _counts(postgres_url) == kept
            other.rollback()
        clock.set(11.0)
        assert _counts(postgres_url) == (2, 2, 2, 0)
        assert sorted((r["X"], r["S"], r["E"]) for r in kb.query("c(X)^[S, E]")) == \
            [(1, 1.0, 2.0), (2, 3.0, 4.0)]


def test_a_connection_lost_inside_the_rules_statements_stores_nothing(postgres_url):
    """The server ends the store's connection while it runs the rule's copy (a trigger
    another session put on the complex type's table ends its own backend): the add is an
    SLRError, none of its events, matches or pending rows stored; once the trigger is gone
    the next add reconnects and derives."""
    with slr_sql.open(postgres_url, clock=ManualClock(10.0)) as kb:
        kb.load(_program("unrestricted"))
        kb.add_many(["a(1)^1", "b(1)^2"])
        with _other(postgres_url, autocommit=True) as other:
            other.execute("CREATE FUNCTION slr_test_die() RETURNS trigger LANGUAGE plpgsql "
                          "AS $$ BEGIN PERFORM pg_terminate_backend(pg_backend_pid()); "
                          "PERFORM pg_sleep(5); RETURN NEW; END $$")
            other.execute("CREATE TRIGGER die BEFORE INSERT ON c "
                          "FOR EACH ROW EXECUTE FUNCTION slr_test_die()")
            with pytest.raises(SLRError):
                kb.add_many(["a(2)^3", "b(2)^4"])
            assert _counts(postgres_url) == (1, 1, 1, 0)
            other.execute("DROP TRIGGER die ON c")
        kb.add_many(["a(3)^5", "b(3)^6"])
        assert _counts(postgres_url) == (2, 2, 2, 0)
        assert sorted((r["X"], r["S"], r["E"]) for r in kb.query("c(X)^[S, E]")) == \
            [(1, 1.0, 2.0), (3, 5.0, 6.0)]


def test_a_rule_decided_in_a_round_another_rule_made_busy_decides_again(postgres_url):
    """One clock move makes the decisions of two rules: the first decides its terminators,
    the second meets a lock on its used-rows table and the round rolls back. The first
    rule's pending rows are back: the next move decides them (not left pending for good
    because that rule had read its pending summary inside the rolled-back round)."""
    clock = ManualClock(0.0)
    program = _program("chronological") + ":- max_delay(e/1, 0).\nd(X) <- a(X) seq e(X).\n"
    with slr_sql.open(postgres_url, clock=clock, busy_timeout=0.3) as kb:
        kb.load(program)
        kb.add_many(["a(1)^1", "b(1)^2", "e(1)^2", "a(2)^3", "b(2)^4", "e(2)^4"])
        with _other(postgres_url) as other:
            key = other.execute("SELECT key FROM slr_cep_rules WHERE head = 'd/1'").fetchone()[0]
            other.execute(f'LOCK TABLE "slr_cep_u_{key}" IN SHARE MODE')
            with pytest.raises(SLRBusy, match="locked"):
                clock.set(10.0)
            assert _counts(postgres_url) == (2, 2, 0, 4)
            other.rollback()
        clock.set(11.0)
        assert _counts(postgres_url) == (2, 2, 2, 0)
        for head in ("c", "d"):
            assert sorted((r["X"], r["S"], r["E"]) for r in kb.query(f"{head}(X)^[S, E]")) \
                == [(1, 1.0, 2.0), (2, 3.0, 4.0)]


def test_a_rule_statement_cancelled_by_the_server_is_an_slr_error_and_stores_nothing(
        postgres_url):
    """The server cancels the rule's copy (``statement_timeout`` of the database, a slow
    trigger another session put on the complex type's table): an SLRStatementTimeout (the
    server's setting, not the call's own timeout, and no condition a retry would pass),
    nothing of the add stored, and the next add, once the trigger is gone, derives."""
    from slr_sql.errors import SLRStatementTimeout
    with _other(postgres_url, autocommit=True) as admin:
        database = admin.execute("SELECT current_database()").fetchone()[0]
        admin.execute(f'ALTER DATABASE "{database}" SET statement_timeout = 300')
    with slr_sql.open(postgres_url, clock=ManualClock(10.0)) as kb:
        kb.load(_program("unrestricted"))
        kb.add_many(["a(1)^1", "b(1)^2"])
        with _other(postgres_url, autocommit=True) as other:
            other.execute("CREATE FUNCTION slr_test_slow() RETURNS trigger LANGUAGE plpgsql "
                          "AS $$ BEGIN PERFORM pg_sleep(2); RETURN NEW; END $$")
            other.execute("CREATE TRIGGER slow BEFORE INSERT ON c "
                          "FOR EACH ROW EXECUTE FUNCTION slr_test_slow()")
            with pytest.raises(SLRStatementTimeout, match="due to statement timeout"):
                kb.add_many(["a(2)^3", "b(2)^4"])
            assert _counts(postgres_url) == (1, 1, 1, 0)
            other.execute("DROP TRIGGER slow ON c")
        kb.add_many(["a(3)^5", "b(3)^6"])
        assert _counts(postgres_url) == (2, 2, 2, 0)
