//! `publish_demo`: publishes a synthetic pose trajectory on the pose service, so that consumers
//! (`omnitrack listen`, `tools/examples/listen_pose.py`) can be tried without a rig.
//!
//! ```text
//! cargo run -p omnitrack-tools --bin publish_demo -- [--service omnitrack/pose] [--count 200] [--hz 30]
//! ```
//!
//! The rig walks a 2 m circle at 1.6 m height, turning to face along the path; status is
//! `initializing` for the first 5 samples, then `tracking`. Prints one line per sample sent to
//! standard error (format of `omnitrack listen`).

use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use nalgebra::{Isometry3, Matrix6, Translation3, UnitQuaternion, Vector3};
use omnitrack::publish::{format_pose_line, PosePublisher, PoseSample, PoseStatus, POSE_SERVICE};

fn main() {
    let mut service = POSE_SERVICE.to_string();
    let mut count: u64 = 200;
    let mut hz: f64 = 30.0;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = |what: &str| {
            args.next().unwrap_or_else(|| {
                eprintln!("publish_demo: {what} needs a value");
                std::process::exit(2)
            })
        };
        match a.as_str() {
            "--service" => service = value("--service"),
            "--count" => {
                count = value("--count")
                    .parse()
                    .unwrap_or_else(|e| fail(&format!("--count: {e}")))
            }
            "--hz" => hz = value("--hz").parse().unwrap_or_else(|e| fail(&format!("--hz: {e}"))),
            other => fail(&format!(
                "unknown argument '{other}' (--service NAME, --count N, --hz F)"
            )),
        }
    }
    if !(hz > 0.0 && hz.is_finite()) {
        fail("--hz must be a positive number");
    }
    let publisher = PosePublisher::create(&service).unwrap_or_else(|e| fail(&e.to_string()));
    if publisher.dead_nodes_cleaned() > 0 {
        eprintln!(
            "publish_demo: cleaned {} dead iceoryx2 node(s)",
            publisher.dead_nodes_cleaned()
        );
    }
    let period = Duration::from_secs_f64(1.0 / hz);
    let start = Instant::now();
    let mut cov = Matrix6::<f64>::zeros();
    for i in 0..3 {
        cov[(i, i)] = 0.02f64.powi(2);
        cov[(i + 3, i + 3)] = 0.5f64.to_radians().powi(2);
    }
    for seq in 0..count {
        let a = seq as f64 * 0.05;
        let pose = Isometry3::from_parts(
            Translation3::new(2.0 * a.cos(), 2.0 * a.sin(), 1.6),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), a + std::f64::consts::FRAC_PI_2),
        );
        let status = if seq < 5 {
            PoseStatus::Initializing
        } else {
            PoseStatus::Tracking
        };
        let now_ns = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map(|d| d.as_nanos() as u64)
            .unwrap_or(0);
        let sample = PoseSample::from_pose(now_ns, seq, status, &pose, &cov, 40 + (seq % 20) as u32, 2.5e-5);
        let reached = publisher.publish(&sample).unwrap_or_else(|e| fail(&e.to_string()));
        let mut line = Vec::new();
        let _ = format_pose_line(&sample, &mut line);
        eprintln!("sent to {reached}: {}", String::from_utf8_lossy(&line));
        let next = start + period * (seq as u32 + 1);
        if let Some(d) = next.checked_duration_since(Instant::now()) {
            std::thread::sleep(d);
        }
    }
}

fn fail(msg: &str) -> ! {
    eprintln!("publish_demo: {msg}");
    std::process::exit(2)
}
