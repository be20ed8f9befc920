"""MCAP files that say they are ``slr export`` files (a channel with ``slr_event`` metadata)
but whose channels were written by someone else (docs/ros.md, "Reading an export back").

A channel's ``slr_arity`` is the arity of its events. Missing, ``slr ros info`` stopped with
"KeyError: 'slr_arity' (this is a bug in slr_sql)"; negative (``-3``), the import stored the
channel's events as ``p/0``; of 5,000 digits, the import passed on Python's advice "use
sys.set_int_max_str_digits() to increase the limit". A message nested beyond the
interpreter's depth stopped ``slr ros info`` ("the term is nested too deeply") instead of
being counted as a message that does not decode. Now the import refuses a channel whose
metadata names no event type before it stores anything, saying which channel, and info
summarizes the rest. Files written with the mcap package; the CLI in a subprocess.
"""
from __future__ import annotations

import hashlib
import os
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.writer import Writer as McapWriter

import slr_sql

from test_ros_import_damaged_bags import one_error_line

REPO = Path(__file__).resolve().parent.parent
GOOD = b'{"arg1":"a","start":1.0,"end":1.0,"arrival":1.0}'


def slr(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "slr_sql", *args], capture_output=True,
                          text=True, timeout=120, env={**os.environ, "PYTHONPATH": str(REPO)})


def crafted(path: Path, metadata: dict, messages: list[bytes], topic: str = "/p/1") -> None:
    """A good channel of q/1 first (its events would be stored before the crafted one's),
    then the crafted channel."""
    with open(path, "wb") as stream:
        writer = McapWriter(stream)
        writer.start(profile="", library="elsewhere")
        schema = writer.register_schema("slr.p/1", "jsonschema", b"{}")
        good = writer.register_channel("/q/1", "json", schema,
                                       {"slr_event": "q", "slr_arity": "1"})
        channel = writer.register_channel(topic, "json", schema, metadata)
        writer.add_message(good, 1, GOOD, 0, 0)
        for i, data in enumerate(messages):
            writer.add_message(channel, (i + 2) * 1_000_000_000, data, 0, i)
        writer.finish()


