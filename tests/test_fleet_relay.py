"""Completeness marks of robots whose rows reach a fleet store relayed by another store
(docs/fleet.md, "Marks"): a site store collects robots r1 and r2 (they push to it) and pushes
everything on to the fleet store. The fleet store holds r1's and r2's rows, so it counts
them among the robots its mark waits for; the relaying store ships the marks it holds for
each robot it relays, so the fleet's marks move with theirs. A store's own name is not one
of the robots its mark waits for: a named site store's mark moves too. And marks never go
ahead of the rows they speak of: a push stopped before it read its rows ships none."""
from __future__ import annotations

import threading

import pytest
from service_helpers import HTTP, ServiceProcess

import slr_sql
from slr_sql import fleet


def robot_store(path, robot: str, until: float | None, events: tuple = ()) -> str:
    """A store of ``robot`` holding ``events``, seen/1 marked complete up to ``until``."""
    with slr_sql.open(path, robot=robot, clock=slr_sql.ManualClock(1000)) as kb:
        for event in events:
            kb.add(event)
        if until is not None:
            kb.mark_complete("seen/1", until)
    return str(path)


def meta(path, key: str):
    with slr_sql.open(path) as kb:
        return kb.store.meta_get(key)


@pytest.fixture
def site(tmp_path):
    """r1 (complete up to 50) and r2 (up to 70) pushed into a site store named 'site'."""
    robot_store(tmp_path / "r1.db", "r1", 50.0, ("seen(a)^10", "seen(b)^20"))
    robot_store(tmp_path / "r2.db", "r2", 70.0, ("seen(c)^15",))
    slr_sql.open(tmp_path / "site.db", robot="site").close()
    for robot in ("r1", "r2"):
        fleet.push(str(tmp_path / f"{robot}.db"), str(tmp_path / "site.db"))
    return tmp_path


def test_a_named_store_that_receives_marks_moves_its_own_mark(site):
    """The site store is named: its own name is not a robot whose mark it waits for (its
    own events' completeness is what its own marks say)."""
    assert meta(site / "site.db", "fleet/mark/r1/seen/1") == 50.0
    assert meta(site / "site.db", "sync/mark/seen/1") == 50.0


@pytest.mark.parametrize("where", ["file", "service", "postgres"])
def test_marks_of_relayed_robots_reach_the_fleet_store(site, where, request):
    fleet_db = site / "fleet.db"
    if where == "postgres":   # a fleet store on a PostgreSQL server, opened by the pusher
        fleet_db = request.getfixturevalue("postgres_url")

    def relay(target: str) -> int:
        return fleet.push(str(site / "site.db"), target).shipped

    def check(target: str) -> None:
        assert relay(target) == 3
        robot_store(site / "r1.db", "r1", 90.0)     # r1 is complete up to 90 now
        fleet.push(str(site / "r1.db"), str(site / "site.db"))
        assert relay(target) == 0

    if where != "service":
        check(str(fleet_db))
    else:
        with ServiceProcess(fleet_db) as served:
            check(served.url)
    # each robot's own mark, as its store said it, and the site's (the least it holds)
    assert meta(fleet_db, "fleet/mark/r1/seen/1") == 90.0
    assert meta(fleet_db, "fleet/mark/r2/seen/1") == 70.0
    assert meta(fleet_db, "fleet/mark/site/seen/1") == 70.0
    # the fleet's history is complete up to the least of them
    assert meta(fleet_db, "sync/mark/seen/1") == 70.0
    with slr_sql.open(fleet_db, clock=slr_sql.ManualClock(0)) as kb:
        assert kb.complete_until("seen/1") == 70.0
        # a synchronized query at 60 is answered now, over every robot's events
        assert sorted(a["X"] for a in kb.query("seen(X)^T, T =< 60", at=60, wait=True,
                                              timeout=30)) == ["a", "b", "c"]


def test_a_relayed_robot_that_marks_less_holds_the_fleet_back(site):
    """A relayed mark is the relayed robot's: the fleet's mark is never above it."""
    fleet_db = site / "fleet.db"
    robot_store(site / "r3.db", "r3", 30.0, ("seen(d)^5",))
    fleet.push(str(site / "r3.db"), str(site / "site.db"))
    fleet.push(str(site / "site.db"), str(fleet_db))
    assert meta(fleet_db, "fleet/mark/r3/seen/1") == 30.0
    assert meta(fleet_db, "sync/mark/seen/1") == 30.0


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    with ServiceProcess(tmp_path_factory.mktemp("relay") / "fleet.db") as s:
        yield s


