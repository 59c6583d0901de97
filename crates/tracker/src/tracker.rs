//! The tracker's state machine (the crate's doc, "States") and its frame loop: a frame is
//! searched for (module `search`), maintained (module `maintenance`, Figure 7), or, while a
//! search runs off the frame path, kept and caught up on afterwards (module
//! [`background`](crate::background)).
//!
//! In: per frame, the frame's [`Edge`]s and its capture time. Out: a [`FrameResult`], and the
//! results of earlier kept frames through [`Tracker::late`].

mod catch_up;
mod hint_age;
mod maintenance;
mod relocalise;
mod search;

use crate::background::{Backlog, SearchJob, SearchLink};
use crate::correspondence::{CorrespondenceState, CorrespondenceTable, HeldEdge, Track};
use crate::frame_rotation::FrameRotation;
use crate::init::{Candidate, InitOptions, Initialiser, SearchVolume};
use crate::matching::{best_edge, EdgeNormals, Gate, Predicted};
use crate::motion_filter::{MotionFilter, MotionNoise};
use crate::report::{FrameResult, StateCounts, TrackerState, TrackerStats};
use crate::visibility::VisibilityTable;
use hint_age::HintAge;
use nalgebra::{Point3, UnitQuaternion};
use omnitrack_config::TrackerConfig;
use omnitrack_core::geometry::{Correspondence, Pose};
use omnitrack_core::memory::resident;
use omnitrack_core::model::Model;
use omnitrack_core::rig::Rig;
use omnitrack_edges::Edge;
use omnitrack_solver::{ConsensusSampler, SharedStart, SolverOptions};
use rand::rngs::SmallRng;
use rand::SeedableRng;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// A rig imaging less than this share of the sphere is narrow: a half-turn or a step along a
/// symmetric corridor shows it the same lines (see `Tracker::narrow`). Four pinholes 90° wide
/// round the horizon see 0.6 of it; one 50° pinhole a twentieth.
const NARROW_VIEW_SHARE: f64 = 0.5;

/// Frames kept while a search runs (module `background`): a 950 ms search at 30 Hz keeps all
/// of its 29; a longer one (the whole model) keeps every other, every fourth… A slot holds the
/// rig's most edges (the shipped rig: 1,536 of 248 bytes, 0.38 MB), so the backlog is about
/// 12 MB, made and written through at start-up (module `background`).
const BACKLOG_FRAMES: usize = 32;

/// Kept frames tracked per arriving frame once a search is taken up: one more than arrive, so the
/// backlog shrinks by two a frame, and each frame's time stays bounded by a few maintenance
/// steps (a few milliseconds each) rather than the search's hundreds.
pub const CATCH_UP_FRAMES: usize = 3;

/// A search under way off the frame path: when its result is due (the search frame's timestamp
/// plus its budget, ns) and what its acceptance needs from the search frame.
#[derive(Debug, Clone, Copy)]
struct PendingSearch {
    started_ns: u64,
    due_ns: u64,
    volume: SearchVolume,
    /// The volume is the hint grown by the walk the rig may have made since (module
    /// `hint_age`): its candidates are judged only when the search looked at all of it.
    grown: bool,
    turn_limit: Option<(UnitQuaternion<f64>, f64)>,
    floor: f64,
    /// Set for a relocalisation (module `maintenance`): what its frame concludes either way.
    relocalisation: Option<Relocalisation>,
}

/// A candidate under confirmation.
#[derive(Debug, Clone, Copy)]
struct Confirming {
    pose: Pose,
    merit_sum: f64,
    frames: u32,
    alive: bool,
    /// Accepted by the share explained over resolved lines (module `search`): the confirmation
    /// frames accept it so too.
    resolved: bool,
}

