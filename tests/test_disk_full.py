"""A full disk, for real: a tiny tmpfs mounted in a private mount namespace (``unshare -Urm``:
a user namespace, so no root is needed and the mount vanishes with the process), filled
until the kernel says ENOSPC. Then every add is :class:`SLRStoreFull` (retryable; nothing
written), opening a healthy store says the disk is full (never "damaged"), a store that
cannot be created leaves no file behind, and the service answers 503 with Retry-After.
SQLite's ``max_page_count`` gives the same SQLITE_FULL without a mount (the last tests)."""
from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import textwrap

import pytest

import slr_sql
from slr_sql import SLRError, SLRStoreFull, SLRUnavailable
from slr_sql.store import EventStore

from service_helpers import HTTP, ROOT, ServiceProcess, slr_env
from store_conditions import slr_failure

# Run by the child inside the namespace: fill() writes a file until the disk is full,
# free() removes it, files() lists the directory with sizes.
PRELUDE = """
import json, os, sys
import slr_sql
folder = sys.argv[1]
path = os.path.join(folder, "robot.db")
def fill():
    fd = os.open(os.path.join(folder, "filler"), os.O_WRONLY | os.O_CREAT | os.O_APPEND)
    try:
        while True:
            os.write(fd, b"x" * 4096)
    except OSError:
        pass
    finally:
        os.close(fd)
def free():
    os.remove(os.path.join(folder, "filler"))
def files():
    return {n: os.path.getsize(os.path.join(folder, n)) for n in sorted(os.listdir(folder))
            if n != "filler"}
def attempt(call):
    try:
        return ["ok", call()]
    except slr_sql.SLRError as exc:
        return [type(exc).__name__, str(exc)]
"""


def on_full_disk(tmp_path, script: str, size: str = "1m") -> dict:
    """Run ``script`` (after PRELUDE) with a fresh tmpfs of ``size`` at a folder of
    ``tmp_path``; it prints one JSON object, returned."""
    folder = tmp_path / "tiny"
    folder.mkdir()
    code = PRELUDE + textwrap.dedent(script)
    r = subprocess.run(
        ["unshare", "-Urm", "sh", "-c",
         f'mount -t tmpfs -o size={size} tmpfs "$1" && exec "$2" -c "$3" "$1"', "sh",
         str(folder), sys.executable, code],
        capture_output=True, text=True, env=slr_env(), cwd=ROOT, timeout=120)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout.strip().splitlines()[-1])


def test_adds_on_a_full_disk_raise_store_full_and_lose_nothing(tmp_path):
    out = on_full_disk(tmp_path, """
        kb = slr_sql.open(path)
        kb.add_many([f"p({i})^{i}" for i in range(100)] + ["q(first)^0", "r(first, 0)^0"])
        fill()
        results = []
        for i in range(400):                   # 4 KB events until the log cannot grow
            results.append(attempt(lambda: kb.add(f"q({'y' * 4000})^{i}")))
            if results[-1][0] != "ok":
                break
        stored_before = kb.sql("SELECT count(*) FROM q")[1][0][0]
        many = attempt(lambda: kb.add_many([f"r({'z' * 4000}, {i})^{i}" for i in range(50)]))
        r_rows = kb.query("findall(I, r(_, I)^_, L)")[0]["L"]
        free()
        kb.add("q(after)^1000")
        print(json.dumps({"last": results[-1], "adds": len(results), "q": stored_before,
                          "many": many, "r": len(r_rows),
                          "p": kb.sql("SELECT count(*) FROM p")[1][0][0],
                          "q_after": kb.sql("SELECT count(*) FROM q")[1][0][0]}))
        kb.close()
    """)
    kind, message = out["last"]
    assert kind == "SLRStoreFull", out
    assert "robot.db: the disk is full" in message and "nothing of this call was written" in message
    assert out["q"] == 1 + out["adds"] - 1      # every acknowledged add is there, no more
    assert out["many"][0] == "SLRStoreFull" and out["r"] == 1   # a batch: all or nothing
    assert out["p"] == 100 and out["q_after"] == out["q"] + 1


