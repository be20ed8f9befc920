"""Robot tokens of a fleet store served by ``slr serve FLEET --token T --robot-tokens FILE``
(docs/fleet.md, "Robot tokens"): a request bearing robot R's token may ship to the fleet
store as R (``GET /fleet/positions``, ``POST /fleet/receive``) and do nothing else; a
shipment under another name, or bringing rows or marks of a robot R's line does not say it
relays, is refused 403 (``ServiceForbidden`` for a client) with nothing stored. The
server's own token still does everything. A file the server cannot take stops it at its
start, in words. A real ``slr serve`` process and SQLite files; pushes through the command
line and through ``slr_sql.fleet.push``.
"""
from __future__ import annotations

import json
import subprocess
import sys

import pytest
from service_helpers import HTTP, ServiceProcess, slr_env

import slr_sql
from slr_sql import fleet
from slr_sql.service.errors import ServiceForbidden

FULL = "full-token"
TOKENS = {"r1": "tok-r1", "r2": "tok-r2", "site": "tok-site", "r5": "tok-r5",
          "lone": "tok-lone"}
TOKENS_FILE = """\
# robot  token      (a store relaying other robots' rows names them)
r1       tok-r1
r2       tok-r2
site     tok-site   relays r5
r5       tok-r5
lone     tok-lone
"""


def bearer(robot: str | None) -> dict:
    return {"Authorization": f"Bearer {TOKENS[robot] if robot else FULL}"}


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    where = tmp_path_factory.mktemp("robot-tokens")
    (where / "tokens").write_text(TOKENS_FILE)
    with ServiceProcess(where / "fleet.db", "--token", FULL, "--robot-tokens",
                        str(where / "tokens")) as server:
        yield server


def robot_store(path, robot: str | None, *events: str, until: float | None = None) -> str:
    with slr_sql.open(path, robot=robot, clock=slr_sql.ManualClock(1000)) as kb:
        for event in events:
            kb.add(event)
        if until is not None:
            kb.mark_complete("seen/1", until)
    return str(path)


def slr(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "slr_sql", *args], env=slr_env(),
                          capture_output=True, text=True, timeout=120)


def origins(server, robot: str) -> list:
    """What the fleet store holds of ``robot`` (asked with the server's own token)."""
    with slr_sql.connect(server.url, token=FULL) as kb:
        return sorted(str(a["X"]) for a in kb.query(f"origin('{robot}', seen(X)^T)"))


def listed(server) -> set[str]:
    with slr_sql.connect(server.url, token=FULL) as kb:
        return {row["robot"] for row in kb.fleet_status()}


def test_a_robot_token_ships_as_its_robot(served, tmp_path):
    db = robot_store(tmp_path / "r1.db", "r1", "seen(a)^10", "seen(b)^11", until=11.0)
    pushed = slr("--token", TOKENS["r1"], "fleet", "push", db, served.url)
    assert pushed.returncode == 0, pushed.stderr
    assert "robot r1: shipped 2 events in 1 batches" in pushed.stdout
    assert origins(served, "r1") == ["a", "b"]
    # pushed again: the positions are asked as r1, nothing is shipped twice
    report = fleet.push(db, served.url, token=TOKENS["r1"])
    assert (report.robot, report.shipped) == ("r1", 0)
    assert origins(served, "r1") == ["a", "b"]


