"""What the tests of a live ROS Bridge share: a pose topic mapped to events, poses
published on it, and spinning the bridge and the test's node until a condition holds."""
from __future__ import annotations

import time
from typing import Any, Callable

from slr_sql.ros.mapping import Mapping, mapping_from_dict

DEADLINE = 30.0


def pose_topic(node: Any, prefix: str, **more: Any) -> tuple[Mapping, Any]:
    """The mapping of ``{prefix}/pose`` (PoseStamped) to ``pose(Frame, X)^T`` (and ``more``
    of the mapping's fields), and a publisher on it."""
    from geometry_msgs.msg import PoseStamped

    mapping = mapping_from_dict({"tf": False, "topics": {f"{prefix}/pose": {
        "event": "pose", "args": ["header.frame_id", "pose.position.x"]}}, **more})
    return mapping, node.create_publisher(PoseStamped, f"{prefix}/pose", 100)


def publish_poses(publisher: Any, count: int) -> None:
    """``count`` poses in frame map: the i-th at x = i, stamped 100 + i seconds."""
    from geometry_msgs.msg import PoseStamped

    for i in range(count):
        msg = PoseStamped()
        msg.header.stamp.sec = 100 + i
        msg.header.frame_id = "map"
        msg.pose.position.x = float(i)
        publisher.publish(msg)


def spinner(bridge: Any, executor: Any, said: Callable[[], str],
            seconds: float = DEADLINE) -> Callable[[Callable[[], bool]], None]:
    """``spin_until(condition)``: spin the bridge and the test's executor until ``condition()``
    holds, failing with ``said()`` once ``seconds`` (from now) have passed."""
    deadline = time.monotonic() + seconds

    def spin_until(condition: Callable[[], bool]) -> None:
        while not condition():
            assert time.monotonic() < deadline, f"timed out; {said()}"
            bridge.spin_once(0.01)
            executor.spin_once(timeout_sec=0.01)
    return spin_until
