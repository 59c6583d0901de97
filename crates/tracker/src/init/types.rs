//! What a search is given and what it gives back: its options ([`InitOptions`], from
//! tracker.toml), the volume to search ([`SearchVolume`]), the poses it finds ([`Candidate`],
//! ranked by [`Candidate::merit`]) and the account of its work ([`InitReport`]).
//!
//! In: the tracker's configuration. Out: plain data.

use nalgebra::Point3;
use omnitrack_config::{GridBlank, TrackerConfig};
use omnitrack_core::geometry::Pose;
use omnitrack_core::status::SearchState;
use std::time::Duration;

/// Tunables of [`Initialiser`](super::Initialiser) (from tracker.toml `[initialisation]` and the noise model).
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
    /// The work the whole run may do, in reference time (module [`work`](super::work); anytime: the cells
    /// nearest the centre come first).
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
    /// The most segments [`Initialiser::set_breadth`](super::Initialiser::set_breadth) may ask for (buffers are sized for it).
    pub wide_segments_considered: usize,
    /// Samples whose rig z axis is further than this from the world's up are dropped (rad;
    /// π keeps every sample).
    pub max_tilt_rad: f64,
    /// The rig centre's height above the floor beneath it (m): poses outside are refused.
    pub height_above_floor_m: [f64; 2],
    /// [`Candidate::blank`]'s radius (rad; 0 = off).
    pub blank_radius_rad: f64,
    /// Which searches' grids rank by the blank share too (`initialisation.grid_blank`).
    pub grid_blank: GridBlank,
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
            grid_blank: i.grid_blank,
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

/// What one [`Initialiser::run`](super::Initialiser::run) did.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct InitReport {
    pub cells_in_volume: usize,
    pub cells_searched: usize,
    pub triplet_matches: u64,
    pub samples: u64,
    pub elapsed: Duration,
    /// The work budget ran out before everything in the volume was searched.
    pub timed_out: bool,
    /// Work units spent (module [`work`](super::work)).
    pub work: u64,
    /// The wall clock stopped the search at [`BACKSTOP_FACTOR`](super::BACKSTOP_FACTOR) × its budget before the work
    /// budget did: the answer then depends on the machine's speed and load.
    pub backstop: bool,
    /// Samples dropped because the rig would be tilted further than `max_tilt_rad` allows.
    pub tilted: u64,
    /// Of `elapsed`, the grid search under the vanishing directions' rotations (with its
    /// climbs and polishes), and how many rotations it had.
    pub grid_elapsed: Duration,
    pub rotations: usize,
    /// Of `work`, what the grid's scan of its lattice spent (module `grid_scan`), and the
    /// lattice positions it scored.
    pub scan_work: u64,
    pub positions_scored: u64,
    /// The grid's best positions climbed and polished.
    pub climbed: usize,
    /// The volume held no valid node: the diameter (m) of the volume actually searched, about
    /// the same centre, out to the nearest valid nodes (`None`: the volume as given).
    pub widened_to_m: Option<f64>,
    /// The diameter (m) of the volume searched (`None`: the whole model).
    pub diameter_m: Option<f64>,
    /// The grid search's plan cells (those of the table's grid meeting the volume) and how
    /// many of them it looked at before its share of the budget was spent: every position of
    /// a cell looked at was scored. In a whole-model search, the cells looked at by all its
    /// lanes: some may lie beyond [`Self::swept_to_m`].
    pub plan_cells_in_volume: usize,
    pub plan_cells_scanned: usize,
    /// Of the volume's plan cells, those nearer its centre than [`Initialiser::set_sweep_from`](super::Initialiser::set_sweep_from)
    /// (looked at by earlier searches of a sweep) and skipped by this one.
    pub plan_cells_skipped: usize,
    /// How far from the centre (m, in plan) the cells looked at by now reach: the distance of
    /// the nearest cell not yet looked at, where the next search of a sweep starts (the whole
    /// model's lanes stop at different distances: from the nearest cell any of them left, so
    /// that a sweep looks at some cells twice rather than skip one). `None`: every cell of the
    /// volume has been looked at.
    pub swept_to_m: Option<f64>,
    /// A cancel flag ([`Initialiser::add_cancel`](super::Initialiser::add_cancel)) stopped the
    /// search before its work budget was spent: its candidates may not have met their rivals,
    /// and a tracker commits none of them.
    pub cancelled: bool,
}

impl InitReport {
    /// What the search made of its volume, as the status message carries it: no cell at all,
    /// widened to the nearest valid nodes ([`InitReport::widened_to_m`]), or as given.
    pub fn search_state(&self) -> SearchState {
        match self.widened_to_m {
            _ if self.cells_in_volume == 0 => SearchState::NoCells,
            Some(_) => SearchState::Widened,
            None => SearchState::AsGiven,
        }
    }
}
