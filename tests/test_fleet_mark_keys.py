"""The marks a fleet store keeps per robot have a key of their own whatever '/' the robot's
name and the type's name hold (docs/fleet.md, "Marks"): robot ``r1/x``'s mark of
``seen/2`` and robot ``r1``'s mark of ``'x/seen'/2`` once shared the key
``fleet/mark/r1/x/seen/2``, so a token allowed to push as ``r1/x`` could make the fleet take
r1's history of ``'x/seen'/2`` as complete to a later time. A store of the layout before
(schema version 13) is migrated (0014): its keys rewritten, a key that two robots it knows
may have written dropped. Real files, real PostgreSQL, a real ``slr serve`` with robot
tokens. Also: ``slr fleet status --json`` writes a time that is not finite as
``{"$float": "inf"}``, not as ``Infinity`` (no JSON)."""
from __future__ import annotations

import json
import sqlite3
import subprocess
import sys

import pytest
from service_helpers import ServiceProcess, slr_env

import slr_sql
from slr_sql import fleet
from slr_sql.fleet import _relayed_marks
from slr_sql.shipping import read_fleet_mark_key
from slr_sql.store.schema import migration_scripts


def robot_store(path, robot: str, marks: dict, *events: str) -> str:
    with slr_sql.open(path, robot=robot, clock=slr_sql.ManualClock(1000)) as kb:
        for event in events:
            kb.add(event)
        for event_type, t in marks.items():
            kb.mark_complete(event_type, t)
    return str(path)


def two_robots(tmp_path) -> tuple[str, str]:
    """r1, with events of 'x/seen'/2 complete up to 5, and r1/x, whose marks of seen/2 and
    'x/seen'/2 say 100: the first of these had r1's key of 'x/seen'/2."""
    r1 = robot_store(tmp_path / "r1.db", "r1", {"x/seen/2": 5.0}, "'x/seen'(a, b)^3")
    r1x = robot_store(tmp_path / "r1x.db", "r1/x", {"seen/2": 100.0, "x/seen/2": 100.0})
    return r1, r1x


def fleet_marks(where: str) -> tuple[dict, float | None]:
    """Every robot's marks the fleet store ``where`` keeps, and its own mark of 'x/seen'/2
    (the least of its robots')."""
    with slr_sql.open(where, clock=slr_sql.ManualClock(0)) as kb:
        return _relayed_marks(kb.store, ""), kb.store.meta_get("sync/mark/x/seen/2")


THEIR_OWN = {"r1": {"x/seen/2": 5.0}, "r1/x": {"seen/2": 100.0, "x/seen/2": 100.0}}


@pytest.mark.parametrize("where", ["file", "postgres"])
def test_each_robot_keeps_its_own_mark_whatever_slashes_the_names_hold(tmp_path, where,
                                                                       request):
    central = (request.getfixturevalue("postgres_url") if where == "postgres"
               else str(tmp_path / "central.db"))
    r1, r1x = two_robots(tmp_path)
    assert fleet.push(r1, central).shipped == 1
    assert fleet.push(r1x, central).shipped == 0
    # r1 said 'x/seen'/2 is complete up to 5: neither its mark nor the fleet's moves past it
    assert fleet_marks(central) == (THEIR_OWN, 5.0)


TOKENS_FILE = """\
r1     tok-r1
r1/x   tok-r1x
"""


def test_a_robot_token_cannot_raise_another_robots_mark_through_a_shared_key(tmp_path):
    (tmp_path / "tokens").write_text(TOKENS_FILE)
    r1, r1x = two_robots(tmp_path)
    central = tmp_path / "central.db"
    with ServiceProcess(central, "--token", "full", "--robot-tokens",
                        str(tmp_path / "tokens")) as server:
        for db, token in ((r1, "tok-r1"), (r1x, "tok-r1x")):
            pushed = subprocess.run([sys.executable, "-m", "slr_sql", "--token", token,
                                     "fleet", "push", db, server.url], env=slr_env(),
                                    capture_output=True, text=True, timeout=120)
            assert pushed.returncode == 0, pushed.stderr
    assert fleet_marks(str(central)) == (THEIR_OWN, 5.0)


# -- a fleet store of schema version 13 -------------------------------------------------------

def _as_version_13(where: str, conn) -> None:
    """Rewrite the fleet mark keys of ``conn``'s store as version 13 wrote them
    (``fleet/mark/<robot>/<name>/<arity>``, names as they are; a key two marks share holds
    the greater, as meta_raise kept it) and forget migration 14."""
    p = "%s" if where == "postgres" else "?"
    rows = conn.execute(f"SELECT key, value FROM slr_meta WHERE key LIKE {p}",
                        ("fleet/mark/%",)).fetchall()
    old: dict[str, float] = {}
    for key, value in rows:
        robot, mark = read_fleet_mark_key(key)
        old_key = f"fleet/mark/{robot}/{mark}"
        old[old_key] = max(old.get(old_key, float("-inf")), json.loads(value))
    conn.execute(f"DELETE FROM slr_meta WHERE key LIKE {p}", ("fleet/mark/%",))
    for key, value in old.items():
        conn.execute(f"INSERT INTO slr_meta (key, value) VALUES ({p}, {p})",
                     (key, json.dumps(value)))
    conn.execute("DROP TABLE slr_fleet_retired")   # (version 15's)
    conn.execute("DELETE FROM slr_migrations WHERE number >= 14")
    if where == "file":
        conn.execute("PRAGMA user_version = 13")


