"""PostgreSQL: the store's statements reach its own objects, whatever else the search path
holds. The store's connections search ``pg_catalog`` (always, first), then the store's
schema, then ``pg_temp`` (named last).

So a name the store gives must not be one of ``pg_catalog``'s (every relation there starts
``pg_``): an event type or predicate named ``pg_...`` gets a table or view of another name
(``ev_pg_class``, ``v_pg_views``), on SQLite too; named as the catalog's, its events were
refused (``INSERT INTO "pg_class"`` went to the catalog) and a reload of its program dropped
the catalog's view when the store's role was a superuser.

And where the store names one of its objects that may be missing (a journal another process
dropped, a view a user dropped), it names it with its schema: unqualified, the name would
reach on to a temporary table or view a ``kb.sql(..., write=True)`` made on the store's
connection (``DROP TABLE IF EXISTS`` dropped it, a trim emptied it, a read answered its
rows, ``DROP VIEW IF EXISTS`` failed on a temporary table) (docs/sql.md, docs/schema.md)."""
from __future__ import annotations

import psycopg
import psycopg.sql
import pytest

import slr_sql
from slr_sql import SLRError


@pytest.fixture
def kb(postgres_url):
    with slr_sql.open(postgres_url, clock=slr_sql.ManualClock(10.0)) as kb:
        kb.add("p(a)^1")
        yield kb


def temporary(kb, name: str) -> list:
    """The rows of the temporary table or view ``name`` on the store's connection."""
    return kb.sql(f'SELECT * FROM pg_temp."{name}" ORDER BY 1', write=True)[1]


def test_a_temporary_table_named_as_a_journal_another_process_dropped_is_left_alone(
        kb, postgres_url):
    table = kb.store.table_for("p", 1)
    journal, trigger = f"slr_subj_{table}", f"slr_subt_{table}"
    kb.store.create_journal(table, 1, journal, trigger)
    kb.add("p(b)^2")
    # another process drops the journal (its trim: no subscription wants p/1 any more)
    with slr_sql.open(postgres_url, clock=slr_sql.ManualClock(10.0)) as other:
        other.store.drop_journal(table, journal, trigger)
    kb.sql(f'CREATE TEMP TABLE "{journal}" (jid bigint, seq bigint, arg1 text, '
           f't_start float8, t_end float8)', write=True)
    kb.sql(f"INSERT INTO pg_temp.\"{journal}\" VALUES (1, 1, 'mine', 0, 0)", write=True)
    # this process's trim, with the journal it listed before the other's drop (the store's
    # SLRError in words, as a read of the journal says it; as without a temporary table)
    with pytest.raises(SLRError, match="does not exist"):
        kb.store.trim_journal(journal, 10)
    with pytest.raises(SLRError, match="does not exist"):
        kb.store.journal_reader(own_connection=False).journal_rows(journal, 1, 0, 10)
    with pytest.raises(SLRError, match="does not exist"):
        kb.store.journal_reader(own_connection=True).max_jid(journal)
    kb.store.drop_journal(table, journal, trigger)
    assert temporary(kb, journal) == [(1, 1, "mine", 0.0, 0.0)]
    # the store goes on: a new journal is the store's, the temporary table stays the user's
    kb.store.create_journal(table, 1, journal, trigger)
    kb.add("p(c)^3")
    assert kb.store.journal_reader(own_connection=False).journal_rows(journal, 1, 0, 10) \
        == [(1, 3, "c", 3.0, 3.0)]
    assert temporary(kb, journal) == [(1, 1, "mine", 0.0, 0.0)]


@pytest.mark.parametrize("temporary_journal", [False, True])
def test_another_clients_insert_reaches_the_journal_whatever_its_search_path(
        kb, postgres_url, temporary_journal):
    # another client of the database, with the server's default search path ("$user",
    # public: pg_temp searched first, the store's schema not at all), writes an event
    sub = kb.subscribe("p(X)^T", since=0)
    assert sub.get(timeout=10) == {"X": "a", "T": 1.0}
    journal = f"slr_subj_{kb.store.table_for('p', 1)}"
    with psycopg.connect(postgres_url, autocommit=True) as other:
        if temporary_journal:
            other.execute(f'CREATE TEMP TABLE "{journal}" (LIKE slr."{journal}")')
        other.execute("INSERT INTO slr.p (arg1, t_start, t_end, arrival) "
                      "VALUES ('b', 2, 2, 2)")
        if temporary_journal:
            assert other.execute(f'SELECT count(*) FROM pg_temp."{journal}"').fetchone() \
                == (0,)
    assert sub.get(timeout=10) == {"X": "b", "T": 2.0}
    sub.close()


@pytest.mark.parametrize("temporary_tables", [False, True])
def test_another_clients_insert_is_buffered_whatever_its_search_path(
        kb, postgres_url, temporary_tables):
    # docs/buffers.md: rows another tool inserts run the buffer's triggers too
    kb.add("p(b)^2")
    buffer = kb.add_buffer("p(_)", keep_last=2)
    with psycopg.connect(postgres_url, autocommit=True) as other:
        if temporary_tables:
            for table in ("p", "slr_counters"):
                other.execute(f"CREATE TEMP TABLE {table} AS SELECT * FROM slr.{table}")
        other.execute("INSERT INTO slr.p (arg1, t_start, t_end, arrival) "
                      "VALUES ('c', 3, 3, 3)")
        if temporary_tables:
            assert other.execute("SELECT arg1 FROM pg_temp.p ORDER BY seq").fetchall() \
                == [("a",), ("b",)]
            assert other.execute("SELECT pruned FROM pg_temp.slr_counters").fetchall() \
                == [(0,)]
    assert [a["X"] for a in kb.query("p(X)^_")] == ["b", "c"]
    assert kb.sql("SELECT pruned FROM slr_counters WHERE buffer_id = ?", (buffer,))[1] \
        == [(1,)]


