"""Red team of the live ROS 2 bridge (docs/ros.md, "Live bridge"): a store that is busy (another
process holding its write lock longer than ``busy_timeout``) when messages arrive. The bridge
stored each burst with one ``kb.add_many``; an SLRBusy from it left ``spin_once`` and stopped
``slr ros bridge`` with the burst's messages lost. Now the events are held and stored once
the store takes writes again (a condition that may pass: SLRUnavailable).

A real rclpy publisher node (the test's own), the bridge node in this process, and a real
second connection to the store file holding its write lock (BEGIN IMMEDIATE), as another
process would."""
from __future__ import annotations

import sqlite3
import time

import slr_sql
from slr_sql.ros.bridge import Bridge
import test_ros_bridge
from bridge_helpers import pose_topic, publish_poses, spinner

# the ROS bridge tests' fixtures: loopback-only discovery on a random domain, a topic prefix
# of this run, a real rclpy node of the test
ros_env, prefix, ros_node = test_ros_bridge.ros_env, test_ros_bridge.prefix, test_ros_bridge.ros_node
DEADLINE = test_ros_bridge.DEADLINE


def test_a_busy_store_holds_the_messages_and_stores_them_once_it_is_free(tmp_path, ros_node,
                                                                          prefix):
    node, executor = ros_node
    db = tmp_path / "live.db"
    mapping, publisher = pose_topic(node, prefix)
    lines: list[str] = []
    with slr_sql.open(db, busy_timeout=0.2, clock=slr_sql.ManualClock(105.0)) as kb:
        bridge = Bridge(kb, mapping, node_name="test_bridge", log=lines.append).start()
        try:
            spin_until = spinner(bridge, executor, lambda: f"log {lines}")

            spin_until(lambda: publisher.get_subscription_count() > 0)
            holder = sqlite3.connect(db, isolation_level=None)
            holder.execute("BEGIN IMMEDIATE")          # another writer holds the store
            try:
                publish_poses(publisher, 5)
                spin_until(lambda: bridge.stats.messages == 5 and bridge.held == 5)
                bridge.spin_once(0.01)                 # and again: still held, no error
            finally:
                holder.execute("ROLLBACK")
                holder.close()
            spin_until(lambda: bridge.stats.events == 5)
        finally:
            bridge.close()
        answers = kb.query("pose(F, X)^T")
    assert [(a["F"], a["X"], a["T"]) for a in answers] == \
        [("map", float(i), 100.0 + i) for i in range(5)]
    assert bridge.stats.rejected == 0
    held = [line for line in lines if "takes no writes now" in line]
    assert len(held) == 1, lines                        # said once, not at every retry
    assert "locked by another writer" in held[0] and "5 message(s) held" in held[0]
    assert "Traceback" not in "".join(lines)
    assert any("stored" in line for line in lines[lines.index(held[0]) + 1:]), lines


def test_held_counts_only_the_messages_whose_marks_are_still_unstored(postgres_url, ros_node,
                                                                       prefix):
    """A flush that stores its events but not its completeness marks (PostgreSQL: the event
    table takes writes, the meta table where marks live is locked) holds only the messages
    with a mark still to store: the pose messages are stored, the mark message is held."""
    import psycopg
    from std_msgs.msg import Header

    node, executor = ros_node
    mapping, poses = pose_topic(
        node, prefix, fully_updated=[{"topic": f"{prefix}/done", "types": ["pose/2"]}])
    done = node.create_publisher(Header, f"{prefix}/done", 10)
    lines: list[str] = []
    with slr_sql.open(postgres_url, busy_timeout=0.2, clock=slr_sql.ManualClock(105.0)) as kb:
        kb.add("pose(map, -1.0)^99")          # the pose table exists before it is locked
        bridge = Bridge(kb, mapping, node_name="test_bridge", log=lines.append).start()
        try:
            spin_until = spinner(bridge, executor, lambda: f"log {lines}")

            spin_until(lambda: poses.get_subscription_count() > 0
                       and done.get_subscription_count() > 0)
            with psycopg.connect(postgres_url) as meta, psycopg.connect(postgres_url) as table:
                meta.execute("LOCK TABLE slr.slr_meta IN SHARE MODE")     # marks wait
                table.execute("LOCK TABLE slr.pose IN SHARE MODE")        # and events too
                publish_poses(poses, 3)
                mark = Header()
                mark.stamp.sec = 103
                done.publish(mark)
                spin_until(lambda: bridge.stats.messages == 4 and bridge.held == 4)
                table.rollback()                  # the events are taken, the mark is not
                spin_until(lambda: bridge.stats.events == 3)
                assert bridge.held == 1 and bridge.stats.marks == 0
                bridge.spin_once(0.01)            # tried again: the mark still waits
                assert bridge.held == 1
                meta.rollback()
            spin_until(lambda: bridge.stats.marks == 1)
            assert bridge.held == 0
        finally:
            bridge.close()
        assert kb.complete_until("pose/2") == 103.0
        answers = kb.query("pose(map, X)^T, T >= 100")
    assert [(a["X"], a["T"]) for a in answers] == [(float(i), 100.0 + i) for i in range(3)]
    said = [line for line in lines if "takes no writes now" in line]
    assert len(said) == 1 and "4 message(s) held" in said[0], lines