def test_a_robot_token_cannot_ship_under_another_name(served, tmp_path):
    """r1's token pushing r2's store (or any store under r2's name) is refused: before robot
    tokens, anyone holding the one token shipped as any robot."""
    db = robot_store(tmp_path / "r2.db", "r2", "seen(c)^12", until=12.0)
    pushed = slr("--token", TOKENS["r1"], "fleet", "push", db, served.url)
    assert pushed.returncode == 1
    assert "the token of robot 'r1' (--robot-tokens) ships as 'r1' only, not as 'r2'" in \
        pushed.stderr, pushed.stderr
    assert "Traceback" not in pushed.stderr
    with pytest.raises(ServiceForbidden, match="ships as 'r1' only, not as 'r2'") as info:
        fleet.push(db, served.url, token=TOKENS["r1"])
    assert (info.value.status, info.value.kind) == (403, "Forbidden")
    # by hand: the shipment, its positions, a contact alone with events pending (which
    # would hold the fleet's marks back for a robot that never ships)
    refused = [
        HTTP.get(served.url + "/fleet/positions", params={"robot": "r2"},
                 headers=bearer("r1")),
        HTTP.post(served.url + "/fleet/receive", headers=bearer("r1"), json={
            "robot": "r2", "batches": [["seen", 1, [[1, "c", 12.0, 12.0, 1.0, "r2"]]]]}),
        HTTP.post(served.url + "/fleet/receive", headers=bearer("r1"), json={
            "robot": "ghost", "batches": [], "pending": 5}),
    ]
    for answer in refused:
        assert answer.status_code == 403, answer.text
        assert answer.json()["error"]["kind"] == "Forbidden"
    assert origins(served, "r2") == []
    assert not {"r2", "ghost"} & listed(served)
    # r2 with its own token ships all the same
    assert fleet.push(db, served.url, token=TOKENS["r2"]).shipped == 1
    assert origins(served, "r2") == ["c"]


@pytest.mark.parametrize("shipment, what", [
    pytest.param({"batches": [["seen", 1, [[1, "x", 1.0, 1.0, 1.0, "lone"],
                                           [2, "y", 2.0, 2.0, 1.0, "ghost"]]]]},
                 "rows of robot 'ghost'", id="a-relayed-row"),
    pytest.param({"batches": [], "relayed": {"ghost": {"seen/1": 1e9}}},
                 "marks of robot 'ghost'", id="relayed-marks"),
    pytest.param({"batches": [["seen", 1, [[1, "x", 1.0, 1.0, 1.0, "r5"]]]]},
                 "rows of robot 'r5'", id="rows-of-a-robot-with-a-token"),
])
def test_a_robot_token_brings_no_rows_or_marks_of_robots_it_does_not_relay(
        served, shipment, what):
    """A robot's token shipping as itself could still bring rows (or marks) of any other
    name as relayed, and take that name's route or hold the fleet's marks back: only the
    robots its line names after ``relays`` may come with it."""
    answer = HTTP.post(served.url + "/fleet/receive", headers=bearer("lone"),
                       json={"robot": "lone", "pending": 0, **shipment})
    assert answer.status_code == 403, answer.text
    error = answer.json()["error"]
    assert error["kind"] == "Forbidden"
    assert f"ships no {what}: it does not relay that robot" in error["message"]
    assert origins(served, "ghost") == [] and origins(served, "lone") == []
    assert not {"lone", "ghost"} & listed(served)


def test_a_relaying_store_ships_the_robots_its_line_names(served, tmp_path):
    """A site store that r5 pushes to relays r5's rows and marks with the site's token (its
    line says ``relays r5``); a store whose line names no robot it relays is refused, and
    nothing of its shipment is stored."""
    r5 = robot_store(tmp_path / "r5.db", "r5", "seen(d)^20", until=20.0)
    site = robot_store(tmp_path / "site.db", "site", "seen(e)^21", until=30.0)
    fleet.push(r5, site)        # (into a store file: no token, full access)
    report = fleet.push(site, served.url, token=TOKENS["site"])
    assert (report.robot, report.shipped) == ("site", 2)
    assert origins(served, "r5") == ["d"] and origins(served, "site") == ["e"]
    with slr_sql.connect(served.url, token=FULL) as kb:
        via = {row["robot"]: row["via"] for row in kb.fleet_status()}
    assert via["r5"] == "site"

    r6 = robot_store(tmp_path / "r6.db", "r6", "seen(f)^22", until=22.0)
    lone = robot_store(tmp_path / "lone.db", "lone", "seen(g)^23")
    fleet.push(r6, lone)
    pushed = slr("--token", TOKENS["lone"], "fleet", "push", lone, served.url)
    assert pushed.returncode == 1
    assert "ships no rows of robot 'r6': it does not relay that robot" in pushed.stderr
    assert "Traceback" not in pushed.stderr
    assert origins(served, "r6") == [] and origins(served, "lone") == []


def _operations(server) -> list[tuple[str, str]]:
    spec = HTTP.get(server.url + "/openapi.json").json()
    return [(method.upper(), path) for path, ops in spec["paths"].items()
            for method, op in ops.items() if "401" in op["responses"]]


