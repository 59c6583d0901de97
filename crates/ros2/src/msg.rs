//! The ROS 2 messages this crate speaks, field for field as their `.msg` files declare them, so
//! that serde's order is the CDR order ROS 2's DDS layer writes (plain CDR, little-endian).
//!
//! DDS matches a reader and a writer on the topic name and the type name: ROS 2 names the type
//! of `pkg/msg/Type` `pkg::msg::dds_::Type_` (ros2-client's [`MessageTypeName`] makes that name),
//! so a subscriber in any DDS implementation declares the same name and the same fields
//! (`crates/ros2/tests/cyclonedds_peer.py` does, in Cyclone DDS's Python IDL).

use ros2_client::MessageTypeName;
use serde::de::{SeqAccess, Visitor};
use serde::ser::SerializeTuple;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// `builtin_interfaces/Time`: seconds and nanoseconds since the Unix epoch on ROS's clock (the
/// system clock when no simulated time is used).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Time {
    pub sec: i32,
    pub nanosec: u32,
}

impl Time {
    /// The time `ns` nanoseconds after the epoch; `None` before it or past `i32` seconds (2038).
    pub fn from_ns(ns: i64) -> Option<Time> {
        let sec = i32::try_from(ns.div_euclid(1_000_000_000)).ok()?;
        (ns >= 0).then_some(Time {
            sec,
            nanosec: ns.rem_euclid(1_000_000_000) as u32,
        })
    }

    /// Nanoseconds since the epoch.
    pub fn ns(&self) -> i64 {
        self.sec as i64 * 1_000_000_000 + self.nanosec as i64
    }
}

/// `std_msgs/Header`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Header {
    pub stamp: Time,
    pub frame_id: String,
}

/// `geometry_msgs/Point`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Point {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

/// `geometry_msgs/Vector3`.
pub type Vector3 = Point;

/// `geometry_msgs/Quaternion` (ROS's order: x, y, z, w).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub w: f64,
}

impl Default for Quaternion {
    fn default() -> Self {
        Quaternion {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        }
    }
}

/// `geometry_msgs/Pose`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Pose {
    pub position: Point,
    pub orientation: Quaternion,
}

/// `float64[36]`: a fixed-size array, written as 36 doubles without a length (serde derives
/// arrays up to 32 only).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Covariance(pub [f64; 36]);

impl Default for Covariance {
    fn default() -> Self {
        Covariance([0.0; 36])
    }
}

impl Serialize for Covariance {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut t = serializer.serialize_tuple(36)?;
        for v in &self.0 {
            t.serialize_element(v)?;
        }
        t.end()
    }
}

impl<'de> Deserialize<'de> for Covariance {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Doubles;
        impl<'de> Visitor<'de> for Doubles {
            type Value = Covariance;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("36 doubles")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Covariance, A::Error> {
                let mut c = [0.0; 36];
                for (i, v) in c.iter_mut().enumerate() {
                    *v = seq
                        .next_element()?
                        .ok_or_else(|| serde::de::Error::invalid_length(i, &self))?;
                }
                Ok(Covariance(c))
            }
        }
        deserializer.deserialize_tuple(36, Doubles)
    }
}

/// `geometry_msgs/PoseWithCovariance`: the covariance row-major over x, y, z and the rotations
/// about the fixed (header frame's) x, y, z axes.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct PoseWithCovariance {
    pub pose: Pose,
    pub covariance: Covariance,
}

/// `geometry_msgs/PoseWithCovarianceStamped`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct PoseWithCovarianceStamped {
    pub header: Header,
    pub pose: PoseWithCovariance,
}

/// `geometry_msgs/Transform`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Transform {
    pub translation: Vector3,
    pub rotation: Quaternion,
}

/// `geometry_msgs/TransformStamped`: `child_frame_id`'s pose in `header.frame_id`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct TransformStamped {
    pub header: Header,
    pub child_frame_id: String,
    pub transform: Transform,
}

/// `tf2_msgs/TFMessage`, the message of `/tf` and `/tf_static`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct TfMessage {
    pub transforms: Vec<TransformStamped>,
}

/// `diagnostic_msgs/KeyValue`.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct KeyValue {
    pub key: String,
    pub value: String,
}

/// `diagnostic_msgs/DiagnosticStatus` (`level` is a `byte`: [`OK`], [`WARN`], [`ERROR`],
/// [`STALE`]).
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct DiagnosticStatus {
    pub level: u8,
    pub name: String,
    pub message: String,
    pub hardware_id: String,
    pub values: Vec<KeyValue>,
}

/// `DiagnosticStatus.level`: all is well.
pub const OK: u8 = 0;
/// `DiagnosticStatus.level`: working, but not as it should.
pub const WARN: u8 = 1;
/// `DiagnosticStatus.level`: not working.
pub const ERROR: u8 = 2;
/// `DiagnosticStatus.level`: no news.
pub const STALE: u8 = 3;

/// `diagnostic_msgs/DiagnosticArray`, the message of `/diagnostics`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct DiagnosticArray {
    pub header: Header,
    pub status: Vec<DiagnosticStatus>,
}

/// The ROS type names of the messages above.
pub fn pose_type() -> MessageTypeName {
    MessageTypeName::new("geometry_msgs", "PoseWithCovarianceStamped")
}

/// `tf2_msgs/TFMessage`.
pub fn tf_type() -> MessageTypeName {
    MessageTypeName::new("tf2_msgs", "TFMessage")
}

/// `diagnostic_msgs/DiagnosticArray`.
pub fn diagnostics_type() -> MessageTypeName {
    MessageTypeName::new("diagnostic_msgs", "DiagnosticArray")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_time_splits_nanoseconds_and_refuses_what_ros_cannot_hold() {
        let t = Time::from_ns(1_700_000_001_250_000_007).unwrap();
        assert_eq!((t.sec, t.nanosec), (1_700_000_001, 250_000_007));
        assert_eq!(t.ns(), 1_700_000_001_250_000_007);
        assert_eq!(Time::from_ns(-1), None);
        assert_eq!(Time::from_ns((i32::MAX as i64 + 1) * 1_000_000_000), None);
    }

    #[test]
    fn the_dds_type_names_are_ros_2s() {
        assert_eq!(
            pose_type().dds_msg_type(),
            "geometry_msgs::msg::dds_::PoseWithCovarianceStamped_"
        );
        assert_eq!(tf_type().dds_msg_type(), "tf2_msgs::msg::dds_::TFMessage_");
        assert_eq!(
            diagnostics_type().dds_msg_type(),
            "diagnostic_msgs::msg::dds_::DiagnosticArray_"
        );
    }
}
