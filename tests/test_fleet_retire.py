"""Retiring a robot from a fleet store (docs/fleet.md, "Retiring a robot").

The fleet's own mark of a type is the least of the marks of the robots it knows, and a
robot that goes quiet keeps counting: a robot scrapped, renamed, or one that only made
contact with a history would hold every synchronized query on the fleet back for good.
``slr fleet retire FLEET ROBOT`` (``slr_sql.fleet.retire``, ``slr_sql.shipping.retire``,
``POST /fleet/retire``) makes the fleet's marks stop waiting for it: they are computed
again from the robots left, and may rise (never fall); its events stay; ``slr fleet
status`` shows it retired; a later shipment of it, or relaying its rows, is refused until
``slr fleet reinstate``. A robot the store does not know, the store's own name and a store
no robot shipped to are refused, nothing changed. In process on a file and on PostgreSQL
(the suite's server), through the command line (real processes), and over a real ``slr
serve`` with robot tokens (only the server's own token retires).
"""
from __future__ import annotations

import json
import subprocess
import sys
import threading
import time

import pytest
from service_helpers import HTTP, ServiceProcess, slr_env

import slr_sql
from slr_sql import fleet
from slr_sql.shipping import RobotRetired, receive, reinstate, retire

from test_fleet_relay import robot_store

DEADLINE = 120.0   # a bound, not a pause: generous for a loaded 2-core machine
FULL = "fleet-server-token"
TOKENS_FILE = "r1 tok-r1\nr2 tok-r2\n"


def slr(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "slr_sql", *args], env=slr_env(),
                          capture_output=True, text=True, timeout=DEADLINE)


def refused(done: subprocess.CompletedProcess, words: str) -> None:
    """A command that failed in words, exit status 1, without a traceback."""
    assert done.returncode == 1, (done.stdout, done.stderr)
    assert words in done.stderr, done.stderr
    assert "Traceback" not in done.stderr, done.stderr


def row(seq: int, value: str, t: float, robot: str | None = None) -> tuple:
    """A shipped row of seen/1 (as a robot's store reads it for shipping)."""
    return (seq, value, t, t, t, robot)


def mark(kb) -> float | None:
    """The fleet store's own mark of seen/1."""
    return kb.store.meta_get("sync/mark/seen/1")


@pytest.fixture(params=["file", "postgres"])
def where(request, tmp_path):
    if request.param == "postgres":
        return request.getfixturevalue("postgres_url")
    return str(tmp_path / "fleet.db")


def test_retiring_a_quiet_robot_lets_the_fleets_marks_rise_and_keeps_its_events(where):
    with slr_sql.open(where, clock=slr_sql.ManualClock(1000)) as kb:
        receive(kb, "r2", [("seen", 1, [row(1, "b", 2.0)])], {"seen/1": 5.0}, pending=0)
        receive(kb, "r1", [("seen", 1, [row(1, "a", 1.0)])], {"seen/1": 20.0}, pending=0)
        receive(kb, "ghost", [], pending=0)        # (a contact alone: listed, not counted)
        assert mark(kb) == 5.0                      # r2 went quiet at 5
        done = retire(kb, "r2")
        assert (done["robot"], done["already"], done["raised"]) == ("r2", False,
                                                                    {"seen/1": 20.0})
        assert mark(kb) == 20.0
        # its events stay, for queries restricted to it and for origin/2
        assert kb.query("seen(X)^T", robot="r2") == [{"X": "b", "T": 2.0}]
        assert [str(a["R"]) for a in kb.query("origin(R, seen(_)^_)")] == ["r1", "r2"]
        status = {r["robot"]: r["retired_at"] for r in kb.store.fleet_contacts()}
        assert status["r2"] == done["retired_at"] and status["r1"] is None
        # the fleet's marks now follow the robots left
        receive(kb, "r1", [], {"seen/1": 30.0})
        assert mark(kb) == 30.0
        # retired again: nothing changes; a contact-only name retired: nothing rises
        assert retire(kb, "r2")["already"] and retire(kb, "r2")["retired_at"] == done["retired_at"]
        assert retire(kb, "ghost")["raised"] == {}
        assert {r["robot"] for r in kb.store.fleet_contacts()
                if r["retired_at"] is not None} == {"r2", "ghost"}
        # reinstated, it counts again -- from where the marks are: they never fall
        assert reinstate(kb, "r2") == {"robot": "r2", "reinstated": True}
        assert reinstate(kb, "r2") == {"robot": "r2", "reinstated": False}
        assert mark(kb) == 30.0
        receive(kb, "r1", [], {"seen/1": 40.0})
        assert mark(kb) == 30.0                    # r2's mark (5) holds it again
        receive(kb, "r2", [], {"seen/1": 35.0})
        assert mark(kb) == 35.0


