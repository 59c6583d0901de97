//! The translation searches that go past the paper (the parent module's doc, "Translation by
//! voting" and "Rotation from vanishing directions, translation by a grid"): under a few
//! rotations, positions on a grid over the search volume scored by coverage (the scan itself
//! in module `grid_scan`) and climbed, and positions voted by the vertical edge planes.
//!
//! In: the frame's edges, the search volume or a centre and diameter, the rotations to try, a
//! work budget. Out: polished candidates offered to the initialiser's list, and what the grid's
//! scan covered.

use super::grid_scan::{GridLattice, GridSweep};
use super::work;
use super::{
    layer_half_height, Initialiser, SearchVolume, CLIMB, GRID_GATE_RAD, GRID_KEEP, GRID_SEGMENTS, GRID_SHARE,
    GRID_STEP_M, GRID_WORTH, HEIGHT_STEP_M, SAME_ROTATION_RAD, VOTED_CANDIDATES, VOTED_ROTATIONS,
};
use crate::matching::Gate;
use crate::vanishing::MAX_ROTATIONS;
use crate::vote::{Grid, PEAKS};
use nalgebra::{Point3, Translation3, UnitQuaternion, Vector3};
use omnitrack_core::geometry::Pose;
use omnitrack_edges::Edge;

impl Initialiser<'_> {
    /// Module `vote`: under the rotations of the best candidates so far (and their quarter
    /// turns about the vertical when `yaw_twins`), the translations most edges agree on, each
    /// polished into a candidate. Within the work budget `limit`.
    pub(super) fn vote_translations(&mut self, edges: &[Edge], centre: &Point3<f64>, diameter: f64, limit: u64) {
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
            if self.spent(limit) {
                return;
            }
            let found = self.vote.run(self.model, &self.vote_edges, r, &grid, &mut peaks);
            self.spend(work::VOTE_PER_EDGE * self.vote_edges.len() as u64);
            for &(_, peak) in &peaks[..found] {
                if self.spent(limit) {
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
                    self.spend(work::SCORE);
                    if score < best_z.0 {
                        best_z = (score, z);
                    }
                }
                start.translation.vector.z = best_z.1;
                if let Some(c) = self.polish(&start, edges) {
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
    /// translation is three numbers, few enough to search outright. The scan spends at most
    /// [`GRID_SHARE`] of the work budget `limit`, the climbs and polishes the rest. Returns the
    /// plan cells looked at (every position scored) and those meeting the volume.
    pub(super) fn grid_search(&mut self, edges: &[Edge], volume: &SearchVolume, limit: u64) -> GridSweep {
        let scan_limit = (GRID_SHARE * limit as f64) as u64;
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
        self.select_plan_cells(volume);
        let grid = GridLattice {
            half,
            step,
            steps,
            slab: [slab_lo, slab_hi],
            band: [band_lo, band_hi],
            gate: Gate::geometric(GRID_GATE_RAD),
            min_len: 3.0 * self.opts.min_length_rad,
        };
        // (Looking at every cell on a coarser lattice first and refining the most promising
        // was tried, and committed more twins: docs/decisions.md.)
        let first = self.plan_cells.partition_point(|c| c.0 < self.sweep_from_m);
        let sweep = self.scan_grid(&grid, volume, first, scan_limit);
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
            if self.spent(limit) {
                break;
            }
            let (ri, k) = (usize::from(ri), usize::from(k));
            let start = self.climb(
                &Pose::from_parts(
                    Translation3::from(self.grid_best[ri][k].1.coords),
                    self.vanishing_rot[ri],
                ),
                grid.min_len,
            );
            self.climbed += 1;
            if let Some(c) = self.polish(&start, edges) {
                self.offer(c);
            }
        }
        sweep
    }

    /// Coordinate ascent of the coarse merit ([`Self::coarse_merit`]) from `start` in x, y and
    /// z, in the steps and gates of [`CLIMB`].
    pub(super) fn climb(&mut self, start: &Pose, min_len: f64) -> Pose {
        let mut pose = *start;
        // The segments in sight from the start: the climb moves a few decimetres at most.
        self.longest_in_sight(&Point3::from(start.translation.vector), usize::MAX);
        let segs = std::mem::take(&mut self.grid_segs);
        for (step, gate_rad) in CLIMB {
            let gate = Gate::geometric(gate_rad);
            // A step is taken only to a better score: one that cannot beat `floor` is not
            // worked out in full.
            let score =
                |me: &mut Self, p: &Pose, floor: f64| me.coarse_merit(p, &segs, &gate, min_len, floor).unwrap_or(0.0);
            let mut best = score(self, &pose, f64::NEG_INFINITY);
            for _ in 0..4 {
                let mut moved = false;
                for axis in 0..3 {
                    for sign in [-1.0, 1.0] {
                        let mut p = pose;
                        p.translation.vector[axis] += sign * step;
                        let s = score(self, &p, best);
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

    /// The grid's kept positions of the last [`Self::run`] as poses under their rotations, with
    /// their coarse merits (for diagnosis: whether the truth's neighbour was among them).
    pub fn grid_kept(&self) -> impl Iterator<Item = (f64, Pose)> + '_ {
        self.grid_best[..self.vanishing_count]
            .iter()
            .zip(&self.vanishing_rot)
            .flat_map(|(best, r)| {
                best.iter()
                    .map(move |b| (b.0, Pose::from_parts(Translation3::from(b.1.coords), *r)))
            })
    }

    /// The grid's coarse merit of `pose` against the edges of the last [`Self::run`] (for
    /// diagnosis: how a pose the grid never kept would have fared).
    pub fn grid_merit(&mut self, pose: &Pose) -> Option<f64> {
        let gate = Gate::geometric(GRID_GATE_RAD);
        self.longest_in_sight(&Point3::from(pose.translation.vector), GRID_SEGMENTS);
        let segs = std::mem::take(&mut self.grid_segs);
        let merit = self.coarse_merit(pose, &segs, &gate, 3.0 * self.opts.min_length_rad, f64::NEG_INFINITY);
        self.grid_segs = segs;
        merit
    }

    /// `self.grid_segs` ← the `keep` longest (by the angle they span in sight) of the segments
    /// in sight from `at` (all of them for `usize::MAX`). Charged with the rays it cast
    /// ([`Self::spend`]): on a detailed model a query costs many times a plain one's.
    pub(super) fn longest_in_sight(&mut self, at: &Point3<f64>, keep: usize) {
        self.grid_segs.clear();
        if keep == usize::MAX {
            let seen = self.at_pose.at(self.model, self.table, at);
            for s in seen {
                if self.grid_segs.len() < self.grid_segs.capacity() {
                    self.grid_segs.push(*s);
                }
            }
        } else {
            let mut order = std::mem::take(&mut self.grid_order);
            self.at_pose.widest(self.model, self.table, at, keep, &mut order);
            self.grid_segs.extend(order.iter().map(|o| o.1));
            self.grid_order = order;
        }
        self.spend(work::SIGHT);
    }
}
