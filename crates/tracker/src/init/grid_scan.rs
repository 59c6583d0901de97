//! The grid's scan (the parent module's doc, "Rotation from vanishing directions, translation
//! by a grid"): every position of the lattice over the volume's plan cells, nearest cell first,
//! scored under each of the vanishing directions' rotations by the coarse merit and kept among
//! its rotation's best few.
//!
//! In: the plan cells (nearest first) from the first one a sweep has not looked at, the
//! lattice, the frame's vote edges and their index, the rotations, the scan's share of the work
//! budget. Out: per rotation the best [`GRID_KEEP`](super::GRID_KEEP) positions (`Initialiser::grid_best`), the
//! work charged, and the [`GridSweep`]: cells scanned and where the next search of a sweep
//! resumes.
//!
//! **Lanes.** The plan cells are dealt out as the triplets' cells are: cell k (nearest first)
//! to lane k mod the lanes' count ([`VOLUME_LANES`] for a bounded volume, [`LANES`] for the whole
//! model, three quarters of a search without a hint), each lane with its own buffers
//! ([`GridLane`]) and an equal share of the scan's budget in the reference machine's time
//! (module `lanes`: the lanes run side by side on the search's thread and its helpers). Each
//! lane's scores and keep-best lists depend only on the cells dealt to it, and the lists are
//! merged in lane order, so the answer depends neither on the number of cores nor on how the
//! threads were scheduled. The lanes stop at different distances: the sweep resumes from the
//! nearest cell some lane left unscanned, so cells are looked at twice rather than skipped.
//!
//! Fixed memory: each lane's buffers are sized in `Initialiser::new`, the helper threads started
//! there; a scan allocates nothing.

use super::scoring::length_share;
#[cfg(debug_assertions)]
use super::scoring::support_of;
use super::{
    charge_of_lanes, lane_share, work, GridBest, Initialiser, SearchVolume, FULL_COVER, GRID_SEGMENTS, LANES,
    VOLUME_LANES, VOTE_EDGES,
};
use crate::edge_index::{EdgeIndex, Reach};
#[cfg(debug_assertions)]
use crate::matching::best_edge_and_cover;
use crate::matching::{Gate, Predicted, SegmentArc, MAX_SENSORS};
use crate::vanishing::MAX_ROTATIONS;
use crate::visibility::at_pose::{sample_point, SeenSegment, SightBuffers, SAMPLES};
use nalgebra::{Point3, Translation3};
use omnitrack_core::geometry::Pose;
use omnitrack_core::memory::resident;
use omnitrack_core::model::Model;
use omnitrack_edges::Edge;
use std::time::Instant;

/// The scratch of one coarse merit ([`Initialiser::merit_with`]).
pub(super) struct MeritScratch {
    /// Per vote edge: explained by a predicted segment.
    explained: [bool; VOTE_EDGES],
    /// The predicted segments, kept in debug builds only for the check against all pairs.
    predicted: Vec<Predicted>,
    /// Which of the segments scored were long enough to count (indices into them).
    counted: Vec<u32>,
    /// Calls so far (debug builds check some against all pairs).
    calls: u64,
}

impl MeritScratch {
    /// For scores over at most `segments` segments (the debug builds' check needs them all).
    pub(super) fn new(segments: usize) -> MeritScratch {
        MeritScratch {
            explained: [false; VOTE_EDGES],
            predicted: Vec::with_capacity(if cfg!(debug_assertions) { segments } else { 0 }),
            counted: resident(Vec::with_capacity(segments)),
            calls: 0,
        }
    }
}

impl Default for MeritScratch {
    fn default() -> Self {
        MeritScratch::new(0)
    }
}

/// One lane of the scan: its buffers, its best positions and its account.
pub(super) struct GridLane {
    sight: SightBuffers,
    order: Vec<(f64, SeenSegment)>,
    segs: Vec<SeenSegment>,
    merit: MeritScratch,
    /// Per rotation, the lane's best positions (score, position).
    best: [GridBest; MAX_ROTATIONS],
    /// Work charged, the part of it told to the search's progress, and the lane's rays
    /// already charged.
    work: u64,
    said: u64,
    rays_charged: u64,
    /// Cells whose every position was scored, and the first of the lane's cells that was not
    /// (`None`: all of them were).
    scanned: usize,
    positions: u64,
    resume: Option<usize>,
    /// The wall clock's backstop or a cancellation stopped the lane.
    backstop: bool,
}