def test_a_robot_token_may_use_no_other_endpoint(served):
    """Every endpoint that needs a token but the two a pusher uses answers a robot's token
    403 Forbidden, before it reads the body or does anything; the clients raise
    ServiceForbidden. Over WebSocket a subscription and a query's answers one at a time are
    refused with code 4403."""
    with slr_sql.connect(served.url, token=FULL) as kb:
        before = kb.query("aggregate_all(count, seen(_)^_, N)")
        programs = kb.programs()
    checked = []
    for method, path in _operations(served):
        if (method, path) in {("GET", "/fleet/positions"), ("POST", "/fleet/receive")}:
            continue
        concrete = path.replace("{handle}", "abc").replace("{buffer_id}", "1")
        answer = HTTP.request(method, served.url + concrete, headers=bearer("r1"),
                              json={"event": "seen(intruder)^1", "goal": "true",
                                    "text": "p(a).", "name": "x", "type": "seen/1",
                                    "time": 1e9, "events": ["seen(intruder)^1"],
                                    "query": "SELECT 1", "pattern": "seen(X)^T",
                                    "keep_last": 1, "id": "x"})
        assert answer.status_code == 403, (method, path, answer.text)
        error = answer.json()["error"]
        assert error["kind"] == "Forbidden"
        assert f"may not use {method} {concrete};" in error["message"], error["message"]
        checked.append((method, path))
    assert {("POST", "/query"), ("POST", "/add"), ("POST", "/load"), ("POST", "/sql"),
            ("GET", "/fleet/status"), ("POST", "/mark_complete")} <= set(checked)
    with slr_sql.connect(served.url, token=TOKENS["r1"]) as robot:
        for call in (lambda: robot.query("seen(X)^T"), lambda: robot.add("seen(z)^1"),
                     lambda: robot.load("p(a).")):
            with pytest.raises(ServiceForbidden, match="may not use"):
                call()
        assert robot.health()["status"] == "ok"      # (/health needs no token at all)

    from websockets.sync.client import connect as ws_connect
    with ws_connect(served.url.replace("http", "ws") + "/subscribe",
                    additional_headers=bearer("r1")) as ws:
        ws.send(json.dumps({"op": "subscribe", "pattern": "seen(X)^T"}))
        message = json.loads(ws.recv())
    assert message["type"] == "error" and message["error"]["kind"] == "Forbidden"
    assert ws.close_code == 4403
    with ws_connect(served.url.replace("http", "ws") + "/solutions",
                    additional_headers=bearer("r1")) as ws:
        ws.send(json.dumps({"op": "solutions", "goal": "seen(X)^T"}))
        message = json.loads(ws.recv())
    assert message["type"] == "error" and message["error"]["kind"] == "Forbidden"
    assert "may not use a query;" in message["error"]["message"]
    assert ws.close_code == 4403
    with slr_sql.connect(served.url, token=TOKENS["r1"]) as robot:
        with pytest.raises(ServiceForbidden, match="may not use a query"):
            next(robot.solutions("seen(X)^T"))
    with slr_sql.connect(served.url, token=FULL) as kb:
        assert kb.query("aggregate_all(count, seen(_)^_, N)") == before
        assert kb.programs() == programs
    assert served.healthy()
    assert "Traceback" not in served.log.read_text()


def test_the_servers_own_token_still_does_everything(served, tmp_path):
    db = robot_store(tmp_path / "r9.db", "r9", "seen(h)^40")
    report = fleet.push(db, served.url, token=FULL)      # as any robot, as before
    assert (report.robot, report.shipped) == ("r9", 1)
    with slr_sql.connect(served.url, token=FULL) as kb:
        kb.add("seen(own)^41")
        kb.load("here(X) :- seen(X)^_.", name="here", replace=True)
        assert {str(a["X"]) for a in kb.query("here(X)")} >= {"h", "own"}
        assert "r9" in {row["robot"] for row in kb.fleet_status()}
        assert kb.fleet_positions("r9") == {("seen", 1): 1}
        assert kb.sql("SELECT count(*) FROM seen WHERE robot = ?", ["r9"])[1] == [(1,)]


