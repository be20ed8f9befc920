"""Input that fails while it is read: a file whose read is an I/O error (a bad disk, a
network file system gone: here /proc/self/mem, whose read at offset 0 is EIO), a name
longer than the file system takes. `slr ingest`, `slr run`, `slr ros info` and `slr ros
import` printed "error: OSError: [Errno 5] Input/output error (this is a bug in slr_sql;
please report it)"; now they say which file could not be read and why, and an ingest keeps
the events of the lines it read before the error. Real `slr` processes, real stores."""
from __future__ import annotations

import errno
import os
import subprocess
import sys
from pathlib import Path

import pytest

import slr_sql
from slr_sql import ManualClock
from slr_sql.cli import ingest_file

REPO = Path(__file__).resolve().parent.parent
UNREADABLE = "/proc/self/mem"


def slr(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "slr_sql", *args], capture_output=True,
                          text=True, timeout=120, env={**os.environ, "PYTHONPATH": str(REPO)},
                          stdin=subprocess.DEVNULL)


def no_bug(result: subprocess.CompletedProcess) -> None:
    assert "bug in slr_sql" not in result.stderr and "Traceback" not in result.stderr, \
        result.stderr


def test_ingest_of_a_file_whose_read_fails_says_so(tmp_path):
    db = tmp_path / "r.db"
    with slr_sql.open(db, clock=ManualClock(0.0)) as kb:
        kb.add("p(1)^1")
    result = slr("ingest", str(db), UNREADABLE)
    no_bug(result)
    assert result.returncode == 1
    assert f"error: cannot read {UNREADABLE} after line 0: Input/output error" \
        in result.stderr, result.stderr


class _FailsAfter:
    """A binary input stream whose read fails (EIO) after ``lines``: the disk under a file
    that went bad half way."""

    def __init__(self, lines: list[bytes]):
        self.lines = lines

    def __iter__(self):
        yield from self.lines
        raise OSError(errno.EIO, os.strerror(errno.EIO))


def test_an_ingest_keeps_the_events_read_before_the_read_failed(tmp_path):
    with slr_sql.open(tmp_path / "r.db", clock=ManualClock(0.0)) as kb:
        report = ingest_file(kb, _FailsAfter([b"p(1)^1\n", b"p(2\n", b"p(3)^3\n"]))
        assert kb.query("p(X)^T") == [{"X": 1, "T": 1.0}, {"X": 3, "T": 3.0}]
    assert report.added == 2 and [n for n, _ in report.bad] == [2]
    assert report.unread == (3, "Input/output error")


def test_run_of_an_example_file_whose_read_fails_says_so():
    result = slr("run", UNREADABLE)
    no_bug(result)
    assert result.returncode == 1
    assert f"error: cannot read {UNREADABLE}: Input/output error" in result.stderr


@pytest.mark.parametrize("command", [["ros", "info"], ["ros", "import"]])
def test_a_bag_name_too_long_for_the_file_system_is_said_in_words(tmp_path, command):
    name = "b" * 5000
    result = slr(*command, name, *([str(tmp_path / "c.db")] if command[1] == "import" else []))
    no_bug(result)
    assert result.returncode == 1
    assert "File name too long" in result.stderr or "no such bag" in result.stderr, \
        result.stderr


def test_an_input_larger_than_memory_is_said_in_words(tmp_path):
    """`slr ingest DB /dev/zero` reads one endless line: MemoryError, whose message is
    empty, was printed as "error: MemoryError:  (this is a bug in slr_sql ...)". The
    process's address space is bounded here (1.5 GB) so that the test does not take the
    machine's memory."""
    import resource

    db = tmp_path / "r.db"
    with slr_sql.open(db, clock=ManualClock(0.0)) as kb:
        kb.add("p(1)^1")

    def bounded() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (1_500_000_000, 1_500_000_000))

    result = subprocess.run([sys.executable, "-m", "slr_sql", "ingest", str(db), "/dev/zero"],
                            capture_output=True, text=True, timeout=120, preexec_fn=bounded,
                            env={**os.environ, "PYTHONPATH": str(REPO)},
                            stdin=subprocess.DEVNULL)
    no_bug(result)
    assert result.returncode == 1
    assert "error: out of memory" in result.stderr, result.stderr
    with slr_sql.open(db, clock=ManualClock(0.0)) as kb:
        assert kb.query("p(X)^T") == [{"X": 1, "T": 1.0}]
