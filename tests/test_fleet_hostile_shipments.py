"""Hostile and mistaken shipments to a fleet store (adversarial review of fleet shipping).

A shipment comes from the network (``POST /fleet/receive`` of ``slr serve``): its rows are
stored as they come, in the columns' stored form, so a row the store could never have written
must be refused before anything is stored -- an argument text that is not a stored term
(``[1,`` would make every later query over the type fail), a robot column that is no robot's
name, a mark that names no event type. And a robot store pushed into itself (the same file
given twice, or a fleet store named as the robot that ships) would store each event again.
"""
from __future__ import annotations

import subprocess
import sys

import pytest
from service_helpers import HTTP, ServiceProcess, reserved_port, slr_env

import slr_sql
from slr_sql import fleet
from slr_sql.errors import SLRError
from slr_sql.shipping import receive


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    with ServiceProcess(tmp_path_factory.mktemp("rt11fleet") / "fleet.db") as s:
        yield s


def row(arg, robot=None, seq=1):
    return [seq, arg, 1.0, 1.0, 1.0, robot]


BAD_ROWS = [
    pytest.param(row("[1,"), "seq 1: argument 1", id="unterminated-list"),
    pytest.param(row('{"f":'), "seq 1: argument 1", id="unterminated-compound"),
    pytest.param(row('"open'), "seq 1: argument 1", id="unterminated-string"),
    pytest.param(row('{"$int":"12x"}'), "seq 1: argument 1", id="bad-big-integer"),
    pytest.param(row("a", robot=7), "robot", id="robot-a-number"),
    pytest.param(row("a", robot=""), "robot", id="robot-empty"),
    pytest.param(row("a", robot="r\x00x"), "robot", id="robot-control-character"),
    pytest.param(row("a", robot="12"), "robot", id="robot-reads-as-a-number"),
    pytest.param(row("a", robot="[r1]"), "robot", id="robot-reads-as-a-list"),
]


@pytest.mark.parametrize("bad, words", BAD_ROWS)
def test_a_shipped_row_the_store_could_not_have_written_is_refused_and_nothing_stored(
        server, bad, words, request):
    type_name = f"t_{request.node.callspec.id.replace('-', '_')}"
    good = [1, "fine", 0.5, 0.5, 0.5, None]
    bad = [2, *bad[1:]]
    answer = HTTP.post(server.url + "/fleet/receive", timeout=30, json={
        "robot": "rx", "batches": [["ok_first", 1, [good]], [type_name, 1, [bad]]]})
    assert answer.status_code == 400, answer.text
    error = answer.json()["error"]
    assert error["kind"] in ("SLRError", "BadRequest")
    assert words.replace("seq 1", "seq 2") in error["message"]
    assert "Error:" not in error["message"] and "Traceback" not in error["message"]
    # nothing of the shipment is stored, and the fleet store still answers over the type
    positions = HTTP.get(server.url + "/fleet/positions", params={"robot": "rx"}, timeout=30)
    assert positions.json() == {"positions": []}
    for goal in (f"{type_name}(X)^T", "ok_first(X)^T"):
        assert HTTP.post(server.url + "/query", json={"goal": goal},
                         timeout=30).json() == {"answers": []}
    robots = HTTP.post(server.url + "/query", json={"goal": "origin(R, ok_first(X)^T)"},
                       timeout=30)
    assert robots.json() == {"answers": []}
    assert server.healthy()


def test_every_stored_form_of_a_term_still_ships(server):
    """The check refuses only what is no stored term: lists, compounds, strings, messages,
    atoms that look like JSON, big integers, relayed rows of another robot all go in."""
    args = ['["a",1,2.5]', '{"f":["a",{"$string":"s"}]}', '"a string"', '{"$atom":"[x"}',
            '{"$int":"123456789012345678901234567890"}',
            '{"$type":"geometry_msgs/msg/Point","x":1.0,"y":2.0,"z":0.5}', "plain", 7, 2.5]
    rows = [[i + 1, a, float(i), float(i), float(i), "r9" if i == 0 else None]
            for i, a in enumerate(args)]
    answer = HTTP.post(server.url + "/fleet/receive", timeout=30, json={
        "robot": "rgood", "batches": [["forms", 1, rows]], "marks": {"forms/1": 3.0,
                                                                       "forms/*": 2.0}})
    assert answer.json() == {"stored": len(args)}, answer.text
    with slr_sql.connect(server.url) as client:
        got = client.query("origin(R, forms(X)^T)")
    assert len(got) == len(args)
    assert {str(a["R"]) for a in got} == {"r9", "rgood"}


