"""A real rclpy client node for tests/test_ros_requests.py and benchmarks/bench_ros_requests.py.

It reads commands, one JSON object a line, on stdin and writes what happens, one JSON object
a line, on stdout:

* ``{"listen": TOPIC}`` — subscribe to std_msgs/String messages on TOPIC; each one received
  is printed as ``{"topic": TOPIC, "data": TEXT}``;
* ``{"pub": TOPIC, "type": "String" | "Float64" | "Header", "data": VALUE}`` — publish one
  message (a Header's ``data`` is its stamp in seconds; the publisher is made on first use);
* ``{"advertise": TOPIC, "type": ...}`` — make the publisher only;
* ``{"matched": TOPIC, "count": N}`` — print ``{"matched": TOPIC}`` once the publisher of
  TOPIC is matched by N subscriptions (N = 0: once nobody subscribes any more);
* ``{"publishers": TOPIC, "count": N}`` — print ``{"publishers": TOPIC}`` once the graph
  shows N publishers of TOPIC;
* ``{"rate": TOPIC, "hz": F, "texts": [...]}`` — publish the texts (String) at F per second,
  then print ``{"sent": K}`` (the benchmark);
* ``{"times": true}`` — print ``{"sent": {token: t}, "received": {token: t}}``: when each
  request was published by ``rate`` and when the reply carrying its token arrived
  (``time.perf_counter()`` of this process);
* ``{"exit": true}`` — stop.

It prints ``{"ready": true}`` when its node is up. Discovery stays on loopback: the caller
sets ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and a random ROS_DOMAIN_ID in its environment.
"""
from __future__ import annotations

import json
import queue
import sys
import threading
import time


def main() -> int:
    import rclpy
    from rclpy.node import Node
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import Float64, Header, String

    types = {"String": String, "Float64": Float64, "Header": Header}
    rclpy.init()
    node = Node("slr_test_client")
    qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.VOLATILE)
    publishers: dict = {}
    waits: list = []      # (kind, topic, count) conditions still to report
    out_lock = threading.Lock()

    def out(obj: dict) -> None:
        with out_lock:
            sys.stdout.write(json.dumps(obj) + "\n")
            sys.stdout.flush()

    def publisher(topic: str, kind: str):
        if topic not in publishers:
            publishers[topic] = node.create_publisher(types[kind], topic, qos)
        return publishers[topic]

    def message(kind: str, data):
        msg = types[kind]()
        if kind == "Header":
            sec = int(data // 1)
            msg.stamp.sec, msg.stamp.nanosec = sec, int(round((data - sec) * 1e9))
        else:
            msg.data = data
        return msg

    commands: queue.Queue = queue.Queue()
    sent: dict = {}
    received: dict = {}

    def heard(topic: str, msg) -> None:
        now = time.perf_counter()
        try:
            token = json.loads(msg.data).get("token")
        except (ValueError, AttributeError):
            token = None
        if isinstance(token, str) and token in sent:
            received.setdefault(token, now)
            return  # benchmark replies are timed, not printed
        out({"topic": topic, "data": msg.data})

    def read_commands() -> None:
        for line in sys.stdin:
            if line.strip():
                commands.put(json.loads(line))
        commands.put({"exit": True})

    threading.Thread(target=read_commands, daemon=True).start()
    out({"ready": True})
    while True:
        rclpy.spin_once(node, timeout_sec=0.005)
        for kind, topic, count in list(waits):
            if kind == "matched":
                done = publishers[topic].get_subscription_count() == count if count == 0 \
                    else publishers[topic].get_subscription_count() >= count
            else:
                done = node.count_publishers(topic) == count
            if done:
                waits.remove((kind, topic, count))
                out({kind: topic})
        while True:
            try:
                cmd = commands.get_nowait()
            except queue.Empty:
                break
            if "exit" in cmd:
                node.destroy_node()
                rclpy.try_shutdown()
                return 0
            if "listen" in cmd:
                topic = cmd["listen"]
                node.create_subscription(String, topic, lambda m, t=topic: heard(t, m), qos)
            elif "advertise" in cmd:
                publisher(cmd["advertise"], cmd.get("type", "String"))
            elif "pub" in cmd:
                kind = cmd.get("type", "String")
                publisher(cmd["pub"], kind).publish(message(kind, cmd["data"]))
            elif "matched" in cmd:
                publisher(cmd["matched"], cmd.get("type", "String"))
                waits.append(("matched", cmd["matched"], cmd.get("count", 1)))
            elif "publishers" in cmd:
                waits.append(("publishers", cmd["publishers"], cmd.get("count", 1)))
            elif "rate" in cmd:
                pub = publisher(cmd["rate"], "String")
                period = 1.0 / cmd["hz"]
                start = time.monotonic()
                for i, text in enumerate(cmd["texts"]):
                    while time.monotonic() < start + i * period:  # keep the rate, serve replies
                        rclpy.spin_once(node, timeout_sec=max(0.0, min(
                            0.002, start + i * period - time.monotonic())))
                    sent[json.loads(text)["token"]] = time.perf_counter()
                    pub.publish(String(data=text))
                out({"sent": len(cmd["texts"])})
            elif "times" in cmd:
                out({"sent": sent, "received": received})


if __name__ == "__main__":
    sys.exit(main())
