//! The process thread: per frame, edges (the detector has its own workers) and the tracker, then
//! the pose sample; on schedule, the status sample.
//!
//! In: frame handles from the hand-over ([`Handover`](super::pool::Handover)). Out: the frame
//! back to the pool before publishing, a [`PoseSample`] per frame (the newest good pose known,
//! late ones included, while the frame has none, its covariance grown by `[motion]`'s speed
//! limits for the time since; initializing before any), a [`StatusSample`] every `budgets.status_interval_ms`, a [`FrameRecord`] per frame to
//! the sink's channel, and the [`ProcessOutcome`] at the end (a type of `summary`, which turns
//! it into the run's summary; this file uses it, not the other way).

use super::pool::Pool;
use super::publishing::{create_publisher, publishing};
use super::shared::{lock, Shared};
use super::stats::{Histogram, SensorCounters, ThreadRole};
use super::summary::{ProcessOutcome, RunEnd};
use super::{stage_budget, PipelineOptions, PipelineThread, Stage, StageClock, TICK};
use crate::FrameRecord;
use crossbeam::channel::{Receiver, RecvTimeoutError, Sender};
use nalgebra::Matrix6;
use omnitrack_config::{MotionConfig, TrackerConfig};
use omnitrack_core::geometry::Pose;
use omnitrack_core::model::Model;
use omnitrack_core::rig::Rig;
use omnitrack_edges::{thread_cpu_time, EdgeDetector};
use omnitrack_io::publish::{
    PosePublisher, PoseSample, SearchState, StatusPublisher, StatusSample, TrackerState, STATUS_MAX_SENSORS,
};
use omnitrack_tracker::visibility::VisibilityTable;
use omnitrack_tracker::{search_link, FrameResult, InitReport, SearchKind, Tracker, TrackerEvent};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

/// Publish errors logged at `warn` before the rest are only counted.
const WARN_LIMIT: u64 = 5;

/// The newest good pose known, with its time and covariance: what a frame without a pose of
/// its own publishes.
#[derive(Debug, Clone, Copy, PartialEq)]
struct LastGood {
    timestamp_ns: u64,
    pose: Pose,
    covariance: Matrix6<f64>,
}

/// Folds a good pose of the frame at `timestamp_ns` into the newest known: a frame's own, or a
/// late one (a search's frame and those kept during it, worked out after later frames came).
/// After a committed search the late poses are the only good ones until the backlog is worked
/// off, and the frames meanwhile must carry them, not the pose of before the search, or none.
fn fold_good(last: &mut Option<LastGood>, timestamp_ns: u64, r: &FrameResult) {
    let Some(pose) = r.pose else {
        return;
    };
    if last.is_none_or(|l| timestamp_ns >= l.timestamp_ns) {
        *last = Some(LastGood {
            timestamp_ns,
            pose,
            covariance: r.covariance,
        });
    }
}

/// What the pose service says for a frame at `timestamp_ns` whose result is `r`, once `last`
/// holds every good pose known (docs/interfaces.md, "PoseSample"): its own pose (tracking);
/// else the last good one with its covariance grown for the time since (lost); else, before any
/// pose, initializing (the pose fields meaningless, the covariance infinite).
fn pose_sample(
    r: &FrameResult,
    timestamp_ns: u64,
    last: Option<&LastGood>,
    motion: &MotionConfig,
) -> (TrackerState, Pose, Matrix6<f64>) {
    match (r.pose, last) {
        (Some(p), _) => (TrackerState::Tracking, p, r.covariance),
        (None, Some(l)) => (
            TrackerState::Lost,
            l.pose,
            grown_covariance(&l.covariance, timestamp_ns.saturating_sub(l.timestamp_ns), motion),
        ),
        (None, None) => (
            TrackerState::Initialising,
            Pose::identity(),
            Matrix6::from_diagonal_element(f64::INFINITY),
        ),
    }
}

