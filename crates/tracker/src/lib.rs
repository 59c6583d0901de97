//! The tracker: Koch–Teller §4.1 (initialisation, Figures 4 and 5) and §4.2 (maintenance,
//! Figures 7 and 8) on the edges, the prior visibility table and the pose solvers.
//!
//! In: per frame, the frame's [`Edge`]s (all sensors) and its capture time. Out: a
//! [`FrameResult`]: the tracker state (initializing → tracking → lost → tracking), the pose
//! `T_world_rig` with its covariance when tracking, and what the frame cost.
//!
//! States:
//! - **Initializing / Lost**: [`init::Initialiser`] searches a volume (the `--init` hint, the
//!   whole model without one, or after a loss a volume around the last good pose that grows with
//!   every failed attempt). Its best distinct candidates are then scored on the next frames
//!   (`confirm_frames`) before one is committed — the paper's admitted weakness is ambiguity from
//!   repeated structure (doorways along a corridor): a single frame may prefer the wrong one. On
//!   each of those frames a candidate must pass the search's acceptance test again, or it is
//!   dropped; with none left, the next frame searches afresh.
//! - **Tracking**: `maintenance` per Figure 7.
//!
//! The searches (initialisation, re-initialisation, relocalisation) run off the frame path and
//! are taken up a budget later on the frames' clock, the frames in between kept and caught up
//! on (module `background`); the earlier frames' poses come out through [`Tracker::late`].
//!
//! A frame is "bad" when the solve fails, leaves fewer than `min_inliers` accepted inliers, or
//! jumps more than `max_jump_m` / `max_jump_deg` from the motion prior; `lost_after_frames`
//! consecutive bad frames lose lock.
//!
//! Memory: everything is sized in [`Tracker::new`]; [`Tracker::process`] allocates nothing in
//! the tracking state (counted by a test). The initialisation's tables are also preallocated.

pub mod background;
pub mod correspondence;
pub mod edge_index;
mod floor;
pub mod init;
mod maintenance;
pub mod matching;
mod vanishing;
pub mod visibility;
mod vote;

use background::Backlog;
pub use background::{search_link, SearchJob, SearchLink, SearchWorker};
pub use correspondence::{CorrespondenceState, CorrespondenceTable, HeldEdge, Track};
pub use init::{Candidate, InitOptions, InitReport, Initialiser, SearchVolume};

use crate::visibility::VisibilityTable;
use matching::{best_edge, Gate, Predicted};
use nalgebra::{Matrix6, Point3, UnitQuaternion};
use omnitrack_config::TrackerConfig;
use omnitrack_core::geometry::{Correspondence, Pose};
use omnitrack_core::model::Model;
use omnitrack_core::rig::Rig;
use omnitrack_edges::Edge;
use omnitrack_solver::{ConsensusSampler, SolverOptions};
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Where the tracker is (the `status` of the pose message).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum TrackerState {
    Initializing,
    Tracking,
    Lost,
}

/// A search the tracker runs off the frame path ([`Tracker::search_under_way`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SearchKind {
    /// The first search for a pose: the hint's volume, or the whole model.
    Initialisation,
    /// The motion prior failed on a frame: a local search about the last good pose (module
    /// `maintenance`).
    Relocalisation,
    /// Tracking was lost: a search that widens with every failed attempt.
    Reinitialisation,
}

/// Something that happened on a frame, for logs and benchmarks.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TrackerEvent {
    /// An initialisation search ran.
    Searched(InitReport),
    /// A candidate was committed: tracking starts. `changed_mind`: the committed candidate was
    /// not the best on the search frame (the confirmation frames overruled it).
    Committed { candidates: usize, changed_mind: bool },
    /// Tracking was lost on this frame.
    LostLock,
    /// The motion prior failed on this frame and a local search found the pose.
    Relocalised,
}

/// The tracker's answer for one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameResult {
    pub state: TrackerState,
    /// `T_world_rig` when this frame was tracked.
    pub pose: Option<Pose>,
    /// Over (tx, ty, tz, rx, ry, rz), world frame (Kumar–Hanson §5).
    pub covariance: Matrix6<f64>,
    /// Accepted correspondences consistent with the pose.
    pub inliers: u32,
    /// Correspondences per state after the frame: unknown, pending, accepted.
    pub states: [u32; 3],
    pub xi_rad2: f64,
    /// Of the segments of VIS(T) long enough to be seen, the fraction with an edge within the
    /// inlier angle at the solved pose (maintenance frames; NaN otherwise).
    pub explained: f32,
    /// Consensus samples drawn.
    pub samples: u64,
    pub match_time: Duration,
    pub solve_time: Duration,
    pub event: Option<TrackerEvent>,
}

impl FrameResult {
    fn empty(state: TrackerState) -> FrameResult {
        FrameResult {
            state,
            pose: None,
            covariance: Matrix6::from_diagonal_element(f64::INFINITY),
            inliers: 0,
            states: [0; 3],
            xi_rad2: f64::NAN,
            explained: f32::NAN,
            samples: 0,
            match_time: Duration::ZERO,
            solve_time: Duration::ZERO,
            event: None,
        }
    }
}

