//! What the publisher is asked to do, checked: the command line's options as values ([`Options`],
//! its QoS, frames and `/tf` mode) and the checks of the names, frame ids, domain id and network
//! interfaces a user or ROS's environment gives, each refusing bad input in one line that names it.
//!
//! In: text from the command line and the environment. Out: [`Options`] for `publish` and
//! `check`, or a [`Ros2Error::Usage`].

use crate::clock::CaptureClock;
use crate::frames::Iso;
use crate::{Ros2Error, DIAGNOSTICS_TOPIC, MAX_DOMAIN_ID, POSE_TOPIC};
use ros2_client::qos::{Durability, History, Reliability, WhenFull};
use ros2_client::{Name, QosProfile};
use std::net::IpAddr;
use std::time::Duration;

/// What goes on `/tf`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum TfMode {
    /// Nothing: the pose topic only (a localisation filter such as robot_localization fuses it
    /// and publishes the transforms).
    None,
    /// `map → odom` from the robot's `odom → base_link` on /tf at the pose's stamp (REP-105).
    MapOdom,
    /// `map → base_link`, for a rig with no odometry (a helmet); refused when /tf shows another
    /// parent of base_link.
    MapBase,
}

/// Delivery of the pose topic.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ReliabilityKind {
    /// Lost samples are sent again (ROS's default; every subscriber can match it).
    Reliable,
    /// No resending; only best-effort subscribers match it (a reliable one does not).
    BestEffort,
}

/// What a late subscriber gets.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum DurabilityKind {
    /// Nothing sent before it joined.
    Volatile,
    /// The last `depth` poses at once ("latched").
    TransientLocal,
}

/// QoS of the pose topic.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PoseQos {
    pub reliability: ReliabilityKind,
    pub durability: DurabilityKind,
    /// Keep-last history depth (≥ 1).
    pub depth: usize,
}

impl Default for PoseQos {
    /// ROS 2's default profile: reliable, volatile, keep last 10.
    fn default() -> Self {
        PoseQos {
            reliability: ReliabilityKind::Reliable,
            durability: DurabilityKind::Volatile,
            depth: 10,
        }
    }
}

impl PoseQos {
    /// The profile: reliable writes wait at most 10 ms for a slow reader's window, then the pose
    /// is counted as not delivered rather than delaying the next.
    pub fn profile(&self) -> QosProfile {
        let reliability = match self.reliability {
            ReliabilityKind::Reliable => Reliability::Reliable {
                when_full: WhenFull::Wait(Duration::from_millis(10)),
            },
            ReliabilityKind::BestEffort => Reliability::BestEffort,
        };
        let durability = match self.durability {
            DurabilityKind::Volatile => Durability::Volatile,
            DurabilityKind::TransientLocal => Durability::TransientLocal,
        };
        QosProfile::publisher_default()
            .reliability(reliability)
            .durability(durability)
            .history(History::KeepLast { depth: self.depth })
    }
}

/// The frames of REP-105 and how the rig sits on the robot.
#[derive(Debug, Clone, PartialEq)]
pub struct Frames {
    pub map: String,
    pub odom: String,
    pub base: String,
    /// `T_base_rig`: the rig's pose in `base` (identity when the rig frame is `base`).
    pub base_rig: Iso,
    pub tf: TfMode,
    /// How far past the newest odometry a pose's stamp may be and still use it.
    pub odom_tolerance: Duration,
    /// How much later than its pose a transform on /tf is stamped (AMCL's `transform_tolerance`):
    /// a lookup at the current time then finds it instead of extrapolating. The transform is the
    /// one at the pose's stamp either way.
    pub transform_tolerance: Duration,
}

impl Default for Frames {
    fn default() -> Self {
        Frames {
            map: "map".into(),
            odom: "odom".into(),
            base: "base_link".into(),
            base_rig: Iso::identity(),
            tf: TfMode::None,
            odom_tolerance: Duration::from_millis(100),
            transform_tolerance: Duration::ZERO,
        }
    }
}

/// Everything `publish` needs.
#[derive(Debug, Clone)]
pub struct Options {
    pub pose_service: String,
    pub status_service: String,
    /// ROS name of the pose topic (relative names are under the root namespace).
    pub topic: String,
    pub diagnostics_topic: String,
    pub frames: Frames,
    pub qos: PoseQos,
    pub capture_clock: CaptureClock,
    pub domain_id: u16,
    /// Local addresses DDS may use (multicast joins, sends, announced locators); all when empty.
    pub interfaces: Vec<IpAddr>,
    /// The ROS node's name.
    pub node_name: String,
    /// Stop after publishing this many poses.
    pub count: Option<u64>,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            pose_service: omnitrack_io::publish::POSE_SERVICE.into(),
            status_service: omnitrack_io::publish::STATUS_SERVICE.into(),
            topic: POSE_TOPIC.into(),
            diagnostics_topic: DIAGNOSTICS_TOPIC.into(),
            frames: Frames::default(),
            qos: PoseQos::default(),
            capture_clock: CaptureClock::Monotonic,
            domain_id: 0,
            interfaces: Vec::new(),
            node_name: "omnitrack".into(),
            count: None,
        }
    }
}

