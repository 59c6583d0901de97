//! The tracker's status (`omnitrack/status`) as a `diagnostic_msgs/DiagnosticStatus`, the form
//! `rqt_robot_monitor`, the diagnostic aggregator and `ros2 topic echo /diagnostics` read.
//!
//! Level: OK while tracking with no search under way; WARN while initialising, or while a search
//! runs; ERROR when lost; STALE when no status came for [`STALE_AFTER`] (the tracker stopped or
//! its service moved). Name `omnitrack: tracker`, hardware id the rig's name (the status
//! message's `source`). The values are the status message's fields by name, the per-sensor and
//! per-stage ones one key each, plus this publisher's own counters and clock offset.

use crate::clock::ClockOffset;
use crate::msg::{DiagnosticStatus, KeyValue, ERROR, OK, STALE, WARN};
use omnitrack_io::publish::{SearchKind, SearchState, Stage, StatusSample, TrackerState};
use std::time::Duration;

/// The `name` of the status in the diagnostic message.
pub const NAME: &str = "omnitrack: tracker";

/// No status for this long is STALE (the tracker sends one every 250 ms).
pub const STALE_AFTER: Duration = Duration::from_secs(2);

/// What this publisher did so far, reported beside the tracker's status.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counters {
    /// Poses received from the pose service.
    pub received: u64,
    /// Poses published (status tracking).
    pub published: u64,
    /// Poses not published: initializing or lost (the last good pose, not a current one), or a
    /// quaternion that is not a rotation.
    pub not_tracking: u64,
    /// `map → odom` transforms published.
    pub tf_published: u64,
    /// Poses with no `map → odom`: no odometry around their stamp.
    pub tf_no_odometry: u64,
}

fn kv(key: &str, value: impl ToString) -> KeyValue {
    KeyValue {
        key: key.to_string(),
        value: value.to_string(),
    }
}

/// The diagnostic status of the tracker's `status`, with this publisher's `counters` and
/// `offset`.
pub fn from_status(status: &StatusSample, counters: &Counters, offset: &ClockOffset) -> DiagnosticStatus {
    let state = TrackerState::try_from(status.tracker_state);
    let searching = SearchKind::from_wire(status.searching);
    let (level, message) = match (state, searching) {
        (Ok(TrackerState::Tracking), Ok(None)) => (OK, "tracking".to_string()),
        (Ok(TrackerState::Tracking), Ok(Some(k))) => (WARN, format!("tracking, {k}")),
        (Ok(TrackerState::Initialising), Ok(k)) => (WARN, format!("initializing, search: {}", SearchKind::word(k))),
        (Ok(TrackerState::Lost), Ok(None)) => (ERROR, "lost".to_string()),
        (Ok(TrackerState::Lost), Ok(Some(k))) => (ERROR, format!("lost, {k}")),
        (Err(b), _) => (ERROR, format!("unknown tracker state {b}")),
        (_, Err(b)) => (ERROR, format!("unknown search {b}")),
    };
    let mut values = vec![
        kv(
            "state",
            state.map_or_else(|b| b.to_string(), |s| s.as_str().to_string()),
        ),
        kv(
            "searching",
            searching.map_or_else(|b| b.to_string(), |k| SearchKind::word(k).to_string()),
        ),
        kv(
            "last search",
            SearchState::try_from(status.search).map_or_else(|b| b.to_string(), |s| s.as_str().to_string()),
        ),
        kv("search widened to (m)", status.search_widened_to_m),
        kv("sensors", status.sensor_count),
    ];
    let sensors = usize::from(status.sensor_count).min(status.frame_rate_hz.len());
    for i in 0..sensors {
        values.push(kv(
            &format!("sensor {i} rate (Hz)"),
            format!("{:.1}", status.frame_rate_hz[i]),
        ));
        values.push(kv(&format!("sensor {i} frames dropped"), status.frames_dropped[i]));
    }
    for stage in Stage::ALL {
        let i = stage.index();
        values.push(kv(&format!("{} p50 (us)", stage.name()), status.stage_p50_us[i]));
        values.push(kv(&format!("{} p99 (us)", stage.name()), status.stage_p99_us[i]));
    }
    values.extend([
        kv("pid", status.pid),
        kv("status sequence", status.sequence),
        kv("poses received", counters.received),
        kv("poses published", counters.published),
        kv("poses not published (not tracking)", counters.not_tracking),
        kv("map to odom published", counters.tf_published),
        kv(
            "map to odom skipped (no odometry at the pose's stamp)",
            counters.tf_no_odometry,
        ),
        kv("clock offset system - monotonic (ns)", offset.offset_ns),
        kv("clock offset uncertainty (ns)", offset.uncertainty_ns),
    ]);
    DiagnosticStatus {
        level,
        name: NAME.to_string(),
        message,
        hardware_id: status.source().to_string(),
        values,
    }
}

