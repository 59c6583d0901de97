//! Initialisation: Koch–Teller §4.1, INIT-SEGMENT-EDGE (Figure 4) inside a search volume
//! (centre T̃, diameter δ) over the cells of the prior visibility grid (§4.1.1), followed by the
//! simplex minimisation of ξ (§4.1.3, Figure 5).
//!
//! In: one frame's [`Edge`]s, a [`SearchVolume`], the model, the visibility table. Out: the best
//! few distinct [`Candidate`] poses (lowest score first) with their inlier correspondences'
//! count and ξ, and an [`InitReport`] of the work done.
//!
//! Per cell meeting the volume (nearest first), as in Figure 4:
//! 1. ℒ: the segments of the cell's visibility set, the `segments_considered` longest as seen
//!    from the node; ℰ: the frame's `edges_considered` strongest edges (once per frame).
//! 2. Dihedral angles: of every edge pair (the angle between their planes, independent of the
//!    rig's rotation), and of every segment pair as a range [min, max] over the cell, from the
//!    planes through the segments at the cell's centre and corners.
//! 3. Triplets: an edge triplet {e_r, e_s, e_t} matches a segment triplet {l_i, l_j, l_k} when
//!    all three dihedral angles fall in the ranges (within the edge noise). The score α of a
//!    match is the normalised product of overlaps: per pair, the overlap of the observation's
//!    interval (±`dihedral_tolerance`) with the expected range divided by their union, so a
//!    narrow, informative range counts more than one that a near segment sweeps over the cell.
//!    `A[r][i]`, `A[s][j]`, `A[t][k]` += α (Figure 4 line 7).
//! 4. The k best edges of each segment (k = 3) by A; random samples of three segments, each with
//!    one of its k best edges; the pose of each sample; the sample's pose scored.
//!
//! **Indexing instead of brute force.** Figure 4 loops over all O(m³n³) triplet pairs (the paper:
//! a minute per initialisation). Here the ordered edge pairs are sorted by dihedral angle, so the
//! pairs compatible with a segment pair are one contiguous slice found by binary search; the third
//! edge is then found in O(1) as the intersection of two 64-bit masks ("edges whose dihedral
//! angle with e_r lies in a range", from per-edge cumulative masks over 0.5° bins). Segment pairs
//! whose range over the cell is wider than `max_range_deg` say little and are pruned. The work
//! per cell is then ~n³/6 × (compatible pairs), a few milliseconds.
//!
//! **Pose of a sample.** Three correspondences fix the pose: the rotation from the three plane
//! normals (edge, rig frame ↔ segment seen from the cell centre, world frame; signs made
//! consistent by the dihedral cosines) by Wahba's SVD, the translation from eq. 9 by linear least
//! squares, then Kumar–Hanson's R_and_T on the three (KT minimise ξ here; R_and_T reaches the same
//! minimum of a 3-line sample ~50× faster). The ξ simplex comes once, on the winner's inliers.
//!
//! **Scoring (deviation).** ξ over a three-line sample is ~0 for many wrong samples, so samples
//! are compared by the truncated ξ over all of the cell's segments (each segment's best edge α,
//! capped), the consensus score of the maintenance sampler. The best samples are then polished:
//! matches gathered at the pose with shrinking gates (model segments in sight, all edges), refit,
//! and ranked by the truncated ξ with the inlier cap.
//!
//! **Translation by voting** (module `vote`; beyond the paper). The triplet sampling finds
//! rotations far more reliably than translations: in a corridor of evenly spaced doors its best
//! poses are the right heading (or the symmetric corridor's 180° twin) a door away. So under the
//! rotations of the two best candidates, and their quarter turns about the vertical where any
//! heading is plausible, the plan positions most vertical edge planes agree on are voted, the
//! height swept at each (`HEIGHT_STEP_M`), and the result polished and ranked with the rest.
//! Measured on 40 starts along the full-length `corridor`: right 33–34 times against 26.
//!
//! **Rotation from vanishing directions, translation by a grid** (modules `vanishing`; beyond
//! the paper). On real photographs the strongest edges are mostly texture (blinds,
//! floorboards, sun patches), and the triplets of the 40 strongest held the truth for 1 of the
//! 32 real panoramas of the ZInD benchmark (docs/decisions.md). But buildings are drawn in few directions,
//! and their lines (texture included) meet in few vanishing points: the frame's vertical and
//! horizontal vanishing directions put onto the model's give a few rotations (a Manhattan
//! building: four, a quarter turn apart), within a degree of the truth on all 32. Under each,
//! the translation is three numbers: positions on a grid over the volume (plan and height steps
//! of 0.25 m, heights in the band above the floor beneath) are scored by *coverage*, the share
//! of the long segments in sight from them along which the frame's longest edges run (in a
//! bounded volume, times the share of their points not blank, as in the final merit:
//! `grid_blank`, module `near_edges`), climbed in finer steps and polished. The grid covers every cell of the
//! visibility table's grid that meets the volume, whether or not its node is valid: a closet or
//! a hallway narrower than the node spacing often has its node inside a wall. This runs first; the triplets get what is
//! left of the time budget.
//!
//! **The budget is work, not time** (issue 24): every step charges the work it does in *work
//! units*, about a microsecond of one core of the reference machine (module [`work`], measured
//! per step on the ZInD panoramas and `lab`, and for the rays on FZK-Haus too). Costs that
//! grow with the model's detail are charged by count, not by a typical figure: the occlusion
//! rays cast by `visibility::at_pose` and the (segment, edge) pairs the grid's scores
//! look at. With flat charges an architect's model spent four times its budget on the wall
//! clock before its first cell was searched (issue 47). The lattice, the climbs (best first), the
//! triplets, the polish of their samples and the vote stop when the search has spent its budget
//! (`time_budget_ms` is that budget in reference milliseconds). So a search does the same work
//! and gives the same answer on an idle or a loaded machine; with a clock deadline, three runs
//! of one recording under CPU hogs differed by up to 8.4 cm and the whole-model search settled
//! 10.9 m off. The lattice's scan stops at [`GRID_SHARE`] of the budget so that its best
//! positions are always climbed and polished (the whole model's scan used to take all of it and
//! return nothing). The triplets stop early by twice what polishing their best samples costs.
//! The clock is only a backstop: a search still running at [`BACKSTOP_FACTOR`] times its budget
//! (a machine far slower than the reference, or starved) stops, and [`InitReport::backstop`]
//! says so.
//!
//! **Visibility at the pose** (`crate::visibility::at_pose`; beyond the paper). The grid, the
//! polish and the scores predict the segments in sight from the candidate position itself (ray
//! cast against the model), not the set of the node serving it, which is seen from up to 0.7 m
//! away and, in a small room, from the other side of a wall. Measured on the ZInD benchmark from
//! the 1.5 m hint: the search's first candidate was the truth for 24 of 32 panoramas, against
//! 19 with the nodes' sets.
//!
//! **Scoring both ways.** A segment counts as explained in proportion to how much of it edges
//! cover (half covered counts whole): a short piece of texture that happens to lie along a
//! predicted line no longer explains it. And [`Candidate::support`] is the share of the frame's
//! edges (all of them, by angle) that the candidate's segments explain: texture is unexplained
//! at every pose, but a wrong pose also leaves the building's own lines unexplained.
//!
//! **Lines across plain surfaces** ([`Candidate::blank`]; beyond the paper). A segment the
//! edges do not explain may be hidden (furniture, a closed door, a faint corner) or simply not
//! there; the two differ in the image: hidden lines lie among other edges, a line that is not
//! there is often drawn across a plain wall or ceiling with no edge of any direction near it.
//! The share of such *blank* sample points (`blank_radius_deg`) is what a wrong pose shows
//! most plainly in a furnished room. Candidates rank by [`Candidate::merit`], explained ×
//! support × (1 − blank). Measured on the ZInD panoramas from the 1.5 m hint (docs/decisions.md): the
//! truth's margin over the best pose 0.6 m or 10° away became clear (ratio ≤ 0.8) on 28 of
//! 32 against 27 with support over all edges alone and 22 before.
//!
//! **The floor beneath** (module `floor`): every candidate must stand `height_above_floor_m`
//! above a floor of the model (none outside the building, inside a wall or above a ceiling);
//! a model without floors gives no such prior. On the ZInD panoramas the rivals that kept the
//! truth from being a clear winner in a kitchen and a closet doorway stood inside walls, 2–5 cm
//! from a face, where they saw a door's jamb and little else.
//!
//! With `upright` set (KT §5.4), the cells are those of the layer nearest the known height, the
//! rotation is the yaw alone (closed form) and every fit solves x, y and yaw only.
//!
//! **A cost that follows what the sensors can see** (issue 47). On a detailed model (FZK-Haus,
//! 9,266 segments: window sashes, stair nosings) the grid used to spend its budget casting rays
//! to every segment a position's nodes see before it had scored one cell. Now:
//! - a grid position asks for the 48 (`GRID_SEGMENTS`) segments spanning the widest angle in sight
//!   (`PoseVisibility::widest`): candidates are taken widest first by the angle the whole
//!   segment spans, and rays are cast only until no candidate left could enter, which gives
//!   the same segments as ray casting them all (tested) for a sixteenth of the rays there;
//! - the grid's scores match each predicted segment only against the edges whose planes can
//!   pass its gate (module `edge_index`; checked against all pairs in debug builds);
//! - [`InitReport::plan_cells_scanned`] says how many of the volume's cells the scan looked
//!   at before its share of the budget was spent, and [`InitReport::swept_to_m`] how far out;
//!   [`Initialiser::set_sweep_from`] lets a later search continue from there, so that searches
//!   over several frames cover a volume one budget does not. The tracker sweeps only with
//!   `initialisation.sweep_volume`, off by default: deciding only once a sweep had covered the
//!   volume added a wrong commit on the ZInD tour (docs/decisions.md).
//!
//! **Lanes on every core.** A search deals the cells of its volume to lanes: the whole model
//! (start-up without a hint, over a thousand cells in `lab`) to [`LANES`], a bounded volume (a
//! hint, a re-initialisation, a relocalisation) to [`VOLUME_LANES`], each lane with its own
//! per-cell buffers, its share of the work budget and, in several lanes, a generator seeded per
//! cell. The search's thread and helper threads started with the initialiser (module `lanes`)
//! run the lanes. The grid's scan, three quarters of a search, is dealt out the same way
//! (module `grid_scan`): its plan cells, nearest first, in turn to the lanes, each with its own
//! buffers, keep-best lists and an equal share of the scan's budget, the lists merged in lane
//! order. What each lane searches is fixed by the dealing alone, so the answer does not depend
//! on the number of cores ([`Initialiser::set_threads`]) or on how the threads were scheduled.
//! Lanes side by side are charged the reference machine's time for them ([`REFERENCE_CORES`]):
//! the budget is that machine's wall time, whatever the lanes.
//!
//! Fixed memory: all tables are sized and the helper threads started in [`Initialiser::new`]; a
//! search allocates nothing.

