//! Poses to ROS 2 without a ROS installation and without a bridge process of ROS's own: the
//! tracker's iceoryx2 services published as ROS 2 topics over DDS (RustDDS, through
//! ros2-client), the wire protocol every ROS 2 node speaks.
//!
//! In: the local pose service `omnitrack/pose` and status service `omnitrack/status` (zero-copy
//! subscribers, like any other local consumer), and where asked the robot's `/tf`. Out:
//!
//! - `geometry_msgs/msg/PoseWithCovarianceStamped` on a topic (default `omnitrack/pose`, DDS
//!   topic `rt/omnitrack/pose`) for every pose whose status is tracking: `header.frame_id` the
//!   model's frame (`map`), the stamp in ROS time ([`clock`]), the pose of `base_link` and its
//!   covariance in ROS's order ([`frames`]);
//! - on `/tf`, by `--tf`: nothing (the default), `map → odom` computed from the robot's own
//!   `odom → base_link` at the pose's stamp (REP-105), or `map → base_link` for a rig that has
//!   no odometry (refused as soon as another parent of `base_link` shows on `/tf`);
//! - `diagnostic_msgs/msg/DiagnosticArray` on `/diagnostics` from every status sample
//!   ([`diag`]), and a STALE one when the status stops.
//!
//! QoS of the pose topic is the caller's ([`PoseQos`]): reliable or best effort, the history
//! depth, volatile or transient local (a late subscriber then gets the last `depth` poses; see
//! docs/interfaces.md for RustDDS's history trim). `/tf` and `/diagnostics` use what tf2 and the
//! diagnostic updater use. ros2-client announces the node (`/omnitrack`) in ROS's discovery
//! information (`ros_discovery_info`, what `ros2 node list` reads: an rclpy node of the interop
//! test sees it), with neither rosout nor parameter services. Like `omnitrack-link`, it is not on the device path: it allocates per message and
//! runs beside the tracker, which never waits for it.

pub mod clock;
pub mod diag;
pub mod frames;
pub mod msg;
mod options;

pub use options::{
    domain_id, frame_id, interfaces, ros_name, DurabilityKind, Frames, Options, PoseQos, ReliabilityKind, TfMode,
};

use clock::{CaptureClock, ClockOffset, StampError};
use diag::Counters;
use frames::{Iso, OdomMiss, Odometry};
use omnitrack_io::publish::{PoseSubscriber, PublishError, StatusSubscriber, TrackerState};
use ros2_client::dds::rustdds;
use ros2_client::qos::{History, Reliability, WhenFull};
use ros2_client::{Context, Node, NodeName, NodeOptions, Publisher, QosProfile, Subscription};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// The default ROS topic of the poses (DDS topic `rt/omnitrack/pose`).
pub const POSE_TOPIC: &str = "omnitrack/pose";
/// The default ROS topic of the diagnostics.
pub const DIAGNOSTICS_TOPIC: &str = "/diagnostics";
/// tf2's topic.
pub const TF_TOPIC: &str = "/tf";
/// Highest DDS domain id: the RTPS port mapping of domain 233 and above leaves the port range.
pub const MAX_DOMAIN_ID: u16 = 232;

/// A publisher that cannot go on: one line naming what failed.
#[derive(Debug, thiserror::Error)]
pub enum Ros2Error {
    #[error("{0}")]
    Local(#[from] PublishError),
    #[error("DDS: {0}")]
    Dds(String),
    #[error("{0}")]
    Stamp(#[from] StampError),
    #[error("{0}")]
    Usage(String),
    #[error("cannot write: {0}")]
    Output(#[from] std::io::Error),
    #[error(
        "/tf: {base} already has the parent {parent}; --tf map-base would give it a second one \
         (REP-105): use --tf map-odom with --odom-frame {parent}"
    )]
    SecondParent { base: String, parent: String },
}

fn dds(what: &str, e: impl std::fmt::Display) -> Ros2Error {
    Ros2Error::Dds(format!("{what}: {}", e.to_string().replace('\n', " ")))
}

/// What `publish` did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Summary {
    pub counters: Counters,
    /// Reliable poses a subscriber's full window did not take within 10 ms.
    pub not_delivered: u64,
    /// The clock offset last measured.
    pub offset: Option<ClockOffset>,
}

