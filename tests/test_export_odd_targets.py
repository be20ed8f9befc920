"""``slr export DB FILE`` where FILE is no plain file: a symbolic link, a FIFO, standard
output. The export is written beside FILE and renamed over it, which replaced a link or a
pipe by a plain file (and as root the machine's /dev/full or /dev/stdout), and the check that
FILE is no SQLite database read a FIFO, which waited forever for a writer. Real `slr`
processes."""
from __future__ import annotations

import io
import os
import stat
import subprocess
import sys
import threading
from pathlib import Path

from mcap.reader import make_reader

import slr_sql
from slr_sql import ManualClock

REPO = Path(__file__).resolve().parent.parent
DEADLINE = 60


def slr(*args: str, **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "slr_sql", *args], capture_output=True,
                          timeout=DEADLINE, env={**os.environ, "PYTHONPATH": str(REPO)},
                          **kwargs)


def messages_in(data: bytes) -> int:
    return sum(1 for _ in make_reader(io.BytesIO(data)).iter_messages())


def store(tmp_path: Path) -> Path:
    db = tmp_path / "r.db"
    with slr_sql.open(db, clock=ManualClock(0.0)) as kb:
        kb.add_many([("p", (i,), float(i), float(i)) for i in range(20)])
    return db


def test_an_export_through_a_symbolic_link_writes_its_target_and_keeps_the_link(tmp_path):
    db = store(tmp_path)
    (tmp_path / "exports").mkdir()
    real = tmp_path / "exports" / "run.mcap"
    real.write_bytes(b"an older export")
    link = tmp_path / "latest.mcap"
    link.symlink_to(real)
    result = slr("export", str(db), str(link))
    assert result.returncode == 0, result.stderr
    assert link.is_symlink() and os.readlink(link) == str(real)
    assert messages_in(real.read_bytes()) == 20
    assert sorted(p.name for p in real.parent.iterdir()) == ["run.mcap"]   # no part left


def test_an_export_into_a_fifo_is_read_from_it_and_the_fifo_stays(tmp_path):
    db = store(tmp_path)
    fifo = tmp_path / "export.fifo"
    os.mkfifo(fifo)
    received: list[bytes] = []

    def read() -> None:
        with open(fifo, "rb") as stream:
            received.append(stream.read())

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        result = slr("export", str(db), str(fifo))
    finally:
        if reader.is_alive():           # (nobody wrote: let the reader's open return)
            with open(fifo, "wb"):
                pass
        reader.join(DEADLINE)
    assert result.returncode == 0, result.stderr
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)
    assert messages_in(received[0]) == 20
    assert b"exported 20 events" in result.stdout


def test_an_export_to_standard_output_is_the_mcap_and_the_summary_goes_to_stderr(tmp_path):
    db = store(tmp_path)
    result = slr("export", str(db), "/proc/self/fd/1")
    assert result.returncode == 0, result.stderr
    assert messages_in(result.stdout) == 20
    assert b"exported 20 events to /proc/self/fd/1" in result.stderr


def test_a_socket_is_refused_before_anything_is_written(tmp_path):
    import socket

    db = store(tmp_path)
    path = tmp_path / "s.sock"
    with socket.socket(socket.AF_UNIX) as listening:
        listening.bind(str(path))
        result = slr("export", str(db), str(path))
    assert result.returncode == 1
    assert b"is not a file (a block device or a socket)" in result.stderr, result.stderr
    assert stat.S_ISSOCK(os.stat(path).st_mode)


def test_an_export_named_as_a_side_file_of_the_store_is_refused_before_it_is_written(tmp_path):
    # robot.db-journal does not exist while the store is in WAL mode: the export was written
    # there and deleted by the store's next open, which took it for a journal
    db = store(tmp_path)
    target = tmp_path / "r.db-journal"
    done = slr("export", str(db), str(target))
    assert done.returncode == 1, done.stdout
    assert done.stderr.decode() == (
        f"error: {target} is the name of a file SQLite keeps beside the store being exported "
        f"({db}-journal): it would destroy the export, or the export the store; name another "
        f"file\n")
    assert not target.exists()
