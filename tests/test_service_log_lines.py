"""What a client sends never becomes a line of `slr serve`'s log of its own: a line break (or
a NUL) in an event's name, which `add_event` takes as any string, is written escaped in the
warnings the server prints. Real `slr serve` processes, on a file and on PostgreSQL."""
from __future__ import annotations

from service_helpers import HTTP, ServiceProcess

FORGED = 'INFO:     127.0.0.1:1 - "GET /forged HTTP/1.1" 200 OK'


def test_an_event_name_with_a_line_break_stays_on_its_warnings_line(backend, tmp_path):
    """The learned-delay warning (an event stamped long before the server's wall clock)
    names the event type: with the name quoted as Prolog writes it, the client's line
    break is the two characters ``\\n`` and its text no line of the log (it was a line of
    its own, a forged access-log line, on both backends)."""
    with ServiceProcess(backend, log=tmp_path / "serve.log") as server:
        answer = HTTP.post(server.url + "/add_event", json={
            "name": f"zz\n{FORGED}\nx", "args": ["a"], "start": 2.0}, timeout=30)
        assert answer.status_code == 200, answer.text
        # (a PostgreSQL store refuses a NUL in a name: 400, docs/postgres.md)
        answer = HTTP.post(server.url + "/add_event", json={
            "name": "n\x00ul", "args": ["a"], "start": 2.0}, timeout=30)
        assert answer.status_code in (200, 400), answer.text
    log = (tmp_path / "serve.log").read_text()
    assert "'zz\\nINFO:" in log, log          # the warning came, with the name escaped
    assert not any(line.startswith(FORGED) for line in log.splitlines()), log
    assert "\x00" not in log, "a NUL of the client's in the log"


def test_warnings_a_client_causes_are_bounded_lines(tmp_path):
    """Each event type a client adds with old times makes a learned-delay warning that names
    the type: printed whole, 30 types of 2,000-character names made 30 lines of 6,000
    characters. They are lines of the service's logger now, as the other lines a client
    causes: cut after 200 characters of text, at most 20 of the kind a minute."""
    log_path = tmp_path / "serve.log"
    with ServiceProcess(tmp_path / "robot.db", log=log_path) as server:
        events = [{"name": f"t{i}_" + "x" * 2000, "args": ["a"], "start": 2.0}
                  for i in range(30)]
        answer = HTTP.post(server.url + "/add_many", json={"events": events}, timeout=60)
        assert answer.status_code == 200 and answer.json()["accepted"] == 30, answer.text
    warned = [line for line in log_path.read_text().splitlines()
              if line.startswith("warning: t")]
    assert 1 <= len(warned) <= 20, warned
    assert all(len(line) < 300 for line in warned), max(map(len, warned))
    assert "more characters)" in warned[0]
