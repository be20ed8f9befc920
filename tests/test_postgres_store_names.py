"""The names the store gives its tables and views are never ``pg_catalog``'s: PostgreSQL
searches ``pg_catalog`` first (always, before the store's schema), and every relation there
starts ``pg_``. An event type or predicate named ``pg_...`` gets a table or view of another
name (``ev_pg_class``, ``v_pg_views``), on SQLite too; named as the catalog's, its events were
refused (``INSERT INTO "pg_class"`` went to the catalog) and a reload of its program dropped
the catalog's view when the store's role was a superuser (docs/schema.md, docs/sql.md)."""
from __future__ import annotations

import pytest

import slr_sql


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
