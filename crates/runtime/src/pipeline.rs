//! The threaded device pipeline: capture threads → frame pool → (frame assembly) → edges +
//! tracker → pose and status publishers → the caller's sink (trajectory writer).
//!
//! In: a [`PipelineSource`] — a whole-rig [`FrameSource`] (replay, or a live source opened as
//! one), or one [`SensorCapture`] per capture device ([`open_pipeline_source`] opens the V4L2 and USB3
//! Vision drivers built into this binary that way) — the model, its visibility table, the tracker
//! config and [`PipelineOptions`]. Out: one [`FrameRecord`] per processed frame to the caller's
//! [`FrameSink`], one [`PoseSample`] per processed frame on the pose service, a [`StatusSample`]
//! every `budgets.status_interval_ms` on the status service, and a [`PipelineSummary`].
//!
//! Threads (all scoped, joined before [`run_pipeline`] returns):
//! - **capture**: one per capture device for per-device sources (a device delivers one sensor, or
//!   the windows of several cropped from its frame), one for a whole-rig source. Each fills a
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
//!   Between records it looks at the tracker's search every tick, and tells the sink how far a
//!   search of more than a second has got, about once a second
//!   ([`FrameSink::search_progress`]): the frame path never does.
//!
//! Scheduling (`priority`): where frames come in real time, process and the edge workers run at
//! `SCHED_FIFO` `[budgets] realtime_priority`, capture and assembly one below, the search thread
//! at the normal policy; the OS may refuse (one warning); [`PipelineSummary::realtime`] says what
//! the run got.
//!
//! Latest frame wins: the hand-over to the tracker holds one frame; a newer frame replaces a
//! pending one, which goes back to the pool and is counted as dropped (whole frame, and per
//! sensor for each valid image in it). With [`PipelineOptions::lossless`] capture waits instead
//! (offline replays and evaluations): nothing is dropped, and a whole-rig source reads no more
//! than `max_frames`.
//!
//! Every frame handed into the pool is counted once ([`PipelineSummary`]): processed, dropped
//! (replaced by a newer one) or left (the run ended while it waited). Every image a source
//! produces is counted exactly once per sensor ([`SensorSummary`]): delivered to the tracker,
//! overwritten (latest frame wins), a fault of the source, missed its sync window, or left. The
//! status sample's per-sensor `frames_dropped` is everything but delivered
//! ([`SensorSummary::lost`]); its `frame_rate_hz` is the rate of delivered images over the last
//! status interval (0 for a dead sensor); its stage p50/p99 are over the whole run so far.
//!
//! Budgets (tracker.toml `[budgets]`): each [`Stage`] with a budget counts its overruns
//! (summary, and `debug` logs on the status schedule). Latency is measured from the hand-over
//! into the pool (the frame complete in memory; for per-sensor capture its first image) to the
//! pose sample sent.
//!
//! Memory: the pool (`pool_size` frame sets, plus 4 images per sensor for per-sensor capture),
//! channels (with crossbeam's lists of waiting threads and each thread's wait context, which it
//! would otherwise make at a first wait: `pool::warm_channel`), histograms (fixed buckets) and
//! counters are allocated at start-up; after it the frame path and the search thread allocate
//! nothing — capture sources aside (the replay's PNG decoder allocates per image
//! inside `image`), and one allocation per published sample inside iceoryx2 0.10 (see
//! [`omnitrack_io::publish`]). [`inside_publish`] tells an allocation counter that the current thread
//! is in such a publish call, so a test can account for those exactly (`tests/pipeline/`).
//!
//! Stopping: [`PipelineOptions::stop`] (set it from anywhere; with `handle_signals` SIGINT and
//! SIGTERM set it, and a second signal exits at once with status 1), the end of the source,
//! `max_frames`, a sink error or a source error. Then the threads are joined, the sink is drained
//! and [`FrameSink::finish`]ed (the trajectory flushed), and the services are dropped. Nothing
//! waits long for a stop: blocked threads look at it every `TICK` (20 ms), a source's own wait (a
//! real-time replay's gap, a device waiting to be reopened) ends within a slice of it
//! (`FrameSource::next_frame_or_stop`), and a search under way ends at its next check and is
//! discarded, its frame without a pose (`Tracker::stop_searches_on`: no pose from half a search).
//!
//! Logs: [`init_logging`] (called by [`run_pipeline`] unless a subscriber is already set) writes
//! `tracing` events to standard error, warnings only unless `OMNITRACK_LOG` or `RUST_LOG` (e.g.
//! `info`, `omnitrack=debug`) raise it.
//!
//! [`FrameSource`]: omnitrack_io::capture::FrameSource
//! [`PoseSample`]: omnitrack_io::publish::PoseSample
//! [`StatusSample`]: omnitrack_io::publish::StatusSample

mod assembly;
mod capture;
mod images;
mod live;
mod logging;
mod options;
mod pool;
mod priority;
mod process;
mod publishing;
mod shared;
mod signals;
mod sink;
mod stats;
mod summary;

