//! Capture: where frames come from.
//!
//! In: a camera rig ([`Rig`]) and a source of images, all behind the [`FrameSource`] trait: a
//! recording on disk ([`replay`], the mock camera), V4L2 devices (`v4l2`, cargo feature `v4l`)
//! or USB3 Vision cameras (`usb`, cargo feature `usb`, over the always-compiled stream parser
//! [`u3v`]). [`open_source`] opens the one a [`SourceSpec`] names (`--source replay:DIR`, `v4l`,
//! `usb`, parsed by [`spec`]) and answers a live source left out of the build with the cargo
//! command that enables it. The live sources share [`LiveSource`] ([`live`]: one camera per
//! capture device, a lost one reopened every second while the others go on), the split of the
//! rig into capture devices of [`device`] (several sensors may be windows of one device's frame)
//! and the pixel conversions of [`convert`]. Files import one way: `open` → the drivers →
//! `live` → `device`, `spec`, `convert`.
//! Out: [`FrameSet`]s — one RGB8 image per rig sensor, with its capture time and whether the
//! sensor delivered for this frame — plus [`SourceStats`] counting everything that went wrong.
//! A caller that may be stopped asks through [`FrameSource::next_frame_or_stop`]: a source's own
//! waits (pacing, reopening) then end within [`STOP_SLICE`] of the stop ([`sleep_until_or_stop`]).
//! The frame types themselves are plain data of `omnitrack-core` ([`omnitrack_core::frame`]),
//! re-exported here, so that the layers that only read frames (edges, tracker) do not link this
//! crate and its transport.
//!
//! Capture knows frames and sensors, nothing of edges or tracking.
//!
//! Memory: a [`FrameSet`] is built once from the rig ([`FrameSet::for_rig`]), each sensor buffer
//! sized width × height × 3, and every [`FrameSource::next_frame`] call fills it in place. A
//! source sizes its own scratch space when it is opened, so that the steady state allocates
//! nothing of its own (see [`replay`] for what its PNG decoder still allocates inside).
//!
//! Failure: one sensor failing for one frame (dropped, missing, corrupt, wrong size) is recorded
//! on that sensor's [`SensorImage`] (`valid = false`, with an [`ImageFault`]), counted in
//! [`SourceStats`], warned on standard error a few times per kind, and the stream goes on.
//! [`SourceError`] is only for the whole source failing (cannot open, wrong frame set).

pub mod control;
pub mod convert;
pub mod device;
pub mod live;
pub mod open;
pub mod replay;
pub mod spec;
pub mod u3v;
#[cfg(feature = "usb")]
pub mod usb;
#[cfg(feature = "usb")]
pub mod usb_control;
#[cfg(feature = "v4l")]
pub mod v4l2;
#[cfg(feature = "v4l")]
pub mod v4l2_ioctl;

pub use live::LiveSource;
pub use omnitrack_core::frame::{FrameSet, ImageFault, SensorImage};
pub use open::{open_source, open_source_with};
pub use replay::{Pacing, ReplaySource};
pub use spec::{ControlPolicy, SourceOptions, SourceSpec, SourceSpecError};

use omnitrack_core::rig::{Rig, RigError};
use omnitrack_core::trajectory::TumError;
use std::fmt;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// What one sensor delivered over the stream so far.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SensorStats {
    /// Valid images delivered.
    pub delivered: u64,
    /// Frames with no image at all for this sensor ([`ImageFault::Dropped`]).
    pub dropped: u64,
    /// [`ImageFault::Missing`]: file or directory missing / unreadable.
    pub missing: u64,
    /// [`ImageFault::Corrupt`]: not decodable.
    pub corrupt: u64,
    /// [`ImageFault::WrongSize`].
    pub wrong_size: u64,
    /// [`ImageFault::WrongFormat`].
    pub wrong_format: u64,
}

impl SensorStats {
    /// The counter of one fault kind.
    pub fn faults(&self, fault: ImageFault) -> u64 {
        match fault {
            ImageFault::Dropped => self.dropped,
            ImageFault::Missing => self.missing,
            ImageFault::Corrupt => self.corrupt,
            ImageFault::WrongSize => self.wrong_size,
            ImageFault::WrongFormat => self.wrong_format,
        }
    }

