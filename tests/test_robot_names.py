"""A robot's name is shown in logs, `slr fleet status` tables, answers and plots: a name
holding a character that is not drawn but changes how the text around it is drawn (a
direction override such as U+202E, an isolate, U+200E/F, a zero-width or soft-hyphen
character, a control character, a line separator) is refused with an SLRError naming the
character and its position, wherever a name comes in: naming a store (API and `slr fleet
name`), a push (`--robot`, or a store named so before the check existed), a shipment to `slr
serve` (its robot, a row's robot column, relayed marks; HTTP 400, nothing stored), the fleet
positions asked for, and queries restricted to a robot (API, CLI, service)."""
from __future__ import annotations

import json
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest
from service_helpers import HTTP, ServiceProcess, slr_env

import slr_sql
from slr_sql import fleet
from slr_sql.errors import SLRError
from slr_sql.store import check_robot_name

ROOT = Path(__file__).resolve().parent.parent

UNSEEN = [
    pytest.param("r1\u202eevil", "U+202E RIGHT-TO-LEFT OVERRIDE at position 3", id="rlo"),
    pytest.param("\u202ar1", "U+202A LEFT-TO-RIGHT EMBEDDING at position 1", id="lre"),
    pytest.param("r1\u2066x\u2069", "U+2066 LEFT-TO-RIGHT ISOLATE at position 3", id="lri"),
    pytest.param("r\u2069", "U+2069 POP DIRECTIONAL ISOLATE at position 2", id="pdi"),
    pytest.param("r1\u200e", "U+200E LEFT-TO-RIGHT MARK at position 3", id="lrm"),
    pytest.param("r1\u200f", "U+200F RIGHT-TO-LEFT MARK at position 3", id="rlm"),
    pytest.param("r\u200b1", "U+200B ZERO WIDTH SPACE at position 2", id="zwsp"),
    pytest.param("r\u00ad1", "U+00AD SOFT HYPHEN at position 2", id="soft-hyphen"),
    pytest.param("r\ufeff1", "U+FEFF ZERO WIDTH NO-BREAK SPACE at position 2", id="bom"),
    pytest.param("r1\x1b[31m", "U+001B at position 3", id="escape"),
    pytest.param("r\x851", "U+0085 at position 2", id="next-line"),
    pytest.param("r\u20281", "U+2028 LINE SEPARATOR at position 2", id="line-separator"),
]


@pytest.mark.parametrize("name, words", UNSEEN)
def test_the_check_says_which_character_at_which_position(name, words):
    with pytest.raises(SLRError) as caught:
        check_robot_name(name)
    message = str(caught.value)
    assert words in message
    # the message itself shows the name escaped: it does not reverse what follows it
    assert name not in message and repr(name) in message


@pytest.mark.parametrize("name", ["r1", "forklift-2", "Roboter_ü", "ロボット1", "a b", " r1 "])
def test_plain_names_in_any_script_are_names(name):
    assert check_robot_name(name) == name


def test_naming_a_store_refuses_it_and_names_nothing(tmp_path):
    db = tmp_path / "r.db"
    slr_sql.open(db).close()
    with pytest.raises(SLRError, match="U\\+202E"):
        slr_sql.open(db, robot="r1\u202eevil")
    with slr_sql.open(db) as kb:
        assert kb.store.robot is None and kb.store.robots() == []


WHITE_SPACE_ONLY = [" ", "   ", "\u3000", "\u00a0 "]


@pytest.mark.parametrize("name", WHITE_SPACE_ONLY)
def test_a_name_of_white_space_only_is_refused_and_names_nothing(tmp_path, name):
    """It was taken: a robot shown in tables and logs as nothing at all."""
    with pytest.raises(SLRError, match="is only white space"):
        check_robot_name(name)
    db = tmp_path / "r.db"
    with pytest.raises(SLRError, match="is only white space"):
        slr_sql.open(db, robot=name)
    with slr_sql.open(db) as kb:
        assert kb.store.robot is None
        with pytest.raises(SLRError, match="is only white space"):
            kb.query("seen(X)^T", robot=name)


def slr(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "slr_sql", *args], capture_output=True,
                          text=True, env=slr_env(), cwd=ROOT, timeout=120)


@pytest.mark.parametrize("command", ["name", "push", "query"])
def test_the_cli_refuses_it_with_words_not_a_traceback(tmp_path, command):
    db = str(tmp_path / "r.db")
    assert slr("add", db, "seen(a)^1").returncode == 0
    bad = "r1\u202eevil"
    args = {"name": ["fleet", "name", db, bad],
            "push": ["fleet", "push", db, str(tmp_path / "fleet.db"), "--robot", bad],
            "query": ["query", db, "seen(X)^T", "--robot", bad]}[command]
    done = slr(*args)
    assert done.returncode == 1, done.stdout
    assert "U+202E RIGHT-TO-LEFT OVERRIDE at position 3" in done.stderr
    assert "Traceback" not in done.stderr and bad not in done.stderr
    assert not (tmp_path / "fleet.db").exists()
    with slr_sql.open(db) as kb:
        assert kb.store.robot is None