def test_opening_a_healthy_store_on_a_full_disk_says_full_not_damaged(tmp_path):
    out = on_full_disk(tmp_path, """
        with slr_sql.open(path) as kb:
            kb.add_many([f"p({i})^{i}" for i in range(100)])
        fill()
        tries = [attempt(lambda: slr_sql.open(path).close()) for _ in range(3)]
        free()
        with slr_sql.open(path) as kb:
            count = kb.sql("SELECT count(*) FROM p")[1][0][0]
        print(json.dumps({"tries": tries, "count": count}))
    """)
    for kind, message in out["tries"]:
        assert kind == "SLRStoreFull", out
        assert "the disk is full" in message and "it was not opened" in message
        assert "damaged" not in message
    assert out["count"] == 100


def test_a_store_that_cannot_be_created_leaves_nothing_behind(tmp_path):
    out = on_full_disk(tmp_path, """
        fill()
        tries = [attempt(lambda: slr_sql.open(path).close()) for _ in range(2)]
        left = files()
        free()
        with slr_sql.open(path) as kb:
            kb.add("p(1)^1")
        print(json.dumps({"tries": tries, "left": left}))
    """)
    for kind, message in out["tries"]:
        assert kind == "SLRStoreFull", out
        assert "it was not created, and nothing was left behind" in message
    assert out["left"] == {}, out


def test_the_service_answers_503_with_retry_after_on_a_full_disk(tmp_path):
    """The server runs in the namespace; the test fills the disk through the child's stdin
    once the server is up, then adds until the answer is 503 (a client keeps the events
    and retries: 400 would tell it to drop them)."""
    folder = tmp_path / "tiny"
    folder.mkdir()
    script = ('mount -t tmpfs -o size=1m tmpfs "$1" && { "$2" -m slr_sql serve "$1/robot.db" '
              '--port 0 & read line; dd if=/dev/zero of="$1/filler" bs=4096 2>/dev/null; '
              'echo filled; wait; }')
    proc = subprocess.Popen(["unshare", "-Urm", "sh", "-c", script, "sh", str(folder),
                             sys.executable], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, env=slr_env(), cwd=ROOT, text=True,
                            start_new_session=True)
    try:
        url = proc.stdout.readline().strip().rsplit(" on ", 1)[1]
        assert HTTP.post(url + "/add", json={"event": "p(1)^1"}, timeout=30).status_code == 200
        proc.stdin.write("fill\n")
        proc.stdin.flush()
        assert proc.stdout.readline().strip() == "filled"
        answer = None
        for i in range(400):
            answer = HTTP.post(url + "/add", json={"event": f"q({'y' * 4000}, {i})^{i}"},
                               timeout=30)
            if answer.status_code != 200:
                break
        assert answer.status_code == 503, answer.text
        assert answer.headers["Retry-After"] == "10"
        error = answer.json()["error"]
        # (the store's words, which name its file, are the server log's: a request id here)
        assert error["kind"] == "SLRStoreFull" and "the store is full" in error["message"]
        with slr_sql.connect(url) as remote, \
                pytest.raises(SLRStoreFull):    # the client raises the class the server did
            remote.add(f"q({'y' * 4000}, x)^1")
        assert HTTP.get(url + "/health", timeout=30).status_code == 200
    finally:
        os.killpg(proc.pid, signal.SIGTERM)   # the shell and the server it started
        _, errors = proc.communicate(timeout=30)
    assert "Traceback" not in errors, errors


