//! The translation searches that go past the paper (the parent module's doc, "Translation by
//! voting" and "Rotation from vanishing directions, translation by a grid"): under a few
//! rotations, positions on a grid over the search volume scored by coverage and climbed, and
//! positions voted by the vertical edge planes.
//!
//! In: the frame's edges, the search volume or a centre and diameter, the rotations to try, a
//! work budget. Out: polished candidates offered to the initialiser's list.

use super::scoring::length_share;
use super::work;
use super::{
    layer_half_height, GridBest, Initialiser, SearchVolume, CLIMB, FULL_COVER, GRID_GATE_RAD, GRID_KEEP, GRID_SEGMENTS,
    GRID_SHARE, GRID_STEP_M, GRID_WORTH, HEIGHT_STEP_M, SAME_POSITION_M, SAME_ROTATION_RAD, VOTED_CANDIDATES,
    VOTED_ROTATIONS,
};
use crate::edge_index::EdgeIndex;
#[cfg(debug_assertions)]
use crate::matching::best_edge_and_cover;
use crate::matching::{gated_cover, Gate, Predicted};
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
        let gate = Gate::geometric(GRID_GATE_RAD);
        let min_len = 3.0 * self.opts.min_length_rad;
        for best in &mut self.grid_best {
            best.clear();
        }
        self.select_plan_cells(volume);
        let grid = GridLattice {
            half,
            step,
            slab: [slab_lo, slab_hi],
            band: [band_lo, band_hi],
        };
        // Plan cells nearest first, every rotation at each: the budget cuts the far cells of
        // all rotations alike, never a whole rotation. Every cell of the table's grid is
        // searched, whether or not its node is valid: a closet or a hallway narrower than the
        // node spacing often has its node inside a wall, and the rig can still stand there.
        // (Looking at every cell on a coarser lattice first and refining the most promising
        // was tried, and committed more twins: docs/decisions.md.)
        let first = self.plan_cells.partition_point(|c| c.0 < self.sweep_from_m);
        let mut scanned = first;
        'cells: for ci in first..self.plan_cells.len() {
            let centre = self.plan_cells[ci].1;
            for ix in 0..steps {
                for iy in 0..steps {
                    if self.spent(scan_limit) {
                        break 'cells;
                    }
                    self.grid_position(&grid, &centre, ix, iy, volume, &gate, min_len);
                }
            }
            scanned = ci + 1;
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
            if self.spent(limit) {
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
            if let Some(c) = self.polish(&start, edges) {
                self.offer(c);
            }
        }
        GridSweep {
            in_volume: self.plan_cells.len(),
            skipped: first,
            scanned: scanned - first,
            next_m: self.plan_cells.get(scanned).map(|c| c.0),
        }
    }

    /// The grid's position (`ix`, `iy`) of the plan cell about `centre`: its heights (inside the
    /// band above the floor beneath, the known height when upright, the whole slab in a model
    /// without floors) and the vanishing directions' rotations scored by
    /// [`Self::coarse_merit`] over the [`GRID_SEGMENTS`] longest segments in sight from the
    /// middle of its heights, each kept among its rotation's best.
    #[allow(clippy::too_many_arguments)]
    fn grid_position(
        &mut self,
        grid: &GridLattice,
        centre: &Point3<f64>,
        ix: usize,
        iy: usize,
        volume: &SearchVolume,
        gate: &Gate,
        min_len: f64,
    ) {
        let (x, y) = (
            centre.x - grid.half + (ix as f64 + 0.5) * grid.step,
            centre.y - grid.half + (iy as f64 + 0.5) * grid.step,
        );
        let Some((z_lo, z_hi)) = self.heights_at(x, y, grid) else {
            return;
        };
        let inside = |p: &Point3<f64>| volume.diameter_m.is_none_or(|d| (p - volume.centre).norm() <= 0.5 * d);
        let plan = Point3::new(x, y, 0.5 * (z_lo + z_hi));
        let (lo, hi) = (Point3::new(x, y, z_lo), Point3::new(x, y, z_hi));
        if !inside(&lo) && !inside(&hi) && !inside(&plan) {
            return;
        }
        // The longest segments in sight from the middle of the heights: a bounded cost per
        // position, and the lines that decide where the rig is.
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
                if let Some(score) = self.coarse_merit(&pose, &segs, gate, min_len) {
                    keep_best_apart(&mut self.grid_best[ri], (score, p));
                }
            }
        }
        self.grid_segs = segs;
    }

    /// The lattice's heights at plan position (`x`, `y`): the band above the floor beneath (none
    /// outside the building), the known height when upright, the table's slab in a model
    /// without floors.
    fn heights_at(&self, x: f64, y: f64, grid: &GridLattice) -> Option<(f64, f64)> {
        let (lo, hi) = match self.opts.upright_height_m {
            Some(z) => (z, z),
            None if self.floors.any() => self.floors.band(x, y, grid.slab, grid.band, self.at_pose.solid())?,
            None => (grid.slab[0], grid.slab[1]),
        };
        (lo <= hi).then_some((lo, hi))
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
    /// in sight from `at` (all of them for `usize::MAX`). Charged with the rays it cast
    /// ([`Self::spend`]): on a detailed model a query costs many times a plain one's.
    pub(super) fn longest_in_sight(&mut self, at: &Point3<f64>, keep: usize) {
        self.grid_segs.clear();
        if keep == usize::MAX {
            let seen = self.at_pose.at(self.model, self.table, at);
            for s in seen {
                if self.grid_segs.len() < self.grid_segs.capacity() {
                    self.grid_segs.push(s.segment);
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

    /// [`Candidate::merit`] at a coarse gate, for the grid: of `segments`, those at least
    /// `min_len` long at `pose`, the share the frame's longest edges cover within `gate` (each up
    /// to [`FULL_COVER`]), times the share (by angle) of those edges (the [`VOTE_EDGES`] longest)
    /// that one of them explains within `gate`. `None` if fewer than six segments are that long.
    ///
    /// The support is over all the vote's edges rather than the few dozen longest, as the final
    /// [`Candidate::support`] is over all edges: measured on the ZInD panoramas (docs/decisions.md), the
    /// 64 longest let the grid drop the truth in favour of poses along texture (3 m hint: 20 of
    /// 32 within 10 cm with 64, 24 with all 256).
    pub(super) fn coarse_merit(&mut self, pose: &Pose, segments: &[u32], gate: &Gate, min_len: f64) -> Option<f64> {
        let (mut explained, mut counted) = (0.0, 0usize);
        self.vote_explained[..self.vote_edges.len()].fill(false);
        self.support_pred.clear();
        for &s in segments {
            let seg = &self.model.segments[s as usize];
            let pred = Predicted::new(&[seg.a, seg.b], pose, &self.centres);
            if pred.length_rad < min_len {
                continue;
            }
            counted += 1;
            let cover = cover_near(
                &pred,
                &self.centres,
                &self.vote_edges,
                &mut self.vote_index,
                gate,
                &mut self.vote_explained,
            );
            if let Some(cover) = cover {
                explained += (cover / FULL_COVER).min(1.0);
            }
            // Kept only for the debug builds' check against all pairs below.
            if cfg!(debug_assertions) && self.support_pred.len() < self.support_pred.capacity() {
                self.support_pred.push(pred);
            }
        }
        let marks = &self.vote_explained[..self.vote_edges.len()];
        let support = (counted >= 6).then(|| length_share(self.vote_edges.iter(), self.centres.len(), |k, _| marks[k]));
        // Debug builds (the tests) check one score in 16 against every pair, as the scores were
        // computed before the index.
        self.merit_calls = self.merit_calls.wrapping_add(1);
        #[cfg(debug_assertions)]
        if let Some(support) = support.filter(|_| self.merit_calls % 16 == 1 && self.support_pred.len() == counted) {
            let mut all = 0.0;
            for &s in segments {
                let seg = &self.model.segments[s as usize];
                let pred = Predicted::new(&[seg.a, seg.b], pose, &self.centres);
                if pred.length_rad >= min_len {
                    if let (Some(_), cover) = best_edge_and_cover(&pred, &self.centres, &self.vote_edges, gate) {
                        all += (cover / FULL_COVER).min(1.0);
                    }
                }
            }
            let plain = self.predicted_support(self.vote_edges.iter(), gate.cos_alpha);
            debug_assert!(
                (all - explained).abs() < 1e-9,
                "explained {explained} by the index, {all} by all pairs"
            );
            debug_assert!(
                (plain - support).abs() < 1e-12,
                "support {support} by the index, {plain} by all pairs"
            );
        }
        self.spend(segments.len() as u64 * self.vote_edges.len() as u64 / 100 * work::MERIT_PER_SEGMENT_100_EDGES);
        Some(explained / counted as f64 * support?)
    }
}

/// [`best_edge_and_cover`]'s cover of `pred` over the edges of `index` (built from `edges`)
/// that can pass the gate: `None` if no edge passes it. Every edge that passes is marked in
/// `explained`: the support's test (plane within the gate, overlapping by half) is the cover's.
fn cover_near(
    pred: &Predicted,
    centres: &[Point3<f64>],
    edges: &[Edge],
    index: &mut EdgeIndex,
    gate: &Gate,
    explained: &mut [bool],
) -> Option<f64> {
    let mut covered = 0.0;
    let mut any = false;
    for (s, c) in centres.iter().enumerate() {
        let n = &pred.normals[s];
        index.near(s, n, gate.cos_alpha, |i| {
            if let Some((_, share)) = gated_cover(pred, c, n, &edges[i], gate) {
                covered += share;
                any = true;
                explained[i] = true;
            }
        });
    }
    any.then_some(covered.min(1.0))
}

/// The grid search's lattice in each plan cell: half the node spacing and the step between its
/// positions (m), the table's slab of heights and the height band above a floor (m).
struct GridLattice {
    half: f64,
    step: f64,
    slab: [f64; 2],
    band: [f64; 2],
}

/// What the grid's scan of a volume's plan cells (nearest first) covered: the cells meeting
/// the volume, those skipped as an earlier search of the sweep's, those scored now, and the
/// distance (m, in plan) of the first cell not looked at (`None`: the volume is covered).
pub(super) struct GridSweep {
    pub in_volume: usize,
    pub skipped: usize,
    pub scanned: usize,
    pub next_m: Option<f64>,
}

/// Keeps `entry` (score, position; highest score best) among the best [`GRID_KEEP`] that are at
/// least [`SAME_POSITION_M`] apart: a better neighbour replaces a worse one.
pub(super) fn keep_best_apart(best: &mut GridBest, entry: (f64, Point3<f64>)) {
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
