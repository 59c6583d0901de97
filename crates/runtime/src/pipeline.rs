//! The threaded device pipeline: capture threads → frame pool → (frame assembly) → edges +
//! tracker → pose and status publishers → the caller's sink (trajectory writer).
//!
//! In: a [`PipelineSource`] — a whole-rig [`FrameSource`] (replay, or a live source opened as
//! one), or one [`SensorCapture`] per sensor ([`open_pipeline_source`] opens the V4L2 and USB3
//! Vision drivers built into this binary that way) — the model, its visibility table, the tracker
//! config and [`PipelineOptions`]. Out: one [`FrameRecord`] per processed frame to the caller's
//! [`FrameSink`], one [`PoseSample`] per processed frame on the pose service, a [`StatusSample`]
//! every `budgets.status_interval_ms` on the status service, and a [`PipelineSummary`].
//!
//! Threads (all scoped, joined before [`run_pipeline`] returns):
//! - **capture**: one per sensor for per-sensor sources, one for a whole-rig source. Each fills a
//!   buffer taken from a preallocated pool and passes its index (a handle) on through a bounded
//!   crossbeam channel.
//! - **assembly** (per-sensor sources only): matches the images of one instant by timestamp within
//!   `budgets.frame_sync_tolerance_ms`, waiting at most `budgets.frame_assembly_wait_ms` after the
//!   first one; images are moved into a pool frame by swapping buffers (no copy). A sensor with
//!   no image in the window is marked invalid for that frame and counted (`sync_missed`, or its
//!   fault when its camera reported one); an image from an instant already assembled is counted
//!   the same way and recycled.
//! - **process**: edges (the detector has its own workers) and the tracker, then the pose sample
//!   (every frame; the last good pose while not tracking) and, on schedule, the status sample.
//!   The frame goes back to the pool before publishing.
//! - the **caller's thread** runs the sink, fed by a bounded channel of [`SINK_BUFFER`] records;
//!   when it is full the tracker waits (the trajectory is never short of a processed frame).
//!
//! Latest frame wins: the hand-over to the tracker holds one frame; a newer frame replaces a
//! pending one, which goes back to the pool and is counted as dropped (whole frame, and per
//! sensor for each valid image in it). With [`PipelineOptions::lossless`] capture waits instead
//! (offline replays and evaluations).
//!
//! Every image a source produces is counted exactly once per sensor ([`SensorSummary`]):
//! delivered to the tracker, overwritten (latest frame wins), a fault of the source, or missed
//! its sync window. The status sample's per-sensor `frames_dropped` is everything but delivered
//! ([`SensorSummary::lost`]); its `frame_rate_hz` is the rate of delivered images over the last
//! status interval (0 for a dead sensor); its stage p50/p99 are over the whole run so far.
//!
//! Budgets (tracker.toml `[budgets]`): each [`PipelineStage`] with a budget counts its overruns
//! (summary, and `debug` logs on the status schedule). Latency is measured from the hand-over
//! into the pool (the frame complete in memory; for per-sensor capture its first image) to the
//! pose sample sent.
//!
//! Memory: the pool (`pool_size` frame sets, plus 4 images per sensor for per-sensor capture),
//! channels, histograms (fixed buckets) and counters are allocated at start-up; after it the frame
//! path allocates nothing — capture sources aside (the replay's PNG decoder allocates per image
//! inside `image`), and one allocation per published sample inside iceoryx2 0.10 (see
//! [`omnitrack_io::publish`]). [`inside_publish`] tells an allocation counter that the current thread
//! is in such a publish call, so a test can account for those exactly (`tests/pipeline.rs`).
//!
//! Stopping: [`PipelineOptions::stop`] (set it from anywhere; with `handle_signals` SIGINT and
//! SIGTERM set it, and a second signal exits at once with status 1), the end of the source,
//! `max_frames`, a sink error or a source error. Then the threads are joined, the sink is drained
//! and [`FrameSink::finish`]ed (the trajectory flushed), and the services are dropped.
//!
//! Logs: [`init_logging`] (called by [`run_pipeline`] unless a subscriber is already set) writes
//! `tracing` events to standard error, warnings only unless `OMNITRACK_LOG` or `RUST_LOG` (e.g.
//! `info`, `omnitrack=debug`) raise it.

mod assembly;
mod live;
mod stats;

pub use live::{live_sensors, open_pipeline_source, LiveSensor, SensorCapture};
pub use stats::{Histogram, PipelineStage, SensorSummary, StageClock, StageSummary};

use super::{FrameRecord, RunError, RunOptions, SinkError};
use crossbeam::channel::{bounded, Receiver, RecvTimeoutError, SendTimeoutError, Sender, TrySendError};
use omnitrack_config::TrackerConfig;
use omnitrack_core::geometry::Pose;
use omnitrack_core::model::Model;
use omnitrack_core::rig::Rig;
use omnitrack_edges::EdgeDetector;
use omnitrack_io::capture::{FrameSet, FrameSource, SensorImage, SourceError, SourceStats};
use omnitrack_io::publish::{
    PosePublisher, PoseSample, PoseStatus, SearchState, StatusPublisher, StatusSample, POSE_SERVICE,
    STATUS_MAX_SENSORS, STATUS_SERVICE, STATUS_STAGES,
};
use omnitrack_tracker::visibility::VisibilityTable;
use omnitrack_tracker::{FrameResult, Tracker, TrackerEvent, TrackerState, TrackerStats};
use stats::SensorCounters;
use std::cell::Cell;
use std::fmt;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