def as_version_13(where: str) -> None:
    if where.startswith("postgresql://"):
        import psycopg

        from slr_sql.store.postgres import split_url
        conninfo, schema = split_url(where)
        with psycopg.connect(conninfo, autocommit=True) as conn, conn.transaction():
            conn.execute(f'SET LOCAL search_path = "{schema}"')
            _as_version_13("postgres", conn)
    else:
        conn = sqlite3.connect(where, isolation_level=None)
        try:
            _as_version_13("file", conn)
        finally:
            conn.close()


def keys(where: str) -> dict:
    with slr_sql.open(where, clock=slr_sql.ManualClock(0)) as kb:
        assert kb.store.schema_version() == migration_scripts()[-1][0] == 15
        return kb.store.meta_items("fleet/mark/")


@pytest.mark.parametrize("where", ["file", "postgres"])
def test_a_version_13_fleet_store_gets_keys_of_its_own_per_robot(tmp_path, where, request):
    central = (request.getfixturevalue("postgres_url") if where == "postgres"
               else str(tmp_path / "central.db"))
    r1, r1x = two_robots(tmp_path)
    r2y = robot_store(tmp_path / "r2y.db", "r2/y", {"seen/2": 7.0}, "seen(c, d)^2")
    percent = robot_store(tmp_path / "pc.db", "a%2Fb", {"seen/1": 3.0}, "seen(e)^1")
    plain = robot_store(tmp_path / "r3.db", "r3", {"seen/1": 9.0, "p": 9.0}, "seen(f)^1",
                       "p(g)^1")
    for db in (r1, r1x, r2y, percent, plain):
        fleet.push(db, central)
    as_version_13(central)
    assert keys(central) == {
        # one reading: one segment of robot, one of name
        "fleet/mark/r3/seen/1": 9.0, "fleet/mark/r3/p/*": 9.0,
        "fleet/mark/a%252Fb/seen/1": 3.0,      # (not robot a/b's)
        # r2/y is known here, r2 is not
        "fleet/mark/r2%2Fy/seen/2": 7.0,
        # fleet/mark/r1/x/seen/2 (r1's 'x/seen'/2 or r1/x's seen/2, holding 100) and
        # fleet/mark/r1/x/x/seen/2 (r1/x's 'x/seen'/2 or r1's 'x/x/seen'/2): both robots are
        # known, so they are dropped, not guessed
    }
    # the robots' next pushes bring their marks back, each under its own key
    for db in (r1, r1x):
        fleet.push(db, central)
    marks, mark = fleet_marks(central)
    assert {r: marks[r] for r in THEIR_OWN} == THEIR_OWN
    assert marks["a%2Fb"] == {"seen/1": 3.0}


def test_a_version_13_fleet_mark_key_of_no_known_robot_is_dropped(tmp_path):
    """A relayed mark of a robot the fleet store does not know yet, under a key with more
    than one reading, cannot be told apart: dropped (the relaying store ships it again)."""
    central = str(tmp_path / "central.db")
    slr_sql.open(central).close()
    with slr_sql.open(central) as kb:
        kb.store.meta_raise("fleet/mark/u/v/w/1", 4.0)
        kb.store.meta_raise("fleet/mark/u/w/1", 4.0)
    as_version_13(central)
    assert keys(central) == {"fleet/mark/u/w/1": 4.0}


# -- slr fleet status --json -------------------------------------------------------------------

def test_fleet_status_json_writes_a_time_that_is_not_finite_as_the_cli_does(tmp_path):
    central = str(tmp_path / "central.db")
    fleet.push(robot_store(tmp_path / "r1.db", "r1", {}, "seen(a)^1"), central)
    # (a fleet file edited by hand, or written by another make)
    conn = sqlite3.connect(central, isolation_level=None)
    conn.execute("UPDATE slr_fleet_robots SET contact_at = 9e999, pending = 1, "
                  "head_arrival = 9e999, last_arrival = 0")
    conn.close()
    shown = subprocess.run([sys.executable, "-m", "slr_sql", "fleet", "status", central,
                            "--json"], env=slr_env(), capture_output=True, text=True,
                           timeout=120)
    assert shown.returncode == 0, shown.stderr

    def no_constant(text: str):
        raise AssertionError(f"{text} is no JSON")
    rows = json.loads(shown.stdout, parse_constant=no_constant)
    assert [(r["robot"], r["last_contact"], r["lag_seconds"]) for r in rows] == [
        ("r1", {"$float": "inf"}, {"$float": "inf"})]