struct Ports {
    pose: Publisher<msg::PoseWithCovarianceStamped>,
    diagnostics: Publisher<msg::DiagnosticArray>,
    tf_out: Option<Publisher<msg::TfMessage>>,
    tf_in: Option<Subscription<msg::TfMessage>>,
    // Dropping the node ends its DDS entities; keep it as long as the ports.
    _node: Node,
}

fn open_ports(o: &Options) -> Result<Ports, Ros2Error> {
    let topic = ros_name("--topic", &o.topic)?;
    let diagnostics_topic = ros_name("--diagnostics-topic", &o.diagnostics_topic)?;
    let node_name = NodeName::new("/", &o.node_name).map_err(|_| {
        Ros2Error::Usage(format!(
            "--node-name '{}' is not a ROS node name (a letter or '_', then letters, digits, '_')",
            o.node_name
        ))
    })?;
    let mut builder = rustdds::DomainParticipantBuilder::new(o.domain_id);
    if !o.interfaces.is_empty() {
        builder = builder.with_only_networks(o.interfaces.iter().copied());
    }
    let participant = builder
        .build()
        .map_err(|e| dds(&format!("cannot join domain {}", o.domain_id), e))?;
    let context = Context::from_domain_participant(participant).map_err(|e| dds("context", e))?;
    let options = NodeOptions::new().enable_rosout(false).start_parameter_services(false);
    let mut node = context.new_node(node_name, options).map_err(|e| dds("node", e))?;

    let qos = o.qos.profile();
    let pose_topic = node
        .create_topic(&topic, msg::pose_type(), &qos)
        .map_err(|e| dds(&format!("topic {}", o.topic), e))?;
    let pose = node
        .create_publisher(&pose_topic, None)
        .map_err(|e| dds(&format!("publisher on {}", o.topic), e))?;

    // What the diagnostic updater uses: reliable, volatile, keep last 10... but never block.
    let diag_qos = QosProfile::publisher_default()
        .reliability(Reliability::Reliable {
            when_full: WhenFull::Fail,
        })
        .history(History::KeepLast { depth: 10 });
    let diag_topic = node
        .create_topic(&diagnostics_topic, msg::diagnostics_type(), &diag_qos)
        .map_err(|e| dds(&format!("topic {}", o.diagnostics_topic), e))?;
    let diagnostics = node
        .create_publisher(&diag_topic, None)
        .map_err(|e| dds(&format!("publisher on {}", o.diagnostics_topic), e))?;

    let (tf_out, tf_in) = if o.frames.tf == TfMode::None {
        (None, None)
    } else {
        // tf2's broadcaster: reliable, volatile, keep last 100. The listener takes best effort,
        // which matches a reliable or a best-effort broadcaster.
        let tf_qos = QosProfile::publisher_default()
            .reliability(Reliability::Reliable {
                when_full: WhenFull::Wait(Duration::from_millis(10)),
            })
            .history(History::KeepLast { depth: 100 });
        let tf_topic = node
            .create_topic(&ros_name("/tf", TF_TOPIC)?, msg::tf_type(), &tf_qos)
            .map_err(|e| dds("topic /tf", e))?;
        let tf_out = node
            .create_publisher(&tf_topic, None)
            .map_err(|e| dds("publisher on /tf", e))?;
        let listen_qos = tf_qos.clone().reliability(Reliability::BestEffort);
        let tf_in = node
            .create_subscription(&tf_topic, Some(listen_qos))
            .map_err(|e| dds("subscription to /tf", e))?;
        (Some(tf_out), Some(tf_in))
    };
    Ok(Ports {
        pose,
        diagnostics,
        tf_out,
        tf_in,
        _node: node,
    })
}

/// A `ros2_client` write: `Ok(false)` and counted when a full reliable window refused it,
/// anything else ends the run.
fn write<M>(what: &str, r: Result<(), ros2_client::WriteError<M>>, not_delivered: &mut u64) -> Result<bool, Ros2Error> {
    match r {
        Ok(()) => Ok(true),
        Err(ros2_client::WriteError::WouldBlock { .. }) => {
            *not_delivered += 1;
            Ok(false)
        }
        Err(e) => Err(dds(&format!("cannot publish on {what}"), e)),
    }
}

