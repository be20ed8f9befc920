"""Red team of ``slr ros info`` and of reading ``slr export`` files back (docs/ros.md): a bag
from elsewhere may hold messages that do not decode. ``slr ros import`` rejects each with its
reason; ``slr ros info`` stopped at the first one with "error: error: unpack_from requires a
buffer ... (this is a bug in slr_sql; please report it)". Now it counts them, says so, and
summarizes the rest. Bags written with rosbags (no ROS needed), the CLI in a subprocess."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.writer import Writer as McapWriter
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

REPO = Path(__file__).resolve().parent.parent


def slr(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "slr_sql", *args], capture_output=True,
                          text=True, timeout=120, env={**os.environ, "PYTHONPATH": str(REPO)})


def tf_bag(path: Path, plugin) -> None:
    """A /tf topic of one good TFMessage (map -> base at 1.5) between two that do not decode
    (truncated CDR, no bytes at all), and a /tf_static that decodes."""
    store = get_typestore(Stores.ROS2_KILTED)
    Tf = store.types["tf2_msgs/msg/TFMessage"]
    Stamped = store.types["geometry_msgs/msg/TransformStamped"]
    Header = store.types["std_msgs/msg/Header"]
    Time = store.types["builtin_interfaces/msg/Time"]
    Transform = store.types["geometry_msgs/msg/Transform"]
    Vector3 = store.types["geometry_msgs/msg/Vector3"]
    Quaternion = store.types["geometry_msgs/msg/Quaternion"]

    def message(parent: str, child: str, sec: int, nanosec: int) -> bytes:
        msg = Tf(transforms=[Stamped(
            header=Header(stamp=Time(sec=sec, nanosec=nanosec), frame_id=parent),
            child_frame_id=child,
            transform=Transform(translation=Vector3(x=1.0, y=0.0, z=0.0),
                                rotation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)))])
        return bytes(store.serialize_cdr(msg, "tf2_msgs/msg/TFMessage"))

    with Writer(path, version=9, storage_plugin=plugin) as writer:
        tf = writer.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=store)
        static = writer.add_connection("/tf_static", "tf2_msgs/msg/TFMessage", typestore=store)
        writer.write(static, 500_000_000, message("base", "cam", 0, 500_000_000))
        writer.write(tf, 1_000_000_000, b"\x00\x01\x00\x00\x05\x00\x00\x00garbage")
        writer.write(tf, 1_500_000_000, message("map", "base", 1, 500_000_000))
        writer.write(tf, 2_000_000_000, b"")


@pytest.mark.parametrize("plugin", [StoragePlugin.SQLITE3, StoragePlugin.MCAP],
                         ids=["sqlite3", "mcap"])
def test_ros_info_counts_messages_that_do_not_decode_and_summarizes_the_rest(tmp_path, plugin):
    bag = tmp_path / "bag"
    tf_bag(bag, plugin)
    result = slr("ros", "info", str(bag))
    assert result.returncode == 0, result.stderr
    assert "bug" not in result.stderr and "Traceback" not in result.stderr
    assert "warning: /tf: 2 of 3 messages do not decode" in result.stderr, result.stderr
    lines = result.stdout.splitlines()
    assert any("map" in line and "base" in line and "1.500" in line for line in lines), \
        result.stdout
    assert any("base" in line and "cam" in line for line in lines), result.stdout
    data = json.loads(slr("ros", "info", str(bag), "--json").stdout)
    assert {t["topic"]: (t["count"], t["undecodable"]) for t in data["topics"]} == \
        {"/tf": (3, 2), "/tf_static": (1, 0)}
    assert [(e["parent"], e["child"], e["count"]) for e in data["frames"]] == \
        [("map", "base", 1), ("base", "cam", 1)]


def crafted_export(path: Path, tf_messages: list[bytes], marks: list[bytes] = ()) -> None:
    """An MCAP file whose channels say they are slr events (``slr_event`` metadata), as
    ``slr export`` writes, but whose messages were written by someone else."""
    with open(path, "wb") as stream:
        writer = McapWriter(stream)
        writer.start(profile="", library="elsewhere")
        schema = writer.register_schema("slr.tf/3", "jsonschema", b"{}")
        channel = writer.register_channel("/tf/3", "json", schema,
                                          {"slr_event": "tf", "slr_arity": "3"})
        for i, data in enumerate(tf_messages):
            writer.add_message(channel, (i + 1) * 1_000_000_000, data, 0, i)
        if marks:
            mark_channel = writer.register_channel("/slr/completeness", "json", schema, {})
            for i, data in enumerate(marks):
                writer.add_message(mark_channel, 9_000_000_000, data, 0, i)
        writer.finish()


GOOD_TF = (b'{"arg1":"map","arg2":"base","arg3":{"pose":[[1.0,0.0,0.0],[0.0,0.0,0.0,1.0]]},'
           b'"start":2.0,"end":2.0,"arrival":2.0}')


def test_ros_info_of_an_export_with_messages_that_are_not_events(tmp_path):
    path = tmp_path / "crafted.mcap"
    crafted_export(path, [b"not json", GOOD_TF, b'{"arg1": "map"}', b"[1, 2]"])
    result = slr("ros", "info", str(path))
    assert result.returncode == 0, result.stderr
    assert "bug" not in result.stderr and "Traceback" not in result.stderr
    assert "warning: /tf/3: 3 of 4 messages do not decode" in result.stderr, result.stderr
    assert any("map" in line and "base" in line for line in result.stdout.splitlines())


@pytest.mark.parametrize("mark", [b'{"type": "tf/3", "until": "soon"}', b"[1]", b"{bad",
                                  b'{"type": "tf/3"}', b'{"type": "tf/3", "until": NaN}'])
def test_importing_an_export_with_a_mark_that_is_not_one_says_which(tmp_path, mark):
    path = tmp_path / "crafted.mcap"
    crafted_export(path, [GOOD_TF], [mark])
    result = slr("ros", "import", str(path), str(tmp_path / "copy.db"))
    assert result.returncode == 1
    assert "bug" not in result.stderr and "Traceback" not in result.stderr
    assert "/slr/completeness: message 1 is not a completeness mark" in result.stderr, \
        result.stderr


def short_bag(path: Path, count: int, kept: int) -> None:
    """A rosbag2 (sqlite3) whose metadata counts ``count`` messages on /chat but whose storage
    holds only the first ``kept`` (rows lost: a damaged db3 repaired by dropping pages, a
    recording whose last writes never reached the disk)."""
    import sqlite3

    store = get_typestore(Stores.ROS2_KILTED)
    String = store.types["std_msgs/msg/String"]
    with Writer(path, version=9, storage_plugin=StoragePlugin.SQLITE3) as writer:
        chat = writer.add_connection("/chat", "std_msgs/msg/String", typestore=store)
        for i in range(count):
            writer.write(chat, (i + 1) * 1_000_000_000,
                         bytes(store.serialize_cdr(String(data=f"m{i}"), "std_msgs/msg/String")))
    (db3,) = path.glob("*.db3")
    with sqlite3.connect(db3) as conn:
        conn.execute("DELETE FROM messages WHERE id > ?", (kept,))


def test_an_import_that_reads_fewer_messages_than_the_bag_counts_says_so(tmp_path):
    """The import read what the storage held and said "imported 60 events from 60
    messages", exit 0, for a bag that counts 100 messages on the topic: 40 lost in
    silence."""
    bag, db = tmp_path / "bag", tmp_path / "r.db"
    short_bag(bag, 100, 60)
    result = slr("ros", "import", str(bag), str(db), "--all")
    assert result.returncode == 1, result
    assert "Traceback" not in result.stderr and "bug" not in result.stderr
    assert (f"{bag}: /chat: the bag counts 100 messages, 60 could be read "
            f"(the bag is damaged or cut short)") in result.stderr, result.stderr
    assert "imported 60 events from 60 messages" in result.stdout   # what could be read is in
    info = slr("ros", "info", str(bag))
    assert info.returncode == 0, info
    assert "warning: /chat: the bag counts 100 messages, 60 could be read" in info.stderr, \
        info.stderr
    data = json.loads(slr("ros", "info", str(bag), "--json").stdout)
    assert [(t["topic"], t["count"], t["read"]) for t in data["topics"]] == [("/chat", 100, 60)]


@pytest.mark.parametrize("where, said", [
    (0.2, "error: cannot read {bag}: the bag is damaged after"),
    (0.5, "warning: /chat: the bag counts 20000 messages, 13610 could be read")])
def test_ros_info_of_a_bag_whose_storage_is_damaged_says_so(tmp_path, where, said):
    """Changed bytes in an MCAP bag: where a record's length is hit, rosbags' ReaderError
    reached the user as "error: ReaderError: Truncated record ... (this is a bug in slr_sql
    ...)"; where a chunk's messages are lost, the summary counted them as if read."""
    bag = tmp_path / "bag"
    store = get_typestore(Stores.ROS2_KILTED)
    String = store.types["std_msgs/msg/String"]
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        chat = writer.add_connection("/chat", "std_msgs/msg/String", typestore=store)
        for i in range(20_000):
            writer.write(chat, (i + 1) * 1_000_000_000,
                         bytes(store.serialize_cdr(String(data=f"m{i}"), "std_msgs/msg/String")))
    (mcap,) = bag.glob("*.mcap")
    data = bytearray(mcap.read_bytes())
    at = int(len(data) * where)
    data[at:at + 64] = bytes(b ^ 0x5A for b in data[at:at + 64])
    mcap.write_bytes(bytes(data))
    result = slr("ros", "info", str(bag))
    assert "Traceback" not in result.stderr and "bug" not in result.stderr, result.stderr
    assert said.format(bag=bag) in result.stderr, result.stderr
    assert result.returncode == (1 if said.startswith("error") else 0)


def test_an_mcap_file_cut_after_its_magic_is_said_to_be_cut_short(tmp_path):
    """A file holding only MCAP's magic (a copy or download cut short): rosbags' reader reads
    the next record's kind with ord() of nothing, and the user read "error: cannot read
    FILE: ord() expected a character, but string of length 0 found" -- Python's words."""
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(b"\x89MCAP0\r\n")
    for args in (("ros", "info", str(cut)), ("ros", "import", str(cut), str(tmp_path / "r.db"))):
        result = slr(*args)
        assert result.returncode == 1 and "Traceback" not in result.stderr
        assert result.stderr.strip() == (f"error: cannot read {cut}: the file ends where a "
                                         "record should begin (it is cut short)"), result.stderr
