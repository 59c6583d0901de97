//! `omnitrack-ros2`: the tracker's poses and status as ROS 2 topics over DDS, with no ROS
//! installation (see the library doc).
//!
//! ```text
//! omnitrack-ros2 publish [--service omnitrack/pose] [--status-service omnitrack/status]
//!     [--topic omnitrack/pose] [--diagnostics-topic /diagnostics] [--domain-id N] [--interface ADDR]...
//!     [--tf none|map-odom|map-base] [--map-frame map] [--odom-frame odom] [--base-frame base_link]
//!     [--rig-in-base X,Y,Z,QX,QY,QZ,QW] [--odom-tolerance-s S] [--transform-tolerance-s S]
//!     [--reliability reliable|best-effort] [--durability volatile|transient-local] [--depth N]
//!     [--capture-clock monotonic|receipt] [--node-name omnitrack] [--count N]
//! omnitrack-ros2 completions SHELL
//! omnitrack-ros2 manpage [--dir DIR]
//! ```
//!
//! `publish` prints the measured clock offset on standard error at start and a summary line
//! at the end. Errors are one line on standard error and exit code 1; usage errors exit 2.

use clap::{Parser, Subcommand};
use omnitrack_ros2::clock::CaptureClock;
use omnitrack_ros2::frames::{parse_transform, Iso};
use omnitrack_ros2::{
    domain_id, publish, stop_on_signals, DurabilityKind, Frames, Options, PoseQos, ReliabilityKind, Ros2Error, TfMode,
    DIAGNOSTICS_TOPIC, POSE_TOPIC,
};
use std::net::IpAddr;
use std::time::Duration;

#[derive(Parser)]
#[command(
    name = "omnitrack-ros2",
    version,
    about = "omnitrack poses and status as ROS 2 topics over DDS, without ROS installed"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

fn positive_seconds(s: &str) -> Result<Duration, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(Duration::from_secs_f64(v)),
        _ => Err(format!("'{s}' is not a number of seconds ≥ 0")),
    }
}

fn depth(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(d) if (1..=10_000).contains(&d) => Ok(d),
        _ => Err(format!("'{s}' is not a history depth (1 to 10000)")),
    }
}

#[derive(Subcommand)]
#[allow(clippy::large_enum_variant)]
enum Command {
    /// Publishes the tracker's poses (status tracking) and status on ROS 2 until stopped.
    Publish {
        /// The local iceoryx2 pose service.
        #[arg(long, default_value = omnitrack_io::publish::POSE_SERVICE)]
        service: String,
        /// The local iceoryx2 status service (to /diagnostics).
        #[arg(long, default_value = omnitrack_io::publish::STATUS_SERVICE)]
        status_service: String,
        /// The ROS topic of the poses (geometry_msgs/msg/PoseWithCovarianceStamped); a relative
        /// name is under the root namespace (DDS topic rt/omnitrack/pose).
        #[arg(long, default_value = POSE_TOPIC)]
        topic: String,
        /// The ROS topic of the tracker's status (diagnostic_msgs/msg/DiagnosticArray).
        #[arg(long, default_value = DIAGNOSTICS_TOPIC)]
        diagnostics_topic: String,
        /// The DDS domain (ROS_DOMAIN_ID), 0 to 232.
        #[arg(long, env = "ROS_DOMAIN_ID", default_value = "0", value_parser = domain_id)]
        domain_id: u16,
        /// A local address DDS may use (repeatable); when none is given, the loopback only for
        /// ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST or ROS_LOCALHOST_ONLY=1, else every interface.
        #[arg(long = "interface", value_name = "ADDR")]
        interfaces: Vec<IpAddr>,
        /// What goes on /tf: none; map-odom, computed from the robot's odom → base_link
        /// (REP-105); map-base, for a rig with no odometry.
        #[arg(long, value_enum, default_value = "none")]
        tf: TfMode,
        /// The building model's frame: header.frame_id of the poses, parent on /tf.
        #[arg(long, default_value = "map")]
        map_frame: String,
        /// The robot's odometry frame (--tf map-odom).
        #[arg(long, default_value = "odom")]
        odom_frame: String,
        /// The robot's body frame, whose pose is published.
        #[arg(long, default_value = "base_link")]
        base_frame: String,
        /// The rig's pose in the base frame, x,y,z,qx,qy,qz,qw (metres; ROS's quaternion
        /// order); the rig frame is the base frame when not given.
        #[arg(long, value_name = "X,Y,Z,QX,QY,QZ,QW", value_parser = parse_transform, allow_hyphen_values = true)]
        rig_in_base: Option<Iso>,
        /// How far past the newest odometry a pose may be and still use it (--tf map-odom).
        #[arg(long = "odom-tolerance-s", value_name = "S", default_value = "0.1", value_parser = positive_seconds, allow_hyphen_values = true)]
        odom_tolerance: Duration,
        /// Stamp the transforms on /tf this much later than their pose (AMCL's
        /// transform_tolerance), for stacks that look transforms up at the current time.
        #[arg(long = "transform-tolerance-s", value_name = "S", default_value = "0", value_parser = positive_seconds, allow_hyphen_values = true)]
        transform_tolerance: Duration,
        /// Delivery of the pose topic.
        #[arg(long, value_enum, default_value = "reliable")]
        reliability: ReliabilityKind,
        /// What a late subscriber of the pose topic gets: nothing, or the last --depth poses.
        #[arg(long, value_enum, default_value = "volatile")]
        durability: DurabilityKind,
        /// History depth of the pose topic (keep last N).
        #[arg(long, default_value = "10", value_parser = depth)]
        depth: usize,
        /// The clock of the tracker's stamps: monotonic (live cameras: stamps move to the system
        /// clock by the measured offset), receipt (a replay: stamped on arrival).
        #[arg(long, value_enum, default_value = "monotonic")]
        capture_clock: CaptureClock,
        /// The ROS node's name.
        #[arg(long, default_value = "omnitrack")]
        node_name: String,
        /// Stop after publishing this many poses.
        #[arg(long)]
        count: Option<u64>,
    },
    /// Prints a shell completion script for omnitrack-ros2 (bash, zsh, fish, elvish or powershell).
    Completions {
        /// The shell.
        shell: omnitrack_manual::Shell,
    },
    /// Prints omnitrack-ros2's manual page (roff), or writes it and a page per command into a
    /// directory.
    Manpage(omnitrack_manual::ManpageArgs),
}

