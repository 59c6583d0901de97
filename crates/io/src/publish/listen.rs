//! `omnitrack listen [--count N] [--status]`: subscribes to the pose service (or, with
//! `--status`, the status service) and prints one line per sample.
//!
//! Line format (one sample per line, space-separated `key=value`, fixed key order):
//!
//! ```text
//! seq=42 t=1700000000123456789ns status=tracking pos=[1.234567,-0.500000,1.600000] q=[0.999999,0.000000,0.001000,0.000000] sd_m=[0.0100,0.0100,0.0200] sd_deg=[0.100,0.100,0.050] inliers=57 xi=1.234e-5
//! ```
//!
//! - `seq`: [`PoseSample::sequence`]; `t`: [`PoseSample::timestamp_ns`] in nanoseconds;
//! - `status`: `initializing`, `tracking`, `lost` (`unknown(N)` for an unknown byte N);
//! - `pos`: position of `T_world_rig` in metres (6 decimals); `q`: its rotation `[w,x,y,z]`;
//! - `sd_m` / `sd_deg`: square roots of the covariance diagonal (translation in metres,
//!   rotation converted to degrees);
//! - `inliers`: accepted correspondences; `xi`: ξ in rad² (scientific notation).
//!
//! Status lines (`--status`), same rules:
//!
//! ```text
//! seq=7 t=1700000000123456789ns source="ladybug2" pid=4242 state=tracking searching=none search=none sensors=6 fps=[30.0,30.0,30.0,30.0,30.0,29.9] dropped=[0,0,0,0,0,2] p50_us=[capture=812,edges=3950,match=420,solve=610,publish=48,frame=8400,track=1700] p99_us=[…]
//! ```
//!
//! - `source`: the publishing rig's name, quoted and escaped as a Rust string; `pid`: the
//!   publishing process;
//! - `state`: the tracker's [`TrackerState`]; `searching`: the search running now
//!   ([`SearchKind`]: `none`, `initialising`, `relocalising`, `reinitialising`); `search`:
//!   the last search's [`SearchState`] (`none`, `as_given`, `widened` followed by `:D` metres,
//!   `no_cells`);
//! - `sensors`, then per sensor the delivered images per second and the images lost since start;
//! - `p50_us` / `p99_us`: per [`Stage`], in microseconds (0 = not measured yet).

use std::io::Write;
use std::time::Duration;

use super::{
    PoseSample, PoseSubscriber, PublishError, SearchKind, SearchState, Stage, StatusSample, StatusSubscriber,
    TrackerState,
};

/// Writes one sample as one line in the format above (without the newline).
pub fn format_pose_line(s: &PoseSample, out: &mut dyn Write) -> std::io::Result<()> {
    let p = &s.position_m;
    let q = &s.rotation_wxyz;
    let sd = |i: usize| s.covariance[i * 7].max(0.0).sqrt();
    write!(out, "seq={} t={}ns status=", s.sequence, s.timestamp_ns)?;
    match TrackerState::try_from(s.status) {
        Ok(st) => write!(out, "{}", st.as_str())?,
        Err(b) => write!(out, "unknown({b})")?,
    }
    write!(
        out,
        " pos=[{:.6},{:.6},{:.6}] q=[{:.6},{:.6},{:.6},{:.6}] sd_m=[{:.4},{:.4},{:.4}] sd_deg=[{:.3},{:.3},{:.3}] \
         inliers={} xi={:.3e}",
        p[0],
        p[1],
        p[2],
        q[0],
        q[1],
        q[2],
        q[3],
        sd(0),
        sd(1),
        sd(2),
        sd(3).to_degrees(),
        sd(4).to_degrees(),
        sd(5).to_degrees(),
        s.inliers,
        s.xi_rad2
    )
}

