"""A read-only kb.sql on PostgreSQL leaves nothing behind on the connection it ran on: a
session setting it changed (the read-only default, search_path, how floats print) or a
session lock it took does not reach the next statement, a second statement in the same text
is refused, and inside a transaction it may still not write."""
from __future__ import annotations

import threading
import time

import psycopg
import pytest

import slr_sql
from slr_sql import SLRError


@pytest.fixture
def kb(postgres_url):
    with slr_sql.open(postgres_url, clock=slr_sql.ManualClock(10.0)) as store:
        yield store


def _tables_named(kb, prefix: str) -> int:
    return kb.sql("SELECT count(*) FROM pg_tables WHERE tablename LIKE ?", [prefix + "%"])[1][0][0]


def test_a_setting_changed_by_one_statement_does_not_reach_the_next(kb):
    kb.add("seg(cup1)^1")
    kb.sql("SET default_transaction_read_only = off")
    with pytest.raises(SLRError, match="read-only"):
        kb.sql("CREATE TABLE review12_evil(a int)")
    assert _tables_named(kb, "review12_evil") == 0
    kb.sql("SET search_path = public")
    assert kb.sql("SELECT arg1 FROM seg")[1] == [("cup1",)]
    kb.sql("SELECT set_config('extra_float_digits', '-15', false)")
    assert kb.sql("SELECT 0.1::float8 + 0.2::float8 AS f")[1] == [(0.1 + 0.2,)]


def test_a_second_statement_in_the_same_text_is_refused(kb):
    with pytest.raises(SLRError):
        kb.sql("COMMIT; SET default_transaction_read_only = off; COMMIT; "
               "CREATE TABLE review12_evil2(a int)")
    with pytest.raises(SLRError, match="read-only"):
        kb.sql("CREATE TABLE review12_evil2(a int)")
    assert _tables_named(kb, "review12_evil2") == 0


def test_a_session_lock_taken_by_a_read_only_statement_is_let_go(postgres_url):
    with slr_sql.open(postgres_url, clock=slr_sql.ManualClock(10.0)) as kb:
        kb.sql("SELECT pg_advisory_lock(424242)")
        with psycopg.connect(postgres_url, autocommit=True) as other:
            assert other.execute("SELECT pg_try_advisory_lock(424242)").fetchone()[0] is True


def test_inside_a_transaction_a_read_only_statement_writes_nothing(kb):
    kb.add("seg(cup1)^1")
    with kb.store.transaction():
        with pytest.raises(SLRError, match="read-only"):
            kb.sql("DELETE FROM seg")
        kb.sql("SET search_path = public")
        assert kb.sql("SELECT count(*) FROM seg")[1] == [(1,)]
    assert kb.sql("SELECT count(*) FROM seg")[1] == [(1,)]
    kb.add("seg(cup2)^2")
    assert [a["X"] for a in kb.query("seg(X)^T")] == ["cup1", "cup2"]


def test_read_only_statements_of_many_threads_use_a_bounded_number_of_connections(kb):
    from slr_sql.store.postgres import MOST_RUNNING
    # each statement counts the connections to the store's database once it slept
    query = ("WITH s AS MATERIALIZED (SELECT pg_sleep(0.3)) SELECT (SELECT count(*) FROM "
             "pg_stat_activity WHERE datname = current_database() AND backend_type = "
             "'client backend') FROM s")
    counts: list = []
    errors: list = []
    start = threading.Barrier(12)

    def read() -> None:
        try:
            start.wait(60)
            counts.append(kb.sql(query, timeout=60)[1][0][0])
        except Exception as exc:  # noqa: BLE001 - reported by the assertion below
            errors.append(exc)
    threads = [threading.Thread(target=read) for _ in range(12)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(120)
    assert errors == [] and len(counts) == 12
    # the store's own connection, and at most MOST_RUNNING of the statements' own
    assert max(counts) <= 1 + MOST_RUNNING


def test_a_kept_connection_the_server_dropped_meanwhile_is_replaced(kb, postgres_server):
    # (a server restart, idle_session_timeout, an administrator: the next call still answers)
    pid = kb.sql("SELECT pg_backend_pid()")[1][0][0]
    with psycopg.connect(postgres_server[1], autocommit=True) as admin:
        assert admin.execute("SELECT pg_terminate_backend(%s)", (pid,)).fetchone()[0]
        deadline = time.monotonic() + 30
        while admin.execute("SELECT count(*) FROM pg_stat_activity WHERE pid = %s",
                            (pid,)).fetchone()[0]:
            assert time.monotonic() < deadline, "the backend never ended"
            time.sleep(0.01)
    assert kb.sql("SELECT 1 AS one")[1] == [(1,)]


def test_parameter_styles_and_a_percent_sign_still_answer_as_written(kb):
    assert kb.sql("SELECT '100%' AS p")[1] == [("100%",)]
    assert kb.sql("SELECT ? AS p, '5%' AS q", ["50%"])[1] == [("50%", "5%")]
    assert kb.sql("SELECT :a AS p", {"a": 1})[1] == [(1,)]
    with kb.store.transaction():
        assert kb.sql("SELECT '100%' AS p")[1] == [("100%",)]
        assert kb.sql("SELECT ? AS p", ["50%"])[1] == [("50%",)]


def test_a_timeout_of_one_statement_inside_a_transaction_ends_with_it(kb):
    # (it was left as the transaction's statement_timeout: its later statements cancelled)
    before = kb.store.execute("SHOW statement_timeout")
    with kb.store.transaction():
        kb.sql("SELECT 1", write=True, timeout=0.05)
        assert kb.store.execute("SHOW statement_timeout") == before
        kb.sql("SELECT 1", timeout=0.05)
        assert kb.store.execute("SHOW statement_timeout") == before
        kb.add("seg(cup1)^1")
    assert kb.store.count("seg", 1) == 1