def test_retiring_never_lowers_a_mark_and_with_no_robot_left_moves_none(where):
    """The fleet's mark went to 20 while r1 was the only robot it knew; r2 joined at 5.
    Retiring r1 leaves r2 (5): the mark stays 20. Retiring r2 too leaves no robot to
    count: the marks stay where they are."""
    with slr_sql.open(where, clock=slr_sql.ManualClock(1000)) as kb:
        receive(kb, "r1", [("seen", 1, [row(1, "a", 1.0)])], {"seen/1": 20.0}, pending=0)
        receive(kb, "r2", [("seen", 1, [row(1, "b", 2.0)])], {"seen/1": 5.0}, pending=0)
        assert mark(kb) == 20.0
        assert retire(kb, "r1")["raised"] == {}
        assert mark(kb) == 20.0
        assert retire(kb, "r2")["raised"] == {}
        assert mark(kb) == 20.0


def test_a_retired_robot_ships_nothing_until_reinstated(where):
    """Rows, marks or a contact alone of a retired robot, and rows of it relayed by another
    store, are refused whole with RobotRetired: nothing stored, no position moved."""
    with slr_sql.open(where, clock=slr_sql.ManualClock(1000)) as kb:
        receive(kb, "r2", [("seen", 1, [row(1, "b", 2.0)])], {"seen/1": 5.0}, pending=0)
        receive(kb, "r1", [("seen", 1, [row(1, "a", 1.0)])], {"seen/1": 20.0}, pending=0)
        receive(kb, "site", [("seen", 1, [row(1, "c", 3.0, "r3")])], pending=0)
        retire(kb, "r2")
        retire(kb, "r3")
        before = (kb.query("seen(X)^T"), kb.store.fleet_positions("r2"),
                  kb.store.fleet_positions("site"), kb.store.meta_items("fleet/mark/"))
        for shipment in (([("seen", 1, [row(2, "late", 4.0)])], None, 0),
                         ([], {"seen/1": 50.0}, None), ([], None, 0)):
            with pytest.raises(RobotRetired, match="robot 'r2' was retired from this fleet "
                               "store .*slr fleet reinstate FLEET r2"):
                receive(kb, "r2", *shipment)
        with pytest.raises(RobotRetired, match="robot 'r3' was retired .*'site' relaying "
                           "its rows is refused"):
            receive(kb, "site", [("seen", 1, [row(2, "d", 4.0), row(3, "e", 5.0, "r3")])])
        assert (kb.query("seen(X)^T"), kb.store.fleet_positions("r2"),
                kb.store.fleet_positions("site"), kb.store.meta_items("fleet/mark/")) == before
        # (the site's own rows, and another robot's, still ship)
        assert receive(kb, "site", [("seen", 1, [row(2, "d", 4.0)])]) == 1
        reinstate(kb, "r2")
        assert receive(kb, "r2", [("seen", 1, [row(2, "late", 4.0)])], pending=0) == 1


