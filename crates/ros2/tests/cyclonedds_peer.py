"""A ROS 2 peer in another DDS implementation (Eclipse Cyclone DDS, PyPI `cyclonedds`), for
crates/ros2/tests/interop.rs: no ROS, no RustDDS, no code shared with omnitrack-ros2.

It declares the ROS 2 messages' IDL types by their DDS names (`geometry_msgs::msg::dds_::
PoseWithCovarianceStamped_`, ...), subscribes to `rt/<topic>`, `rt/tf` and `rt/diagnostics`,
and prints every sample it takes as one JSON line, each field as Cyclone decoded it, with the
system time of its arrival. With --odom it is the robot too: it publishes `odom -> base_link` on
`rt/tf` at 100 Hz, the odometry a known function of the stamp (odom(), below), stamped
--odom-lead-s ahead so that every pose's stamp lies between two samples. It prints `ready` once
its entities exist, and exits after --poses pose samples, --diagnostics diagnostic samples and
--transforms transforms other than its own, or after --timeout-s (exit code 3).

    python cyclonedds_peer.py --domain D --topic omnitrack/pose [--poses N] [--diagnostics N]
        [--transforms N] [--odom T0_NS] [--transient-local] [--depth N] [--settle-s S] [--timeout-s S]
"""

import argparse
import json
import math
import sys
import time
from dataclasses import dataclass

import cyclonedds.idl.annotations as annotate
from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import array, float64, int32, sequence, uint8, uint32
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration


@dataclass
@annotate.final
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32
    nanosec: uint32


@dataclass
@annotate.final
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time
    frame_id: str


