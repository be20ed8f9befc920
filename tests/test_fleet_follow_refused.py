"""``slr fleet push --follow`` and a fleet that refuses it (docs/fleet.md, "--follow"): a
refusal no retry changes (a bad or missing token 401, a robot token that may not ship as
this robot 403, a shipment the fleet will never take 400, an unknown endpoint 404, a body
beyond the fleet's limit 413) ends the pusher with one line of words and exit status 1;
what may pass (no answer, 503, 500, 408, 429) is retried with backoff until SIGTERM, exit 0.

Real ``slr serve`` processes for the refusals it gives (401, 403, 400), and for the other
statuses a small HTTP server of this process that answers each request with the status
and the service's error body (``slr serve`` gives a 404 or a 413 to a pusher only behind a
proxy or when misconfigured, and a 503 only under load); the pushers are real
``python -m slr_sql`` processes.
"""
from __future__ import annotations

import json
import signal
import subprocess
import sys
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import pytest
from service_helpers import ServiceProcess, slr_env

import slr_sql

ROOT = Path(__file__).resolve().parent.parent
DEADLINE = 120.0   # a bound, not a pause: generous for a loaded 2-core machine


def robot_store(path: Path, robot: str) -> str:
    with slr_sql.open(path, robot=robot, clock=slr_sql.ManualClock(1000)) as kb:
        kb.add("seen(a)^10")
        kb.add("seen(b)^11")
    return str(path)


def follow(*args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "slr_sql", *args, "--follow"],
                            env=slr_env(), cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def ended(pusher: subprocess.Popen) -> tuple[int, str, str]:
    """The exit status, stdout and stderr of a pusher that must end on its own."""
    try:
        out, err = pusher.communicate(timeout=DEADLINE)
    except subprocess.TimeoutExpired:
        pusher.kill()
        out, err = pusher.communicate()
        raise AssertionError(f"the pusher kept following a refusal: {err}") from None
    return pusher.returncode, out, err


def held(fleet_db: Path) -> int:
    with slr_sql.open(fleet_db) as kb:
        return len(kb.query("seen(X)^T"))


def assert_stopped_in_words(err: str, status: str) -> None:
    lines = err.splitlines()
    assert lines[0].startswith("following "), err          # (what --follow says first)
    assert len(lines) == 2, err
    assert lines[1].startswith("error: fleet http://127.0.0.1:"), err
    assert f"refused the push for good (HTTP {status}" in lines[1], err
    assert "the push stopped" in lines[1] and "retrying" not in err, err
    assert "Traceback" not in err


def test_a_bad_or_missing_token_ends_a_following_pusher(tmp_path):
    db = robot_store(tmp_path / "r1.db", "r1")
    with ServiceProcess(tmp_path / "fleet.db", "--token", "right") as served:
        for token in (["--token", "wrong"], []):
            code, out, err = ended(follow(*token, "fleet", "push", db, served.url))
            assert code == 1, err
            assert_stopped_in_words(err, "401 Unauthorized")
            assert out == ""
    assert held(tmp_path / "fleet.db") == 0


def test_a_robot_token_that_may_not_ship_as_this_robot_ends_a_following_pusher(tmp_path):
    (tmp_path / "tokens").write_text("r1 tok-r1\nr2 tok-r2\n")
    db = robot_store(tmp_path / "r2.db", "r2")
    with ServiceProcess(tmp_path / "fleet.db", "--token", "full", "--robot-tokens",
                        str(tmp_path / "tokens")) as served:
        code, out, err = ended(follow("--token", "tok-r1", "fleet", "push", db, served.url))
        assert code == 1, err
        assert_stopped_in_words(err, "403 Forbidden")
        assert "ships as 'r1' only, not as 'r2'" in err
        # its own token ships it
        shipped = subprocess.run([sys.executable, "-m", "slr_sql", "--token", "tok-r2",
                                  "fleet", "push", db, served.url], env=slr_env(), cwd=ROOT,
                                 capture_output=True, text=True, timeout=DEADLINE)
        assert shipped.returncode == 0, shipped.stderr
    assert held(tmp_path / "fleet.db") == 2