    /// Counts one fault.
    pub fn count(&mut self, fault: ImageFault) {
        match fault {
            ImageFault::Dropped => self.dropped += 1,
            ImageFault::Missing => self.missing += 1,
            ImageFault::Corrupt => self.corrupt += 1,
            ImageFault::WrongSize => self.wrong_size += 1,
            ImageFault::WrongFormat => self.wrong_format += 1,
        }
    }

    /// All faults of every kind.
    pub fn total_faults(&self) -> u64 {
        ImageFault::ALL.iter().map(|&f| self.faults(f)).sum()
    }
}

/// Index rows (e.g. of `frames.csv`) that were skipped at open, by reason.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct BadRowStats {
    /// Not exactly the expected number of comma-separated fields.
    pub field_count: u64,
    /// A numeric field (frame, sensor, timestamp) that is not a non-negative integer.
    pub not_a_number: u64,
    /// A sensor id the rig does not have.
    pub unknown_sensor: u64,
    /// A second row for a (frame, sensor) pair already seen (the first one is kept).
    pub duplicate: u64,
    /// An empty path field.
    pub empty_path: u64,
    /// A path that leaves the recording (absolute, or with `..`): a recording reads only what
    /// is inside its folder.
    pub outside: u64,
    /// Not a line of text: not UTF-8, or longer than any row of the format can be.
    pub unreadable: u64,
}

impl BadRowStats {
    pub fn total(&self) -> u64 {
        self.field_count
            + self.not_a_number
            + self.unknown_sensor
            + self.duplicate
            + self.empty_path
            + self.outside
            + self.unreadable
    }
}

/// Everything a source counted: what it delivered and what went wrong. Bounded in size (counters
/// only, no stored messages), so it can live for the whole run.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SourceStats {
    /// Frame sets delivered (`next_frame` returned `Ok(true)`).
    pub frames_delivered: u64,
    /// Indexed by sensor id.
    pub sensors: Vec<SensorStats>,
    /// Index rows skipped when the source was opened.
    pub bad_rows: BadRowStats,
    /// Warnings written to standard error.
    pub warnings_printed: u64,
    /// Warnings counted but not written (past the per-kind limit).
    pub warnings_suppressed: u64,
}

impl SourceStats {
    /// Zeroed counters for a rig of `sensors` sensors.
    pub fn new(sensors: usize) -> SourceStats {
        SourceStats {
            sensors: vec![SensorStats::default(); sensors],
            ..SourceStats::default()
        }
    }

    /// Sum over sensors of one fault kind.
    pub fn faults(&self, fault: ImageFault) -> u64 {
        self.sensors.iter().map(|s| s.faults(fault)).sum()
    }

    /// Valid images delivered, all sensors.
    pub fn images_delivered(&self) -> u64 {
        self.sensors.iter().map(|s| s.delivered).sum()
    }
}

impl fmt::Display for SourceStats {
    /// One line, e.g. `12 frames, 70/72 images; dropped 1, corrupt 1; 0 bad rows; 2 warnings (0 suppressed)`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let expected = self.frames_delivered * self.sensors.len() as u64;
        write!(
            f,
            "{} frames, {}/{} images",
            self.frames_delivered,
            self.images_delivered(),
            expected
        )?;
        let mut sep = "; ";
        for fault in ImageFault::ALL {
            let n = self.faults(fault);
            if n > 0 {
                write!(f, "{sep}{fault} {n}")?;
                sep = ", ";
            }
        }
        write!(
            f,
            "; {} bad rows; {} warnings ({} suppressed)",
            self.bad_rows.total(),
            self.warnings_printed,
            self.warnings_suppressed
        )
    }
}