use super::edge_index::EdgeIndex;
use super::floor::Floors;
use super::matching::Predicted;
use super::vanishing::{VanishingDirections, MAX_ROTATIONS};
use super::vote::{TranslationVote, PEAKS};
use crate::visibility::at_pose::{PoseVisibility, SeenSegment};
use crate::visibility::VisibilityTable;
use grid_scan::{GridLane, MeritScratch};
use lanes::LanePool;
use nalgebra::{Point3, UnitQuaternion, Vector3};
use near_edges::NearEdges;
use omnitrack_core::geometry::{Correspondence, Pose};
use omnitrack_core::memory::resident;
use omnitrack_core::model::Model;
use omnitrack_core::rig::{Rig, ViewMap};
use omnitrack_edges::Edge;
use omnitrack_solver::SolverOptions;
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

mod grid_scan;
mod lanes;
mod near_edges;
mod progress;
mod run;
mod scoring;
mod translation;
mod triplets;
mod types;
pub mod work;

pub use progress::{SearchProgress, SearchSnapshot};
pub use types::{Candidate, InitOptions, InitReport, SearchVolume};

/// Dihedral-angle bins of the edge masks (rad).
const BIN_RAD: f64 = 0.5 * std::f64::consts::PI / 180.0;
/// Bins covering [0, π/2].
const BINS: usize = 181;
/// Most edges per frame the triplet matching considers (one bit each in a u64 mask).
pub const MAX_EDGES_CONSIDERED: usize = 64;
/// Samples kept per cell for polishing, and candidates polished per run.
const KEEP_PER_CELL: usize = 3;
const POOL: usize = 64;
pub(crate) const POLISHED: usize = 16;