def test_a_fleet_that_is_the_robots_own_store_ends_a_following_pusher(tmp_path):
    """Served (a 400) or opened by the pusher (a store named as the robot), the fleet
    refuses every shipment of the robot: the follow ends the same way."""
    db = robot_store(tmp_path / "r1.db", "r1")
    with ServiceProcess(tmp_path / "r1.db") as served:
        code, _, err = ended(follow("fleet", "push", db, served.url))
    assert code == 1, err
    assert_stopped_in_words(err, "400 ShipmentRefused")
    assert "is the store of robot 'r1' itself" in err

    robot_store(tmp_path / "other.db", "r1")   # another file, named as the robot
    code, _, err = ended(follow("fleet", "push", db, str(tmp_path / "other.db")))
    assert code == 1, err
    lines = err.splitlines()
    assert len(lines) == 2 and lines[1].startswith("error: fleet "), err
    assert "other.db refused the push for good (this fleet store is the store of robot " \
           "'r1' itself" in lines[1], err
    assert "Traceback" not in err


class StatusServer:
    """An HTTP server of this process that answers every request with ``status`` and the
    error body ``slr serve`` gives (kind, status, message); counts the requests."""

    def __init__(self, status: int, kind: str):
        self.requests = 0
        self.asked = threading.Condition()
        outer = self

        class Handler(BaseHTTPRequestHandler):
            def answer(self) -> None:
                length = int(self.headers.get("Content-Length") or 0)
                if length:
                    self.rfile.read(length)
                body = json.dumps({"error": {"kind": kind, "status": status,
                                             "message": f"the stub answers {status}"}}).encode()
                self.send_response(status)
                self.send_header("Content-Type", "application/json")
                self.send_header("Content-Length", str(len(body)))
                if status == 503:
                    self.send_header("Retry-After", "0")
                self.end_headers()
                self.wfile.write(body)
                with outer.asked:
                    outer.requests += 1
                    outer.asked.notify_all()

            do_GET = do_POST = answer

            def log_message(self, *args: object) -> None:
                pass

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}"
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)

    def __enter__(self) -> StatusServer:
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.server.shutdown()
        self.server.server_close()

    def wait_for(self, requests: int) -> bool:
        with self.asked:
            return self.asked.wait_for(lambda: self.requests >= requests, timeout=DEADLINE)


@pytest.mark.parametrize("status, kind", [
    (400, "BadRequest"), (401, "Unauthorized"), (403, "Forbidden"), (404, "NotFound"),
    (405, "MethodNotAllowed"), (413, "PayloadTooLarge")])
def test_a_refusal_that_waiting_does_not_change_ends_the_follow(tmp_path, status, kind):
    db = robot_store(tmp_path / "r1.db", "r1")
    with StatusServer(status, kind) as stub:
        code, out, err = ended(follow("fleet", "push", db, stub.url))
        assert stub.requests == 1     # (asked once, not again)
    assert code == 1, err
    assert_stopped_in_words(err, f"{status} {kind}: the stub answers {status}")


@pytest.mark.parametrize("status, kind", [
    (408, "RequestTimeout"), (409, "Conflict"), (429, "TooManyRequests"),
    (500, "InternalError"), (503, "Unavailable")])
def test_what_may_pass_is_retried_until_sigterm(tmp_path, status, kind):
    db = robot_store(tmp_path / "r1.db", "r1")
    with StatusServer(status, kind) as stub:
        pusher = follow("fleet", "push", db, stub.url)
        try:
            assert stub.wait_for(4), "the pusher did not ask again"
            assert pusher.poll() is None
            pusher.send_signal(signal.SIGTERM)
            out, err = pusher.communicate(timeout=DEADLINE)
        finally:
            if pusher.poll() is None:
                pusher.kill()
                pusher.communicate()
    assert pusher.returncode == 0, err
    assert "retrying with backoff" in err and "Traceback" not in err
    assert err.count("retrying with backoff") == 1, err     # said once per outage
    assert "robot r1: shipped 0 events" in out


def test_a_pusher_without_follow_stops_at_a_refusal_as_before(tmp_path):
    db = robot_store(tmp_path / "r1.db", "r1")
    with ServiceProcess(tmp_path / "fleet.db", "--token", "right") as served:
        done = subprocess.run([sys.executable, "-m", "slr_sql", "--token", "wrong", "fleet",
                               "push", db, served.url], env=slr_env(), cwd=ROOT,
                              capture_output=True, text=True, timeout=DEADLINE)
    assert done.returncode == 1
    assert done.stderr.startswith("error: ") and "Traceback" not in done.stderr
