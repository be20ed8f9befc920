"""Shipments no robot's store could have sent, from a misbehaving or hostile robot.

``POST /fleet/receive`` stores a shipment's rows as they come (no decoding), so its check
must refuse what no store holds before anything is stored: an integer beyond 64 bits (a
sequence, an argument, a time, a pending count: SQLite's and PostgreSQL's integers stop
there, and the store's own answer was Python's "int too large to convert to SQLite INTEGER"
passed on as a 400), an event that starts after it ends (a store refuses to add one; a
shipped one answered ``S = 5.0, E = 1.0`` to every query), and rows of one type sent out of
sequence order in two batches of one shipment (the second batch's rows lie below the
position the first moved to: they were skipped without a word and lost). A real server
process and SQLite file; PostgreSQL from the suite's fixture, in process.
"""
from __future__ import annotations

import pytest
from service_helpers import HTTP, ServiceProcess

import slr_sql
from slr_sql.errors import SLRError
from slr_sql import fleet
from slr_sql.shipping import receive

BIG = 2 ** 63   # one past the largest 64-bit integer


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    with ServiceProcess(tmp_path_factory.mktemp("forged") / "fleet.db") as s:
        yield s


def row(seq=1, arg="a", start=1.0, end=1.0, arrival=1.0, robot=None):
    return [seq, arg, start, end, arrival, robot]


FORGED = [
    pytest.param({"batches": [["f_seq", 1, [row(seq=BIG)]]]}, "beyond 64 bits", id="sequence"),
    pytest.param({"batches": [["f_arg", 1, [row(arg=BIG)]]]}, "beyond 64 bits", id="argument"),
    pytest.param({"batches": [["f_neg", 1, [row(arg=-BIG - 1)]]]}, "beyond 64 bits",
                 id="negative-argument"),
    pytest.param({"batches": [["f_time", 1, [row(start=2 ** 70, end=2 ** 70)]]]}, "beyond 64 bits",
                 id="time"),
    pytest.param({"batches": [["f_arrival", 1, [row(arrival=BIG)]]]}, "beyond 64 bits",
                 id="arrival"),
    pytest.param({"batches": [], "pending": BIG}, "pending", id="pending"),
    pytest.param({"batches": [["f_order", 1, [row(start=5.0, end=1.0)]]]},
                 "starts after it ends", id="start-after-end"),
    pytest.param({"batches": [["f_twice", 1, [row(seq=5)]], ["f_twice", 1, [row(seq=3)]]]},
                 "ascending", id="type-out-of-order-across-batches"),
    pytest.param({"batches": [["f_same", 1, [row(seq=5)]], ["f_same", 1, [row(seq=5)]]]},
                 "ascending", id="type-repeated-across-batches"),
]


@pytest.mark.parametrize("forged, words", FORGED)
def test_a_forged_shipment_is_refused_in_words_and_stores_nothing(server, forged, words,
                                                                  request):
    robot = "f" + request.node.callspec.id.replace("-", "")[:20]
    good = ["f_first", 1, [row(seq=1, arg="fine")]]
    body = {"robot": robot, **forged, "batches": [good, *forged["batches"]]}
    answer = HTTP.post(server.url + "/fleet/receive", json=body, timeout=30)
    assert answer.status_code == 400, answer.text
    error = answer.json()["error"]
    assert error["kind"] == "SLRError", error
    assert words in error["message"], error["message"]
    assert "Python" not in error["message"] and "SQLite INTEGER" not in error["message"]
    positions = HTTP.get(server.url + "/fleet/positions", params={"robot": robot}, timeout=30)
    assert positions.json() == {"positions": []}
    status = HTTP.get(server.url + "/fleet/status", timeout=30).json()["robots"]
    assert robot not in [r["robot"] for r in status]
    assert server.healthy()
    assert "did not take" not in server.log.read_text()


def test_the_largest_64_bit_integers_still_ship(server):
    """The bound is the integers' own: the largest and smallest 64-bit ones go in and read
    back as themselves."""
    rows = [row(seq=BIG - 2, arg=BIG - 1), row(seq=BIG - 1, arg=-BIG)]
    answer = HTTP.post(server.url + "/fleet/receive", timeout=30, json={
        "robot": "fedge", "batches": [["f_edge", 1, rows]], "pending": BIG - 1})
    assert answer.json() == {"stored": 2}, answer.text
    with slr_sql.connect(server.url) as client:
        assert sorted(a["X"] for a in client.query("f_edge(X)^T")) == [-BIG, BIG - 1]


@pytest.mark.parametrize("forged, words", [*FORGED, pytest.param(
    # (over the service a time is read as a float: in process it comes as given)
    {"batches": [], "pending": 1, "head_arrival": BIG}, "head_arrival", id="head-arrival")])