/// Most candidates a search returns: the polished, the vote's peaks and the grid's kept.
pub(crate) const MAX_CANDIDATES: usize = POLISHED + VOTED_ROTATIONS * PEAKS + MAX_ROTATIONS * GRID_KEEP;
/// Two candidates closer than this are the same (m, rad).
const SAME_POSITION_M: f64 = 0.3;
const SAME_ROTATION_RAD: f64 = 0.0873;
/// The translation vote runs under the rotations of this many of the best candidates (with
/// their quarter turns: at most this many rotations in all).
const VOTED_CANDIDATES: usize = 2;
const VOTED_ROTATIONS: usize = 8 + MAX_ROTATIONS;
/// The longest edges of the frame that vote for translations (module `vote`): many more than
/// the triplet matching's strongest few, since under a known rotation only the edges whose
/// planes are vertical vote, and clutter outshines structure on real photographs.
const VOTE_EDGES: usize = 256;
/// A segment covered this much by its matching edges counts as wholly explained: furniture
/// hides parts of the walls' lines, and the model is coarse (KT §5.3's "10–25 cm").
const FULL_COVER: f64 = 0.5;
/// How far a pose may stray outside the height band above its floor (m): the polish moves a
/// start by centimetres.
const HEIGHT_SLACK_M: f64 = 0.1;
/// The grid search under the vanishing directions' rotations: its spacing in plan and height
/// (m, about the polish's basin at a few metres), the positions polished per rotation, and the
/// coarse gate of its scoring (rad).
const GRID_STEP_M: f64 = 0.25;
const GRID_KEEP: usize = 8;
/// The longest segments in sight from a grid position (module `visibility::at_pose`) that the
/// grid scores it by.
const GRID_SEGMENTS: usize = 48;
/// Grid positions scoring below this share of the best are not polished.
const GRID_WORTH: f64 = 0.5;
const GRID_GATE_RAD: f64 = 6.0 * std::f64::consts::PI / 180.0;
/// The grid's best positions climb the coverage score in steps of these sizes (m) and gates
/// (rad) before the polish: the true position's peak is narrower than the grid.
const CLIMB: [(f64, f64); 3] = [
    (0.12, 4.0 * std::f64::consts::PI / 180.0),
    (0.06, 3.0 * std::f64::consts::PI / 180.0),
    (0.03, 2.0 * std::f64::consts::PI / 180.0),
];
/// Step of the height sweep at a voted plan position (m).
const HEIGHT_STEP_M: f64 = 0.1;

