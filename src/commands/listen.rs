//! `omnitrack listen`: one line per sample of the pose service (or, with `--status`, the status
//! service), as `key=value` text or, with `--json`, one JSON object per line
//! (docs/interfaces.md, "`omnitrack listen` lines" and "JSON output").

use super::CommandResult;
use omnitrack::publish::{
    format_pose_line, format_status_line, listen_as, listen_status_as, PoseSample, SearchKind, SearchState, Stage,
    StatusSample, TrackerState,
};
use serde::ser::{Serialize, SerializeMap, Serializer};
use std::io::Write;

/// `listen`'s arguments.
#[derive(clap::Args)]
pub struct Args {
    /// Stop after N samples (default: until Ctrl-C).
    #[arg(long)]
    count: Option<u64>,
    /// The status service instead: tracker state, search, per-sensor rates and drops, stage
    /// timings.
    #[arg(long)]
    status: bool,
    /// The tracker's service prefix (its `run --services`): PREFIX/pose, PREFIX/status.
    #[arg(long, value_name = "PREFIX", default_value = "omnitrack")]
    services: String,
    /// One JSON object per sample and line instead of key=value text (fields in
    /// docs/interfaces.md; a number that is not finite is null).
    #[arg(long)]
    json: bool,
}

pub fn run(a: Args) -> CommandResult {
    let mut out = std::io::stdout().lock();
    if a.status {
        let format = if a.json { status_json } else { format_status_line };
        listen_status_as(&super::service_name(&a.services, "status")?, a.count, &mut out, format)?;
    } else {
        let format = if a.json { pose_json } else { format_pose_line };
        listen_as(&super::service_name(&a.services, "pose")?, a.count, &mut out, format)?;
    }
    Ok(())
}

/// A wire byte's word, or `unknown(N)` for a byte this build does not know (a newer tracker).
fn word<T>(byte: u8, known: impl FnOnce(u8) -> Option<T>, as_str: impl FnOnce(T) -> &'static str) -> String {
    known(byte).map_or_else(|| format!("unknown({byte})"), |v| as_str(v).to_string())
}

/// One pose sample as a JSON object: the fields of `PoseSample` under their own names, the
/// status as its word.
#[derive(serde::Serialize)]
pub struct PoseJson<'a> {
    sequence: u64,
    timestamp_ns: u64,
    status: String,
    position_m: &'a [f64],
    rotation_wxyz: &'a [f64],
    covariance: &'a [f64],
    inliers: u32,
    xi_rad2: f64,
}

impl<'a> From<&'a PoseSample> for PoseJson<'a> {
    fn from(s: &'a PoseSample) -> Self {
        PoseJson {
            sequence: s.sequence,
            timestamp_ns: s.timestamp_ns,
            status: word(s.status, |b| TrackerState::try_from(b).ok(), TrackerState::as_str),
            position_m: &s.position_m,
            rotation_wxyz: &s.rotation_wxyz,
            covariance: &s.covariance,
            inliers: s.inliers,
            xi_rad2: s.xi_rad2,
        }
    }
}

/// The per-stage microseconds of a status sample as an object keyed by stage name, in
/// `Stage::ALL` order.
struct Stages<'a>(&'a [u32]);

impl Serialize for Stages<'_> {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut map = serializer.serialize_map(Some(Stage::ALL.len()))?;
        for stage in Stage::ALL {
            map.serialize_entry(stage.name(), &self.0[stage.index()])?;
        }
        map.end()
    }
}

/// One sensor of a status sample.
#[derive(serde::Serialize)]
struct SensorJson {
    frame_rate_hz: f32,
    frames_dropped: u64,
}

/// One status sample as a JSON object.
#[derive(serde::Serialize)]
struct StatusJson<'a> {
    sequence: u64,
    timestamp_ns: u64,
    source: &'a str,
    pid: u32,
    state: String,
    searching: String,
    search: String,
    search_widened_to_m: f32,
    sensors: Vec<SensorJson>,
    stage_p50_us: Stages<'a>,
    stage_p99_us: Stages<'a>,
}

/// (A write error keeps its kind through serde_json: a reader gone away stays a closed pipe, which
/// ends `listen` quietly.)
fn pose_json(s: &PoseSample, out: &mut dyn Write) -> std::io::Result<()> {
    serde_json::to_writer(out, &PoseJson::from(s)).map_err(std::io::Error::from)
}

fn status_json(s: &StatusSample, out: &mut dyn Write) -> std::io::Result<()> {
    let n = usize::from(s.sensor_count).min(s.frame_rate_hz.len());
    let json = StatusJson {
        sequence: s.sequence,
        timestamp_ns: s.timestamp_ns,
        source: s.source(),
        pid: s.pid,
        state: word(
            s.tracker_state,
            |b| TrackerState::try_from(b).ok(),
            TrackerState::as_str,
        ),
        searching: word(s.searching, |b| SearchKind::from_wire(b).ok(), SearchKind::word),
        search: word(s.search, |b| SearchState::try_from(b).ok(), SearchState::as_str),
        search_widened_to_m: s.search_widened_to_m,
        sensors: (0..n)
            .map(|k| SensorJson {
                frame_rate_hz: s.frame_rate_hz[k],
                frames_dropped: s.frames_dropped[k],
            })
            .collect(),
        stage_p50_us: Stages(&s.stage_p50_us),
        stage_p99_us: Stages(&s.stage_p99_us),
    };
    serde_json::to_writer(out, &json).map_err(std::io::Error::from)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every field of a pose sample comes out under its name, an infinite covariance as null,
    /// an unknown status byte as its number.
    #[test]
    fn a_pose_sample_is_one_json_object_with_every_field() {
        let mut s = PoseSample {
            timestamp_ns: 1_700_000_000_123_456_789,
            sequence: 42,
            status: TrackerState::Tracking as u8,
            position_m: [1.5, -2.25, 1.6],
            rotation_wxyz: [1.0, 0.0, 0.0, 0.0],
            covariance: [0.0; 36],
            inliers: 57,
            xi_rad2: 1.25e-5,
        };
        s.covariance[0] = 1e-4;
        s.covariance[35] = f64::INFINITY;
        let mut out = Vec::new();
        pose_json(&s, &mut out).unwrap();
        let v: serde_json::Value = serde_json::from_slice(&out).unwrap();
        assert_eq!(v["sequence"], 42);
        assert_eq!(v["timestamp_ns"], 1_700_000_000_123_456_789u64);
        assert_eq!(v["status"], "tracking");
        assert_eq!(v["position_m"], serde_json::json!([1.5, -2.25, 1.6]));
        assert_eq!(v["rotation_wxyz"], serde_json::json!([1.0, 0.0, 0.0, 0.0]));
        assert_eq!(v["covariance"].as_array().unwrap().len(), 36);
        assert_eq!(v["covariance"][0], 1e-4);
        assert!(v["covariance"][35].is_null());
        assert_eq!(v["inliers"], 57);
        assert_eq!(v["xi_rad2"], 1.25e-5);
        assert_eq!(v.as_object().unwrap().len(), 8, "{v}");
        s.status = 9;
        let mut out = Vec::new();
        pose_json(&s, &mut out).unwrap();
        let v: serde_json::Value = serde_json::from_slice(&out).unwrap();
        assert_eq!(v["status"], "unknown(9)");
    }
}
