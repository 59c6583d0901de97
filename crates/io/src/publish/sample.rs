//! The messages on the wire: [`PoseSample`] (service `omnitrack/pose`) and [`StatusSample`]
//! (service `omnitrack/status`).
//!
//! Both are `#[repr(C)]` plain data with a stable iceoryx2 type name; a consumer in another
//! language (see `tools/examples/listen_pose.py`) declares the same C struct field for field and
//! the same type name, and iceoryx2 refuses to connect it when size, alignment or name differ.
//! Changing a field means a new type name (`.v2`), never a silent edit of `.v1`.

use iceoryx2::prelude::ZeroCopySend;
use nalgebra::Matrix6;

use omnitrack_core::geometry::{rotation_to_wxyz, Pose};
pub use omnitrack_core::status::{SearchKind, SearchState, TrackerState};

/// One pose of the rig, `T_world_rig`, as published on `omnitrack/pose` (docs/interfaces.md,
/// "Pose service"). C layout, 384 bytes, alignment 8:
///
/// | offset | field | type |
/// | --- | --- | --- |
/// | 0 | `timestamp_ns` | u64 |
/// | 8 | `sequence` | u64 |
/// | 16 | `status` | u8 (then 7 bytes padding) |
/// | 24 | `position_m` | [f64; 3] |
/// | 48 | `rotation_wxyz` | [f64; 4] |
/// | 80 | `covariance` | [f64; 36] |
/// | 368 | `inliers` | u32 (then 4 bytes padding) |
/// | 376 | `xi_rad2` | f64 |
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("omnitrack.PoseSample.v1")]
#[repr(C)]
pub struct PoseSample {
    /// Capture time of the frame the pose was solved from, in nanoseconds (the capture clock).
    pub timestamp_ns: u64,
    /// Frame counter.
    pub sequence: u64,
    /// [`TrackerState`] as a byte: 0 initializing, 1 tracking, 2 lost.
    pub status: u8,
    /// t of `T_world_rig`, metres, model coordinates.
    pub position_m: [f64; 3],
    /// R of `T_world_rig` as a unit quaternion `[w, x, y, z]`, w ≥ 0.
    pub rotation_wxyz: [f64; 4],
    /// 6×6 covariance, row-major over tx, ty, tz, rx, ry, rz (rotation as a small-angle vector in
    /// the world frame); units m², m·rad, rad².
    pub covariance: [f64; 36],
    /// Accepted correspondences used by the solution.
    pub inliers: u32,
    /// Koch–Teller ξ of the solution: mean squared angle between observed and predicted planes, rad².
    pub xi_rad2: f64,
}

impl Default for PoseSample {
    /// Initialising, identity pose, zero covariance, all counters 0.
    fn default() -> Self {
        PoseSample {
            timestamp_ns: 0,
            sequence: 0,
            status: TrackerState::Initialising as u8,
            position_m: [0.0; 3],
            rotation_wxyz: [1.0, 0.0, 0.0, 0.0],
            covariance: [0.0; 36],
            inliers: 0,
            xi_rad2: 0.0,
        }
    }
}

impl PoseSample {
    /// A sample from the tracker's result: `pose` is `T_world_rig`, `covariance` is over
    /// (tx, ty, tz, rx, ry, rz) and is written row-major.
    pub fn from_pose(
        timestamp_ns: u64,
        sequence: u64,
        status: TrackerState,
        pose: &Pose,
        covariance: &Matrix6<f64>,
        inliers: u32,
        xi_rad2: f64,
    ) -> Self {
        let t = &pose.translation.vector;
        let mut cov = [0.0; 36];
        for r in 0..6 {
            for c in 0..6 {
                cov[r * 6 + c] = covariance[(r, c)];
            }
        }
        PoseSample {
            timestamp_ns,
            sequence,
            status: status as u8,
            position_m: [t.x, t.y, t.z],
            rotation_wxyz: rotation_to_wxyz(&pose.rotation),
            covariance: cov,
            inliers,
            xi_rad2,
        }
    }

    /// The status byte as a [`TrackerState`]; `Err(byte)` when it is none of the known values.
    pub fn pose_status(&self) -> Result<TrackerState, u8> {
        TrackerState::try_from(self.status)
    }