/// A ROS name (topic) checked, with a message saying what is wrong in it.
pub fn ros_name(option: &str, s: &str) -> Result<Name, Ros2Error> {
    let why = |w: String| Ros2Error::Usage(format!("{option} '{s}' is not a ROS topic name: {w}"));
    if s.is_empty() {
        return Err(why("it is empty".into()));
    }
    const RULE: &str = "letters, digits and single underscores, each part starting with a letter or \
                        an underscore, parts separated by one '/'";
    if let Some(c) = s
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || *c == '_' || *c == '/'))
    {
        return Err(why(format!("{c:?} is not allowed ({RULE})")));
    }
    // The node lives in the root namespace, so a relative name is the absolute one. Resolved
    // here: ros2-client 0.12 maps a relative name of a node in "/" to "rt//name" (the namespace's
    // slash and its own), a DDS topic no other ROS 2 node subscribes to; the interop test caught it.
    let absolute = if s.starts_with('/') {
        s.to_string()
    } else {
        format!("/{s}")
    };
    Name::parse(&absolute).map_err(|e| {
        why(match e {
            ros2_client::names::NameError::Empty => "a part of it is empty".into(),
            ros2_client::names::NameError::BadChar(_) => format!("a part breaks the rule ({RULE})"),
            ros2_client::names::NameError::BadSlash(..) => "it has an empty part ('//' or a trailing '/')".into(),
        })
    })
}

/// A frame id checked: tf2 takes any non-empty text, but one with spaces or a leading '/' is a
/// mistake every time.
pub fn frame_id(option: &str, s: &str) -> Result<String, Ros2Error> {
    let bad = |w: &str| Err(Ros2Error::Usage(format!("{option} '{s}' is not a frame id: {w}")));
    if s.is_empty() {
        bad("it is empty")
    } else if s.starts_with('/') {
        bad("ROS 2 frame ids have no leading '/'")
    } else if s.chars().any(|c| c.is_whitespace() || c.is_control()) {
        bad("it has white space")
    } else {
        Ok(s.to_string())
    }
}

/// The `ROS_DOMAIN_ID` as DDS takes it, or why not; empty is 0, as ROS reads an empty variable.
pub fn domain_id(s: &str) -> Result<u16, String> {
    if s.trim().is_empty() {
        return Ok(0);
    }
    match s.trim().parse::<u16>() {
        Ok(d) if d <= MAX_DOMAIN_ID => Ok(d),
        _ => Err(format!("'{s}' is not a ROS domain id (0 to {MAX_DOMAIN_ID})")),
    }
}

/// The local addresses DDS may use: those given (`--interface`), else, as ROS 2 reads its
/// environment, only the loopback for `ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST` (Jazzy) or
/// `ROS_LOCALHOST_ONLY=1` (before), and every interface otherwise (`SUBNET`, ROS's default).
/// `OFF` (static peers only) is refused: this publisher finds its peers by discovery.
pub fn interfaces(
    given: Vec<IpAddr>,
    discovery_range: Option<&str>,
    localhost_only: Option<&str>,
) -> Result<Vec<IpAddr>, Ros2Error> {
    if !given.is_empty() {
        return Ok(given);
    }
    let loopback = vec![IpAddr::from([127, 0, 0, 1])];
    match discovery_range.map(str::trim) {
        Some("LOCALHOST") => Ok(loopback),
        Some("OFF") => Err(Ros2Error::Usage(
            "ROS_AUTOMATIC_DISCOVERY_RANGE=OFF (static peers only) is not supported: unset it, or \
             set LOCALHOST or SUBNET"
                .into(),
        )),
        Some("SUBNET" | "SYSTEM_DEFAULT" | "") | None if localhost_only.map(str::trim) == Some("1") => Ok(loopback),
        Some("SUBNET" | "SYSTEM_DEFAULT" | "") | None => Ok(Vec::new()),
        Some(other) => Err(Ros2Error::Usage(format!(
            "ROS_AUTOMATIC_DISCOVERY_RANGE='{other}' is none of LOCALHOST, SUBNET, OFF, SYSTEM_DEFAULT"
        ))),
    }
}
