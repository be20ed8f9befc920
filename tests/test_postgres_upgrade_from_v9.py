"""A store of the schema version before this one's fleet routes and pending-row notifications
(version 9) opens with this slr_sql on PostgreSQL too: migrations pg_0010 and later apply
to it, a robot that shipped rows before keeps its direct route, and the store's connection
hears another session's pending rows afterwards. A store connection that the server dropped
and that was opened again hears them too (the new connection LISTENs again)."""
from __future__ import annotations

import psycopg
import pytest

import slr_sql
from slr_sql import ManualClock, SLRError, fleet
from slr_sql.store import RouteConflict
from slr_sql.store.postgres import split_url
from slr_sql.store.schema import migration_scripts

from test_fleet_routes import robot_store, seen
from test_other_process_pending import BY_DELAY, _add_in_another_process, _c, _heard_of_it
from test_postgres_long_keys import as_version_12


def as_version_9(url: str) -> None:
    """Take a PostgreSQL store back to what schema version 9 wrote: no routes table, no
    notifying trigger on the pending rows (as another client of the database)."""
    as_version_12(url)
    conninfo, schema = split_url(url)
    with psycopg.connect(conninfo, autocommit=True) as conn:
        conn.execute(f'SET search_path = "{schema}"')
        conn.execute("DROP TRIGGER slr_cep_pending_inserted ON slr_cep_pending")
        conn.execute("DROP TRIGGER slr_cep_pending_updated ON slr_cep_pending")
        conn.execute("DROP FUNCTION slr_cep_pending_notify()")
        conn.execute("DROP TABLE slr_fleet_routes")
        conn.execute("DELETE FROM slr_migrations WHERE number >= 10")


def hears_what_another_process_leaves_pending(kb, url: str) -> None:
    """Another process adds events that leave a decision pending: ``kb`` hears of it, and
    its clock moving on decides it."""
    before = kb.store.others_version()
    _add_in_another_process(url, ["a(1)^1", "b(1)^2"])
    _heard_of_it(kb, before)
    assert kb.store.others_version() != before
    kb.clock.set(8.0)
    assert _c(kb) == [(1, 1.0, 2.0)]


def test_a_version_9_fleet_store_on_postgresql_keeps_its_direct_routes(tmp_path,
                                                                        postgres_url):
    r1 = robot_store(tmp_path / "r1.db", "r1", ("seen(a)^10", "seen(b)^20"))
    slr_sql.open(tmp_path / "site.db", robot="site").close()
    site = str(tmp_path / "site.db")
    fleet.push(r1, site)
    assert fleet.push(r1, postgres_url).shipped == 2
    as_version_9(postgres_url)
    with slr_sql.open(postgres_url) as kb:   # (migrates)
        assert kb.store.schema_version() == migration_scripts()[-1][0]  # (numbered as SQLite's)
    with pytest.raises(RouteConflict, match="robot 'r1' ships to this store directly"):
        fleet.push(site, postgres_url)
    assert seen(postgres_url) == [("r1", "a", 10.0), ("r1", "b", 20.0)]
    assert [(r["robot"], r["shipped"], r["via"]) for r in fleet.status(postgres_url)] == [
        ("r1", 2, None)]


def test_a_version_9_store_on_postgresql_hears_other_sessions_after_the_upgrade(
        postgres_url):
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as kb:
        kb.load(BY_DELAY)
    as_version_9(postgres_url)
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as kb:   # (migrates)
        kb.clock.advance(1)
        hears_what_another_process_leaves_pending(kb, postgres_url)


def test_a_connection_opened_again_hears_other_sessions(postgres_url, postgres_server):
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as kb:
        kb.load(BY_DELAY)
        kb.clock.advance(1)
        lost = kb.store._conn.raw.info.backend_pid
        with psycopg.connect(postgres_server[1], autocommit=True) as admin:
            admin.execute("SELECT pg_terminate_backend(%s)", (lost,))
        # the statement that meets the lost connection fails; the next one opens it again
        for _ in range(2):
            try:
                kb.query("a(X)^T")
                break
            except SLRError:
                continue
        assert kb.store._conn.raw.info.backend_pid != lost
        kb.clock.advance(1)                  # (the rules look: what they missed is read)
        hears_what_another_process_leaves_pending(kb, postgres_url)


def _listening(kb) -> list:
    """The channels the store's own connection LISTENs to (asked on that connection)."""
    raw = kb.store._db.conn.raw
    return [row[0] for row in raw.execute("SELECT pg_listening_channels()").fetchall()]


def test_a_store_without_event_rules_never_listens(postgres_url):
    """A listener that reads nothing holds every other session's notifications in the
    server's queue: a store that never looks at other sessions' pending rows (no event rules:
    a reader, a dashboard) does not LISTEN; one with event rules does from its first look."""
    with slr_sql.open(postgres_url, clock=ManualClock(10.0)) as reader:
        reader.add_many(["a(1)^1", "b(1)^2"])
        assert reader.query("a(X)^T") == [{"X": 1, "T": 1.0}]
        reader.clock.advance(1)
        assert _listening(reader) == []
        with slr_sql.open(postgres_url, clock=ManualClock(10.0)) as detector:
            detector.load(BY_DELAY)
            detector.add_many(["a(2)^3"])        # an add looks, after its commit
            assert _listening(detector) == ["slr_pending"]
        assert _listening(reader) == []
