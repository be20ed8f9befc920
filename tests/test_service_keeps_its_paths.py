"""A client of `slr serve` is not told where the server keeps its store. An answer whose words
are the server's own -- a 503 (the store locked past the busy timeout), a failure of the store
itself (a damaged file), a cancel at the database server's statement_timeout -- named the
store's file path (or a PostgreSQL URL's host and database) to any client: it now says its
kind in general words with a request id, and the server's log has the words under that id.
Every way an error reaches a client: HTTP routes, a submitted query's poll, the fleet's
endpoints, a WebSocket subscription. Real `slr serve` processes, real stores."""
from __future__ import annotations

import re
import sqlite3

import psycopg
import pytest

import slr_sql
from slr_sql import SLRBusy
from service_helpers import HTTP, ServiceProcess

REQUEST = re.compile(r"request ([0-9a-f]{12})")


def _hidden(answer_text: str, *secrets: str) -> str:
    """The request id an answer names, after checking it names none of ``secrets``."""
    for secret in secrets:
        assert secret not in answer_text, answer_text
    found = REQUEST.search(answer_text)
    assert found, answer_text
    return found.group(1)


def _logged(log: str, request_id: str, words: str) -> None:
    [line] = [line for line in log.splitlines() if request_id in line]
    assert words in line, line
    assert "Traceback" not in log, log