/// The share of the budget the lattice's scan may spend: the rest is for climbing and polishing
/// its best positions, the triplets and the vote.
pub const GRID_SHARE: f64 = 0.75;
/// A search still running at this many times its budget on the wall clock stops (reported).
/// An unoptimised build (the tests') does the same work several times slower by construction,
/// and its tests run side by side: at 4× there, a loaded machine stopped a relocalisation short
/// and the tracker test that expects it to commit failed (2026-11-29). The backstop is for a
/// machine far slower than the reference, not for the build.
pub const BACKSTOP_FACTOR: u32 = if cfg!(debug_assertions) { 40 } else { 4 };

/// Lanes of the whole-model search (and most threads it uses).
pub const LANES: usize = 4;

/// Lanes of a bounded volume's search (a hint, a re-initialisation, a relocalisation): two, the
/// reference machine's cores, so that the search's thread and one helper look at every cell of
/// a 3 m volume of FZK-Haus within the budget (one lane looked at 44 % of them). Held back
/// until a re-initialisation after a loss went on trial (module `tracker::search`): looking at
/// every cell of a volume the walking rig had left, two lanes committed its look-alike 1.04 m
/// off (docs/decisions.md, 2026-12-01).
pub const VOLUME_LANES: usize = 2;

/// Cores of the reference machine the work units are measured on (module [`work`]). Lanes run
/// side by side on that many, so a stretch of lanes is charged its lanes' work over
/// `min(lanes, REFERENCE_CORES)`: its time there. The budgets are that machine's time, so a
/// search's result is due when the reference machine would have it; a machine with fewer cores
/// finishes later, and the tracker waits for it (lossless) or takes it up when done (live).
pub const REFERENCE_CORES: usize = 2;

/// One thread per core, at most [`LANES`]. (Asked once: the standard library reads the
/// process's CPU quota from files to answer, which allocates.)
fn default_threads() -> usize {
    std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .clamp(1, LANES)
}

/// What `work` done in `lanes` lanes side by side costs in the reference machine's time.
fn charge_of_lanes(work: u64, lanes: usize) -> u64 {
    work / lanes.clamp(1, REFERENCE_CORES) as u64
}