# a recent rule on the fleet store: its decision for b(1)^3 waits for a/1 and b/1 to be
# complete up to 3 (the declared max_delays leave that to the marks)
RECENT_RULE = (":- max_delay(a/1, 1.0e9).\n:- max_delay(b/1, 1.0e9).\n"
               ":- consumption(recent).\nr(X) <- a(X) seq b(X).\n")


@pytest.mark.parametrize("shipped_by", ["the same connection", "another connection"])
@pytest.mark.parametrize("raised_by", ["a shipment's marks", "a retirement"])
def test_the_marks_a_fleet_store_raises_make_the_decisions_of_its_event_rules(where,
                                                                               raised_by,
                                                                               shipped_by):
    """The fleet's marks rise in the fleet store's own transaction (a shipment of marks, a
    retirement), not by a mark added to it: the decisions of its event rules that they
    allow are made then, as a mark's are -- they waited for the next add or clock move,
    and a synchronized query on the complex events timed out on a decision pending though
    every type the rule reads was complete. When another connection (another pusher) left
    the decision pending, a query waiting on the complex events is not released by the
    marks before it is made (it was answered without the complex event)."""
    def a_row(seq: int, value: int, t: float) -> tuple:
        return (seq, value, t, t, t, None)

    clock = slr_sql.ManualClock(1000)
    with slr_sql.open(where, clock=clock) as kb, slr_sql.open(where, clock=clock) as other:
        kb.load(RECENT_RULE)
        shipping = kb if shipped_by == "the same connection" else other
        receive(shipping, "r2", [("a", 1, [a_row(1, 1, 0.5)])], {"a/1": 2.0, "b/1": 2.0},
                pending=0)
        receive(shipping, "r1", [("a", 1, [a_row(1, 1, 1.0)]), ("b", 1, [a_row(2, 1, 3.0)])],
                {"a/1": 10.0, "b/1": 10.0}, pending=0)
        assert kb.query("r(X)^[S, E]") == []          # the fleet: complete up to 2 only
        waiting = kb.submit("r(X)^[S, E]", at=5)
        if raised_by == "a retirement":
            assert retire(kb, "r2")["raised"] == {"a/1": 10.0, "b/1": 10.0}
        else:
            receive(kb, "r2", [], {"a/1": 10.0, "b/1": 10.0})
        assert kb.query("r(X)^[S, E]") == [{"X": 1, "S": 1.0, "E": 3.0}]
        assert waiting.result(timeout=DEADLINE) == [{"X": 1, "S": 1.0, "E": 3.0}]


def test_an_error_after_the_marks_a_shipment_raised_is_logged_and_the_shipment_stands(
        where, caplog):
    """A listener of the fleet store failing on the complex events the shipment's marks let
    its rules decide, once the shipment committed: receive raised the listener's own
    ZeroDivisionError (a served fleet store answered the pusher 500, its log a traceback)
    though the shipment was stored. It is logged in words; receive answers as stored."""
    def a_row(seq: int, value: int, t: float) -> tuple:
        return (seq, value, t, t, t, None)

    def fails_on_complex_events(batch: list) -> None:
        if any(event[0] == "r" for event in batch):
            raise ZeroDivisionError("division by zero")

    with slr_sql.open(where, clock=slr_sql.ManualClock(1000)) as kb:
        kb.load(RECENT_RULE)
        kb.add_listeners.append(fails_on_complex_events)
        receive(kb, "r2", [], {"a/1": 2.0, "b/1": 2.0}, pending=0)
        receive(kb, "r1", [("a", 1, [a_row(1, 1, 1.0)]), ("b", 1, [a_row(2, 1, 3.0)])],
                {"a/1": 10.0, "b/1": 10.0}, pending=0)
        with caplog.at_level("WARNING", logger="slr_sql.shipping"):
            assert receive(kb, "r2", [("a", 1, [a_row(1, 7, 4.0)])],
                           {"a/1": 10.0, "b/1": 10.0}, pending=3) == 1
        assert kb.query("r(X)^[S, E]") == [{"X": 1, "S": 1.0, "E": 3.0}]
        assert [r.getMessage() for r in caplog.records] == [
            "the fleet store's marks moved (committed), but its event rules' decisions "
            "failed (ZeroDivisionError: division by zero)"]
        assert all(r.exc_info is None for r in caplog.records)
        assert {c["robot"]: c["pending"] for c in kb.store.fleet_contacts()}["r2"] == 3