# A ManualClock where events are stamped 0, 1, ...: on a wall clock they would be "decades
# late" (a LearnedDelayWarning); nothing here waits on the store's time.
def test_the_size_limit_of_sqlite_is_store_full_too(tmp_path):
    """SQLITE_FULL without a mount: the connection's page limit. The same words and class,
    and the store takes events again once the limit is raised."""
    with slr_sql.open(tmp_path / "robot.db", clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add_many([f"p({i})^{i}" for i in range(10)])
        pages = kb.sql("PRAGMA page_count")[1][0][0]
        kb.sql(f"PRAGMA max_page_count = {pages + 2}", write=True)
        with pytest.raises(SLRStoreFull, match="robot.db: the disk is full .*nothing of this "
                                               "call was written"):
            kb.add_many([f"q({'y' * 4000}, {i})^{i}" for i in range(20)])
        assert kb.sql("SELECT count(*) FROM p")[1] == [(10,)]
        assert "q" not in [name for name, in kb.sql("SELECT name FROM sqlite_master")[1]]
        with pytest.raises(SLRStoreFull):       # also a statement of kb.sql that writes
            kb.sql("CREATE TABLE notes AS SELECT randomblob(100000) AS body", write=True)
        kb.sql("PRAGMA max_page_count = 1073741823", write=True)
        kb.add_many([f"q({'y' * 4000}, {i})^{i}" for i in range(20)])
        assert kb.sql("SELECT count(*) FROM q")[1] == [(20,)]


def test_the_stores_statements_at_its_size_limit_are_store_full(tmp_path):
    """The statements the store runs for the parts above (the subscription hub, the event
    rules, buffers) on its own connection, outside the knowledge base's boundary: each
    raises SLRStoreFull in words, not sqlite3's error, and the store goes on once the limit
    is raised."""
    path = str(tmp_path / "robot.db")
    store = EventStore(path)
    try:
        store.execute("CREATE TABLE notes (body)")
        pages = store.execute("PRAGMA page_count")[0][0]
        store.execute(f"PRAGMA max_page_count = {pages}")
        body = b"x" * 100_000
        insert = "INSERT INTO notes VALUES (:body)"
        calls = {
            "execute": lambda: store.execute("INSERT INTO notes VALUES (?)", (body,)),
            "executemany": lambda: store.executemany("INSERT INTO notes VALUES (?)", [(body,)]),
            "executescript": lambda: store.executescript(
                "INSERT INTO notes VALUES (zeroblob(100000));"),
            "run_compiled": lambda: store.run_compiled(insert, {"body": body}),
            "run_compiled_many": lambda: store.run_compiled_many(insert, [{"body": body}]),
            "run_compiled_batch": lambda: store.run_compiled_batch(
                [(insert, [{"body": body}], True)]),
        }
        for name, call in calls.items():
            exc = slr_failure(call)
            assert isinstance(exc, SLRStoreFull), (name, exc)
            assert str(exc).startswith(f"{path}: the disk is full"), (name, exc)
        store.execute("PRAGMA max_page_count = 1073741823")
        store.execute("INSERT INTO notes VALUES (?)", (body,))
        assert store.execute("SELECT count(*) FROM notes") == [(1,)]
    finally:
        store.close()


# An event rule whose decisions wait until b/1 is complete: the add of the mark that completes
# it commits, and the decision round after it -- whose failure the add does not raise (its
# events are stored) -- derives c(X), a row as large as X
CHRONO = ":- consumption(chronological).\nc(X) <- a(X) seq b(X).\n"


def test_a_decision_round_at_the_size_limit_says_why_on_its_rule(tmp_path):
    """The round's insert meets the page limit: SLRStoreFull from the store's statement.
    The rule's ``last_error`` says so (it did for a statement's own error only), the
    decision stays pending, and is made once there is room."""
    with slr_sql.open(tmp_path / "robot.db", clock=slr_sql.ManualClock(0.0)) as kb:
        kb.load(CHRONO)
        big = "x" * 100_000
        assert kb.add_many([f"a('{big}')^1", f"b('{big}')^2", "fullyUpdated(a/1)^10"]) == []
        pages = kb.sql("PRAGMA page_count")[1][0][0]
        kb.sql(f"PRAGMA max_page_count = {pages + 3}", write=True)   # room for the mark only
        assert kb.add_many(["fullyUpdated(b/1)^10"]) == []
        [rule] = kb.event_rules()
        assert rule["pending"] == 1 and rule["last_error"] == \
            f"the round rolled back: {tmp_path / 'robot.db'}: the disk is full (or the store " \
            f"reached its size limit; database or disk is full); nothing of this call was " \
            f"written: free space and retry"
        kb.sql("PRAGMA max_page_count = 1073741823", write=True)
        kb.mark_complete("b/1", 11)
        assert len(kb.query("c(X)^[S, E]")) == 1 and kb.event_rules()[0]["pending"] == 0


def test_a_decision_round_whose_commit_the_full_disk_refuses_says_why_on_its_rule(tmp_path):
    """On a full disk the round's rows go to the write-ahead log at its commit: the commit is
    refused (SLRStoreFull), and the rules that decided in the round say so. The disk keeps
    room for the mark's own commit (a file removed after the disk was filled), not for
    c(X)."""
    out = on_full_disk(tmp_path, f"""
        kb = slr_sql.open(path, clock=slr_sql.ManualClock(0.0))
        kb.load({CHRONO!r})
        big = "x" * 400_000
        kb.add_many([f"a('{{big}}')^1", f"b('{{big}}')^2", "fullyUpdated(a/1)^10"])
        with open(os.path.join(folder, "reserve"), "wb") as f:
            f.write(b"r" * 131072)
        fill()
        os.remove(os.path.join(folder, "reserve"))
        added = attempt(lambda: kb.add_many(["fullyUpdated(b/1)^10"]))
        [rule] = kb.event_rules()
        pending = kb.sql("SELECT count(*) FROM slr_cep_pending")[1][0][0]
        free()
        kb.mark_complete("b/1", 11)
        derived = len(kb.query("c(X)^[S, E]"))
        kb.close()
        print(json.dumps({{"added": added, "pending": [rule["pending"], pending],
                          "last_error": rule["last_error"], "derived": derived}}))
    """, size="4m")
    # (pending: as kb.event_rules() says it, as the table holds it)
    assert out["added"] == ["ok", []] and out["pending"] == [1, 1], out
    assert out["last_error"].startswith("the round rolled back: ") and \
        "robot.db: the disk is full" in out["last_error"], out
    assert out["derived"] == 1, out


def test_the_hubs_housekeeping_on_a_full_disk_is_one_line(tmp_path):
    """The subscription hub's housekeeping writes on the store's connection, on a thread of
    its own (no knowledge base call around it): a commit the full disk refuses is logged as
    one WARNING line naming SLRStoreFull, and the next round once there is space writes:
    the position the refused commit did not store is still due (no lease renewal then,
    which would write every position anyway)."""
    out = on_full_disk(tmp_path, """
        import io, logging, time
        lines = io.StringIO()
        logging.getLogger("slr_sql").addHandler(logging.StreamHandler(lines))
        kb = slr_sql.open(path, clock=slr_sql.ManualClock(0.0))
        hub = kb._subscriptions
        hub.persist_interval = hub.cleanup_interval = 3600.0   # rounds only when asked
        sub = kb.subscribe("p(X)^T", since=0, id="log")
        kb.add_many(["p(1)^1", "p(2)^2"])
        got = [sub.get(timeout=30)["X"] for _ in range(2)]
        fill()
        hub._last_persist = hub._last_lease = 0.0   # a position and a lease are due: a write
        full = hub.housekeeping_round(30)
        free()
        hub._last_persist, hub._last_lease = 0.0, time.monotonic()   # a position only
        again = hub.housekeeping_round(30)
        [row] = [r for r in hub.subscriptions() if r["id"] == "log"]
        stored = [row["history_done"], row["live_pos"]]
        kb.add("p(3)^3")
        got.append(sub.get(timeout=30)["X"])
        sub.close()
        kb.close()
        print(json.dumps({"got": got, "rounds": [full, again], "log": lines.getvalue(),
                          "stored": stored}))
    """)
    assert out["got"] == [1, 2, 3] and out["rounds"] == [True, True], out
    # the first answer was handled (taking the second says so): the position past it
    assert out["stored"] == [1, 1], out
    [line] = [line for line in out["log"].splitlines() if "housekeeping failed" in line]
    assert "SLRStoreFull" in line and "robot.db: the disk is full" in line, out["log"]
    assert "Traceback" not in out["log"], out["log"]


def test_a_lock_held_too_long_is_503_with_retry_after(tmp_path):
    """Held longer than ``slr serve --busy-timeout`` (0.5 s here; 5 s by default)."""
    db = tmp_path / "robot.db"
    with slr_sql.open(db, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add("p(1)^1")
    with ServiceProcess(db, "--busy-timeout", "0.5") as server:
        holder = sqlite3.connect(db, isolation_level=None)
        holder.execute("BEGIN IMMEDIATE")
        try:
            answer = HTTP.post(server.url + "/add", json={"event": "p(2)^2"}, timeout=60)
        finally:
            holder.execute("ROLLBACK")
            holder.close()
        assert answer.status_code == 503, answer.text
        assert answer.headers["Retry-After"] == "1"
        assert answer.json()["error"]["kind"] == "SLRBusy"
        assert HTTP.post(server.url + "/add", json={"event": "p(2)^2"},
                         timeout=30).status_code == 200
    # (the store's words, which name its file, are the server log's, under the request id;
    # a log line is cut at 200 characters)
    [line] = [line for line in server.log.read_text().splitlines()
              if answer.json()["error"]["request"] in line]
    assert f"SLRBusy: {db}: locked by another writer" in line, line


def test_unavailable_conditions_are_one_family():
    assert issubclass(SLRStoreFull, SLRUnavailable) and issubclass(SLRUnavailable, SLRError)
    assert {"SLRStoreFull", "SLRUnavailable"} <= set(slr_sql.__all__)
