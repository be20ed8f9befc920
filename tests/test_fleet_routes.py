"""One route per robot (docs/fleet.md, "One route per robot"): a fleet store keeps its
positions per shipping robot, so rows of robot r1 that reached it directly (r1 pushes to it)
and again relayed by a site store (r1 pushes to the site too, the site pushes on) would be
stored twice. The fleet store keeps, per robot whose rows it holds, the one store they come
through (the robot itself, or the store relaying them) and refuses rows of that robot
through any other, whichever came first, with the reason; `slr fleet status` lists the
relayed robots with the store they come through."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest
from service_helpers import ServiceProcess, slr_env

import slr_sql
from slr_sql import SLRError, fleet
from slr_sql.store import RouteConflict


def robot_store(path, robot: str, events: tuple) -> str:
    with slr_sql.open(path, robot=robot, clock=slr_sql.ManualClock(1000)) as kb:
        for event in events:
            kb.add(event)
    return str(path)


def seen(where) -> list[tuple]:
    with slr_sql.open(where, clock=slr_sql.ManualClock(0)) as kb:
        return sorted((a["R"], str(a["X"]), a["T"])
                      for a in kb.query("origin(R, seen(X)^T)"))


@pytest.fixture
def robots(tmp_path):
    """r1 and r2 push to a site store named 'site'."""
    r1 = robot_store(tmp_path / "r1.db", "r1", ("seen(a)^10", "seen(b)^20"))
    r2 = robot_store(tmp_path / "r2.db", "r2", ("seen(c)^15",))
    slr_sql.open(tmp_path / "site.db", robot="site").close()
    site = str(tmp_path / "site.db")
    for path in (r1, r2):
        fleet.push(path, site)
    return tmp_path


def _central(robots, where: str, request) -> str:
    if where == "postgres":
        return request.getfixturevalue("postgres_url")
    return str(robots / "central.db")


ONCE = [("r1", "a", 10.0), ("r1", "b", 20.0), ("r2", "c", 15.0)]


@pytest.mark.parametrize("where", ["file", "postgres"])
def test_a_robot_shipping_directly_and_relayed_is_refused_not_stored_twice(robots, where,
                                                                            request):
    central = _central(robots, where, request)
    assert fleet.push(str(robots / "r1.db"), central).shipped == 2
    with pytest.raises(RouteConflict, match=r"robot 'r1' ships to this store directly; "
                                            r"'site' relaying its rows too would store each "
                                            r"of them twice"):
        fleet.push(str(robots / "site.db"), central)
    # nothing of the refused batch went in: r1's rows once, r2's not yet (same type, one
    # batch with r1's)
    assert seen(central) == [("r1", "a", 10.0), ("r1", "b", 20.0)]
    # r1 keeps shipping directly
    robot_store(robots / "r1.db", "r1", ("seen(d)^30",))
    assert fleet.push(str(robots / "r1.db"), central).shipped == 1


@pytest.mark.parametrize("where", ["file", "postgres"])
def test_a_relayed_robot_shipping_directly_too_is_refused(robots, where, request):
    central = _central(robots, where, request)
    assert fleet.push(str(robots / "site.db"), central).shipped == 3
    with pytest.raises(RouteConflict, match=r"the rows of robot 'r1' reach this store "
                                            r"relayed by 'site'; r1 shipping them here "
                                            r"directly too would store each of them twice"):
        fleet.push(str(robots / "r1.db"), central)
    assert seen(central) == ONCE
    # the relay goes on
    robot_store(robots / "r1.db", "r1", ("seen(d)^30",))
    fleet.push(str(robots / "r1.db"), str(robots / "site.db"))
    assert fleet.push(str(robots / "site.db"), central).shipped == 1
    assert seen(central) == sorted(ONCE + [("r1", "d", 30.0)])


def test_two_stores_relaying_one_robot_are_refused(robots):
    slr_sql.open(robots / "site2.db", robot="site2").close()
    fleet.push(str(robots / "r1.db"), str(robots / "site2.db"))
    central = str(robots / "central.db")
    fleet.push(str(robots / "site.db"), central)
    with pytest.raises(RouteConflict, match=r"the rows of robot 'r1' reach this store "
                                            r"relayed by 'site'; 'site2' relaying them too"):
        fleet.push(str(robots / "site2.db"), central)
    assert seen(central) == ONCE


def test_the_refusal_reaches_a_pusher_over_the_service(robots):
    with ServiceProcess(robots / "central.db") as served:
        assert fleet.push(str(robots / "r1.db"), served.url).shipped == 2
        with pytest.raises(SLRError, match=r"robot 'r1' ships to this store directly"):
            fleet.push(str(robots / "site.db"), served.url)
    assert seen(robots / "central.db") == [("r1", "a", 10.0), ("r1", "b", 20.0)]


@pytest.mark.parametrize("where", ["file", "service"])
def test_status_lists_relayed_robots_with_the_store_they_come_through(robots, where):
    central = str(robots / "central.db")
    fleet.push(str(robots / "site.db"), central)
    robot_store(robots / "r3.db", "r3", ("seen(e)^40",))
    fleet.push(str(robots / "r3.db"), central)
    if where == "file":
        rows = fleet.status(central)
    else:
        with ServiceProcess(central) as served:
            rows = fleet.status(served.url)
    assert [(r["robot"], r["via"], r["shipped"]) for r in rows] == [
        ("r1", "site", 2), ("r2", "site", 1), ("r3", None, 1), ("site", None, 3)]
    relayed = rows[0]
    assert relayed["pending"] is None and relayed["lag_seconds"] is None
    assert relayed["last_contact"] is None
    # the command line marks them
    result = subprocess.run([sys.executable, "-m", "slr_sql", "fleet", "status", central],
                            capture_output=True, text=True, env=slr_env(), timeout=60)
    assert result.returncode == 0, result.stderr
    lines = {line.split()[0]: line for line in result.stdout.splitlines()[1:]}
    assert lines["r1"].split()[:2] == ["r1", "2"] and lines["r1"].endswith("relayed via site")
    assert lines["r2"].endswith("relayed via site")
    assert "UTC" in lines["r3"] and "UTC" in lines["site"]
    listed = json.loads(subprocess.run(
        [sys.executable, "-m", "slr_sql", "fleet", "status", central, "--json"],
        capture_output=True, text=True, env=slr_env(), timeout=60).stdout)
    assert [(r["robot"], r["via"]) for r in listed] == [
        ("r1", "site"), ("r2", "site"), ("r3", None), ("site", None)]


def test_a_fleet_store_from_before_routes_knows_its_direct_robots_after_the_upgrade(robots):
    import sqlite3
    central = str(robots / "central.db")
    assert fleet.push(str(robots / "r1.db"), central).shipped == 2
    # the store as schema version 9 wrote it: no routes
    conn = sqlite3.connect(central, isolation_level=None)
    conn.execute("DROP TABLE slr_fleet_routes")
    conn.execute("DROP TABLE slr_fleet_retired")   # (version 15's)
    conn.execute("DELETE FROM slr_migrations WHERE number >= 10")
    conn.execute("PRAGMA user_version = 9")
    conn.close()
    with pytest.raises(RouteConflict, match="robot 'r1' ships to this store directly"):
        fleet.push(str(robots / "site.db"), central)      # (migrates first)
    assert seen(central) == [("r1", "a", 10.0), ("r1", "b", 20.0)]


def test_two_routes_taken_at_once_on_postgresql_let_one_through(robots, postgres_url):
    """Another session takes r1's direct route and has not committed: the site's shipment
    relaying r1 waits for it, then is refused (not both routes pass)."""
    import threading
    import time

    import psycopg

    from slr_sql.store.postgres import split_url
    central = postgres_url
    slr_sql.open(central).close()                       # (the schema, migrated)
    other = psycopg.connect(split_url(central)[0])
    other.execute("SET search_path = slr")
    other.execute("INSERT INTO slr_fleet_routes (robot, via) VALUES ('r1', 'r1')")
    raised: list = []

    def relay() -> None:
        try:
            fleet.push(str(robots / "site.db"), central)
        except SLRError as exc:
            raised.append(exc)
    thread = threading.Thread(target=relay)
    thread.start()
    try:
        # until the relay waits for the other's route (committed before it got there, the
        # refusal would say nothing of the wait)
        deadline = time.monotonic() + 60
        with psycopg.connect(split_url(central)[0], autocommit=True) as watcher:
            while not watcher.execute(
                    "SELECT 1 FROM pg_stat_activity WHERE wait_event_type = 'Lock' AND "
                    "query LIKE '%slr_fleet_routes%'").fetchall():
                assert thread.is_alive(), f"the relay ended without waiting: {raised}"
                assert time.monotonic() < deadline, "the relay never waited for the route"
                time.sleep(0.01)
        other.commit()
    finally:
        other.close()
        thread.join(timeout=60)
    assert len(raised) == 1 and isinstance(raised[0], RouteConflict), raised
    assert seen(central) == []


@pytest.mark.parametrize("where", ["file", "postgres"])
def test_a_stores_own_rows_relayed_back_to_it_are_refused(tmp_path, where, request):
    # a cycle: the named fleet store pushes to a site store, which pushes back to it
    central = _central(tmp_path, where, request)
    with slr_sql.open(central, robot="central", clock=slr_sql.ManualClock(100)) as kb:
        kb.add("seen(x)^1")
    slr_sql.open(tmp_path / "site.db", robot="site").close()
    assert fleet.push(central, str(tmp_path / "site.db")).shipped == 1
    with pytest.raises(RouteConflict, match=r"the rows of robot 'central' are this store's "
                                            r"own; 'site' relaying them back would store "
                                            r"each of them twice"):
        fleet.push(str(tmp_path / "site.db"), central)
    assert seen(central) == [("central", "x", 1.0)]


def slr_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "slr_sql", *args], env=slr_env(),
                          capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("where", ["file", "postgres"])
def test_pushing_an_unnamed_store_as_a_robot_names_it_so_a_cycle_through_it_is_refused(
        tmp_path, where, request):
    # an unnamed fleet store (its events have no robot) is pushed with --robot central:
    # from then on it is central's store, as `slr fleet name` would make it
    central = _central(tmp_path, where, request)
    with slr_sql.open(central, clock=slr_sql.ManualClock(100)) as kb:
        kb.add("seen(x)^1")
    site = str(tmp_path / "site.db")
    slr_sql.open(site, robot="site").close()
    pushed = slr_cli("fleet", "push", central, site, "--robot", "central")
    assert pushed.returncode == 0, pushed.stderr
    assert "robot central: shipped 1 events" in pushed.stdout
    with slr_sql.open(central, clock=slr_sql.ManualClock(100)) as kb:
        assert kb.store.robot == "central"
        kb.add("seen(y)^2")     # its new events carry the name (those before it: none)
        assert kb.query("origin(R, seen(X)^_)") == [
            {"R": slr_sql.Atom("central"), "X": slr_sql.Atom("y")}]
    # the site pushing back brings central's own rows: a cycle, refused, nothing stored
    back = slr_cli("fleet", "push", site, central)
    assert back.returncode == 1
    assert "the rows of robot 'central' are this store's own; 'site' relaying them back " \
           "would store each of them twice" in back.stderr, back.stderr
    assert "Traceback" not in back.stderr
    with slr_sql.open(central, clock=slr_sql.ManualClock(100)) as kb:
        assert [a["X"] for a in kb.query("seen(X)^_")] == [slr_sql.Atom("x"),
                                                          slr_sql.Atom("y")]
    # and it ships as central only
    other = slr_cli("fleet", "push", central, site, "--robot", "other")
    assert other.returncode == 1
    assert "is the store of robot 'central', not 'other'" in other.stderr, other.stderr
    again = slr_cli("fleet", "push", central, site)
    assert again.returncode == 0, again.stderr
    assert "robot central: shipped 1 events" in again.stdout
