"""PostgreSQL's indexes over texts users choose hold slr_key(text) (migration pg_0013): a
store of the version before (12) is migrated to them and then takes values of any length
there, and the lookups' statements still search those indexes (their plans)."""
from __future__ import annotations

import re

import psycopg

import slr_sql
from slr_sql import ManualClock, fleet
from slr_sql.planner import plan_for
from slr_sql.store.dialect import POSTGRES
from slr_sql.store.postgres import split_url
from slr_sql.store.schema import migration_scripts

from test_long_keys import LONG, OTHER

# what version 12 had where pg_0013 puts keys (the catalog's own names)
_VERSION_12_CATALOG = """
DROP INDEX slr_meta_key, slr_meta_by_key;
ALTER TABLE slr_meta ADD PRIMARY KEY (key);
DROP INDEX slr_event_types_key, slr_event_types_by_name;
ALTER TABLE slr_event_types ADD PRIMARY KEY (name, arity);
DROP INDEX slr_buffers_by_type;
CREATE INDEX slr_buffers_by_type ON slr_buffers (type_name, type_arity) WHERE removed_at IS NULL;
DROP INDEX slr_subscriptions_key, slr_subscriptions_by_id, slr_subscriptions_by_type;
ALTER TABLE slr_subscriptions ADD PRIMARY KEY (id);
CREATE INDEX slr_subscriptions_by_type ON slr_subscriptions (type_name, type_arity);
DROP INDEX slr_program_by_name;
CREATE INDEX slr_program_by_name ON slr_program (name, id);
DROP INDEX slr_fleet_positions_key;
ALTER TABLE slr_fleet_positions ADD PRIMARY KEY (robot, type_name, type_arity);
"""


def _indexes(conn) -> dict[str, str]:
    return dict(conn.execute("SELECT indexname, indexdef FROM pg_indexes "
                             "WHERE schemaname = current_schema()").fetchall())


def as_version_12(url: str) -> None:
    """Take a PostgreSQL store back to what schema version 12 wrote (as another client of
    the database): its indexes over the texts themselves, no slr_key."""
    conninfo, schema = split_url(url)
    with psycopg.connect(conninfo, autocommit=True) as conn, conn.transaction():
        conn.execute(f'SET LOCAL search_path = "{schema}"')
        for name, definition in _indexes(conn).items():
            if "char_length(arg" in definition or "slr_key(arg" in definition:
                conn.execute(f'DROP INDEX "{name}"')   # (the key indexes over arguments)
                if not name.endswith("_k"):
                    conn.execute(re.sub(r" WHERE .*", "", definition))
        conn.execute(_VERSION_12_CATALOG)
        conn.execute("DROP FUNCTION slr_key(text)")
        conn.execute("DROP TABLE slr_fleet_retired")   # (version 15's)
        conn.execute("DELETE FROM slr_migrations WHERE number >= 13")


