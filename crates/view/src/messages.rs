//! The view's messages, as JSON bytes in the schemas of [`crate::schemas`].
//!
//! In: pose and status samples as the tracker publishes them, the model's segments, the
//! trajectory so far. Out: the serialised messages (the same bytes go to the MCAP file and to
//! every WebSocket client).
//!
//! Stamps are the samples' own (the tracker's capture clock: a replay's recording time, a live
//! camera's monotonic time), so a recording's MCAP plays on the recording's time line.

use nalgebra::{Matrix3, SymmetricEigen, UnitQuaternion};
use omnitrack_core::status::{SearchKind, SearchState, TrackerState};
use omnitrack_io::publish::{PoseSample, Stage, StatusSample};
use serde_json::{json, Value};

use crate::schemas::{RIG_FRAME, WORLD_FRAME};

/// Colours of the scene, RGBA in 0..1.
const MODEL_COLOUR: [f64; 4] = [0.55, 0.6, 0.65, 1.0];
const TRAJECTORY_COLOUR: [f64; 4] = [0.1, 0.8, 0.2, 1.0];
const ELLIPSOID_COLOUR: [f64; 4] = [1.0, 0.5, 0.0, 0.35];

/// A time in Foxglove's `{sec, nsec}` form.
pub fn time(ns: u64) -> Value {
    json!({"sec": ns / 1_000_000_000, "nsec": ns % 1_000_000_000})
}

fn colour(c: [f64; 4]) -> Value {
    json!({"r": c[0], "g": c[1], "b": c[2], "a": c[3]})
}

fn point(p: [f64; 3]) -> Value {
    json!({"x": p[0], "y": p[1], "z": p[2]})
}

fn quaternion_wxyz(q: [f64; 4]) -> Value {
    json!({"x": q[1], "y": q[2], "z": q[3], "w": q[0]})
}

fn identity_pose() -> Value {
    json!({"position": point([0.0; 3]), "orientation": quaternion_wxyz([1.0, 0.0, 0.0, 0.0])})
}

fn bytes(v: &Value) -> Vec<u8> {
    // A Value built here always serialises (its keys are strings, its numbers finite or null).
    serde_json::to_vec(v).unwrap_or_default()
}

/// The state word of a sample's status byte.
pub fn state_word(status: u8) -> &'static str {
    TrackerState::try_from(status).map_or("unknown", TrackerState::as_str)
}

/// Whether a sample carries a current pose (status tracking).
pub fn is_tracking(s: &PoseSample) -> bool {
    s.pose_status() == Ok(TrackerState::Tracking)
}

/// `foxglove.PoseInFrame` of a sample.
pub fn pose_in_frame(s: &PoseSample) -> Vec<u8> {
    bytes(&json!({
        "timestamp": time(s.timestamp_ns),
        "frame_id": WORLD_FRAME,
        "pose": {"position": point(s.position_m), "orientation": quaternion_wxyz(s.rotation_wxyz)},
    }))
}

/// `foxglove.FrameTransform` world → rig of a sample.
pub fn frame_transform(s: &PoseSample) -> Vec<u8> {
    bytes(&json!({
        "timestamp": time(s.timestamp_ns),
        "parent_frame_id": WORLD_FRAME,
        "child_frame_id": RIG_FRAME,
        "translation": point(s.position_m),
        "rotation": quaternion_wxyz(s.rotation_wxyz),
    }))
}

fn sigmas(c: &[f64; 36], first: usize) -> [f64; 3] {
    std::array::from_fn(|i| {
        let v = c[(first + i) * 6 + first + i];
        if v.is_finite() && v >= 0.0 {
            v.sqrt()
        } else {
            f64::NAN
        }
    })
}

/// `omnitrack.PoseSample` of a sample: every field, the status as its word, and the standard
/// deviations of the covariance's diagonal (the numbers a plot of the uncertainty wants).
pub fn pose_sample(s: &PoseSample) -> Vec<u8> {
    let finite = |v: f64| if v.is_finite() { json!(v) } else { Value::Null };
    bytes(&json!({
        "timestamp_ns": s.timestamp_ns,
        "sequence": s.sequence,
        "status": state_word(s.status),
        "position_m": s.position_m.map(finite),
        "rotation_wxyz": s.rotation_wxyz.map(finite),
        "covariance": s.covariance.iter().map(|&v| finite(v)).collect::<Vec<_>>(),
        "position_sigma_m": sigmas(&s.covariance, 0).map(finite),
        "rotation_sigma_deg": sigmas(&s.covariance, 3).map(|v| finite(v.to_degrees())),
        "inliers": s.inliers,
        "xi_rad2": finite(s.xi_rad2),
    }))
}