/// The robot's `odom → base_link`, and a refusal of `map → base_link` when base_link has
/// another parent.
fn take_tf(tf_in: &Subscription<msg::TfMessage>, o: &Options, odometry: &mut Odometry) -> Result<(), Ros2Error> {
    let f = &o.frames;
    // Bounded: what arrived since the last pose (tf2's depth is 100), never an endless drain.
    for _ in 0..10_000 {
        let message = match tf_in.take() {
            Ok(Some((m, _))) => m,
            Ok(None) => return Ok(()),
            // A sample that does not decode as a TFMessage: skipped (RustDDS moves past it).
            Err(_) => continue,
        };
        for t in &message.transforms {
            let (parent, child) = (
                frames::frame_name(&t.header.frame_id),
                frames::frame_name(&t.child_frame_id),
            );
            if child != f.base {
                continue;
            }
            if f.tf == TfMode::MapBase && parent != f.map {
                return Err(Ros2Error::SecondParent {
                    base: f.base.clone(),
                    parent: parent.to_string(),
                });
            }
            if parent == f.odom {
                if let Some(odom_base) = frames::from_msg_transform(&t.transform) {
                    odometry.push(t.header.stamp.ns(), odom_base);
                }
            }
        }
    }
    Ok(())
}

/// Checks what can be checked before anything is opened: names, frames, depth.
pub fn check(o: &Options) -> Result<(), Ros2Error> {
    ros_name("--topic", &o.topic)?;
    ros_name("--diagnostics-topic", &o.diagnostics_topic)?;
    NodeName::new("/", &o.node_name).map_err(|_| {
        Ros2Error::Usage(format!(
            "--node-name '{}' is not a ROS node name (a letter or '_', then letters, digits, '_')",
            o.node_name
        ))
    })?;
    if o.qos.depth == 0 {
        return Err(Ros2Error::Usage("--depth must be at least 1".into()));
    }
    let f = &o.frames;
    for (option, id) in [
        ("--map-frame", &f.map),
        ("--odom-frame", &f.odom),
        ("--base-frame", &f.base),
    ] {
        frame_id(option, id)?;
    }
    if f.tf == TfMode::MapOdom && (f.odom == f.map || f.odom == f.base) {
        return Err(Ros2Error::Usage(format!(
            "--odom-frame '{}' must differ from --map-frame and --base-frame",
            f.odom
        )));
    }
    if f.map == f.base {
        return Err(Ros2Error::Usage(format!(
            "--map-frame and --base-frame are both '{}'",
            f.map
        )));
    }
    Ok(())
}

