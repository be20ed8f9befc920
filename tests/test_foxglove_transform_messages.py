"""``foxglove.FrameTransforms`` messages of stored tf rows (slr_sql/viz/channels.py), which
the live view sends and ``slr export`` writes: a transform whose numbers are no finite
floats, or whose quaternion is zero (no rotation: ``tf_lookup`` refuses it as tf2 does), is
left out, whether the message is written from the stored text (one row) or
decoded (several rows)."""
from __future__ import annotations

import json

import pytest

from slr_sql.viz.channels import transform_message

GOOD = ("map", "base", '{"pose":[[1.0,2.0,3.0],[0.0,0.0,0.0,1.0]]}', 2.5, 2.5, 3.0, 1)
HUGE = str(10 ** 400)


@pytest.mark.parametrize("pose", [
    f'{{"pose":[[{HUGE},0,0],[0,0,0,1]]}}',
    f'{{"pose":[[1,0,0],[0,0,0,-{HUGE}]]}}',
    '{"pose":[[9e999,0,0],[0,0,0,1]]}',
])
def test_a_transform_beyond_any_float_is_left_out(pose):
    """One row was written as it was stored (a message with a number of 400 digits);
    two rows stopped the view with "OverflowError: int too large to convert to float"."""
    bad = ("map", "cam", pose, 1.0, 1.0, 1.0, 2)
    assert transform_message([bad]) is None
    message = json.loads(transform_message([bad, GOOD]))
    assert [t["child_frame_id"] for t in message["transforms"]] == ["base"]
    assert message["transforms"][0]["translation"] == {"x": 1.0, "y": 2.0, "z": 3.0}


def test_a_row_of_plain_numbers_is_still_written_from_its_text():
    message = json.loads(transform_message([GOOD]))
    assert message["transforms"][0]["rotation"] == {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}


@pytest.mark.parametrize("pose", [
    '{"pose":[[01,2,3],[0,0,0,1]]}',          # a leading zero
    '{"pose":[[,2,3],[0,0,0,1]]}',            # an empty place
    '{"pose":[[1e5e5,2,3],[0,0,0,1]]}',       # two exponents
    '{"pose":[[1.,2,3],[0,0,0,1]]}',          # no digit after the point
    '{"pose":[[+1,2,3],[0,0,0,1]]}',          # a plus sign
])
def test_a_stored_pose_of_texts_that_are_no_json_numbers_gives_no_broken_message(pose):
    """A pose row written by hand whose numbers only looked like numbers (digits, points,
    signs, e's) was copied as it was into the message: invalid JSON in the MCAP file and
    on Foxglove's socket. Such a row is now decoded like any other (and left out)."""
    row = ("map", "cam", pose, 1.0, 1.0, 1.0, 2)
    assert transform_message([row]) is None
    message = json.loads(transform_message([row, GOOD]))
    assert [t["child_frame_id"] for t in message["transforms"]] == ["base"]


def test_poses_of_json_numbers_are_written_from_their_text_as_decoded():
    rows = [GOOD, ("map", "cam", '{"pose":[[1e-05,-2.5,3.25],[0.0,0.0,0.7071,0.7071]]}', 4.0,
                   5.0, 6.0, 3),
            ("map", "odom", '{"pose":[[1.5e+16,-0.0,2E-7],[0.0,0.0,0.0,1.0]]}', 4.0, 5.0, 6.0,
             4)]
    for row in rows:   # the text as stored; decoding it gives the same numbers
        fast = json.loads(transform_message([row]))["transforms"]
        assert json.loads(transform_message([row, row]))["transforms"] == fast * 2


@pytest.mark.parametrize("quaternion", ["[0,0,0,0]", "[0.0,-0.0,0e5,0.0]"])
def test_a_transform_whose_quaternion_is_zero_is_left_out(quaternion):
    """It was sent and exported as it was stored, a rotation of zero length that no viewer
    can apply, where tf_lookup over the same row fails."""
    bad = ("map", "cam", f'{{"pose":[[1,0,0],{quaternion}]}}', 1.0, 1.0, 1.0, 2)
    assert transform_message([bad]) is None
    message = json.loads(transform_message([bad, GOOD]))
    assert [t["child_frame_id"] for t in message["transforms"]] == ["base"]


def test_an_export_leaves_a_zero_rotation_out_of_its_frame_transforms(tmp_path):
    """The event itself is exported as stored (its channel), only /tf leaves it out."""
    import slr_sql
    from slr_sql import ManualClock, Struct
    from mcap.reader import make_reader
    from slr_sql.viz.mcap_export import export_mcap

    with slr_sql.open(tmp_path / "r.db", clock=ManualClock(10.0)) as kb:
        kb.add_many([("tf", ("map", "cam", Struct("pose", ([1, 0, 0], [0, 0, 0, 0]))), 1.0, 1.0),
                     ("tf", ("map", "base", Struct("pose", ([1, 0, 0], [0, 0, 0, 1]))), 2.0, 2.0)])
        export_mcap(kb.store, tmp_path / "r.mcap")
    with open(tmp_path / "r.mcap", "rb") as stream:
        topics = [(channel.topic, json.loads(message.data))
                  for _, channel, message in make_reader(stream).iter_messages()]
    assert [t for t, _ in topics] == ["/tf/3", "/tf/3", "/tf"]
    assert topics[2][1]["transforms"][0]["child_frame_id"] == "base"
