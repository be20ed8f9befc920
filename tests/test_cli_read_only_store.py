"""A store this process may read but not write (docs/architecture.md, "Many processes and
threads on one file"): the commands that read it answer, those that write refuse in words
that name the path and say it is read-only; nothing of the file changes.

Two real conditions, since permission bits do not stop root:

* a file system mounted read-only: the folder bound read-only on itself in a mount
  namespace of its own (``unshare --mount --map-root-user``: root, or any user where user
  namespaces are allowed), the ``slr`` commands and ``slr serve`` run inside it;
* a file of mode 0444, in a folder the process may write (reads work, SQLite makes the
  ``-shm`` beside it) and in one it may not (mode 0555: SQLite cannot read a store in WAL
  mode there, said in words): run as the unprivileged user 65534 (``setpriv``) when the
  suite runs as root.
"""
from __future__ import annotations

import hashlib
import os
import queue
import shutil
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

import httpx
import pytest
from service_helpers import slr_env

import slr_sql

ROOT = Path(__file__).resolve().parent.parent
DEADLINE = 120.0
READ_ONLY = "the store is read-only (attempt to write a readonly database"

# binds the folder $1 read-only on itself, checks that it is, then runs the rest
MOUNT_READ_ONLY = """\
mount --bind "$1" "$1" && mount -o remount,ro,bind "$1" || exit 98
if touch "$1/probe" 2>/dev/null; then echo "$1 is not read-only" >&2; exit 99; fi
shift
exec "$@"
"""


def make_store(path: Path) -> str:
    with slr_sql.open(path, clock=slr_sql.ManualClock(100)) as kb:
        kb.add("seen(a)^1")
        kb.add("seen(b)^2")
    return str(path)


def digest(folder: Path) -> dict:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in folder.iterdir()}


def on_read_only_mount(folder: Path, *args: str) -> list[str]:
    return ["unshare", "--mount", "--map-root-user", "sh", "-c", MOUNT_READ_ONLY, "sh",
            str(folder), sys.executable, "-m", "slr_sql", *args]


def run(command: list[str]) -> subprocess.CompletedProcess:
    return subprocess.run(command, env=slr_env(), cwd=ROOT, capture_output=True, text=True,
                          timeout=DEADLINE, stdin=subprocess.DEVNULL)


@pytest.fixture
def mounted(tmp_path):
    folder = tmp_path / "media"
    folder.mkdir()
    db = make_store(folder / "robot.db")
    before = digest(folder)
    yield folder, db
    assert digest(folder) == before      # not a byte changed, no -wal or -shm left


@pytest.mark.parametrize("args, printed", [
    (["query", "{db}", "seen(X)^T"], "X = a, T = 1.0\nX = b, T = 2.0\n"),
    (["sql", "{db}", "SELECT arg1 FROM seen ORDER BY seq"], "arg1\na\nb\n"),
    (["stats", "{db}"], "seen/1: 2 stored"),
    (["describe", "{db}"], "seen/1"),
    (["programs", "{db}"], ""),
])
def test_a_store_on_a_read_only_file_system_is_read(mounted, args, printed):
    folder, db = mounted
    done = run(on_read_only_mount(folder, *(a.format(db=db) for a in args)))
    assert done.returncode == 0, done.stderr
    assert printed in done.stdout and "Traceback" not in done.stderr


@pytest.mark.parametrize("args", [
    ["add", "{db}", "seen(c)^3"], ["sql", "{db}", "DELETE FROM seen", "--write"],
    ["load", "{db}", "{program}"], ["fleet", "name", "{db}", "r1"],
    ["ingest", "{db}", "{events}"],
])
def test_a_write_to_a_store_on_a_read_only_file_system_is_refused_in_words(
        mounted, tmp_path, args):
    folder, db = mounted
    (tmp_path / "p.slr").write_text("p(1).\n")
    (tmp_path / "ev.txt").write_text("seen(c)^3\n")
    done = run(on_read_only_mount(folder, *(a.format(db=db, program=tmp_path / "p.slr",
                                                     events=tmp_path / "ev.txt")
                                            for a in args)))
    assert done.returncode == 1, (done.stdout, done.stderr)
    assert f"{db}: {READ_ONLY}" in done.stderr, done.stderr
    assert "Traceback" not in done.stderr


def test_slr_serve_serves_a_store_on_a_read_only_file_system_for_reading(mounted):
    folder, db = mounted
    server = subprocess.Popen(on_read_only_mount(folder, "serve", db, "--port", "0"),
                              env=slr_env(), cwd=ROOT, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL)
    try:
        lines: queue.Queue = queue.Queue()
        threading.Thread(target=lambda: lines.put(server.stdout.readline()),
                         daemon=True).start()
        first = lines.get(timeout=DEADLINE)
        assert " on http" in first, (first, server.stderr.read() if server.poll() else "")
        url = first.strip().rsplit(" on ", 1)[1]
        with slr_sql.connect(url) as kb:
            assert [a["X"] for a in kb.query("seen(X)^T")] == ["a", "b"]
            with pytest.raises(slr_sql.SLRError, match="the store is read-only"):
                kb.add("seen(c)^3")
            assert kb.sql("SELECT count(*) FROM seen")[1] == [(2,)]
        assert httpx.get(url + "/health", timeout=30).status_code == 200
    finally:
        server.terminate()
        _, log = server.communicate(timeout=DEADLINE)
    assert "Traceback" not in log, log


# -- a file of mode 0444 -------------------------------------------------------------------------

def unprivileged(*args: str) -> list[str]:
    """The command line of ``slr ARGS`` run as a user permission bits hold: 65534 when the
    suite runs as root."""
    command = [sys.executable, "-m", "slr_sql", *args]
    if os.geteuid() != 0:
        return command
    return ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups", *command]


@pytest.fixture
def open_folder():
    """A folder every user may enter and write (the tests' own folders are root's alone
    when the suite runs as root)."""
    folder = Path(tempfile.mkdtemp(prefix="slr-read-only-"))
    os.chmod(folder, 0o777)
    yield folder
    for path in folder.rglob("*"):
        if path.is_dir():
            os.chmod(path, 0o755)
    shutil.rmtree(folder)


def test_a_read_only_file_is_read_and_refuses_writes(open_folder):
    db = make_store(open_folder / "robot.db")
    os.chmod(db, 0o444)
    read = run(unprivileged("query", db, "seen(X)^T"))
    assert (read.returncode, read.stdout) == (0, "X = a, T = 1.0\nX = b, T = 2.0\n"), read.stderr
    for args in (["add", db, "seen(c)^3"], ["sql", db, "DELETE FROM seen", "--write"]):
        done = run(unprivileged(*args))
        assert done.returncode == 1, done.stdout
        assert f"{db}: {READ_ONLY}" in done.stderr and "Traceback" not in done.stderr
    with slr_sql.open(db) as kb:
        assert len(kb.query("seen(X)^T")) == 2


def test_a_read_only_file_in_a_read_only_folder_is_said_to_be_unreadable_in_words(
        open_folder):
    folder = open_folder / "locked"
    folder.mkdir()
    db = make_store(folder / "robot.db")
    os.chmod(db, 0o444)
    os.chmod(folder, 0o555)
    for args in (["query", db, "seen(X)^T"], ["add", db, "seen(c)^3"]):
        done = run(unprivileged(*args))
        assert done.returncode == 1, done.stdout
        assert done.stderr.startswith(
            f"error: {db}: cannot open the store: it is read-only to this process, and so is "
            "its folder, where SQLite makes the -shm file"), done.stderr
    assert sorted(p.name for p in folder.iterdir()) == ["robot.db"]