fn run(cli: Cli) -> Result<(), Ros2Error> {
    match cli.command {
        Command::Publish {
            service,
            status_service,
            topic,
            diagnostics_topic,
            domain_id,
            interfaces,
            tf,
            map_frame,
            odom_frame,
            base_frame,
            rig_in_base,
            odom_tolerance,
            transform_tolerance,
            reliability,
            durability,
            depth,
            capture_clock,
            node_name,
            count,
        } => {
            let options = Options {
                pose_service: service,
                status_service,
                topic,
                diagnostics_topic,
                frames: Frames {
                    map: map_frame,
                    odom: odom_frame,
                    base: base_frame,
                    base_rig: rig_in_base.unwrap_or_else(Iso::identity),
                    tf,
                    odom_tolerance,
                    transform_tolerance,
                },
                qos: PoseQos {
                    reliability,
                    durability,
                    depth,
                },
                capture_clock,
                domain_id,
                interfaces: omnitrack_ros2::interfaces(
                    interfaces,
                    std::env::var("ROS_AUTOMATIC_DISCOVERY_RANGE").ok().as_deref(),
                    std::env::var("ROS_LOCALHOST_ONLY").ok().as_deref(),
                )?,
                node_name,
                count,
            };
            let stop = stop_on_signals();
            let s = publish(&options, &stop, &mut |offset| {
                eprintln!(
                    "omnitrack-ros2: domain {domain_id}, {} → {}; clock: {offset} (measured every {} s)",
                    options.pose_service,
                    options.topic,
                    omnitrack_ros2::clock::REMEASURE.as_secs()
                )
            })?;
            let c = s.counters;
            eprintln!(
                "omnitrack-ros2: {} poses received, {} published, {} not tracking; {} transforms, \
                 {} poses without odometry; {} messages a full reliable window refused",
                c.received, c.published, c.not_tracking, c.tf_published, c.tf_no_odometry, s.not_delivered
            );
        }
        Command::Completions { shell } => omnitrack_manual::run_completions(&manual(), shell)?,
        Command::Manpage(args) => omnitrack_manual::run_manpage(&manual(), &args)?,
    }
    Ok(())
}

fn manual() -> omnitrack_manual::Manual {
    omnitrack_manual::Manual::new(<Cli as clap::CommandFactory>::command())
}

fn main() {
    match run(Cli::parse()) {
        Ok(()) => {}
        Err(Ros2Error::Output(e)) if e.kind() == std::io::ErrorKind::BrokenPipe => {}
        Err(e) => {
            eprintln!("omnitrack-ros2: {e}");
            std::process::exit(1);
        }
    }
}