/// A relocalisation under way (module `background`): what its candidates are judged by, and
/// what its frame concludes when none wins.
#[derive(Debug, Clone, Copy)]
struct Relocalisation {
    predicted: Pose,
    /// Where maintenance last held the pose (the last good frame's position), if it did and
    /// the rig is wide (module `relocalise`).
    held: Option<nalgebra::Vector3<f64>>,
    /// The last good rotation and the turn the rig can have made since.
    turned_from: UnitQuaternion<f64>,
    turn_limit: f64,
    /// The least share of VIS(T) a candidate must explain (0 on a bad frame).
    floor: f64,
    diameter_m: f64,
    /// The tracker's `last_time` when the frame came (the previous frame's).
    last_time: u64,
    tail: Tail,
}

/// A maintenance frame's result so far and what it concludes without a relocalisation.
#[derive(Debug, Clone, Copy)]
struct Tail {
    result: FrameResult,
    pose: Option<Pose>,
    good: bool,
    predicted: Pose,
    timestamp_ns: u64,
}

/// Most relocalised frames held back at once (module `relocalise`, "On probation"); the chain's
/// limit is `maintenance.lost_after_frames`, at most this.
const PROBATION_LINKS: usize = 8;

/// Relocalised frames' answers, held until a frame's maintenance holds the pose (module
/// `relocalise`, "On probation").
#[derive(Debug, Clone, Default)]
struct Probation {
    /// The frames' stamps and answers, oldest first.
    links: heapless::Vec<(u64, FrameResult), PROBATION_LINKS>,
    /// The last pose maintenance held before the first of them, and its time: where the rig
    /// is searched for when they are withdrawn.
    held: Option<(Pose, u64)>,
    /// The link is a re-initialisation after a loss, on trial (module `search`, "On trial"):
    /// what its withdrawal restores.
    trial: Option<Trial>,
}