def test_a_version_12_store_is_migrated_and_then_takes_long_keys(tmp_path, postgres_url):
    robot = tmp_path / "r1.db"
    with slr_sql.open(robot, robot="r1", clock=ManualClock(1000.0)) as kb:
        kb.add_event("seen", ["cup"], 10.0)
    with slr_sql.open(postgres_url, clock=ManualClock(10.0)) as kb:
        kb.load(":- max_delay(a/2, 0).\n:- max_delay(b/2, 0).\nc(X) <- a(_, X) seq b(_, X).\n",
                name="rules")
        kb.add_many(["e(cup, 1)^1.0", "a(1, cup)^1.0", "b(2, cup)^2.0"])
        with kb.subscribe("e(X, N)^T", id="watcher", since=0) as sub:
            assert sub.get(timeout=30) == {"X": "cup", "N": 1, "T": 1.0}
        kb.mark_complete("e/2", 5.0)
    assert fleet.push(str(robot), postgres_url).shipped == 1
    as_version_12(postgres_url)
    conninfo, schema = split_url(postgres_url)
    with psycopg.connect(conninfo, autocommit=True) as conn:
        conn.execute(f'SET search_path = "{schema}"')
        old = _indexes(conn)
    assert "slr_key" not in " ".join(old.values())
    assert "(arg1, t_end, t_start)" in old["slr_ix__e__a1_end"]
    assert "(arg2, t_end, t_start)" in old["slr_cep_ix__b__arg2_end"]

    with slr_sql.open(postgres_url, clock=ManualClock(10.0)) as kb:   # (migrates)
        assert kb.store.schema_version() == migration_scripts()[-1][0] == 15
        # what was stored answers as before
        assert kb.query("e(X, N)^T") == [{"X": "cup", "N": 1, "T": 1.0}]
        assert [a["S"] for a in kb.query("c(X)^[S, E]")] == [1.0]
        assert kb.complete_until("e/2") == 5.0
        # and long texts go where the old indexes refused them
        kb.add_many([("e", [LONG, 2], 2.0, 2.0), ("a", [3, LONG], 3.0, 3.0),
                     ("b", [4, LONG], 4.0, 4.0), ("t" + LONG, [1], 4.0, 4.0)])
        assert [a["N"] for a in kb.query(f"prev(e('{LONG}', N)^T, 9)")] == [2]
        assert [a["X"] == LONG for a in kb.query("c(X)^[S, E]")] == [False, True]
        kb.mark_complete(f"t{LONG}/1", 5.0)
        kb.load("p(1).\n", name=LONG)
        with kb.subscribe("e(X, N)^T", id="watcher", since=0) as sub:   # (resumes)
            assert sub.get(timeout=30)["N"] == 2
        with kb.subscribe("e(X, N)^T", id=LONG, since=0) as sub:
            assert sub.get(timeout=30)["N"] == 1
    with slr_sql.open(robot, robot="r1", clock=ManualClock(1000.0)) as kb:
        kb.add_event("s" + OTHER, [1], 20.0)
    assert fleet.push(str(robot), postgres_url).shipped == 1
    with psycopg.connect(conninfo, autocommit=True) as conn:
        conn.execute(f'SET search_path = "{schema}"')
        new = _indexes(conn)
    assert new["slr_ix__e__a1_end"].endswith(
        "(arg1, t_end, t_start) WHERE (char_length(arg1) < 64)")
    assert new["slr_ix__e__a1_end_k"].endswith("(slr_key(arg1), t_end, t_start)")
    assert new["slr_cep_ix__b__arg2_end_k"].endswith("(slr_key(arg2), t_end, t_start)")
    for name, definition in new.items():   # a B-tree over an argument's text holds short ones
        if re.search(r"USING btree \((arg\d|.*, arg\d)", definition.split(" WHERE ")[0]):
            assert re.search(r" WHERE \(char_length\(arg\d\) < 64\)$", definition), definition


def _plan_of(url: str, sql: str, params) -> str:
    conninfo, schema = split_url(url)
    with psycopg.connect(conninfo, autocommit=True) as conn:
        conn.execute(f'SET search_path = "{schema}"')
        conn.execute("ANALYZE")
        return "\n".join(row[0] for row in conn.execute(
            "EXPLAIN " + POSTGRES.statement(sql), params).fetchall())


def test_lookups_by_the_first_argument_search_its_index(postgres_url):
    """A store's prev lookup and compiled goals with the first argument bound read the
    partial index over short first arguments backwards from the time, from the index
    alone, as they read the one over arg1 before; a long first argument is read through
    the index over slr_key(arg1)."""
    with slr_sql.open(postgres_url, clock=ManualClock(1e6)) as kb:
        kb.load(":- max_delay(seg/2, 0).\n")
        kb.add_many([("seg", [f"o{i % 200}" if i % 400 else LONG, i], float(i), float(i))
                     for i in range(20_000)])
        # (read in pages: the first of 8 rows)
        lookup = kb.store.lookup_sql("prev", "seg", 2, {0: "o5"}) + " LIMIT 8"
        assert lookup.count("?") == 2
        plan = _plan_of(postgres_url, lookup, ["o5", 9000.0])
        assert re.search(r"Index (Only )?Scan Backward using slr_ix__seg__a1_end ", plan), plan
        for goal in ("prev(seg(o5, N)^T, 9000)", "seg(o5, N)^T, N > 8000"):
            entry = plan_for(kb, kb.plans.plan(goal, ()), False)
            plan = _plan_of(postgres_url, entry.sql, entry.params)
            assert "slr_ix__seg__a1_end " in plan, (goal, plan)
        entry = plan_for(kb, kb.plans.plan(f"prev(seg('{LONG}', N)^T, 9000)", ()), False)
        plan = _plan_of(postgres_url, entry.sql, entry.params)
        assert "slr_ix__seg__a1_end_k " in plan, plan