    /// The pose back as `T_world_rig`; `Err` when the quaternion is not unit or not finite.
    pub fn pose(&self) -> Result<Pose, omnitrack_core::geometry::PoseError> {
        omnitrack_core::geometry::pose_from_parts(self.position_m, self.rotation_wxyz)
    }

    /// The covariance back as a matrix (rows and columns tx, ty, tz, rx, ry, rz).
    pub fn covariance_matrix(&self) -> Matrix6<f64> {
        Matrix6::from_row_slice(&self.covariance)
    }

    /// The sample as bytes for a network link: the C layout of the table above, little-endian,
    /// padding zero. The same bytes a little-endian subscriber reads from shared memory, so a
    /// far host decodes them with the same struct declaration, and no protocol of our own.
    pub fn to_wire(&self) -> [u8; POSE_WIRE_BYTES] {
        let mut b = [0u8; POSE_WIRE_BYTES];
        b[0..8].copy_from_slice(&self.timestamp_ns.to_le_bytes());
        b[8..16].copy_from_slice(&self.sequence.to_le_bytes());
        b[16] = self.status;
        let floats = self
            .position_m
            .iter()
            .chain(&self.rotation_wxyz)
            .chain(&self.covariance);
        for (i, v) in floats.enumerate() {
            b[24 + 8 * i..32 + 8 * i].copy_from_slice(&v.to_le_bytes());
        }
        b[368..372].copy_from_slice(&self.inliers.to_le_bytes());
        b[376..384].copy_from_slice(&self.xi_rad2.to_le_bytes());
        b
    }

    /// A sample from [`PoseSample::to_wire`]'s bytes; `Err` says in a few words why they are
    /// not one (wrong length, an unknown status byte).
    pub fn from_wire(b: &[u8]) -> Result<PoseSample, WireError> {
        if b.len() != POSE_WIRE_BYTES {
            return Err(WireError::Length(b.len()));
        }
        let u64_at = |o: usize| u64::from_le_bytes(b[o..o + 8].try_into().expect("8 bytes"));
        let f64_at = |o: usize| f64::from_le_bytes(b[o..o + 8].try_into().expect("8 bytes"));
        TrackerState::try_from(b[16]).map_err(WireError::Status)?;
        let mut s = PoseSample {
            timestamp_ns: u64_at(0),
            sequence: u64_at(8),
            status: b[16],
            inliers: u32::from_le_bytes(b[368..372].try_into().expect("4 bytes")),
            xi_rad2: f64_at(376),
            ..PoseSample::default()
        };
        for i in 0..3 {
            s.position_m[i] = f64_at(24 + 8 * i);
        }
        for i in 0..4 {
            s.rotation_wxyz[i] = f64_at(48 + 8 * i);
        }
        for i in 0..36 {
            s.covariance[i] = f64_at(80 + 8 * i);
        }
        Ok(s)
    }
}

/// Bytes of a [`PoseSample`] on a network link ([`PoseSample::to_wire`]): its C size.
pub const POSE_WIRE_BYTES: usize = 384;

/// Bytes that are not a [`PoseSample`] ([`PoseSample::from_wire`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum WireError {
    #[error("{0} bytes, a pose sample has {POSE_WIRE_BYTES}")]
    Length(usize),
    #[error("status byte {0} is none of initializing (0), tracking (1), lost (2)")]
    Status(u8),
}

#[cfg(test)]
mod wire_tests {
    use super::*;

