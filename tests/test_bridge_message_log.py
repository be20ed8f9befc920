"""The lines a ROS publisher's messages make the live bridge log (docs/printed_text.md): a
message whose event the store refuses is said in one line, escaped and bounded, and at most
BURST such lines a minute however many such messages come. A real rclpy publisher node and
the bridge node in this process, as tests/test_bridge_busy_store.py."""
from __future__ import annotations

import slr_sql
import test_ros_bridge
from bridge_helpers import pose_topic, spinner
from slr_sql.log_throttle import BURST
from slr_sql.printable import LOG_TEXT_LIMIT
from slr_sql.ros.bridge import Bridge

ros_env, prefix, ros_node = test_ros_bridge.ros_env, test_ros_bridge.prefix, test_ros_bridge.ros_node


def test_a_flood_of_refused_messages_logs_a_few_safe_lines(tmp_path, ros_node, prefix):
    from geometry_msgs.msg import PoseStamped

    node, executor = ros_node
    mapping, publisher = pose_topic(node, prefix)
    lines: list[str] = []
    sent = 3 * BURST
    with slr_sql.open(tmp_path / "live.db", clock=slr_sql.ManualClock(105.0)) as kb:
        bridge = Bridge(kb, mapping, node_name="test_bridge", log=lines.append).start()
        try:
            spin_until = spinner(bridge, executor, lambda: f"log {lines}")
            spin_until(lambda: publisher.get_subscription_count() > 0)
            for i in range(sent):
                msg = PoseStamped()
                msg.header.stamp.sec = 100 + i
                # a frame name with a forged line and an escape sequence; x NaN: refused
                msg.header.frame_id = "map\nwarning: forged\x1b]0;owned\x07" + "f" * 2000
                msg.pose.position.x = float("nan")
                publisher.publish(msg)
            spin_until(lambda: bridge.stats.messages == sent and bridge.stats.rejected == sent)
        finally:
            bridge.close()
    refused = [line for line in lines if "event rejected" in line]
    assert len(refused) == BURST, lines
    assert all("\n" not in line and "\x1b" not in line and len(line) < LOG_TEXT_LIMIT + 60
               for line in refused), refused