/// Records buffered between the tracker and the sink.
pub const SINK_BUFFER: usize = 256;
/// Frame sets in the pool by default: one being captured, one waiting, one being tracked, one
/// spare.
pub const DEFAULT_POOL_SIZE: usize = 4;
/// Image buffers per sensor for per-sensor capture.
const IMAGES_PER_SENSOR: usize = 4;
/// How often blocked threads look at the stop flag.
const TICK: Duration = Duration::from_millis(20);
/// Publish errors logged at `warn` before the rest are only counted.
const WARN_LIMIT: u64 = 5;

/// Where the pipeline's frames come from.
pub enum PipelineSource {
    /// A whole-rig source: one capture thread calls `next_frame`.
    Rig(Box<dyn FrameSource + Send>),
    /// One capture per sensor (indexed by sensor id, one each), each on its own thread, and the
    /// assembly of frames by timestamp.
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

/// The threads of the pipeline, for [`PipelineOptions::on_thread_start`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PipelineThread {
    /// A capture thread: `Some(k)` reads sensor k, `None` a whole-rig source.
    Capture { sensor: Option<usize> },
    /// Frame assembly (per-sensor sources).
    Assembly,
    /// Edges, tracker and publishers. (The edge detector's workers are its own threads.)
    Process,
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
            lossless: false,
            on_thread_start: None,
        }
    }
}

/// Where processed frames go, on the caller's thread.
pub trait FrameSink {
    /// One processed frame. An error stops the pipeline (the frames already handed over stay).
    fn frame(&mut self, record: &FrameRecord) -> Result<(), SinkError>;
    /// Called once after the last frame (also after a stop or an error): flush here.
    fn finish(&mut self) -> Result<(), SinkError> {
        Ok(())
    }
}

impl<F: FnMut(&FrameRecord) -> Result<(), SinkError>> FrameSink for F {
    fn frame(&mut self, record: &FrameRecord) -> Result<(), SinkError> {
        self(record)
    }
}

/// A trajectory file that could not be created or written.
#[derive(Debug, thiserror::Error)]
#[error("{}: cannot {action}: {source}", path.display())]
pub struct TrajectoryFileError {
    pub path: PathBuf,
    /// `create` or `write`.
    pub action: &'static str,
    #[source]
    pub source: std::io::Error,
}

/// A [`FrameSink`] writing the tracked poses as a TUM trajectory (the format of
/// [`omnitrack_core::trajectory`]), buffered, flushed at [`FrameSink::finish`]. Allocation-free per frame.
#[derive(Debug)]
pub struct TumSink {
    path: PathBuf,
    out: std::io::BufWriter<std::fs::File>,
    poses: u64,
}

impl TumSink {
    /// Creates (truncates) `path` and writes the header comment.
    pub fn create(path: &Path) -> Result<TumSink, TrajectoryFileError> {
        let failed = |action, source| TrajectoryFileError {
            path: path.to_path_buf(),
            action,
            source,
        };
        let f = std::fs::File::create(path).map_err(|e| failed("create", e))?;
        let mut out = std::io::BufWriter::with_capacity(64 << 10, f);
        writeln!(out, "# timestamp_s tx ty tz qx qy qz qw (T_world_rig)").map_err(|e| failed("write", e))?;
        Ok(TumSink {
            path: path.to_path_buf(),
            out,
            poses: 0,
        })
    }

    /// Poses written so far.
    pub fn poses(&self) -> u64 {
        self.poses
    }

    fn write_failed(&self, source: std::io::Error) -> SinkError {
        Box::new(TrajectoryFileError {
            path: self.path.clone(),
            action: "write",
            source,
        })
    }
}

impl FrameSink for TumSink {
    fn frame(&mut self, r: &FrameRecord) -> Result<(), SinkError> {
        let Some(pose) = &r.result.pose else {
            return Ok(());
        };
        let stamped = omnitrack_core::trajectory::Stamped {
            timestamp_ns: r.timestamp_ns,
            pose: *pose,
        };
        if let Err(e) =
            omnitrack_core::trajectory::write_tum_line(&mut self.out, &stamped).and_then(|()| writeln!(self.out))
        {
            return Err(self.write_failed(e));
        }
        self.poses += 1;
        Ok(())
    }

    fn finish(&mut self) -> Result<(), SinkError> {
        self.out.flush().map_err(|e| self.write_failed(e))
    }
}

/// Why the pipeline stopped (when it did not fail). Not the solver's `StopReason`, which says why
/// consensus sampling stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RunEnd {
    /// The source ended.
    EndOfStream,
    /// `max_frames` were processed.
    MaxFrames,
    /// The stop flag was set (by the caller or a signal).
    Stopped,
}

/// What a run did.
#[derive(Debug, Clone)]
pub struct PipelineSummary {
    pub reason: RunEnd,
    /// Start-up done → last frame processed.
    pub elapsed: Duration,
    /// Frames handed into the pool by capture (or assembly).
    pub frames_captured: u64,
    pub frames_processed: u64,
    /// Whole frames replaced by a newer one before the tracker took them (latest frame wins).
    pub frames_dropped: u64,
    /// Indexed by sensor id.
    pub sensors: Vec<SensorSummary>,
    /// Indexed by [`PipelineStage::index`].
    pub stages: [StageSummary; PipelineStage::COUNT],
    pub tracker: TrackerStats,
    /// The whole-rig source's own counters (per-sensor sources: `None`).
    pub source: Option<SourceStats>,
    pub poses_published: u64,
    pub status_published: u64,
    pub publish_errors: u64,
    /// Why a service could not be opened (the run went on without it).
    pub publisher_error: Option<String>,
}

impl PipelineSummary {
    pub fn stage(&self, stage: PipelineStage) -> &StageSummary {
        &self.stages[stage.index()]
    }