def test_events_whose_adds_answer_was_lost_are_not_sent_again(ros_node, prefix):
    """A bridge storing into a served knowledge base whose server reads the add and dies
    without answering (a real TCP server of the test): the events may be stored, so they are
    not sent again (each would be stored twice), said and counted; nothing stays held."""
    from service_helpers import DroppingServer

    node, executor = ros_node
    mapping, publisher = pose_topic(node, prefix)
    lines: list[str] = []
    with DroppingServer() as server, slr_sql.connect(server.url) as kb:
        bridge = Bridge(kb, mapping, node_name="test_bridge", log=lines.append).start()
        try:
            spin_until = spinner(bridge, executor, lambda: f"log {lines}")

            spin_until(lambda: publisher.get_subscription_count() > 0)
            publish_poses(publisher, 3)
            spin_until(lambda: bridge.stats.messages == 3 and bridge.stats.uncertain == 3)
            sent = server.dropped
            for _ in range(5):                    # later spins send nothing again
                bridge.spin_once(0.01)
        finally:
            bridge.close()
    assert 1 <= sent <= 3 and server.dropped == sent, (sent, server.dropped)
    assert bridge.held == 0 and bridge.stats.events == 0
    lost = [line for line in lines if "may or may not be stored" in line]
    assert lost and all("not sent again" in line for line in lost), lines
    assert "Traceback" not in "".join(lines)


def test_of_an_add_many_in_several_requests_only_the_broken_ones_events_are_not_resent(
        ros_node, prefix):
    """A burst above the served store's body limit goes in several requests: the first is
    answered, the second's answer is lost, the rest were never sent. Only the second's
    events are given up (maybe stored); the rest are held and stored at the next spin."""
    from service_helpers import DroppingServer

    node, executor = ros_node
    mapping, publisher = pose_topic(node, prefix)
    lines: list[str] = []
    limits = b'{"status": "ok", "limits": {"max_body": 2048}}'
    with DroppingServer(limits, script="ad" + "a" * 40,
                        post_body=b'{"accepted": 1, "rejected": []}') as server, \
            slr_sql.connect(server.url) as kb:
        bridge = Bridge(kb, mapping, node_name="test_bridge", log=lines.append).start()
        try:
            deadline = time.monotonic() + DEADLINE
            spinner(bridge, executor, lambda: f"log {lines}")(
                lambda: publisher.get_subscription_count() > 0)
            publish_poses(publisher, 60)
            # all 60 taken before the first flush (spin_once stores what arrived so far)
            while bridge.stats.messages < 60:
                assert time.monotonic() < deadline, (bridge.stats, lines)
                bridge._executor.spin_once(timeout_sec=0.01)
            while bridge.stats.events + bridge.stats.uncertain < 60 or bridge.held:
                assert time.monotonic() < deadline, (bridge.stats, lines)
                bridge.spin_once(0.01)
        finally:
            bridge.close()
    stats = bridge.stats
    assert server.dropped == 1 and 0 < stats.uncertain < 60, (stats, lines)
    assert stats.events + stats.uncertain == 60, (stats, lines)
    lost = [line for line in lines if "may or may not be stored" in line]
    assert len(lost) == 1 and f"{stats.uncertain} event(s)" in lost[0], lines
    assert any("1 message(s) held" in line for line in lines), lines     # the unsent rest
    assert lines[-1] == "the store takes writes again: the held messages are stored", lines
