"""``slr ros import`` of a bag whose storage is damaged after its index (a flipped byte in a
rosbag1 chunk, a rosbag2 .db3 cut short, an MCAP chunk whose checksum no longer holds or whose
record says it is longer than any file).

The bag opens (its index and summary are whole) and the readers of rosbags raise while the
messages are read: their own errors and bare ones (AssertionError, KeyError, sqlite3's
DatabaseError, OverflowError). ``slr ros info`` said "the bag is damaged"; ``slr ros import``
let them through as "error: AssertionError:  (this is a bug in slr_sql; please report it)".
Now both say in one line that the bag is damaged after how many messages, exit 1, and the
store is as it was (the damage comes before the first batch is stored). A bag whose message
definition is not UTF-8 no longer prints the whole definition's bytes. Bags written with
rosbags (examples/ros/make_bag.py), the CLI in a subprocess, real SQLite stores.
"""
from __future__ import annotations

import hashlib
import importlib.util
import os
import struct
import subprocess
import sys
from pathlib import Path

import pytest

import slr_sql

REPO = Path(__file__).resolve().parent.parent
spec = importlib.util.spec_from_file_location("make_bag", REPO / "examples/ros/make_bag.py")
make_bag = importlib.util.module_from_spec(spec)
spec.loader.exec_module(make_bag)


def slr(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "slr_sql", *args], capture_output=True,
                          text=True, timeout=120, env={**os.environ, "PYTHONPATH": str(REPO)})


def storage_file(bag: Path) -> Path:
    return bag if bag.is_file() else next(f for f in bag.iterdir()
                                          if f.suffix in (".db3", ".mcap"))


def ros1_message_of_unknown_kind(data: bytes) -> bytes:
    """A rosbag1 message data record (op 0x02) whose op is no record kind."""
    assert b"op=\x02" in data
    return data.replace(b"op=\x02", b"op=\xff", 1)