/// What a re-initialisation on trial replaced, restored when the next frame does not hold it
/// (module `search`, "On trial").
#[derive(Debug, Clone, Copy)]
struct Trial {
    /// The running mean of the share of VIS(T) explained before the commit lowered it.
    explained_ref: f64,
    /// The volume level of the search that committed it: the next search goes one beyond.
    volume_level: u32,
    /// Maintenance frames that must still hold the pose, each passing the search's acceptance
    /// test at it too (module `search`, "Frames agreeing").
    frames_left: u32,
    /// The tracker's first commit (from Initialising): withdrawn, it initialises again.
    first: bool,
    /// Accepted by the share explained over resolved lines: the trial frames accept it so too.
    resolved: bool,
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
    /// The consensus samples' fits' shared first step from the prediction (`SharedStart`).
    shared_start: SharedStart,
    /// S̄ for the solver and, per entry, its track.
    set: Vec<Correspondence>,
    set_track: Vec<usize>,
    /// Per track: the edge matched this frame and its α.
    matched: Vec<Option<(u32, f64)>>,
    /// Per track: its edge within the inlier angle at a maintenance attempt's pose
    /// (`consistent_count`), and at the pose solved so far, which the observations reuse.
    support_at: Vec<Option<(u32, f64)>>,
    support_solved: Vec<Option<(u32, f64)>>,
    /// The frame's edge normals packed for matching (`matching::EdgeNormals`).
    edge_normals: EdgeNormals,
    /// The turn between consecutive frames from their edges (`motion.frame_rotation`).
    frame_rotation: FrameRotation,
    /// The weights and residuals of the final robust fit (`solver::refine::cauchy`).
    robust_scratch: Vec<f64>,
    rng: SmallRng,
    state: TrackerState,
    hint: Option<SearchVolume>,
    /// How long the rig may have been moving since the hint's frame (module `hint_age`).
    hint_age: HintAge,
    /// Per edge of a search frame, whether the best candidate and a rival explain it (the
    /// disputed edges, module `search`).
    explained_by: [Vec<bool>; 2],
    pose: Pose,
    /// Previous tracked pose and its time, for the constant-velocity prior.
    previous: Option<(Pose, u64)>,
    /// The motion filter (`motion.filter`): the prediction maintenance starts from and the
    /// pose it publishes.
    filter: MotionFilter,
    last_time: u64,
    last_good: Option<Pose>,
    /// When `last_good` was seen (ns).
    last_good_time: u64,
    /// Relocalised frames' answers waiting for a frame to hold their pose.
    probation: Probation,
    /// Post-loss searches double their volume after each widened attempt fails.
    volume_level: u32,
    /// A sweep under way (module `search`): the searches so far looked at the volume's cells
    /// nearer its centre than this (m, in plan) and found nothing to commit; the next one goes
    /// on from here. 0: the next search starts at the centre.
    sweep_from_m: f64,
    /// The best candidates of the sweep's earlier searches: polished again on each later
    /// search's frame, they stay its rivals (a part of a volume must not commit what the rest
    /// of it would have refused) and may win there.
    carried: [Option<Pose>; crate::background::STARTS],
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
    /// The searcher's progress ([`Tracker::search_progress`]).
    progress: Arc<crate::init::SearchProgress>,
    /// The CPU time of the searches' helper threads ([`Tracker::search_helpers_cpu`]).
    search_helpers_cpu: Arc<std::sync::atomic::AtomicU64>,
    /// The owner's flags that stop a search too ([`Tracker::stop_searches_on`]).
    stops: Vec<Arc<AtomicBool>>,
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
        let mut init = Initialiser::new(rig, model, table, opts.clone(), solver.clone(), max_edges);
        // The frame path's initialiser polishes and scores; it never runs a search's lanes.
        init.set_threads(Some(1));
        let cancel = Arc::new(AtomicBool::new(false));
        let mut searcher = Initialiser::new(rig, model, table, opts, solver.clone(), max_edges);
        searcher.add_cancel(&cancel);
        let progress = Arc::clone(searcher.progress());
        let search_helpers_cpu = searcher.helpers_cpu();
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
            shared_start: SharedStart::new(capacity),
            set: resident(Vec::with_capacity(capacity)),
            set_track: resident(Vec::with_capacity(capacity)),
            matched: vec![None; capacity],
            support_at: resident(vec![None; capacity]),
            support_solved: resident(vec![None; capacity]),
            edge_normals: EdgeNormals::new(max_edges),
            frame_rotation: FrameRotation::new(max_edges),
            robust_scratch: resident(vec![0.0; 2 * capacity]),
            rng: SmallRng::seed_from_u64(seed),
            state: TrackerState::Initialising,
            hint,
            hint_age: HintAge::new(cfg.noise.edge_normal_sigma_deg.to_radians(), max_edges),
            explained_by: [
                resident(Vec::with_capacity(max_edges)),
                resident(Vec::with_capacity(max_edges)),
            ],
            pose: Pose::identity(),
            previous: None,
            filter: MotionFilter::new(MotionNoise {
                accel_m_s2: cfg.motion.accel_noise_m_s2,
                angular_accel_rad_s2: cfg.motion.angular_accel_noise_deg_s2.to_radians(),
                start_speed_m_s: cfg.motion.max_speed_m_s,
                start_turn_rad_s: cfg.motion.max_turn_rate_deg_s.to_radians(),
            }),
            last_time: 0,
            last_good: None,
            last_good_time: 0,
            probation: Probation::default(),
            volume_level: 0,
            sweep_from_m: 0.0,
            carried: [None; crate::background::STARTS],
            confirming: [Confirming {
                pose: Pose::identity(),
                merit_sum: 0.0,
                frames: 0,
                alive: false,
                resolved: false,
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
            scratch: resident(Vec::with_capacity(max_edges)),
            late: Vec::with_capacity(BACKLOG_FRAMES + 1 + PROBATION_LINKS),
            defer: false,
            cancel,
            progress,
            search_helpers_cpu,
            stops: Vec::new(),
        }
    }

    /// How far the search under way has got (initialisation, relocalisation and
    /// re-initialisation alike, on the worker or inline): shared, so a thread other than the
    /// frame path's can watch a search of seconds and say so (`omnitrack run`'s progress lines).
    pub fn search_progress(&self) -> &Arc<crate::init::SearchProgress> {
        &self.progress
    }

