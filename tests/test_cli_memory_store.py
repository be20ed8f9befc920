"""``:memory:`` as the store of a command (README.md, the paragraph after the commands): a
command that writes to the store refuses it in words (what it wrote would vanish at its
exit), one that only reads says there is no such store; ``slr serve :memory:`` serves a
store in memory for as long as it runs. Real ``python -m slr_sql`` processes, run in an
empty folder that must stay empty.
"""
from __future__ import annotations

import pytest
from service_helpers import ServiceProcess
from test_cli import slr

import slr_sql

WRITES = "is a store in memory, which would start empty and vanish with what {} writes"


@pytest.fixture
def files(tmp_path):
    """A program, an events file and a robot store, in a folder of their own."""
    folder = tmp_path / "files"
    folder.mkdir()
    (folder / "ex.slr").write_text("p(1).\n% events\nseen(a)^1.\n")
    (folder / "ev.txt").write_text("seen(a)^1\n")
    with slr_sql.open(folder / "r1.db", robot="r1", clock=slr_sql.ManualClock(10)) as kb:
        kb.add("seen(a)^1")
    return folder


@pytest.mark.parametrize("args, command", [
    (["add", ":memory:", "seen(a)^1"], "slr add"),
    (["load", ":memory:", "{files}/ex.slr"], "slr load"),
    (["ingest", ":memory:", "{files}/ev.txt"], "slr ingest"),
    (["run", "{files}/ex.slr", "--db", ":memory:"], "slr run --db"),
    (["demo", "--db", ":memory:"], "slr demo --db"),
    (["fleet", "name", ":memory:", "r1"], "slr fleet name"),
    (["fleet", "push", "{files}/r1.db", ":memory:"], "slr fleet push"),
    (["ros", "import", "{files}/ev.txt", ":memory:"], "slr ros import"),
])
def test_a_command_that_writes_refuses_a_store_in_memory(tmp_path, files, args, command):
    work = tmp_path / "work"
    work.mkdir()
    done = slr(*(a.format(files=files) for a in args), cwd=work)
    assert done.returncode == 1, (done.stdout, done.stderr)
    assert done.stderr.startswith(f"error: {command}: ':memory:' "), done.stderr
    assert WRITES.format(command) in done.stderr and "Traceback" not in done.stderr
    assert done.stdout == ""
    assert list(work.iterdir()) == []


@pytest.mark.parametrize("args", [
    ["query", ":memory:", "true"], ["sql", ":memory:", "SELECT 1"], ["stats", ":memory:"],
    ["describe", ":memory:"], ["programs", ":memory:"], ["unload", ":memory:", "main"],
    ["explain", ":memory:", "true"], ["shell", ":memory:"], ["sql", ":memory:", "SELECT 1",
                                                            "--write"],
    ["fleet", "push", ":memory:", "{files}/fleet.db"], ["fleet", "status", ":memory:"],
])
def test_a_command_that_reads_says_there_is_no_such_store(tmp_path, files, args):
    work = tmp_path / "work"
    work.mkdir()
    done = slr(*(a.format(files=files) for a in args), cwd=work)
    assert done.returncode == 1, (done.stdout, done.stderr)
    assert done.stderr.startswith("error: no such store: ':memory:' is a store in memory"), \
        done.stderr
    assert list(work.iterdir()) == []


def test_slr_serve_serves_a_store_in_memory_while_it_runs(tmp_path):
    with ServiceProcess(":memory:", log=tmp_path / "server.log") as served:
        assert slr("add", served.url, "seen(a)^1").returncode == 0
        assert slr("query", served.url, "seen(X)^T").stdout == "X = a, T = 1.0\n"
    refused = slr("serve", ":memory:", "--port", "0", "--foxglove", "--foxglove-port", "0",
                  cwd=tmp_path)
    assert refused.returncode == 1
    assert refused.stderr.startswith("error: slr serve --foxglove needs the store's file"), \
        refused.stderr