    /// Frames processed per second of the run.
    pub fn frame_rate_hz(&self) -> f64 {
        if self.elapsed.is_zero() {
            return 0.0;
        }
        self.frames_processed as f64 / self.elapsed.as_secs_f64()
    }
}

impl fmt::Display for PipelineSummary {
    /// One line: frames, rate, drops, latency, overruns.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let lat = self.stage(PipelineStage::Latency);
        write!(
            f,
            "{} frames processed of {} captured ({:.1} frames/s), {} dropped; latency p50 {:.1} ms, p99 {:.1} ms; overruns:",
            self.frames_processed,
            self.frames_captured,
            self.frame_rate_hz(),
            self.frames_dropped,
            lat.p50.as_secs_f64() * 1e3,
            lat.p99.as_secs_f64() * 1e3
        )?;
        for s in PipelineStage::ALL {
            let st = self.stage(s);
            if st.budget.is_some() {
                write!(f, " {} {}", s.name(), st.overruns)?;
            }
        }
        Ok(())
    }
}

thread_local! {
    static IN_PUBLISH: Cell<bool> = const { Cell::new(false) };
}

/// Whether the current thread is inside an iceoryx2 publish call of the pipeline (which
/// allocates once per sample inside iceoryx2 0.10): for allocation counters. Never allocates.
pub fn inside_publish() -> bool {
    IN_PUBLISH.try_with(Cell::get).unwrap_or(false)
}

fn publishing<T>(f: impl FnOnce() -> T) -> T {
    IN_PUBLISH.with(|c| c.set(true));
    let r = f();
    IN_PUBLISH.with(|c| c.set(false));
    r
}

/// Installs the `tracing` subscriber of the device runtime unless one is set already: standard
/// error, `warn` and above by default; `OMNITRACK_LOG`, else `RUST_LOG`, raise or lower it with
/// `target=level` directives (`info`, `omnitrack=debug,iceoryx2=warn`). Returns whether it was
/// installed now.
pub fn init_logging() -> bool {
    use tracing_subscriber::filter::{LevelFilter, Targets};
    use tracing_subscriber::prelude::*;
    let spec = std::env::var("OMNITRACK_LOG")
        .ok()
        .filter(|s| !s.trim().is_empty())
        .or_else(|| std::env::var("RUST_LOG").ok().filter(|s| !s.trim().is_empty()));
    let default = Targets::new().with_default(LevelFilter::WARN);
    let (filter, bad) = match spec.as_deref().map(str::parse::<Targets>) {
        None => (default, None),
        Some(Ok(t)) => (t, None),
        Some(Err(e)) => (default, Some(e)),
    };
    let layer = tracing_subscriber::fmt::layer().with_writer(std::io::stderr);
    let installed = tracing_subscriber::registry()
        .with(layer)
        .with(filter)
        .try_init()
        .is_ok();
    if let (true, Some(e)) = (installed, bad) {
        tracing::warn!(
            "log filter {:?} not understood ({e}); logging warnings only",
            spec.unwrap_or_default()
        );
    }
    installed
}

/// Signal handlers installed by [`stop_on_signals`]; dropping it removes them and gives SIGINT
/// and SIGTERM their default action (terminate) back.
#[derive(Debug)]
pub struct SignalGuard {
    ids: Vec<signal_hook::SigId>,
    default_action: Arc<AtomicBool>,
}

impl Drop for SignalGuard {
    fn drop(&mut self) {
        for id in self.ids.drain(..) {
            signal_hook::low_level::unregister(id);
        }
        self.default_action.store(true, Ordering::SeqCst);
    }
}

/// Makes SIGINT and SIGTERM set `stop` while the returned guard lives; a second one while `stop`
/// is already set exits the process at once with status 1 (a stuck shutdown can still be
/// interrupted). signal-hook cannot uninstall its handler, so the default action is emulated
/// after the guard is gone (one such emulation per process, off while a guard lives).
pub fn stop_on_signals(stop: &Arc<AtomicBool>) -> std::io::Result<SignalGuard> {
    use signal_hook::consts::{SIGINT, SIGTERM};
    static DEFAULT_ACTION: Mutex<Option<Arc<AtomicBool>>> = Mutex::new(None);
    let default_action = {
        let mut d = lock(&DEFAULT_ACTION);
        match d.as_ref() {
            Some(flag) => Arc::clone(flag),
            None => {
                let flag = Arc::new(AtomicBool::new(false));
                for sig in [SIGINT, SIGTERM] {
                    signal_hook::flag::register_conditional_default(sig, Arc::clone(&flag))?;
                }
                *d = Some(Arc::clone(&flag));
                flag
            }
        }
    };
    default_action.store(false, Ordering::SeqCst);
    let mut guard = SignalGuard {
        ids: Vec::new(),
        default_action,
    };
    for sig in [SIGINT, SIGTERM] {
        // Registered first, so it sees the flag as it was before this signal.
        guard.ids.push(signal_hook::flag::register_conditional_shutdown(
            sig,
            1,
            Arc::clone(stop),
        )?);
        guard.ids.push(signal_hook::flag::register(sig, Arc::clone(stop))?);
    }
    Ok(guard)
}

/// State shared by all pipeline threads: flags and counters (atomics), the capture clock.
struct Shared<'o> {
    stop: &'o AtomicBool,
    /// Set by the pipeline itself: processing ended, the sink or a sensor failed.
    halt: AtomicBool,
    sensors: Box<[SensorCounters]>,
    frames_captured: AtomicU64,
    frames_dropped: AtomicU64,
    capture: Mutex<StageClock>,
    source_error: Mutex<Option<SourceError>>,
    lossless: bool,
    hook: Option<fn(PipelineThread)>,
}