/// The 3σ ellipsoid of a position covariance: its axes' full lengths (m) and its orientation
/// in the world (x, y, z along the axes). `None` when the block is not a finite, positive
/// semi-definite matrix.
pub fn ellipsoid(c: &[f64; 36]) -> Option<([f64; 3], UnitQuaternion<f64>)> {
    let m = Matrix3::from_fn(|r, k| c[r * 6 + k]);
    if m.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let eig = SymmetricEigen::new((m + m.transpose()) * 0.5);
    if eig.eigenvalues.iter().any(|&v| v < -1e-12) {
        return None;
    }
    let mut axes = eig.eigenvectors;
    if axes.determinant() < 0.0 {
        axes.set_column(2, &-axes.column(2));
    }
    let rotation = UnitQuaternion::from_matrix(&axes);
    let size = std::array::from_fn(|i| 6.0 * eig.eigenvalues[i].max(0.0).sqrt());
    Some((size, rotation))
}

/// `foxglove.SceneUpdate` of the position's 3σ ellipsoid at a sample's position (one entity,
/// replaced by every pose); `None` when its covariance has none.
pub fn uncertainty(s: &PoseSample) -> Option<Vec<u8>> {
    let (size, r) = ellipsoid(&s.covariance)?;
    let orientation = json!({"x": r.i, "y": r.j, "z": r.k, "w": r.w});
    Some(bytes(&json!({
        "deletions": [],
        "entities": [entity(s.timestamp_ns, "position 3 sigma", json!({
            "spheres": [{
                "pose": {"position": point(s.position_m), "orientation": orientation},
                "size": point(size),
                "color": colour(ELLIPSOID_COLOUR),
            }],
        }))],
    })))
}

fn entity(timestamp_ns: u64, id: &str, primitives: Value) -> Value {
    let mut e = json!({
        "timestamp": time(timestamp_ns),
        "frame_id": WORLD_FRAME,
        "id": id,
        // Zero: the entity stays until an entity of the same id replaces it.
        "lifetime": time(0),
        "frame_locked": false,
        "metadata": [], "arrows": [], "cubes": [], "spheres": [], "cylinders": [], "lines": [],
        "triangles": [], "texts": [], "models": [],
    });
    if let (Some(e), Some(p)) = (e.as_object_mut(), primitives.as_object()) {
        for (k, v) in p {
            e.insert(k.clone(), v.clone());
        }
    }
    e
}

fn line(kind: u8, points: Vec<Value>, thickness: f64, c: [f64; 4]) -> Value {
    json!({
        "type": kind, "pose": identity_pose(), "thickness": thickness, "scale_invariant": true,
        "points": points, "color": colour(c), "colors": [], "indices": [],
    })
}

/// `foxglove.SceneUpdate` of the model's segments: one entity, a line list of segment end points.
pub fn model(segments: &[([f64; 3], [f64; 3])], timestamp_ns: u64) -> Vec<u8> {
    let points = segments.iter().flat_map(|(a, b)| [point(*a), point(*b)]).collect();
    bytes(&json!({
        "deletions": [],
        "entities": [entity(timestamp_ns, "model", json!({"lines": [line(2, points, 1.5, MODEL_COLOUR)]}))],
    }))
}

/// `foxglove.SceneUpdate` of one piece of the trajectory (a line strip through `positions`),
/// an entity of its own (`trajectory <piece>`) that stays: the pieces together are the whole
/// trajectory, and each position is sent once, so the file grows with the run, not its square.
pub fn trajectory_piece(piece: u64, positions: &[[f64; 3]], timestamp_ns: u64) -> Vec<u8> {
    let points = positions.iter().map(|p| point(*p)).collect();
    bytes(&json!({
        "deletions": [],
        "entities": [entity(
            timestamp_ns,
            &format!("trajectory {piece}"),
            json!({"lines": [line(0, points, 3.0, TRAJECTORY_COLOUR)]}),
        )],
    }))
}

