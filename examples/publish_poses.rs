//! Publishes poses on the tracker's iceoryx2 service, as `omnitrack run` does for every frame:
//! a rig walking a 2 m circle at 30 Hz, each pose with a covariance, for `SECONDS` (default 3).
//! Any subscriber on the same computer receives them without a copy: `omnitrack listen`,
//! `cargo run --example subscribe_poses`, or `tools/examples/listen_pose.py`.
//!
//! Run: `cargo run --release --example publish_poses [SECONDS]`.

use nalgebra::{Matrix6, Translation3, UnitQuaternion, Vector3};
use omnitrack::geometry::Pose;
use omnitrack::publish::{PosePublisher, TrackerState, POSE_SERVICE};
use std::time::{Duration, Instant};

/// This host's `CLOCK_MONOTONIC`, nanoseconds: the clock of V4L2 and USB3 Vision frame stamps.
fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `ts` is a valid timespec to write; CLOCK_MONOTONIC always exists on Linux.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

fn main() {
    let seconds: f64 = match std::env::args().nth(1) {
        None => 3.0,
        Some(s) => match s.parse() {
            Ok(v) if v > 0.0 => v,
            _ => {
                eprintln!("publish_poses: SECONDS must be a positive number, got {s:?}");
                std::process::exit(2)
            }
        },
    };
    let publisher = PosePublisher::create(POSE_SERVICE).unwrap_or_else(|e| {
        eprintln!("publish_poses: {e}");
        std::process::exit(2)
    });
    // 1 cm and 0.1° standard deviations.
    let covariance = Matrix6::from_diagonal(&nalgebra::Vector6::new(1e-4, 1e-4, 1e-4, 3e-6, 3e-6, 3e-6));
    let start = Instant::now();
    let mut sequence = 0u64;
    while start.elapsed().as_secs_f64() < seconds {
        let angle = 0.5 * start.elapsed().as_secs_f64();
        let pose: Pose = Pose::from_parts(
            Translation3::new(2.0 * angle.cos(), 2.0 * angle.sin(), 1.5),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), angle + std::f64::consts::FRAC_PI_2),
        );
        // Stamped as a live camera stamps its frames: this host's monotonic clock
        // (docs/interfaces.md, "Pose service"; omnitrack-ros2 turns it into ROS time).
        let now_ns = monotonic_ns();
        match publisher.publish_pose(now_ns, sequence, TrackerState::Tracking, &pose, &covariance, 60, 1e-5) {
            Ok(reached) if sequence % 30 == 0 => println!("seq {sequence}: {reached} subscriber(s)"),
            Ok(_) => {}
            Err(e) => {
                eprintln!("publish_poses: {e}");
                std::process::exit(2)
            }
        }
        sequence += 1;
        std::thread::sleep(Duration::from_millis(33));
    }
    println!("published {sequence} poses on {POSE_SERVICE}");
}
