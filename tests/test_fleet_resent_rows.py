"""Rows a fleet store holds already, shipped again: a fleet store keeps, per robot and event
type, the last sequence of the robot's store it holds, and skipped every shipped row at or
below it as held -- without looking at it. A robot re-sending a sequence with other content
(two stores shipping as one robot, a pusher whose positions went stale while another store
in its name shipped, a hostile sender) lost those rows without a word. Now a row at or below
the position must be one the fleet store holds identically (the robot's row with the same
arguments, start and end): else the shipment is refused (``ShipmentConflict``, an SLRError;
HTTP 400 over ``slr serve``) and nothing of it is stored. Sending identical rows again still
stores none of them. A real SQLite file and the suite's PostgreSQL server; a real server
process for the service."""
from __future__ import annotations

import pytest
from service_helpers import HTTP, ServiceProcess

import slr_sql
from slr_sql.errors import SLRError
from slr_sql.shipping import receive
from slr_sql.store import ShipmentConflict


def row(seq: int, arg, start: float = 1.0, end: float | None = None, robot=None) -> tuple:
    return (seq, arg, start, start if end is None else end, 1.0, robot)


HELD = [row(1, "a", 1.0), row(2, "b", 2.0), row(3, "c", 3.0)]


@pytest.fixture(params=["file", "postgres"])
def fleet_store(request, tmp_path):
    where = (request.getfixturevalue("postgres_url") if request.param == "postgres"
             else str(tmp_path / "fleet.db"))
    with slr_sql.open(where) as kb:
        assert receive(kb, "r1", [("seen", 1, HELD)]) == 3
        yield kb


def held_rows(kb) -> list:
    return sorted((a["X"], a["S"]) for a in kb.query("seen(X)^[S, E]"))


CHANGED = [
    pytest.param([row(2, "x", 2.0), row(3, "c", 3.0), row(4, "d", 4.0)], id="argument"),
    pytest.param([row(3, "c", 3.5), row(4, "d", 4.0)], id="start-and-end"),
    pytest.param([row(3, "c", 2.5, 3.0), row(4, "d", 4.0)], id="start"),
    pytest.param([row(2, 2, 2.0), row(4, "d", 4.0)], id="argument-type"),
    pytest.param([row(1, "a", 1.0, robot="r9"), row(4, "d", 4.0)], id="robot-column"),
]


@pytest.mark.parametrize("resent", CHANGED)
def test_a_held_sequence_sent_again_with_other_content_is_refused_and_nothing_stored(
        fleet_store, resent):
    with pytest.raises(ShipmentConflict) as refused:
        receive(fleet_store, "r1", [("seen", 1, resent)], {"seen/1": 10.0}, pending=0)
    message = str(refused.value)
    assert f"robot 'r1' shipped seen/1 seq {resent[0][0]} again" in message, message
    assert "nothing of the shipment is stored" in message
    assert isinstance(refused.value, SLRError)
    store = fleet_store.store
    assert store.fleet_positions("r1") == {("seen", 1): 3}
    assert held_rows(fleet_store) == [("a", 1.0), ("b", 2.0), ("c", 3.0)]
    assert store.meta_get("fleet/mark/r1/seen/1") is None
    assert [r["contact_at"] for r in store.fleet_contacts()] == [None]
    assert store.robots() == ["r1"]


def test_identical_rows_sent_again_store_nothing_new(fleet_store):
    assert receive(fleet_store, "r1", [("seen", 1, HELD)]) == 0
    assert receive(fleet_store, "r1", [("seen", 1, HELD[1:] + [row(4, "d", 4.0)])]) == 1
    assert held_rows(fleet_store) == [("a", 1.0), ("b", 2.0), ("c", 3.0), ("d", 4.0)]
    assert fleet_store.store.fleet_positions("r1") == {("seen", 1): 4}


def test_rows_relayed_again_are_compared_with_their_robots_rows(fleet_store):
    """A relaying store's rows keep their robot: held means held as that robot's."""
    relayed = [row(1, "p", 1.0, robot="r7"), row(2, "q", 2.0, robot="r8")]
    assert receive(fleet_store, "site", [("seen", 1, relayed)]) == 2
    assert receive(fleet_store, "site", [("seen", 1, relayed)]) == 0
    with pytest.raises(ShipmentConflict, match="robot 'site' shipped seen/1 seq 2 again"):
        receive(fleet_store, "site", [("seen", 1, [row(2, "q", 2.0, robot="r7")])])


def test_the_service_refuses_it_in_words(tmp_path):
    with ServiceProcess(tmp_path / "fleet.db") as server:
        url = server.url + "/fleet/receive"
        first = {"robot": "r1", "batches": [["seen", 1, [list(r) for r in HELD]]]}
        assert HTTP.post(url, json=first, timeout=30).json() == {"stored": 3}
        assert HTTP.post(url, json=first, timeout=30).json() == {"stored": 0}
        answer = HTTP.post(url, timeout=30, json={"robot": "r1", "batches": [
            ["seen", 1, [list(row(3, "other", 3.0)), list(row(4, "d", 4.0))]]],
            "marks": {"seen/1": 9.0}})
        assert answer.status_code == 400, answer.text
        error = answer.json()["error"]
        assert error["kind"] == "ShipmentConflict"
        assert "robot 'r1' shipped seen/1 seq 3 again" in error["message"]
        assert "Traceback" not in error["message"]
        positions = HTTP.get(server.url + "/fleet/positions", params={"robot": "r1"},
                             timeout=30).json()
        assert positions == {"positions": [["seen", 1, 3]]}
        assert server.healthy()


def test_a_fleet_store_running_event_rules_compares_them_alike(fleet_store):
    """With event rules loaded the fleet store stores shipped events decoded (its rules run
    over them): rows sent again are compared with what that path stored."""
    fleet_store.load("twice(X) <- seen(X) seq seen(X).")
    rows = [row(4, "d", 4.0), row(5, '["a",1,2.5]', 5.0), row(6, 7, 6.0), row(7, 2.5, 7.0)]
    assert receive(fleet_store, "r1", [("seen", 1, rows)]) == 4
    assert receive(fleet_store, "r1", [("seen", 1, rows)]) == 0
    with pytest.raises(ShipmentConflict, match="seq 6 again"):
        receive(fleet_store, "r1", [("seen", 1, [row(6, 7.0, 6.0)])])
