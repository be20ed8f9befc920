"""PostgreSQL: the store's reads of its catalog (the tables, triggers, indexes, views, the
versions) on a closed store say that it is closed, as on SQLite, and open no connection
(the store's connection, closed, would otherwise be opened again by the next statement and
never closed)."""
from __future__ import annotations

import logging
import time

import psycopg
import pytest

from slr_sql.errors import SLRError
from slr_sql.store import EventStore
from slr_sql.store.postgres import PgDatabase

from hub_helpers import DEADLINE, hub_with_one_delivery
from store_conditions import slr_failure
from test_store_read_connection_errors import READS as SQLITE_READS

READS = {**{name: read for name, read in SQLITE_READS.items() if not name.startswith("sql")},
         "changes": lambda db: db.changes(),
         "query_plan": lambda db: db.query_plan("SELECT * FROM slr_meta")}


PROBE = "slr-test-probe"


def _probe(url: str) -> psycopg.Connection:
    """A connection of this test's own, named so that the counts leave it out: a probe's
    backend stays in pg_stat_activity a moment after the probe closed, and the next probe
    counted it as if a read of the closed store had opened a session."""
    return psycopg.connect(url, autocommit=True, application_name=PROBE)


def _sessions(url: str) -> int:
    """The clients connected to the database of ``url``, the test's probes not counted (nor
    the server's own workers: an autovacuum worker visits the database when it will)."""
    with _probe(url) as conn:
        return conn.execute("SELECT count(*) FROM pg_stat_activity WHERE datname = "
                            "current_database() AND backend_type = 'client backend' "
                            "AND application_name <> %s",
                            (PROBE,)).fetchone()[0]


def _session_alive(url: str, pid: int) -> bool:
    with _probe(url) as conn:
        return conn.execute("SELECT count(*) FROM pg_stat_activity WHERE pid = %s",
                            (pid,)).fetchone()[0] > 0


def test_each_catalog_read_of_a_closed_store_says_it_is_closed(postgres_url):
    db = PgDatabase(postgres_url)
    for read in READS.values():
        read(db)   # (works while open)
    pid = db.conn.raw.info.backend_pid
    db.close()
    # (a closed session's backend leaves pg_stat_activity a moment after the close: counted
    # before it has, it made `before` one more than the count after the reads)
    gone = time.monotonic() + DEADLINE
    while _session_alive(postgres_url, pid):
        assert time.monotonic() < gone, "the closed store's session did not end"
        time.sleep(0.01)
    before = _sessions(postgres_url)
    for name, read in READS.items():
        exc = slr_failure(lambda: read(db))
        assert str(exc) == "the event store is closed", name
    assert db.conn.raw.closed and _sessions(postgres_url) == before



def _drop_journal(url: str) -> None:
    """Another session drops the journal of p/1."""
    with psycopg.connect(url, autocommit=True) as other:
        other.execute("DROP TABLE slr.slr_subj_p CASCADE")


@pytest.mark.parametrize("own_connection", [True, False], ids=["own", "store"])
def test_a_journal_another_session_dropped_is_an_slr_error_on_each_reader(postgres_url,
                                                                         own_connection):
    """The subscription hub's journal reads, on a connection of their own or the store's:
    a statement's own error is an SLRError named after it, as on SQLite (it was the
    connection's PgStatementError, and on the store's connection an AttributeError)."""
    store = EventStore(postgres_url)
    reads = None
    try:
        store.add_event("p", ("a",), 1, 1)
        store.create_journal("p", 1, "slr_subj_p", "slr_subt_p")
        reads = store.journal_reader(own_connection)
        assert reads.max_jid("slr_subj_p") == 0
        _drop_journal(postgres_url)
        exc = slr_failure(lambda: reads.max_jid("slr_subj_p"))
        assert type(exc) is SLRError
        # (named with the schema, as the store names a journal another process may drop)
        assert str(exc) == f'{store.path}: the store failed (relation "slr.slr_subj_p" ' \
                           f'does not exist)'
    finally:
        if reads is not None:
            reads.close()
        store.close()


@pytest.mark.parametrize("through_store", [False, True], ids=["own", "store"])
def test_the_hub_logs_a_read_of_a_journal_another_session_dropped_as_one_line(
        postgres_url, caplog, through_store):
    with hub_with_one_delivery(postgres_url, caplog) as (kb, hub, sub):
        _drop_journal(postgres_url)
        hub.notify(through_store=through_store)
        assert hub.drain(DEADLINE)
        assert not [r for r in caplog.records if r.levelno >= logging.ERROR], caplog.text
        [record] = [r for r in caplog.records if "delivery pass failed" in r.getMessage()]
        assert record.levelno == logging.WARNING and record.exc_info is None
        assert f'SLRError: {kb.store.path}: the store failed (relation "slr.slr_subj_p" does ' \
               f'not exist)' in record.getMessage()
        sub.close()