@pytest.mark.parametrize("extra, words", [
    ({"marks": {"x": 5.0}}, "marks"),
    ({"marks": {"seen/one": 5.0}}, "marks"),
    ({"marks": {"": 5.0}}, "marks"),
    ({"pending": -4}, "pending"),
    ({"head_arrival": {"$float": "inf"}}, "head_arrival"),
])
def test_a_shipment_whose_marks_or_contact_say_nothing_is_refused(server, extra, words):
    body = {"robot": "rm", "batches": [["m_type", 1, [[1, "a", 1.0, 1.0, 1.0, None]]]],
            **extra}
    answer = HTTP.post(server.url + "/fleet/receive", json=body, timeout=30)
    assert answer.status_code == 400, answer.text
    assert words in answer.json()["error"]["message"]
    positions = HTTP.get(server.url + "/fleet/positions", params={"robot": "rm"}, timeout=30)
    assert positions.json() == {"positions": []}


def test_the_checks_hold_in_process_too():
    with slr_sql.open() as kb:
        with pytest.raises(SLRError, match="argument 1"):
            receive(kb, "r1", [("seen", 1, [(1, "[1,", 1.0, 1.0, 1.0, None)])])
        with pytest.raises(SLRError, match="robot"):
            receive(kb, "r1", [("seen", 1, [(1, "a", 1.0, 1.0, 1.0, 5)])])
        assert kb.query("seen(X)^T") == [] and kb.store.robots() == []


# -- a robot store pushed into itself --------------------------------------------------------

def robot_store(path):
    with slr_sql.open(path, robot="r1", clock=slr_sql.ManualClock(100)) as kb:
        kb.add("seen(p, d)^10")
        kb.add("seen(q, d)^11")


def seen_rows(path) -> int:
    with slr_sql.open(path) as kb:
        return len(kb.query("seen(X, Y)^T"))


@pytest.mark.parametrize("spelling", ["same", "dot-slash", "symlink"])
def test_a_store_pushed_into_itself_is_refused_and_stores_nothing_twice(tmp_path, spelling):
    db = tmp_path / "r1.db"
    robot_store(db)
    target = {"same": str(db), "dot-slash": str(tmp_path / "." / "r1.db"),
              "symlink": str(tmp_path / "link.db")}[spelling]
    if spelling == "symlink":
        (tmp_path / "link.db").symlink_to(db)
    with pytest.raises(SLRError, match="itself"):
        fleet.push(str(db), target)
    assert seen_rows(db) == 2


def test_an_unnamed_store_pushed_into_itself_as_a_robot_is_refused(tmp_path):
    db = tmp_path / "plain.db"
    with slr_sql.open(db, clock=slr_sql.ManualClock(100)) as kb:
        kb.add("seen(p, d)^10")
    with pytest.raises(SLRError, match="itself"):
        fleet.push(str(db), str(db), robot="r1")
    with slr_sql.open(db) as kb:
        assert len(kb.query("seen(X, Y)^T")) == 1
        assert kb.store.robot is None   # (a push refused does not name the store either)


def test_a_fleet_store_refuses_a_shipment_of_its_own_robot(tmp_path):
    """Over the service the pusher cannot see the file: the fleet store named r1 refuses
    what a robot r1 ships (its own events, or another store's under the same name)."""
    db = tmp_path / "r1.db"
    robot_store(db)
    with ServiceProcess(db) as served:
        with pytest.raises(SLRError, match="itself|its own"):
            fleet.push(str(db), served.url)
        assert served.healthy()
    assert seen_rows(db) == 2


def test_the_cli_says_why_a_push_into_itself_is_refused(tmp_path):
    db = tmp_path / "r1.db"
    robot_store(db)
    done = subprocess.run([sys.executable, "-m", "slr_sql", "fleet", "push", str(db), str(db)],
                          capture_output=True, text=True, env=slr_env(), timeout=60)
    assert done.returncode == 1
    assert "itself" in done.stderr and "Traceback" not in done.stderr
    assert seen_rows(db) == 2


# -- a fleet store restored or replaced behind a following pusher -------------------------------