@pytest.mark.parametrize("metadata", [
    pytest.param({"slr_event": "p"}, id="no-arity"),
    pytest.param({"slr_event": "p", "slr_arity": "-3"}, id="negative"),
    pytest.param({"slr_event": "p", "slr_arity": "abc"}, id="not-a-number"),
    pytest.param({"slr_event": "p", "slr_arity": "9" * 5000}, id="5000-digits"),
    pytest.param({"slr_event": "p", "slr_arity": "1 "}, id="with-a-space"),
])
def test_a_channel_whose_arity_is_none_is_refused_and_nothing_stored(tmp_path, metadata):
    path = tmp_path / "crafted.mcap"
    crafted(path, metadata, [GOOD])
    db = tmp_path / "robot.db"
    with slr_sql.open(db, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add("keep(me)^1")
    before = hashlib.sha256(db.read_bytes()).hexdigest()
    line = one_error_line(slr("ros", "import", str(path), str(db)))
    assert f"cannot read {path}: channel /p/1: its slr_arity " in line, line
    assert "sys.set_int_max_str_digits" not in line and len(line) < 400, line
    assert hashlib.sha256(db.read_bytes()).hexdigest() == before
    info = slr("ros", "info", str(path))
    assert info.returncode == 0, info.stderr
    assert "bug" not in info.stderr and "Traceback" not in info.stderr
    assert "/p/1" in info.stdout and "/q/1" in info.stdout


def test_ros_info_counts_a_message_nested_too_deeply_as_one_that_does_not_decode(tmp_path):
    path = tmp_path / "deep.mcap"
    deep = (b'{"arg1":' + b"[" * 200_000 + b"]" * 200_000
            + b',"arg2":"b","arg3":1,"start":1,"end":1,"arrival":1}')
    good = (b'{"arg1":"map","arg2":"base","arg3":{"pose":[[1.0,0.0,0.0],[0.0,0.0,0.0,1.0]]},'
            b'"start":2.0,"end":2.0,"arrival":2.0}')
    crafted(path, {"slr_event": "tf", "slr_arity": "3"}, [deep, good], topic="/tf/3")
    result = slr("ros", "info", str(path))
    assert result.returncode == 0, result.stderr
    assert "warning: /tf/3: 1 of 2 messages do not decode" in result.stderr, result.stderr
    assert any("map" in line and "base" in line for line in result.stdout.splitlines())
    line = one_error_line(slr("ros", "import", str(path), str(tmp_path / "x.db")))
    assert "/tf/3: message 1 is not an slr event" in line, line


def test_a_message_with_an_integer_of_5000_digits_is_said_in_words(tmp_path):
    """Python's JSON reader refuses integers of more than 4,300 digits with advice for a
    programmer ("use sys.set_int_max_str_digits() to increase the limit"), which the import
    passed on; and a message's reason quoted whole."""
    path = tmp_path / "digits.mcap"
    crafted(path, {"slr_event": "p", "slr_arity": "1"},
            [b'{"arg1":' + b"9" * 5000 + b',"start":1,"end":1,"arrival":1}'])
    line = one_error_line(slr("ros", "import", str(path), str(tmp_path / "x.db")))
    assert "/p/1: message 1 is not an slr event: an integer of more than 4300 digits" in line, \
        line
    assert "sys.set_int_max_str_digits" not in line


@pytest.mark.parametrize("message, reason", [
    pytest.param(b'{"arg1":"a","start":true,"end":true,"arrival":1}',
                 "its start time true is no number", id="true"),
    pytest.param(b'{"arg1":"a","start":"1.5","end":2,"arrival":1}',
                 'its start time "1.5" is no number', id="text"),
    pytest.param(b'{"arg1":"a","start":1,"end":[2],"arrival":1}',
                 "its end time [2] is no number", id="list"),
    pytest.param(b'{"arg1":"a","start":' + b"9" * 400 + b',"end":1,"arrival":1}',
                 "its start time is an integer beyond any float", id="400-digits"),
    pytest.param(b'[1, 2]', "it is no JSON object", id="array"),
    pytest.param(b'{"start":1,"end":1}', "it has no arg1", id="no-argument"),
    pytest.param(b'{"arg1":"a","start":1,"arrival":1}', "it has no end", id="no-end"),
])
def test_a_message_whose_times_are_no_numbers_is_refused_in_words(tmp_path, message, reason):
    """Times were read with float(): JSON ``true`` was stored as 1.0 and ``"1.5"`` as 1.5,
    times the export never had; an integer of 400 digits stopped the import with
    "OverflowError ... (this is a bug in slr_sql)"; a missing key was said as ``'end'``."""
    path = tmp_path / "times.mcap"
    crafted(path, {"slr_event": "p", "slr_arity": "1"}, [message])
    db = tmp_path / "robot.db"
    with slr_sql.open(db, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add("keep(me)^1")
    before = hashlib.sha256(db.read_bytes()).hexdigest()
    line = one_error_line(slr("ros", "import", str(path), str(db)))
    assert line.endswith(f"/p/1: message 1 is not an slr event: {reason}"), line
    assert hashlib.sha256(db.read_bytes()).hexdigest() == before


def test_ros_info_counts_a_transform_whose_time_is_beyond_any_float_as_undecodable(tmp_path):
    path = tmp_path / "tf.mcap"
    crafted(path, {"slr_event": "tf", "slr_arity": "3"},
            [b'{"arg1":"map","arg2":"base","arg3":[0,0,0],"start":' + b"9" * 400
             + b',"end":1,"arrival":1}'], topic="/tf")
    info = slr("ros", "info", str(path))
    assert info.returncode == 0, info.stderr
    assert "bug" not in info.stderr and "Traceback" not in info.stderr
    assert "warning: /tf: 1 of 1 messages do not decode" in info.stderr, info.stderr