/// Totals over a run.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct TrackerStats {
    pub frames: u64,
    pub tracked: u64,
    /// Initialisation searches after the first (re-initialisations after a loss).
    pub reinitialisations: u64,
    pub losses: u64,
    /// Frames rescued by a local search after the motion prior failed.
    pub relocalisations: u64,
    /// Wall time of the first search and of all searches.
    pub first_search: Option<Duration>,
    pub search_time: Duration,
    /// Commits where the confirmation frames overruled the search frame's best candidate.
    pub changed_mind: u64,
    /// Frames whose solve, far from the prediction, a second opinion replaced (the polished
    /// prediction, or the solve's rotation polished at the predicted position).
    pub second_opinions: u64,
    /// Searches the wall clock stopped before their work budget did ([`InitReport::backstop`]):
    /// their answers depend on the machine's load.
    pub search_backstops: u64,
    /// Adoption frames that had to wait for the search worker (module `background`), and how
    /// long in all: the machine was slower than the reference, or loaded.
    pub search_waits: u64,
    pub search_wait_time: Duration,
    /// Frames kept during a search and tracked afterwards (module `background`), and frames
    /// the backlog dropped (thinned during a long search, passed over by a fresh search when
    /// the backlog spans more than two budgets, or left at the end, [`Tracker::finish`]).
    pub caught_up: u64,
    pub backlog_dropped: u64,
    /// Due frames on which the worker was not done: the search was taken up on a later frame.
    pub search_deferrals: u64,
    /// Poses of kept frames, handed out late through [`Tracker::late`] (not in `tracked`).
    pub late_poses: u64,
    /// Over all initialisation searches: the grid cells meeting their volumes, and those they
    /// looked at before the budget was spent ([`InitReport::plan_cells_scanned`]).
    pub plan_cells_in_volume: u64,
    pub plan_cells_scanned: u64,
}

/// A search under way off the frame path: when its result is due (the search frame's timestamp
/// plus its budget, ns) and what its acceptance needs from the search frame.
#[derive(Debug, Clone, Copy)]
struct PendingSearch {
    started_ns: u64,
    due_ns: u64,
    volume: SearchVolume,
    turn_limit: Option<(UnitQuaternion<f64>, f64)>,
    floor: f64,
    /// Set for a relocalisation (module `maintenance`): what its frame concludes either way.
    relocalisation: Option<maintenance::Relocalisation>,
}

/// The search's acceptance test: enough inliers, and the pose and the frame explaining each
/// other well enough both ways (`accept_explained_fraction` of the segments it predicts,
/// `accept_support_fraction` of the frame's longest edges).
fn acceptable(cfg: &TrackerConfig, c: &Candidate) -> bool {
    let i = &cfg.initialisation;
    c.inliers >= cfg.maintenance.min_inliers as usize
        && c.explained >= i.accept_explained_fraction
        && c.support >= i.accept_support_fraction
}

/// Candidates this close to each other are one basin (m, rad): the margin of a clear winner
/// is over the others.
const BASIN_M: f64 = 0.6;
const BASIN_RAD: f64 = 0.175;

/// A rig imaging less than this share of the sphere is narrow: a half-turn or a step along a
/// symmetric corridor shows it the same lines (see `Tracker::narrow`). Four pinholes 90° wide
/// round the horizon see 0.6 of it; one 50° pinhole a twentieth.
const NARROW_VIEW_SHARE: f64 = 0.5;

/// A committed pose may lie this far outside the search volume (m): the truth at the volume's
/// edge polishes a few centimetres either way.
const VOLUME_SLACK_M: f64 = 0.1;

/// Frames kept while a search runs (module `background`): a 950 ms search at 30 Hz keeps all
/// of its 29; a longer one (the whole model) keeps every other, every fourth… A slot holds the
/// rig's most edges (the shipped rig: 1,536 of 248 bytes, 0.38 MB), so the backlog is about
/// 12 MB, made at start-up.
const BACKLOG_FRAMES: usize = 32;

/// Kept frames tracked per arriving frame once a search is taken up: one more than arrive, so the
/// backlog shrinks by two a frame, and each frame's time stays bounded by a few maintenance
/// steps (a few milliseconds each) rather than the search's hundreds.
pub const CATCH_UP_FRAMES: usize = 3;

/// Whether `pose` lies in `volume` (within [`VOLUME_SLACK_M`] of it).
fn within(volume: &SearchVolume, pose: &Pose) -> bool {
    volume
        .diameter_m
        .is_none_or(|d| (pose.translation.vector - volume.centre.coords).norm() <= 0.5 * d + VOLUME_SLACK_M)
}

/// A candidate under confirmation.
#[derive(Debug, Clone, Copy)]
struct Confirming {
    pose: Pose,
    merit_sum: f64,
    frames: u32,
    alive: bool,
}

