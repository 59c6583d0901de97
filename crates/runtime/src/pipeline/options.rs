//! What [`run_pipeline`](super::run_pipeline) is asked to run: the [`PipelineSource`] its frames
//! come from (a whole-rig source, or a [`SensorCapture`] per capture device), and the
//! [`PipelineOptions`] (run limits, pool size, stop flag, signals, services, lossless capture, a
//! hook per thread naming it by [`PipelineThread`]).

use super::DEFAULT_POOL_SIZE;
use crate::RunOptions;
use omnitrack_core::frame::SensorImage;
use omnitrack_core::rig::Rig;
use omnitrack_io::capture::{FrameSource, SourceError};
use omnitrack_io::publish::{POSE_SERVICE, STATUS_SERVICE};
use std::fmt;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

/// Where the pipeline's frames come from.
pub enum PipelineSource {
    /// A whole-rig source: one capture thread calls `next_frame`.
    Rig(Box<dyn FrameSource + Send>),
    /// One capture per capture device (together delivering every sensor once), each on its own
    /// thread, and the assembly of frames by timestamp.
    Sensors {
        rig: Rig,
        sensors: Vec<Box<dyn SensorCapture>>,
    },
}

impl PipelineSource {
    pub fn rig(&self) -> &Rig {
        match self {
            PipelineSource::Rig(s) => s.rig(),
            PipelineSource::Sensors { rig, .. } => rig,
        }
    }
}

impl fmt::Debug for PipelineSource {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PipelineSource::Rig(s) => write!(f, "PipelineSource::Rig({})", s.rig().name),
            PipelineSource::Sensors { rig, sensors } => {
                write!(f, "PipelineSource::Sensors({}, {} sensors)", rig.name, sensors.len())
            }
        }
    }
}

/// The images of one capture device's sensors, read on a thread of its own.
pub trait SensorCapture: Send {
    /// The sensor ids it delivers (indices in the rig), in order; at most
    /// [`MAX_WINDOWS_PER_DEVICE`](omnitrack_io::capture::device::MAX_WINDOWS_PER_DEVICE).
    fn sensors(&self) -> &[usize];

    /// Reads the next images into `imgs` (one per sensor of [`SensorCapture::sensors`], in that
    /// order, each sized for its sensor) and marks each: valid with its capture time (ns, a clock
    /// shared by all sensors of the rig), or invalid with its fault. `Ok(false)`: this device's
    /// stream has ended, or `stop` said true during a wait of its own (a device waiting to be
    /// reopened looks at it every [`STOP_SLICE`](omnitrack_io::capture::STOP_SLICE)). A
    /// per-image failure is never an `Err`.
    fn capture(&mut self, imgs: &mut [&mut SensorImage], stop: &dyn Fn() -> bool) -> Result<bool, SourceError>;
}

/// The threads of the pipeline, for [`PipelineOptions::on_thread_start`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PipelineThread {
    /// A capture thread: `Some(k)` reads sensor k, `None` a whole-rig source.
    Capture { sensor: Option<usize> },
    /// Frame assembly (per-sensor sources).
    Assembly,
    /// Edges, tracker and publishers. (The edge detector's workers are its own threads.)
    Process,
    /// The tracker's search worker: initialisation and re-initialisation searches off the frame
    /// path (`omnitrack_tracker::background`).
    Search,
    /// The caller's thread, about to run the sink.
    Sink,
}

/// How to run the pipeline.
#[derive(Debug, Clone)]
pub struct PipelineOptions {
    /// Search volume, seed, frame limit (frames processed).
    pub run: RunOptions,
    /// Frame sets in the pool (at least 3).
    pub pool_size: usize,
    /// Set to stop; shared with signal handlers and other threads.
    pub stop: Arc<AtomicBool>,
    /// Whether SIGINT and SIGTERM set `stop` for the duration of the run (the CLI's choice; off by
    /// default, since a library should not take over signals).
    pub handle_signals: bool,
    /// The pose service (`None`: do not publish poses).
    pub pose_service: Option<String>,
    /// The status service (`None`: do not publish status).
    pub status_service: Option<String>,
    /// Capture waits for the tracker instead of dropping frames: for replays not paced in real
    /// time (`Pacing::AsFastAsPossible` would otherwise race through the recording while the
    /// tracker initialises) and evaluations.
    pub lossless: bool,
    /// Called first thing on each pipeline thread (e.g. to mark threads for an allocation counter).
    pub on_thread_start: Option<fn(PipelineThread)>,
    /// A service asked for that cannot be opened stops the run before its first frame (default):
    /// a tracker whose poses reach no one is a fault, not a warning. Off, the run goes on without
    /// it; either way [`PipelineSummary::publisher_error`](super::PipelineSummary) says why.
    pub require_services: bool,
}

impl Default for PipelineOptions {
    fn default() -> Self {
        PipelineOptions {
            run: RunOptions::default(),
            pool_size: DEFAULT_POOL_SIZE,
            stop: Arc::new(AtomicBool::new(false)),
            handle_signals: false,
            pose_service: Some(POSE_SERVICE.to_string()),
            status_service: Some(STATUS_SERVICE.to_string()),
            require_services: true,
            lossless: false,
            on_thread_start: None,
        }
    }
}