pub use live::{live_sensors, open_pipeline_source, LiveDevice};
pub use logging::init_logging;
pub use omnitrack_io::publish::Stage;
pub use omnitrack_tracker::SearchSnapshot;
pub use options::{PipelineOptions, PipelineSource, PipelineThread, SensorCapture};
#[cfg(unix)]
pub use priority::current_thread_policy;
pub use priority::{upstream_priority, Realtime, ThreadPolicy};
pub use publishing::inside_publish;
pub use signals::{stop_on_signals, SignalGuard};
pub use sink::{FrameSink, TrajectoryFileError, TumSink, PROGRESS_AFTER, PROGRESS_EVERY};
pub use stats::{stage_budget, CpuSummary, Histogram, SensorSummary, StageClock, StageSummary};
pub use summary::{PipelineSummary, RunEnd};

use super::{FrameRecord, RunError};
use crossbeam::channel::bounded;
use images::SensorImages;
use omnitrack_config::TrackerConfig;
use omnitrack_core::model::Model;
use omnitrack_io::capture::SourceError;
use omnitrack_tracker::visibility::VisibilityTable;
use omnitrack_tracker::{FrameResult, TrackerState};
use pool::{Handover, Pool};
use shared::{lock, Shared};
use std::sync::atomic::Ordering;
use std::time::Duration;

/// Records buffered between the tracker and the sink.
pub const SINK_BUFFER: usize = 256;
/// Frame sets in the pool by default: one being captured, one waiting, one being tracked, one
/// spare.
pub const DEFAULT_POOL_SIZE: usize = 4;
/// How often blocked threads look at the stop flag.
const TICK: Duration = Duration::from_millis(20);

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
        let mut ids: Vec<usize> = sensors.iter().flat_map(|s| s.sensors().iter().copied()).collect();
        ids.sort_unstable();
        let too_many = sensors.iter().any(|s| {
            s.sensors().is_empty() || s.sensors().len() > omnitrack_io::capture::device::MAX_WINDOWS_PER_DEVICE
        });
        if too_many || ids != (0..n).collect::<Vec<_>>() {
            return Err(RunError::Source(SourceError::Device {
                device: rig.name.clone(),
                message: format!(
                    "per-device capture must deliver each of sensors 0..{n} once, by 1 to {} per device, found {ids:?}",
                    omnitrack_io::capture::device::MAX_WINDOWS_PER_DEVICE
                ),
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
    let shared = Shared::new(opts, n, &cfg.budgets);
    let pool = Pool::new(&rig, opts.pool_size.max(3));
    let sensor_images: Vec<SensorImages> = match &source {
        PipelineSource::Sensors { .. } => (0..n).map(|k| SensorImages::new(&rig, k)).collect(),
        PipelineSource::Rig(_) => Vec::new(),
    };
    let (ready_tx, ready_rx) = bounded::<usize>(1);
    // What is still in the hand-over once every thread has ended: a capture thread may post a
    // frame after the process thread's last look (it had room again), and that frame was read.
    let leftover = ready_rx.clone();
    let (records_tx, records_rx) = bounded::<FrameRecord>(SINK_BUFFER);
    pool::warm_channel(&ready_tx, &ready_rx, || 0);
    let no_record = || FrameRecord::late(0, 0, FrameResult::empty(TrackerState::Initialising));
    pool::warm_channel(&records_tx, &records_rx, no_record);
    tracing::info!(
        rig = %rig.name,
        sensors = n,
        threads = match &source { PipelineSource::Rig(_) => "one capture thread", PipelineSource::Sensors { .. } => "one capture thread per capture device" },
        pool = opts.pool_size.max(3),
        lossless = opts.lossless,
        "pipeline starting"
    );
    let (outcome, source_stats, sink_error) = std::thread::scope(|scope| {
        let shared = &shared;
        let pool = &pool;
        let handover = Handover {
            tx: ready_tx.clone(),
            rx: ready_rx.clone(),
        };
        let capture_handles =
            capture::spawn_capture(scope, &mut source, shared, pool, &sensor_images, handover, &cfg.budgets);
        drop(ready_tx);

        let records_tx = records_tx;
        let process = std::thread::Builder::new()
            .name("omnitrack-process".into())
            .spawn_scoped(scope, move || {
                process::run_process(shared, pool, ready_rx, records_tx, &rig, model, table, cfg, opts)
            })
            .expect("spawn the process thread");

        // The sink, on this thread, until the process thread closes the channel.
        let sink_cpu = omnitrack_edges::thread_cpu_time();
        let sink_error = sink::drain(sink, &records_rx, shared);
        shared.add_cpu(
            stats::ThreadRole::Sink,
            omnitrack_edges::thread_cpu_time().saturating_sub(sink_cpu),
        );
        let joined = process.join();
        // Whatever ended the process thread ends capture too (also after a panic, so that the
        // scope can join).
        shared.halt.store(true, Ordering::Relaxed);
        let outcome = match joined {
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
        while let Ok(h) = leftover.try_recv() {
            shared.leave(pool, h);
        }
        (outcome, source_stats, sink_error)
    });

    if let Some(e) = lock(&shared.source_error).take() {
        return Err(RunError::Source(e));
    }
    if let Some(e) = sink_error {
        return Err(RunError::Sink(e));
    }
    let summary = summary::summarize(&shared, outcome, source_stats);
    tracing::info!(reason = ?summary.reason, "pipeline stopped: {summary}");
    Ok(summary)
}