@pytest.mark.parametrize("relayed, words", [
    ({"r1": {"seen": 5.0}}, "relayed"),
    ({"r1": [5.0]}, "relayed"),
    ({"12": {"seen/1": 5.0}}, "robot"),
    ({"": {"seen/1": 5.0}}, "robot"),
    ({"r1": {"seen/1": "soon"}}, "relayed"),
])
def test_relayed_marks_that_say_nothing_are_refused(server, relayed, words):
    answer = HTTP.post(server.url + "/fleet/receive", timeout=30, json={
        "robot": "hub", "batches": [], "relayed": relayed})
    assert answer.status_code == 400, answer.text
    assert words in answer.json()["error"]["message"]
    with slr_sql.open(server.db) as kb:
        assert kb.store.meta_items("fleet/mark/") == {}


# -- marks never go ahead of the rows they speak of ------------------------------------------

@pytest.mark.parametrize("relayed", [False, True])
def test_a_push_stopped_before_its_rows_ships_no_mark(tmp_path, relayed):
    """A pusher stopped (SIGINT, SIGTERM, ``stop``) before a round read its rows sent the
    round's contact with the robot's marks anyway: the fleet store took the robot's history
    as complete up to the mark without holding its events, and a synchronized query there
    answered early, without them. A round cut short ships its batches and what is left, not
    the marks; the next push ships them with the rows."""
    robot_store(tmp_path / "r1.db", "r1", 50.0, ("seen(a)^10", "seen(b)^20"))
    source = tmp_path / "r1.db"
    if relayed:   # the same through a site store that relays r1
        slr_sql.open(tmp_path / "site.db", robot="site").close()
        fleet.push(str(source), str(tmp_path / "site.db"))
        source = tmp_path / "site.db"
    fleet_db = tmp_path / "fleet.db"
    stopped = threading.Event()
    stopped.set()
    assert fleet.push(str(source), str(fleet_db), stop=stopped).shipped == 0
    with slr_sql.open(fleet_db, clock=slr_sql.ManualClock(0)) as kb:
        assert kb.store.meta_items("fleet/mark/") == {}
        assert kb.complete_until("seen/1") < 40
        with pytest.raises(slr_sql.SLRTimeout):
            kb.query("seen(X)^T, T =< 40", at=40, wait=True, timeout=0)
    assert fleet.push(str(source), str(fleet_db)).shipped == 2
    with slr_sql.open(fleet_db, clock=slr_sql.ManualClock(0)) as kb:
        assert kb.store.meta_get("fleet/mark/r1/seen/1") == 50.0
        assert sorted(a["X"] for a in kb.query("seen(X)^T, T =< 40", at=40, wait=True,
                                              timeout=30)) == ["a", "b"]


@pytest.mark.parametrize("relayed", [False, True])
def test_a_push_of_some_types_ships_no_mark_of_the_others(tmp_path, relayed):
    """``push(types=...)`` ships the rows of those types only: the marks of the other types
    (the robot's own, the relayed robots', and ``p/*`` ones that speak of a type left out)
    speak of rows it did not ship, and the fleet store took those histories as complete
    without holding them (a synchronized query there answered early, without them)."""
    with slr_sql.open(tmp_path / "r1.db", robot="r1", clock=slr_sql.ManualClock(1000)) as kb:
        kb.add_many(["seen(a)^10", "lost(b)^20", "part(c)^30", "part(c, d)^30"])
        for mark in ("seen/1", "lost/1", "part"):   # (part: every arity, part/*)
            kb.mark_complete(mark, 50.0)
    source = tmp_path / "r1.db"
    if relayed:   # the same through a site store that relays r1 (every type of it)
        slr_sql.open(tmp_path / "site.db", robot="site").close()
        fleet.push(str(source), str(tmp_path / "site.db"))
        source = tmp_path / "site.db"
    fleet_db = tmp_path / "fleet.db"
    assert fleet.push(str(source), str(fleet_db), types=["seen/1", "part/1"]).shipped == 2
    with slr_sql.open(fleet_db, clock=slr_sql.ManualClock(0)) as kb:
        assert kb.store.meta_get("fleet/mark/r1/seen/1") == 50.0
        assert sorted(kb.store.meta_items("fleet/mark/r1/")) == ["fleet/mark/r1/seen/1"]
        with pytest.raises(slr_sql.SLRTimeout):
            kb.query("lost(X)^T, T =< 40", at=40, wait=True, timeout=0)
    assert fleet.push(str(source), str(fleet_db)).shipped == 2   # lost/1, part/2
    with slr_sql.open(fleet_db, clock=slr_sql.ManualClock(0)) as kb:
        assert kb.store.meta_get("fleet/mark/r1/lost/1") == 50.0
        assert kb.store.meta_get("fleet/mark/r1/part/*") == 50.0
        assert [a["X"] for a in kb.query("lost(X)^T, T =< 40", at=40, wait=True,
                                         timeout=30)] == ["b"]