/// Each of `lanes` lanes' share of `left` work units of the reference machine's time.
fn lane_share(left: u64, lanes: usize) -> u64 {
    left.saturating_mul(lanes.clamp(1, REFERENCE_CORES) as u64) / lanes.max(1) as u64
}

/// One worker's per-cell buffers (Figure 4's ℒ, dihedral ranges, score table A, the k best
/// edges and the sampling weights) and the best samples it found.
struct CellScratch {
    seg_order: Vec<(f64, u32)>,
    segs: Vec<u32>,
    seg_normals: Vec<Vector3<f64>>,
    ranges: Vec<(f32, f32)>,
    score: Vec<f32>,
    best: Vec<[(f32, u8); 3]>,
    weights: Vec<f64>,
    corr: Vec<Correspondence>,
    pool: Pool,
    /// What the lane did in the last search (its part of the report).
    done: InitReport,
}

impl CellScratch {
    /// For m edges, n segments and visibility sets of at most `max_set` segments.
    fn new(m: usize, n: usize, max_set: usize) -> CellScratch {
        CellScratch {
            seg_order: resident(Vec::with_capacity(max_set)),
            segs: resident(Vec::with_capacity(n)),
            seg_normals: resident(vec![Vector3::zeros(); n * 9]),
            ranges: resident(vec![(0.0, 0.0); n * n]),
            score: resident(vec![0.0; n * m]),
            best: resident(vec![[(0.0, 0); 3]; n]),
            weights: resident(vec![0.0; n]),
            corr: Vec::with_capacity(3),
            pool: Pool::new(),
            done: InitReport::default(),
        }
    }
}

/// The best [`POOL`] candidate poses with their scores.
type Pool = heapless::Vec<(f64, Pose), POOL>;

/// Keeps `entry` in `pool` if there is room or it beats the worst (lowest score is best).
fn keep_best(pool: &mut Pool, entry: (f64, Pose)) {
    if let Err(entry) = pool.push(entry) {
        if let Some(w) = pool.iter_mut().max_by(|a, b| a.0.total_cmp(&b.0)) {
            if entry.0 < w.0 {
                *w = entry;
            }
        }
    }
}

/// One rotation's best [`GRID_KEEP`] grid positions with their scores.
type GridBest = heapless::Vec<(f64, Point3<f64>), GRID_KEEP>;