impl Shared<'_> {
    fn stopping(&self) -> bool {
        self.halt.load(Ordering::Relaxed) || self.stop.load(Ordering::Relaxed)
    }

    fn thread_started(&self, t: PipelineThread) {
        if let Some(hook) = self.hook {
            hook(t);
        }
    }

    fn record_capture(&self, d: Duration) {
        lock(&self.capture).record(d);
    }

    fn fail(&self, e: SourceError) {
        // Returned by `run_pipeline` (the caller says it); logged here only at `debug`.
        tracing::debug!("source failed: {e}");
        lock(&self.source_error).get_or_insert(e);
        self.halt.store(true, Ordering::Relaxed);
    }
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// A frame of the pool and what the pipeline knows of it.
struct Slot {
    frame: FrameSet,
    /// The pipeline's frame counter (gaps = dropped frames).
    seq: u64,
    /// When it was handed into the pool.
    arrived: Instant,
}

/// The preallocated frame sets and the list of free ones (handles = indices).
struct Pool {
    slots: Box<[Mutex<Slot>]>,
    free_tx: Sender<usize>,
    free_rx: Receiver<usize>,
}

impl Pool {
    fn new(rig: &Rig, size: usize) -> Pool {
        let (free_tx, free_rx) = bounded(size);
        let now = Instant::now();
        let slots = (0..size)
            .map(|i| {
                free_tx.send(i).expect("room for every handle");
                Mutex::new(Slot {
                    frame: FrameSet::for_rig(rig),
                    seq: 0,
                    arrived: now,
                })
            })
            .collect();
        Pool {
            slots,
            free_tx,
            free_rx,
        }
    }

    fn slot(&self, h: usize) -> MutexGuard<'_, Slot> {
        lock(&self.slots[h])
    }

    /// A free frame, waiting for one; `None` once the pipeline stops.
    fn take(&self, shared: &Shared) -> Option<usize> {
        loop {
            if shared.stopping() {
                return None;
            }
            match self.free_rx.recv_timeout(TICK) {
                Ok(h) => return Some(h),
                Err(RecvTimeoutError::Timeout) => continue,
                Err(RecvTimeoutError::Disconnected) => return None,
            }
        }
    }

    fn release(&self, h: usize) {
        // Never full: there are as many places as handles.
        let _ = self.free_tx.try_send(h);
    }
}

/// The producer's side of the hand-over to the tracker: a channel of one handle, and a receiver
/// to take back a frame that a newer one replaces.
struct Handover {
    tx: Sender<usize>,
    rx: Receiver<usize>,
}

impl Handover {
    /// Hands frame `h` to the tracker: the latest frame wins (or, lossless, waits). False once
    /// the pipeline stops.
    fn post(&self, shared: &Shared, pool: &Pool, h: usize) -> bool {
        shared.frames_captured.fetch_add(1, Ordering::Relaxed);
        let mut h = h;
        if shared.lossless {
            loop {
                match self.tx.send_timeout(h, TICK) {
                    Ok(()) => return true,
                    Err(SendTimeoutError::Timeout(x)) => {
                        if shared.stopping() {
                            pool.release(x);
                            return false;
                        }
                        h = x;
                    }
                    Err(SendTimeoutError::Disconnected(x)) => {
                        pool.release(x);
                        return false;
                    }
                }
            }
        }
        loop {
            match self.tx.try_send(h) {
                Ok(()) => return true,
                Err(TrySendError::Full(x)) => {
                    h = x;
                    if let Ok(old) = self.rx.try_recv() {
                        self.drop_frame(shared, pool, old);
                    }
                }
                Err(TrySendError::Disconnected(x)) => {
                    pool.release(x);
                    return false;
                }
            }
        }
    }

    /// A frame replaced before the tracker took it: counted, back to the pool.
    fn drop_frame(&self, shared: &Shared, pool: &Pool, h: usize) {
        {
            let slot = pool.slot(h);
            for (img, c) in slot.frame.sensors().iter().zip(shared.sensors.iter()) {
                if img.valid {
                    SensorCounters::add(&c.overwritten, 1);
                }
            }
        }
        shared.frames_dropped.fetch_add(1, Ordering::Relaxed);
        pool.release(h);
    }
}

/// The capture thread of a whole-rig source. Returns the source's counters.
fn capture_rig(source: &mut dyn FrameSource, shared: &Shared, pool: &Pool, handover: Handover) -> SourceStats {
    shared.thread_started(PipelineThread::Capture { sensor: None });
    let mut seq = 0u64;
    while let Some(h) = pool.take(shared) {
        let mut slot = pool.slot(h);
        let started = Instant::now();
        let got = source.next_frame(&mut slot.frame);
        shared.record_capture(started.elapsed());
        match got {
            Ok(true) => {
                for (img, c) in slot.frame.sensors().iter().zip(shared.sensors.iter()) {
                    if !img.valid {
                        SensorCounters::add(&c.faults, 1);
                    }
                }
                slot.seq = seq;
                slot.arrived = Instant::now();
                seq += 1;
                drop(slot);
                if !handover.post(shared, pool, h) {
                    break;
                }
            }
            Ok(false) => {
                drop(slot);
                pool.release(h);
                tracing::info!(frames = seq, "source ended");
                break;
            }
            Err(e) => {
                drop(slot);
                pool.release(h);
                shared.fail(e);
                break;
            }
        }
    }
    source.stats().clone()
}

/// One sensor's image buffers (per-sensor capture) and the list of free ones.
struct SensorImages {
    images: Box<[Mutex<SensorImage>]>,
    free_tx: Sender<usize>,
    free_rx: Receiver<usize>,
}