def test_a_batch_sent_after_a_position_the_fleet_no_longer_holds_is_a_conflict(server):
    rows = [[i, f"a{i}", float(i), float(i), float(i), None] for i in range(1, 4)]
    body = {"robot": "rb", "batches": [["after_t", 1, rows]], "after": [["after_t", 1, 0]]}
    assert HTTP.post(server.url + "/fleet/receive", json=body, timeout=30).json() == {
        "stored": 3}
    later = [[i, f"a{i}", float(i), float(i), float(i), None] for i in range(10, 12)]
    body = {"robot": "rb", "batches": [["after_t", 1, later]], "after": [["after_t", 1, 9]]}
    answer = HTTP.post(server.url + "/fleet/receive", json=body, timeout=30)
    assert answer.status_code == 409, answer.text
    assert answer.json()["error"]["kind"] == "Conflict"
    assert "up to seq 3, not 9" in answer.json()["error"]["message"]
    positions = HTTP.get(server.url + "/fleet/positions", params={"robot": "rb"}, timeout=30)
    assert positions.json() == {"positions": [["after_t", 1, 3]]}
    # the client cuts a large batch in requests, each after the one before
    many = [(i, f"m{i}", float(i), float(i), float(i), None) for i in range(1, 2501)]
    with slr_sql.connect(server.url) as client:
        assert client.fleet_receive("rb", [("many_t", 1, many)], after={("many_t", 1): 0}) \
            == 2500
        with pytest.raises(SLRError) as caught:
            client.fleet_receive("rb", [("many_t", 1, [(2600, "x", 1.0, 1.0, 1.0, None)])],
                                 after={("many_t", 1): 2599})
        assert getattr(caught.value, "kind", None) == "Conflict"


@pytest.fixture
def port():
    """A port held for the test, on which ``slr serve --port`` starts and restarts: closed
    first, another worker's server could be given it in between (``reserved_port``)."""
    with reserved_port() as held:
        yield held


def test_a_fleet_store_replaced_behind_a_following_pusher_gets_every_event(tmp_path, port):
    """The fleet's server restarts on an empty (or restored) store at the same URL between
    two rounds: the pusher, whose HTTP client reconnects without a word, kept the positions
    it had asked for and shipped only what came after them -- the events before were never
    shipped to the new store. Now the store answers Conflict and the pusher asks again."""
    import threading
    import time

    robot, fleet_db = tmp_path / "r1.db", tmp_path / "fleet.db"
    with slr_sql.open(robot, robot="r1", clock=slr_sql.ManualClock(100)) as kb:
        kb.add_many([f"seen(p{i})^{i}" for i in range(10)])

    def held(url: str) -> int:
        with slr_sql.connect(url) as client:
            return len(client.query("seen(X)^T"))

    def wait_for(count: int, url: str) -> None:
        deadline = time.monotonic() + 60
        while held(url) != count:
            assert time.monotonic() < deadline, f"the fleet holds {held(url)}, not {count}"
            stop.wait(0.05)

    stop = threading.Event()
    said: list[str] = []
    server = ServiceProcess(fleet_db, "--port", str(port))
    pusher = threading.Thread(target=fleet.push, args=(str(robot), server.url),
                              kwargs={"follow": True, "stop": stop, "say": said.append})
    pusher.start()
    try:
        wait_for(10, server.url)
        server.stop()
        for f in tmp_path.glob("fleet.db*"):
            f.unlink()
        server = ServiceProcess(fleet_db, "--port", str(port))
        with slr_sql.open(robot, clock=slr_sql.ManualClock(200)) as kb:
            kb.add_many([f"seen(p{i})^{i}" for i in range(10, 15)])
        wait_for(15, server.url)
    finally:
        stop.set()
        pusher.join()
        server.stop()
    # (the pusher asks the positions again either at the new store's Conflict or, when a
    # round met the server down -- a loaded machine's restart takes seconds -- once it is
    # reachable again: every event is shipped either way; the Conflict's path alone is
    # the test below)
    assert any("restored or replaced" in line for line in said) or \
        any("reachable again" in line for line in said), said


