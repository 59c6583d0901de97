//! Poses to other hosts: the pose service `omnitrack/pose` carried over Zenoh.
//!
//! In: on the rig's computer, the local iceoryx2 pose service (a zero-copy subscriber, like any
//! other local consumer); on a far host, a Zenoh session that reaches the rig's. Out: every
//! [`PoseSample`] put on the Zenoh key expression `omnitrack/pose` as its
//! [`PoseSample::to_wire`] bytes (the C layout of the shared-memory sample, little-endian), and
//! on the far host one line per sample in `omnitrack listen`'s format and, if asked, the same
//! sample on a local iceoryx2 service of the far host.
//!
//! Why not iceoryx2's own Zenoh tunnel: the tunnel crates on crates.io stop at iceoryx2 0.8
//! (`iceoryx2-tunnel-zenoh` 0.8.1), and the tracker speaks iceoryx2 0.10, whose shared-memory
//! layout the 0.8 tunnel cannot open. So the link is a process of its own, as the tunnel
//! would be: it subscribes locally and puts each sample on Zenoh with Zenoh's reliable,
//! blocking congestion control, so that a slow network delays samples rather than drops them.
//! No protocol of ours: the payload is the documented C struct (little-endian), which a Zenoh
//! subscriber in another language can declare as `tools/examples/listen_pose.py` does for
//! shared memory.
//!
//! Sessions are Zenoh peers with explicit endpoints (`--listen tcp/ADDR:PORT` on one side,
//! `--connect tcp/ADDR:PORT` on the other) and multicast scouting off, so that nothing else on
//! the network joins unasked. A peer that cannot be reached within [`CONNECT_TIMEOUT`] is one
//! line and a non-zero exit, never a hang.
//!
//! The link is not on the device path: it allocates per sample (Zenoh's buffers) and runs beside
//! the tracker, which never waits for it.
//!
//! Latency (`listen --latency`): a pose's age on arrival is `now − timestamp_ns` only where both
//! are read on one clock. `send` attaches to every sample which machine it runs on ([`boot_id`]:
//! processes of one boot, network namespaces included, share `CLOCK_MONOTONIC`), and `listen`
//! counts an age only for a sample from its own boot whose stamp is on that clock now (within
//! [`MAX_LIVE_AGE`] before it: a live source's). A replay's stamps are its recording's time, and
//! another host's clock is not this one's: those samples are counted as not comparable, with
//! the reason ([`NotComparable`]), never as an age.

use omnitrack_io::publish::{format_pose_line, PoseSample, PoseSubscriber, SamplePublisher, WireError};
use std::io::Write;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use zenoh::qos::CongestionControl;
use zenoh::Wait;

/// The Zenoh key expression of the poses (the iceoryx2 service's name).
pub const POSE_KEY: &str = "omnitrack/pose";

/// How long a session keeps trying to reach the endpoints it was told to connect to.
pub const CONNECT_TIMEOUT: Duration = Duration::from_secs(10);

/// A link that cannot go on: one line naming what failed.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    #[error("zenoh: {0}")]
    Zenoh(String),
    #[error("{0}")]
    Local(#[from] omnitrack_io::publish::PublishError),
    #[error("{key}: a sample that is not a pose: {error}")]
    Wire { key: String, error: WireError },
    #[error("cannot write: {0}")]
    Output(#[from] std::io::Error),
}

fn zenoh_error(what: &str, e: impl std::fmt::Display) -> LinkError {
    // One line, whatever Zenoh's message holds, without the source location it appends.
    let message = e.to_string().replace('\n', " ");
    let message = message.split(" at /").next().unwrap_or_default().trim_end_matches('.');
    LinkError::Zenoh(format!("{what}: {message}"))
}

/// Where a session listens and what it connects to (Zenoh endpoints such as `tcp/10.0.0.1:7447`).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Endpoints {
    pub listen: Vec<String>,
    pub connect: Vec<String>,
}