impl SensorImages {
    fn new(rig: &Rig, k: usize) -> SensorImages {
        let s = &rig.sensors[k];
        let (free_tx, free_rx) = bounded(IMAGES_PER_SENSOR);
        let images = (0..IMAGES_PER_SENSOR)
            .map(|i| {
                free_tx.send(i).expect("room for every handle");
                Mutex::new(SensorImage::new(s.id, s.width, s.height))
            })
            .collect();
        SensorImages {
            images,
            free_tx,
            free_rx,
        }
    }

    fn image(&self, i: usize) -> MutexGuard<'_, SensorImage> {
        lock(&self.images[i])
    }

    fn take(&self, shared: &Shared) -> Option<usize> {
        loop {
            if shared.stopping() {
                return None;
            }
            match self.free_rx.recv_timeout(TICK) {
                Ok(i) => return Some(i),
                Err(RecvTimeoutError::Timeout) => continue,
                Err(RecvTimeoutError::Disconnected) => return None,
            }
        }
    }

    fn release(&self, i: usize) {
        let _ = self.free_tx.try_send(i);
    }
}

/// An image of one sensor, ready in its buffer `slot`.
#[derive(Debug, Clone, Copy)]
struct Arrival {
    sensor: usize,
    slot: usize,
    arrived: Instant,
}

/// The capture thread of one sensor.
fn capture_sensor(
    capture: &mut dyn SensorCapture,
    k: usize,
    shared: &Shared,
    images: &SensorImages,
    arrivals: Sender<Arrival>,
) {
    shared.thread_started(PipelineThread::Capture { sensor: Some(k) });
    while let Some(i) = images.take(shared) {
        let mut img = images.image(i);
        let started = Instant::now();
        let got = capture.capture(&mut img);
        shared.record_capture(started.elapsed());
        match got {
            Ok(true) => {
                if !img.valid {
                    SensorCounters::add(&shared.sensors[k].faults, 1);
                }
                drop(img);
                let a = Arrival {
                    sensor: k,
                    slot: i,
                    arrived: Instant::now(),
                };
                // Room for every buffer of every sensor: never blocks for long.
                if arrivals.send(a).is_err() {
                    break;
                }
            }
            Ok(false) => {
                drop(img);
                images.release(i);
                tracing::info!(sensor = k, "sensor stream ended");
                break;
            }
            Err(e) => {
                drop(img);
                images.release(i);
                shared.fail(e);
                break;
            }
        }
    }
}

/// What the process thread hands back.
struct ProcessOutcome {
    reason: RunEnd,
    clocks: Vec<StageClock>,
    tracker: TrackerStats,
    frames_processed: u64,
    first_frame: Option<Instant>,
    last_frame: Option<Instant>,
    poses_published: u64,
    status_published: u64,
    publish_errors: u64,
    publisher_error: Option<String>,
}

fn pose_status(r: &FrameResult) -> PoseStatus {
    match r.state {
        TrackerState::Initializing => PoseStatus::Initializing,
        TrackerState::Tracking if r.pose.is_some() => PoseStatus::Tracking,
        TrackerState::Tracking | TrackerState::Lost => PoseStatus::Lost,
    }
}

/// The process thread: edges, tracker, publishers.
struct Processor<'a, 'o, 'm> {
    shared: &'a Shared<'o>,
    pool: &'a Pool,
    ready: Receiver<usize>,
    records: Sender<FrameRecord>,
    detector: EdgeDetector,
    tracker: Tracker<'m>,
    poses: Option<PosePublisher>,
    status: Option<StatusPublisher>,
    clocks: Vec<StageClock>,
    budgets: omnitrack_config::BudgetConfig,
    max_frames: Option<u64>,
    processed: u64,
    last_ts: u64,
    last_pose: Pose,
    last_state: PoseStatus,
    first_frame: Option<Instant>,
    last_frame: Option<Instant>,
    poses_published: u64,
    status_published: u64,
    publish_errors: u64,
    /// Delivered images per sensor at the last status, and when it was.
    status_delivered: Vec<u64>,
    status_rates: Vec<f32>,
    status_at: Instant,
    status_overruns: [u64; PipelineStage::COUNT],
    /// What the last search made of its volume, and the widened diameter (m), for the status.
    search: SearchState,
    search_widened_to_m: f32,
}