/// Publishes the pose and status services on ROS 2 until `stop` is set or `count` poses went
/// out; `on_start` is called once the DDS entities exist, with the clock offset first measured.
pub fn publish(o: &Options, stop: &AtomicBool, on_start: &mut dyn FnMut(&ClockOffset)) -> Result<Summary, Ros2Error> {
    check(o)?;
    let f = &o.frames;
    let poses = PoseSubscriber::create(&o.pose_service)?;
    let statuses = StatusSubscriber::create(&o.status_service)?;
    let ports = open_ports(o)?;

    let mut offset = ClockOffset::measure();
    let mut measured = Instant::now();
    on_start(&offset);
    let mut summary = Summary::default();
    let mut odometry = Odometry::default();
    let mut last_status = Instant::now();
    let mut last_stale = Instant::now();
    let mut hardware_id = String::new();
    let mut missed_once: Option<OdomMiss> = None;
    let c = &mut summary.counters;
    while !stop.load(Ordering::Relaxed) && o.count.is_none_or(|n| c.published < n) {
        if measured.elapsed() >= clock::REMEASURE {
            offset = ClockOffset::measure();
            measured = Instant::now();
        }
        if let Some(tf_in) = &ports.tf_in {
            take_tf(tf_in, o, &mut odometry)?;
        }
        while let Some(status) = statuses.receive()? {
            last_status = Instant::now();
            hardware_id = status.source().to_string();
            let stamp = match o.capture_clock {
                CaptureClock::Monotonic => i64::try_from(status.timestamp_ns).unwrap_or(0) + offset.offset_ns,
                CaptureClock::Receipt => clock::system_ns(),
            };
            let array = msg::DiagnosticArray {
                header: msg::Header {
                    stamp: msg::Time::from_ns(stamp).unwrap_or_default(),
                    frame_id: String::new(),
                },
                status: vec![diag::from_status(&status, c, &offset)],
            };
            write(
                &o.diagnostics_topic,
                ports.diagnostics.publish(array),
                &mut summary.not_delivered,
            )?;
        }
        if last_status.elapsed() >= diag::STALE_AFTER && last_stale.elapsed() >= Duration::from_secs(1) {
            last_stale = Instant::now();
            let array = msg::DiagnosticArray {
                header: msg::Header {
                    stamp: msg::Time::from_ns(clock::system_ns()).unwrap_or_default(),
                    frame_id: String::new(),
                },
                status: vec![diag::stale(&o.status_service, last_status.elapsed(), c, &hardware_id)],
            };
            write(
                &o.diagnostics_topic,
                ports.diagnostics.publish(array),
                &mut summary.not_delivered,
            )?;
        }

        let sample = match poses.wait(Duration::from_millis(20)) {
            Ok(Some(sample)) => sample,
            Ok(None) => continue,
            // SIGINT/SIGTERM interrupt the wait (iceoryx2 reports it as an error): a stop.
            Err(_) if stop.load(Ordering::Relaxed) => break,
            Err(e) => return Err(e.into()),
        };
        c.received += 1;
        let rig = rig_pose_if_tracking(&sample);
        let Some((map_rig, cov_rig)) = rig else {
            c.not_tracking += 1;
            continue;
        };
        let stamp_ns = clock::ros_stamp_ns(
            o.capture_clock,
            sample.sequence,
            sample.timestamp_ns,
            clock::monotonic_ns(),
            clock::system_ns(),
            &offset,
        )?;
        let stamp = msg::Time::from_ns(stamp_ns).ok_or(StampError::OutOfRange {
            sequence: sample.sequence,
        })?;
        let (map_base, cov_base) = frames::base_pose(&map_rig, &cov_rig, &f.base_rig);
        let header = msg::Header {
            stamp,
            frame_id: f.map.clone(),
        };
        let mut covariance = [0.0; 36];
        for (i, v) in covariance.iter_mut().enumerate() {
            *v = cov_base[(i / 6, i % 6)];
        }
        let message = msg::PoseWithCovarianceStamped {
            header: header.clone(),
            pose: msg::PoseWithCovariance {
                pose: frames::to_msg_pose(&map_base),
                covariance: msg::Covariance(covariance),
            },
        };
        if write(&o.topic, ports.pose.publish(message), &mut summary.not_delivered)? {
            c.published += 1;
        }

        let transform = match f.tf {
            TfMode::None => None,
            TfMode::MapBase => Some((f.base.clone(), map_base)),
            TfMode::MapOdom => match odometry.at(stamp_ns, o.frames.odom_tolerance.as_nanos() as i64) {
                Ok(odom_base) => Some((f.odom.clone(), frames::map_odom(&map_base, &odom_base))),
                Err(miss) => {
                    c.tf_no_odometry += 1;
                    if missed_once.is_none() {
                        eprintln!(
                            "omnitrack-ros2: no {} → {} for pose {}: {} (counted in /diagnostics)",
                            f.odom,
                            f.base,
                            sample.sequence,
                            miss.as_str()
                        );
                        missed_once = Some(miss);
                    }
                    None
                }
            },
        };
        if let (Some((child, t)), Some(tf_out)) = (transform, &ports.tf_out) {
            let tf_stamp = stamp_ns.saturating_add(f.transform_tolerance.as_nanos() as i64);
            let tf = msg::TfMessage {
                transforms: vec![msg::TransformStamped {
                    header: msg::Header {
                        stamp: msg::Time::from_ns(tf_stamp).unwrap_or(header.stamp),
                        ..header
                    },
                    child_frame_id: child,
                    transform: frames::to_msg_transform(&t),
                }],
            };
            if write(TF_TOPIC, tf_out.publish(tf), &mut summary.not_delivered)? {
                c.tf_published += 1;
            }
        }
    }
    summary.offset = Some(offset);
    Ok(summary)
}

/// The rig's pose and covariance of a sample whose status is tracking; `None` for one
/// initialising or lost (its pose is the last good one, not a current one) or one whose
/// quaternion is not a rotation.
pub fn rig_pose_if_tracking(s: &omnitrack_io::publish::PoseSample) -> Option<(Iso, nalgebra::Matrix6<f64>)> {
    (s.pose_status() == Ok(TrackerState::Tracking))
        .then(|| frames::rig_pose(s))
        .flatten()
}

/// A flag set by SIGINT or SIGTERM (the subscriber processes' one, from omnitrack-io).
pub use omnitrack_io::publish::stop_on_signals;