@pytest.mark.parametrize("text, args, words", [
    pytest.param(None, (), "cannot read the robot tokens", id="missing"),
    pytest.param(b"r1 tok\xff\n", (), "not UTF-8 text", id="not-utf8"),
    pytest.param("# nothing but a comment\n\n", (), "hold no token", id="empty"),
    pytest.param("r1\n", (), "line 1: a robot token line is 'ROBOT TOKEN'", id="no-token"),
    pytest.param("r1 tok-r1\nr2 tok two\n", (),
                 "line 2: a robot token line is 'ROBOT TOKEN' or 'ROBOT TOKEN relays ROBOT...'; "
                 "this one has 1 more field(s) after the token", id="extra-field"),
    pytest.param("site tok relays\n", (), "names no robot after 'relays'", id="relays-nobody"),
    pytest.param("[r1] tok\n", (), "line 1: robot name", id="bad-robot-name"),
    pytest.param("site tok relays 42\n", (), "line 1: robot name", id="bad-relayed-name"),
    pytest.param("r1 tok\x01en\n", (), "line 1: a token cannot hold a control character",
                 id="control-character"),
    pytest.param("r1 full-token\n", (), "line 1: the token of robot 'r1' is the server's own "
                 "token", id="the-full-token"),
    pytest.param("r1 same\nr2 same\n", (), "line 2: the token of robot 'r2' is also the token "
                 "of robot 'r1' (TOKENS line 1)", id="a-token-twice"),
    pytest.param("r1 tok-r1\n", ("--no-token",), "robot tokens need the server's own token",
                 id="without-the-servers-token"),
])
def test_a_robot_tokens_file_the_server_cannot_take_stops_it_at_its_start(
        tmp_path, text, args, words):
    tokens = tmp_path / "tokens"
    if isinstance(text, bytes):
        tokens.write_bytes(text)
    elif text is not None:
        tokens.write_text(text)
    token = () if "--no-token" in args else ("--token", FULL)
    db = tmp_path / "fleet.db"
    result = subprocess.run(
        [sys.executable, "-m", "slr_sql", "serve", str(db), "--port", "0", *token,
         "--robot-tokens", str(tokens)],
        env=slr_env(), capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)
    assert result.returncode == 1, result
    assert words.replace("TOKENS", str(tokens)) in result.stderr, result.stderr
    assert "Traceback" not in result.stderr and result.stdout == ""
    said = result.stderr.replace(str(tmp_path), "FILE")
    for secret in ("tok-r1", "tok\x01en", FULL, "same"):   # (a secret: its line is named)
        assert secret not in said, said
    assert not db.exists()            # refused before the store is opened


def test_a_fleet_store_on_postgresql_served_with_robot_tokens_tells_robots_apart(
        postgres_url, tmp_path):
    """The tokens are the service's, whatever store it serves: a PostgreSQL fleet store
    behind ``slr serve`` takes r1's shipment from r1's token and refuses r2's."""
    (tmp_path / "tokens").write_text(TOKENS_FILE)
    r1 = robot_store(tmp_path / "r1.db", "r1", "seen(a)^10")
    r2 = robot_store(tmp_path / "r2.db", "r2", "seen(c)^12")
    with ServiceProcess(postgres_url, "--token", FULL, "--robot-tokens",
                        str(tmp_path / "tokens"), log=tmp_path / "serve.log") as server:
        assert fleet.push(r1, server.url, token=TOKENS["r1"]).shipped == 1
        with pytest.raises(ServiceForbidden, match="ships as 'r1' only, not as 'r2'"):
            fleet.push(r2, server.url, token=TOKENS["r1"])
        assert origins(server, "r1") == ["a"] and origins(server, "r2") == []
        assert listed(server) == {"r1"}


def test_the_tokens_file_of_the_docs_reads_as_it_says():
    from pathlib import Path

    from slr_sql.service.auth import parse_robot_tokens
    text = (Path(__file__).resolve().parent.parent / "docs" / "fleet.md").read_text()
    example = "#" + text.split("\n# robots.tokens:", 1)[1].split("```", 1)[0]
    assert [(t.robot, t.relays) for t in parse_robot_tokens(example)] == [
        ("r1", frozenset()), ("r2", frozenset()), ("site", frozenset({"r3", "r4"}))]