def test_postgresql_refuses_them_alike(postgres_url, forged, words):
    batches = [("f_first", 1, [tuple(row(seq=1, arg="fine"))])] + [
        (name, arity, [tuple(r) for r in rows]) for name, arity, rows in forged["batches"]]
    with slr_sql.open(postgres_url) as fleet:
        with pytest.raises(SLRError, match=words):
            receive(fleet, "r1", batches, pending=forged.get("pending"),
                    head_arrival=forged.get("head_arrival"))
        assert fleet.store.fleet_positions("r1") == {}
        assert fleet.store.fleet_contacts() == []
        assert fleet.query("f_first(X)^T") == []


# -- marks of another robot ------------------------------------------------------------------

def seen(seq: int, arg: str) -> tuple:
    return (seq, arg, 1.0, 1.0, 1.0, None)


@pytest.mark.parametrize("where", ["file", "postgres"])
def test_a_robot_cannot_move_the_marks_of_a_robot_that_does_not_come_through_it(
        tmp_path, where, request):
    """``relayed`` carries the marks a relaying store holds of the robots whose rows it
    relays. A robot sending marks of another robot whose rows reach the fleet store directly
    (or through a third store) moved that robot's mark, and with it the fleet's: r1 saying
    r2's seen/1 is complete up to 1e9 made the fleet's seen/1 complete up to r1's 100 while
    r2 had said 5 (a synchronized query answered before r2's events came). Now it is
    refused and nothing of the shipment is stored; marks of a robot the fleet does not know
    yet, or of one relayed through the sender, still go in."""
    where = (request.getfixturevalue("postgres_url") if where == "postgres"
             else str(tmp_path / "fleet.db"))
    with slr_sql.open(where) as fleet:
        receive(fleet, "r2", [("seen", 1, [seen(1, "a")])], {"seen/1": 5.0})
        receive(fleet, "r3", [("seen", 1, [(1, "c", 1.0, 1.0, 1.0, "r4")])],
                relayed={"r4": {"seen/1": 5.0}})
        receive(fleet, "r1", [("seen", 1, [seen(1, "b")])], {"seen/1": 100.0})
        assert fleet.store.meta_get("sync/mark/seen/1") == 5.0
        for forged in ({"r2": {"seen/1": 1e9}}, {"r4": {"seen/1": 1e9}}):
            with pytest.raises(SLRError, match="marks of robot"):
                receive(fleet, "r1", [("seen", 1, [seen(2, "b2")])], {"seen/1": 200.0},
                        relayed=forged)
            assert fleet.store.meta_get("sync/mark/seen/1") == 5.0
            assert fleet.store.meta_get("fleet/mark/r1/seen/1") == 100.0
            assert fleet.store.fleet_positions("r1") == {("seen", 1): 1}
        assert fleet.store.meta_get("fleet/mark/r2/seen/1") == 5.0
        assert fleet.store.meta_get("fleet/mark/r4/seen/1") == 5.0
        # a robot relayed through the sender, and one the fleet does not know yet
        receive(fleet, "r3", [], relayed={"r4": {"seen/1": 7.0}, "r5": {"seen/1": 9.0}})
        assert fleet.store.meta_get("fleet/mark/r4/seen/1") == 7.0
        assert fleet.store.meta_get("fleet/mark/r5/seen/1") == 9.0


def test_the_service_refuses_it_in_words(server):
    url = server.url + "/fleet/receive"
    assert HTTP.post(url, timeout=30, json={"robot": "mdirect", "batches": [
        ["m_seen", 1, [row(seq=1)]]], "marks": {"m_seen/1": 5.0}}).status_code == 200
    answer = HTTP.post(url, timeout=30, json={"robot": "mforger", "batches": [
        ["m_seen", 1, [row(seq=1)]]], "relayed": {"mdirect": {"m_seen/1": 1e9}}})
    assert answer.status_code == 400, answer.text
    assert "marks of robot 'mdirect'" in answer.json()["error"]["message"]
    assert HTTP.get(server.url + "/fleet/positions", params={"robot": "mforger"},
                    timeout=30).json() == {"positions": []}


# -- marks alone, sent directly --------------------------------------------------------------

TOKEN = "fleet-token-shared-by-every-robot"