/// The whole source failed: one line naming the file or device and the problem.
#[derive(Debug, thiserror::Error)]
pub enum SourceError {
    /// The rig file of a recording (or of a live source) is missing or invalid.
    #[error("{0}")]
    Rig(#[from] RigError),
    /// The ground-truth trajectory of a recording is present but unreadable.
    #[error("{0}")]
    GroundTruth(#[from] TumError),
    /// A file or directory the source needs cannot be read.
    #[error("{}: {message}", path.display())]
    Io { path: PathBuf, message: String },
    /// A file the source needs is readable but not in the expected format.
    #[error("{}{}: {message}", path.display(), line.map(|l| format!(":{l}")).unwrap_or_default())]
    Format {
        path: PathBuf,
        line: Option<usize>,
        message: String,
    },
    /// A capture device failed (for live drivers): `device` is e.g. `/dev/video0`.
    #[error("{device}: {message}")]
    Device { device: String, message: String },
    /// `next_frame` was given a [`FrameSet`] not built for this source's rig.
    #[error("frame set does not fit rig '{rig}': build it with FrameSet::for_rig(source.rig())")]
    FrameSetMismatch { rig: String },
}

/// A source of rig frames: a recording now, live cameras later. Object-safe, so a runtime can hold
/// a `Box<dyn FrameSource>` chosen from the command line.
pub trait FrameSource {
    /// The rig whose frames this source delivers; build the [`FrameSet`] from it.
    fn rig(&self) -> &Rig;

    /// Fills `out` (built by [`FrameSet::for_rig`] from [`FrameSource::rig`]) in place with the
    /// next frame. `Ok(true)`: a frame was delivered (some sensors may be invalid, see
    /// [`SensorImage::valid`]); `Ok(false)`: end of stream, `out` is untouched; `Err`: the whole
    /// source failed. A per-sensor failure is never an `Err`.
    fn next_frame(&mut self, out: &mut FrameSet) -> Result<bool, SourceError>;

    /// [`FrameSource::next_frame`] for a caller that may be asked to stop: a wait of the
    /// source's own (a replay paced at its recorded times, a live source with no camera waiting
    /// to reopen one) looks at `stop` every [`STOP_SLICE`] and, once it says true, ends with
    /// `Ok(false)`, no frame taken and `out` untouched. A source that never waits long need not
    /// override it.
    fn next_frame_or_stop(&mut self, out: &mut FrameSet, stop: &dyn Fn() -> bool) -> Result<bool, SourceError> {
        let _ = stop;
        self.next_frame(out)
    }

    /// Counters so far.
    fn stats(&self) -> &SourceStats;

    /// What each live camera made of the rig's `[control]` when it was last opened, one report
    /// per camera asked anything ([`control`]); none for a recording.
    fn control_reports(&self) -> Vec<control::ControlReport> {
        Vec::new()
    }
}

/// The longest a source's own wait goes without looking at its caller's stop
/// ([`FrameSource::next_frame_or_stop`]): a stopping service must be gone within a tenth of a
/// second, whatever gap a recording or a reopening interval asks for.
pub const STOP_SLICE: Duration = Duration::from_millis(20);

/// Sleeps until `until` (`None`: for ever) in slices of at most [`STOP_SLICE`]; false as soon as
/// `stop` says true, true once `until` has come.
pub fn sleep_until_or_stop(until: Option<Instant>, stop: &dyn Fn() -> bool) -> bool {
    loop {
        let now = Instant::now();
        if until.is_some_and(|t| t <= now) {
            return true;
        }
        if stop() {
            return false;
        }
        let left = until.map_or(STOP_SLICE, |t| t - now);
        std::thread::sleep(left.min(STOP_SLICE));
    }
}

/// Writes capture warnings to standard error, at most `limit` per kind, counting the rest.
/// A fixed array of counters: no allocation, no stored strings.
#[derive(Debug, Clone)]
pub(crate) struct WarningLimiter {
    printed: [u32; WarningKind::COUNT],
    limit: u32,
}

/// What a warning is about, for rate limiting.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum WarningKind {
    Image(ImageFault),
    BadRow,
    Directory,
}

impl WarningKind {
    const COUNT: usize = ImageFault::ALL.len() + 2;

    fn index(self) -> usize {
        match self {
            WarningKind::Image(f) => f.index(),
            WarningKind::BadRow => ImageFault::ALL.len(),
            WarningKind::Directory => ImageFault::ALL.len() + 1,
        }
    }
}

impl WarningLimiter {
    pub(crate) fn new(limit: u32) -> WarningLimiter {
        WarningLimiter {
            printed: [0; WarningKind::COUNT],
            limit,
        }
    }

    /// Prints `message` (prefixed `warning: `) unless `kind` has reached its limit; the last
    /// printed one of a kind says that more will be counted only. Updates `stats`.
    pub(crate) fn warn(&mut self, stats: &mut SourceStats, kind: WarningKind, message: fmt::Arguments<'_>) {
        let n = &mut self.printed[kind.index()];
        if *n >= self.limit {
            stats.warnings_suppressed += 1;
            return;
        }
        *n += 1;
        stats.warnings_printed += 1;
        if *n == self.limit {
            eprintln!("warning: {message} (further warnings of this kind are only counted)");
        } else {
            eprintln!("warning: {message}");
        }
    }
}