impl Processor<'_, '_, '_> {
    fn run(mut self) -> ProcessOutcome {
        let interval = Duration::from_secs_f64(self.budgets.status_interval_ms / 1e3);
        let mut next_status = Instant::now() + interval;
        self.publish_status();
        let reason = loop {
            if self.shared.stop.load(Ordering::Relaxed) {
                break RunEnd::Stopped;
            }
            if self.shared.halt.load(Ordering::Relaxed) {
                // A sink or source failure; the caller reports it.
                break RunEnd::Stopped;
            }
            if self.max_frames.is_some_and(|m| self.processed >= m) {
                break RunEnd::MaxFrames;
            }
            let wait = next_status.saturating_duration_since(Instant::now()).min(TICK);
            match self.ready.recv_timeout(wait) {
                Ok(h) => self.frame(h),
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => break RunEnd::EndOfStream,
            }
            let now = Instant::now();
            if now >= next_status {
                self.publish_status();
                next_status += interval;
                if next_status <= now {
                    next_status = now + interval;
                }
            }
        };
        self.shared.halt.store(true, Ordering::Relaxed);
        // A frame still waiting for the tracker is dropped like any replaced one.
        while let Ok(h) = self.ready.try_recv() {
            {
                let slot = self.pool.slot(h);
                for (img, c) in slot.frame.sensors().iter().zip(self.shared.sensors.iter()) {
                    if img.valid {
                        SensorCounters::add(&c.overwritten, 1);
                    }
                }
            }
            self.shared.frames_dropped.fetch_add(1, Ordering::Relaxed);
            self.pool.release(h);
        }
        self.publish_status();
        ProcessOutcome {
            reason,
            clocks: std::mem::take(&mut self.clocks),
            tracker: *self.tracker.stats(),
            frames_processed: self.processed,
            first_frame: self.first_frame,
            last_frame: self.last_frame,
            poses_published: self.poses_published,
            status_published: self.status_published,
            publish_errors: self.publish_errors,
            publisher_error: None,
        }
    }

    fn frame(&mut self, h: usize) {
        let (record, arrived) = {
            let slot = self.pool.slot(h);
            let frame = &slot.frame;
            let timestamp_ns = frame.timestamp_ns().unwrap_or(self.last_ts + 1);
            let started = Instant::now();
            let edges = self.detector.detect(frame);
            let edge_time = started.elapsed();
            let edge_count = edges.len();
            let result = self.tracker.process(edges, timestamp_ns);
            let frame_time = started.elapsed();
            for (img, c) in frame.sensors().iter().zip(self.shared.sensors.iter()) {
                if img.valid {
                    SensorCounters::add(&c.delivered, 1);
                }
            }
            let record = FrameRecord {
                sequence: slot.seq,
                timestamp_ns,
                valid_sensors: frame.valid_count(),
                edges: edge_count,
                edge_time,
                track_time: frame_time - edge_time,
                frame_time,
                result,
            };
            (record, slot.arrived)
        };
        self.pool.release(h);
        self.last_ts = record.timestamp_ns;
        self.processed += 1;
        let r = &record.result;
        match (&r.event, r.pose.is_some()) {
            (Some(TrackerEvent::Searched(rep)), _) => {
                (self.search, self.search_widened_to_m) = match rep.widened_to_m {
                    _ if rep.cells_in_volume == 0 => (SearchState::NoCells, 0.0),
                    Some(d) => (SearchState::Widened, d as f32),
                    None => (SearchState::AsGiven, 0.0),
                }
            }
            (_, true) => (self.search, self.search_widened_to_m) = (SearchState::None, 0.0),
            _ => {}
        }
        if let Some(p) = &r.pose {
            self.last_pose = *p;
        }
        self.last_state = pose_status(r);
        let publish_time = self.publish_pose(&record);
        let done = Instant::now();
        self.first_frame.get_or_insert(done);
        self.last_frame = Some(done);
        let c = &mut self.clocks;
        c[PipelineStage::Edges.index()].record(record.edge_time);
        c[PipelineStage::Match.index()].record(r.match_time);
        c[PipelineStage::Solve.index()].record(r.solve_time);
        c[PipelineStage::Track.index()].record(record.track_time);
        if let Some(t) = publish_time {
            c[PipelineStage::Publish.index()].record(t);
        }
        c[PipelineStage::Latency.index()].record(done - arrived);
        // The sink drains until this channel closes: a full buffer only makes the tracker wait.
        let _ = self.records.send(record);
    }

    /// Publishes the frame's pose sample; returns the time it took.
    fn publish_pose(&mut self, record: &FrameRecord) -> Option<Duration> {
        let publisher = self.poses.as_ref()?;
        let r = &record.result;
        let started = Instant::now();
        let sent = publishing(|| {
            publisher.publish_pose(
                record.timestamp_ns,
                record.sequence,
                self.last_state,
                &self.last_pose,
                &r.covariance,
                r.inliers,
                r.xi_rad2,
            )
        });
        let took = started.elapsed();
        match sent {
            Ok(_) => self.poses_published += 1,
            Err(e) => self.publish_error(&e),
        }
        Some(took)
    }

    fn publish_error(&mut self, e: &omnitrack_io::publish::PublishError) {
        self.publish_errors += 1;
        if self.publish_errors <= WARN_LIMIT {
            tracing::warn!(errors = self.publish_errors, "{e}");
        }
    }

    /// Builds and sends a status sample (and logs new budget overruns at `debug`).
    fn publish_status(&mut self) {
        let now = Instant::now();
        let dt = now.duration_since(self.status_at).as_secs_f64();
        // Rates over at least half an interval: a status right after another (the last one, at
        // stop) repeats the previous rates.
        let fresh = dt >= self.budgets.status_interval_ms / 2e3;
        if fresh {
            self.status_at = now;
        }
        let mut s = StatusSample {
            timestamp_ns: self.last_ts
                + self
                    .last_frame
                    .map_or(0, |t| now.saturating_duration_since(t).as_nanos() as u64),
            sequence: self.status_published,
            tracker_state: self.last_state as u8,
            sensor_count: self.shared.sensors.len().min(STATUS_MAX_SENSORS) as u8,
            search: self.search as u8,
            search_widened_to_m: self.search_widened_to_m,
            ..StatusSample::default()
        };
        for (k, c) in self.shared.sensors.iter().enumerate() {
            let snap = c.snapshot();
            if fresh {
                let before = std::mem::replace(&mut self.status_delivered[k], snap.delivered);
                self.status_rates[k] = ((snap.delivered - before) as f64 / dt) as f32;
            }
            if k < STATUS_MAX_SENSORS {
                s.frame_rate_hz[k] = self.status_rates[k];
                s.frames_dropped[k] = snap.lost();
            }
        }
        let capture = lock(&self.shared.capture);
        for stage in PipelineStage::ALL {
            let clock = match stage {
                PipelineStage::Capture => &*capture,
                _ => &self.clocks[stage.index()],
            };
            if let Some(slot) = stage.status_stage().map(|st| st.index()).filter(|&i| i < STATUS_STAGES) {
                let us = |d: Duration| u32::try_from(d.as_micros()).unwrap_or(u32::MAX);
                s.stage_p50_us[slot] = us(clock.histogram.quantile(0.5));
                s.stage_p99_us[slot] = us(clock.histogram.quantile(0.99));
            }
            let seen = &mut self.status_overruns[stage.index()];
            if clock.overruns > *seen {
                tracing::debug!(
                    stage = stage.name(),
                    overruns = clock.overruns,
                    new = clock.overruns - *seen,
                    budget = ?clock.budget,
                    p99 = ?clock.histogram.quantile(0.99),
                    "stage over its budget"
                );
                *seen = clock.overruns;
            }
        }
        drop(capture);
        let Some(publisher) = self.status.as_ref() else {
            return;
        };
        match publishing(|| publisher.publish(&s)) {
            Ok(_) => self.status_published += 1,
            Err(e) => self.publish_error(&e),
        }
    }
}