/// Opens a Zenoh peer session on `endpoints` (see the module doc).
pub fn open_session(endpoints: &Endpoints) -> Result<zenoh::Session, LinkError> {
    let mut config = zenoh::Config::default();
    let set = |config: &mut zenoh::Config, key: &str, value: String| {
        config
            .insert_json5(key, &value)
            .map_err(|e| zenoh_error(&format!("configuration {key} = {value}"), e))
    };
    let list = |v: &[String]| {
        let quoted: Vec<String> = v.iter().map(|e| format!("{e:?}")).collect();
        format!("[{}]", quoted.join(","))
    };
    set(&mut config, "mode", "\"peer\"".into())?;
    set(&mut config, "scouting/multicast/enabled", "false".into())?;
    set(&mut config, "listen/endpoints", list(&endpoints.listen))?;
    set(&mut config, "connect/endpoints", list(&endpoints.connect))?;
    set(
        &mut config,
        "connect/timeout_ms",
        CONNECT_TIMEOUT.as_millis().to_string(),
    )?;
    set(&mut config, "connect/exit_on_failure", "true".into())?;
    let what = match (endpoints.connect.is_empty(), endpoints.listen.is_empty()) {
        (false, _) => format!("cannot reach {}", endpoints.connect.join(", ")),
        (true, false) => format!("cannot listen on {}", endpoints.listen.join(", ")),
        (true, true) => "cannot open a session".to_string(),
    };
    zenoh::open(config).wait().map_err(|e| zenoh_error(&what, e))
}

/// Nanoseconds of this host's `CLOCK_MONOTONIC`: the clock of V4L2 capture timestamps, so that
/// on the rig's own machine `now − timestamp_ns` is a pose's age since capture.
pub fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `ts` is a valid timespec to write; CLOCK_MONOTONIC always exists on Linux.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// Oldest a stamp on this host's monotonic clock can be and still be a live capture's: a replay's
/// stamps (its recording's time) are older, or ahead.
pub const MAX_LIVE_AGE: Duration = Duration::from_secs(10);

/// What `send` attaches to every sample: this prefix, then the sender's [`boot_id`].
const CLOCK_ATTACHMENT: &str = "omnitrack-link clock v1 boot_id=";

/// This machine's boot id (`/proc/sys/kernel/random/boot_id`): two processes read the same
/// `CLOCK_MONOTONIC` exactly when their boot ids are equal.
pub fn boot_id() -> Option<String> {
    let id = std::fs::read_to_string("/proc/sys/kernel/random/boot_id").ok()?;
    let id = id.trim();
    (!id.is_empty()).then(|| id.to_string())
}

/// Why a pose's age on arrival cannot be read off its stamp.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum NotComparable {
    /// The sample carries no sender clock (an older `omnitrack-link send`, or another program).
    UnknownSender,
    /// The sender runs on another machine (or boot): its monotonic clock is not this one's.
    OtherHost,
    /// The stamp is not this clock's time now (older than [`MAX_LIVE_AGE`], or ahead): a replay
    /// stamps its recording's time.
    NotLive,
}

impl std::fmt::Display for NotComparable {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            NotComparable::UnknownSender => "the sender does not say which clock it runs on",
            NotComparable::OtherHost => "the sender runs on another host, whose clock is not this one's",
            NotComparable::NotLive => "the stamps are not this host's clock now (a replay's are its recording's time)",
        })
    }
}