def test_a_pusher_whose_fleet_store_was_replaced_between_two_rounds_ships_it_all(tmp_path, port):
    """Between two rounds of one pusher the fleet's server restarts on an empty store at
    the same URL: the pusher's HTTP client reconnects without a word, and its positions are
    the old store's; the new store answers Conflict, the pusher says so, asks the positions
    again and ships every event, not only those after its old positions."""
    import threading

    robot, fleet_db = tmp_path / "r1.db", tmp_path / "fleet.db"
    said: list[str] = []
    stop = threading.Event()
    server = ServiceProcess(fleet_db, "--port", str(port))
    try:
        with slr_sql.open(robot, robot="r1", clock=slr_sql.ManualClock(100)) as kb:
            kb.add_many([f"seen(p{i})^{i}" for i in range(10)])
            pusher = fleet._Pusher(kb.store, lambda: fleet.open_target(server.url), "r1",
                                   None, fleet.BATCH, said.append, server.url)
            try:
                pusher.round(stop)
                server.stop()
                for f in tmp_path.glob("fleet.db*"):
                    f.unlink()
                server = ServiceProcess(fleet_db, "--port", str(port))
                kb.add_many([f"seen(p{i})^{i}" for i in range(10, 15)])
                pusher.round(stop)
            finally:
                pusher.drop()
        with slr_sql.connect(server.url) as client:
            assert len(client.query("seen(X)^T")) == 15
    finally:
        server.stop()
    assert any("restored or replaced" in line for line in said), said
    with slr_sql.open(fleet_db) as kb:
        assert sorted(str(a["X"]) for a in kb.query("seen(X)^T")) == sorted(
            f"p{i}" for i in range(15))


def test_a_following_pusher_stops_at_a_fleet_that_refuses_it_for_good(tmp_path):
    """A fleet that answers no to every shipment (here: the served store is the robot's own,
    a 400) is not an outage, and waiting does not change it: the pusher stops with the
    fleet's reason (tests/test_fleet_follow_refused.py: the command line, other statuses)."""
    db = tmp_path / "r1.db"
    robot_store(db)
    said: list[str] = []
    with ServiceProcess(db) as served:
        with pytest.raises(fleet.FleetRefused) as refused:
            fleet.push(str(db), served.url, follow=True, say=said.append)
    assert refused.value.status == 400
    assert "refused the push for good" in str(refused.value), refused.value
    assert "itself" in str(refused.value), refused.value
    assert not any("unreachable" in line for line in said), said
    assert seen_rows(db) == 2


# -- a robot that ships marks before any event ---------------------------------------------------

def marks_only_store(path, robot: str, until: float, events: int = 0) -> None:
    with slr_sql.open(path, robot=robot, clock=slr_sql.ManualClock(1000)) as kb:
        for i in range(events):
            kb.add(f"seen(x{i})^{i + 1}")
        kb.mark_complete("seen/1", until)


def fleet_mark(path) -> float | None:
    with slr_sql.open(path) as kb:
        return kb.store.meta_get("sync/mark/seen/1")


@pytest.mark.parametrize("where", ["file", "service"])
def test_a_robot_that_has_marks_but_no_events_ships_them(tmp_path, where):
    """A robot store with a completeness mark and no event yet: its push failed with
    "ValueError: min() arg is an empty sequence (this is a bug in slr_sql)" (and a
    following pusher died of it). Its mark counts for the fleet's from its first contact:
    the fleet's history is complete up to the least mark of the robots it knows."""
    fleet_db = tmp_path / "fleet.db"
    marks_only_store(tmp_path / "m1.db", "m1", 50.0)
    marks_only_store(tmp_path / "r2.db", "r2", 100.0, events=2)

    def push(name: str, target: str) -> int:
        return fleet.push(str(tmp_path / f"{name}.db"), target).shipped

    if where == "file":
        target = str(fleet_db)
        assert push("m1", target) == 0
        assert fleet_mark(fleet_db) == 50.0
        assert push("r2", target) == 2
        assert fleet_mark(fleet_db) == 50.0          # m1 is complete up to 50 only
        marks_only_store(tmp_path / "r2.db", "r2", 120.0)
        assert push("r2", target) == 0
        assert fleet_mark(fleet_db) == 50.0
        marks_only_store(tmp_path / "m1.db", "m1", 70.0)
        assert push("m1", target) == 0
        assert fleet_mark(fleet_db) == 70.0
    else:
        with ServiceProcess(fleet_db) as served:
            assert push("m1", served.url) == 0
            assert push("r2", served.url) == 2
            marks_only_store(tmp_path / "r2.db", "r2", 120.0)
            assert push("r2", served.url) == 0
        assert fleet_mark(fleet_db) == 50.0


@pytest.mark.parametrize("robot", ["", "a\x00b", "12", "[r1]"])
def test_a_contact_without_rows_from_a_robot_that_has_no_name_is_refused(server, robot):
    answer = HTTP.post(server.url + "/fleet/receive", timeout=30, json={
        "robot": robot, "batches": [], "pending": 3, "marks": {"seen/1": 5.0}})
    assert answer.status_code == 400, answer.text
    assert "robot" in answer.json()["error"]["message"]
    status = HTTP.get(server.url + "/fleet/status", timeout=30).json()["robots"]
    assert robot not in [r["robot"] for r in status]
