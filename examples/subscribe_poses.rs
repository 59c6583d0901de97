//! Receives poses from the tracker's iceoryx2 service, as a navigation or AR process on the rig's
//! computer would: it sleeps until a sample arrives and reads it from shared memory, no copy on
//! the way. Stops after `COUNT` poses (default 5), or with exit code 1 after `TIMEOUT` seconds
//! (default 10) without one.
//!
//! Run: `cargo run --release --example subscribe_poses [COUNT] [TIMEOUT]`, beside `omnitrack run`
//! or `cargo run --release --example publish_poses`.

use omnitrack::publish::{format_pose_line, PoseSample, SampleSubscriber, POSE_SERVICE};
use std::io::Write;
use std::time::Duration;

/// The argument `what` as a positive number, `default` when absent; one line and exit 2 otherwise.
fn positive(arg: Option<String>, what: &str, default: f64) -> f64 {
    match arg.map(|s| (s.parse::<f64>(), s)) {
        None => default,
        Some((Ok(v), _)) if v > 0.0 && v.is_finite() => v,
        Some((_, s)) => {
            eprintln!("subscribe_poses: {what} must be a positive number, got {s:?}");
            std::process::exit(2)
        }
    }
}

fn main() {
    let mut args = std::env::args().skip(1);
    let count: u64 = positive(args.next(), "COUNT", 5.0) as u64;
    let timeout = Duration::from_secs_f64(positive(args.next(), "TIMEOUT", 10.0));
    let subscriber = SampleSubscriber::<PoseSample>::create(POSE_SERVICE).unwrap_or_else(|e| {
        eprintln!("subscribe_poses: {e}");
        std::process::exit(2)
    });
    let mut stdout = std::io::stdout();
    for _ in 0..count {
        match subscriber.wait(timeout) {
            Ok(Some(sample)) => {
                // The fields of docs/interfaces.md, "Pose service"; here printed as `omnitrack
                // listen` prints them.
                if format_pose_line(&sample, &mut stdout)
                    .and_then(|()| writeln!(stdout))
                    .is_err()
                {
                    std::process::exit(2)
                }
            }
            Ok(None) => {
                eprintln!("subscribe_poses: no pose on {POSE_SERVICE} within {timeout:?}");
                std::process::exit(1)
            }
            Err(e) => {
                eprintln!("subscribe_poses: {e}");
                std::process::exit(2)
            }
        }
    }
}