@pytest.fixture
def relayed_fleet(tmp_path):
    """A fleet server (one token for every robot) to which a site store relays r2: r2
    pushes to the site, the site pushes on. The site's own mark of seen/1 is 100, r2's 5:
    the fleet's is 5, waiting for r2."""
    site, r2 = str(tmp_path / "site.db"), str(tmp_path / "r2.db")
    with slr_sql.open(r2, robot="r2", clock=slr_sql.ManualClock(10.0)) as kb:
        kb.add("seen(a)^1")
        kb.mark_complete("seen/1", 5.0)
    fleet.push(r2, site)
    with slr_sql.open(site, robot="site", clock=slr_sql.ManualClock(10.0)) as kb:
        kb.mark_complete("seen/1", 100.0)   # (the site's own events are complete to 100)
    with ServiceProcess(tmp_path / "fleet.db", "--token", TOKEN) as server:
        fleet.push(site, server.url, token=TOKEN)
        assert fleet_mark(server) == 5.0
        yield server, tmp_path


def fleet_mark(server) -> float | None:
    """The fleet store's own mark of seen/1 (the least of its robots')."""
    with slr_sql.open(server.db) as kb:
        return kb.store.meta_get("sync/mark/seen/1")


def test_a_robot_relayed_by_a_site_cannot_send_its_marks_alone_directly(relayed_fleet):
    """The route check applied to marks relayed by another store, not to a robot's own
    marks sent with no rows: r2, whose rows reach the fleet relayed by the site, pushed
    a store that held only marks (a second store of r2, a robot restarted on an empty
    store pointed at the fleet) straight to the fleet with the shared token, and r2's mark
    and the fleet's moved to 100 while r2's events after 5 were still at the site: a
    synchronized query answered without them. Now it is refused as a route conflict and
    nothing of the shipment is stored."""
    server, tmp_path = relayed_fleet
    marks_only = str(tmp_path / "r2-marks-only.db")
    with slr_sql.open(marks_only, robot="r2", clock=slr_sql.ManualClock(10.0)) as kb:
        kb.mark_complete("seen/1", 1e9)
    with pytest.raises(SLRError, match="the marks of robot 'r2' cannot come from it "
                                       "directly: its rows reach this store relayed by "
                                       "'site'"):
        fleet.push(marks_only, server.url, token=TOKEN)
    assert fleet_mark(server) == 5.0
    with slr_sql.open(server.db) as kb:
        assert kb.store.meta_get("fleet/mark/r2/seen/1") == 5.0
        assert [(r["robot"], r["via"]) for r in kb.store.fleet_contacts()] == [
            ("r2", "site"), ("site", None)]


def test_a_robot_cannot_send_marks_alone_as_another_robot_relayed_by_a_site(relayed_fleet):
    """The same over the wire: any robot holding the fleet's token sending marks alone in
    r2's name (no rows, no pending) moved r2's mark."""
    server, _ = relayed_fleet
    answer = HTTP.post(server.url + "/fleet/receive", timeout=30,
                       headers={"Authorization": f"Bearer {TOKEN}"},
                       json={"robot": "r2", "batches": [], "marks": {"seen/1": 1e9}})
    assert answer.status_code == 400, answer.text
    assert answer.json()["error"]["kind"] == "RouteConflict"
    assert "the marks of robot 'r2' cannot come from it directly" in \
        answer.json()["error"]["message"]
    assert fleet_mark(server) == 5.0
    # the site's own marks still go in, and r2's relayed by it
    with slr_sql.connect(server.url, token=TOKEN) as client:
        assert client.fleet_receive("site", [], {"seen/1": 200.0}, None, None,
                                    relayed={"r2": {"seen/1": 7.0}}) == 0
    assert fleet_mark(server) == 7.0


@pytest.mark.parametrize("where", ["file", "postgres"])
def test_marks_alone_follow_the_route_of_the_robots_rows_on_either_backend(
        tmp_path, where, request):
    where = (request.getfixturevalue("postgres_url") if where == "postgres"
             else str(tmp_path / "fleet.db"))
    with slr_sql.open(where) as fleet_store:
        receive(fleet_store, "site", [("seen", 1, [(1, "a", 1.0, 1.0, 1.0, "r2")])],
                {"seen/1": 100.0}, relayed={"r2": {"seen/1": 5.0}})
        receive(fleet_store, "r1", [("seen", 1, [seen(1, "b")])], {"seen/1": 100.0})
        assert fleet_store.store.meta_get("sync/mark/seen/1") == 5.0
        with pytest.raises(SLRError, match="cannot come from it directly"):
            receive(fleet_store, "r2", [], {"seen/1": 1e9}, pending=0)
        assert fleet_store.store.meta_get("fleet/mark/r2/seen/1") == 5.0
        assert fleet_store.store.meta_get("sync/mark/seen/1") == 5.0
        assert "r2" not in {r["robot"] for r in fleet_store.store.fleet_contacts()
                            if r["contact_at"] is not None}
        # a robot shipping directly still sends its marks alone
        receive(fleet_store, "r1", [], {"seen/1": 150.0})
        assert fleet_store.store.meta_get("fleet/mark/r1/seen/1") == 150.0
