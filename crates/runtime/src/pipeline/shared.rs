//! State shared by all pipeline threads: the stop flag and the pipeline's own halt, per-sensor
//! and frame counters (atomics), the capture clock, the first source error and the thread hook.
//!
//! In: the [`PipelineOptions`] and the budgets. Out: what every thread reads and counts into;
//! [`run_pipeline`](super::run_pipeline) turns it into the summary at the end.

use super::pool::Pool;
use super::priority::{self, Realtime};
use super::stats::SensorCounters;
use super::stats::{Histogram, ThreadRole};
use super::{stage_budget, PipelineOptions, PipelineThread, Stage, StageClock};
use omnitrack_config::BudgetConfig;
use omnitrack_io::capture::SourceError;
use omnitrack_tracker::SearchProgress;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, OnceLock};
use std::time::Duration;

/// State shared by all pipeline threads: flags and counters (atomics), the capture clock.
pub(super) struct Shared<'o> {
    pub(super) stop: &'o Arc<AtomicBool>,
    /// Set by the pipeline itself: processing ended, the sink or a sensor failed. Shared (like
    /// `stop`) with the tracker, whose search ends at either.
    pub(super) halt: Arc<AtomicBool>,
    pub(super) sensors: Box<[SensorCounters]>,
    pub(super) frames_captured: AtomicU64,
    pub(super) frames_dropped: AtomicU64,
    /// Frames read but never processed: the run ended while they waited (`summary`'s
    /// `frames_left`).
    pub(super) frames_left: AtomicU64,
    pub(super) capture: Mutex<StageClock>,
    /// CPU time (thread clock) of each read of the source by a capture thread.
    pub(super) capture_cpu: Mutex<Histogram>,
    /// CPU time (ns) each kind of pipeline thread used over the run, added as each ends
    /// ([`ThreadRole`]).
    pub(super) thread_cpu_ns: [AtomicU64; ThreadRole::COUNT],
    pub(super) source_error: Mutex<Option<SourceError>>,
    pub(super) lossless: bool,
    /// A lossless run reads no more frames than it will process (`max_frames`): a whole-rig
    /// source stops there instead of reading ahead frames the run would then leave.
    pub(super) capture_limit: Option<u64>,
    pub(super) hook: Option<fn(PipelineThread)>,
    /// `[budgets] realtime_priority` (0: off).
    realtime_priority: u8,
    /// What the frame-path threads got so far (`priority`).
    pub(super) realtime: Mutex<Realtime>,
    /// The tracker's search progress, set by the process thread once the tracker is made; the
    /// sink's thread watches it (`sink::drain`).
    pub(super) search: OnceLock<Arc<SearchProgress>>,
}

impl<'o> Shared<'o> {
    pub(super) fn new(opts: &'o PipelineOptions, sensors: usize, budgets: &BudgetConfig) -> Shared<'o> {
        Shared {
            stop: &opts.stop,
            halt: Arc::new(AtomicBool::new(false)),
            sensors: (0..sensors).map(|_| SensorCounters::default()).collect(),
            frames_captured: AtomicU64::new(0),
            frames_dropped: AtomicU64::new(0),
            frames_left: AtomicU64::new(0),
            capture: Mutex::new(StageClock::new(stage_budget(Stage::Capture, budgets))),
            capture_cpu: Mutex::new(Histogram::new()),
            thread_cpu_ns: std::array::from_fn(|_| AtomicU64::new(0)),
            source_error: Mutex::new(None),
            lossless: opts.lossless,
            capture_limit: opts.run.max_frames.filter(|_| opts.lossless),
            hook: opts.on_thread_start,
            realtime_priority: if opts.lossless { 0 } else { budgets.realtime_priority },
            realtime: Mutex::new(if budgets.realtime_priority == 0 {
                Realtime::Off
            } else if opts.lossless {
                Realtime::Lossless
            } else {
                Realtime::Granted(budgets.realtime_priority)
            }),
            search: OnceLock::new(),
        }
    }
}

impl Shared<'_> {
    pub(super) fn stopping(&self) -> bool {
        self.halt.load(Ordering::Relaxed) || self.stop.load(Ordering::Relaxed)
    }

    /// Sets the thread's scheduling for its role (`priority`) and makes its channel wait context
    /// (`pool::warm_channel`: crossbeam makes it on a thread's first wait, which allocates and
    /// could come late in the run), then calls the caller's hook.
    pub(super) fn thread_started(&self, t: PipelineThread) {
        let (tx, rx) = crossbeam::channel::bounded::<()>(1);
        super::pool::warm_channel(&tx, &rx, || ());
        if let Err(reason) = priority::apply(t, self.realtime_priority) {
            let mut realtime = lock(&self.realtime);
            if !matches!(*realtime, Realtime::Refused { .. }) {
                let refused = Realtime::Refused {
                    priority: self.realtime_priority,
                    reason,
                };
                // Once per run: the run goes on, its latency at the mercy of other programs.
                tracing::warn!("{refused}; set budgets.realtime_priority = 0 to not ask");
                *realtime = refused;
            }
        }
        if let Some(hook) = self.hook {
            hook(t);
        }
    }

    /// A frame read but left unprocessed as the run ends: counted (whole, and per sensor for
    /// each valid image in it) and its slot back to the pool.
    pub(super) fn leave(&self, pool: &Pool, h: usize) {
        self.give_back(pool, h, &self.frames_left, |c| &c.left);
    }

    /// A frame that will not be processed: `frames` counts it, each sensor's `counter` each of
    /// its valid images, and its slot goes back to the pool.
    pub(super) fn give_back(
        &self,
        pool: &Pool,
        h: usize,
        frames: &AtomicU64,
        counter: impl Fn(&SensorCounters) -> &AtomicU64,
    ) {
        {
            let slot = pool.slot(h);
            for (img, c) in slot.frame.sensors().iter().zip(self.sensors.iter()) {
                if img.valid {
                    SensorCounters::add(counter(c), 1);
                }
            }
        }
        frames.fetch_add(1, Ordering::Relaxed);
        pool.release(h);
    }

    /// One read of the source: `d` of wall time, `cpu` of the capture thread's CPU time.
    pub(super) fn record_capture(&self, d: Duration, cpu: Duration) {
        lock(&self.capture).record(d);
        lock(&self.capture_cpu).record(cpu);
    }

    /// Adds the CPU time the calling thread has used since it started to `role`'s total: called
    /// by each pipeline thread as it ends.
    pub(super) fn add_thread_cpu(&self, role: ThreadRole) {
        let ns = u64::try_from(omnitrack_edges::thread_cpu_time().as_nanos()).unwrap_or(u64::MAX);
        self.add_cpu(role, Duration::from_nanos(ns));
    }

    pub(super) fn add_cpu(&self, role: ThreadRole, d: Duration) {
        let ns = u64::try_from(d.as_nanos()).unwrap_or(u64::MAX);
        self.thread_cpu_ns[role as usize].fetch_add(ns, Ordering::Relaxed);
    }

    pub(super) fn fail(&self, e: SourceError) {
        // Returned by `run_pipeline` (the caller says it); logged here only at `debug`.
        tracing::debug!("source failed: {e}");
        lock(&self.source_error).get_or_insert(e);
        self.halt.store(true, Ordering::Relaxed);
    }
}

pub(super) fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}
