"""The ROS 2 bridge's conversion, without ROS: `python3 -m unittest discover -s tools/ros2`."""

import math
import unittest
from types import SimpleNamespace

from omnitrack_ros2 import to_ros


def sample(status=1, wxyz=(math.cos(0.35), 0.0, 0.0, math.sin(0.35))):
    return SimpleNamespace(
        status=status,
        timestamp_ns=1_700_000_001_250_000_000,
        position_m=(1.5, -2.0, 1.25),
        rotation_wxyz=wxyz,
        covariance=[float(i) for i in range(36)],
    )


class ToRos(unittest.TestCase):
    def test_a_tracking_sample_becomes_the_messages(self):
        m = to_ros(sample())
        self.assertEqual(m["stamp"], (1_700_000_001, 250_000_000))
        self.assertEqual((m["frame_id"], m["child_frame_id"]), ("map", "base_link"))
        self.assertEqual(m["position"], (1.5, -2.0, 1.25))
        # ROS orders x, y, z, w; a 0.7 rad yaw about z.
        x, y, z, w = m["orientation"]
        self.assertAlmostEqual(z, math.sin(0.35))
        self.assertAlmostEqual(w, math.cos(0.35))
        self.assertEqual((x, y), (0.0, 0.0))
        # Row-major over x, y, z and rotations about the fixed x, y, z axes: copied as it is.
        self.assertEqual(m["covariance"], [float(i) for i in range(36)])
        self.assertEqual(m["covariance"][6 * 3 + 5], 23.0)

    def test_frames_can_be_renamed(self):
        m = to_ros(sample(), "building", "rig")
        self.assertEqual((m["frame_id"], m["child_frame_id"]), ("building", "rig"))

    def test_stale_and_broken_samples_are_not_republished(self):
        self.assertIsNone(to_ros(sample(status=0)))  # initialising
        self.assertIsNone(to_ros(sample(status=2)))  # lost: the last good pose, not a current one
        self.assertIsNone(to_ros(sample(wxyz=(0.0, 0.0, 0.0, 0.0))))
        self.assertIsNone(to_ros(sample(wxyz=(float("nan"), 0.0, 0.0, 1.0))))

    def test_an_unnormalised_quaternion_is_normalised(self):
        x, y, z, w = to_ros(sample(wxyz=(2.0, 0.0, 0.0, 0.0)))["orientation"]
        self.assertEqual((x, y, z, w), (0.0, 0.0, 0.0, 1.0))


if __name__ == "__main__":
    unittest.main()