#[cfg(test)]
mod tests {
    use super::*;
    use omnitrack_io::publish::PoseSample;
    use ros2_client::qos::Durability;
    use std::net::IpAddr;

    #[test]
    fn a_relative_topic_is_under_the_root_namespace_once() {
        let node = NodeName::new("/", "omnitrack").unwrap();
        for (name, dds) in [
            ("omnitrack/pose", "rt/omnitrack/pose"),
            ("/omnitrack/pose", "rt/omnitrack/pose"),
            ("/diagnostics", "rt/diagnostics"),
            ("pose", "rt/pose"),
        ] {
            assert_eq!(ros_name("--topic", name).unwrap().to_dds_name("rt", &node, ""), dds);
        }
    }

    #[test]
    fn names_frames_and_domains_that_ros_would_refuse_are_named() {
        assert!(ros_name("--topic", "omnitrack/pose").is_ok());
        assert!(ros_name("--topic", "/diagnostics").is_ok());
        let e = |s: &str| ros_name("--topic", s).unwrap_err().to_string();
        assert_eq!(e(""), "--topic '' is not a ROS topic name: it is empty");
        assert_eq!(
            e("omnitrack//pose"),
            "--topic 'omnitrack//pose' is not a ROS topic name: it has an empty part ('//' or a trailing '/')"
        );
        assert!(e("omni track").contains("' ' is not allowed"), "{}", e("omni track"));
        assert_eq!(
            frame_id("--map-frame", "/map").unwrap_err().to_string(),
            "--map-frame '/map' is not a frame id: ROS 2 frame ids have no leading '/'"
        );
        let lo = vec![IpAddr::from([127, 0, 0, 1])];
        let eth = vec![IpAddr::from([192, 168, 10, 5])];
        assert_eq!(
            interfaces(eth.clone(), Some("LOCALHOST"), None).unwrap(),
            eth,
            "--interface wins"
        );
        assert_eq!(interfaces(vec![], Some("LOCALHOST"), None).unwrap(), lo);
        assert_eq!(interfaces(vec![], None, Some("1")).unwrap(), lo);
        assert!(interfaces(vec![], Some("SUBNET"), None).unwrap().is_empty());
        assert!(interfaces(vec![], None, None).unwrap().is_empty());
        assert_eq!(
            interfaces(vec![], Some("OFF"), None).unwrap_err().to_string(),
            "ROS_AUTOMATIC_DISCOVERY_RANGE=OFF (static peers only) is not supported: unset it, or set LOCALHOST or SUBNET"
        );
        assert!(interfaces(vec![], Some("LAN"), None).is_err());
        assert_eq!(domain_id("232"), Ok(232));
        assert_eq!(domain_id(""), Ok(0), "ROS_DOMAIN_ID= is the default domain");
        assert_eq!(domain_id("233").unwrap_err(), "'233' is not a ROS domain id (0 to 232)");
        assert_eq!(domain_id("x").unwrap_err(), "'x' is not a ROS domain id (0 to 232)");
    }

    #[test]
    fn only_tracking_poses_with_a_rotation_are_published() {
        let mut s = PoseSample {
            status: TrackerState::Tracking as u8,
            ..PoseSample::default()
        };
        assert!(rig_pose_if_tracking(&s).is_some());
        s.status = TrackerState::Lost as u8;
        assert!(rig_pose_if_tracking(&s).is_none());
        s.status = TrackerState::Initialising as u8;
        assert!(rig_pose_if_tracking(&s).is_none());
        s.status = TrackerState::Tracking as u8;
        s.rotation_wxyz = [0.0; 4];
        assert!(rig_pose_if_tracking(&s).is_none());
    }

    #[test]
    fn the_default_qos_is_ros_2s_default_profile() {
        let p = PoseQos::default().profile();
        assert!(matches!(p.reliability, Reliability::Reliable { .. }));
        assert_eq!(p.durability, Durability::Volatile);
        assert_eq!(p.history, History::KeepLast { depth: 10 });
        let latched = PoseQos {
            reliability: ReliabilityKind::BestEffort,
            durability: DurabilityKind::TransientLocal,
            depth: 1,
        }
        .profile();
        assert_eq!(latched.reliability, Reliability::BestEffort);
        assert_eq!(latched.durability, Durability::TransientLocal);
        assert_eq!(latched.history, History::KeepLast { depth: 1 });
    }
}