@pytest.mark.parametrize("command", ["name", "push", "query"])
def test_the_cli_refuses_a_name_of_white_space_only_in_words(tmp_path, command):
    db = str(tmp_path / "r.db")
    assert slr("add", db, "seen(a)^1").returncode == 0
    args = {"name": ["fleet", "name", db, " "],
            "push": ["fleet", "push", db, str(tmp_path / "fleet.db"), "--robot", " "],
            "query": ["query", db, "seen(X)^T", "--robot", " "]}[command]
    done = slr(*args)
    assert done.returncode == 1, done.stdout
    assert done.stderr == ("error: robot name ' ' is only white space; name robots with "
                           "plain words (r1, forklift-2, ...)\n")
    assert not (tmp_path / "fleet.db").exists()
    with slr_sql.open(db) as kb:
        assert kb.store.robot is None and kb.store.robots() == []


def test_a_store_named_so_before_the_check_does_not_ship(tmp_path):
    """A store named before names were checked for these characters opens as it is, but
    a push of it is refused before anything is shipped."""
    db = tmp_path / "old.db"
    with slr_sql.open(db, robot="r1", clock=slr_sql.ManualClock(10)) as kb:
        kb.add("seen(a)^1")
    conn = sqlite3.connect(db)
    with conn:
        conn.execute("UPDATE slr_meta SET value = ? WHERE key = 'robot'",
                     (json.dumps("r1\u202eevil"),))
    conn.close()
    with pytest.raises(SLRError, match="U\\+202E"):
        fleet.push(str(db), str(tmp_path / "fleet.db"))
    assert not (tmp_path / "fleet.db").exists()


def test_a_query_restricted_to_it_is_refused(tmp_path):
    with slr_sql.open(tmp_path / "r.db") as kb:
        for ask in (lambda: kb.query("seen(X)^T", robot="r\u200f"),
                    lambda: list(kb.solutions("seen(X)^T", robot="r\u200f")),
                    lambda: kb.submit("seen(X)^T", at=1, robot="r\u200f")):
            with pytest.raises(SLRError, match="U\\+200F RIGHT-TO-LEFT MARK at position 2"):
                ask()


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    with ServiceProcess(tmp_path_factory.mktemp("names") / "fleet.db") as s:
        yield s


BAD_SHIPMENTS = [
    pytest.param({"robot": "r1\u202eevil", "batches": [["seen", 1, [[1, "a", 1.0, 1.0, 1.0,
                                                                      None]]]]},
                 id="shipping-robot"),
    pytest.param({"robot": "r1", "batches": [["seen", 1, [[1, "a", 1.0, 1.0, 1.0,
                                                            "r2\u202eevil"]]]]},
                 id="row-robot"),
    pytest.param({"robot": "r1\u2066", "batches": [], "pending": 0,
                  "marks": {"seen/1": 5.0}}, id="contact-alone"),
    pytest.param({"robot": "hub", "batches": [], "relayed": {"r2\u200e": {"seen/1": 5.0}}},
                 id="relayed-marks"),
]


@pytest.mark.parametrize("shipment", BAD_SHIPMENTS)
def test_a_shipment_naming_it_is_a_400_and_stores_nothing(server, shipment):
    answer = HTTP.post(server.url + "/fleet/receive", json=shipment, timeout=30)
    assert answer.status_code == 400, answer.text
    message = answer.json()["error"]["message"]
    assert "robot name" in message and " at position " in message
    with slr_sql.open(server.db) as kb:
        assert kb.store.robots() == [] and kb.store.fleet_contacts() == []
        assert kb.store.meta_items("fleet/mark/") == {}
        assert "seen" not in {name for name, _ in kb.store.event_types()}


@pytest.mark.parametrize("ask", ["positions", "query"])
def test_the_service_refuses_it_in_a_question_too(server, ask):
    if ask == "positions":
        answer = HTTP.get(server.url + "/fleet/positions", params={"robot": "r1\u202e"},
                          timeout=30)
    else:
        answer = HTTP.post(server.url + "/query", timeout=30,
                           json={"goal": "seen(X)^T", "robot": "r1\u202e"})
    assert answer.status_code == 400, answer.text
    assert "U+202E RIGHT-TO-LEFT OVERRIDE at position 3" in answer.json()["error"]["message"]


