"""Hostile and mistaken command lines (adversarial review of the CLI).

``slr export DB FILE`` opened FILE for writing before reading DB: given the store's own path
(the same file twice, another spelling, a link) it truncated the store and then failed with
"database disk image is malformed" -- every event lost. Given another store's path (``slr
export robot.db fleet.db``, meaning ``slr fleet push``) it overwrote that store with MCAP.
"""
from __future__ import annotations

import subprocess
import sys

import pytest
from service_helpers import slr_env

import slr_sql
from slr_sql import SLRError
from slr_sql.viz.mcap_export import export_mcap


def slr(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "slr_sql", *args], capture_output=True,
                          text=True, env=slr_env(), timeout=120)


def a_store(path) -> None:
    with slr_sql.open(path, clock=slr_sql.ManualClock(100)) as kb:
        kb.add("seen(p, d)^10")
        kb.add("seen(q, d)^11")


def events_in(path) -> int:
    with slr_sql.open(path) as kb:
        return len(kb.query("seen(X, Y)^T"))


@pytest.mark.parametrize("spelling", ["same", "dot-slash", "symlink"])
def test_export_into_the_store_itself_is_refused_and_the_store_kept(tmp_path, spelling):
    db = tmp_path / "robot.db"
    a_store(db)
    target = {"same": str(db), "dot-slash": str(tmp_path / "." / "robot.db"),
              "symlink": str(tmp_path / "link.db")}[spelling]
    if spelling == "symlink":
        (tmp_path / "link.db").symlink_to(db)
    done = slr("export", str(db), target)
    assert done.returncode == 1, done.stdout
    assert done.stderr.startswith("error: ") and "store" in done.stderr
    assert "Traceback" not in done.stderr and "malformed" not in done.stderr
    assert events_in(db) == 2


def test_export_over_another_store_is_refused_and_that_store_kept(tmp_path):
    db, other = tmp_path / "robot.db", tmp_path / "fleet.db"
    a_store(db)
    a_store(other)
    done = slr("export", str(db), str(other))
    assert done.returncode == 1
    assert "SQLite" in done.stderr and "Traceback" not in done.stderr
    assert events_in(other) == 2


def test_the_library_refuses_too_and_an_mcap_file_is_still_overwritten(tmp_path):
    db = tmp_path / "robot.db"
    a_store(db)
    out = tmp_path / "out.mcap"
    out.write_bytes(b"an older export")
    with slr_sql.open(db) as kb:
        with pytest.raises(SLRError, match="itself"):
            export_mcap(kb.store, db)
        assert export_mcap(kb.store, out).messages == 2
    assert events_in(db) == 2
    assert out.read_bytes()[:5] == b"\x89MCAP"


# -- an empty store path -------------------------------------------------------------------------

@pytest.mark.parametrize("args", [
    ["add", "", "p(1)^1"],
    ["ingest", "", "-"],
    ["fleet", "push", "{robot}", ""],
], ids=["add", "ingest", "fleet-push-into"])
def test_an_empty_store_path_is_refused_not_a_store_that_vanishes(tmp_path, args):
    """SQLite opens "" as a private temporary database deleted on close: `slr add "" EVENT`
    said "added 1 event" and the event was gone; `slr fleet push DB ""` said it shipped."""
    robot = tmp_path / "r1.db"
    with slr_sql.open(robot, robot="r1", clock=slr_sql.ManualClock(100)) as kb:
        kb.add("seen(p)^10")
    args = [a.replace("{robot}", str(robot)) for a in args]
    done = subprocess.run([sys.executable, "-m", "slr_sql", *args], capture_output=True,
                          text=True, env=slr_env(), timeout=120, input="p(1)^1\n",
                          cwd=tmp_path)
    assert done.returncode == 1, done.stdout
    assert done.stderr.startswith("error: ") and "empty" in done.stderr, done.stderr
    assert "shipped" not in done.stdout and "added" not in done.stdout


def test_the_library_refuses_an_empty_path_too():
    with pytest.raises(SLRError, match="empty"):
        slr_sql.open("")


def test_a_batch_beyond_any_count_is_refused_in_words(tmp_path):
    robot = tmp_path / "r1.db"
    with slr_sql.open(robot, robot="r1", clock=slr_sql.ManualClock(100)) as kb:
        kb.add("seen(p)^10")
    done = slr("fleet", "push", str(robot), str(tmp_path / "f.db"), "--batch",
               "99999999999999999999")
    assert done.returncode in (1, 2)
    assert "batch" in done.stderr and "bug" not in done.stderr and "Overflow" not in done.stderr


@pytest.mark.parametrize("url", ["postgresql://[::1", "postgres://u@[fe80::1/db"])
def test_a_malformed_postgresql_url_is_said_in_words(url):
    with pytest.raises(SLRError) as caught:
        slr_sql.open(url)
    assert "ValueError" not in str(caught.value) and "URL" in str(caught.value)
    done = slr("query", url, "X = 1")
    assert done.returncode == 1
    assert done.stderr.startswith("error: ") and "URL" in done.stderr
    assert "ValueError" not in done.stderr and "bug" not in done.stderr


def test_an_ingested_integer_beyond_pythons_digits_is_said_in_words(tmp_path):
    """A JSON line's {"$int": ...} of 5,000 digits: the bad line said Python's advice to
    Python programmers ("use sys.set_int_max_str_digits() to increase the limit"); it now
    says what `slr add` says of the same integer. The other lines are still added."""
    lines = tmp_path / "events.jsonl"
    lines.write_text('{"name": "big", "args": [{"$int": "' + "9" * 5000 + '"}], "time": 1}\n'
                     '{"name": "big", "args": [7], "time": 2}\n')
    done = slr("ingest", str(tmp_path / "robot.db"), str(lines))
    assert done.returncode == 1, done.stderr
    assert f"{lines}:1: bad argument: an integer too long (5000 digits): at most 4300 " \
           f"digits are read" in done.stderr, done.stderr
    assert "sys.set_int_max_str_digits" not in done.stderr
    assert "ingested 1 event, 1 bad line" in done.stdout + done.stderr
