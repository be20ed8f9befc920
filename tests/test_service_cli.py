"""`slr serve` and the other commands given the URL of a running server (real processes)."""
from __future__ import annotations

import json
import socket
import subprocess
import sys

import pytest

import slr_sql
from slr_sql.service.cli import is_loopback

from service_helpers import ROOT, ServiceProcess, slr_env

PROGRAM = """\
color(O, C)^T :- prev(obj(O, _, C)^_Z, T).
"""


def slr(*args: str, env: dict | None = None, stdin: str = "") -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "slr_sql", *args], input=stdin,
                          capture_output=True, text=True, cwd=ROOT, env=slr_env(env), timeout=120)


@pytest.fixture(scope="module")
def secured(tmp_path_factory):
    with ServiceProcess(tmp_path_factory.mktemp("cli") / "robot.db", "--token", "tok") as s:
        yield s


def test_every_db_command_takes_the_url(secured, tmp_path):
    url, env = secured.url, {"SLR_TOKEN": "tok"}
    program = tmp_path / "robot.slr"
    program.write_text(PROGRAM, encoding="utf-8")
    r = slr("load", url, str(program), env=env)
    assert r.returncode == 0 and "loaded" in r.stdout, r.stderr
    r = slr("add", url, "obj(cup1, cup, red)^2.0", "obj(cup1, cup, green)^9.0", env=env)
    assert r.returncode == 0 and "added 2 events" in r.stdout, r.stderr
    events = tmp_path / "events.txt"
    events.write_text('seg(cup1, [0.4, 0.1, 0.9])^10\n'
                      '{"name": "seg", "args": ["cup2", [1, 2, 3]], "time": 11}\n'
                      'seg(X, bad)^12\n', encoding="utf-8")
    r = slr("ingest", url, str(events), env=env)
    assert r.returncode == 1 and "ingested 2 events, 1 bad line" in r.stdout
    assert f"{events}:3:" in r.stderr
    r = slr("--token", "tok", "query", url, "color(cup1, C)^5")     # the group option
    assert r.returncode == 0 and r.stdout.splitlines() == ["C = red"], r.stderr
    r = slr("query", url, "seg(O, L)^T", "--at", "10.5", env=env)
    assert r.stdout.splitlines() == ["O = cup1, L = [0.4,0.1,0.9], T = 10.0"], r.stderr
    r = slr("add", url, "fullyUpdated(seg/2)^20", env=env)
    assert r.returncode == 0, r.stderr
    r = slr("query", url, "findall(O, seg(O, _)^_, L)", "--wait", "--at", "20", "--timeout", "10",
            env=env)
    assert r.returncode == 0 and r.stdout.splitlines() == ["L = [cup1,cup2]"], r.stderr
    assert r.stderr.startswith("% ") and "answered at clock" in r.stderr   # what it waited for
    r = slr("explain", url, "color(cup1, C)^5", env=env)
    assert r.returncode == 0 and r.stdout.startswith("goal: color(cup1, C)^5"), r.stderr
    r = slr("sql", url, "SELECT arg1, t_end FROM seg ORDER BY seq", "--json", env=env)
    assert json.loads(r.stdout) == [{"arg1": "cup1", "t_end": 10.0}, {"arg1": "cup2", "t_end": 11.0}]
    r = slr("sql", url, "DELETE FROM seg", env=env)
    assert r.returncode == 1 and "read-only" in r.stderr and "Traceback" not in r.stderr
    r = slr("stats", url, env=env)
    assert r.returncode == 0 and "seg/2: 2 stored" in r.stdout, r.stderr
    r = slr("shell", url, stdin="add obj(cup3, cup, blue)^3.\ncolor(cup3, C)^4.\n", env=env)
    assert r.stdout.splitlines() == ["added.", "C = blue ."], r.stderr


@pytest.mark.parametrize("args, env, words", [
    (("query", "{url}", "color(cup1, C"), {"SLR_TOKEN": "tok"}, "<query>:1:"),
    (("query", "{url}", "X is 1/0"), {"SLR_TOKEN": "tok"}, "error: arithmetic: division by zero"),
    (("query", "{url}", "true"), {"SLR_TOKEN": "wrong"}, "error: a valid token is required"),
    (("query", "{url}", "true"), None, "error: a valid token is required"),
    (("add", "{url}", "p(X)^1"), {"SLR_TOKEN": "tok"}, "p(X)^1.0: event arguments must be ground"),
])
def test_errors_through_the_url_are_words_not_tracebacks(secured, args, env, words):
    r = slr(*(a.format(url=secured.url) for a in args), env=env)
    assert r.returncode == 1
    assert words in r.stderr and "Traceback" not in r.stderr


def test_a_syntax_error_through_the_url_shows_the_caret(secured):
    r = slr("query", secured.url, "X = 1,\n  foo(", env={"SLR_TOKEN": "tok"})
    assert r.returncode == 1
    assert r.stderr.splitlines()[0].startswith("<query>:2:7:") and "^" in r.stderr


def test_an_unreachable_url_is_an_error_in_words():
    # a port bound and not listening (refused), held until the command is done: closed
    # first, another process's server could be given it meanwhile
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
        r = slr("query", f"http://127.0.0.1:{port}", "true")
    assert r.returncode == 1 and "cannot reach slr serve" in r.stderr
    assert "Traceback" not in r.stderr


@pytest.mark.parametrize("host", ["0.0.0.0", "::", ""])
def test_serve_refuses_a_non_loopback_address_without_a_token(tmp_path, host):
    db = tmp_path / "robot.db"
    r = slr("serve", str(db), "--host", host, "--port", "0")
    assert r.returncode == 1
    assert "refusing to serve" in r.stderr and "without a token" in r.stderr
    assert "Traceback" not in r.stderr
    assert not db.exists()       # refused before the store was opened


def test_serve_on_a_taken_port_is_an_error_in_words(tmp_path):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen(1)
        port = s.getsockname()[1]
        r = slr("serve", str(tmp_path / "robot.db"), "--port", str(port))
    assert r.returncode == 1 and f"cannot listen on 127.0.0.1:{port}" in r.stderr
    assert "Traceback" not in r.stderr


def test_serve_stops_cleanly_on_sigterm(tmp_path):
    db = tmp_path / "robot.db"
    server = ServiceProcess(db)
    with slr_sql.connect(server.url) as kb:
        kb.add("p(a)^1")
    server.stop()
    assert server.proc.returncode == 0
    with slr_sql.open(db) as kb:
        assert kb.query("p(X)^T") == [{"X": "a", "T": 1.0}]


@pytest.mark.parametrize("host, loopback", [
    ("127.0.0.1", True), ("127.0.0.2", True), ("::1", True), ("[::1]", True),
    ("localhost", True), ("0.0.0.0", False), ("::", False), ("", False), ("10.1.2.3", False),
])
def test_which_addresses_are_loopback(host, loopback):
    assert is_loopback(host) is loopback


def test_serve_parses_http_with_httptools(secured):
    # the C parser: the server's CPU per request (and so per add_many) ~10% below h11's
    # (uvicorn's default picks it only where it happens to be installed); the server process
    # has loaded its extension (a real process's memory map, not a setting read back)
    with open(f"/proc/{secured.proc.pid}/maps") as maps:
        assert "httptools/parser/parser." in maps.read()