@pytest.mark.parametrize("name", [
    "r" * 100_000 + "\u202e",       # (each refused for its length now, before its
    "1" * 100_000,                  # character, its reading as a number, its lone
    "r\ud800" + "r" * 100_000,      # surrogate)
    ["r"] * 100_000,                # no text at all
    "r" * 254 + "\u202e",           # the longest refused for a character
    "1" * 255,                      # ... for reading as a number
], ids=["format-character", "number", "surrogate", "no-text", "format-character-255",
        "number-255"])
def test_a_long_name_refused_makes_a_short_error(server, name):
    """The service's answer (and a log line) quotes the name refused: a 100 KB name made a
    100 KB error message, shown whole to whoever reads the answer or the log."""
    with pytest.raises(SLRError) as refused:
        check_robot_name(name)
    assert len(str(refused.value)) < 500, str(refused.value)[:200]
    if isinstance(name, str) and "\ud800" not in name:
        answer = HTTP.post(server.url + "/query", timeout=30,
                           json={"goal": "seen(X)^T", "robot": name})
        assert answer.status_code == 400, answer.text[:200]
        assert len(answer.json()["error"]["message"]) < 500


# -- a name's length ---------------------------------------------------------------------------

LONG = "r" * 500_000


def test_a_name_of_at_most_255_characters_of_any_script_is_a_name():
    assert check_robot_name("r" * 255) == "r" * 255
    assert check_robot_name("ロ" * 255) == "ロ" * 255   # (765 bytes of UTF-8)
    with pytest.raises(SLRError, match="is longer than 255 characters"):
        check_robot_name("r" * 256)


def test_naming_a_store_with_a_name_too_long_names_nothing(tmp_path):
    db = tmp_path / "r.db"
    with pytest.raises(SLRError, match="is longer than 255 characters"):
        slr_sql.open(db, robot=LONG)
    with slr_sql.open(db) as kb:
        assert kb.store.robot is None and kb.store.robots() == []


@pytest.mark.parametrize("shipment", [
    pytest.param({"robot": LONG, "batches": [["seen", 1, [[1, "a", 1.0, 1.0, 1.0, None]]]],
                  "marks": {"seen/1": 5.0}, "pending": 0}, id="shipping-robot"),
    pytest.param({"robot": "r1", "batches": [["seen", 1, [[1, "a", 1.0, 1.0, 1.0, LONG]]]]},
                 id="row-robot"),
    pytest.param({"robot": LONG, "batches": [], "marks": {"seen/1": 5.0}}, id="marks-alone"),
    pytest.param({"robot": "hub", "batches": [], "relayed": {LONG: {"seen/1": 5.0}}},
                 id="relayed-marks"),
])
def test_a_shipment_naming_a_robot_of_500_000_characters_is_a_400_and_stores_nothing(
        server, shipment):
    """A robot's name had no length limit: a shipment as a robot of 500,000 characters was
    stored (its rows, its marks under a 500 KB key, its contact), and `slr fleet status`
    printed the name whole."""
    answer = HTTP.post(server.url + "/fleet/receive", json=shipment, timeout=60)
    assert answer.status_code == 400, answer.text[:200]
    message = answer.json()["error"]["message"]
    assert "is longer than 255 characters" in message and len(message) < 500, message[:300]
    with slr_sql.open(server.db) as kb:
        assert kb.store.robots() == [] and kb.store.fleet_contacts() == []
        assert kb.store.meta_items("fleet/mark/") == {}
        assert "seen" not in {name for name, _ in kb.store.event_types()}


def test_postgresql_refuses_it_alike_and_takes_255_characters(postgres_url):
    from slr_sql.shipping import receive

    with slr_sql.open(postgres_url) as kb:
        with pytest.raises(SLRError, match="is longer than 255 characters"):
            receive(kb, LONG, [("seen", 1, [(1, "a", 1.0, 1.0, 1.0, None)])], {"seen/1": 5.0},
                    pending=0)
        assert kb.store.robots() == [] and kb.store.fleet_contacts() == []
        assert kb.store.meta_items("fleet/mark/") == {}
        longest = "ロ" * 255
        assert receive(kb, longest, [("seen", 1, [(1, "a", 1.0, 1.0, 1.0, None)])],
                       {"seen/1": 5.0}, pending=0) == 1
        assert kb.query("origin(R, seen(X)^T)", robot=longest)[0]["R"] == slr_sql.Atom(longest)


def test_the_cli_refuses_a_name_too_long_in_words(tmp_path):
    db = str(tmp_path / "r.db")
    assert slr("add", db, "seen(a)^1").returncode == 0
    done = slr("fleet", "push", db, str(tmp_path / "fleet.db"), "--robot", "r" * 300)
    assert done.returncode == 1, done.stdout
    assert "is longer than 255 characters" in done.stderr and "Traceback" not in done.stderr
    assert len(done.stderr) < 500
    assert not (tmp_path / "fleet.db").exists()