fn stages(v: &[u32]) -> Value {
    Value::Object(
        Stage::ALL
            .iter()
            .map(|s| (s.name().to_string(), json!(v[s.index()])))
            .collect(),
    )
}

/// `omnitrack.StatusSample` of a status sample.
pub fn status_sample(s: &StatusSample) -> Vec<u8> {
    let n = usize::from(s.sensor_count).min(s.frame_rate_hz.len());
    bytes(&json!({
        "timestamp_ns": s.timestamp_ns,
        "sequence": s.sequence,
        "state": state_word(s.tracker_state),
        "searching": SearchKind::from_wire(s.searching).map_or("unknown", SearchKind::word),
        "search": SearchState::try_from(s.search).map_or("unknown", SearchState::as_str),
        "source": s.source(),
        "pid": s.pid,
        "frame_rate_hz": s.frame_rate_hz[..n].iter().map(|&f| if f.is_finite() { json!(f) } else { Value::Null }).collect::<Vec<_>>(),
        "frames_dropped": &s.frames_dropped[..n],
        "stage_p50_us": stages(&s.stage_p50_us),
        "stage_p99_us": stages(&s.stage_p99_us),
    }))
}

/// Log levels of `foxglove.Log`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Level {
    Info = 2,
    Warning = 3,
}

/// `foxglove.Log` of one line.
pub fn log(timestamp_ns: u64, level: Level, message: &str) -> Vec<u8> {
    bytes(&json!({
        "timestamp": time(timestamp_ns),
        "level": level as u8,
        "message": message,
        "name": "omnitrack",
        "file": "",
        "line": 0,
    }))
}

/// The line to log when the tracker's state or search changes from `before` to `now` (two
/// status samples, or a first one), and its level; `None` when neither changed.
pub fn state_change(before: Option<&StatusSample>, now: &StatusSample) -> Option<(Level, String)> {
    let key = |s: &StatusSample| (s.tracker_state, s.searching, s.search);
    if before.is_some_and(|b| key(b) == key(now)) {
        return None;
    }
    let state = state_word(now.tracker_state);
    let searching = SearchKind::from_wire(now.searching).map_or("unknown", SearchKind::word);
    let level = if state == "lost" { Level::Warning } else { Level::Info };
    let mut line = format!("{} {state}, searching: {searching}", now.source());
    if let Ok(SearchState::Widened) = SearchState::try_from(now.search) {
        line.push_str(&format!(
            " (the search widened to {:.1} m: no visibility node in the volume)",
            now.search_widened_to_m
        ));
    }
    Some((level, line))
}

