"""A real ROS 2 node for crates/ros2/tests/interop.rs: rclpy of ROS 2 Jazzy over its default
middleware, rmw_fastrtps_cpp (eProsima Fast DDS), from PyPI's `ros-jazzy-*` wheels. No code
shared with omnitrack-ros2 or RustDDS.

It subscribes to --topic (geometry_msgs/msg/PoseWithCovarianceStamped) and /diagnostics with
ROS's default QoS (reliable, volatile, keep last 10) and prints each message as one JSON line,
with the ROS time of its arrival. It prints `ready` once its subscriptions exist, and when it
has --poses poses and --diagnostics diagnostic arrays it prints one `graph` line, what `ros2
node list` and `ros2 topic info -v` would show: the nodes, and the publishers of the pose topic
with their node and QoS. Exits 0 then, or 3 after --timeout-s.

    ROS_DOMAIN_ID=D python rclpy_peer.py [--topic /omnitrack/pose] [--poses N] [--diagnostics N]
        [--timeout-s S]
"""

import argparse
import json
import sys
import time

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseWithCovarianceStamped
from rclpy.qos import QoSProfile


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--topic", default="/omnitrack/pose")
    p.add_argument("--poses", type=int, default=10)
    p.add_argument("--diagnostics", type=int, default=2)
    p.add_argument("--timeout-s", type=float, default=60.0)
    a = p.parse_args()

    rclpy.init()
    node = rclpy.create_node("omnitrack_interop_listener")
    got = {"pose": 0, "diagnostics": 0}

    def now_ns():
        return node.get_clock().now().nanoseconds

    def on_pose(m):
        h, pc = m.header, m.pose
        line = {
            "topic": "pose",
            "received_ns": now_ns(),
            "stamp": [h.stamp.sec, h.stamp.nanosec],
            "frame_id": h.frame_id,
            "position": [pc.pose.position.x, pc.pose.position.y, pc.pose.position.z],
            "orientation": [pc.pose.orientation.x, pc.pose.orientation.y, pc.pose.orientation.z, pc.pose.orientation.w],
            "covariance": [float(c) for c in pc.covariance],
        }
        print(json.dumps(line), flush=True)
        got["pose"] += 1

    def on_diagnostics(m):
        line = {
            "topic": "diagnostics",
            "received_ns": now_ns(),
            "stamp": [m.header.stamp.sec, m.header.stamp.nanosec],
            "status": [
                {
                    "level": int.from_bytes(s.level, "little") if isinstance(s.level, bytes) else int(s.level),
                    "name": s.name,
                    "message": s.message,
                    "hardware_id": s.hardware_id,
                    "values": {kv.key: kv.value for kv in s.values},
                }
                for s in m.status
            ],
        }
        print(json.dumps(line), flush=True)
        got["diagnostics"] += 1

    node.create_subscription(PoseWithCovarianceStamped, a.topic, on_pose, QoSProfile(depth=10))
    node.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, QoSProfile(depth=10))
    print("ready", flush=True)

    deadline = time.monotonic() + a.timeout_s
    while got["pose"] < a.poses or got["diagnostics"] < a.diagnostics:
        if time.monotonic() > deadline:
            print(f"timeout: {got}", file=sys.stderr, flush=True)
            sys.exit(3)
        rclpy.spin_once(node, timeout_sec=0.05)

    publishers = [
        {
            "node": i.node_name,
            "namespace": i.node_namespace,
            "type": i.topic_type,
            "reliability": i.qos_profile.reliability.name,
            "durability": i.qos_profile.durability.name,
        }
        for i in node.get_publishers_info_by_topic(a.topic)
    ]
    nodes = sorted(f"{ns.rstrip('/')}/{n}" for n, ns in node.get_node_names_and_namespaces())
    print(json.dumps({"topic": "graph", "nodes": nodes, "publishers": publishers}), flush=True)
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