/// Writes one status sample as one line in the format above (without the newline).
pub fn format_status_line(s: &StatusSample, out: &mut dyn Write) -> std::io::Result<()> {
    write!(
        out,
        "seq={} t={}ns source={:?} pid={} state=",
        s.sequence,
        s.timestamp_ns,
        s.source(),
        s.pid
    )?;
    match TrackerState::try_from(s.tracker_state) {
        Ok(st) => write!(out, "{}", st.as_str())?,
        Err(b) => write!(out, "unknown({b})")?,
    }
    write!(out, " searching=")?;
    match SearchKind::from_wire(s.searching) {
        Ok(kind) => write!(out, "{}", SearchKind::word(kind))?,
        Err(b) => write!(out, "unknown({b})")?,
    }
    write!(out, " search=")?;
    match SearchState::try_from(s.search) {
        Ok(SearchState::Widened) => write!(out, "widened:{:.1}", s.search_widened_to_m)?,
        Ok(st) => write!(out, "{}", st.as_str())?,
        Err(b) => write!(out, "unknown({b})")?,
    }
    let n = usize::from(s.sensor_count).min(s.frame_rate_hz.len());
    write!(out, " sensors={n} fps=[")?;
    for (i, f) in s.frame_rate_hz[..n].iter().enumerate() {
        write!(out, "{}{f:.1}", if i > 0 { "," } else { "" })?;
    }
    write!(out, "] dropped=[")?;
    for (i, d) in s.frames_dropped[..n].iter().enumerate() {
        write!(out, "{}{d}", if i > 0 { "," } else { "" })?;
    }
    for (key, values) in [("p50_us", &s.stage_p50_us), ("p99_us", &s.stage_p99_us)] {
        write!(out, "] {key}=[")?;
        for (i, stage) in Stage::ALL.iter().enumerate() {
            write!(
                out,
                "{}{}={}",
                if i > 0 { "," } else { "" },
                stage.name(),
                values[stage.index()]
            )?;
        }
    }
    write!(out, "]")
}

/// Why `omnitrack listen` stopped.
#[derive(Debug, thiserror::Error)]
pub enum ListenError {
    /// The subscription failed (no shared memory, a service of another layout, …).
    #[error("{0}")]
    Service(#[from] PublishError),
    /// The output went away (a closed pipe) or could not be written.
    #[error("writing to output: {0}")]
    Output(#[source] std::io::Error),
}

/// Subscribes to `service` and prints one line per received pose sample to `out` (format in the
/// module doc), flushing after each; stops after `count` samples, or never when `None`. A sample
/// already published before the call (history 1) is printed first. Waits on the service's event,
/// so an idle listener sleeps.
pub fn listen(service: &str, count: Option<u64>, out: &mut dyn Write) -> Result<(), ListenError> {
    listen_as(service, count, out, format_pose_line)
}

/// [`listen`] for the status service: one line per [`StatusSample`] (format in the module doc).
pub fn listen_status(service: &str, count: Option<u64>, out: &mut dyn Write) -> Result<(), ListenError> {
    listen_status_as(service, count, out, format_status_line)
}

/// [`listen`] with the caller's line `format` (`omnitrack listen --json`: one JSON object per
/// line); the newline and the flush after each sample are this function's.
pub fn listen_as(
    service: &str,
    count: Option<u64>,
    out: &mut dyn Write,
    format: fn(&PoseSample, &mut dyn Write) -> std::io::Result<()>,
) -> Result<(), ListenError> {
    let subscriber = PoseSubscriber::create(service)?;
    print_samples(|t| subscriber.wait(t), format, count, out)
}

/// [`listen_status`] with the caller's line `format`.
pub fn listen_status_as(
    service: &str,
    count: Option<u64>,
    out: &mut dyn Write,
    format: fn(&StatusSample, &mut dyn Write) -> std::io::Result<()>,
) -> Result<(), ListenError> {
    let subscriber = StatusSubscriber::create(service)?;
    print_samples(|t| subscriber.wait(t), format, count, out)
}

fn print_samples<T>(
    mut wait: impl FnMut(Duration) -> Result<Option<T>, PublishError>,
    format: fn(&T, &mut dyn Write) -> std::io::Result<()>,
    count: Option<u64>,
    out: &mut dyn Write,
) -> Result<(), ListenError> {
    let mut printed = 0u64;
    while count.is_none_or(|n| printed < n) {
        let Some(sample) = wait(Duration::from_secs(1))? else {
            continue;
        };
        format(&sample, out)
            .and_then(|_| writeln!(out))
            .and_then(|_| out.flush())
            .map_err(ListenError::Output)?;
        printed += 1;
    }
    Ok(())
}