    #[test]
    fn the_wire_bytes_are_the_c_layout_and_decode_back() {
        assert_eq!(std::mem::size_of::<PoseSample>(), POSE_WIRE_BYTES);
        let mut s = PoseSample {
            timestamp_ns: 0x0102_0304_0506_0708,
            sequence: 42,
            status: TrackerState::Tracking as u8,
            position_m: [1.5, -2.25, 1e-300],
            rotation_wxyz: [0.5, 0.5, -0.5, 0.5],
            inliers: 77,
            xi_rad2: 2.5e-5,
            ..PoseSample::default()
        };
        for (i, c) in s.covariance.iter_mut().enumerate() {
            *c = i as f64 * 0.125 - 1.0;
        }
        let b = s.to_wire();
        assert_eq!(PoseSample::from_wire(&b), Ok(s));
        // Field for field at the offsets of the table: what a C reader of the struct sees.
        let c = unsafe {
            let mut c = std::mem::MaybeUninit::<PoseSample>::zeroed();
            std::ptr::copy_nonoverlapping(b.as_ptr(), c.as_mut_ptr().cast::<u8>(), POSE_WIRE_BYTES);
            c.assume_init()
        };
        if cfg!(target_endian = "little") {
            assert_eq!(c, s);
        }
        assert_eq!(&b[0..8], &[8, 7, 6, 5, 4, 3, 2, 1]);
        assert_eq!(&b[17..24], &[0; 7], "padding is zero");
        assert_eq!(PoseSample::from_wire(&b[..383]), Err(WireError::Length(383)));
        let mut bad = b;
        bad[16] = 9;
        assert_eq!(PoseSample::from_wire(&bad), Err(WireError::Status(9)));
        assert_eq!(
            WireError::Status(9).to_string(),
            "status byte 9 is none of initializing (0), tracking (1), lost (2)"
        );
    }
}

/// Bytes of [`StatusSample::source`]: a rig name longer than this is cut at a character
/// boundary.
pub const STATUS_SOURCE_BYTES: usize = 32;

/// Most sensors a [`StatusSample`] reports on.
pub const STATUS_MAX_SENSORS: usize = 16;
/// Number of stage-timing slots in a [`StatusSample`] (see [`Stage`]).
pub const STATUS_STAGES: usize = 8;

/// The pipeline's timed stages, by their slot in a [`StatusSample`]: one type for the status
/// message, the pipeline's clocks and budgets, and its summary.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum Stage {
    /// Frame grab and hand-over into the frame pool (all sensors).
    Capture = 0,
    /// Edge + hue extraction of a whole multi-sensor frame.
    Edges = 1,
    /// Correspondence maintenance / initialisation matching.
    Match = 2,
    /// Pose solve (robust sampling + refinement + covariance).
    Solve = 3,
    /// Loan, write and send of the pose sample.
    Publish = 4,
    /// Whole frame: from its hand-over into the frame pool (capture complete; for per-sensor
    /// capture, its first image) to the pose sent — the latency.
    Frame = 5,
    /// The tracker's whole step (matching and solving are parts of it).
    Track = 6,
}

// Every stage has its slot in the status message.
const _: () = assert!(Stage::COUNT <= STATUS_STAGES);

impl Stage {
    /// How many stages there are (slots beyond these in a [`StatusSample`] stay 0).
    pub const COUNT: usize = 7;

    /// All named stages, in slot order.
    pub const ALL: [Stage; Stage::COUNT] = [
        Stage::Capture,
        Stage::Edges,
        Stage::Match,
        Stage::Solve,
        Stage::Publish,
        Stage::Frame,
        Stage::Track,
    ];

    /// Slot index in [`StatusSample::stage_p50_us`] / [`StatusSample::stage_p99_us`].
    pub fn index(self) -> usize {
        self as usize
    }

    /// Lower-case name: `capture`, `edges`, `match`, `solve`, `publish`, `frame`, `track`.
    pub fn name(self) -> &'static str {
        match self {
            Stage::Capture => "capture",
            Stage::Edges => "edges",
            Stage::Match => "match",
            Stage::Solve => "solve",
            Stage::Publish => "publish",
            Stage::Frame => "frame",
            Stage::Track => "track",
        }
    }
}