impl GridLane {
    pub(super) fn new(model: &Model) -> GridLane {
        GridLane {
            sight: SightBuffers::new(model),
            order: resident(Vec::with_capacity(GRID_SEGMENTS)),
            segs: resident(Vec::with_capacity(GRID_SEGMENTS)),
            merit: MeritScratch::new(GRID_SEGMENTS),
            best: std::array::from_fn(|_| GridBest::new()),
            work: 0,
            said: 0,
            rays_charged: 0,
            scanned: 0,
            positions: 0,
            resume: None,
            backstop: false,
        }
    }

    /// Occlusion rays cast in this lane since it was made.
    pub(super) fn rays_cast(&self) -> u64 {
        self.sight.rays_cast()
    }

    /// Charges a step, as [`Initialiser::spend`] does: `units`, or the rays cast since the
    /// last charge if they come to more.
    fn spend(&mut self, units: u64) {
        let rays = self.sight.rays_cast();
        let cast = rays.saturating_sub(self.rays_charged) / work::RAYS_PER_UNIT;
        self.rays_charged = rays;
        self.work = self.work.saturating_add(units.max(cast));
    }
}

/// The grid search's lattice in each plan cell: half the node spacing, the step between its
/// positions (m) and their count along x and y, the table's slab of heights and the height
/// band above a floor (m); the scores' gate and the shortest segment they count (rad).
pub(super) struct GridLattice {
    pub half: f64,
    pub step: f64,
    pub steps: usize,
    pub slab: [f64; 2],
    pub band: [f64; 2],
    pub gate: Gate,
    pub min_len: f64,
}

/// What the grid's scan of a volume's plan cells (nearest first) covered: the cells meeting
/// the volume, those skipped as an earlier search of the sweep's, those scored now (in all
/// lanes), and the distance (m, in plan) of the nearest cell not looked at (`None`: the volume
/// is covered).
pub(super) struct GridSweep {
    pub in_volume: usize,
    pub skipped: usize,
    pub scanned: usize,
    pub next_m: Option<f64>,
    /// The work the scan charged, and the lattice positions it scored.
    pub work: u64,
    pub positions: u64,
}