    /// CPU time the searches' helper threads have spent since start-up (a search's lanes run on
    /// the thread that runs the search and on these; module `init`).
    pub fn search_helpers_cpu(&self) -> std::time::Duration {
        std::time::Duration::from_nanos(self.search_helpers_cpu.load(std::sync::atomic::Ordering::Relaxed))
    }

    /// Runs the searches on a worker from now on (module `background`): `link` sends jobs to a
    /// thread running [`SearchWorker::run`](crate::background::SearchWorker::run) and takes them back. Without one, a search runs on the
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

    /// A search under way stops at its next check (a few milliseconds) once `flag` is set: a
    /// pipeline's stop, so that a shutdown does not wait for the whole model's search. A search
    /// so cut short is discarded, its frame answered with no pose and counted in
    /// [`TrackerStats::searches_cancelled`]: its best candidate may not have met the rivals that
    /// would have refused it, and a wrong pose is worse than none.
    pub fn stop_searches_on(&mut self, flag: Arc<AtomicBool>) {
        if !self.stops.iter().any(|s| Arc::ptr_eq(s, &flag)) {
            self.stops.push(flag);
        }
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
        if self.state == TrackerState::Initialising && self.hint.is_some_and(|h| h.diameter_m.is_some()) {
            self.hint_age.observe(edges, timestamp_ns);
        }
        let result = match self.state {
            TrackerState::Tracking => self.maintain(edges, timestamp_ns),
            TrackerState::Initialising | TrackerState::Lost => self.initialise(edges, timestamp_ns),
        };
        self.last_time = timestamp_ns;
        result
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
        self.sweep_from_m = 0.0;
        self.carried = [None; crate::background::STARTS];
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
        result.covariance = self.measured_covariance(pose);
        result.xi_rad2 = omnitrack_core::geometry::xi(&self.set, pose);
        result.explained = explained as f32;
        result.pose = Some(*pose);
        result.states = self.state_counts();
        self.previous = Some((*pose, timestamp_ns));
        self.filter.start(pose, &result.covariance, timestamp_ns);
        result
    }

    /// Kumar–Hanson §5's covariance of `pose` fitted to `set`, at the noise the lines show
    /// where that exceeds the configured σ (a model drawn a few centimetres off, blur): the
    /// filter weighs a frame by it, and a covariance at the configured σ alone would make a
    /// frame of a few poorly placed lines as certain as the motion so far.
    pub(super) fn measured_covariance(&self, pose: &Pose) -> nalgebra::Matrix6<f64> {
        covariance_at_seen_noise(&self.set, pose, &self.solver)
    }

    fn state_counts(&self) -> StateCounts {
        let mut n = StateCounts::default();
        for t in self.tracks.tracks() {
            match t.state {
                CorrespondenceState::Unknown => n.unknown += 1,
                CorrespondenceState::Pending => n.pending += 1,
                CorrespondenceState::Accepted => n.accepted += 1,
            }
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

/// Kumar–Hanson §5's covariance of `pose` fitted to `set`, at the noise the lines show where
/// that exceeds the configured σ (see [`Tracker::measured_covariance`]).
fn covariance_at_seen_noise(set: &[Correspondence], pose: &Pose, solver: &SolverOptions) -> nalgebra::Matrix6<f64> {
    let cov = omnitrack_solver::covariance(set, pose, solver);
    let sigma2 = solver.edge_sigma_rad * solver.edge_sigma_rad;
    let seen = omnitrack_core::geometry::xi(set, pose);
    if sigma2 > 0.0 && seen > sigma2 {
        cov * (seen / sigma2)
    } else {
        cov
    }
}

#[cfg(test)]
mod tests {
    use super::NARROW_VIEW_SHARE;
    use omnitrack_core::rig::{Rig, ViewMap};
    use std::path::Path;

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
            "tools/rigs/dual_double_sphere.toml",
        ] {
            assert!(share(wide) >= NARROW_VIEW_SHARE, "{wide}: {}", share(wide));
        }
        assert!(share("tools/rigs/pinhole1.toml") < NARROW_VIEW_SHARE);
    }
}