@dataclass
@annotate.final
class Point(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    x: float64
    y: float64
    z: float64


@dataclass
@annotate.final
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: float64
    y: float64
    z: float64


@dataclass
@annotate.final
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: float64
    y: float64
    z: float64
    w: float64


@dataclass
@annotate.final
class Pose(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    position: Point
    orientation: Quaternion


@dataclass
@annotate.final
class PoseWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovariance_"):
    pose: Pose
    covariance: array[float64, 36]


@dataclass
@annotate.final
class PoseWithCovarianceStamped(IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovarianceStamped_"):
    header: Header
    pose: PoseWithCovariance


@dataclass
@annotate.final
class Transform(IdlStruct, typename="geometry_msgs::msg::dds_::Transform_"):
    translation: Vector3
    rotation: Quaternion


@dataclass
@annotate.final
class TransformStamped(IdlStruct, typename="geometry_msgs::msg::dds_::TransformStamped_"):
    header: Header
    child_frame_id: str
    transform: Transform


@dataclass
@annotate.final
class TFMessage(IdlStruct, typename="tf2_msgs::msg::dds_::TFMessage_"):
    transforms: sequence[TransformStamped]


@dataclass
@annotate.final
class KeyValue(IdlStruct, typename="diagnostic_msgs::msg::dds_::KeyValue_"):
    key: str
    value: str


@dataclass
@annotate.final
class DiagnosticStatus(IdlStruct, typename="diagnostic_msgs::msg::dds_::DiagnosticStatus_"):
    level: uint8
    name: str
    message: str
    hardware_id: str
    values: sequence[KeyValue]


@dataclass
@annotate.final
class DiagnosticArray(IdlStruct, typename="diagnostic_msgs::msg::dds_::DiagnosticArray_"):
    header: Header
    status: sequence[DiagnosticStatus]


def odom(t_ns, t0_ns):
    """The robot's odom -> base_link at ROS time t_ns: 0.4 m/s along x, 0.1 m/s along y, turning
    0.05 rad/s about z, from the identity at t0_ns. Returns (x, y, z), (qx, qy, qz, qw)."""
    s = (t_ns - t0_ns) / 1e9
    yaw = 0.05 * s
    return (0.4 * s, 0.1 * s, 0.0), (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))


def stamp_of(t_ns):
    return Time(sec=t_ns // 1_000_000_000, nanosec=t_ns % 1_000_000_000)


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--domain", type=int, required=True)
    p.add_argument("--topic", default="omnitrack/pose")
    p.add_argument("--poses", type=int, default=0)
    p.add_argument("--diagnostics", type=int, default=0)
    p.add_argument("--transforms", type=int, default=0, help="map -> odom transforms to wait for")
    p.add_argument("--odom", type=int, metavar="T0_NS")
    p.add_argument("--odom-lead-s", type=float, default=0.5)
    p.add_argument("--transient-local", action="store_true")
    p.add_argument("--depth", type=int, default=1000, help="the readers' keep-last depth")
    p.add_argument("--settle-s", type=float, default=0.0, help="wait this long, then until the pose cache is still")
    p.add_argument("--timeout-s", type=float, default=60.0)
    a = p.parse_args()

    dp = DomainParticipant(a.domain)
    durability = Policy.Durability.TransientLocal if a.transient_local else Policy.Durability.Volatile
    reader_qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), durability, Policy.History.KeepLast(a.depth))
    pose_reader = DataReader(dp, Topic(dp, "rt/" + a.topic.lstrip("/"), PoseWithCovarianceStamped), qos=reader_qos)
    diag_reader = DataReader(dp, Topic(dp, "rt/diagnostics", DiagnosticArray), qos=reader_qos)
    tf_topic = Topic(dp, "rt/tf", TFMessage)
    tf_reader = DataReader(dp, tf_topic, qos=Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(1000)))
    tf_writer = None
    if a.odom is not None:
        tf_qos = Qos(
            Policy.Reliability.Reliable(duration(seconds=1)),
            Policy.Durability.Volatile,
            Policy.History.KeepLast(100),
        )
        tf_writer = DataWriter(dp, tf_topic, qos=tf_qos)
    print("ready", flush=True)
    if a.settle_s > 0:
        # At least --settle-s, then until the pose reader's cache (its last --depth samples) has
        # stopped changing for half a second: what a late joiner's history holds once the
        # writer's resend is over.
        time.sleep(a.settle_s)
        seen, stable_since, give_up = None, time.monotonic(), time.monotonic() + a.timeout_s
        while time.monotonic() - stable_since < 0.5 and time.monotonic() < give_up:
            now = [(m.header.stamp.sec, m.header.stamp.nanosec) for m in pose_reader.read(N=a.depth)]
            if now != seen or not now:
                seen, stable_since = now, time.monotonic()
            time.sleep(0.05)

    poses = diagnostics = transforms = 0
    deadline = time.monotonic() + a.timeout_s
    next_odom = time.monotonic()
    while poses < a.poses or diagnostics < a.diagnostics or transforms < a.transforms:
        if time.monotonic() > deadline:
            print(f"timeout: {poses} poses, {diagnostics} diagnostics, {transforms} transforms", file=sys.stderr, flush=True)
            sys.exit(3)
        if tf_writer is not None and time.monotonic() >= next_odom:
            next_odom += 0.01
            t = time.time_ns() + int(a.odom_lead_s * 1e9)
            (x, y, z), (qx, qy, qz, qw) = odom(t, a.odom)
            tf_writer.write(
                TFMessage(
                    transforms=[
                        TransformStamped(
                            header=Header(stamp=stamp_of(t), frame_id="odom"),
                            child_frame_id="base_link",
                            transform=Transform(
                                translation=Vector3(x=x, y=y, z=z),
                                rotation=Quaternion(x=qx, y=qy, z=qz, w=qw),
                            ),
                        )
                    ]
                )
            )
        for m in pose_reader.take(N=100):
            h, pc = m.header, m.pose
            line = {
                "topic": "pose",
                "received_ns": time.time_ns(),
                "stamp": [h.stamp.sec, h.stamp.nanosec],
                "frame_id": h.frame_id,
                "position": [pc.pose.position.x, pc.pose.position.y, pc.pose.position.z],
                "orientation": [pc.pose.orientation.x, pc.pose.orientation.y, pc.pose.orientation.z, pc.pose.orientation.w],
                "covariance": list(pc.covariance),
            }
            print(json.dumps(line), flush=True)
            poses += 1
        for m in diag_reader.take(N=100):
            line = {
                "topic": "diagnostics",
                "received_ns": time.time_ns(),
                "stamp": [m.header.stamp.sec, m.header.stamp.nanosec],
                "status": [
                    {
                        "level": s.level,
                        "name": s.name,
                        "message": s.message,
                        "hardware_id": s.hardware_id,
                        "values": {kv.key: kv.value for kv in s.values},
                    }
                    for s in m.status
                ],
            }
            print(json.dumps(line), flush=True)
            diagnostics += 1
        for m in tf_reader.take(N=1000):
            for t in m.transforms:
                if t.header.frame_id == "odom":
                    continue  # our own odometry
                tr, r = t.transform.translation, t.transform.rotation
                line = {
                    "topic": "tf",
                    "stamp": [t.header.stamp.sec, t.header.stamp.nanosec],
                    "parent": t.header.frame_id,
                    "child": t.child_frame_id,
                    "translation": [tr.x, tr.y, tr.z],
                    "rotation": [r.x, r.y, r.z, r.w],
                }
                print(json.dumps(line), flush=True)
                transforms += 1
        time.sleep(0.002)


if __name__ == "__main__":
    main()