impl Initialiser<'_> {
    /// Scores the lattice's positions of the plan cells from `first` on (nearest first) within
    /// `scan_limit` work units in all (what the run has spent included), into
    /// `self.grid_best`: in [`VOLUME_LANES`] lanes for a bounded volume, in [`LANES`] for the
    /// whole model.
    pub(super) fn scan_grid(
        &mut self,
        grid: &GridLattice,
        volume: &SearchVolume,
        first: usize,
        scan_limit: u64,
    ) -> GridSweep {
        let lanes = if volume.diameter_m.is_none() {
            LANES
        } else {
            VOLUME_LANES
        };
        let lane_limit = lane_share(scan_limit.saturating_sub(self.work), lanes);
        let mut all = std::mem::take(&mut self.grid_lanes);
        let used = &mut all[..lanes];
        for lane in used.iter_mut() {
            for best in &mut lane.best {
                best.clear();
            }
            lane.work = 0;
            lane.said = 0;
            lane.rays_charged = lane.sight.rays_cast();
            lane.scanned = 0;
            lane.positions = 0;
            lane.resume = None;
            lane.backstop = false;
        }
        let me = &*self;
        me.on_threads(used, |k, lane| {
            me.scan_lane(lane, grid, volume, first + k, lanes, lane_limit)
        });
        // In lane order, so that the lists do not depend on the threads.
        let mut sweep = GridSweep {
            in_volume: self.plan_cells.len(),
            skipped: first,
            scanned: 0,
            next_m: None,
            work: 0,
            positions: 0,
        };
        let mut resume = None::<usize>;
        let mut lanes_work = 0;
        self.grid_best = used[0].best.clone();
        for (k, lane) in used.iter().enumerate() {
            if k > 0 {
                for (into, from) in self.grid_best.iter_mut().zip(&lane.best) {
                    for &entry in from {
                        keep_best_apart(into, entry);
                    }
                }
            }
            sweep.scanned += lane.scanned;
            resume = match (resume, lane.resume) {
                (Some(a), Some(b)) => Some(a.min(b)),
                (a, b) => a.or(b),
            };
            lanes_work += lane.work;
            sweep.positions += lane.positions;
            self.backstop_hit |= lane.backstop;
        }
        sweep.work = charge_of_lanes(lanes_work, lanes);
        self.work = self.work.saturating_add(sweep.work);
        sweep.next_m = resume.map(|ci| self.plan_cells[ci].0);
        self.grid_lanes = all;
        sweep
    }

    /// One lane: the plan cells `first`, `first + stride`, … until the lane has spent `limit`.
    fn scan_lane(
        &self,
        lane: &mut GridLane,
        grid: &GridLattice,
        volume: &SearchVolume,
        first: usize,
        stride: usize,
        limit: u64,
    ) {
        // Plan cells nearest first, every rotation at each: the budget cuts the far cells of
        // all rotations alike, never a whole rotation. Every cell of the table's grid is
        // searched, whether or not its node is valid: a closet or a hallway narrower than the
        // node spacing often has its node inside a wall, and the rig can still stand there.
        for ci in (first..self.plan_cells.len()).step_by(stride) {
            let centre = self.plan_cells[ci].1;
            for ix in 0..grid.steps {
                for iy in 0..grid.steps {
                    if self.lane_spent(lane, limit, stride) {
                        lane.resume = Some(ci);
                        return;
                    }
                    self.grid_position(lane, grid, &centre, ix, iy, volume);
                }
            }
            lane.scanned += 1;
        }
    }

    /// Whether `lane` (of `lanes`) has spent `limit`, or the wall clock's backstop has fallen
    /// or the search was cancelled: checked in every lane, so that none runs on after the
    /// others stop.
    fn lane_spent(&self, lane: &mut GridLane, limit: u64, lanes: usize) -> bool {
        self.progress.add_work(charge_of_lanes(lane.work - lane.said, lanes));
        lane.said = lane.work;
        if lane.work >= limit {
            return true;
        }
        if Instant::now() >= self.backstop || self.cancelled() {
            lane.backstop = true;
            return true;
        }
        false
    }

    /// The grid's position (`ix`, `iy`) of the plan cell about `centre`: its heights (inside the
    /// band above the floor beneath, the known height when upright, the whole slab in a model
    /// without floors) and the vanishing directions' rotations scored by
    /// [`Self::merit_with`] over the [`GRID_SEGMENTS`] longest segments in sight from the
    /// middle of its heights, each kept among its rotation's best.
    fn grid_position(
        &self,
        lane: &mut GridLane,
        grid: &GridLattice,
        centre: &Point3<f64>,
        ix: usize,
        iy: usize,
        volume: &SearchVolume,
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
        self.at_pose.widest_with(
            &mut lane.sight,
            self.model,
            self.table,
            &plan,
            GRID_SEGMENTS,
            &mut lane.order,
        );
        lane.segs.clear();
        lane.segs.extend(lane.order.iter().map(|o| o.1));
        lane.spend(work::SIGHT);
        lane.positions += 1;
        let mut z = z_lo;
        while z <= z_hi + 1e-9 {
            let p = Point3::new(x, y, z);
            z += super::GRID_STEP_M;
            if !inside(&p) {
                continue;
            }
            for ri in 0..self.vanishing_count {
                let pose = Pose::from_parts(Translation3::from(p.coords), self.vanishing_rot[ri]);
                // Below the least of a full list, a position cannot enter it.
                let best = &lane.best[ri];
                let floor = match best.is_full() {
                    true => best.iter().map(|b| b.0).fold(f64::INFINITY, f64::min),
                    false => f64::NEG_INFINITY,
                };
                let (merit, charge) =
                    self.merit_with(&mut lane.merit, &pose, &lane.segs, &grid.gate, grid.min_len, floor);
                lane.spend(charge);
                if let Some(score) = merit {
                    keep_best_apart(&mut lane.best[ri], (score, p));
                }
            }
        }
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

    /// [`Candidate::merit`](super::Candidate::merit) at a coarse gate, for the grid: of
    /// `segments`, those at least `min_len` long at `pose`, the share the frame's longest edges
    /// cover within `gate` (each up to [`FULL_COVER`]), times the share (by angle) of those
    /// edges (the [`VOTE_EDGES`] longest) that one of them explains within `gate`. `None` if
    /// fewer than six segments are that long. With `grid_blank`, times one minus the share of
    /// their points in sight and in view that are blank, as in the final merit (module
    /// `near_edges`); that factor can only lower the merit, so it is worked out only where the
    /// merit without it beats `floor` (`None` otherwise). Only reads the initialiser (the
    /// lanes share it); returns the work to charge.
    ///
    /// The support is over all the vote's edges rather than the few dozen longest, as the final
    /// [`Candidate::support`](super::Candidate::support) is over all edges: measured on the ZInD
    /// panoramas (docs/decisions.md), the 64 longest let the grid drop the truth in favour of
    /// poses along texture (3 m hint: 20 of 32 within 10 cm with 64, 24 with all 256).
    pub(super) fn merit_with(
        &self,
        m: &mut MeritScratch,
        pose: &Pose,
        segments: &[SeenSegment],
        gate: &Gate,
        min_len: f64,
        floor: f64,
    ) -> (Option<f64>, u64) {
        let (mut explained, mut counted) = (0.0, 0usize);
        let mut reach = [Reach::Anything; MAX_SENSORS];
        for (s, r) in reach.iter_mut().enumerate().take(self.centres.len()) {
            *r = self.vote_index.reach(s, gate.cos_alpha);
        }
        m.explained[..self.vote_edges.len()].fill(false);
        m.predicted.clear();
        m.counted.clear();
        for (i, seen) in segments.iter().enumerate() {
            let seg = &self.model.segments[seen.segment as usize];
            let pred = Predicted::new(&[seg.a, seg.b], pose, &self.centres);
            if pred.length_rad < min_len {
                continue;
            }
            counted += 1;
            if m.counted.len() < m.counted.capacity() {
                m.counted.push(i as u32);
            }
            let cover = cover_near(
                &pred,
                &self.centres,
                &self.vote_edges,
                &self.vote_index,
                &reach,
                gate,
                &mut m.explained,
            );
            if let Some(cover) = cover {
                explained += (cover / FULL_COVER).min(1.0);
            }
            // Kept only for the debug builds' check against all pairs below.
            if cfg!(debug_assertions) && m.predicted.len() < m.predicted.capacity() {
                m.predicted.push(pred);
            }
        }
        let marks = &m.explained[..self.vote_edges.len()];
        let support = (counted >= 6).then(|| length_share(self.vote_edges.iter(), self.centres.len(), |k, _| marks[k]));
        // Debug builds (the tests) check one score in 16 against every pair, as the scores were
        // computed before the index.
        m.calls = m.calls.wrapping_add(1);
        #[cfg(debug_assertions)]
        if let Some(support) = support.filter(|_| m.calls % 16 == 1 && m.predicted.len() == counted) {
            let mut all = 0.0;
            for seen in segments {
                let seg = &self.model.segments[seen.segment as usize];
                let pred = Predicted::new(&[seg.a, seg.b], pose, &self.centres);
                if pred.length_rad >= min_len {
                    if let (Some(_), cover) = best_edge_and_cover(&pred, &self.centres, &self.vote_edges, gate) {
                        all += (cover / FULL_COVER).min(1.0);
                    }
                }
            }
            let plain = support_of(&m.predicted, &self.centres, self.vote_edges.iter(), gate.cos_alpha);
            debug_assert!(
                (all - explained).abs() < 1e-9,
                "explained {explained} by the index, {all} by all pairs"
            );
            debug_assert!(
                (plain - support).abs() < 1e-12,
                "support {support} by the index, {plain} by all pairs"
            );
        }
        let mut charge = segments.len() as u64 * self.vote_edges.len() as u64 / 100 * work::MERIT_PER_SEGMENT_100_EDGES;
        // The blank share can only lower the merit, so it is looked at only where the merit
        // without it would beat `floor`.
        let Some(bound) = support.map(|support| explained / counted as f64 * support) else {
            return (None, charge);
        };
        if bound <= floor {
            return (None, charge);
        }
        if !self.grid_blank || self.opts.blank_radius_rad <= 0.0 {
            return (Some(bound), charge);
        }
        let (blank, points) = self.blank_points(pose, segments, &m.counted);
        charge += points as u64 / work::BLANK_POINTS_PER_UNIT;
        let open = if points == 0 {
            1.0
        } else {
            1.0 - blank as f64 / points as f64
        };
        (Some(bound * open), charge)
    }

    /// [`Candidate::blank`](super::Candidate::blank)'s test on the points in sight (the masks
    /// of `segments`) and in view of those of `segments` at `counted`, by the frame's map of
    /// directions near an edge: (blank points, points).
    fn blank_points(&self, pose: &Pose, segments: &[SeenSegment], counted: &[u32]) -> (usize, usize) {
        let (mut blank, mut points) = (0, 0);
        for &i in counted {
            let seen = &segments[i as usize];
            let seg = &self.model.segments[seen.segment as usize];
            for k in (0..SAMPLES).filter(|k| seen.mask & (1 << k) != 0) {
                let p = pose.inverse_transform_point(&sample_point(&seg.a, &seg.b, k)).coords;
                if self.view.sees(&p) {
                    points += 1;
                    blank += usize::from(!self.near.near_point(&p, &self.centres));
                }
            }
        }
        (blank, points)
    }

    /// [`Self::merit_with`] in the initialiser's own scratch, charged: for the climbs and for
    /// diagnosis, on the calling thread.
    pub(super) fn coarse_merit(
        &mut self,
        pose: &Pose,
        segments: &[SeenSegment],
        gate: &Gate,
        min_len: f64,
        floor: f64,
    ) -> Option<f64> {
        let mut m = std::mem::take(&mut self.merit);
        let (merit, charge) = self.merit_with(&mut m, pose, segments, gate, min_len, floor);
        self.merit = m;
        self.spend(charge);
        merit
    }
}