/// Health of the running tracker, published on `omnitrack/status` (a few times a second is
/// plenty). C layout, 320 bytes, alignment 8:
///
/// | offset | field | type |
/// | --- | --- | --- |
/// | 0 | `timestamp_ns` | u64 |
/// | 8 | `sequence` | u64 |
/// | 16 | `tracker_state` | u8 ([`TrackerState`]) |
/// | 17 | `sensor_count` | u8 |
/// | 18 | `search` | u8 ([`SearchState`], then 1 byte padding) |
/// | 20 | `frame_rate_hz` | [f32; 16] |
/// | 84 | `search_widened_to_m` | f32 |
/// | 88 | `frames_dropped` | [u64; 16] |
/// | 216 | `stage_p50_us` | [u32; 8] |
/// | 248 | `stage_p99_us` | [u32; 8] |
/// | 280 | `source` | [u8; 32] |
/// | 312 | `pid` | u32 |
/// | 316 | `searching` | u8 ([`SearchKind::wire`]: 0 none) |
/// | 317 | `reserved` | [u8; 3], zero |
///
/// v2 (2026-11-27) put the search's state in what was v1's padding: same size, new name, since
/// a v1 writer leaves those bytes undefined. v3 (2026-11-28) added who publishes (the rig's
/// name and the process) and the search under way: the pose message, fixed as `.v1` by the
/// interface, carries neither, and the two services of one prefix have one publisher each.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("omnitrack.StatusSample.v3")]
#[repr(C)]
pub struct StatusSample {
    /// When this status was taken, nanoseconds (same clock as [`PoseSample::timestamp_ns`]).
    pub timestamp_ns: u64,
    /// Status counter.
    pub sequence: u64,
    /// [`TrackerState`] byte of the tracker.
    pub tracker_state: u8,
    /// How many of the per-sensor slots are in use (≤ [`STATUS_MAX_SENSORS`]).
    pub sensor_count: u8,
    /// [`SearchState`] byte of the tracker's last search.
    pub search: u8,
    /// Frames per second delivered by each sensor (slot = sensor index).
    pub frame_rate_hz: [f32; STATUS_MAX_SENSORS],
    /// With [`SearchState::Widened`]: the diameter (m) of the volume actually searched, about
    /// the given volume's centre; 0 otherwise.
    pub search_widened_to_m: f32,
    /// Frames dropped per sensor since start (latest-frame-wins drops, counted, never silent).
    pub frames_dropped: [u64; STATUS_MAX_SENSORS],
    /// Median time per [`Stage`] slot, microseconds (0 = not measured).
    pub stage_p50_us: [u32; STATUS_STAGES],
    /// 99th percentile time per [`Stage`] slot, microseconds (0 = not measured).
    pub stage_p99_us: [u32; STATUS_STAGES],
    /// The publishing tracker's rig name (the rig file's `name`), UTF-8, NUL-padded: which rig
    /// the poses of this prefix come from ([`StatusSample::set_source`], [`StatusSample::source`]).
    pub source: [u8; STATUS_SOURCE_BYTES],
    /// The publishing tracker's process id.
    pub pid: u32,
    /// [`SearchKind::wire`] byte: the search running now, if any (0: none).
    pub searching: u8,
    /// Zero; room for later fields of the same version's size.
    pub reserved: [u8; 3],
}

impl Default for StatusSample {
    fn default() -> Self {
        StatusSample {
            timestamp_ns: 0,
            sequence: 0,
            tracker_state: TrackerState::Initialising as u8,
            sensor_count: 0,
            search: SearchState::None as u8,
            frame_rate_hz: [0.0; STATUS_MAX_SENSORS],
            search_widened_to_m: 0.0,
            frames_dropped: [0; STATUS_MAX_SENSORS],
            stage_p50_us: [0; STATUS_STAGES],
            stage_p99_us: [0; STATUS_STAGES],
            source: [0; STATUS_SOURCE_BYTES],
            pid: 0,
            searching: SearchKind::wire(None),
            reserved: [0; 3],
        }
    }
}

impl StatusSample {
    /// Writes `name` into [`StatusSample::source`], cut at the last character boundary that
    /// fits, the rest NUL.
    pub fn set_source(&mut self, name: &str) {
        let mut end = name.len().min(STATUS_SOURCE_BYTES);
        while !name.is_char_boundary(end) {
            end -= 1;
        }
        self.source = [0; STATUS_SOURCE_BYTES];
        self.source[..end].copy_from_slice(&name.as_bytes()[..end]);
    }

    /// [`StatusSample::source`] up to its first NUL; of bytes that are not UTF-8 (a foreign
    /// writer), the valid beginning.
    pub fn source(&self) -> &str {
        let bytes = &self.source[..self.source.iter().position(|&b| b == 0).unwrap_or(STATUS_SOURCE_BYTES)];
        match std::str::from_utf8(bytes) {
            Ok(s) => s,
            Err(e) => std::str::from_utf8(&bytes[..e.valid_up_to()]).unwrap_or_default(),
        }
    }
}
