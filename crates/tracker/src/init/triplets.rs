//! INIT-SEGMENT-EDGE (Koch–Teller §4.1, Figure 4) over one cell of the prior visibility grid:
//! the frame's strongest edges and the cell's longest segments, their dihedral angles, the
//! triplet matches indexed by sorted pairs and 64-bit masks, and the random samples of three
//! matched lines whose poses are kept for polishing (the parent module's doc, steps 1–4 and
//! "Indexing instead of brute force").
//!
//! In: the frame's edges (once per frame), a cell (a node of the table) and its scratch, the
//! search volume, a generator. Out: the cell's best sample poses in its scratch pool, and the
//! counts of triplets and samples tried.

use super::{
    keep_best, layer_half_height, nearest_layer_z, CellScratch, Initialiser, SearchVolume, BINS, BIN_RAD,
    KEEP_PER_CELL, VOTE_EDGES,
};
use crate::matching::{best_edge, correspondence, Gate, Predicted};
use nalgebra::{Point3, Translation3, Vector2, Vector3};
use omnitrack_core::geometry::{Correspondence, Pose};
use omnitrack_edges::Edge;
use omnitrack_solver::minimal::{translation_given_rotation, wahba, yaw_fit};
use omnitrack_solver::{r_and_t_refine, refine_upright};
use rand::rngs::SmallRng;
use rand::Rng;

impl Initialiser<'_> {
    /// ℰ: the strongest edges of sufficient length, their dihedral angles, masks and sorted pairs.
    pub(super) fn prepare_edges(&mut self, edges: &[Edge]) {
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
            // Never full: at most VOTE_EDGES are taken.
            let _ = self.vote_edges.push(edges[i as usize]);
        }
        self.vote_index.build(&self.vote_edges);
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
    pub(super) fn select_plan_cells(&mut self, volume: &SearchVolume) {
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
    pub(super) fn cell_gap(&self, at: &Point3<f64>, node: u32) -> Option<f64> {
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
    pub(super) fn nearest_node_gap(&self, at: &Point3<f64>) -> Option<f64> {
        (0..self.table.node_count() as u32)
            .filter_map(|node| self.cell_gap(at, node))
            .min_by(f64::total_cmp)
    }

    /// The nodes whose cells meet the volume, nearest first (one layer when upright).
    pub(super) fn select_cells(&mut self, volume: &SearchVolume) {
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
    pub(super) fn cell_points(&self, node: u32, out: &mut [Point3<f64>; 9]) -> usize {
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
    pub(super) fn score_cell(&self, w: &mut CellScratch, node: u32) -> u64 {
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
    pub(super) fn sample_cell(
        &self,
        w: &mut CellScratch,
        node: u32,
        volume: &SearchVolume,
        rng: &mut SmallRng,
    ) -> (u64, u64) {
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
    pub(super) fn sample_pose(
        &self,
        w: &mut CellScratch,
        pick: &[(usize, usize); 3],
        centre: &Point3<f64>,
    ) -> Option<Pose> {
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
    pub(super) fn fit(&self, corr: &[Correspondence], start: &Pose) -> Option<Pose> {
        match self.opts.upright_height_m {
            Some(_) => refine_upright(corr, start, &self.solver),
            None => r_and_t_refine(corr, start, &self.solver),
        }
    }

    /// Truncated ξ of a sample's pose over the cell's segments and the frame's top edges (a
    /// loose cap: the sample's pose is not refined yet).
    pub(super) fn loose_score(&self, w: &CellScratch, pose: &Pose) -> f64 {
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
}

/// Angle (rad, [0, π/2]) between two planes given their unit normals.
#[inline]
pub(super) fn dihedral(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    a.cross(b).norm().atan2(a.dot(b).abs())
}

#[inline]
pub(super) fn dihedral_v(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    dihedral(a, b)
}

#[inline]
pub(super) fn bin(d: f64) -> usize {
    ((d / BIN_RAD).floor().max(0.0) as usize).min(BINS - 1)
}

/// Edges whose dihedral angle with the mask's edge lies in `range` ± `tol` (conservative to the
/// bin; the exact test is the overlap score).
#[inline]
pub(super) fn range_mask(le: &[u64], range: (f32, f32), tol: f32) -> u64 {
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
pub(super) fn jaccard(d: f32, range: (f32, f32), tol: f32) -> f32 {
    let inter = (d + tol).min(range.1) - (d - tol).max(range.0);
    if inter <= 0.0 {
        return 0.0;
    }
    let union = (d + tol).max(range.1) - (d - tol).min(range.0);
    inter / union
}

pub(super) fn weighted_index(weights: &[f64], total: f64, rng: &mut SmallRng) -> usize {
    let mut x = rng.random_range(0.0..total);
    for (i, w) in weights.iter().enumerate() {
        if x < *w {
            return i;
        }
        x -= w;
    }
    weights.len() - 1
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
}