/// The tracker for one rig, model and visibility table.
pub struct Tracker<'m> {
    model: &'m Model,
    table: &'m VisibilityTable,
    cfg: TrackerConfig,
    solver: SolverOptions,
    centres: Vec<Point3<f64>>,
    init: Initialiser<'m>,
    tracks: CorrespondenceTable,
    sampler: ConsensusSampler,
    /// S̄ for the solver and, per entry, its track.
    set: Vec<Correspondence>,
    set_track: Vec<usize>,
    /// Per track: the edge matched this frame and its α.
    matched: Vec<Option<(u32, f64)>>,
    /// The weights and residuals of the final robust fit (`solver::refine::cauchy`).
    robust_scratch: Vec<f64>,
    rng: SmallRng,
    state: TrackerState,
    hint: Option<SearchVolume>,
    pose: Pose,
    /// Previous tracked pose and its time, for the constant-velocity prior.
    previous: Option<(Pose, u64)>,
    last_time: u64,
    last_good: Option<Pose>,
    /// When `last_good` was seen (ns).
    last_good_time: u64,
    /// Post-loss searches double their volume after each widened attempt fails.
    volume_level: u32,
    confirming: [Confirming; 4],
    confirm_count: usize,
    search_attempts: u32,
    bad_frames: u32,
    /// Inliers of the last good frame.
    last_inliers: u32,
    /// The last search found no acceptable candidate: search more broadly.
    widen: bool,
    /// The rig images less than half the sphere: one view cannot tell a symmetric place from its
    /// twin, so a commit needs `narrow_rig_searches` decided searches in a row to choose one
    /// place.
    narrow: bool,
    /// The place the last decided searches chose (narrow rigs), and how many in a row chose it.
    agreed: Option<(Pose, u32)>,
    /// Running mean of the fraction of VIS(T) that good frames explain (NaN before the first
    /// commit): a pose explaining much less is suspect (`maintenance.min_explained_ratio`).
    explained_ref: f64,
    stats: TrackerStats,
    /// The search job while it is at home (module `background`), the worker it goes to, and
    /// the search under way.
    job: Option<Box<SearchJob<'m>>>,
    link: Option<SearchLink<'m>>,
    pending: Option<PendingSearch>,
    /// The frames that arrive during a search, and the buffer a kept frame is tracked from.
    backlog: Backlog,
    scratch: Vec<Edge>,
    /// A due search whose worker is not done is taken up on a later frame rather than waited
    /// for ([`Tracker::defer_late_searches`]).
    defer: bool,
    /// Results of earlier frames worked out on this call (see [`Tracker::late`]).
    late: Vec<(u64, FrameResult)>,
    /// Stops a search on the worker when the tracker goes (no one will read it).
    cancel: Arc<AtomicBool>,
}

impl Drop for Tracker<'_> {
    /// A search still running on the worker stops at its next check: the worker's thread then
    /// ends promptly with the tracker's side of the link.
    fn drop(&mut self) {
        self.cancel.store(true, Ordering::Relaxed);
    }
}

