"""PostgreSQL: the store's reads of its catalog (the tables, triggers, indexes, views, the
versions) on a closed store say that it is closed, as on SQLite, and open no connection
(the store's connection, closed, would otherwise be opened again by the next statement and
never closed)."""
from __future__ import annotations

import psycopg

from slr_sql.store.postgres import PgDatabase

from test_store_read_connection_errors import _failure

READS = {
    "data_version": lambda db: db.data_version(),
    "schema_version": lambda db: db.schema_version(),
    "table_names": lambda db: db.table_names(),
    "triggers": lambda db: db.triggers("p"),
    "index_names": lambda db: db.index_names("p"),
    "object_names": lambda db: db.object_names(),
    "view_statements": lambda db: db.view_statements(["v"]),
    "changes": lambda db: db.changes(),
    "query_plan": lambda db: db.query_plan("SELECT * FROM slr_meta"),
}


def _sessions(url: str) -> int:
    """The sessions connected to the database of ``url`` (this one's not counted)."""
    with psycopg.connect(url, autocommit=True) as conn:
        return conn.execute("SELECT count(*) FROM pg_stat_activity WHERE datname = "
                            "current_database() AND pid <> pg_backend_pid()").fetchone()[0]


def test_each_catalog_read_of_a_closed_store_says_it_is_closed(postgres_url):
    db = PgDatabase(postgres_url)
    for read in READS.values():
        read(db)   # (works while open)
    db.close()
    before = _sessions(postgres_url)
    for name, read in READS.items():
        exc = _failure(lambda: read(db))
        assert str(exc) == "the event store is closed", name
    assert db.conn.raw.closed and _sessions(postgres_url) == before