def test_a_shipment_waits_for_a_retirement_of_its_robot_in_flight(postgres_url):
    """Two connections of a PostgreSQL fleet store: a shipment of r2 that starts while a
    retirement of r2 has not committed waits for it, then is refused -- it must not store
    r2's rows behind marks the retirement raised past them (on SQLite one writer at a time
    does the same)."""
    import psycopg

    clock = slr_sql.ManualClock(1000)
    with slr_sql.open(postgres_url, clock=clock) as shipping, \
            slr_sql.open(postgres_url, clock=clock) as operator:
        receive(shipping, "r2", [("seen", 1, [row(1, "b", 2.0)])], {"seen/1": 5.0}, pending=0)
        receive(shipping, "r1", [("seen", 1, [row(1, "a", 1.0)])], {"seen/1": 20.0}, pending=0)
        outcome: list = []

        def ship() -> None:
            try:
                outcome.append(receive(shipping, "r2", [("seen", 1, [row(2, "late", 3.0)])]))
            except slr_sql.SLRError as exc:
                outcome.append(exc)
        shipper = threading.Thread(target=ship)
        with operator.store.transaction():
            assert retire(operator, "r2")["raised"] == {"seen/1": 20.0}
            shipper.start()
            deadline = time.monotonic() + DEADLINE
            with psycopg.connect(postgres_url, autocommit=True) as watch:
                # (until the shipment waits for a lock, or is done: each look a round trip)
                while shipper.is_alive() and not watch.execute(
                        "SELECT count(*) FROM pg_locks WHERE NOT granted AND locktype = "
                        "'advisory'").fetchone()[0]:
                    assert time.monotonic() < deadline, "the shipment neither waited nor ended"
        shipper.join(DEADLINE)
        assert len(outcome) == 1 and isinstance(outcome[0], RobotRetired), outcome
        assert shipping.query("seen(X)^T", robot="r2") == [{"X": "b", "T": 2.0}]


def test_a_robot_known_by_its_events_alone_is_listed_once_retired(tmp_path):
    """A robot the fleet store holds events of without a contact row (a store upgraded from
    before contacts were kept, or edited by hand) can be retired, and is listed so."""
    import sqlite3

    where = str(tmp_path / "fleet.db")
    with slr_sql.open(where, clock=slr_sql.ManualClock(1000)) as kb:
        receive(kb, "r1", [("seen", 1, [row(1, "a", 1.0)])], {"seen/1": 20.0}, pending=0)
    conn = sqlite3.connect(where, isolation_level=None)
    conn.execute("INSERT INTO slr_robots (name) VALUES ('old')")
    conn.close()
    with slr_sql.open(where, clock=slr_sql.ManualClock(1000)) as kb:
        assert "old" not in {r["robot"] for r in kb.store.fleet_contacts()}
        at = retire(kb, "old")["retired_at"]
        assert [(r["robot"], r["retired_at"]) for r in kb.store.fleet_contacts()] == [
            ("old", at), ("r1", None)]