/// The age on arrival of a pose stamped `stamp_ns`, received at `now_ns` (this host's monotonic
/// clock, boot `own_boot`) with the sender's attachment `attachment`; or why it has none.
pub fn pose_age_us(
    stamp_ns: u64,
    now_ns: u64,
    attachment: Option<&[u8]>,
    own_boot: Option<&str>,
) -> Result<f64, NotComparable> {
    let sender_boot = attachment
        .and_then(|a| std::str::from_utf8(a).ok())
        .and_then(|a| a.strip_prefix(CLOCK_ATTACHMENT))
        .ok_or(NotComparable::UnknownSender)?;
    if own_boot != Some(sender_boot) {
        return Err(NotComparable::OtherHost);
    }
    match now_ns.checked_sub(stamp_ns) {
        Some(age) if age <= MAX_LIVE_AGE.as_nanos() as u64 => Ok(age as f64 / 1e3),
        _ => Err(NotComparable::NotLive),
    }
}

/// What `send` did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SendSummary {
    pub forwarded: u64,
}

/// Forwards the local pose service `service` to Zenoh key `key` until `stop` is set or `count`
/// samples went out.
pub fn send(
    service: &str,
    key: &str,
    endpoints: &Endpoints,
    count: Option<u64>,
    stop: &AtomicBool,
) -> Result<SendSummary, LinkError> {
    let subscriber = PoseSubscriber::create(service)?;
    let session = open_session(endpoints)?;
    let publisher = session
        .declare_publisher(key.to_string())
        .congestion_control(CongestionControl::Block)
        .wait()
        .map_err(|e| zenoh_error(&format!("cannot publish on {key}"), e))?;
    let mut summary = SendSummary::default();
    // Which clock the stamps may be compared with (see the module doc).
    let clock = boot_id().map(|id| format!("{CLOCK_ATTACHMENT}{id}").into_bytes());
    while !stop.load(Ordering::Relaxed) && count.is_none_or(|n| summary.forwarded < n) {
        let Some(sample) = subscriber.wait(Duration::from_millis(100))? else {
            continue;
        };
        publisher
            .put(sample.to_wire().to_vec())
            .attachment(clock.clone())
            .wait()
            .map_err(|e| zenoh_error(&format!("cannot put on {key}"), e))?;
        summary.forwarded += 1;
    }
    let _ = session.close().wait();
    Ok(summary)
}

/// What `listen` received.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ListenSummary {
    pub received: u64,
    /// Sequence numbers skipped between consecutive samples (a publisher restart resets them
    /// and counts nothing).
    pub missing: u64,
    /// `now − timestamp_ns` of each sample on this host's monotonic clock (µs), when asked and
    /// comparable ([`pose_age_us`]).
    pub latencies_us: Vec<f64>,
    /// Samples whose age could not be read, by reason, when asked.
    pub not_comparable: std::collections::BTreeMap<NotComparable, u64>,
}

impl ListenSummary {
    /// The `q`-quantile of the latencies (nearest rank), if any.
    pub fn latency_quantile_us(&self, q: f64) -> Option<f64> {
        let mut v = self.latencies_us.clone();
        v.sort_by(f64::total_cmp);
        let last = v.len().checked_sub(1)?;
        Some(v[((q * last as f64).round() as usize).min(last)])
    }
}

/// What `listen` does with each pose besides printing it.
#[derive(Debug, Clone, Default)]
pub struct ListenOptions {
    /// Stop after this many poses.
    pub count: Option<u64>,
    /// Stop when none came for this long.
    pub idle: Option<Duration>,
    /// Keep each pose's age on arrival where the clocks are comparable
    /// ([`ListenSummary::latencies_us`], [`ListenSummary::not_comparable`]).
    pub latency: bool,
    /// Publish each pose on this local iceoryx2 service too, so that programs on the far host
    /// read it with the same zero-copy subscriber as on the rig (`omnitrack listen --services`).
    pub republish: Option<String>,
}