/// The covariance of the last good pose `elapsed_ns` later, with nothing observed since: each
/// position σ grows by `max_speed_m_s` × the time, each rotation σ by `max_turn_rate_deg_s` × the
/// time (independent per axis, added to the variances), so the rig is within about one σ of the
/// last pose as long as it moved no faster than those.
fn grown_covariance(last: &Matrix6<f64>, elapsed_ns: u64, motion: &MotionConfig) -> Matrix6<f64> {
    let t = elapsed_ns as f64 * 1e-9;
    let (dp, dr) = (motion.max_speed_m_s * t, motion.max_turn_rate_deg_s.to_radians() * t);
    let mut c = *last;
    for k in 0..3 {
        c[(k, k)] += dp * dp;
        c[(k + 3, k + 3)] += dr * dr;
    }
    c
}

/// CPU time per processed frame (thread clocks), and the edge workers' share over the run.
#[derive(Default)]
pub(super) struct CpuClocks {
    pub(super) edges: Histogram,
    pub(super) track: Histogram,
    pub(super) frame: Histogram,
    /// The edge workers' CPU time on frames (the process thread's share apart).
    pub(super) edge_workers: Duration,
    /// The searches' helper threads' CPU time over the run (the search thread's apart).
    pub(super) search_helpers: Duration,
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
    /// CPU time per frame: edges (every thread's), tracker, the whole frame path.
    cpu: CpuClocks,
    budgets: omnitrack_config::BudgetConfig,
    max_frames: Option<u64>,
    processed: u64,
    last_ts: u64,
    /// The sequence number of the last frame processed.
    last_sequence: u64,
    /// The newest good pose known (of a frame or a late result), which the samples of frames
    /// without a pose carry, their covariance grown.
    last_good: Option<LastGood>,
    motion: MotionConfig,
    last_state: TrackerState,
    /// The search under way after the last frame, to say when one starts.
    searching: Option<SearchKind>,
    first_frame: Option<Instant>,
    last_frame: Option<Instant>,
    poses_published: u64,
    status_published: u64,
    publish_errors: u64,
    /// Delivered images per sensor at the last status, and when it was.
    status_delivered: Vec<u64>,
    status_rates: Vec<f32>,
    status_at: Instant,
    status_overruns: [u64; Stage::COUNT],
    /// What the last search made of its volume, and the widened diameter (m), for the status.
    search: SearchState,
    search_widened_to_m: f32,
    /// Who publishes (rig name, process id): every status sample starts from it.
    status_source: StatusSample,
    /// The CPU time of the current frame's edges and tracker (publishing is added to it).
    frame_cpu: Duration,
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
        // The frames have ended: a search under way and the frames kept meanwhile are worked
        // out for the sink (a stop does not wait for them).
        if matches!(reason, RunEnd::EndOfStream | RunEnd::MaxFrames) {
            self.tracker.finish();
            self.hand_over_late(self.last_sequence);
        }
        self.shared.halt.store(true, Ordering::Relaxed);
        // A frame still waiting for the tracker was read but is left: not dropped (no newer
        // frame replaced it), not processed.
        while let Ok(h) = self.ready.try_recv() {
            self.shared.leave(self.pool, h);
        }
        self.publish_status();
        ProcessOutcome {
            reason,
            clocks: std::mem::take(&mut self.clocks),
            cpu: CpuClocks {
                search_helpers: self.tracker.search_helpers_cpu(),
                ..std::mem::take(&mut self.cpu)
            },
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
            let cpu0 = thread_cpu_time();
            let edges = self.detector.detect(frame);
            let edge_time = started.elapsed();
            let cpu1 = thread_cpu_time();
            let edge_count = edges.len();
            let result = self.tracker.process(edges, timestamp_ns);
            let frame_time = started.elapsed();
            let track_cpu = thread_cpu_time().saturating_sub(cpu1);
            let edge_cpu = self.detector.last_cpu();
            self.cpu.edge_workers += edge_cpu.saturating_sub(cpu1.saturating_sub(cpu0));
            self.cpu.edges.record(edge_cpu);
            self.cpu.track.record(track_cpu);
            self.frame_cpu = edge_cpu + track_cpu;
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
                late: false,
            };
            (record, slot.arrived)
        };
        self.pool.release(h);
        // A search is seconds of silence (the whole model's, 10 s of work): the log says when
        // one starts, and which.
        let searching = self.tracker.search_under_way();
        if let (Some(kind), None) = (searching, self.searching) {
            tracing::info!(frame = record.sequence, "search started: {kind:?}");
        }
        self.searching = searching;
        self.last_ts = record.timestamp_ns;
        self.processed += 1;
        self.last_sequence = record.sequence;
        self.hand_over_late(record.sequence);
        let r = &record.result;
        match (&r.event, r.pose.is_some()) {
            (Some(TrackerEvent::Searched(rep)), _) => (self.search, self.search_widened_to_m) = search_state(rep),
            (_, true) => (self.search, self.search_widened_to_m) = (SearchState::None, 0.0),
            _ => {}
        }
        fold_good(&mut self.last_good, record.timestamp_ns, r);
        let (state, pose, covariance) = pose_sample(r, record.timestamp_ns, self.last_good.as_ref(), &self.motion);
        self.last_state = state;
        let publish_cpu = thread_cpu_time();
        let publish_time = self.publish_pose(&record, &pose, &covariance);
        let publish_cpu = thread_cpu_time().saturating_sub(publish_cpu);
        self.cpu.frame.record(self.frame_cpu + publish_cpu);
        let done = Instant::now();
        self.first_frame.get_or_insert(done);
        self.last_frame = Some(done);
        let c = &mut self.clocks;
        c[Stage::Edges.index()].record(record.edge_time);
        c[Stage::Match.index()].record(r.match_time);
        c[Stage::Solve.index()].record(r.solve_time);
        c[Stage::Track.index()].record(record.track_time);
        if let Some(t) = publish_time {
            c[Stage::Publish.index()].record(t);
        }
        c[Stage::Frame.index()].record(done - arrived);
        // The sink drains until this channel closes: a full buffer only makes the tracker wait.
        let _ = self.records.send(record);
    }

    /// Hands the sink the earlier frames' results the tracker worked out on this call (frames
    /// kept during a search: `Tracker::late`), before the frame's own. They are not published:
    /// subscribers have had later frames. The search they report sets the status's search state.
    fn hand_over_late(&mut self, sequence: u64) {
        for &(t, r) in self.tracker.late() {
            if let Some(TrackerEvent::Searched(rep)) = &r.event {
                (self.search, self.search_widened_to_m) = search_state(rep);
            }
            fold_good(&mut self.last_good, t, &r);
            let _ = self.records.send(FrameRecord::late(sequence, t, r));
        }
    }

    /// Publishes the frame's pose sample (of [`pose_sample`]); returns the time it took.
    fn publish_pose(&mut self, record: &FrameRecord, pose: &Pose, covariance: &Matrix6<f64>) -> Option<Duration> {
        let publisher = self.poses.as_ref()?;
        let r = &record.result;
        let started = Instant::now();
        let sent = publishing(|| {
            publisher.publish_pose(
                record.timestamp_ns,
                record.sequence,
                self.last_state,
                pose,
                covariance,
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
            searching: SearchKind::wire(self.tracker.search_under_way()),
            ..self.status_source
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
        for stage in Stage::ALL {
            let clock = match stage {
                Stage::Capture => &*capture,
                _ => &self.clocks[stage.index()],
            };
            let us = |d: Duration| u32::try_from(d.as_micros()).unwrap_or(u32::MAX);
            s.stage_p50_us[stage.index()] = us(clock.histogram.quantile(0.5));
            s.stage_p99_us[stage.index()] = us(clock.histogram.quantile(0.99));
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

/// What a search made of its volume, and the widened diameter (m), for the status.
fn search_state(rep: &InitReport) -> (SearchState, f32) {
    let state = rep.search_state();
    let widened = match state {
        SearchState::Widened => rep.widened_to_m.unwrap_or(0.0) as f32,
        _ => 0.0,
    };
    (state, widened)
}

/// The process thread's body. The publishers, the edge detector and the tracker are made here,
/// on this thread: the detector allocates nothing per frame only on the thread that built it.
#[allow(clippy::too_many_arguments)]
pub(super) fn run_process(
    shared: &Shared,
    pool: &Pool,
    ready_rx: Receiver<usize>,
    records_tx: Sender<FrameRecord>,
    rig: &Rig,
    model: &Model,
    table: &VisibilityTable,
    cfg: &TrackerConfig,
    opts: &PipelineOptions,
) -> ProcessOutcome {
    shared.thread_started(PipelineThread::Process);
    let mut publisher_error = None;
    let poses = create_publisher::<PoseSample>(opts.pose_service.as_deref(), &mut publisher_error);
    let status = create_publisher::<StatusSample>(opts.status_service.as_deref(), &mut publisher_error);
    if opts.require_services && publisher_error.is_some() {
        shared.halt.store(true, Ordering::Relaxed);
    }
    let clocks = Stage::ALL
        .iter()
        .map(|s| StageClock::new(stage_budget(*s, &cfg.budgets)))
        .collect();
    let mut processor = Processor {
        shared,
        pool,
        ready: ready_rx,
        records: records_tx,
        detector: EdgeDetector::for_tracking(rig, &cfg.edges),
        tracker: {
            let mut tracker = Tracker::new(rig, model, table, cfg, opts.run.hint, opts.run.seed);
            // A stop is honoured within a tick, not after the whole model's search: the search
            // ends at its next check and is discarded (no pose from half a search).
            tracker.stop_searches_on(std::sync::Arc::clone(shared.stop));
            tracker.stop_searches_on(std::sync::Arc::clone(&shared.halt));
            let _ = shared.search.set(std::sync::Arc::clone(tracker.search_progress()));
            tracker
        },
        poses,
        status,
        clocks,
        cpu: CpuClocks::default(),
        frame_cpu: Duration::ZERO,
        budgets: cfg.budgets.clone(),
        max_frames: opts.run.max_frames,
        processed: 0,
        last_sequence: 0,
        last_ts: 0,
        last_good: None,
        motion: cfg.motion.clone(),
        last_state: TrackerState::Initialising,
        searching: None,
        first_frame: None,
        last_frame: None,
        poses_published: 0,
        status_published: 0,
        publish_errors: 0,
        status_delivered: vec![0; rig.sensors.len()],
        status_rates: vec![0.0; rig.sensors.len()],
        status_at: Instant::now(),
        status_overruns: [0; Stage::COUNT],
        search: SearchState::None,
        search_widened_to_m: 0.0,
        status_source: {
            let mut s = StatusSample {
                pid: std::process::id(),
                ..StatusSample::default()
            };
            s.set_source(&rig.name);
            s
        },
    };
    // The searches run on their own thread while the frames go on (`omnitrack_tracker::background`);
    // it ends when the tracker, holding its job channel, is dropped with the processor.
    let (link, worker) = search_link();
    let mut outcome = std::thread::scope(|scope| {
        let worker = std::thread::Builder::new()
            .name("omnitrack-search".into())
            .spawn_scoped(scope, move || {
                shared.thread_started(PipelineThread::Search);
                worker.run();
                shared.add_thread_cpu(ThreadRole::Search);
            });
        // Without the thread the searches run on the frame path (and the link is dropped:
        // nothing would ever answer it).
        match worker {
            Ok(_) => {
                processor.tracker.attach_search_worker(link);
                // A live source (latest frame wins) does not wait for a search that is late: it
                // would drop the frames meanwhile. A lossless run waits, and answers every frame
                // as it would with the search inline.
                processor.tracker.defer_late_searches(!opts.lossless);
            }
            Err(e) => tracing::warn!("cannot start the search thread ({e}); searches run on the frame path"),
        }
        processor.run()
    });
    outcome.publisher_error = publisher_error;
    shared.add_cpu(ThreadRole::EdgeWorkers, outcome.cpu.edge_workers);
    shared.add_cpu(ThreadRole::Search, outcome.cpu.search_helpers);
    shared.add_thread_cpu(ThreadRole::Process);
    outcome
}

#[cfg(test)]
mod tests {
    use super::*;

    fn result(state: TrackerState, pose: Option<Pose>) -> FrameResult {
        let mut r = FrameResult::empty(state);
        r.pose = pose;
        if pose.is_some() {
            r.covariance = Matrix6::from_diagonal_element(1e-4);
        }
        r
    }

    /// Issue 50: between a committed search and the first frame caught up on, the frames have no
    /// pose of their own and the committed one comes late; they carry it (status lost, its
    /// covariance grown), not 0,0,0 with an infinite covariance. Before any pose: initializing.
    #[test]
    fn a_frame_without_a_pose_carries_the_newest_good_one_late_ones_included() {
        let motion = MotionConfig::default();
        let mut last = None;
        let searching = result(TrackerState::Initialising, None);
        let (state, _, c) = pose_sample(&searching, 100, last.as_ref(), &motion);
        assert_eq!(state, TrackerState::Initialising);
        assert!(c[(0, 0)].is_infinite());

        // The search committed on frame 100, handed over late on frame 400, which is being
        // caught up on (tracking, no pose yet).
        let committed = Pose::translation(1.0, 2.0, 1.5);
        fold_good(&mut last, 100, &result(TrackerState::Tracking, Some(committed)));
        let catching_up = result(TrackerState::Tracking, None);
        let (state, pose, c) = pose_sample(&catching_up, 400, last.as_ref(), &motion);
        assert_eq!(state, TrackerState::Lost);
        assert_eq!(pose, committed);
        assert!(c[(0, 0)] > 1e-4 && c[(0, 0)].is_finite(), "{}", c[(0, 0)]);
        assert_eq!(c, grown_covariance(&Matrix6::from_diagonal_element(1e-4), 300, &motion));

        // A frame's own pose wins, and a late pose older than the newest known changes nothing.
        let own = Pose::translation(1.1, 2.0, 1.5);
        let tracked = result(TrackerState::Tracking, Some(own));
        fold_good(&mut last, 500, &tracked);
        assert_eq!(pose_sample(&tracked, 500, last.as_ref(), &motion).1, own);
        fold_good(&mut last, 200, &result(TrackerState::Tracking, Some(committed)));
        assert_eq!(last.map(|l| (l.timestamp_ns, l.pose)), Some((500, own)));
        let (state, pose, _) = pose_sample(&catching_up, 600, last.as_ref(), &motion);
        assert_eq!((state, pose), (TrackerState::Lost, own));
    }

    #[test]
    fn the_last_good_covariance_grows_with_the_time_since_it() {
        let motion = MotionConfig::default();
        let last = Matrix6::from_diagonal(&nalgebra::Vector6::new(1e-4, 2e-4, 3e-4, 1e-6, 2e-6, 3e-6));
        assert_eq!(grown_covariance(&last, 0, &motion), last);
        let half = grown_covariance(&last, 500_000_000, &motion);
        let v = motion.max_speed_m_s * 0.5;
        let w = motion.max_turn_rate_deg_s.to_radians() * 0.5;
        assert!((half[(0, 0)] - (1e-4 + v * v)).abs() < 1e-12);
        assert!((half[(5, 5)] - (3e-6 + w * w)).abs() < 1e-12);
        assert_eq!(half[(0, 1)], 0.0);
        let one = grown_covariance(&last, 1_000_000_000, &motion);
        assert!((0..6).all(|k| one[(k, k)] > half[(k, k)]));
        // Never tracked: unknown stays unknown.
        let unknown = Matrix6::from_diagonal_element(f64::INFINITY);
        assert!(grown_covariance(&unknown, 1, &motion)[(0, 0)].is_infinite());
    }
}