@pytest.fixture
def served_store(tmp_path):
    folder = tmp_path / "secret-folder"
    folder.mkdir()
    db = folder / "robot.db"
    with slr_sql.open(db, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add("p(1)^1")
    return db


WRITES = [("/add", {"event": "p(2)^2"}),
          ("/add_event", {"name": "p", "args": [3], "start": 3.0}),
          ("/add_many", {"events": ["p(4)^4", "p(5)^5"]}),
          ("/load", {"text": "q(1).", "name": "q"}),
          ("/mark_complete", {"type": "p/1", "time": 3}),
          ("/fleet/receive", {"robot": "r1", "batches": [], "pending": 2})]


def test_a_lock_held_too_long_is_503_without_the_stores_path(served_store):
    with ServiceProcess(served_store, "--busy-timeout", "0.3") as server:
        holder = sqlite3.connect(served_store, isolation_level=None)
        holder.execute("BEGIN IMMEDIATE")
        try:
            answers = [HTTP.post(server.url + path, json=body, timeout=60)
                       for path, body in WRITES]
        finally:
            holder.execute("ROLLBACK")
            holder.close()
        ids = []
        for answer in answers:
            assert answer.status_code == 503, answer.text
            assert answer.headers["Retry-After"] == "1"
            error = answer.json()["error"]
            assert error["kind"] == "SLRBusy" and error["message"].startswith("the store is busy")
            ids.append(_hidden(answer.text, "secret-folder", "robot.db"))
            assert error["request"] == ids[-1]
        # a retry once the lock is gone goes through
        assert HTTP.post(server.url + "/add", json={"event": "p(2)^2"},
                         timeout=30).status_code == 200
    log = server.log.read_text()
    for request_id in ids:
        _logged(log, request_id, f"{served_store}: locked by another writer")


def test_a_subscription_refused_by_a_lock_says_no_path(served_store):
    """A durable subscription (``id=``) writes its claim in the store: the lock's SLRBusy
    reaches the WebSocket client as an error message, which the client raises."""
    with ServiceProcess(served_store, "--busy-timeout", "0.3") as server, \
            slr_sql.connect(server.url) as client:
        holder = sqlite3.connect(served_store, isolation_level=None)
        holder.execute("BEGIN IMMEDIATE")
        try:
            with pytest.raises(SLRBusy) as refused:
                client.subscribe("p(X)^T", since=0, id="durable")
        finally:
            holder.execute("ROLLBACK")
            holder.close()
        request_id = _hidden(str(refused.value), "secret-folder", "robot.db")
        sub = client.subscribe("p(X)^T", since=0, id="durable")
        assert sub.get(timeout=30)["X"] == 1
        sub.close()
    _logged(server.log.read_text(), request_id, f"{served_store}: locked by another writer")


def _damage_table(db, table: str) -> None:
    """Overwrite the root page of ``table`` with bytes that are no b-tree page (the store
    checkpointed first, so the page is read from the file)."""
    with sqlite3.connect(db) as conn:
        conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
        page_size = conn.execute("PRAGMA page_size").fetchone()[0]
        [root] = conn.execute("SELECT rootpage FROM sqlite_master WHERE name = ?",
                              (table,)).fetchone()
    with open(db, "r+b") as f:
        f.seek((root - 1) * page_size)
        f.write(b"\xa5" * page_size)


def test_a_damaged_store_is_a_500_without_its_path(served_store):
    """The file damaged under a running server: a failure of the store, not of the request
    (it was a 400 naming the file), on a query and on a submitted query's poll."""
    with ServiceProcess(served_store) as server:
        other = slr_sql.open(served_store, clock=slr_sql.ManualClock(0.0))
        other.add_many([f"hidden({n})^{n}" for n in range(1, 50)])
        other.close()
        _damage_table(served_store, "hidden")
        asked = HTTP.post(server.url + "/query", json={"goal": "hidden(X)^T"}, timeout=30)
        # (answered at once: nothing to wait for; its poll says the same)
        submitted = HTTP.post(server.url + "/submit", json={"goal": "hidden(X)^T"}, timeout=30)
        polled = HTTP.get(server.url + f"/submit/{submitted.json()['handle']}?wait=30",
                          timeout=60)
        assert server.healthy()
    assert submitted.status_code in (202, 500), submitted.text   # (done by then, or not)
    assert "secret-folder" not in submitted.text and "robot.db" not in submitted.text
    ids = []
    for answer in (asked, polled):
        assert answer.status_code == 500, answer.text
        assert answer.json()["error"]["message"].startswith("the store failed"), answer.text
        ids.append(_hidden(answer.text, "secret-folder", "robot.db"))
    log = server.log.read_text()
    for request_id in ids:
        _logged(log, request_id, f"{served_store}: the file is damaged")


def test_a_postgresql_lock_held_too_long_names_no_host_or_database(postgres_url, tmp_path):
    """On PostgreSQL the store's location is its URL: the socket folder (or host) and the
    database's name."""
    database = re.search(r"/([^/?]+)(\?|$)", postgres_url.split("://", 1)[1]).group(1)
    folder = re.search(r"host=([^&]+)", postgres_url)
    secrets = [database] + ([folder.group(1)] if folder else [])
    with slr_sql.open(postgres_url, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add("p(1)^1")
    with ServiceProcess(postgres_url, "--busy-timeout", "0.3",
                        log=tmp_path / "serve.log") as server:
        with psycopg.connect(postgres_url.replace("postgresql://", "postgresql://", 1)
                             .split("?schema=")[0]) as holder:
            holder.execute("LOCK TABLE slr.p IN ACCESS EXCLUSIVE MODE")
            answer = HTTP.post(server.url + "/add", json={"event": "p(2)^2"}, timeout=60)
            holder.rollback()
        assert answer.status_code == 503, answer.text
        assert answer.json()["error"]["kind"] == "SLRBusy"
        request_id = _hidden(answer.text, *secrets)
        assert HTTP.post(server.url + "/add", json={"event": "p(2)^2"},
                         timeout=30).status_code == 200
        # a value the store cannot hold: the request's fault (400), its words kept, without
        # the location the store's message starts with
        refused = HTTP.post(server.url + "/mark_complete", json={"type": "p\x00/1", "time": 3},
                            timeout=30)
    _logged(server.log.read_text(), request_id, f"{database}")
    assert refused.status_code == 400, refused.text
    message = refused.json()["error"]["message"]
    assert message.startswith("the store failed (") and "U+0000" in message, message
    for secret in secrets:
        assert secret not in refused.text, refused.text


def test_the_services_own_refusals_keep_their_words(served_store):
    """A 4xx of a bad request, and the service's own words, are as they were."""
    with ServiceProcess(served_store) as server:
        bad = HTTP.post(server.url + "/query", json={"goal": "p(X"}, timeout=30)
        unknown = HTTP.post(server.url + "/query", json={"goal": "nosuch(X)"}, timeout=30)
    assert bad.status_code == 400 and bad.json()["error"]["kind"] == "SLRSyntaxError"
    assert "request" not in bad.json()["error"]
    assert unknown.status_code in (200, 400), unknown.text


def _slr_stats(where: str) -> str:
    import subprocess
    import sys

    from service_helpers import slr_env

    done = subprocess.run([sys.executable, "-m", "slr_sql", "stats", where], env=slr_env(),
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_stats_say_the_figures_and_not_where_the_store_is(served_store):
    """GET /stats answered the store's path to any client past the token, while a 5xx no
    longer names it: it says the figures without the location, as `slr stats URL` prints
    them; `slr stats DB` on the server's machine still names its file."""
    with ServiceProcess(served_store) as server:
        answer = HTTP.get(server.url + "/stats", timeout=30)
        remote_text = _slr_stats(server.url)
    assert answer.status_code == 200, answer.text
    stats = answer.json()
    for secret in ("secret-folder", "robot.db"):
        assert secret not in answer.text and secret not in remote_text
    assert "path" not in stats and {"type": "p/1", "count": 1} in stats["rows"]
    assert stats["text"].startswith("store file: ") and "p/1: 1 stored" in stats["text"]
    assert remote_text.startswith("store file: ") and "p/1: 1 stored" in remote_text
    assert _slr_stats(str(served_store)).startswith(f"file {served_store}: ")


def test_stats_of_a_postgresql_store_name_no_host_or_database(postgres_url, tmp_path):
    database = re.search(r"/([^/?]+)(\?|$)", postgres_url.split("://", 1)[1]).group(1)
    folder = re.search(r"host=([^&]+)", postgres_url)
    with slr_sql.open(postgres_url, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add("p(1)^1")
    with ServiceProcess(postgres_url, log=tmp_path / "serve.log") as server:
        answer = HTTP.get(server.url + "/stats", timeout=30)
    assert answer.status_code == 200, answer.text
    for secret in [database] + ([folder.group(1)] if folder else []):
        assert secret not in answer.text, answer.text
    assert answer.json()["text"].startswith("store: ") and "p/1: 1 stored" in answer.text