def db3_cut_short(data: bytes) -> bytes:
    """The last hundredth of a rosbag2 .db3 file gone (its messages' last pages)."""
    return data[:len(data) * 99 // 100]


def mcap_chunk(data: bytes) -> tuple[int, int]:
    """Where the first chunk's body and its records start in an MCAP file."""
    at = 8   # (after the magic)
    while True:
        opcode = data[at]
        (length,) = struct.unpack_from("<Q", data, at + 1)
        if opcode == 0x06:   # Chunk: start, end, uncompressed size, crc, compression, records
            body = at + 9
            (compression_length,) = struct.unpack_from("<I", data, body + 28)
            return body, body + 32 + compression_length + 8
        at += 9 + length


def mcap_chunk_checksum_wrong(data: bytes) -> bytes:
    """The first chunk's checksum not that of its records."""
    body, _ = mcap_chunk(data)
    damaged = bytearray(data)
    damaged[body + 24:body + 28] = struct.pack("<I", 0x5EED)
    return bytes(damaged)


def mcap_record_of_huge_length(data: bytes) -> bytes:
    """The first record in the first chunk says it is 2**63 bytes long and more."""
    _, records = mcap_chunk(data)
    damaged = bytearray(data)
    damaged[records + 8] ^= 0xFF    # (the length's highest byte)
    return bytes(damaged)


DAMAGES = [
    pytest.param("ros1", ros1_message_of_unknown_kind, id="rosbag1-unknown-record"),
    pytest.param("sqlite3", db3_cut_short, id="rosbag2-db3-cut-short"),
    pytest.param("mcap-file", mcap_chunk_checksum_wrong, id="mcap-chunk-checksum"),
    pytest.param("mcap-file", mcap_record_of_huge_length, id="mcap-record-length"),
]


def damaged_bag(tmp_path: Path, fmt: str, damage) -> Path:
    bag = tmp_path / ("rec.bag" if fmt == "ros1" else "rec.mcap" if fmt == "mcap-file"
                      else "rec")
    make_bag.write_bag(bag, fmt, make_bag.demo_items(fmt))
    target = storage_file(bag)
    target.write_bytes(damage(target.read_bytes()))
    return bag


def one_error_line(result: subprocess.CompletedProcess) -> str:
    assert result.returncode == 1, (result.stdout, result.stderr)
    assert "Traceback" not in result.stderr and "bug" not in result.stderr, result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, lines
    return lines[0]


@pytest.mark.parametrize("fmt, damage", DAMAGES)
def test_a_bag_damaged_after_its_index_is_said_so_and_changes_nothing(tmp_path, fmt, damage):
    bag = damaged_bag(tmp_path, fmt, damage)
    db = tmp_path / "robot.db"
    with slr_sql.open(db, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add("keep(me)^1")
    before = hashlib.sha256(db.read_bytes()).hexdigest()
    for args in ([], ["--all"]):
        line = one_error_line(slr("ros", "import", str(bag), str(db), *args))
        assert line.startswith(f"error: cannot read {bag}: the bag is damaged after "), line
        assert hashlib.sha256(db.read_bytes()).hexdigest() == before
    # a new store is not left behind either
    fresh = tmp_path / "fresh.db"
    one_error_line(slr("ros", "import", str(bag), str(fresh)))
    assert not fresh.exists()
    # slr ros info says the same
    line = one_error_line(slr("ros", "info", str(bag)))
    assert f"cannot read {bag}: the bag is damaged after " in line, line


def test_a_message_definition_that_is_no_utf8_is_said_in_few_words(tmp_path):
    bag = tmp_path / "rec"
    make_bag.write_bag(bag, "sqlite3", make_bag.demo_items("sqlite3"))
    target = storage_file(bag)
    data = target.read_bytes()
    rule = b"=" * 20   # (the separator line of a message definition)
    assert rule in data
    target.write_bytes(data.replace(rule, b"\xff" + rule[1:], 1))
    for args in (["ros", "info", str(bag)], ["ros", "import", str(bag), str(tmp_path / "x.db")]):
        line = one_error_line(slr(*args))
        assert "not UTF-8" in line and "=====" not in line and len(line) < 300, line


def test_a_message_whose_text_is_no_utf8_is_rejected_in_few_words(tmp_path):
    """A /tf message whose frame name holds a byte that is no UTF-8: its rejection printed
    the whole message's bytes (``utf-8 b'map\\x00\\x05...' 0 1 invalid start byte``); a
    message of a megabyte made a line of megabytes, 20 times."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_KILTED)
    types = store.types
    big = "f" * 100_000

    def tf(parent: str, child: str) -> bytes:
        msg = types["tf2_msgs/msg/TFMessage"](transforms=[
            types["geometry_msgs/msg/TransformStamped"](
                header=types["std_msgs/msg/Header"](
                    stamp=types["builtin_interfaces/msg/Time"](sec=1, nanosec=0),
                    frame_id=parent),
                child_frame_id=child,
                transform=types["geometry_msgs/msg/Transform"](
                    translation=types["geometry_msgs/msg/Vector3"](x=1.0, y=0.0, z=0.0),
                    rotation=types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0,
                                                                   w=1.0)))])
        return bytes(store.serialize_cdr(msg, "tf2_msgs/msg/TFMessage"))

    bag = tmp_path / "bag"
    with Writer(bag, version=9, storage_plugin=StoragePlugin.SQLITE3) as writer:
        connection = writer.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=store)
        writer.write(connection, 1_000_000_000, tf("m\u00e9p" + big, "base").replace(
            "m\u00e9p".encode(), b"m\xffp"))
        writer.write(connection, 2_000_000_000, tf("map", "base"))
    result = slr("ros", "import", str(bag), str(tmp_path / "r.db"))
    assert result.returncode == 1, result.stderr
    assert "Traceback" not in result.stderr and "bug" not in result.stderr
    (line,) = [line for line in result.stderr.splitlines() if "/tf message 1" in line]
    assert "not UTF-8" in line and len(line) < 400, line[:500]
    assert "imported 2 events from 2 messages, 1 rejected" not in result.stdout
    assert "imported 1 event from 2 messages, 1 rejected" in result.stdout, result.stdout
