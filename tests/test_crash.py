"""Durability: an event whose add returned survives SIGKILL of the process that added it,
also with several writer processes on one file."""
from __future__ import annotations

import os
import random
import signal
import sqlite3
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import slr_sql
from slr_sql.store import EventStore
from slr_sql.terms import make_list

REPO = Path(__file__).resolve().parent.parent

# The child acknowledges each add on stdout only after add_event/add_events has returned.
CHILD = textwrap.dedent("""
    import sys
    sys.path.insert(0, {repo!r})
    from slr_sql.store import EventStore
    from slr_sql.terms import Atom, make_list

    store = EventStore({path!r})
    batch = {batch}
    i = 0
    while True:
        if batch == 1:
            store.add_event("seg", (Atom("o%d" % i), make_list([i, 0.5])), float(i), float(i))
        else:
            store.add_events([("seg", (Atom("o%d" % k), make_list([k, 0.5])), float(k), float(k))
                              for k in range(i * batch, (i + 1) * batch)], atomic=True)
        sys.stdout.write("%d\\n" % i)
        sys.stdout.flush()
        i += 1
""")

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="needs SIGKILL")


def run_and_kill(path: Path, batch: int, acknowledgements: int) -> tuple[int, int]:
    """Start the writer, read acknowledgements until enough, SIGKILL it; return the count
    read before the kill and the count it had written by then (the writer runs on between
    the last read and the kill, its acknowledgements wait in the pipe)."""
    child = subprocess.Popen(
        [sys.executable, "-c", CHILD.format(repo=str(REPO), path=str(path), batch=batch)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=str(REPO))
    acknowledged = 0
    try:
        while acknowledged < acknowledgements:
            line = child.stdout.readline()
            if not line:
                raise AssertionError(f"writer died: {child.stderr.read()}")
            assert int(line) == acknowledged
            acknowledged += 1
    finally:
        os.kill(child.pid, signal.SIGKILL)
        child.wait()
        written = acknowledged + len(child.stdout.read().split())
        child.stdout.close()
        child.stderr.close()
    assert child.returncode == -signal.SIGKILL
    return acknowledged, written


def test_acknowledged_events_survive_sigkill(tmp_path):
    path = tmp_path / "crash.db"
    acknowledged, written = run_and_kill(path, batch=1, acknowledgements=2000)

    with EventStore(path) as store:
        assert store.sql("PRAGMA integrity_check")[1] == [("ok",)]
        stored = [(str(args[0]), args[1], start) for args, start, _, _ in store.scan("seg", 2)]
    # every acknowledged event is there, intact; at most the one in flight is extra
    assert acknowledged <= written <= len(stored) <= written + 1
    for i, (name, position, start) in enumerate(stored):
        assert (name, position, start) == (f"o{i}", make_list([i, 0.5]), float(i))

    conn = sqlite3.connect(path)  # and plain SQLite agrees
    assert conn.execute("PRAGMA integrity_check").fetchone() == ("ok",)
    assert conn.execute("SELECT count(*) FROM seg").fetchone()[0] == len(stored)
    conn.close()


def test_a_killed_batch_is_all_or_nothing(tmp_path):
    path = tmp_path / "crash.db"
    batch = 500
    acknowledged, written = run_and_kill(path, batch=batch, acknowledgements=40)

    with EventStore(path) as store:
        assert store.sql("PRAGMA integrity_check")[1] == [("ok",)]
        count = store.count("seg", 2)
        assert count % batch == 0  # no half-stored batch
        assert acknowledged * batch <= written * batch <= count <= (written + 1) * batch
        starts = [start for _, start, _, _ in store.scan("seg", 2)]
    assert starts == [float(k) for k in range(count)]


# Several writer processes on one file through the public API, killed together at random
# points: every event whose add_many returned (acknowledged on stdout) must be stored.
WRITER = textwrap.dedent("""
    import sys
    sys.path.insert(0, {repo!r})
    import slr_sql

    kb = slr_sql.open({path!r})
    writer, seq = {writer}, {start}
    while True:
        kb.add_many([("w", ("w%d" % writer, seq + k), float(seq + k), float(seq + k))
                     for k in range(5)])
        sys.stdout.write("%d\\n" % seq)
        sys.stdout.flush()
        seq += 5
""")


def test_concurrent_writers_killed_together_lose_nothing(tmp_path):
    path = tmp_path / "shared.db"
    with slr_sql.open(path) as kb:
        kb.load(":- event(w/2).")
    rng = random.Random(11)
    acknowledged: dict[str, set] = {"w0": set(), "w1": set()}
    for round_ in range(3):
        writers = [subprocess.Popen(
            [sys.executable, "-c", WRITER.format(repo=str(REPO), path=str(path), writer=w,
                                                 start=1_000_000 * round_)],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=str(REPO))
            for w in (0, 1)]
        try:
            for w, child in enumerate(writers):
                for _ in range(rng.randint(5, 40)):
                    line = child.stdout.readline()
                    if not line:
                        raise AssertionError(f"writer died: {child.stderr.read()}")
                    acknowledged[f"w{w}"].update(range(int(line), int(line) + 5))
        finally:
            for child in writers:
                os.kill(child.pid, signal.SIGKILL)
            for w, child in enumerate(writers):
                child.wait()
                for line in child.stdout.read().split():   # acknowledged before the kill
                    acknowledged[f"w{w}"].update(range(int(line), int(line) + 5))
                child.stdout.close()
                child.stderr.close()
                assert child.returncode == -signal.SIGKILL
    conn = sqlite3.connect(path)
    assert conn.execute("PRAGMA integrity_check").fetchone() == ("ok",)
    stored: dict[str, set] = {"w0": set(), "w1": set()}
    for writer, seq in conn.execute("SELECT arg1, arg2 FROM w"):
        stored[writer].add(seq)
    conn.close()
    for writer, seqs in acknowledged.items():
        assert seqs and seqs <= stored[writer], f"{writer}: lost {sorted(seqs - stored[writer])[:5]}"
    with slr_sql.open(path) as kb:   # and the file reopens as a knowledge base
        assert kb.query("w(w0, 0)^_") == [{}]