def test_retire_refuses_what_is_no_robot_of_the_fleet(where, tmp_path):
    named = str(tmp_path / "site.db")
    with slr_sql.open(where, clock=slr_sql.ManualClock(1000)) as kb:
        with pytest.raises(slr_sql.SLRError, match="no fleet store: no robot has shipped"):
            retire(kb, "r1")
        receive(kb, "r1", [("seen", 1, [row(1, "a", 1.0)])], {"seen/1": 20.0}, pending=0)
        for call in (retire, reinstate):
            with pytest.raises(slr_sql.SLRError, match=r"knows no robot 'r9' \(it knows 'r1'\)"):
                call(kb, "r9")
            with pytest.raises(slr_sql.SLRError, match="robot name"):
                call(kb, "r1\u202e")
        assert kb.store.fleet_retired() == {} and mark(kb) == 20.0
    with slr_sql.open(named, robot="site", clock=slr_sql.ManualClock(1000)) as kb:
        receive(kb, "r1", [("seen", 1, [row(1, "a", 1.0)])], pending=0)
        with pytest.raises(slr_sql.SLRError, match="'site' is this fleet store's own name"):
            retire(kb, "site")
        assert kb.store.fleet_retired() == {}


def test_the_command_line_retires_shows_and_reinstates(tmp_path):
    """Real processes: retire, status (text and --json), a push of the retired robot
    refused (exit 1, --follow too, in words), the errors without a traceback, reinstate."""
    r1 = robot_store(tmp_path / "r1.db", "r1", 20.0, ("seen(a)^1",))
    r2 = robot_store(tmp_path / "r2.db", "r2", 5.0, ("seen(b)^2",))
    r3 = robot_store(tmp_path / "r3.db", "r3", 30.0, ("seen(c)^3",))
    fleet_db = str(tmp_path / "fleet.db")
    fleet.push(r2, fleet_db)
    fleet.push(r1, fleet_db)
    fleet.push(r3, str(tmp_path / "site.db"))
    fleet.push(str(tmp_path / "site.db"), fleet_db, robot="site")   # (relays r3)
    done = slr("fleet", "retire", fleet_db, "r2")
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("robot r2 retired (")
    assert done.stdout.rstrip().endswith("UTC); the fleet's marks rose: seen/1 to 20")
    again = slr("fleet", "retire", fleet_db, "r2")
    assert again.returncode == 0 and "robot r2 was retired already" in again.stdout
    fleet.retire(fleet_db, "r3")
    text = slr("fleet", "status", fleet_db)
    assert text.returncode == 0, text.stderr
    lines = {line.split()[0]: line for line in text.stdout.splitlines()[1:]}
    assert "retired 20" in lines["r2"] and lines["r2"].rstrip().endswith(" UTC")
    assert lines["r3"].rstrip().endswith(" UTC, relayed via site") and "retired 20" in lines["r3"]
    assert "retired" not in lines["r1"] + lines["site"]
    rows = {r["robot"]: r for r in json.loads(slr("fleet", "status", fleet_db, "--json").stdout)}
    assert rows["r1"]["retired_at"] is None and isinstance(rows["r2"]["retired_at"], float)
    # the relaying store: its shipments go on while they bring no row of r3 (its marks of r3
    # are kept, and do not count); one that does is refused
    assert fleet.push(str(tmp_path / "site.db"), fleet_db).shipped == 0
    with slr_sql.open(r3, clock=slr_sql.ManualClock(1000)) as kb:
        kb.add("seen(d)^4")
    fleet.push(r3, str(tmp_path / "site.db"))
    with pytest.raises(RobotRetired, match="robot 'r3' was retired .*'site' relaying"):
        fleet.push(str(tmp_path / "site.db"), fleet_db)
    refused(slr("fleet", "push", r2, fleet_db), "robot 'r2' was retired from this fleet store")
    refused(slr("fleet", "push", r2, fleet_db, "--follow"),
            "refused the push for good (robot 'r2' was retired")
    refused(slr("fleet", "retire", fleet_db, "r9"), "error: this fleet store knows no robot 'r9'")
    refused(slr("fleet", "retire", r1, "r1"), "'r1' is this fleet store's own name")
    refused(slr("fleet", "retire", r1, "r7"), "no fleet store: no robot has shipped to it")
    refused(slr("fleet", "retire", str(tmp_path / "none.db"), "r1"), "no such store")
    assert not (tmp_path / "none.db").exists()
    back = slr("fleet", "reinstate", fleet_db, "r2")
    assert back.returncode == 0 and "robot r2 reinstated" in back.stdout
    pushed = slr("fleet", "push", r2, fleet_db)
    assert pushed.returncode == 0, pushed.stderr


