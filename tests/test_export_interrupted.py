"""Red team of ``slr export`` / :func:`export_mcap` (docs/ros.md, "MCAP export"): an export
that stops half way (a cancel from its progress callback, Ctrl-C, disk full) leaves neither a
half-written MCAP file nor a destroyed older export; output paths that cannot be an export
are refused before anything is written."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader

import slr_sql
from slr_sql import ManualClock
from slr_sql.viz.mcap_export import ExportRefused, export_mcap

REPO = Path(__file__).resolve().parent.parent


def slr(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "slr_sql", *args], capture_output=True,
                          text=True, timeout=60, env={**os.environ, "PYTHONPATH": str(REPO)})


class Cancelled(Exception):
    """What a user's progress callback raises to stop an export (a Cancel button)."""


def read_messages(path: Path) -> int:
    with open(path, "rb") as stream:
        return sum(1 for _ in make_reader(stream).iter_messages())


@pytest.mark.parametrize("stop", [Cancelled, KeyboardInterrupt])
def test_an_export_stopped_half_way_keeps_the_older_export_and_leaves_no_half_file(
        tmp_path, stop):
    out = tmp_path / "out.mcap"
    with slr_sql.open(tmp_path / "r.db", clock=ManualClock(0.0)) as kb:
        kb.add_many([("p", (i,), float(i), float(i)) for i in range(5)])
        export_mcap(kb.store, out)
        before = out.read_bytes()
        assert read_messages(out) == 5
        kb.add_many([("p", (i,), float(i), float(i)) for i in range(5, 25_000)])
        seen = []

        def progress(n: int) -> None:
            seen.append(n)
            raise stop()

        with pytest.raises(stop):
            export_mcap(kb.store, out, progress=progress)
        assert seen == [10_000]                  # it did stop half way
    assert out.read_bytes() == before           # the older export is whole
    leftovers = sorted(p.name for p in tmp_path.iterdir()
                       if p.name not in ("out.mcap", "r.db", "r.db-wal", "r.db-shm"))
    assert leftovers == []


def test_an_export_into_a_new_file_stopped_half_way_leaves_nothing(tmp_path):
    out = tmp_path / "new.mcap"
    with slr_sql.open(tmp_path / "r.db", clock=ManualClock(0.0)) as kb:
        kb.add_many([("p", (i,), float(i), float(i)) for i in range(12_000)])

        def progress(n: int) -> None:
            raise Cancelled()

        with pytest.raises(Cancelled):
            export_mcap(kb.store, out, progress=progress)
        assert not out.exists()
        report = export_mcap(kb.store, out)      # and the next export is whole
    assert report.messages == 12_000 and read_messages(out) == 12_000
    assert sorted(p.name for p in tmp_path.iterdir() if not p.name.startswith("r.db")) \
        == ["new.mcap"]


def test_a_directory_as_output_is_refused_before_any_work(tmp_path):
    target = tmp_path / "exports"
    target.mkdir()
    with slr_sql.open(tmp_path / "r.db", clock=ManualClock(0.0)) as kb:
        kb.add_many([("p", (1,), 1.0, 1.0)])
        with pytest.raises(ExportRefused, match="is a directory"):
            export_mcap(kb.store, target)
    assert list(target.iterdir()) == []
    assert sorted(p.name for p in tmp_path.iterdir() if not p.name.startswith("r.db")) \
        == ["exports"]



def test_types_whose_names_hold_a_slash_are_chosen_by_name_and_by_name_arity(tmp_path):
    """An event type may be named ``'a/b'`` (a quoted atom; ROS topic names make such names):
    ``a/b`` and ``a/b/1`` name it. The name was cut at its first slash, so neither did
    (``no event type a/b in the store (it has: a/b/1, ...)``)."""
    db, out = tmp_path / "r.db", tmp_path / "out.mcap"
    with slr_sql.open(db, clock=ManualClock(0.0)) as kb:
        kb.add_many([("a/b", (1,), 1.0, 1.0), ("a", (1, 2), 2.0, 2.0),
                     ("a/b/c", (), 3.0, 3.0)])
    for spec, topics in (("a/b", ["/a/b/1"]), ("a/b/1", ["/a/b/1"]), ("a", ["/a/2"]),
                         ("a/2", ["/a/2"]), ("a/b/c", ["/a/b/c/0"]), ("a/b/c/0", ["/a/b/c/0"])):
        result = slr("export", str(db), str(out), spec)
        assert result.returncode == 0, (spec, result.stderr)
        with open(out, "rb") as stream:
            channels = make_reader(stream).get_summary().channels.values()
        assert sorted(c.topic for c in channels) == topics, spec
    result = slr("export", str(db), str(out), "a/b/2")
    assert result.returncode == 1
    assert "error: no event type a/b/2 in the store (it has: a/2, a/b/1, a/b/c/0)" \
        in result.stderr