/// The search's buffers, sized once.
pub struct Initialiser<'m> {
    model: &'m Model,
    table: &'m VisibilityTable,
    centres: Vec<Point3<f64>>,
    opts: InitOptions,
    solver: SolverOptions,
    // Per frame.
    edge_order: Vec<(f32, u32)>,
    top: Vec<Edge>,
    dihedral: Vec<f32>,
    le_mask: Vec<u64>,
    pairs: Vec<(f32, u8, u8)>,
    // Per cell: the cells to search, and one scratch per worker.
    cells: Vec<(f64, u32)>,
    /// The grid search's plan cells: (distance from the volume's centre, cell centre).
    plan_cells: Vec<(f64, Point3<f64>)>,
    scratch: Vec<CellScratch>,
    // Results.
    pool: Pool,
    corr: Vec<Correspondence>,
    alphas: Vec<f64>,
    candidates: Vec<Candidate>,
    /// Translation by voting under the candidates' rotations (module `vote`), and whether
    /// their quarter-turn twins about the vertical are voted too.
    vote: TranslationVote,
    /// The frame's longest edges, for the vote.
    vote_edges: heapless::Vec<Edge, VOTE_EDGES>,
    /// `vote_edges` by the direction of their planes (module `edge_index`): the grid's scores
    /// match each segment against the edges that can pass its gate, not against all.
    vote_index: EdgeIndex,
    /// The scratch of [`Self::coarse_merit`] on the calling thread (the climbs).
    merit: MeritScratch,
    /// The grid scan's lanes (module `grid_scan`): [`VOLUME_LANES`] for a bounded volume,
    /// [`LANES`] for the whole model.
    grid_lanes: Vec<GridLane>,
    /// Whether this search's grid ranks by the blank share too (`opts.grid_blank` for its volume).
    grid_blank: bool,
    /// The threads that run the lanes beside the calling one (module `lanes`; one per core
    /// unless [`Initialiser::set_threads`] says otherwise), and the CPU time they have spent on
    /// them.
    helpers: LanePool,
    helpers_cpu_ns: Arc<AtomicU64>,
    /// Rotation hypotheses from vanishing directions (module `vanishing`).
    vanishing: VanishingDirections,
    /// The floors: the rig stands in a band above the one beneath it.
    floors: Floors,
    /// The grid search's best positions under each rotation (score, position).
    grid_best: [GridBest; MAX_ROTATIONS],
    /// VIS(T) refined at the candidate's own position: what polishing and scoring predict.
    at_pose: PoseVisibility,
    /// The directions the rig's sensors image.
    view: ViewMap,
    /// Scratch of [`Self::edge_support`]: the predicted segments.
    support_pred: Vec<Predicted>,
    /// Scratch of [`Self::explained_resolved`].
    resolved: Vec<scoring::ResolvedLine>,
    /// Work spent in this run (module [`work`]), and when the wall clock's backstop falls.
    work: u64,
    /// Rays of `at_pose` already charged.
    rays_charged: u64,
    backstop: Instant,
    backstop_hit: bool,
    /// The backstop falls at this many times the budget ([`BACKSTOP_FACTOR`] by default).
    backstop_factor: u32,
    /// How far the run under way has got, for whoever watches ([`Self::progress`]).
    progress: Arc<SearchProgress>,
    /// Set by the owner to stop a search early (module `background`: a tracker shutting down,
    /// or its pipeline stopping, does not wait for a search nobody will read).
    cancel: Vec<Arc<AtomicBool>>,
    /// The segments in sight from a grid position: (angle they span in sight, the segment with
    /// its points in sight), and the longest kept.
    grid_order: Vec<(f64, SeenSegment)>,
    grid_segs: Vec<SeenSegment>,
    /// The directions near this frame's edges, per sensor: the coarse merit's blank test.
    near: NearEdges,
    /// This frame's rotations from vanishing directions.
    vanishing_rot: [UnitQuaternion<f64>; MAX_ROTATIONS],
    vanishing_count: usize,
    /// The grid's best positions climbed and polished in this search.
    climbed: usize,
    yaw_twins: bool,
    /// A rotation the rig cannot have turned further from than the angle (rad): samples beyond
    /// it are dropped before they take a place in the pool.
    rotation_prior: Option<(UnitQuaternion<f64>, f64)>,
    /// Cells nearer the volume's centre than this (m, in plan) are skipped: earlier searches
    /// of the sweep looked at them.
    sweep_from_m: f64,
}

