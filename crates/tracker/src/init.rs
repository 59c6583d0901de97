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
//!    A[r][i], A[s][j], A[t][k] += α (Figure 4 line 7).
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
//! 32 real panoramas of the ZInD benchmark (README). But buildings are drawn in few directions,
//! and their lines (texture included) meet in few vanishing points: the frame's vertical and
//! horizontal vanishing directions put onto the model's give a few rotations (a Manhattan
//! building: four, a quarter turn apart), within a degree of the truth on all 32. Under each,
//! the translation is three numbers: positions on a grid over the volume (plan and height steps
//! of 0.25 m, heights in the band above the floor beneath) are scored by *coverage*, the share
//! of the long segments in sight from them along which the frame's longest edges run, climbed in
//! finer steps and polished. The grid covers every cell of the visibility table's grid that
//! meets the volume, whether or not its node is valid: a closet or a hallway narrower than the
//! node spacing often has its node inside a wall. This runs first; the triplets get what is
//! left of the time budget.
//!
//! **The time budget is a deadline** for the whole search: the lattice, the climbs (best
//! first), the triplets, the polish of their samples and the vote all stop at it. The triplets
//! stop early by twice what polishing their best samples takes at the pace of the grid's own
//! polishes. Measured on the ZInD benchmark from the 3 m hint: the polish of the triplets'
//! samples used to run 35–55 ms past the budget (up to 0.5 s with four pinholes).
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
//! support × (1 − blank). Measured on the ZInD panoramas from the 1.5 m hint (README): the
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
//! **The whole model** (start-up without a hint, over a thousand cells in `lab`) is dealt out to
//! one worker per core, each with its own per-cell buffers and a generator seeded per cell, so
//! the answer does not depend on the dealing. On 2 cores the 1,177 cells of `lab` take 8.1 s,
//! against 16 s on one.
//!
//! Fixed memory: all tables are sized in [`Initialiser::new`]. A bounded volume (a hint, a
//! re-initialisation, a relocalisation) is searched on the calling thread and allocates nothing;
//! only the whole-model search starts threads.

use super::floor::Floors;
use super::matching::{best_edge, best_edge_and_cover, correspondence, overlap, Gate, Predicted};
use super::vanishing::{VanishingDirections, MAX_ROTATIONS};
use super::vote::{Grid, TranslationVote, PEAKS};
use crate::visibility::at_pose::{sample_point, PoseVisibility, SAMPLES};
use crate::visibility::VisibilityTable;
use nalgebra::{Matrix2, Matrix3, Point3, Translation3, UnitQuaternion, Vector2, Vector3};
use omnitrack_config::TrackerConfig;
use omnitrack_core::geometry::{xi, Correspondence, Pose};
use omnitrack_core::model::Model;
use omnitrack_core::rig::{Rig, ViewMap};
use omnitrack_edges::Edge;
use omnitrack_solver::robust::MAD_TO_SIGMA;
use omnitrack_solver::{
    minimise_xi, minimise_xi_upright, r_and_t_refine, refine_upright, SimplexOptions, SolverOptions,
};
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use std::time::{Duration, Instant};

/// Dihedral-angle bins of the edge masks (rad).
const BIN_RAD: f64 = 0.5 * std::f64::consts::PI / 180.0;
/// Bins covering [0, π/2].
const BINS: usize = 181;
/// Most edges per frame the triplet matching considers (one bit each in a u64 mask).
pub const MAX_EDGES_CONSIDERED: usize = 64;
/// Samples kept per cell for polishing, and candidates polished per run.
const KEEP_PER_CELL: usize = 3;
const POOL: usize = 64;
const POLISHED: usize = 16;
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

/// Tunables of [`Initialiser`] (from tracker.toml `[initialisation]` and the noise model).
#[derive(Debug, Clone, PartialEq)]
pub struct InitOptions {
    /// m: strongest edges of the frame used in the triplet matching (≤ 64).
    pub edges_considered: usize,
    /// n: longest visible segments of a cell used in the triplet matching.
    pub segments_considered: usize,
    /// k of Figure 4.
    pub best_edges_per_segment: usize,
    /// Random correspondence samples per cell.
    pub samples_per_cell: usize,
    /// The whole run stops by this deadline (anytime: the cells nearest the centre come first).
    pub time_budget: Duration,
    /// Half-width of an observed dihedral angle's interval (rad).
    pub dihedral_tolerance_rad: f64,
    /// Segment pairs whose dihedral range over a cell is wider than this are pruned (rad).
    pub max_range_rad: f64,
    /// A correspondence is an inlier when its α is below this (rad).
    pub inlier_alpha_rad: f64,
    /// Edges and predicted segments shorter than this are ignored (rad).
    pub min_length_rad: f64,
    /// KT §5.4: the rig's known height when it rolls upright (x, y and yaw only).
    pub upright_height_m: Option<f64>,
    /// KT §4.1.3: finish with the simplex minimisation of ξ.
    pub simplex_refinement: bool,
    /// Distinct candidates returned.
    pub candidates: usize,
    /// The most segments [`Initialiser::set_breadth`] may ask for (buffers are sized for it).
    pub wide_segments_considered: usize,
    /// Samples whose rig z axis is further than this from the world's up are dropped (rad;
    /// π keeps every sample).
    pub max_tilt_rad: f64,
    /// The rig centre's height above the floor beneath it (m): poses outside are refused.
    pub height_above_floor_m: [f64; 2],
    /// [`Candidate::blank`]'s radius (rad; 0 = off).
    pub blank_radius_rad: f64,
}

impl InitOptions {
    /// The options tracker.toml gives: `[initialisation]`, the inlier angle of `[maintenance]`,
    /// the minimum edge length and the upright mode; three candidates.
    pub fn from_config(cfg: &TrackerConfig) -> Self {
        let i = &cfg.initialisation;
        InitOptions {
            edges_considered: i.edges_considered as usize,
            segments_considered: i.segments_considered as usize,
            best_edges_per_segment: i.best_edges_per_segment as usize,
            samples_per_cell: i.samples_per_cell as usize,
            time_budget: Duration::from_secs_f64(i.time_budget_ms / 1e3),
            dihedral_tolerance_rad: i.dihedral_tolerance_deg.to_radians(),
            max_range_rad: i.max_dihedral_range_deg.to_radians(),
            inlier_alpha_rad: cfg.maintenance.inlier_angle_deg.to_radians(),
            min_length_rad: cfg.edges.min_edge_length_deg.to_radians(),
            upright_height_m: cfg.motion.upright.then_some(cfg.motion.upright_height_m),
            simplex_refinement: i.simplex_refinement,
            candidates: 3,
            wide_segments_considered: i.wide_segments_considered as usize,
            max_tilt_rad: cfg.motion.max_tilt_deg.to_radians(),
            height_above_floor_m: cfg.motion.height_above_floor_m,
            blank_radius_rad: i.blank_radius_deg.to_radians(),
        }
    }
}

/// Where to search.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SearchVolume {
    /// T̃.
    pub centre: Point3<f64>,
    /// δ; `None` searches the whole model.
    pub diameter_m: Option<f64>,
}

/// A pose found by initialisation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Candidate {
    pub pose: Pose,
    /// Truncated ξ over the segments predicted visible (rad², lower is better).
    pub score: f64,
    /// Correspondences with α below the inlier angle.
    pub inliers: usize,
    /// Plain ξ over those inliers (rad²).
    pub xi_rad2: f64,
    /// Fraction of the segments in sight from the pose (each weighted by the share of it in
    /// sight) long enough to be seen with an edge within the inlier angle, each in proportion to
    /// how much of its part in sight edges cover (up to half of it).
    pub explained: f64,
    /// Fraction of the frame's longest edges (by angle) that a segment in sight from the pose
    /// explains within the inlier angle: the other way round. Texture and clutter make edges the model
    /// cannot explain at any pose, but a wrong pose leaves the building's own lines
    /// unexplained too.
    pub support: f64,
    /// Share of the sampled points of the segments in sight (and on some sensor's image) that
    /// have no edge of any direction near them: where the model draws a line across a plain
    /// surface of the image.
    pub blank: f64,
}

impl Candidate {
    /// How well the pose and the frame explain each other, both ways (higher is better): the
    /// search's ranking.
    pub fn merit(&self) -> f64 {
        self.explained * self.support * (1.0 - self.blank)
    }
}

/// What one [`Initialiser::run`] did.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct InitReport {
    pub cells_in_volume: usize,
    pub cells_searched: usize,
    pub triplet_matches: u64,
    pub samples: u64,
    pub elapsed: Duration,
    pub timed_out: bool,
    /// Samples dropped because the rig would be tilted further than `max_tilt_rad` allows.
    pub tilted: u64,
    /// Of `elapsed`, the grid search under the vanishing directions' rotations (with its
    /// climbs and polishes), and how many rotations it had.
    pub grid_elapsed: Duration,
    pub rotations: usize,
    /// The volume held no valid node: the diameter (m) of the volume actually searched, about
    /// the same centre, out to the nearest valid nodes (`None`: the volume as given).
    pub widened_to_m: Option<f64>,
}

/// Most threads the whole-model search uses.
const MAX_WORKERS: usize = 4;

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
}

