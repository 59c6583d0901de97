//! What the tracker says about a frame and a run: the state it is in, the search under way,
//! what happened ([`TrackerEvent`]), the frame's answer ([`FrameResult`]) and the run's totals
//! ([`TrackerStats`]).
//!
//! In: nothing (plain data). Out: the types the tracker hands its callers; the runtime maps the
//! states onto the pose message's codes.

use crate::init::InitReport;
use nalgebra::Matrix6;
use omnitrack_core::geometry::Pose;
use std::time::Duration;

pub use omnitrack_core::status::{SearchKind, TrackerState};

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
    /// Correspondences per state after the frame.
    pub states: StateCounts,
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
    pub fn empty(state: TrackerState) -> FrameResult {
        FrameResult {
            state,
            pose: None,
            covariance: Matrix6::from_diagonal_element(f64::INFINITY),
            inliers: 0,
            states: StateCounts::default(),
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
    /// Searches launched, of every kind (initialisation, re-initialisation, relocalisation).
    pub searches: u64,
    pub losses: u64,
    /// Frames rescued by a local search after the motion prior failed.
    pub relocalisations: u64,
    /// Of those, the relocalised poses the next frame's maintenance did not hold (module
    /// `relocalise`, "On probation"): withdrawn unpublished, and the lock counted lost.
    pub relocalisations_withdrawn: u64,
    /// Re-initialisations after a loss that the next frame's maintenance did not hold (module
    /// `tracker::search`, "On trial"): withdrawn unpublished, and the lock counted lost again.
    pub reinitialisations_withdrawn: u64,
    /// First commits whose trial frames did not hold them or failed the search's acceptance
    /// test at the pose held (module `tracker::search`, "Frames agreeing"): none of their frames
    /// was published, and the tracker initialised again.
    pub commits_withdrawn: u64,
    /// Maintenance fits outside the motion filter's gate refused as bad frames because the rig
    /// would have moved faster than `motion.max_speed_m_s` to reach them (module
    /// `tracker::maintenance`).
    pub too_fast: u64,
    /// Wall time of the first search and of all searches.
    pub first_search: Option<Duration>,
    pub search_time: Duration,
    /// Commits where the confirmation frames overruled the search frame's best candidate.
    pub changed_mind: u64,
    /// Frames whose solve, far from the prediction, a second opinion replaced (the polished
    /// prediction, or the solve's rotation polished at the predicted position).
    pub second_opinions: u64,
    /// Frames with fewer accepted inliers than `maintenance.min_inliers` whose pose the motion
    /// filter fused where their lines fix it (module `motion_filter`), instead of refusing.
    pub filtered_few_lines: u64,
    /// Maintenance frames whose predicted turn came from the image (module `frame_rotation`).
    pub frame_turns: u64,
    /// Searches the wall clock stopped before their work budget did ([`InitReport::backstop`]):
    /// their answers depend on the machine's load.
    pub search_backstops: u64,
    /// Searches a stop cut short ([`Tracker::stop_searches_on`](crate::Tracker::stop_searches_on)):
    /// discarded, their frames with no pose.
    pub searches_cancelled: u64,
    /// Adoption frames that had to wait for the search worker (module `background`), and how
    /// long in all: the machine was slower than the reference, or loaded.
    pub search_waits: u64,
    pub search_wait_time: Duration,
    /// Frames kept during a search and tracked afterwards (module `background`), and frames
    /// the backlog dropped (thinned during a long search, passed over by a fresh search when
    /// the backlog spans more than two budgets, or left at the end, [`Tracker::finish`](crate::Tracker::finish)).
    pub caught_up: u64,
    pub backlog_dropped: u64,
    /// Due frames on which the worker was not done: the search was taken up on a later frame.
    pub search_deferrals: u64,
    /// Poses of kept frames, handed out late through [`Tracker::late`](crate::Tracker::late) (not in `tracked`).
    pub late_poses: u64,
    /// Over all initialisation searches: the grid cells meeting their volumes, and those they
    /// looked at before the budget was spent ([`InitReport::plan_cells_scanned`]).
    pub plan_cells_in_volume: u64,
    pub plan_cells_scanned: u64,
}

/// The correspondence table's tracks per state (Figure 8) after a frame.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct StateCounts {
    pub unknown: u32,
    pub pending: u32,
    pub accepted: u32,
}

/// A candidate being weighed while initialising ([`Tracker::candidates`](crate::Tracker::candidates)(crate::Tracker::candidates)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Weighed {
    pub pose: Pose,
    /// Its mean [`Candidate::merit`](crate::Candidate::merit) over the frames scored (higher is
    /// better).
    pub merit: f64,
    pub frames: u32,
    /// Still in the running.
    pub alive: bool,
}