fn create_publisher<T: omnitrack_io::publish::Message>(
    service: Option<&str>,
    errors: &mut Option<String>,
) -> Option<omnitrack_io::publish::SamplePublisher<T>> {
    let service = service?;
    match omnitrack_io::publish::SamplePublisher::<T>::create(service) {
        Ok(p) => {
            if p.dead_nodes_cleaned() > 0 {
                tracing::info!(
                    service,
                    cleaned = p.dead_nodes_cleaned(),
                    "removed what crashed runs left"
                );
            }
            Some(p)
        }
        Err(e) => {
            tracing::warn!("not publishing: {e}");
            errors.get_or_insert_with(|| e.to_string());
            None
        }
    }
}

/// Runs the pipeline over `source` until it ends, `max_frames` are processed, the stop flag is
/// set or something fails; every processed frame goes to `sink` on the calling thread. See the
/// module doc. A source or sink failure is the error (after the sink was drained and finished).
pub fn run_pipeline(
    source: impl Into<PipelineSource>,
    model: &Model,
    table: &VisibilityTable,
    cfg: &TrackerConfig,
    opts: &PipelineOptions,
    sink: &mut dyn FrameSink,
) -> Result<PipelineSummary, RunError> {
    init_logging();
    let mut source = source.into();
    let rig = source.rig().clone();
    let n = rig.sensors.len();
    if let PipelineSource::Sensors { sensors, .. } = &source {
        let ids: Vec<usize> = sensors.iter().map(|s| s.sensor()).collect();
        if ids != (0..n).collect::<Vec<_>>() {
            return Err(RunError::Source(SourceError::Device {
                device: rig.name.clone(),
                message: format!("per-sensor capture must list sensors 0..{n} in order, found {ids:?}"),
            }));
        }
    }
    let _signals = if opts.handle_signals {
        match stop_on_signals(&opts.stop) {
            Ok(g) => Some(g),
            Err(e) => {
                tracing::warn!("cannot handle SIGINT/SIGTERM: {e}");
                None
            }
        }
    } else {
        None
    };
    let b = &cfg.budgets;
    let shared = Shared {
        stop: &opts.stop,
        halt: AtomicBool::new(false),
        sensors: (0..n).map(|_| SensorCounters::default()).collect(),
        frames_captured: AtomicU64::new(0),
        frames_dropped: AtomicU64::new(0),
        capture: Mutex::new(StageClock::new(PipelineStage::Capture.budget(b))),
        source_error: Mutex::new(None),
        lossless: opts.lossless,
        hook: opts.on_thread_start,
    };
    let pool = Pool::new(&rig, opts.pool_size.max(3));
    let sensor_images: Vec<SensorImages> = match &source {
        PipelineSource::Sensors { .. } => (0..n).map(|k| SensorImages::new(&rig, k)).collect(),
        PipelineSource::Rig(_) => Vec::new(),
    };
    let (ready_tx, ready_rx) = bounded::<usize>(1);
    let (records_tx, records_rx) = bounded::<FrameRecord>(SINK_BUFFER);
    tracing::info!(
        rig = %rig.name,
        sensors = n,
        threads = match &source { PipelineSource::Rig(_) => "one capture thread", PipelineSource::Sensors { .. } => "one capture thread per sensor" },
        pool = opts.pool_size.max(3),
        lossless = opts.lossless,
        "pipeline starting"
    );

    let mut sink_error: Option<SinkError> = None;
    let (outcome, source_stats, publisher_error) = std::thread::scope(|scope| {
        let shared = &shared;
        let pool = &pool;
        let mut capture_handles = Vec::new();
        match &mut source {
            PipelineSource::Rig(src) => {
                let handover = Handover {
                    tx: ready_tx.clone(),
                    rx: ready_rx.clone(),
                };
                let src: &mut (dyn FrameSource + Send) = src.as_mut();
                capture_handles.push(
                    std::thread::Builder::new()
                        .name("omnitrack-capture".into())
                        .spawn_scoped(scope, move || Some(capture_rig(src, shared, pool, handover)))
                        .expect("spawn the capture thread"),
                );
            }
            PipelineSource::Sensors { sensors, .. } => {
                let (arrivals_tx, arrivals_rx) = bounded::<Arrival>(n * IMAGES_PER_SENSOR);
                for (k, capture) in sensors.iter_mut().enumerate() {
                    let images = &sensor_images[k];
                    let tx = arrivals_tx.clone();
                    let capture: &mut dyn SensorCapture = capture.as_mut();
                    capture_handles.push(
                        std::thread::Builder::new()
                            .name(format!("omnitrack-capture-{k}"))
                            .spawn_scoped(scope, move || {
                                capture_sensor(capture, k, shared, images, tx);
                                None
                            })
                            .expect("spawn a capture thread"),
                    );
                }
                drop(arrivals_tx);
                let handover = Handover {
                    tx: ready_tx.clone(),
                    rx: ready_rx.clone(),
                };
                let images = &sensor_images;
                let tolerance = Duration::from_secs_f64(b.frame_sync_tolerance_ms / 1e3);
                let wait = Duration::from_secs_f64(b.frame_assembly_wait_ms / 1e3);
                capture_handles.push(
                    std::thread::Builder::new()
                        .name("omnitrack-assembly".into())
                        .spawn_scoped(scope, move || {
                            shared.thread_started(PipelineThread::Assembly);
                            let mut a = assembly::Assembler::new(shared, pool, images, handover, tolerance, wait);
                            a.run(arrivals_rx);
                            None
                        })
                        .expect("spawn the assembly thread"),
                );
            }
        }
        drop(ready_tx);

        let records_tx = records_tx;
        let process = std::thread::Builder::new()
            .name("omnitrack-process".into())
            .spawn_scoped(scope, move || {
                shared.thread_started(PipelineThread::Process);
                let mut publisher_error = None;
                let poses = create_publisher::<PoseSample>(opts.pose_service.as_deref(), &mut publisher_error);
                let status = create_publisher::<StatusSample>(opts.status_service.as_deref(), &mut publisher_error);
                let clocks = PipelineStage::ALL
                    .iter()
                    .map(|s| StageClock::new(s.budget(&cfg.budgets)))
                    .collect();
                let processor = Processor {
                    shared,
                    pool,
                    ready: ready_rx,
                    records: records_tx,
                    detector: EdgeDetector::new(&rig, &cfg.edges),
                    tracker: Tracker::new(&rig, model, table, cfg, opts.run.hint, opts.run.seed),
                    poses,
                    status,
                    clocks,
                    budgets: cfg.budgets.clone(),
                    max_frames: opts.run.max_frames,
                    processed: 0,
                    last_ts: 0,
                    last_pose: Pose::identity(),
                    last_state: PoseStatus::Initializing,
                    first_frame: None,
                    last_frame: None,
                    poses_published: 0,
                    status_published: 0,
                    publish_errors: 0,
                    status_delivered: vec![0; rig.sensors.len()],
                    status_rates: vec![0.0; rig.sensors.len()],
                    status_at: Instant::now(),
                    status_overruns: [0; PipelineStage::COUNT],
                    search: SearchState::None,
                    search_widened_to_m: 0.0,
                };
                let outcome = processor.run();
                (outcome, publisher_error)
            })
            .expect("spawn the process thread");

        // The sink, on this thread, until the process thread closes the channel.
        shared.thread_started(PipelineThread::Sink);
        for record in records_rx.iter() {
            if sink_error.is_none() {
                if let Err(e) = sink.frame(&record) {
                    tracing::debug!("sink failed: {e}");
                    sink_error = Some(e);
                    shared.halt.store(true, Ordering::Relaxed);
                }
            }
        }
        if let Err(e) = sink.finish() {
            tracing::debug!("sink failed: {e}");
            sink_error.get_or_insert(e);
        }
        let joined = process.join();
        // Whatever ended the process thread ends capture too (also after a panic, so that the
        // scope can join).
        shared.halt.store(true, Ordering::Relaxed);
        let (outcome, publisher_error) = match joined {
            Ok(x) => x,
            Err(panic) => std::panic::resume_unwind(panic),
        };
        let mut source_stats = None;
        for h in capture_handles {
            match h.join() {
                Ok(s) => source_stats = source_stats.or(s),
                Err(panic) => std::panic::resume_unwind(panic),
            }
        }
        (outcome, source_stats, publisher_error)
    });

    if let Some(e) = lock(&shared.source_error).take() {
        return Err(RunError::Source(e));
    }
    if let Some(e) = sink_error {
        return Err(RunError::Sink(e));
    }
    let mut outcome = outcome;
    outcome.publisher_error = publisher_error;
    let capture = lock(&shared.capture).summary();
    let mut stages = [StageSummary::default(); PipelineStage::COUNT];
    for s in PipelineStage::ALL {
        stages[s.index()] = match s {
            PipelineStage::Capture => capture,
            _ => outcome.clocks[s.index()].summary(),
        };
    }
    let elapsed = match (outcome.first_frame, outcome.last_frame) {
        // From the first frame's pose: start-up (edge tables, publishers) is not the rate.
        (Some(a), Some(b)) if outcome.frames_processed > 1 => {
            (b - a).mul_f64(outcome.frames_processed as f64 / (outcome.frames_processed - 1) as f64)
        }
        _ => Duration::ZERO,
    };
    let summary = PipelineSummary {
        reason: outcome.reason,
        elapsed,
        frames_captured: shared.frames_captured.load(Ordering::Relaxed),
        frames_processed: outcome.frames_processed,
        frames_dropped: shared.frames_dropped.load(Ordering::Relaxed),
        sensors: shared.sensors.iter().map(SensorCounters::snapshot).collect(),
        stages,
        tracker: outcome.tracker,
        source: source_stats,
        poses_published: outcome.poses_published,
        status_published: outcome.status_published,
        publish_errors: outcome.publish_errors,
        publisher_error: outcome.publisher_error,
    };
    tracing::info!(reason = ?summary.reason, "pipeline stopped: {summary}");
    Ok(summary)
}