/// The status sent when none came for `since` on `service`.
pub fn stale(service: &str, since: Duration, counters: &Counters, hardware_id: &str) -> DiagnosticStatus {
    DiagnosticStatus {
        level: STALE,
        name: NAME.to_string(),
        message: format!("no status from {service} for {:.1} s", since.as_secs_f64()),
        hardware_id: hardware_id.to_string(),
        values: vec![
            kv("poses received", counters.received),
            kv("poses published", counters.published),
        ],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn value<'a>(s: &'a DiagnosticStatus, key: &str) -> &'a str {
        &s.values
            .iter()
            .find(|v| v.key == key)
            .unwrap_or_else(|| panic!("{key}: {s:?}"))
            .value
    }

    #[test]
    fn the_level_follows_the_trackers_state_and_search() {
        let offset = ClockOffset {
            offset_ns: 12,
            uncertainty_ns: 3,
        };
        let c = Counters::default();
        let mut s = StatusSample {
            tracker_state: TrackerState::Tracking as u8,
            sensor_count: 2,
            ..StatusSample::default()
        };
        s.set_source("ladybug2");
        s.frame_rate_hz[1] = 29.96;
        s.frames_dropped[1] = 4;
        s.stage_p99_us[Stage::Frame.index()] = 21_000;
        let d = from_status(&s, &c, &offset);
        assert_eq!(
            (d.level, d.message.as_str(), d.hardware_id.as_str()),
            (OK, "tracking", "ladybug2")
        );
        assert_eq!(d.name, NAME);
        assert_eq!(value(&d, "sensor 1 rate (Hz)"), "30.0");
        assert_eq!(value(&d, "sensor 1 frames dropped"), "4");
        assert_eq!(value(&d, "frame p99 (us)"), "21000");
        assert_eq!(value(&d, "clock offset system - monotonic (ns)"), "12");
        assert!(d.values.iter().all(|v| !v.key.starts_with("sensor 2")));

        s.searching = SearchKind::wire(Some(SearchKind::Relocalisation));
        assert_eq!(from_status(&s, &c, &offset).level, WARN);
        s.tracker_state = TrackerState::Lost as u8;
        let d = from_status(&s, &c, &offset);
        assert_eq!((d.level, d.message.as_str()), (ERROR, "lost, relocalising"));
        s.tracker_state = TrackerState::Initialising as u8;
        s.searching = SearchKind::wire(Some(SearchKind::Initialisation));
        let d = from_status(&s, &c, &offset);
        assert_eq!(
            (d.level, d.message.as_str()),
            (WARN, "initializing, search: initialising")
        );
        s.tracker_state = 7;
        assert_eq!(from_status(&s, &c, &offset).message, "unknown tracker state 7");
        let d = stale("omnitrack/status", Duration::from_millis(2500), &c, "ladybug2");
        assert_eq!(
            (d.level, d.message.as_str()),
            (STALE, "no status from omnitrack/status for 2.5 s")
        );
    }
}