impl<'m> Tracker<'m> {
    /// A tracker that starts by searching `hint` (`None`: the whole model). `seed` drives the
    /// random sampling (same seed and input, same output).
    pub fn new(
        rig: &Rig,
        model: &'m Model,
        table: &'m VisibilityTable,
        cfg: &TrackerConfig,
        hint: Option<SearchVolume>,
        seed: u64,
    ) -> Tracker<'m> {
        let solver = cfg.solver_options();
        let max_edges = rig.sensors.len() * cfg.edges.max_edges_per_sensor as usize;
        let m = &cfg.maintenance;
        let opts = InitOptions::from_config(cfg);
        let init = Initialiser::new(rig, model, table, opts.clone(), solver.clone(), max_edges);
        let cancel = Arc::new(AtomicBool::new(false));
        let mut searcher = Initialiser::new(rig, model, table, opts, solver.clone(), max_edges);
        searcher.set_cancel(cancel.clone());
        let job = Box::new(SearchJob::new(searcher, max_edges));
        let narrow = init.view_share() < NARROW_VIEW_SHARE;
        let max_set = (0..table.node_count() as u32)
            .map(|n| table.node_set(n).segments.len())
            .max()
            .unwrap_or(0);
        // Twice the largest set: seen correspondences outlive their node's set (module doc of
        // `correspondence`).
        let capacity = (2 * max_set).max(16);
        let lambda = (m.sample_size as usize).min(capacity);
        Tracker {
            model,
            table,
            cfg: cfg.clone(),
            solver,
            centres: rig.sensors.iter().map(|s| s.centre()).collect(),
            init,
            tracks: CorrespondenceTable::new(capacity),
            sampler: ConsensusSampler::new(capacity, lambda, m.max_samples as u64),
            set: Vec::with_capacity(capacity),
            set_track: Vec::with_capacity(capacity),
            matched: vec![None; capacity],
            robust_scratch: vec![0.0; 2 * capacity],
            rng: SmallRng::seed_from_u64(seed),
            state: TrackerState::Initializing,
            hint,
            pose: Pose::identity(),
            previous: None,
            last_time: 0,
            last_good: None,
            last_good_time: 0,
            volume_level: 0,
            confirming: [Confirming {
                pose: Pose::identity(),
                merit_sum: 0.0,
                frames: 0,
                alive: false,
            }; 4],
            confirm_count: 0,
            search_attempts: 0,
            bad_frames: 0,
            last_inliers: 0,
            widen: false,
            narrow,
            agreed: None,
            explained_ref: f64::NAN,
            stats: TrackerStats::default(),
            job: Some(job),
            link: None,
            pending: None,
            backlog: Backlog::new(BACKLOG_FRAMES, max_edges),
            scratch: Vec::with_capacity(max_edges),
            late: Vec::with_capacity(BACKLOG_FRAMES + 1),
            defer: false,
            cancel,
        }
    }

    /// Runs the searches on a worker from now on (module `background`): `link` sends jobs to a
    /// thread running [`SearchWorker::run`] and takes them back. Without one, a search runs on the
    /// frame that starts it; its result is taken up on the same later frame either way.
    pub fn attach_search_worker(&mut self, link: SearchLink<'m>) {
        self.link = Some(link);
    }

    /// With `on`, a frame on which a search is due but the worker is not done does not wait
    /// for it: the search is taken up on a later frame (counted in
    /// [`TrackerStats::search_deferrals`]), and the frames meanwhile come out late, with the same
    /// poses, unless the backlog fills and is thinned meanwhile (counted in
    /// [`TrackerStats::backlog_dropped`]). For a live source, where waiting costs dropped frames;
    /// a lossless replay (the default, off) waits, and every frame is answered exactly as with
    /// the search inline.
    pub fn defer_late_searches(&mut self, on: bool) {
        self.defer = on;
    }

    /// Whether a search is under way.
    pub fn searching(&self) -> bool {
        self.pending.is_some()
    }

    /// The search under way, if any: why frames are not being tracked just now.
    pub fn search_under_way(&self) -> Option<SearchKind> {
        let pending = self.pending.as_ref()?;
        Some(if pending.relocalisation.is_some() {
            SearchKind::Relocalisation
        } else if self.state == TrackerState::Initializing {
            SearchKind::Initialisation
        } else {
            SearchKind::Reinitialisation
        })
    }

    /// Starts a search of the current state's volume on this frame's `edges` (module
    /// `background`).
    fn start_search(&mut self, edges: &[Edge], timestamp_ns: u64) {
        let Some(mut job) = self.job.take() else {
            return;
        };
        let volume = self.search_volume();
        let budget = self.search_budget();
        let i = &self.cfg.initialisation;
        let breadth = if self.widen {
            (
                i.wide_edges_considered as usize,
                i.wide_segments_considered as usize,
                i.wide_samples_per_cell as usize,
            )
        } else {
            (
                i.edges_considered as usize,
                i.segments_considered as usize,
                i.samples_per_cell as usize,
            )
        };
        // After a loss the rig cannot have turned further than its turn rate allows since
        // the last good frame: the mirror twin of a symmetric room is refused.
        let turn_limit = match (self.state, self.last_good) {
            (TrackerState::Lost, Some(p)) => Some((p.rotation, self.max_turn_rad(timestamp_ns))),
            _ => None,
        };
        // After a loss, a candidate must also explain about as much as the frames before
        // it did; the requirement relaxes with every failed attempt, since the rig may
        // have walked somewhere that is seen less well.
        let floor = match self.state {
            TrackerState::Lost => self.explained_floor(self.search_attempts),
            _ => 0.0,
        };
        // Quarter-turn twins are worth searching only where any heading is plausible.
        let yaw_twins = turn_limit.is_none_or(|(_, limit)| limit >= std::f64::consts::PI);
        let rng = SmallRng::seed_from_u64(self.rng.random());
        job.prepare(edges, volume, budget, breadth, yaw_twins, turn_limit, rng);
        let pending = PendingSearch {
            started_ns: timestamp_ns,
            due_ns: timestamp_ns.saturating_add(u64::try_from(budget.as_nanos()).unwrap_or(u64::MAX)),
            volume,
            turn_limit,
            floor,
            relocalisation: None,
        };
        self.launch(job, pending);
    }

    /// The budget of the search the current state would start: the whole model's or a volume's.
    fn search_budget(&self) -> Duration {
        let budget_ms = if self.search_volume().diameter_m.is_none() {
            self.cfg.initialisation.whole_model_time_budget_ms
        } else {
            self.cfg.initialisation.time_budget_ms
        };
        Duration::from_secs_f64(budget_ms.max(0.0) / 1e3)
    }

    /// Sends a prepared job to the worker (or runs it here without one) and marks it under way.
    fn launch(&mut self, mut job: Box<SearchJob<'m>>, pending: PendingSearch) {
        self.pending = Some(pending);
        match &self.link {
            Some(link) => {
                if let Err(e) = link.jobs.send(job) {
                    // The worker is gone: search here.
                    self.link = None;
                    let mut job = e.into_inner();
                    job.run();
                    self.job = Some(job);
                }
            }
            None => {
                job.run();
                self.job = Some(job);
            }
        }
    }

    /// Whether the search under way is done (its job at home, or back from the worker now).
    fn search_done(&mut self) -> bool {
        if self.job.is_some() {
            return true;
        }
        let Some(link) = self.link.as_ref() else {
            return true;
        };
        match link.done.try_recv() {
            Ok(job) => {
                self.job = Some(job);
                true
            }
            Err(crossbeam::channel::TryRecvError::Empty) => false,
            // The worker is gone: `collect_search` says so.
            Err(crossbeam::channel::TryRecvError::Disconnected) => true,
        }
    }

    /// The finished job of the search under way: at home already, or back from the worker
    /// (waiting for it, counted, if it is not done).
    fn collect_search(&mut self) -> Option<Box<SearchJob<'m>>> {
        if let Some(job) = self.job.take() {
            return Some(job);
        }
        let link = self.link.as_ref()?;
        if let Ok(job) = link.done.try_recv() {
            return Some(job);
        }
        let waited = Instant::now();
        let job = link.done.recv().ok();
        self.stats.search_waits += 1;
        self.stats.search_wait_time += waited.elapsed();
        if job.is_none() {
            self.link = None;
        }
        job
    }

    pub fn state(&self) -> TrackerState {
        self.state
    }

    pub fn stats(&self) -> &TrackerStats {
        &self.stats
    }

    /// S_t.
    pub fn correspondences(&self) -> &[Track] {
        self.tracks.tracks()
    }

    /// The candidates being weighed while initialising: pose, mean merit so far
    /// ([`Candidate::merit`], higher is better), frames scored, and whether it is still in the
    /// running.
    pub fn candidates(&self) -> impl Iterator<Item = (Pose, f64, u32, bool)> + '_ {
        self.confirming[..self.confirm_count]
            .iter()
            .map(|c| (c.pose, c.merit_sum / c.frames.max(1) as f64, c.frames, c.alive))
    }

    /// The search's own refinement and score of any pose (`Initialiser::polish`): for
    /// diagnostics and benchmarks, e.g. how the true pose would have scored.
    pub fn polish(&mut self, pose: &Pose, edges: &[Edge]) -> Option<Candidate> {
        self.init.polish(pose, edges)
    }

    /// How many model segments the rig would see long enough to detect from `pose`
    /// (`Initialiser::segments_in_view`): for benchmarks, e.g. whether a frame can be
    /// initialised at all.
    pub fn segments_in_view(&mut self, pose: &Pose) -> usize {
        self.init.segments_in_view(pose)
    }

    /// The current pose estimate (meaningful when tracking).
    pub fn pose(&self) -> &Pose {
        &self.pose
    }

    /// One frame: initialisation or maintenance depending on the state; while a search is under
    /// way, the frame is kept and, once the search is taken up, caught up on (module
    /// `background`).
    pub fn process(&mut self, edges: &[Edge], timestamp_ns: u64) -> FrameResult {
        self.stats.frames += 1;
        self.late.clear();
        let result = if self.pending.is_none() && self.backlog.is_empty() {
            self.step(edges, timestamp_ns)
        } else {
            self.behind(edges, timestamp_ns)
        };
        if result.pose.is_some() {
            self.stats.tracked += 1;
        }
        result
    }

    /// One frame's work in the current state.
    fn step(&mut self, edges: &[Edge], timestamp_ns: u64) -> FrameResult {
        let result = match self.state {
            TrackerState::Tracking => self.maintain(edges, timestamp_ns),
            TrackerState::Initializing | TrackerState::Lost => self.initialise(edges, timestamp_ns),
        };
        self.last_time = timestamp_ns;
        result
    }

    /// A frame that arrives while a search is under way, or while frames kept during one wait:
    /// it joins the backlog; a search that is due is taken up on its own frame; then up to
    /// [`CATCH_UP_FRAMES`] kept frames are tracked, oldest first. The frame gets a pose once
    /// the backlog has been worked off up to it.
    fn behind(&mut self, edges: &[Edge], timestamp_ns: u64) -> FrameResult {
        let started = Instant::now();
        self.backlog.push(edges, timestamp_ns);
        if let Some(pending) = self.pending {
            // Not due yet; or due, but the worker is not done (a machine slower than the
            // reference, or loaded) and the frames do not wait for it. Taking a search up later
            // changes no pose (the same search, judged on its own frame, then the same kept
            // frames), only which of them are answered late; unless the backlog fills and is
            // thinned meanwhile (counted in `backlog_dropped`): the last backstop under load.
            let deferred = self.defer && timestamp_ns >= pending.due_ns && !self.search_done();
            if timestamp_ns < pending.due_ns || deferred {
                self.stats.search_deferrals += u64::from(deferred);
                let mut result = FrameResult::empty(self.state);
                result.match_time = started.elapsed();
                return result;
            }
            self.pending = None;
            let r = self.take_up(pending);
            self.note_late(pending.started_ns, r);
        }
        let mut result = None;
        for _ in 0..CATCH_UP_FRAMES {
            if self.pending.is_some() || self.backlog.is_empty() {
                break;
            }
            match self.catch_up_one() {
                Some((_, r)) if self.backlog.is_empty() => result = Some(r),
                Some((t, r)) => self.note_late(t, r),
                None => break,
            }
        }
        let mut result = result.unwrap_or_else(|| FrameResult::empty(self.state));
        result.match_time = started.elapsed();
        result
    }

    /// Tracks the oldest kept frame; a fresh search starts from it too. Not from the newest: a
    /// search that failed is followed by one on the next frame, as inline, so that the searches
    /// after a start stay near the hint's time (searching from the newest, the corridor's
    /// searches fell 1 s apart, the rig walked out of the hint's reach between them, and the
    /// sixth search committed the next doorway, 4 m off).
    fn catch_up_one(&mut self) -> Option<(u64, FrameResult)> {
        // ... unless the kept frames span more than two search budgets (a worker slower than the
        // frames, searching again and again): then from the newest, so the lag stays bounded.
        if self.state != TrackerState::Tracking && self.confirm_count == 0 {
            let budget_ns = u64::try_from(self.search_budget().as_nanos()).unwrap_or(u64::MAX);
            if self.backlog.span_ns() > budget_ns.saturating_mul(2) {
                let before = self.backlog.dropped;
                self.backlog.keep_newest();
                self.stats.backlog_dropped += self.backlog.dropped - before;
            }
        }
        let mut buf = std::mem::take(&mut self.scratch);
        let t = self.backlog.pop_into(&mut buf);
        let r = t.map(|t| (t, self.step(&buf, t)));
        self.scratch = buf;
        self.stats.caught_up += u64::from(r.is_some());
        r
    }

    /// Keeps an earlier frame's result for [`Tracker::late`] when it has a pose or an event.
    fn note_late(&mut self, timestamp_ns: u64, r: FrameResult) {
        if (r.pose.is_some() || r.event.is_some()) && self.late.len() < self.late.capacity() {
            self.stats.late_poses += u64::from(r.pose.is_some());
            self.late.push((timestamp_ns, r));
        }
    }

    /// The results of earlier frames worked out on the last call of [`Tracker::process`] or
    /// [`Tracker::finish`], oldest first, with their timestamps: the search frame's once its search
    /// is taken up, and the kept frames' as they are caught up on (only those with a pose or an
    /// event). They are older than the frames already answered, so a live subscriber does not
    /// want them; a trajectory does.
    pub fn late(&self) -> &[(u64, FrameResult)] {
        &self.late
    }

    /// The frames have ended: a search under way is taken up now (waiting for it) and every kept
    /// frame is tracked, their results in [`Tracker::late`], so that a recording's last second
    /// is not lost. Kept frames that would need a fresh search are dropped (counted).
    pub fn finish(&mut self) {
        self.late.clear();
        if let Some(pending) = self.pending.take() {
            let r = self.take_up(pending);
            self.note_late(pending.started_ns, r);
        }
        while !self.backlog.is_empty() {
            if self.state != TrackerState::Tracking && self.confirm_count == 0 {
                break;
            }
            match self.catch_up_one() {
                Some((t, r)) => self.note_late(t, r),
                None => break,
            }
        }
        let before = self.backlog.dropped;
        while self.backlog.pop_into(&mut self.scratch).is_some() {
            self.backlog.dropped += 1;
        }
        self.stats.backlog_dropped += self.backlog.dropped - before;
    }

    /// Figure 5 (started here, run off the frame path and taken up by [`Tracker::adopt`]) plus
    /// the confirmation of candidates over the next frames.
    fn initialise(&mut self, edges: &[Edge], timestamp_ns: u64) -> FrameResult {
        let started = Instant::now();
        let mut result = FrameResult::empty(self.state);
        if self.confirm_count == 0 {
            self.start_search(edges, timestamp_ns);
            result.match_time = started.elapsed();
            return result;
        }
        // Each confirmation frame applies the search's acceptance test again: a candidate that
        // explains less than `accept_explained_fraction` of what it predicts here is dropped,
        // and when none is left the next frame searches afresh. (The wrong commits in `lab`'s
        // initialisation trials were candidates that barely passed on the search frame and
        // failed it on the next while the truth was never found.)
        for k in 0..self.confirm_count {
            if !self.confirming[k].alive {
                continue;
            }
            match self.init.polish(&self.confirming[k].pose, edges) {
                Some(c) if acceptable(&self.cfg, &c) => {
                    let slot = &mut self.confirming[k];
                    slot.pose = c.pose;
                    slot.merit_sum += c.merit();
                    slot.frames += 1;
                }
                _ => self.confirming[k].alive = false,
            }
        }
        let mut result = self.decide(edges, timestamp_ns, result);
        result.match_time = started.elapsed();
        result
    }

    /// Takes up a finished search on its own frame: an initialisation's or a relocalisation's.
    fn take_up(&mut self, pending: PendingSearch) -> FrameResult {
        let result = match pending.relocalisation {
            Some(r) => self.conclude_relocalisation(r, pending.started_ns),
            None => self.adopt(pending),
        };
        self.last_time = pending.started_ns;
        result
    }

    /// Takes up a finished initialisation search on its own frame (the job holds that frame's edges): its
    /// acceptable candidates go to confirmation, and a clear decision commits there and then.
    fn adopt(&mut self, pending: PendingSearch) -> FrameResult {
        let mut result = FrameResult::empty(self.state);
        let Some(job) = self.collect_search() else {
            return result;
        };
        let PendingSearch {
            volume,
            turn_limit,
            floor,
            started_ns,
            ..
        } = pending;
        let (candidates, report) = job.result();
        let report = *report;
        // A volume without a valid node was searched out to the nearest ones.
        let volume = SearchVolume {
            diameter_m: report.widened_to_m.or(volume.diameter_m),
            ..volume
        };
        let plausible = |c: &Candidate| turn_limit.is_none_or(|(r, limit)| c.pose.rotation.angle_to(&r) <= limit);
        // And it must be a clear winner: every other candidate of the search that is not in
        // its basin (the same place turned, or a step away) explains at most
        // `clear_winner_ratio` of what it explains. Repeated structure (the twin turned a
        // half or quarter round, the next door along) is refused by evidence; "no pose yet"
        // is better than a wrong one.
        let ratio = self.cfg.initialisation.clear_winner_ratio;
        let clear = |c: &Candidate| {
            candidates
                .iter()
                .filter(|o| !init::same_pose(&o.pose, &c.pose, BASIN_M, BASIN_RAD))
                .all(|o| o.merit() <= ratio * c.merit())
        };
        // And it must lie in the volume searched (the polish may carry a start beyond it): a
        // hint says where the rig is. Candidates outside still count as rivals above.
        let inside = |c: &Candidate| within(&volume, &c.pose);
        let accepted =
            |c: &&Candidate| acceptable(&self.cfg, c) && plausible(c) && c.explained >= floor && inside(c) && clear(c);
        // A failed search is repeated once more broadly on the same volume; if that fails
        // too, the volume doubles and the breadth is normal again (widening a large volume
        // only lets the time budget cover fewer cells).
        let failed = !candidates.iter().any(|c| accepted(&c));
        if failed && self.widen {
            self.volume_level += 1;
        }
        self.widen = failed && !self.widen;
        let mut n = 0;
        for c in candidates.iter().filter(accepted).take(self.confirming.len()) {
            self.confirming[n] = Confirming {
                pose: c.pose,
                merit_sum: c.merit(),
                frames: 1,
                alive: true,
            };
            n += 1;
        }
        self.confirm_count = n;
        if self.search_attempts > 0 || self.stats.first_search.is_some() {
            self.stats.reinitialisations += 1;
        }
        self.search_attempts += 1;
        self.stats.search_time += report.elapsed;
        self.stats.plan_cells_in_volume += report.plan_cells_in_volume as u64;
        self.stats.plan_cells_scanned += report.plan_cells_scanned as u64;
        self.stats.search_backstops += u64::from(report.backstop);
        self.stats.first_search.get_or_insert(report.elapsed);
        result.event = Some(TrackerEvent::Searched(report));
        if n > 0 {
            result = self.decide(job.edges(), started_ns, result);
        }
        self.job = Some(job);
        self.last_time = started_ns;
        result
    }

    /// Whether the candidates under confirmation are told apart (and, for a narrow rig, agreed
    /// on): the winner is committed on this frame, or, when they cannot be told apart, the next
    /// frame searches afresh. `result` is this frame's answer so far.
    fn decide(&mut self, edges: &[Edge], timestamp_ns: u64, mut result: FrameResult) -> FrameResult {
        let alive = self.confirming[..self.confirm_count].iter().filter(|c| c.alive).count();
        let frames = self.confirming[..self.confirm_count]
            .iter()
            .filter(|c| c.alive)
            .map(|c| c.frames)
            .max()
            .unwrap_or(0);
        let decided = alive == 1 || self.clear_winner();
        // A narrow rig's search that decided counts towards agreement: it commits only once
        // `narrow_rig_searches` decided searches in a row chose the same place.
        let agreement = match (decided, self.narrow) {
            (true, true) => {
                let best = self.best_confirming().map(|(_, c)| c.pose);
                let n = match (self.agreed, best) {
                    (Some((place, n)), Some(p)) if init::same_pose(&p, &place, BASIN_M, BASIN_RAD) => n + 1,
                    _ => 1,
                };
                self.agreed = best.map(|p| (p, n));
                n
            }
            _ => u32::MAX,
        };
        if alive == 0 || (frames >= self.cfg.initialisation.confirm_frames && !decided) {
            // Nothing left, or the frames did not tell the candidates apart: search afresh. Two
            // places that stayed alike are the ambiguity a narrow rig's agreement waits out.
            if alive > 1 {
                self.agreed = None;
            }
            self.confirm_count = 0;
        } else if decided && agreement < self.cfg.initialisation.narrow_rig_searches {
            // Not yet agreed: search afresh.
            self.confirm_count = 0;
        } else if decided {
            self.agreed = None;
            let (k, winner) = self.best_confirming().expect("one candidate is alive");
            let changed_mind = k != 0;
            if changed_mind {
                self.stats.changed_mind += 1;
            }
            let candidates = self.confirm_count;
            self.confirm_count = 0;
            result = self.commit(&winner.pose, edges, timestamp_ns);
            result.event = Some(TrackerEvent::Committed {
                candidates,
                changed_mind,
            });
        }
        result
    }

    /// The live candidate with the best mean merit, and its index (0: the search's own best).
    fn best_confirming(&self) -> Option<(usize, Confirming)> {
        self.confirming[..self.confirm_count]
            .iter()
            .enumerate()
            .filter(|(_, c)| c.alive)
            .max_by(|a, b| (a.1.merit_sum / a.1.frames as f64).total_cmp(&(b.1.merit_sum / b.1.frames as f64)))
            .map(|(k, c)| (k, *c))
    }

    /// Whether the best candidate so far beats every other outside its basin by the configured
    /// margin (their mean merit at most `clear_winner_ratio` × its): no further frames are needed
    /// to decide. Candidates in its basin (the same place a few centimetres or a degree apart,
    /// as the search's own clear-winner test counts them) are the same answer, not rivals: they
    /// score alike on every frame, and counting them kept the tracker searching afresh forever
    /// where the search had found nothing but the truth (ZInD `pano_33`).
    fn clear_winner(&self) -> bool {
        let live = || self.confirming[..self.confirm_count].iter().filter(|c| c.alive);
        let mean = |c: &Confirming| c.merit_sum / c.frames.max(1) as f64;
        let Some(best) = live().max_by(|a, b| mean(a).total_cmp(&mean(b))) else {
            return false;
        };
        let ratio = self.cfg.initialisation.clear_winner_ratio;
        live()
            .filter(|c| !init::same_pose(&c.pose, &best.pose, BASIN_M, BASIN_RAD))
            .all(|c| mean(c) <= ratio * mean(best))
    }

    /// The least fraction of VIS(T) a pose must explain: `min_explained_ratio` of the running
    /// mean, relaxed by a fifth for each of `relax` failed attempts (0 before the first commit).
    fn explained_floor(&self, relax: u32) -> f64 {
        let ratio = self.cfg.maintenance.min_explained_ratio;
        if ratio <= 0.0 || !self.explained_ref.is_finite() {
            return 0.0;
        }
        ratio * self.explained_ref * 0.8f64.powi(relax.min(32) as i32)
    }

    /// Folds a good frame's explained fraction into the running mean (about ten frames).
    fn note_explained(&mut self, explained: f64) {
        self.explained_ref = if self.explained_ref.is_finite() {
            0.9 * self.explained_ref + 0.1 * explained
        } else {
            explained
        };
    }

    /// The largest turn since the last good frame that is still plausible at `timestamp_ns`.
    fn max_turn_rad(&self, timestamp_ns: u64) -> f64 {
        let elapsed_s = timestamp_ns.saturating_sub(self.last_good_time) as f64 * 1e-9;
        self.cfg.maintenance.max_jump_deg.to_radians() + self.cfg.motion.max_turn_rate_deg_s.to_radians() * elapsed_s
    }

    /// Where to search now: the hint or the whole model at first; after a loss, around the
    /// last good pose, the volume doubling in diameter with every failed attempt.
    fn search_volume(&self) -> SearchVolume {
        match (self.state, self.last_good) {
            (TrackerState::Lost, Some(p)) => {
                let base = self.cfg.initialisation.search_diameter_m;
                let grow = 2f64.powi(self.volume_level.min(6) as i32);
                SearchVolume {
                    centre: Point3::from(p.translation.vector),
                    diameter_m: Some(base * grow).filter(|d| *d < 64.0 * base),
                }
            }
            _ => self.hint.unwrap_or(SearchVolume {
                centre: Point3::origin(),
                diameter_m: None,
            }),
        }
    }

    /// Starts tracking at a known `pose`, as if a search had committed it: what maintenance
    /// makes of a right start, apart from whether a search finds it (benchmarks, tests).
    pub fn start_at(&mut self, pose: &Pose, edges: &[Edge], timestamp_ns: u64) -> FrameResult {
        self.stats.frames += 1;
        self.stats.tracked += 1;
        self.confirm_count = 0;
        self.agreed = None;
        let result = self.commit(pose, edges, timestamp_ns);
        self.last_time = timestamp_ns;
        result
    }

    /// Tracking starts at `pose`: S_0 is VIS(pose), the matched ones accepted.
    fn commit(&mut self, pose: &Pose, edges: &[Edge], timestamp_ns: u64) -> FrameResult {
        self.state = TrackerState::Tracking;
        self.search_attempts = 0;
        self.bad_frames = 0;
        self.pose = *pose;
        self.previous = None;
        self.last_good = Some(*pose);
        self.last_good_time = timestamp_ns;
        self.volume_level = 0;
        let gate = Gate::geometric(self.cfg.maintenance.inlier_angle_deg.to_radians());
        let min_len = self.cfg.edges.min_edge_length_deg.to_radians();
        self.tracks.clear();
        let (mut eligible, mut seen) = (0u32, 0u32);
        if let Some(set) = self.table.query(&Point3::from(pose.translation.vector)) {
            let (model, centres) = (self.model, &self.centres);
            self.tracks.reset_with(set.segments.iter().map(|&s| {
                let seg = &model.segments[s as usize];
                let pred = Predicted::new(&[seg.a, seg.b], pose, centres);
                eligible += (pred.length_rad >= min_len) as u32;
                match (pred.length_rad >= min_len)
                    .then(|| best_edge(&pred, centres, edges, &gate))
                    .flatten()
                {
                    Some((e, _)) => {
                        seen += 1;
                        Track::accepted(s, HeldEdge::from(&edges[e]))
                    }
                    None => Track::unknown(s),
                }
            }));
        }
        // The committed pose passed the search's own tests: where it explains less than the
        // running mean, the rig has come somewhere seen less well, and that is the new norm.
        let explained = seen as f64 / eligible.max(1) as f64;
        // (`f64::min` takes the number over NaN: the first commit sets the mean.)
        self.explained_ref = self.explained_ref.min(explained);
        let mut result = FrameResult::empty(TrackerState::Tracking);
        self.collect_accepted_set(edges, pose, true);
        result.inliers = self.set.len() as u32;
        self.last_inliers = result.inliers;
        result.covariance = omnitrack_solver::covariance(&self.set, pose, &self.solver);
        result.xi_rad2 = omnitrack_core::geometry::xi(&self.set, pose);
        result.explained = explained as f32;
        result.pose = Some(*pose);
        result.states = self.state_counts();
        self.previous = Some((*pose, timestamp_ns));
        result
    }

    fn state_counts(&self) -> [u32; 3] {
        let mut n = [0u32; 3];
        for t in self.tracks.tracks() {
            n[t.state.code() as usize] += 1;
        }
        n
    }

    /// `set` ← the accepted tracks' held edges with their segments (used right after a commit,
    /// where the held edges are this frame's).
    fn collect_accepted_set(&mut self, _edges: &[Edge], _pose: &Pose, accepted_only: bool) {
        self.set.clear();
        self.set_track.clear();
        for (i, t) in self.tracks.tracks().iter().enumerate() {
            if accepted_only && t.state != CorrespondenceState::Accepted {
                continue;
            }
            if let Some(e) = &t.edge {
                let seg = &self.model.segments[t.segment as usize];
                self.set.push(Correspondence {
                    edge: e.plane,
                    segment: [seg.a, seg.b],
                });
                self.set_track.push(i);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{within, SearchVolume, NARROW_VIEW_SHARE, VOLUME_SLACK_M};
    use nalgebra::Point3;
    use omnitrack_core::geometry::Pose;
    use omnitrack_core::rig::{Rig, ViewMap};
    use std::path::Path;

    #[test]
    fn a_pose_is_within_a_volume_up_to_the_slack_and_always_within_the_whole_model() {
        let volume = SearchVolume {
            centre: Point3::new(1.0, 2.0, 1.5),
            diameter_m: Some(3.0),
        };
        let at = |x: f64| Pose::from_parts(nalgebra::Translation3::new(1.0 + x, 2.0, 1.5), Default::default());
        assert!(within(&volume, &at(1.5 + 0.5 * VOLUME_SLACK_M)));
        assert!(!within(&volume, &at(1.5 + 2.0 * VOLUME_SLACK_M)));
        let whole = SearchVolume {
            diameter_m: None,
            ..volume
        };
        assert!(within(&whole, &at(1e3)));
    }

    /// Only the one-pinhole example waits for searches to agree: the shipped rig and the other
    /// examples see enough of the sphere to tell twins apart on one frame.
    #[test]
    fn only_a_rig_seeing_less_than_half_the_sphere_is_narrow() {
        let share = |path: &str| {
            let rig = Rig::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../..").join(path)).expect("rig");
            ViewMap::new(&rig).share()
        };
        for wide in [
            "firmware_config/ladybug2.toml",
            "tools/rigs/pinhole4.toml",
            "tools/rigs/dual_fisheye.toml",
        ] {
            assert!(share(wide) >= NARROW_VIEW_SHARE, "{wide}: {}", share(wide));
        }
        assert!(share("tools/rigs/pinhole1.toml") < NARROW_VIEW_SHARE);
    }
}