def test_an_export_cut_short_is_named_so_by_ros_import_and_ros_info(tmp_path):
    """A copy of an export cut half way (a full disk, a transfer that stopped) has no summary.
    It was taken for a ROS bag and refused with "Profile is not ros2"."""
    db, out, cut = tmp_path / "r.db", tmp_path / "out.mcap", tmp_path / "cut.mcap"
    with slr_sql.open(db, clock=ManualClock(0.0)) as kb:
        kb.add_many([("p", (i,), float(i), float(i)) for i in range(50_000)])
        export_mcap(kb.store, out)
    data = out.read_bytes()
    cut.write_bytes(data[:len(data) // 2])
    for args in (("ros", "import", str(cut), str(tmp_path / "copy.db")),
                 ("ros", "info", str(cut))):
        result = slr(*args)
        assert result.returncode == 1, result
        assert f"cannot read {cut}: an slr export cut short (no summary at its end" \
            in result.stderr, result.stderr
        assert "Traceback" not in result.stderr and "bug" not in result.stderr
    assert not (tmp_path / "copy.db").exists()     # nothing was created for it


def test_a_window_that_ends_before_it_starts_is_refused_not_an_empty_export(tmp_path):
    """``--from 10 --to 1`` wrote an MCAP file of no events ("exported 0 events") where
    ``slr plot`` says "empty time window"; now it is refused before anything is written."""
    db, out = tmp_path / "r.db", tmp_path / "out.mcap"
    with slr_sql.open(db, clock=ManualClock(0.0)) as kb:
        kb.add_many([("p", (i,), float(i), float(i)) for i in range(12)])
    result = slr("export", str(db), str(out), "--from", "10", "--to", "1")
    assert result.returncode == 1
    assert "error: empty time window: --from 10 is after --to 1" in result.stderr, result.stderr
    assert not out.exists()
    result = slr("export", str(db), str(out), "--from", "5", "--to", "5")   # one instant
    assert result.returncode == 0 and "exported 1 event to" in result.stdout, result


def test_a_damaged_export_is_named_so_by_ros_import_and_ros_info(tmp_path):
    """Bytes of a compressed chunk changed (a bad disk, a bad copy): the reader's zstd or CRC
    error reached the user raw ("ZstdError: ... (this is a bug in slr_sql ...)")."""
    db, out = tmp_path / "r.db", tmp_path / "out.mcap"
    with slr_sql.open(db, clock=ManualClock(0.0)) as kb:
        kb.add_many([("p", (i,), float(i), float(i)) for i in range(50_000)])
        export_mcap(kb.store, out)
    data = bytearray(out.read_bytes())
    middle = len(data) // 2
    data[middle:middle + 64] = bytes(b ^ 0x5A for b in data[middle:middle + 64])
    out.write_bytes(bytes(data))
    for args in (("ros", "info", str(out)), ("ros", "import", str(out), str(tmp_path / "c.db"))):
        result = slr(*args)
        assert result.returncode == 1, result
        assert f"cannot read {out}: the MCAP file is damaged" in result.stderr, result.stderr
        assert "Traceback" not in result.stderr and "bug" not in result.stderr


def test_long_atoms_are_not_kept_by_the_channels_text_cache(tmp_path):
    """The live view and the export keep the JSON text of atoms they have written (frame and
    object names repeat), up to 65,536 of them -- of any length: a history of distinct long
    atoms (log lines, file contents mapped to atoms) kept up to 65,536 x their size in the
    view's memory for as long as it runs. Only short atoms are kept now."""
    from slr_sql.viz import channels

    with slr_sql.open(tmp_path / "r.db", clock=ManualClock(0.0)) as kb:
        kb.add_many([("log", (f"{i:06d}" + "x" * 50_000,), float(i), float(i))
                     for i in range(200)])
        kb.add_many([("seen", ("cup1",), 1.0, 1.0), ("seen", ("cup1",), 2.0, 2.0)])
        report = export_mcap(kb.store, tmp_path / "out.mcap")
    assert report.messages == 202
    held = sum(len(k) + len(v) for k, v in list(channels._TEXTS.items()))
    assert held < 1_000_000, held
    assert "cup1" in channels._TEXTS            # short names are still kept


def test_a_row_that_is_no_event_stops_the_export_in_words(tmp_path):
    """A row written by hand with a NULL argument ended the export with "ValueError: NULL is
    not a stored term (this is a bug in slr_sql ...)"; now the error names the type and the
    row, and no file is written."""
    import sqlite3

    db, out = tmp_path / "r.db", tmp_path / "out.mcap"
    with slr_sql.open(db, clock=ManualClock(0.0)) as kb:
        kb.add_many([("p", (1,), 1.0, 1.0), ("p", (2,), 2.0, 2.0)])
    with sqlite3.connect(db) as conn:
        conn.execute('UPDATE "p" SET arg1 = NULL WHERE seq = 2')
    result = slr("export", str(db), str(out))
    assert result.returncode == 1
    assert "error: p/1: the row of seq 2 is not an event (NULL is not a stored term)" \
        in result.stderr, result.stderr
    assert "bug" not in result.stderr and "Traceback" not in result.stderr
    assert not out.exists()