impl CellScratch {
    /// For m edges, n segments and visibility sets of at most `max_set` segments.
    fn new(m: usize, n: usize, max_set: usize) -> CellScratch {
        CellScratch {
            seg_order: Vec::with_capacity(max_set),
            segs: Vec::with_capacity(n),
            seg_normals: vec![Vector3::zeros(); n * 9],
            ranges: vec![(0.0, 0.0); n * n],
            score: vec![0.0; n * m],
            best: vec![[(0.0, 0); 3]; n],
            weights: vec![0.0; n],
            corr: Vec::with_capacity(3),
            pool: Pool::new(),
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

/// Keeps `entry` (score, position; highest score best) among the best [`GRID_KEEP`] that are at
/// least [`SAME_POSITION_M`] apart: a better neighbour replaces a worse one.
fn keep_best_apart(best: &mut GridBest, entry: (f64, Point3<f64>)) {
    if let Some(k) = best.iter().position(|b| (b.1 - entry.1).norm() < SAME_POSITION_M) {
        if entry.0 > best[k].0 {
            best[k] = entry;
        }
        return;
    }
    if let Err(entry) = best.push(entry) {
        if let Some(w) = best.iter_mut().min_by(|a, b| a.0.total_cmp(&b.0)) {
            if entry.0 > w.0 {
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
    vote_edges: Vec<Edge>,
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
    /// Time spent polishing in this run, and how many polishes: what the pool's polish will
    /// take, so that the triplets leave it.
    polish_time: (Duration, u32),
    /// The segments in sight from a grid position: (angle they span in sight, index), and the
    /// longest kept.
    grid_order: Vec<(f64, u32)>,
    grid_segs: Vec<u32>,
    /// This frame's rotations from vanishing directions.
    vanishing_rot: [UnitQuaternion<f64>; MAX_ROTATIONS],
    vanishing_count: usize,
    yaw_twins: bool,
    /// A rotation the rig cannot have turned further from than the angle (rad): samples beyond
    /// it are dropped before they take a place in the pool.
    rotation_prior: Option<(UnitQuaternion<f64>, f64)>,
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
        // The whole-model search (start-up without a hint) spreads its cells over the cores.
        let workers = std::thread::available_parallelism()
            .map_or(1, |n| n.get())
            .clamp(1, MAX_WORKERS);
        let floors = Floors::new(model);
        Initialiser {
            model,
            table,
            centres: rig.sensors.iter().map(|s| s.centre()).collect(),
            opts,
            solver,
            edge_order: Vec::with_capacity(max_edges),
            top: Vec::with_capacity(m),
            dihedral: vec![0.0; m * m],
            le_mask: vec![0; m * BINS],
            pairs: Vec::with_capacity(m * m),
            cells: Vec::with_capacity(table.node_count()),
            plan_cells: Vec::with_capacity((table.header.dims[0] as usize) * (table.header.dims[1] as usize)),
            scratch: (0..workers).map(|_| CellScratch::new(m, n, max_set)).collect(),
            pool: Pool::new(),
            corr: Vec::with_capacity(max_set),
            alphas: Vec::with_capacity(max_set),
            candidates: Vec::with_capacity(POLISHED + VOTED_ROTATIONS * PEAKS + MAX_ROTATIONS * GRID_KEEP),
            vote: TranslationVote::new(model.segments.len()),
            vote_edges: Vec::with_capacity(VOTE_EDGES),
            vanishing: VanishingDirections::new(model, max_edges),
            floors,
            grid_best: std::array::from_fn(|_| GridBest::new()),
            at_pose: PoseVisibility::new(model),
            view: ViewMap::new(rig),
            support_pred: Vec::with_capacity(max_set),
            polish_time: (Duration::ZERO, 0),
            grid_order: Vec::with_capacity(max_set),
            grid_segs: Vec::with_capacity(max_set),
            vanishing_rot: [UnitQuaternion::identity(); MAX_ROTATIONS],
            vanishing_count: 0,
            yaw_twins: true,
            rotation_prior: None,
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

    /// The rotation hypotheses the vanishing directions of `edges` give (module `vanishing`), for
    /// diagnosis; the search computes its own.
    pub fn vanishing_rotations(&mut self, edges: &[Edge]) -> Vec<UnitQuaternion<f64>> {
        let mut out = [UnitQuaternion::identity(); MAX_ROTATIONS];
        let n = self.vanishing.rotations(edges, self.opts.max_tilt_rad, &mut out);
        out[..n].to_vec()
    }

    /// Changes the search's time budget (a volume, or the whole model).
    pub fn set_time_budget(&mut self, budget: Duration) {
        self.opts.time_budget = budget;
    }

    /// The grid search under the rotations of the vanishing directions, INIT-SEGMENT-EDGE over
    /// the cells meeting `volume`, the polish of the best samples, and the translation vote.
    /// Returns the distinct candidates, best [`Candidate::merit`] first (empty if nothing was
    /// found).
    pub fn run(&mut self, edges: &[Edge], volume: &SearchVolume, rng: &mut SmallRng) -> (&[Candidate], InitReport) {
        let started = Instant::now();
        let deadline = started + self.opts.time_budget;
        self.polish_time = (Duration::ZERO, 0);
        let mut report = InitReport::default();
        self.candidates.clear();
        self.pool.clear();
        self.prepare_edges(edges);
        self.select_cells(volume);
        // A volume that holds no valid node (a hint outside the building, in a wall, or in a
        // part of the model with no room to stand) is widened about its centre to the nearest
        // valid nodes, and the report says so: a search of nothing would repeat forever.
        // The hint's own extent is kept beyond the gap: it says how far off the rig may be.
        let widened = match (self.cells.is_empty(), volume.diameter_m) {
            (true, Some(d)) => self.nearest_node_gap(&volume.centre).map(|gap| SearchVolume {
                centre: volume.centre,
                diameter_m: Some(2.0 * gap + d.max(self.table.header.spacing_m)),
            }),
            _ => None,
        };
        let volume = match &widened {
            Some(w) => {
                self.select_cells(w);
                report.widened_to_m = w.diameter_m;
                w
            }
            None => volume,
        };
        report.cells_in_volume = self.cells.len();
        let mut rotations = [UnitQuaternion::identity(); MAX_ROTATIONS];
        let found = self.vanishing.rotations(edges, self.opts.max_tilt_rad, &mut rotations);
        self.vanishing_count = 0;
        for r in &rotations[..found] {
            if self.rotation_prior.is_none_or(|(p, limit)| r.angle_to(&p) <= limit) {
                self.vanishing_rot[self.vanishing_count] = *r;
                self.vanishing_count += 1;
            }
        }
        // The grid search under the vanishing directions first: on real photographs it finds
        // what the triplets miss, and the triplets then have what is left of the time budget.
        self.grid_search(edges, volume, deadline);
        report.grid_elapsed = started.elapsed();
        report.rotations = self.vanishing_count;
        // The triplets leave twice the time their samples' polish takes at the grid's pace (a
        // tenth of the budget when the grid polished nothing): a cell's sampling overshoots its
        // check, and a polish cut short makes the result hang on the clock.
        let reserve = match self.polish_time {
            (total, n) if n > 0 => 2 * (total / n * POLISHED as u32),
            _ => self.opts.time_budget / 10,
        };
        let sampling_ends = deadline.checked_sub(reserve).unwrap_or(started);
        if self.top.len() >= 3 {
            // A bounded volume is searched on this thread, nearest cell first, from `rng`. The
            // whole model (start-up without a hint: over a thousand cells) is dealt out to every
            // worker in turn; each cell then draws from its own seeded generator, so the result
            // does not depend on the dealing.
            let mut scratch = std::mem::take(&mut self.scratch);
            let workers = if volume.diameter_m.is_none() { scratch.len() } else { 1 };
            let me = &*self;
            let search = |w: &mut CellScratch, first: usize, rng: Option<&mut SmallRng>, base: u64| {
                let mut own = None;
                let rng = rng.unwrap_or_else(|| own.insert(SmallRng::seed_from_u64(base)));
                let mut done = InitReport::default();
                w.pool.clear();
                for ci in (first..me.cells.len()).step_by(workers) {
                    if Instant::now() >= sampling_ends {
                        done.timed_out = true;
                        break;
                    }
                    let node = me.cells[ci].1;
                    if workers > 1 {
                        *rng = SmallRng::seed_from_u64(base ^ u64::from(node).wrapping_mul(0x9E37_79B9_7F4A_7C15));
                    }
                    done.cells_searched += 1;
                    done.triplet_matches += me.score_cell(w, node);
                    let (drawn, tilted) = me.sample_cell(w, node, volume, rng);
                    done.samples += drawn;
                    done.tilted += tilted;
                }
                done
            };
            let mut add = |part: InitReport| {
                report.cells_searched += part.cells_searched;
                report.triplet_matches += part.triplet_matches;
                report.samples += part.samples;
                report.tilted += part.tilted;
                report.timed_out |= part.timed_out;
            };
            if workers > 1 {
                // Threads only here, at start-up: a bounded search allocates nothing.
                let base: u64 = rng.random();
                let (first, rest) = scratch.split_at_mut(1);
                std::thread::scope(|scope| {
                    let helpers: Vec<_> = rest
                        .iter_mut()
                        .enumerate()
                        .map(|(k, w)| scope.spawn(move || search(w, k + 1, None, base)))
                        .collect();
                    add(search(&mut first[0], 0, None, base));
                    for h in helpers {
                        add(h.join().unwrap_or_default());
                    }
                });
            } else {
                add(search(&mut scratch[0], 0, Some(rng), 0));
            }
            for w in &scratch {
                for &entry in &w.pool {
                    keep_best(&mut self.pool, entry);
                }
            }
            self.scratch = scratch;
        }
        self.pool.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        let mut polished = 0;
        for pi in 0..self.pool.len() {
            if polished >= POLISHED || Instant::now() >= deadline {
                report.timed_out |= polished < POLISHED;
                break;
            }
            let start = self.pool[pi].1;
            if self.pool[..pi]
                .iter()
                .any(|p| same_pose(&p.1, &start, 2.0 * SAME_POSITION_M, 2.0 * SAME_ROTATION_RAD))
            {
                continue;
            }
            polished += 1;
            if let Some(c) = self.timed_polish(&start, edges) {
                self.offer(c);
            }
        }
        self.candidates.sort_unstable_by(|a, b| b.merit().total_cmp(&a.merit()));
        if let Some(d) = volume.diameter_m {
            self.vote_translations(edges, &volume.centre, d, deadline);
        }
        self.candidates.sort_unstable_by(|a, b| b.merit().total_cmp(&a.merit()));
        self.candidates.truncate(self.opts.candidates);
        report.elapsed = started.elapsed();
        (&self.candidates, report)
    }

    /// Adds a polished candidate, or replaces the one in its place (the same pose within
    /// [`SAME_POSITION_M`] and [`SAME_ROTATION_RAD`]) if it fits the frame better (lower
    /// truncated ξ): starts from different searches settle a few centimetres apart.
    fn offer(&mut self, c: Candidate) {
        let same = self
            .candidates
            .iter()
            .position(|o| same_pose(&o.pose, &c.pose, SAME_POSITION_M, SAME_ROTATION_RAD));
        match same {
            Some(k) if c.score < self.candidates[k].score => self.candidates[k] = c,
            Some(_) => {}
            None if self.candidates.len() < self.candidates.capacity() => self.candidates.push(c),
            None => {}
        }
    }

    /// Module `vote`: under the rotations of the best candidates so far (and their quarter
    /// turns about the vertical when `yaw_twins`), the translations most edges agree on, each
    /// polished into a candidate. Within the time budget.
    fn vote_translations(&mut self, edges: &[Edge], centre: &Point3<f64>, diameter: f64, deadline: Instant) {
        if self.cells.is_empty() {
            return;
        }
        // The segments seen from the volume, and the span of heights of the node layers it
        // meets (the known height when upright).
        self.vote.clear_segments();
        let half_z = layer_half_height(&self.table.header.heights_m);
        let (mut z_lo, mut z_hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for k in 0..self.cells.len() {
            let node = self.cells[k].1;
            self.vote.add_segments(self.table.node_set(node).segments);
            let z = self.table.node_position(node).z;
            z_lo = z_lo.min(z - half_z);
            z_hi = z_hi.max(z + half_z);
        }
        if let Some(h) = self.opts.upright_height_m {
            (z_lo, z_hi) = (h, h);
        }
        let mid_z = 0.5 * (z_lo + z_hi);
        let grid = Grid::new(&Point3::new(centre.x, centre.y, mid_z), diameter);
        let mut rotations = [UnitQuaternion::identity(); VOTED_ROTATIONS];
        let mut n_rot = 0;
        for r in &self.vanishing_rot[..self.vanishing_count] {
            rotations[n_rot] = *r;
            n_rot += 1;
        }
        let turns: &[f64] = if self.yaw_twins { &[0.0, 0.5, 1.0, 1.5] } else { &[0.0] };
        for c in self.candidates.iter().take(VOTED_CANDIDATES) {
            for &t in turns {
                let r = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), t * std::f64::consts::PI) * c.pose.rotation;
                if n_rot < rotations.len() && rotations[..n_rot].iter().all(|o| o.angle_to(&r) > SAME_ROTATION_RAD) {
                    rotations[n_rot] = r;
                    n_rot += 1;
                }
            }
        }
        let mut peaks = [(0u16, Pose::identity()); PEAKS];
        for r in &rotations[..n_rot] {
            if Instant::now() >= deadline {
                return;
            }
            let found = self.vote.run(self.model, &self.vote_edges, r, &grid, &mut peaks);
            for &(_, peak) in &peaks[..found] {
                if Instant::now() >= deadline {
                    return;
                }
                // The height: the best truncated ξ over a sweep of the layers' span (the polish
                // alone settles on a wrong height from a start a few decimetres off), then the
                // polish from there.
                let mut start = peak;
                let mut best_z = (f64::INFINITY, mid_z);
                let steps = ((z_hi - z_lo) / HEIGHT_STEP_M).ceil().max(0.0) as usize;
                for k in 0..=steps {
                    let z = (z_lo + k as f64 * HEIGHT_STEP_M).min(z_hi);
                    start.translation.vector.z = z;
                    let (score, _, _, _) = self.final_score(&start, edges);
                    if score < best_z.0 {
                        best_z = (score, z);
                    }
                }
                start.translation.vector.z = best_z.1;
                if let Some(c) = self.timed_polish(&start, edges) {
                    self.offer(c);
                }
            }
        }
    }

    /// Under each rotation of the vanishing directions, the positions of a grid over the plan
    /// cells of the volume (plan and height steps of [`GRID_STEP_M`], heights within the band
    /// above the floor beneath) scored by [`Self::coarse_merit`] over the [`GRID_SEGMENTS`]
    /// longest segments in sight from each; the best few per rotation (within [`GRID_WORTH`] of
    /// the best of all) climbed and polished into candidates. With the rotation known the
    /// translation is three numbers, few enough to search outright. Within the time budget.
    fn grid_search(&mut self, edges: &[Edge], volume: &SearchVolume, deadline: Instant) {
        let h = &self.table.header;
        let half = 0.5 * h.spacing_m;
        let half_z = layer_half_height(&h.heights_m);
        let steps = (h.spacing_m / GRID_STEP_M).round().max(1.0) as usize;
        let step = h.spacing_m / steps as f64;
        let [band_lo, band_hi] = self.opts.height_above_floor_m;
        // The table's slab: heights a node layer serves.
        let (slab_lo, slab_hi) = match (h.heights_m.first(), h.heights_m.last()) {
            (Some(lo), Some(hi)) => (h.origin[2] + lo - half_z, h.origin[2] + hi + half_z),
            _ => (h.origin[2], h.origin[2]),
        };
        let gate = Gate::geometric(GRID_GATE_RAD);
        let min_len = 3.0 * self.opts.min_length_rad;
        for best in &mut self.grid_best {
            best.clear();
        }
        self.select_plan_cells(volume);
        // Plan cells nearest first, every rotation at each: the time budget cuts the far cells
        // of all rotations alike, never a whole rotation. Every cell of the table's grid is
        // searched, whether or not its node is valid: a closet or a hallway narrower than the
        // node spacing often has its node inside a wall, and the rig can still stand there.
        'cells: for ci in 0..self.plan_cells.len() {
            if Instant::now() >= deadline {
                break;
            }
            let centre = self.plan_cells[ci].1;
            for ix in 0..steps {
                for iy in 0..steps {
                    let (x, y) = (
                        centre.x - half + (ix as f64 + 0.5) * step,
                        centre.y - half + (iy as f64 + 0.5) * step,
                    );
                    // Heights: inside the band above the floor beneath (the known height when
                    // upright; the whole slab in a model without floors).
                    let (z_lo, z_hi) = match self.opts.upright_height_m {
                        Some(z) => (z, z),
                        None if self.floors.any() => {
                            match self
                                .floors
                                .band(x, y, [slab_lo, slab_hi], [band_lo, band_hi], self.at_pose.solid())
                            {
                                Some(b) => b,
                                None => continue,
                            }
                        }
                        None => (slab_lo, slab_hi),
                    };
                    if z_hi < z_lo {
                        continue;
                    }
                    let inside =
                        |p: &Point3<f64>| volume.diameter_m.is_none_or(|d| (p - volume.centre).norm() <= 0.5 * d);
                    let plan = Point3::new(x, y, 0.5 * (z_lo + z_hi));
                    let (lo, hi) = (Point3::new(x, y, z_lo), Point3::new(x, y, z_hi));
                    if !inside(&lo) && !inside(&hi) && !inside(&plan) {
                        continue;
                    }
                    // The longest segments in sight from the middle of the heights: a bounded
                    // cost per position, and the lines that decide where the rig is.
                    self.longest_in_sight(&plan, GRID_SEGMENTS);
                    let segs = std::mem::take(&mut self.grid_segs);
                    let mut z = z_lo;
                    while z <= z_hi + 1e-9 {
                        let p = Point3::new(x, y, z);
                        z += GRID_STEP_M;
                        if !inside(&p) {
                            continue;
                        }
                        for ri in 0..self.vanishing_count {
                            let pose = Pose::from_parts(Translation3::from(p.coords), self.vanishing_rot[ri]);
                            if let Some(score) = self.coarse_merit(&pose, &segs, &gate, min_len) {
                                keep_best_apart(&mut self.grid_best[ri], (score, p));
                            }
                        }
                    }
                    self.grid_segs = segs;
                    if Instant::now() >= deadline {
                        break 'cells;
                    }
                }
            }
        }
        // Positions far below the best of any rotation are not worth a climb and a polish; the
        // others climb best first, so that the deadline cuts the least promising.
        let top = self.grid_best[..self.vanishing_count]
            .iter()
            .flatten()
            .map(|b| b.0)
            .fold(0.0, f64::max);
        let mut order = [(0.0, 0u8, 0u8); MAX_ROTATIONS * GRID_KEEP];
        let mut n = 0;
        for ri in 0..self.vanishing_count {
            for (k, b) in self.grid_best[ri].iter().enumerate() {
                if b.0 >= GRID_WORTH * top {
                    order[n] = (b.0, ri as u8, k as u8);
                    n += 1;
                }
            }
        }
        order[..n].sort_unstable_by(|a, b| b.0.total_cmp(&a.0));
        for &(_, ri, k) in &order[..n] {
            if Instant::now() >= deadline {
                break;
            }
            let (ri, k) = (usize::from(ri), usize::from(k));
            let start = self.climb(
                &Pose::from_parts(
                    Translation3::from(self.grid_best[ri][k].1.coords),
                    self.vanishing_rot[ri],
                ),
                min_len,
            );
            if let Some(c) = self.timed_polish(&start, edges) {
                self.offer(c);
            }
        }
    }

    /// [`Self::polish`], its time added to `self.polish_time`.
    fn timed_polish(&mut self, start: &Pose, edges: &[Edge]) -> Option<Candidate> {
        let t = Instant::now();
        let c = self.polish(start, edges);
        self.polish_time.0 += t.elapsed();
        self.polish_time.1 += 1;
        c
    }

    /// Coordinate ascent of the coarse merit ([`Self::coarse_merit`]) from `start` in x, y and
    /// z, in the steps and gates of [`CLIMB`].
    fn climb(&mut self, start: &Pose, min_len: f64) -> Pose {
        let mut pose = *start;
        // The segments in sight from the start: the climb moves a few decimetres at most.
        self.longest_in_sight(&Point3::from(start.translation.vector), usize::MAX);
        let segs = std::mem::take(&mut self.grid_segs);
        for (step, gate_rad) in CLIMB {
            let gate = Gate::geometric(gate_rad);
            let score = |me: &mut Self, p: &Pose| me.coarse_merit(p, &segs, &gate, min_len).unwrap_or(0.0);
            let mut best = score(self, &pose);
            for _ in 0..4 {
                let mut moved = false;
                for axis in 0..3 {
                    for sign in [-1.0, 1.0] {
                        let mut p = pose;
                        p.translation.vector[axis] += sign * step;
                        let s = score(self, &p);
                        if s > best {
                            (best, pose, moved) = (s, p, true);
                        }
                    }
                }
                if !moved {
                    break;
                }
            }
        }
        self.grid_segs = segs;
        pose
    }

    /// The grid's coarse merit of `pose` against the edges of the last [`Self::run`] (for
    /// diagnosis: how a pose the grid never kept would have fared).
    pub fn grid_merit(&mut self, pose: &Pose) -> Option<f64> {
        let gate = Gate::geometric(GRID_GATE_RAD);
        self.longest_in_sight(&Point3::from(pose.translation.vector), GRID_SEGMENTS);
        let segs = std::mem::take(&mut self.grid_segs);
        let merit = self.coarse_merit(pose, &segs, &gate, 3.0 * self.opts.min_length_rad);
        self.grid_segs = segs;
        merit
    }

    /// `self.grid_segs` ← the `keep` longest (by the angle they span in sight) of the segments
    /// in sight from `at`.
    fn longest_in_sight(&mut self, at: &Point3<f64>, keep: usize) {
        let seen = self.at_pose.at(self.model, self.table, at);
        self.grid_order.clear();
        for s in seen {
            let seg = &self.model.segments[s.segment as usize];
            let (a, b) = (seg.a - at, seg.b - at);
            if self.grid_order.len() < self.grid_order.capacity() {
                let angle = a.cross(&b).norm().atan2(a.dot(&b));
                self.grid_order.push((angle * f64::from(s.fraction), s.segment));
            }
        }
        let keep = self.grid_order.len().min(keep);
        if keep > 0 && keep < self.grid_order.len() {
            self.grid_order
                .select_nth_unstable_by(keep - 1, |x, y| y.0.total_cmp(&x.0));
        }
        self.grid_segs.clear();
        for i in 0..keep {
            self.grid_segs.push(self.grid_order[i].1);
        }
    }

    /// [`Candidate::merit`] at a coarse gate, for the grid: of `segments`, those at least
    /// `min_len` long at `pose`, the share the frame's longest edges cover within `gate` (each up
    /// to [`FULL_COVER`]), times the share (by angle) of those edges (the [`VOTE_EDGES`] longest)
    /// that one of them explains within `gate`. `None` if fewer than six segments are that long.
    ///
    /// The support is over all the vote's edges rather than the few dozen longest, as the final
    /// [`Candidate::support`] is over all edges: measured on the ZInD panoramas (README), the
    /// 64 longest let the grid drop the truth in favour of poses along texture (3 m hint: 20 of
    /// 32 within 10 cm with 64, 24 with all 256).
    fn coarse_merit(&mut self, pose: &Pose, segments: &[u32], gate: &Gate, min_len: f64) -> Option<f64> {
        let (mut explained, mut counted) = (0.0, 0usize);
        self.support_pred.clear();
        for &s in segments {
            let seg = &self.model.segments[s as usize];
            let pred = Predicted::new(&[seg.a, seg.b], pose, &self.centres);
            if pred.length_rad < min_len {
                continue;
            }
            counted += 1;
            if let (Some(_), cover) = best_edge_and_cover(&pred, &self.centres, &self.vote_edges, gate) {
                explained += (cover / FULL_COVER).min(1.0);
            }
            if self.support_pred.len() < self.support_pred.capacity() {
                self.support_pred.push(pred);
            }
        }
        if counted < 6 {
            return None;
        }
        let support = self.predicted_support(self.vote_edges.iter(), gate.cos_alpha);
        Some(explained / counted as f64 * support)
    }

    /// ℰ: the strongest edges of sufficient length, their dihedral angles, masks and sorted pairs.
    fn prepare_edges(&mut self, edges: &[Edge]) {
        self.edge_order.clear();
        for (i, e) in edges.iter().enumerate() {
            if e.length_rad >= self.opts.min_length_rad && self.edge_order.len() < self.edge_order.capacity() {
                self.edge_order.push((e.strength, i as u32));
            }
        }
        self.edge_order.sort_unstable_by(|a, b| b.0.total_cmp(&a.0));
        self.top.clear();
        for &(_, i) in self.edge_order.iter().take(self.opts.edges_considered) {
            self.top.push(edges[i as usize]);
        }
        // The vote's edges: the longest (reusing the order buffer, which is done with).
        for entry in self.edge_order.iter_mut() {
            entry.0 = edges[entry.1 as usize].length_rad as f32;
        }
        self.edge_order.sort_unstable_by(|a, b| b.0.total_cmp(&a.0));
        self.vote_edges.clear();
        for &(_, i) in self.edge_order.iter().take(VOTE_EDGES) {
            self.vote_edges.push(edges[i as usize]);
        }
        let m = self.top.len();
        let mm = self.opts.edges_considered;
        self.le_mask.iter_mut().for_each(|x| *x = 0);
        self.pairs.clear();
        for r in 0..m {
            for s in 0..m {
                if r == s {
                    self.dihedral[r * mm + s] = 0.0;
                    continue;
                }
                let d = dihedral(&self.top[r].plane.normal, &self.top[s].plane.normal);
                self.dihedral[r * mm + s] = d as f32;
                self.le_mask[r * BINS + bin(d)] |= 1u64 << s;
                self.pairs.push((d as f32, r as u8, s as u8));
            }
            for b in 1..BINS {
                self.le_mask[r * BINS + b] |= self.le_mask[r * BINS + b - 1];
            }
        }
        self.pairs.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    }

    /// The table grid's plan cells (valid node or not) that meet the volume's plan disc,
    /// nearest its centre first: (distance, cell centre at the volume's height).
    fn select_plan_cells(&mut self, volume: &SearchVolume) {
        self.plan_cells.clear();
        let h = &self.table.header;
        let half = 0.5 * h.spacing_m;
        for j in 0..h.dims[1] {
            for i in 0..h.dims[0] {
                let c = Point3::new(
                    h.origin[0] + f64::from(i) * h.spacing_m,
                    h.origin[1] + f64::from(j) * h.spacing_m,
                    volume.centre.z,
                );
                let d = volume.centre - c;
                let gap = Vector2::new((d.x.abs() - half).max(0.0), (d.y.abs() - half).max(0.0)).norm();
                if volume.diameter_m.is_none_or(|dm| gap <= 0.5 * dm)
                    && self.plan_cells.len() < self.plan_cells.capacity()
                {
                    self.plan_cells.push((d.norm(), c));
                }
            }
        }
        self.plan_cells.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    }

    /// How far (m) `at` lies from `node`'s cell (0 inside it), or `None` for a node off the
    /// known layer when upright (whose height is not searched).
    fn cell_gap(&self, at: &Point3<f64>, node: u32) -> Option<f64> {
        let h = &self.table.header;
        let p = self.table.node_position(node);
        let half = 0.5 * h.spacing_m;
        let dz = match self.opts.upright_height_m {
            Some(z) => {
                if (p.z - nearest_layer_z(h.origin[2], &h.heights_m, z)).abs() > 1e-6 {
                    return None;
                }
                0.0
            }
            None => ((at.z - p.z).abs() - layer_half_height(&h.heights_m)).max(0.0),
        };
        let d = at - p;
        Some(Vector3::new((d.x.abs() - half).max(0.0), (d.y.abs() - half).max(0.0), dz).norm())
    }

    /// How far (m) the nearest searchable node's cell lies from `at`, or `None` for a table
    /// without one.
    fn nearest_node_gap(&self, at: &Point3<f64>) -> Option<f64> {
        (0..self.table.node_count() as u32)
            .filter_map(|node| self.cell_gap(at, node))
            .min_by(f64::total_cmp)
    }

    /// The nodes whose cells meet the volume, nearest first (one layer when upright).
    fn select_cells(&mut self, volume: &SearchVolume) {
        self.cells.clear();
        for node in 0..self.table.node_count() as u32 {
            let Some(gap) = self.cell_gap(&volume.centre, node) else {
                continue;
            };
            if volume.diameter_m.is_none_or(|dm| gap <= 0.5 * dm) && self.cells.len() < self.cells.capacity() {
                let distance = (volume.centre - self.table.node_position(node)).norm();
                self.cells.push((distance, node));
            }
        }
        self.cells.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    }

    /// The sample points of a node's cell: its centre and corners (at the known height when
    /// upright). Returns how many of `out` were filled.
    fn cell_points(&self, node: u32, out: &mut [Point3<f64>; 9]) -> usize {
        let h = &self.table.header;
        let p = self.table.node_position(node);
        let half = 0.5 * h.spacing_m;
        if let Some(z) = self.opts.upright_height_m {
            out[0] = Point3::new(p.x, p.y, z);
            let mut k = 1;
            for sx in [-1.0, 1.0] {
                for sy in [-1.0, 1.0] {
                    out[k] = Point3::new(p.x + sx * half, p.y + sy * half, z);
                    k += 1;
                }
            }
            5
        } else {
            let hz = layer_half_height(&h.heights_m);
            out[0] = p;
            let mut k = 1;
            for sx in [-1.0, 1.0] {
                for sy in [-1.0, 1.0] {
                    for sz in [-1.0, 1.0] {
                        out[k] = Point3::new(p.x + sx * half, p.y + sy * half, p.z + sz * hz);
                        k += 1;
                    }
                }
            }
            9
        }
    }

    /// Figure 4 lines 1–10 for one cell: ℒ, the dihedral ranges, the triplet matching into the
    /// score table, the k best edges per segment. Returns the number of triplet matches.
    fn score_cell(&self, w: &mut CellScratch, node: u32) -> u64 {
        let mut points = [Point3::origin(); 9];
        let np = self.cell_points(node, &mut points);
        let centre = points[0];
        let set = self.table.node_set(node);
        w.seg_order.clear();
        for &s in set.segments {
            let seg = &self.model.segments[s as usize];
            let (a, b) = (seg.a - centre, seg.b - centre);
            let len = a.cross(&b).norm().atan2(a.dot(&b));
            if len >= 1.5 * self.opts.min_length_rad && w.seg_order.len() < w.seg_order.capacity() {
                w.seg_order.push((len, s));
            }
        }
        w.seg_order.sort_unstable_by(|a, b| b.0.total_cmp(&a.0));
        w.segs.clear();
        let n_max = self.opts.segments_considered;
        for &(_, s) in w.seg_order.iter().take(n_max) {
            w.segs.push(s);
        }
        let n = w.segs.len();
        let m = self.top.len();
        let mm = self.opts.edges_considered;
        for (i, &s) in w.segs.iter().enumerate() {
            let seg = &self.model.segments[s as usize];
            for (k, p) in points[..np].iter().enumerate() {
                let nrm = (seg.a - p).cross(&(seg.b - p));
                w.seg_normals[i * 9 + k] = nrm.try_normalize(1e-12).unwrap_or_else(Vector3::z);
            }
        }
        let tol = self.opts.dihedral_tolerance_rad as f32;
        let max_width = self.opts.max_range_rad as f32;
        for i in 0..n {
            for j in i + 1..n {
                let (mut lo, mut hi) = (f32::INFINITY, 0f32);
                for k in 0..np {
                    let d = dihedral_v(&w.seg_normals[i * 9 + k], &w.seg_normals[j * 9 + k]) as f32;
                    lo = lo.min(d);
                    hi = hi.max(d);
                }
                w.ranges[i * n_max + j] = (lo, hi);
            }
        }
        w.score[..n_max * mm].iter_mut().for_each(|x| *x = 0.0);
        let mut matches = 0u64;
        for i in 0..n {
            for j in i + 1..n {
                let rij = w.ranges[i * n_max + j];
                if rij.1 - rij.0 > max_width {
                    continue;
                }
                let a = self.pairs.partition_point(|p| p.0 < rij.0 - tol);
                let b = self.pairs.partition_point(|p| p.0 <= rij.1 + tol);
                if a >= b {
                    continue;
                }
                for k in j + 1..n {
                    let rik = w.ranges[i * n_max + k];
                    let rjk = w.ranges[j * n_max + k];
                    if rik.1 - rik.0 > max_width || rjk.1 - rjk.0 > max_width {
                        continue;
                    }
                    for &(d_rs, r, s) in &self.pairs[a..b] {
                        let (r, s) = (r as usize, s as usize);
                        let mask = range_mask(&self.le_mask[r * BINS..(r + 1) * BINS], rik, tol)
                            & range_mask(&self.le_mask[s * BINS..(s + 1) * BINS], rjk, tol);
                        let mut bits = mask & !((1u64 << r) | (1u64 << s));
                        while bits != 0 {
                            let t = bits.trailing_zeros() as usize;
                            bits &= bits - 1;
                            let alpha = jaccard(d_rs, rij, tol)
                                * jaccard(self.dihedral[r * mm + t], rik, tol)
                                * jaccard(self.dihedral[s * mm + t], rjk, tol);
                            if alpha > 0.0 {
                                matches += 1;
                                w.score[i * mm + r] += alpha;
                                w.score[j * mm + s] += alpha;
                                w.score[k * mm + t] += alpha;
                            }
                        }
                    }
                }
            }
        }
        // Lines 8–10: the k best edges of each segment; a segment's weight in the sampling is
        // how much its best edge stands out of its row.
        let kb = self.opts.best_edges_per_segment;
        for i in 0..n {
            let row = &w.score[i * mm..i * mm + m];
            let mut best = [(0f32, 0u8); 3];
            let mut total = 0f32;
            for (r, &v) in row.iter().enumerate() {
                total += v;
                if v > best[kb - 1].0 {
                    let mut p = kb - 1;
                    while p > 0 && best[p - 1].0 < v {
                        best[p] = best[p - 1];
                        p -= 1;
                    }
                    best[p] = (v, r as u8);
                }
            }
            w.best[i] = best;
            w.weights[i] = if total > 0.0 { (best[0].0 / total) as f64 } else { 0.0 };
        }
        matches
    }

    /// Figure 4 lines 11–15 for one cell: random correspondence samples, a pose for each, the best
    /// kept in the pool. Returns the number of samples drawn and how many of them were dropped as
    /// tilted.
    fn sample_cell(&self, w: &mut CellScratch, node: u32, volume: &SearchVolume, rng: &mut SmallRng) -> (u64, u64) {
        let n = w.segs.len();
        let total: f64 = w.weights[..n].iter().sum();
        if n < 3 || total <= 0.0 || w.weights[..n].iter().filter(|w| **w > 0.0).count() < 3 {
            return (0, 0);
        }
        let min_up = self.opts.max_tilt_rad.cos();
        let mut tilted = 0u64;
        let mut points = [Point3::origin(); 9];
        self.cell_points(node, &mut points);
        let centre = points[0];
        let h = &self.table.header;
        let reach = h.spacing_m;
        // Predictions for scoring are recomputed per sample pose; the segment list is the cell's.
        let mut kept = [(f64::INFINITY, Pose::identity()); KEEP_PER_CELL];
        let mut drawn = 0u64;
        let mut attempts = 0;
        let tol = self.opts.dihedral_tolerance_rad as f32;
        let (mm, n_max) = (self.opts.edges_considered, self.opts.segments_considered);
        while (drawn as usize) < self.opts.samples_per_cell && attempts < 20 * self.opts.samples_per_cell {
            attempts += 1;
            let mut pick = [(0usize, 0usize); 3];
            let mut ok = true;
            for slot in 0..3 {
                let mut found = false;
                for _attempt in 0..8 {
                    let i = weighted_index(&w.weights[..n], total, rng);
                    let options = w.best[i].iter().filter(|b| b.0 > 0.0).count();
                    if options == 0 {
                        continue;
                    }
                    let r = w.best[i][rng.random_range(0..options)].1 as usize;
                    if pick[..slot].iter().any(|&(pi, pr)| pi == i || pr == r) {
                        continue;
                    }
                    pick[slot] = (i, r);
                    found = true;
                    break;
                }
                if !found {
                    ok = false;
                    break;
                }
            }
            if !ok {
                continue;
            }
            // Figure 4's compatibility holds for the sample as a whole: all three pairs' dihedral
            // angles must fall in their ranges (the table only scored each pair's members).
            let consistent = (0..3).all(|a| {
                let b = (a + 1) % 3;
                let (i, j) = (pick[a].0.min(pick[b].0), pick[a].0.max(pick[b].0));
                let d = self.dihedral[pick[a].1 * mm + pick[b].1];
                jaccard(d, w.ranges[i * n_max + j], tol) > 0.0
            });
            if !consistent {
                continue;
            }
            drawn += 1;
            let Some(pose) = self.sample_pose(w, &pick, &centre) else {
                continue;
            };
            let p = pose.translation.vector;
            let inside_cell = (p.x - centre.x).abs() <= reach && (p.y - centre.y).abs() <= reach;
            let inside_volume = volume
                .diameter_m
                .is_none_or(|dm| (p - volume.centre.coords).xy().norm() <= 0.5 * dm + reach);
            let z_ok = self.opts.upright_height_m.is_some() || (p.z - centre.z).abs() <= reach;
            if !(inside_cell && inside_volume && z_ok) {
                continue;
            }
            if self
                .rotation_prior
                .is_some_and(|(r, limit)| pose.rotation.angle_to(&r) > limit)
            {
                continue;
            }
            // The rig's up axis in the world: a worn rig is never upside down, and a symmetric
            // building's upside-down twin explains as much as the truth on one frame.
            if (pose.rotation * Vector3::z()).z < min_up {
                tilted += 1;
                continue;
            }
            let s = self.loose_score(w, &pose);
            if s < kept[KEEP_PER_CELL - 1].0 {
                kept[KEEP_PER_CELL - 1] = (s, pose);
                kept.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
            }
        }
        for (s, pose) in kept {
            if s.is_finite() {
                keep_best(&mut w.pool, (s, pose));
            }
        }
        (drawn, tilted)
    }

    /// The pose of three correspondences (segment slot, top-edge index): Wahba rotation from the
    /// plane normals at the cell centre, eq. 9 translation, R_and_T on the three.
    fn sample_pose(&self, w: &mut CellScratch, pick: &[(usize, usize); 3], centre: &Point3<f64>) -> Option<Pose> {
        let mut u = [Vector3::zeros(); 3];
        let mut v = [Vector3::zeros(); 3];
        for (k, &(i, r)) in pick.iter().enumerate() {
            u[k] = self.top[r].plane.normal.into_inner();
            v[k] = w.seg_normals[i * 9];
        }
        // Normals carry no sign: make the edge normals' pairwise signs agree with the segments'.
        for k in 1..3 {
            if u[0].dot(&u[k]) * v[0].dot(&v[k]) < 0.0 {
                u[k] = -u[k];
            }
        }
        let rotation = if self.opts.upright_height_m.is_some() {
            let plus = yaw_fit(&u, &v, 1.0);
            let minus = yaw_fit(&u, &v, -1.0);
            if plus.1 <= minus.1 {
                plus.0
            } else {
                minus.0
            }
        } else {
            let plus = wahba(&u, &v, 1.0)?;
            let minus = wahba(&u, &v, -1.0)?;
            if plus.1 <= minus.1 {
                plus.0
            } else {
                minus.0
            }
        };
        w.corr.clear();
        for &(i, r) in pick {
            let seg = &self.model.segments[w.segs[i] as usize];
            w.corr.push(correspondence(&self.top[r], &[seg.a, seg.b]));
        }
        let t = translation_given_rotation(&w.corr, &rotation, self.opts.upright_height_m, centre)?;
        let start = Pose::from_parts(Translation3::from(t), rotation);
        self.fit(&w.corr, &start)
    }

    /// R_and_T (or its upright form) on `corr` from `start`.
    fn fit(&self, corr: &[Correspondence], start: &Pose) -> Option<Pose> {
        match self.opts.upright_height_m {
            Some(_) => refine_upright(corr, start, &self.solver),
            None => r_and_t_refine(corr, start, &self.solver),
        }
    }

    /// The fit of `self.corr` from `start`, then twice: correspondences whose α exceeds
    /// max(inlier angle, 2.5 robust σ from the median α) are dropped and the rest refitted. A
    /// greedy gather at a wide gate holds wrong matches, and one of them is enough to pull a plain
    /// least-squares fit into a neighbouring minimum.
    fn trimmed_fit(&mut self, start: &Pose) -> Option<Pose> {
        let mut pose = self.fit(&self.corr, start)?;
        for _ in 0..2 {
            self.alphas.clear();
            self.alphas.extend(self.corr.iter().map(|c| c.alpha(&pose)));
            let n = self.alphas.len();
            if n < 5 {
                break;
            }
            let (_, median, _) = self.alphas.select_nth_unstable_by(n / 2, f64::total_cmp);
            let limit = (2.5 * MAD_TO_SIGMA * *median).max(self.opts.inlier_alpha_rad);
            let before = self.corr.len();
            self.corr.retain(|c| c.alpha(&pose) <= limit);
            if self.corr.len() == before {
                break;
            }
            if self.corr.len() < 4 {
                return None;
            }
            pose = self.fit(&self.corr, &pose)?;
        }
        Some(pose)
    }

    /// Truncated ξ of a sample's pose over the cell's segments and the frame's top edges (a
    /// loose cap: the sample's pose is not refined yet).
    fn loose_score(&self, w: &CellScratch, pose: &Pose) -> f64 {
        let cap = (4.0 * self.opts.inlier_alpha_rad).min(0.2);
        let gate = Gate::geometric(cap);
        let mut sum = 0.0;
        let mut counted = 0usize;
        for &s in &w.segs {
            let seg = &self.model.segments[s as usize];
            let pred = Predicted::new(&[seg.a, seg.b], pose, &self.centres);
            if pred.length_rad < self.opts.min_length_rad {
                continue;
            }
            counted += 1;
            sum += match best_edge(&pred, &self.centres, &self.top, &gate) {
                Some((_, a)) => a * a,
                None => cap * cap,
            };
        }
        if counted < 3 {
            f64::INFINITY
        } else {
            sum / counted as f64
        }
    }

    /// Matches gathered at `start` with shrinking gates over the segments in sight and all of
    /// the frame's edges, refit each time, the ξ simplex last; scored by the truncated ξ.
    pub fn polish(&mut self, start: &Pose, edges: &[Edge]) -> Option<Candidate> {
        let candidate = self.polish_unchecked(start, edges)?;
        self.height_ok(&candidate.pose).then_some(candidate)
    }

    /// Whether `pose` stands within the height band above a floor of the model (always true for
    /// a model without floors and when upright, whose height is given).
    pub fn height_ok(&self, pose: &Pose) -> bool {
        if self.opts.upright_height_m.is_some() || !self.floors.any() {
            return true;
        }
        let p = Point3::from(pose.translation.vector);
        let [lo, hi] = self.opts.height_above_floor_m;
        self.floors
            .below(&p, self.at_pose.solid())
            .is_some_and(|f| p.z - f >= lo - HEIGHT_SLACK_M && p.z - f <= hi + HEIGHT_SLACK_M)
    }

    fn polish_unchecked(&mut self, start: &Pose, edges: &[Edge]) -> Option<Candidate> {
        let inlier = self.opts.inlier_alpha_rad;
        let mut pose = *start;
        for gate_rad in [4.0 * inlier, 2.0 * inlier, inlier] {
            let count = self.gather(&pose, edges, gate_rad);
            if count < 4 {
                return None;
            }
            pose = self.trimmed_fit(&pose)?;
        }
        let count = self.gather(&pose, edges, inlier);
        if count < 4 {
            return None;
        }
        if self.opts.simplex_refinement {
            let opts = SimplexOptions {
                max_iterations: 600,
                ..SimplexOptions::default()
            };
            let (p, _, _, _) = match self.opts.upright_height_m {
                Some(_) => minimise_xi_upright(&self.corr, &pose, &opts),
                None => minimise_xi(&self.corr, &pose, &opts),
            };
            if xi(&self.corr, &p) <= xi(&self.corr, &pose) {
                pose = p;
            }
        }
        let (score, inliers, _, explained) = self.final_score(&pose, edges);
        let support = self.edge_support(&pose, edges);
        let blank = self.blank_share(&pose, edges);
        let count = self.gather(&pose, edges, inlier);
        Some(Candidate {
            blank,
            pose,
            score,
            inliers,
            xi_rad2: xi(&self.corr[..count], &pose),
            explained,
            support,
        })
    }

    /// `self.corr` ← for each segment in sight from the pose and long enough, its best edge within
    /// `gate_rad`.
    fn gather(&mut self, pose: &Pose, edges: &[Edge], gate_rad: f64) -> usize {
        self.corr.clear();
        let gate = Gate::geometric(gate_rad);
        let seen = self
            .at_pose
            .at(self.model, self.table, &Point3::from(pose.translation.vector));
        for s in seen {
            let seg = &self.model.segments[s.segment as usize];
            let ends = [seg.a, seg.b];
            let pred = Predicted::new(&ends, pose, &self.centres);
            if pred.length_rad < self.opts.min_length_rad {
                continue;
            }
            if let Some((e, _)) = best_edge(&pred, &self.centres, edges, &gate) {
                if self.corr.len() < self.corr.capacity() {
                    self.corr.push(correspondence(&edges[e], &ends));
                }
            }
        }
        self.corr.len()
    }

    /// [`Candidate::score`] of any pose (truncated ξ over the segments in sight from the pose).
    pub fn score(&mut self, pose: &Pose, edges: &[Edge]) -> f64 {
        self.final_score(pose, edges).0
    }

    /// [`Candidate::support`] of any pose: the share (by angle) of all of `edges` at least the
    /// shortest edge long that a segment in sight from the pose explains within the inlier angle.
    ///
    /// All of them, not the longest few: on real photographs the longest edges are mostly
    /// texture (shelves, blinds, floorboards), so a share of a few dozen of them is a noisy
    /// sample that a wrong pose along the texture wins as often as the truth. Over the ZInD
    /// panoramas' candidates (README, "Real photographs") the share over all edges gave the
    /// truth a clear margin (merit ratio ≤ 0.8) over the best pose 0.6 m or 10° away on 27 of 32,
    /// against 22 with the 64 longest.
    pub fn edge_support(&mut self, pose: &Pose, edges: &[Edge]) -> f64 {
        // Each segment's plane in every sensor, once.
        self.support_pred.clear();
        let seen = self
            .at_pose
            .at(self.model, self.table, &Point3::from(pose.translation.vector));
        for k in seen {
            let seg = &self.model.segments[k.segment as usize];
            if self.support_pred.len() < self.support_pred.capacity() {
                self.support_pred
                    .push(Predicted::new(&[seg.a, seg.b], pose, &self.centres));
            }
        }
        let min_len = self.opts.min_length_rad;
        self.predicted_support(
            edges.iter().filter(|e| e.length_rad >= min_len),
            self.opts.inlier_alpha_rad.cos(),
        )
    }

    /// The share (by angle) of `edges` that one of `self.support_pred` explains: plane within
    /// the gate (cos) and overlapping.
    fn predicted_support<'e>(&self, edges: impl Iterator<Item = &'e Edge>, cos_gate: f64) -> f64 {
        let (mut explained, mut total) = (0.0, 0.0);
        for e in edges {
            let s = e.sensor as usize;
            if s >= self.centres.len() {
                continue;
            }
            total += e.length_rad;
            let hit = self.support_pred.iter().any(|pred| {
                let nrm = &pred.normals[s];
                nrm.dot(&e.plane.normal).abs() >= cos_gate && overlap(pred, &self.centres[s], nrm, e) >= 0.5
            });
            if hit {
                explained += e.length_rad;
            }
        }
        if total > 0.0 {
            explained / total
        } else {
            0.0
        }
    }

    /// How many model segments the rig images long enough to detect from `pose`: in sight
    /// (`at_pose`), on some sensor's image ([`ViewMap`]) for at least one of their sampled
    /// points, and at least the shortest edge long. What a frame there can match at best.
    ///
    /// Scores do not count this way (yet): judging candidates by the segments in view alone
    /// made a one-pinhole rig commit wrong poses on real photographs (README, "Real photographs",
    /// "Not there yet").
    pub fn segments_in_view(&mut self, pose: &Pose) -> usize {
        let seen = self
            .at_pose
            .at(self.model, self.table, &Point3::from(pose.translation.vector));
        let mut n = 0;
        for s in seen {
            let seg = &self.model.segments[s.segment as usize];
            if in_view(&self.view, pose, &seg.a, &seg.b, s.mask) > 0.0
                && Predicted::new(&[seg.a, seg.b], pose, &self.centres).length_rad >= self.opts.min_length_rad
            {
                n += 1;
            }
        }
        n
    }

    /// [`Candidate::explained`] of any pose.
    pub fn explained(&mut self, pose: &Pose, edges: &[Edge]) -> f64 {
        self.final_score(pose, edges).3
    }

    /// (truncated ξ with the inlier cap over the segments in sight from the pose and long enough,
    /// inliers, segments counted, the share of them explained). A segment counts as explained, and at its
    /// α rather than the cap, in proportion to how much of it the matching edges cover, up to
    /// [`FULL_COVER`].
    fn final_score(&mut self, pose: &Pose, edges: &[Edge]) -> (f64, usize, usize, f64) {
        let cap = self.opts.inlier_alpha_rad;
        let gate = Gate::geometric(cap);
        let seen = self
            .at_pose
            .at(self.model, self.table, &Point3::from(pose.translation.vector));
        let (mut sum, mut counted, mut inliers) = (0.0, 0usize, 0usize);
        let (mut explained, mut weight) = (0.0, 0.0);
        for s in seen {
            let seg = &self.model.segments[s.segment as usize];
            let pred = Predicted::new(&[seg.a, seg.b], pose, &self.centres);
            if pred.length_rad < self.opts.min_length_rad {
                continue;
            }
            // A segment partly hidden counts for the part in sight, and is explained when edges
            // cover half of that part.
            let f = f64::from(s.fraction);
            counted += 1;
            weight += f;
            match best_edge_and_cover(&pred, &self.centres, edges, &gate) {
                (Some((_, a)), cover) => {
                    let w = (cover / (FULL_COVER * f)).min(1.0);
                    sum += f * (w * a * a + (1.0 - w) * cap * cap);
                    explained += f * w;
                    inliers += 1;
                }
                (None, _) => sum += f * cap * cap,
            }
        }
        if counted == 0 || weight <= 0.0 {
            (f64::INFINITY, 0, 0, 0.0)
        } else {
            (sum / weight, inliers, counted, explained / weight)
        }
    }

    /// [`Candidate::blank`] of any pose: of the [`SAMPLES`] points of each segment in sight and
    /// long enough, those in sight and on some sensor's image ([`ViewMap`]), the share with no
    /// edge of any direction within `blank_radius_deg` of its ray from that edge's sensor (off
    /// the edge's plane and beyond its ends alike). 0 when the radius is 0 or nothing is in
    /// view. Cost: points × edges plane tests, a millisecond or two per pose.
    pub fn blank_share(&mut self, pose: &Pose, edges: &[Edge]) -> f64 {
        let r = self.opts.blank_radius_rad;
        if r <= 0.0 {
            return 0.0;
        }
        let sin_r = r.sin();
        let seen = self
            .at_pose
            .at(self.model, self.table, &Point3::from(pose.translation.vector));
        let (mut blank, mut points) = (0usize, 0usize);
        for s in seen {
            let seg = &self.model.segments[s.segment as usize];
            let pred = Predicted::new(&[seg.a, seg.b], pose, &self.centres);
            if pred.length_rad < self.opts.min_length_rad {
                continue;
            }
            for k in 0..SAMPLES {
                if s.mask & (1 << k) == 0 {
                    continue;
                }
                let p = pose.inverse_transform_point(&sample_point(&seg.a, &seg.b, k)).coords;
                if !self.view.sees(&p) {
                    continue;
                }
                points += 1;
                let mut dirs = [Vector3::zeros(); super::matching::MAX_SENSORS];
                for (d, c) in dirs.iter_mut().zip(&self.centres) {
                    *d = (p - c.coords).try_normalize(1e-9).unwrap_or_else(Vector3::zeros);
                }
                let near = edges.iter().any(|e| {
                    let Some(d) = dirs.get(e.sensor as usize) else {
                        return false;
                    };
                    if e.plane.normal.dot(d).abs() > sin_r {
                        return false;
                    }
                    let a0 = e.plane.ends[0].dot(d).clamp(-1.0, 1.0).acos();
                    let a1 = e.plane.ends[1].dot(d).clamp(-1.0, 1.0).acos();
                    a0 + a1 - e.length_rad <= 2.0 * r
                });
                if !near {
                    blank += 1;
                }
            }
        }
        if points == 0 {
            0.0
        } else {
            blank as f64 / points as f64
        }
    }

    /// The correspondences of the last [`Self::polish`] (inliers at its pose).
    pub fn correspondences(&self) -> &[Correspondence] {
        &self.corr
    }
}

/// Angle (rad, [0, π/2]) between two planes given their unit normals.
#[inline]
fn dihedral(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    a.cross(b).norm().atan2(a.dot(b).abs())
}

#[inline]
fn dihedral_v(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    dihedral(a, b)
}

#[inline]
fn bin(d: f64) -> usize {
    ((d / BIN_RAD).floor().max(0.0) as usize).min(BINS - 1)
}

/// Edges whose dihedral angle with the mask's edge lies in `range` ± `tol` (conservative to the
/// bin; the exact test is the overlap score).
#[inline]
fn range_mask(le: &[u64], range: (f32, f32), tol: f32) -> u64 {
    let lo = (range.0 - tol) as f64;
    let hi = (range.1 + tol) as f64;
    if hi < 0.0 {
        return 0;
    }
    let bh = bin(hi);
    let upper = le[bh];
    if lo <= 0.0 {
        return upper;
    }
    let bl = bin(lo);
    if bl == 0 {
        upper
    } else {
        upper & !le[bl - 1]
    }
}

/// Overlap of [d − tol, d + tol] with `range`, over their union.
#[inline]
fn jaccard(d: f32, range: (f32, f32), tol: f32) -> f32 {
    let inter = (d + tol).min(range.1) - (d - tol).max(range.0);
    if inter <= 0.0 {
        return 0.0;
    }
    let union = (d + tol).max(range.1) - (d - tol).min(range.0);
    inter / union
}

fn weighted_index(weights: &[f64], total: f64, rng: &mut SmallRng) -> usize {
    let mut x = rng.random_range(0.0..total);
    for (i, w) in weights.iter().enumerate() {
        if x < *w {
            return i;
        }
        x -= w;
    }
    weights.len() - 1
}

/// Share of the segment a–b in view from `pose`: of its [`SAMPLES`] sampled points, those in
/// sight (bit k of `mask`, as `at_pose` gives it) that some sensor of the rig images.
fn in_view(view: &ViewMap, pose: &Pose, a: &Point3<f64>, b: &Point3<f64>, mask: u8) -> f64 {
    let mut n = 0;
    for k in 0..SAMPLES {
        if mask & (1 << k) != 0 && view.sees(&pose.inverse_transform_point(&sample_point(a, b, k)).coords) {
            n += 1;
        }
    }
    n as f64 / SAMPLES as f64
}

/// Wahba's problem for R (rig → world) with R (sign·u_k) ≈ v_k: the rotation and its residual.
fn wahba(u: &[Vector3<f64>; 3], v: &[Vector3<f64>; 3], sign: f64) -> Option<(UnitQuaternion<f64>, f64)> {
    let mut b = Matrix3::zeros();
    for k in 0..3 {
        b += v[k] * (u[k] * sign).transpose();
    }
    let svd = b.svd(true, true);
    let (uu, vt) = (svd.u?, svd.v_t?);
    let d = (uu * vt).determinant().signum();
    let r = uu * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * vt;
    let q = UnitQuaternion::from_matrix(&r);
    let residual = (0..3).map(|k| (q * (u[k] * sign) - v[k]).norm_squared()).sum();
    Some((q, residual))
}

/// The yaw ψ with Rz(ψ) (sign·u_k) ≈ v_k in the ground plane (closed form), and its residual.
fn yaw_fit(u: &[Vector3<f64>; 3], v: &[Vector3<f64>; 3], sign: f64) -> (UnitQuaternion<f64>, f64) {
    let (mut s, mut c) = (0.0, 0.0);
    for k in 0..3 {
        let a = u[k] * sign;
        s += a.x * v[k].y - a.y * v[k].x;
        c += a.x * v[k].x + a.y * v[k].y;
    }
    let q = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), s.atan2(c));
    let residual = (0..3).map(|k| (q * (u[k] * sign) - v[k]).norm_squared()).sum();
    (q, residual)
}

/// Eq. 9 with the rotation known: every end point P of a segment lies on its edge's plane, whose
/// world normal is m = R n through the world point t + R c: m · t = m · (P − R c). Upright: z is
/// the known height and only x, y are solved. `None` if the planes do not fix the position.
fn translation_given_rotation(
    c: &[Correspondence],
    rotation: &UnitQuaternion<f64>,
    upright_height: Option<f64>,
    centre: &Point3<f64>,
) -> Option<Vector3<f64>> {
    match upright_height {
        Some(z) => {
            let mut a = Matrix2::zeros();
            let mut b = Vector2::zeros();
            for l in c {
                let m = rotation * l.edge.normal.into_inner();
                let rc = rotation * l.edge.centre.coords;
                for p in &l.segment {
                    let row = Vector2::new(m.x, m.y);
                    let rhs = m.dot(&(p.coords - rc)) - m.z * z;
                    a += row * row.transpose();
                    b += row * rhs;
                }
            }
            // A little pull towards the cell centre keeps a pair of parallel planes solvable.
            a += Matrix2::identity() * 1e-6;
            b += Vector2::new(centre.x, centre.y) * 1e-6;
            let xy = a.lu().solve(&b)?;
            Some(Vector3::new(xy.x, xy.y, z))
        }
        None => {
            let mut a = Matrix3::zeros();
            let mut b = Vector3::zeros();
            for l in c {
                let m = rotation * l.edge.normal.into_inner();
                let rc = rotation * l.edge.centre.coords;
                for p in &l.segment {
                    a += m * m.transpose();
                    b += m * m.dot(&(p.coords - rc));
                }
            }
            a += Matrix3::identity() * 1e-6;
            b += centre.coords * 1e-6;
            a.lu().solve(&b)
        }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn masks_select_edges_by_dihedral_range_and_jaccard_prefers_narrow_ranges() {
        // Cumulative masks of one edge whose partners sit at 10°, 30° and 60°.
        let mut le = vec![0u64; BINS];
        for (t, deg) in [(1usize, 10.0f64), (2, 30.0), (3, 60.0)] {
            le[bin(deg.to_radians())] |= 1 << t;
        }
        for b in 1..BINS {
            le[b] |= le[b - 1];
        }
        let r = |a: f64, b: f64| (a.to_radians() as f32, b.to_radians() as f32);
        let tol = 1f64.to_radians() as f32;
        assert_eq!(range_mask(&le, r(25.0, 35.0), tol), 1 << 2);
        assert_eq!(range_mask(&le, r(0.0, 31.0), tol), (1 << 1) | (1 << 2));
        assert_eq!(range_mask(&le, r(40.0, 50.0), tol), 0);
        let d = 30f64.to_radians() as f32;
        assert!(jaccard(d, r(29.0, 31.0), tol) > jaccard(d, r(10.0, 50.0), tol));
        assert_eq!(jaccard(d, r(40.0, 50.0), tol), 0.0);
    }

    #[test]
    fn a_segment_is_in_view_for_the_share_a_sensor_images() {
        // One pinhole looking along rig x, 2 × atan(320 / 686) ≈ 50° wide.
        let rig = Rig::from_toml_str(
            "name = \"one\"\n[[sensors]]\nid = 0\nresolution = [640, 480]\nmodel = \"pinhole\"\n\
             intrinsics = [686.0, 686.0, 319.5, 239.5]\nrotation_wxyz = [0.5, -0.5, 0.5, -0.5]\n\
             translation_m = [0.0, 0.0, 0.0]\n",
            "one.toml",
        )
        .unwrap();
        let view = ViewMap::new(&rig);
        let at = Pose::identity();
        // A horizontal line 3 m ahead from y = −6 to 6: its sampled points at y = ±0.75 lie within
        // ±14° of the axis, those at ±2.25 (37°) and beyond outside.
        let (a, b) = (Point3::new(3.0, -6.0, 0.0), Point3::new(3.0, 6.0, 0.0));
        assert_eq!(in_view(&view, &at, &a, &b, 0xff), 2.0 / 8.0);
        // Hidden points do not count, whatever the sensor would see.
        assert_eq!(in_view(&view, &at, &a, &b, 0b1110_0111), 0.0);
        // Turned half round, the rig sees none of it; a quarter round to the left, none either.
        let turned = |deg: f64| {
            Pose::from_parts(
                Translation3::identity(),
                UnitQuaternion::from_euler_angles(0.0, 0.0, deg.to_radians()),
            )
        };
        assert_eq!(in_view(&view, &turned(180.0), &a, &b, 0xff), 0.0);
        assert_eq!(in_view(&view, &turned(90.0), &a, &b, 0xff), 0.0);
        // Turned 45° to the left (a view from 20° to 70°), the points at y = 2.25, 3.75 and 5.25
        // (37°, 51°, 60°) are on the image and the one at 0.75 (14°) is not.
        assert_eq!(in_view(&view, &turned(45.0), &a, &b, 0xff), 3.0 / 8.0);
    }

    #[test]
    fn wahba_recovers_a_rotation_from_three_normals() {
        let truth = UnitQuaternion::from_euler_angles(0.1, -0.2, 2.0);
        let u = [
            Vector3::new(1.0, 0.2, 0.0).normalize(),
            Vector3::new(0.0, 1.0, 0.3).normalize(),
            Vector3::new(0.3, 0.0, 1.0).normalize(),
        ];
        let v = u.map(|x| truth * x);
        let (q, res) = wahba(&u, &v, 1.0).unwrap();
        assert!(q.angle_to(&truth) < 1e-9 && res < 1e-18);
        let up = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), -1.3);
        let (q, _) = yaw_fit(&u, &u.map(|x| up * x), 1.0);
        assert!(q.angle_to(&up) < 1e-12);
    }
}