impl<'m> Initialiser<'m> {
    /// Buffers for `rig` (its sensors' centres), `model` and `table`; `max_edges` is the most
    /// edges a frame can have (sensors × edges per sensor).
    pub fn new(
        rig: &Rig,
        model: &'m Model,
        table: &'m VisibilityTable,
        mut opts: InitOptions,
        solver: SolverOptions,
        max_edges: usize,
    ) -> Initialiser<'m> {
        opts.edges_considered = opts.edges_considered.clamp(3, MAX_EDGES_CONSIDERED);
        opts.segments_considered = opts.segments_considered.max(3);
        opts.wide_segments_considered = opts.wide_segments_considered.max(opts.segments_considered);
        opts.best_edges_per_segment = opts.best_edges_per_segment.clamp(1, 3);
        opts.candidates = opts.candidates.max(1);
        // Buffers for the widest search `set_breadth` may ask for.
        let (m, n) = (MAX_EDGES_CONSIDERED, opts.wide_segments_considered);
        let max_set = (0..table.node_count() as u32)
            .map(|i| table.node_set(i).segments.len())
            .max()
            .unwrap_or(0)
            .max(model.segments.len());
        let floors = Floors::new(model);
        let helpers_cpu_ns = Arc::new(AtomicU64::new(0));
        Initialiser {
            model,
            table,
            centres: rig.sensors.iter().map(|s| s.centre()).collect(),
            opts,
            solver,
            // Every buffer resident from the start (`omnitrack_core::memory`): a search that
            // reaches further into one than the searches before would otherwise take memory.
            edge_order: resident(Vec::with_capacity(max_edges)),
            top: resident(Vec::with_capacity(m)),
            dihedral: resident(vec![0.0; m * m]),
            le_mask: resident(vec![0; m * BINS]),
            pairs: resident(Vec::with_capacity(m * m)),
            cells: resident(Vec::with_capacity(table.node_count())),
            plan_cells: resident(Vec::with_capacity(
                (table.header.dims[0] as usize) * (table.header.dims[1] as usize),
            )),
            scratch: (0..LANES).map(|_| CellScratch::new(m, n, max_set)).collect(),
            pool: Pool::new(),
            corr: resident(Vec::with_capacity(max_set)),
            alphas: resident(Vec::with_capacity(max_set)),
            candidates: resident(Vec::with_capacity(MAX_CANDIDATES)),
            vote: TranslationVote::new(model.segments.len()),
            vote_edges: heapless::Vec::new(),
            vote_index: EdgeIndex::new(VOTE_EDGES, rig.sensors.len().min(crate::matching::MAX_SENSORS)),
            merit: MeritScratch::new(max_set),
            grid_lanes: (0..LANES).map(|_| GridLane::new(model)).collect(),
            grid_blank: false,
            helpers: LanePool::new(default_threads(), &helpers_cpu_ns),
            helpers_cpu_ns,
            vanishing: VanishingDirections::new(model, max_edges),
            floors,
            grid_best: std::array::from_fn(|_| GridBest::new()),
            at_pose: PoseVisibility::new(model),
            view: ViewMap::new(rig),
            support_pred: resident(Vec::with_capacity(max_set)),
            resolved: resident(Vec::with_capacity(max_set)),
            work: 0,
            rays_charged: 0,
            backstop: Instant::now(),
            backstop_hit: false,
            backstop_factor: BACKSTOP_FACTOR,
            progress: Arc::new(SearchProgress::default()),
            cancel: Vec::new(),
            grid_order: resident(Vec::with_capacity(max_set)),
            grid_segs: resident(Vec::with_capacity(max_set)),
            near: NearEdges::new(rig.sensors.len()),
            vanishing_rot: [UnitQuaternion::identity(); MAX_ROTATIONS],
            vanishing_count: 0,
            climbed: 0,
            yaw_twins: true,
            rotation_prior: None,
            sweep_from_m: 0.0,
        }
    }

    /// Share of the sphere of directions the rig's sensors image ([`ViewMap::share`]).
    pub fn view_share(&self) -> f64 {
        self.view.share()
    }

    pub fn options(&self) -> &InitOptions {
        &self.opts
    }

    /// Changes how broad the search is: m edges (≤ 64), n segments (≤ the wide size given at
    /// construction) and samples per cell.
    pub fn set_breadth(&mut self, edges: usize, segments: usize, samples_per_cell: usize) {
        self.opts.edges_considered = edges.clamp(3, MAX_EDGES_CONSIDERED);
        self.opts.segments_considered = segments.clamp(3, self.opts.wide_segments_considered);
        self.opts.samples_per_cell = samples_per_cell.max(1);
    }

    /// Whether the translation vote also tries each candidate rotation turned by quarter turns
    /// about the vertical (on by default; off where the rotation is known to be near, as in a
    /// relocalisation).
    pub fn set_yaw_twins(&mut self, on: bool) {
        self.yaw_twins = on;
    }

    /// Where the rig's rotation is known to within an angle (after a loss or a bad frame: the
    /// last good rotation and the turn the rig's turn rate allows since), samples turned further
    /// are dropped: they could not be accepted, and in a symmetric building their twins (the same
    /// place seen turned half round, or upside down) would otherwise fill the pool and crowd out
    /// the plausible samples. `None`: any rotation.
    pub fn set_rotation_prior(&mut self, prior: Option<(UnitQuaternion<f64>, f64)>) {
        self.rotation_prior = prior;
    }

    /// Continues a sweep of the volume: the next searches skip the cells nearer its centre
    /// than `m` (in plan), which an earlier search of the same volume looked at (its
    /// [`InitReport::swept_to_m`]), and look further out (0: the whole volume, nearest first).
    /// A volume too large for one search's budget is then covered over a few searches rather
    /// than its nearest cells searched again and again.
    pub fn set_sweep_from(&mut self, m: f64) {
        self.sweep_from_m = if m.is_finite() { m.max(0.0) } else { 0.0 };
    }

    /// The rotation hypotheses the vanishing directions of `edges` give (module `vanishing`), for
    /// diagnosis; the search computes its own.
    pub fn vanishing_rotations(&mut self, edges: &[Edge]) -> Vec<UnitQuaternion<f64>> {
        let mut out = [UnitQuaternion::identity(); MAX_ROTATIONS];
        let n = self.vanishing.rotations(edges, self.opts.max_tilt_rad, &mut out);
        out[..n].to_vec()
    }

    /// Changes the search's budget (a volume, or the whole model), in reference time.
    pub fn set_time_budget(&mut self, budget: Duration) {
        self.opts.time_budget = budget;
    }

    /// Moves the wall clock's backstop to `factor` times the budget (a test that loads the
    /// machine on purpose must not meet it).
    pub fn set_backstop_factor(&mut self, factor: u32) {
        self.backstop_factor = factor.max(1);
    }

    /// One more flag that, once set, stops this initialiser's searches at their next check
    /// (reported as a backstop, and as [`InitReport::cancelled`]). A flag given before is not
    /// added twice.
    pub fn add_cancel(&mut self, flag: &Arc<AtomicBool>) {
        if !self.cancel.iter().any(|c| Arc::ptr_eq(c, flag)) {
            self.cancel.push(Arc::clone(flag));
        }
    }

    /// At most `threads` threads run a search's lanes (`None`: one per core); at most [`LANES`]
    /// are used. The answer does not depend on it: what each lane searches is fixed by the
    /// dealing of the cells alone. Starts or stops helper threads: a set-up call.
    pub fn set_threads(&mut self, threads: Option<usize>) {
        let wanted = threads.map_or_else(default_threads, |t| t.clamp(1, LANES));
        if self.helpers.threads() != wanted {
            self.helpers = LanePool::new(wanted, &self.helpers_cpu_ns);
        }
    }

    /// CPU time the helper threads have spent on this initialiser's searches since it was
    /// made (shared: read it from any thread; the search's own thread's time is its own).
    pub fn helpers_cpu(&self) -> Arc<AtomicU64> {
        Arc::clone(&self.helpers_cpu_ns)
    }

    /// How far this initialiser's run under way has got (shared: watch it from any thread).
    pub fn progress(&self) -> &Arc<SearchProgress> {
        &self.progress
    }

    fn cancelled(&self) -> bool {
        self.cancel.iter().any(|c| c.load(Ordering::Relaxed))
    }

    /// The budget in work units.
    fn work_limit(&self) -> u64 {
        u64::try_from(self.opts.time_budget.as_micros()).unwrap_or(u64::MAX)
    }

    /// Charges a step that has just been done: `units` of work, or the occlusion rays it cast
    /// (since the last charge) at [`work::RAYS_PER_UNIT`] if they come to more. Their count
    /// follows the model's detail.
    pub(super) fn spend(&mut self, units: u64) {
        let rays = self.at_pose.rays_cast();
        let cast = rays.saturating_sub(self.rays_charged) / work::RAYS_PER_UNIT;
        self.rays_charged = rays;
        self.work = self.work.saturating_add(units.max(cast));
        self.progress.set_work(self.work);
    }

    /// Occlusion rays cast so far (`visibility::at_pose`, the grid's lanes included): what the
    /// searches are charged for on a detailed model.
    pub fn rays_cast(&self) -> u64 {
        self.at_pose.rays_cast() + self.grid_lanes.iter().map(GridLane::rays_cast).sum::<u64>()
    }

    /// Whether the run has spent `limit` work units, or the wall clock's backstop has fallen.
    pub(super) fn spent(&mut self, limit: u64) -> bool {
        if self.work >= limit {
            return true;
        }
        if Instant::now() >= self.backstop || self.cancelled() {
            self.backstop_hit = true;
            return true;
        }
        false
    }
}

/// Half the spacing between the table's node layers (0.25 m if there is one layer).
fn layer_half_height(heights: &[f64]) -> f64 {
    if heights.len() < 2 {
        return 0.25;
    }
    let mut gap = f64::INFINITY;
    for w in heights.windows(2) {
        gap = gap.min((w[1] - w[0]).abs());
    }
    0.5 * gap
}

fn nearest_layer_z(floor: f64, heights: &[f64], z: f64) -> f64 {
    heights
        .iter()
        .map(|h| floor + h)
        .min_by(|a, b| (a - z).abs().total_cmp(&(b - z).abs()))
        .unwrap_or(z)
}

/// Whether two poses are within `pos` metres and `rot` radians of each other.
pub fn same_pose(a: &Pose, b: &Pose, pos: f64, rot: f64) -> bool {
    (a.translation.vector - b.translation.vector).norm() < pos && a.rotation.angle_to(&b.rotation) < rot
}