/// The model's segments as end-point pairs.
pub fn segments(model: &omnitrack_core::model::Model) -> Vec<([f64; 3], [f64; 3])> {
    model
        .segments
        .iter()
        .map(|s| (s.a.coords.into(), s.b.coords.into()))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn tracking(position: [f64; 3]) -> PoseSample {
        let mut s = PoseSample {
            timestamp_ns: 12_345_678_901,
            sequence: 7,
            status: TrackerState::Tracking as u8,
            position_m: position,
            rotation_wxyz: [0.5f64.sqrt(), 0.0, 0.0, 0.5f64.sqrt()],
            inliers: 40,
            xi_rad2: 1e-5,
            ..PoseSample::default()
        };
        // σ 1, 2, 3 cm along x, y, z; 0.5° about every axis.
        for (i, sigma) in [0.01, 0.02, 0.03].into_iter().enumerate() {
            s.covariance[i * 6 + i] = sigma * sigma;
        }
        for i in 3..6 {
            s.covariance[i * 6 + i] = 0.5f64.to_radians().powi(2);
        }
        s
    }

    #[test]
    fn a_pose_reads_back_as_foxglove_has_it_quaternion_order_and_time_split() {
        let s = tracking([1.0, -2.0, 1.5]);
        let v: Value = serde_json::from_slice(&pose_in_frame(&s)).unwrap();
        assert_eq!(v["timestamp"], json!({"sec": 12, "nsec": 345_678_901}));
        assert_eq!(v["frame_id"], "world");
        assert_eq!(v["pose"]["position"], json!({"x": 1.0, "y": -2.0, "z": 1.5}));
        assert_eq!(v["pose"]["orientation"]["w"], s.rotation_wxyz[0]);
        assert_eq!(v["pose"]["orientation"]["z"], s.rotation_wxyz[3]);
        let t: Value = serde_json::from_slice(&frame_transform(&s)).unwrap();
        assert_eq!(
            (t["parent_frame_id"].as_str(), t["child_frame_id"].as_str()),
            (Some("world"), Some("rig"))
        );
        let p: Value = serde_json::from_slice(&pose_sample(&s)).unwrap();
        assert_eq!(p["status"], "tracking");
        assert_eq!(p["covariance"].as_array().unwrap().len(), 36);
        let sig = p["position_sigma_m"].as_array().unwrap();
        assert!((sig[1].as_f64().unwrap() - 0.02).abs() < 1e-12);
        assert!((p["rotation_sigma_deg"][2].as_f64().unwrap() - 0.5).abs() < 1e-9);
    }

    #[test]
    fn the_ellipsoid_has_the_covariances_axes_at_three_sigma() {
        let mut s = tracking([0.0; 3]);
        // Rotate the covariance by 30° about z: the ellipsoid must turn with it.
        let r = nalgebra::Rotation3::from_axis_angle(&Vector3::z_axis(), 30f64.to_radians());
        let c = Matrix3::from_diagonal(&Vector3::new(1e-4, 4e-4, 9e-4));
        let turned = r.matrix() * c * r.matrix().transpose();
        for i in 0..3 {
            for k in 0..3 {
                s.covariance[i * 6 + k] = turned[(i, k)];
            }
        }
        let (size, q) = ellipsoid(&s.covariance).unwrap();
        let axes = q.to_rotation_matrix();
        // Each axis of the ellipsoid, turned back, is a principal axis of the original with 6σ.
        for (i, len) in size.iter().enumerate() {
            let dir = axes.matrix().column(i).into_owned();
            let variance = (dir.transpose() * turned * dir)[(0, 0)];
            assert!(
                (len - 6.0 * variance.sqrt()).abs() < 1e-9,
                "axis {i}: {len} vs {variance}"
            );
        }
        let mut sorted = size;
        sorted.sort_by(f64::total_cmp);
        for (got, want) in sorted.iter().zip([0.06, 0.12, 0.18]) {
            assert!((got - want).abs() < 1e-9, "{sorted:?}");
        }
        s.covariance[0] = f64::NAN;
        assert!(ellipsoid(&s.covariance).is_none());
        s.covariance[0] = -1.0;
        assert!(ellipsoid(&s.covariance).is_none(), "not a covariance");
    }

    #[test]
    fn a_state_change_is_logged_once_and_a_loss_as_a_warning() {
        let mut a = StatusSample::default();
        a.set_source("ladybug2");
        let first = state_change(None, &a).unwrap();
        assert_eq!(first.0, Level::Info);
        assert!(first.1.starts_with("ladybug2 initializing"), "{}", first.1);
        assert!(state_change(Some(&a), &a).is_none());
        let mut b = a;
        b.tracker_state = TrackerState::Lost as u8;
        b.searching = SearchKind::Reinitialisation as u8;
        let lost = state_change(Some(&a), &b).unwrap();
        assert_eq!(lost.0, Level::Warning);
        assert!(lost.1.contains("lost"), "{}", lost.1);
        let v: Value = serde_json::from_slice(&log(5, lost.0, &lost.1)).unwrap();
        assert_eq!(v["level"], 3);
    }

    #[test]
    fn the_model_is_a_line_list_of_its_segments_end_points() {
        let segs = [([0.0, 0.0, 0.0], [1.0, 0.0, 0.0]), ([0.0, 0.0, 0.0], [0.0, 0.0, 2.5])];
        let v: Value = serde_json::from_slice(&model(&segs, 0)).unwrap();
        let line = &v["entities"][0]["lines"][0];
        assert_eq!(line["type"], 2);
        let pts = line["points"].as_array().unwrap();
        assert_eq!(pts.len(), 4);
        assert_eq!(pts[3], json!({"x": 0.0, "y": 0.0, "z": 2.5}));
        let t: Value = serde_json::from_slice(&trajectory_piece(3, &[[0.0; 3], [1.0, 1.0, 0.0]], 9)).unwrap();
        assert_eq!(t["entities"][0]["id"], "trajectory 3");
        assert_eq!(t["entities"][0]["lines"][0]["type"], 0);
    }
}
