//! What a run did: why it ended ([`RunEnd`]) and its [`PipelineSummary`] (frames, drops,
//! per-sensor and per-stage counts, publishing), one line of it as its `Display`.
//!
//! In: the counters the threads shared, the process thread's outcome ([`ProcessOutcome`], defined
//! here with [`RunEnd`] so that the process thread uses this file and not the other way) and the
//! whole-rig source's own counters. Out: the summary [`run_pipeline`](super::run_pipeline)
//! returns.

use super::shared::{lock, Shared};
use super::stats::{summary_of, CpuSummary, SensorCounters, ThreadRole};
use super::{Realtime, SensorSummary, Stage, StageClock, StageSummary};
use omnitrack_io::capture::SourceStats;
use omnitrack_tracker::TrackerStats;
use std::fmt;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

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

/// What the process thread hands back.
pub(super) struct ProcessOutcome {
    pub(super) reason: RunEnd,
    pub(super) clocks: Vec<StageClock>,
    pub(super) cpu: super::process::CpuClocks,
    pub(super) tracker: TrackerStats,
    pub(super) frames_processed: u64,
    pub(super) first_frame: Option<Instant>,
    pub(super) last_frame: Option<Instant>,
    pub(super) poses_published: u64,
    pub(super) status_published: u64,
    pub(super) publish_errors: u64,
    pub(super) publisher_error: Option<String>,
}

/// What a run did.
#[derive(Debug, Clone)]
pub struct PipelineSummary {
    pub reason: RunEnd,
    /// Start-up done → last frame processed.
    pub elapsed: Duration,
    /// Frames read from the source and handed into the pool by capture (or assembly). Each
    /// ends processed, dropped or left: `frames_captured = frames_processed + frames_dropped +
    /// frames_left`. A lossless run with `max_frames` reads no more than it processes.
    pub frames_captured: u64,
    pub frames_processed: u64,
    /// Whole frames replaced by a newer one before the tracker took them (latest frame wins;
    /// always 0 in a lossless run).
    pub frames_dropped: u64,
    /// Frames read but never processed because the run ended while they waited (a stop, or
    /// `max_frames` reached while a live source had read ahead).
    pub frames_left: u64,
    /// Indexed by sensor id.
    pub sensors: Vec<SensorSummary>,
    /// Indexed by [`Stage::index`].
    pub stages: [StageSummary; Stage::COUNT],
    /// CPU time per frame and per thread (thread CPU clocks).
    pub cpu: CpuSummary,
    pub tracker: TrackerStats,
    /// The whole-rig source's own counters (per-sensor sources: `None`).
    pub source: Option<SourceStats>,
    pub poses_published: u64,
    pub status_published: u64,
    pub publish_errors: u64,
    /// Why a service could not be opened (the run stopped before its first frame, or with
    /// `require_services` off went on without it).
    pub publisher_error: Option<String>,
    /// The frame path's scheduling (`[budgets] realtime_priority`).
    pub realtime: Realtime,
}

impl PipelineSummary {
    pub fn stage(&self, stage: Stage) -> &StageSummary {
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
    /// One line: frames, rate, drops, latency, overruns, the frame path's scheduling.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let lat = self.stage(Stage::Frame);
        write!(
            f,
            "{} frames processed of {} captured ({:.1} frames/s), {} dropped",
            self.frames_processed,
            self.frames_captured,
            self.frame_rate_hz(),
            self.frames_dropped,
        )?;
        if self.frames_left > 0 {
            write!(f, ", {} left unprocessed at the end", self.frames_left)?;
        }
        write!(
            f,
            "; latency p50 {:.1} ms, p99 {:.1} ms; overruns:",
            lat.p50.as_secs_f64() * 1e3,
            lat.p99.as_secs_f64() * 1e3
        )?;
        for s in Stage::ALL {
            let st = self.stage(s);
            if st.budget.is_some() {
                write!(f, " {} {}", s.name(), st.overruns)?;
            }
        }
        write!(f, "; {}", self.realtime)
    }
}

/// The summary of a run that did not fail.
pub(super) fn summarize(
    shared: &Shared,
    outcome: ProcessOutcome,
    source_stats: Option<SourceStats>,
) -> PipelineSummary {
    let capture = lock(&shared.capture).summary();
    let mut stages = [StageSummary::default(); Stage::COUNT];
    for s in Stage::ALL {
        stages[s.index()] = match s {
            Stage::Capture => capture,
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
    let thread = |r: ThreadRole| Duration::from_nanos(shared.thread_cpu_ns[r as usize].load(Ordering::Relaxed));
    let cpu = CpuSummary {
        edges: summary_of(&outcome.cpu.edges),
        track: summary_of(&outcome.cpu.track),
        frame: summary_of(&outcome.cpu.frame),
        capture: summary_of(&lock(&shared.capture_cpu)),
        capture_total: thread(ThreadRole::Capture),
        process_total: thread(ThreadRole::Process),
        edge_workers_total: thread(ThreadRole::EdgeWorkers),
        search_total: thread(ThreadRole::Search),
        sink_total: thread(ThreadRole::Sink),
    };
    PipelineSummary {
        cpu,
        reason: outcome.reason,
        elapsed,
        frames_captured: shared.frames_captured.load(Ordering::Relaxed),
        frames_processed: outcome.frames_processed,
        frames_dropped: shared.frames_dropped.load(Ordering::Relaxed),
        frames_left: shared.frames_left.load(Ordering::Relaxed),
        sensors: shared.sensors.iter().map(SensorCounters::snapshot).collect(),
        stages,
        tracker: outcome.tracker,
        source: source_stats,
        poses_published: outcome.poses_published,
        status_published: outcome.status_published,
        publish_errors: outcome.publish_errors,
        publisher_error: outcome.publisher_error,
        realtime: lock(&shared.realtime).clone(),
    }
}