/// [`best_edge_and_cover`]'s cover of `pred` over the edges of `index` (built from `edges`)
/// that can pass the gate: `None` if no edge passes it. Every edge that passes is marked in
/// `explained`: the support's test (plane within the gate, overlapping by half) is the cover's.
///
/// Only the sensors whose edges the segment can meet are looked at (`reach`: each sensor's
/// [`EdgeIndex::reach`] for the gate), with the same answer: a segment in front of one sensor of
/// a ring has far fewer pairs to test.
fn cover_near(
    pred: &Predicted,
    centres: &[Point3<f64>],
    edges: &[Edge],
    index: &EdgeIndex,
    reach: &[Reach],
    gate: &Gate,
    explained: &mut [bool],
) -> Option<f64> {
    let mut covered = 0.0;
    let mut any = false;
    for ((s, c), reach) in centres.iter().enumerate().zip(reach) {
        if !reach.may_share(&(pred.ends_rig[0] - c.coords), &(pred.ends_rig[1] - c.coords)) {
            continue;
        }
        let n = &pred.normals[s];
        let Some(arc) = SegmentArc::new(pred, c, n) else {
            continue;
        };
        index.near(s, n, gate.cos_alpha, |i| {
            if let Some((_, share)) = arc.gated_cover(n, &edges[i], gate) {
                covered += share;
                any = true;
                explained[i] = true;
            }
        });
    }
    any.then_some(covered.min(1.0))
}

/// Keeps `entry` (score, position; highest score best) among the best [`GRID_KEEP`](super::GRID_KEEP) that are at
/// least [`SAME_POSITION_M`](super::SAME_POSITION_M) apart: a better neighbour replaces a worse
/// one.
pub(super) fn keep_best_apart(best: &mut GridBest, entry: (f64, Point3<f64>)) {
    if let Some(k) = best
        .iter()
        .position(|b| (b.1 - entry.1).norm() < super::SAME_POSITION_M)
    {
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