def test_over_slr_serve_only_the_servers_token_retires(tmp_path):
    """A robot's token may not retire another robot (403, nothing changed); the server's
    own token retires, which answers a synchronized query waiting on the fleet; a retired
    robot's following pusher stops with exit status 1; status shows it retired."""
    (tmp_path / "tokens").write_text(TOKENS_FILE)
    # (marks beyond the server's wall clock, so that only they can answer the query)
    r1 = robot_store(tmp_path / "r1.db", "r1", 2e12, ("seen(a)^1",))
    r2 = robot_store(tmp_path / "r2.db", "r2", 1e12, ("seen(b)^2",))
    with ServiceProcess(tmp_path / "fleet.db", "--token", FULL, "--robot-tokens",
                        str(tmp_path / "tokens")) as server, \
            slr_sql.connect(server.url, token=FULL) as client:
        fleet.push(r2, server.url, token="tok-r2")
        fleet.push(r1, server.url, token="tok-r1")
        pending = client.submit("findall(X, seen(X)^_, L)", at=1.5e12)
        answer = HTTP.post(server.url + "/fleet/retire", json={"robot": "r2"}, timeout=30,
                           headers={"Authorization": "Bearer tok-r1"})
        assert answer.status_code == 403 and answer.json()["error"]["kind"] == "Forbidden"
        refused(slr("--token", "tok-r1", "fleet", "retire", server.url, "r2"),
                "may not use POST /fleet/retire; the server's own token may")
        assert [r["retired_at"] for r in client.fleet_status()] == [None, None]
        assert not pending.done()
        done = slr("--token", FULL, "fleet", "retire", server.url, "r2")
        assert done.returncode == 0 and "rose: seen/1 to 2e+12" in done.stdout, done.stderr
        assert [str(x) for x in pending.result(timeout=DEADLINE)[0]["L"]] == ["a", "b"]
        refused(slr("--token", "tok-r2", "fleet", "push", r2, server.url, "--follow"),
                "HTTP 400 RobotRetired: robot 'r2' was retired")
        refused(slr("--token", FULL, "fleet", "retire", server.url, "r9"), "knows no robot 'r9'")
        rows = json.loads(slr("--token", FULL, "fleet", "status", server.url, "--json").stdout)
        assert [(r["robot"], r["retired_at"] is not None) for r in rows] == [("r1", False),
                                                                            ("r2", True)]
        assert client.fleet_reinstate("r2") == {"robot": "r2", "reinstated": True}
        assert fleet.push(r2, server.url, token="tok-r2").shipped == 0


def test_a_pushed_mark_answers_a_synchronized_query_waiting_on_a_served_fleet(tmp_path):
    """A shipment whose marks raise the fleet's mark releases the queries waiting on the
    served fleet store: it raises the mark on the server's own connection, which the
    server's check for other processes' commits does not see (the query waited for its
    timeout before)."""
    r1 = robot_store(tmp_path / "r1.db", "r1", 1e12, ("seen(a)^1",))
    with ServiceProcess(tmp_path / "fleet.db") as server, \
            slr_sql.connect(server.url) as client:
        fleet.push(r1, server.url)
        # (marks beyond the server's wall clock, so that only they can answer the query)
        pending = client.submit("findall(X, seen(X)^_, L)", at=1.5e12)
        assert not pending.done()
        robot_store(tmp_path / "r1.db", "r1", 2e12)
        fleet.push(r1, server.url)
        assert [str(x) for x in pending.result(timeout=DEADLINE)[0]["L"]] == ["a"]