/// Receives poses from Zenoh key `key`, one line each to `out`, until `stop` is set, `count`
/// samples came, or none came for `idle` (when given).
pub fn listen(
    key: &str,
    endpoints: &Endpoints,
    options: &ListenOptions,
    stop: &AtomicBool,
    out: &mut dyn Write,
) -> Result<ListenSummary, LinkError> {
    let ListenOptions {
        count,
        idle,
        latency,
        republish,
    } = options;
    let (count, idle, latency) = (*count, *idle, *latency);
    let local = republish
        .as_deref()
        .map(SamplePublisher::<PoseSample>::create)
        .transpose()?;
    let session = open_session(endpoints)?;
    let subscriber = session
        .declare_subscriber(key.to_string())
        .with(zenoh::handlers::FifoChannel::new(4096))
        .wait()
        .map_err(|e| zenoh_error(&format!("cannot subscribe to {key}"), e))?;
    let mut summary = ListenSummary::default();
    let own_boot = boot_id();
    let mut last_seq: Option<u64> = None;
    let mut last_at = Instant::now();
    while !stop.load(Ordering::Relaxed) && count.is_none_or(|n| summary.received < n) {
        let got = subscriber
            .recv_timeout(Duration::from_millis(100))
            .map_err(|e| zenoh_error(&format!("cannot receive from {key}"), e))?;
        let Some(sample) = got else {
            if idle.is_some_and(|d| last_at.elapsed() >= d) {
                break;
            }
            continue;
        };
        let now = monotonic_ns();
        last_at = Instant::now();
        let bytes = sample.payload().to_bytes();
        let pose = PoseSample::from_wire(&bytes).map_err(|error| LinkError::Wire {
            key: key.to_string(),
            error,
        })?;
        if let Some(prev) = last_seq {
            if pose.sequence > prev + 1 {
                summary.missing += pose.sequence - prev - 1;
            }
        }
        last_seq = Some(pose.sequence);
        summary.received += 1;
        if latency {
            let attachment = sample.attachment().map(|a| a.to_bytes());
            match pose_age_us(pose.timestamp_ns, now, attachment.as_deref(), own_boot.as_deref()) {
                Ok(age) => summary.latencies_us.push(age),
                Err(why) => *summary.not_comparable.entry(why).or_default() += 1,
            }
        }
        if let Some(local) = &local {
            local.publish(&pose)?;
        }
        format_pose_line(&pose, out)?;
        writeln!(out)?;
    }
    let _ = session.close().wait();
    Ok(summary)
}

/// A flag set by SIGINT or SIGTERM (the subscriber processes' one, from omnitrack-io).
pub use omnitrack_io::publish::stop_on_signals;

#[cfg(test)]
mod tests {
    use super::*;

    const S: u64 = 1_000_000_000;

    fn from(boot: &str) -> Vec<u8> {
        format!("{CLOCK_ATTACHMENT}{boot}").into_bytes()
    }

    #[test]
    fn an_age_is_read_only_on_one_clock_and_for_a_live_stamp() {
        let me = Some("b0");
        let now = 5_000 * S;
        assert_eq!(pose_age_us(now - 2_000_000, now, Some(&from("b0")), me), Ok(2_000.0));
        // A replay printed 1,340 s here before: its stamps are its recording's time.
        assert_eq!(
            pose_age_us(now - 1_340 * S, now, Some(&from("b0")), me),
            Err(NotComparable::NotLive)
        );
        assert_eq!(
            pose_age_us(now + S, now, Some(&from("b0")), me),
            Err(NotComparable::NotLive)
        );
        assert_eq!(
            pose_age_us(now - 1_000, now, Some(&from("b1")), me),
            Err(NotComparable::OtherHost)
        );
        assert_eq!(
            pose_age_us(now - 1_000, now, Some(&from("b0")), None),
            Err(NotComparable::OtherHost)
        );
        assert_eq!(
            pose_age_us(now - 1_000, now, None, me),
            Err(NotComparable::UnknownSender)
        );
        assert_eq!(
            pose_age_us(now - 1_000, now, Some(b"something else"), me),
            Err(NotComparable::UnknownSender)
        );
    }

    #[test]
    fn this_machine_has_a_boot_id() {
        assert!(boot_id().is_some_and(|id| id.len() == 36), "{:?}", boot_id());
    }
}
