"""ROS 2 bridge for omnitrack: republishes the tracker's poses for ROS 2 nodes.

Subscribes to the iceoryx2 service `omnitrack/pose` (the same zero-copy `PoseSample` as
tools/examples/listen_pose.py) and publishes, for every sample whose status is `tracking`:

- `geometry_msgs/msg/PoseWithCovarianceStamped` on the topic `omnitrack/pose` (default), in the
  frame `map`: the rig's pose `T_world_rig`, its 6x6 covariance copied as it is (omnitrack's
  order x, y, z, rotation about the world's x, y, z axes is ROS's fixed-axis order);
- the transform `map -> base_link` on /tf (REP-105: `map` is the building model's frame, z up;
  `base_link` is the rig frame, x forward, y left, z up, as omnitrack's).

Samples while initialising or lost carry the last good pose and are not republished: a ROS
consumer would take a stale pose for a current one. Stamps are the frame's capture time.

Needs a ROS 2 installation (rclpy, geometry_msgs, tf2_ros) and the iceoryx2 Python bindings
(`pip install iceoryx2==0.10.0`, as for listen_pose.py). Run:

    source /opt/ros/jazzy/setup.bash
    python3 tools/ros2/omnitrack_ros2.py [--service omnitrack/pose] [--topic omnitrack/pose]
        [--map-frame map] [--base-frame base_link]

The conversion itself (`to_ros`) needs neither and is tested by tools/ros2/test_omnitrack_ros2.py.
"""

import argparse
import math
import sys

TRACKING = 1


def to_ros(sample, map_frame="map", base_frame="base_link"):
    """The ROS 2 messages' contents for one PoseSample-like object, or None when not tracking.

    Returns a dict: `stamp` (sec, nanosec), `frame_id`, `child_frame_id`, `position` (x, y, z),
    `orientation` (x, y, z, w: ROS's order), `covariance` (36 floats, row-major).
    """
    if sample.status != TRACKING:
        return None
    q = list(sample.rotation_wxyz)
    norm = math.sqrt(sum(c * c for c in q))
    if not (norm > 0.0 and all(math.isfinite(c) for c in q)):
        return None
    w, x, y, z = (c / norm for c in q)
    return {
        "stamp": (sample.timestamp_ns // 1_000_000_000, sample.timestamp_ns % 1_000_000_000),
        "frame_id": map_frame,
        "child_frame_id": base_frame,
        "position": tuple(float(v) for v in sample.position_m),
        "orientation": (x, y, z, w),
        "covariance": [float(v) for v in sample.covariance],
    }


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--service", default="omnitrack/pose")
    parser.add_argument("--topic", default="omnitrack/pose")
    parser.add_argument("--map-frame", default="map")
    parser.add_argument("--base-frame", default="base_link")
    args = parser.parse_args(argv)

    import rclpy
    from geometry_msgs.msg import PoseWithCovarianceStamped, TransformStamped
    from tf2_ros import TransformBroadcaster
    import iceoryx2 as iox2

    sys.path.insert(0, __file__.rsplit("/", 2)[0] + "/examples")
    from listen_pose import subscribe  # the C layout and the service settings, defined once

    rclpy.init()
    node = rclpy.create_node("omnitrack_bridge")
    publisher = node.create_publisher(PoseWithCovarianceStamped, args.topic, 10)
    broadcaster = TransformBroadcaster(node)
    _iox_node, subscriber, listener = subscribe(args.service)

    while rclpy.ok():
        sample = subscriber.receive()
        if sample is None:
            # Sleep on the publisher's event, not a spin: a pose comes at the camera's rate.
            listener.timed_wait(iox2.Duration.from_millis(100))
            rclpy.spin_once(node, timeout_sec=0.0)
            continue
        m = to_ros(sample.payload().contents, args.map_frame, args.base_frame)
        if m is None:
            continue
        msg = PoseWithCovarianceStamped()
        msg.header.stamp.sec, msg.header.stamp.nanosec = m["stamp"]
        msg.header.frame_id = m["frame_id"]
        p, o = msg.pose.pose.position, msg.pose.pose.orientation
        p.x, p.y, p.z = m["position"]
        o.x, o.y, o.z, o.w = m["orientation"]
        msg.pose.covariance = m["covariance"]
        publisher.publish(msg)
        tf = TransformStamped()
        tf.header = msg.header
        tf.child_frame_id = m["child_frame_id"]
        t, r = tf.transform.translation, tf.transform.rotation
        t.x, t.y, t.z = m["position"]
        r.x, r.y, r.z, r.w = m["orientation"]
        broadcaster.sendTransform(tf)


if __name__ == "__main__":
    main()