def test_a_buffers_functions_made_by_an_older_version_get_the_stores_search_path(
        postgres_url):
    with slr_sql.open(postgres_url, clock=slr_sql.ManualClock(10.0)) as kb:
        kb.add("p(a)^1")
        kb.add_buffer("p(_)", keep_last=2)
    # as an older slr_sql left them: no search path of their own, their statements as the
    # comments (what a reopen compares)
    with psycopg.connect(postgres_url, autocommit=True) as other:
        functions = other.execute(
            "SELECT p.proname, obj_description(p.oid, 'pg_proc') FROM pg_proc p JOIN "
            "pg_namespace n ON n.oid = p.pronamespace WHERE n.nspname = 'slr' "
            "AND p.proname LIKE 'slr\\_buf\\_%'").fetchall()
        assert functions
        for name, statement in functions:
            older = statement.replace(' SET search_path = "slr", pg_temp', "")
            assert older != statement
            other.execute(f'ALTER FUNCTION slr."{name}"() RESET search_path')
            other.execute(f"COMMENT ON FUNCTION slr.\"{name}\"() IS "
                          f"{psycopg.sql.quote(older)}")
    with slr_sql.open(postgres_url, clock=slr_sql.ManualClock(10.0)):
        pass
    with psycopg.connect(postgres_url, autocommit=True) as other:
        assert other.execute(
            "SELECT DISTINCT p.proconfig FROM pg_proc p JOIN pg_namespace n ON "
            "n.oid = p.pronamespace WHERE n.nspname = 'slr' AND p.proname LIKE "
            "'slr\\_buf\\_%'").fetchall() == [(['search_path=slr, pg_temp'],)]


@pytest.mark.parametrize("made", [
    "CREATE TEMP VIEW colour AS SELECT 'mine'::text AS arg1",
    "CREATE TEMP TABLE colour AS SELECT 'mine'::text AS arg1",
])
def test_a_temporary_object_named_as_a_dropped_view_survives_the_next_load(kb, made):
    kb.load("colour(red).")
    assert kb.sql("SELECT arg1 FROM colour")[1] == [("red",)]
    kb.sql("DROP VIEW colour", write=True)
    kb.sql(made, write=True)
    kb.load("colour(blue).", replace=True)
    assert temporary(kb, "colour") == [("mine",)]
    # (a read-only statement runs on a connection of its own: no temporary object there)
    assert kb.sql("SELECT arg1 FROM colour")[1] == [("blue",)]
    assert [a["X"] for a in kb.query("colour(X)")] == ["blue"]


def test_a_temporary_index_named_as_a_buffers_index_survives_the_buffers_removal(kb):
    # (a guard: the store drops a buffer's objects it has just listed in its schema, under
    # its lock, so the search order alone finds its own index first)
    kb.add("face(ann, 1)^2")
    buffer = kb.add_buffer("face(P, _)", keep_last=1)
    index = f"slr_bix_{buffer}"
    kb.sql("CREATE TEMP TABLE mine (x int)", write=True)
    kb.sql(f'CREATE INDEX "{index}" ON pg_temp.mine (x)', write=True)
    kb.remove_buffer(buffer)
    assert kb.sql("SELECT to_regclass(?)::text", (f"pg_temp.{index}",), write=True)[1] \
        == [(index,)]
    assert kb.sql("SELECT count(*) FROM pg_indexes WHERE indexname = ? "
                  "AND schemaname = current_schema()", (index,))[1] == [(0,)]


@pytest.mark.parametrize("name", ["pg_class", "pg_settings", "pg_robot"])
def test_an_event_type_named_as_a_system_catalog_has_a_table_of_its_own(backend, name):
    with slr_sql.open(backend, clock=slr_sql.ManualClock(10.0)) as kb:
        kb.add(f"{name}(a)^1")
        kb.add(f"{name}(b)^2")
        assert [a["X"] for a in kb.query(f"{name}(X)^_")] == ["a", "b"]
        assert kb.store.table_for(name, 1) == f"ev_{name}"
    with slr_sql.open(backend, clock=slr_sql.ManualClock(10.0)) as kb:
        assert [a["X"] for a in kb.query(f"{name}(X)^_")] == ["a", "b"]


def test_a_predicate_named_as_a_system_view_has_a_view_of_its_own(backend):
    with slr_sql.open(backend, clock=slr_sql.ManualClock(10.0)) as kb:
        kb.load("pg_views(a). pg_tables(b).")
        kb.load("pg_views(c). pg_tables(d).", replace=True)
        assert kb.sql("SELECT arg1 FROM v_pg_views")[1] == [("c",)]
        assert kb.sql("SELECT arg1 FROM v_pg_tables")[1] == [("d",)]
        assert [a["X"] for a in kb.query("pg_views(X)")] == ["c"]
