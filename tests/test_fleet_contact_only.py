"""A robot that only made contact with a fleet store does not hold the fleet's marks back.

The fleet's mark of a type is the least of the marks of the robots it knows (docs/fleet.md,
"Marks"). A shipment carrying only a contact -- ``pending`` 0, no rows, no marks: the pusher
of a robot whose store holds nothing yet, or anyone holding the shared fleet token using a
new name -- made that name one of the robots the mark waits for, and the fleet's mark never
moved again until that name shipped a mark: synchronized queries on the fleet waited for
ever. Such a robot has no history anywhere for the fleet to wait for; it counts once the
fleet store holds rows or a mark of it, or its pusher says events wait on it (``pending``
above 0). A robot genuinely still shipping keeps holding the mark back. A real server
process and SQLite file; PostgreSQL from the suite's fixture, in process.
"""
from __future__ import annotations

import pytest
from service_helpers import HTTP, ServiceProcess

import slr_sql
from slr_sql import fleet
from slr_sql.shipping import receive

from test_fleet_relay import robot_store

TOKEN = "fleet-token-shared-by-every-robot"


def mark_complete(path, until: float) -> None:
    with slr_sql.open(path, clock=slr_sql.ManualClock(1000)) as kb:
        kb.mark_complete("seen/1", until)


def fleet_mark(db) -> float | None:
    """The fleet store's own mark of seen/1 (the least of its robots')."""
    with slr_sql.open(db) as kb:
        return kb.store.meta_get("sync/mark/seen/1")


def contact(server, robot: str, pending: int = 0) -> None:
    answer = HTTP.post(server.url + "/fleet/receive", timeout=30,
                       headers={"Authorization": f"Bearer {TOKEN}"},
                       json={"robot": robot, "batches": [], "pending": pending})
    assert answer.status_code == 200, answer.text


def test_a_contact_alone_does_not_hold_the_fleets_mark_back(tmp_path):
    """A robot whose store holds nothing (its pusher ships only a contact) and a forged
    contact under a new name with the shared token: the fleet's mark follows r1's."""
    r1 = robot_store(tmp_path / "r1.db", "r1", 5.0, ("seen(a)^1",))
    idle = robot_store(tmp_path / "idle.db", "idle", None)
    with ServiceProcess(tmp_path / "fleet.db", "--token", TOKEN) as server:
        fleet.push(r1, server.url, token=TOKEN)
        assert fleet_mark(server.db) == 5.0
        fleet.push(idle, server.url, token=TOKEN)
        contact(server, "ghost")
        with slr_sql.open(server.db) as kb:   # (both made contact: status lists them)
            assert {"idle", "ghost"} <= {r["robot"] for r in kb.store.fleet_contacts()}
        mark_complete(r1, 10.0)
        fleet.push(r1, server.url, token=TOKEN)
        assert fleet_mark(server.db) == 10.0
        # the idle robot counts from its first mark, and holds the fleet's mark from then on
        mark_complete(idle, 12.0)
        fleet.push(idle, server.url, token=TOKEN)
        mark_complete(r1, 20.0)
        fleet.push(r1, server.url, token=TOKEN)
        assert fleet_mark(server.db) == 12.0


def test_a_robot_still_shipping_holds_the_fleets_mark_back(tmp_path):
    """A robot whose pusher says events wait on it (``pending``), and one whose rows the
    fleet holds without a mark, keep the fleet's mark where it is: their events are on the
    way."""
    r1 = robot_store(tmp_path / "r1.db", "r1", 5.0, ("seen(a)^1",))
    unmarked = robot_store(tmp_path / "r2.db", "r2", None, ("seen(b)^2",))
    with ServiceProcess(tmp_path / "fleet.db", "--token", TOKEN) as server:
        fleet.push(r1, server.url, token=TOKEN)
        contact(server, "r3", pending=2)
        mark_complete(r1, 10.0)
        fleet.push(r1, server.url, token=TOKEN)
        assert fleet_mark(server.db) == 5.0
        contact(server, "r3", pending=0)     # (r3 now has nothing waiting, nor any history)
        fleet.push(r1, server.url, token=TOKEN)
        assert fleet_mark(server.db) == 10.0
        fleet.push(unmarked, server.url, token=TOKEN)
        mark_complete(r1, 20.0)
        fleet.push(r1, server.url, token=TOKEN)
        assert fleet_mark(server.db) == 10.0   # (r2's rows are here, its mark is not)


@pytest.mark.parametrize("where", ["file", "postgres"])
def test_either_backend_counts_only_robots_with_a_history_here(tmp_path, where, request):
    where = (request.getfixturevalue("postgres_url") if where == "postgres"
             else str(tmp_path / "fleet.db"))
    with slr_sql.open(where) as fleet_store:
        receive(fleet_store, "r1", [("seen", 1, [(1, "a", 1.0, 1.0, 1.0, None)])],
                {"seen/1": 5.0}, pending=0)
        receive(fleet_store, "ghost", [], pending=0)
        receive(fleet_store, "waiting", [], pending=1)
        receive(fleet_store, "r1", [], {"seen/1": 10.0})
        assert fleet_store.store.meta_get("sync/mark/seen/1") == 5.0   # (waiting)
        receive(fleet_store, "waiting", [], pending=0)
        receive(fleet_store, "r1", [], {"seen/1": 15.0})
        assert fleet_store.store.meta_get("sync/mark/seen/1") == 15.0
        receive(fleet_store, "ghost", [], {"other/1": 3.0}, pending=0)   # (a mark: it counts)
        receive(fleet_store, "r1", [], {"seen/1": 20.0})
        assert fleet_store.store.meta_get("sync/mark/seen/1") == 15.0
