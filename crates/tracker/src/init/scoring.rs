//! Polishing and scoring a candidate pose (the parent module's doc, "Scoring", "Scoring both
//! ways", "Lines across plain surfaces" and "Visibility at the pose"): matches gathered at the
//! pose with shrinking gates, the trimmed refit, and the measures a candidate ranks by — the
//! truncated ξ, the share of segments explained, the share of edges supported and the blank
//! share.
//!
//! In: a pose, the frame's edges. Out: a polished [`Candidate`] or one of its measures.

use super::{Candidate, Initialiser, FULL_COVER, HEIGHT_SLACK_M};
use crate::matching::{best_edge, best_edge_and_cover, correspondence, overlap, Gate, Predicted};
use crate::visibility::at_pose::{sample_point, SAMPLES};
use nalgebra::{Point3, Vector3};
use omnitrack_core::geometry::{xi, Correspondence, Pose};
use omnitrack_core::rig::ViewMap;
use omnitrack_edges::Edge;
use omnitrack_solver::refine::cauchy::MAD_TO_SIGMA;
use omnitrack_solver::{minimise_xi, minimise_xi_upright, SimplexOptions};

/// The gates a polish gathers its matches with, in inlier angles, widest first: a start further
/// off than the widest in rotation rarely reaches the pose.
const POLISH_GATES: [f64; 3] = [4.0, 2.0, 1.0];

impl Initialiser<'_> {
    /// The widest gate of [`Self::polish`] (rad): about how far off in rotation a start may be.
    pub fn polish_reach_rad(&self) -> f64 {
        POLISH_GATES[0] * self.opts.inlier_alpha_rad
    }

    /// The fit of `self.corr` from `start`, then twice: correspondences whose α exceeds
    /// max(inlier angle, 2.5 robust σ from the median α) are dropped and the rest refitted. A
    /// greedy gather at a wide gate holds wrong matches, and one of them is enough to pull a plain
    /// least-squares fit into a neighbouring minimum.
    pub(super) fn trimmed_fit(&mut self, start: &Pose) -> Option<Pose> {
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

    /// [`Self::polish`] without the floor test, charged when done (its rays with it).
    pub(super) fn polish_unchecked(&mut self, start: &Pose, edges: &[Edge]) -> Option<Candidate> {
        let c = self.polish_steps(start, edges);
        self.spend(super::work::POLISH);
        c
    }

    /// [`Self::polish`]'s gathers and trimmed fits from `start` without the ξ simplex, and the
    /// truncated ξ of the pose they reach: what a pose near `start` scores, for a caller that
    /// only compares scores and refits the winner itself (maintenance's second opinion). The
    /// simplex is most of a polish's time (1.3–2 ms of 2.5 on `lab`).
    pub fn refit_score(&mut self, start: &Pose, edges: &[Edge]) -> Option<(Pose, f64)> {
        let pose = self.gathered_fit(start, edges);
        self.spend(super::work::POLISH);
        let pose = pose.filter(|p| self.height_ok(p))?;
        Some((pose, self.final_score(&pose, edges).0))
    }

    /// The gathers at shrinking gates from `start`, each refitted; `self.corr` then holds the
    /// last gather at the inlier angle.
    fn gathered_fit(&mut self, start: &Pose, edges: &[Edge]) -> Option<Pose> {
        let inlier = self.opts.inlier_alpha_rad;
        let mut pose = *start;
        for widening in POLISH_GATES {
            let gate_rad = widening * inlier;
            let count = self.gather(&pose, edges, gate_rad);
            if count < 4 {
                return None;
            }
            pose = self.trimmed_fit(&pose)?;
        }
        let count = self.gather(&pose, edges, inlier);
        (count >= 4).then_some(pose)
    }

    fn polish_steps(&mut self, start: &Pose, edges: &[Edge]) -> Option<Candidate> {
        let inlier = self.opts.inlier_alpha_rad;
        let mut pose = self.gathered_fit(start, edges)?;
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
    pub(super) fn gather(&mut self, pose: &Pose, edges: &[Edge], gate_rad: f64) -> usize {
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
    /// panoramas' candidates (docs/decisions.md, real photographs) the share over all edges gave the
    /// truth a clear margin (merit ratio ≤ 0.8) over the best pose 0.6 m or 10° away on 27 of 32,
    /// against 22 with the 64 longest.
    pub fn edge_support(&mut self, pose: &Pose, edges: &[Edge]) -> f64 {
        self.predict_in_sight(pose);
        let min_len = self.opts.min_length_rad;
        self.predicted_support(
            edges.iter().filter(|e| e.length_rad >= min_len),
            self.opts.inlier_alpha_rad.cos(),
        )
    }

    /// Per edge of `edges` (at least the shortest edge long), whether a segment in sight from
    /// `pose` explains it as [`Self::edge_support`] counts: plane within the inlier gate and
    /// overlapping by half.
    pub fn edges_explained(&mut self, pose: &Pose, edges: &[Edge], out: &mut Vec<bool>) {
        self.predict_in_sight(pose);
        let cos_gate = self.opts.inlier_alpha_rad.cos();
        let min_len = self.opts.min_length_rad;
        out.clear();
        out.extend(edges.iter().map(|e| {
            e.length_rad >= min_len
                && (e.sensor as usize) < self.centres.len()
                && explains(&self.support_pred, &self.centres, e, cos_gate)
        }));
    }

    /// `self.support_pred` ← each segment in sight from `pose`, its plane in every sensor.
    fn predict_in_sight(&mut self, pose: &Pose) {
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
    }

    /// The share (by angle) of `edges` that one of `self.support_pred` explains: plane within
    /// the gate (cos) and overlapping.
    pub(super) fn predicted_support<'e>(&self, edges: impl Iterator<Item = &'e Edge>, cos_gate: f64) -> f64 {
        support_of(&self.support_pred, &self.centres, edges, cos_gate)
    }

    /// How many model segments the rig images long enough to detect from `pose`: in sight
    /// (`at_pose`), on some sensor's image ([`ViewMap`]) for at least one of their sampled
    /// points, and at least the shortest edge long. What a frame there can match at best.
    ///
    /// Scores do not count this way (yet): judging candidates by the segments in view alone
    /// made a one-pinhole rig commit wrong poses on real photographs (docs/decisions.md, "a one-sensor
    /// pinhole rig").
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

    /// What the search's acceptance test reads of any pose as it stands, unpolished:
    /// [`Candidate::inliers`], [`Candidate::explained`] and [`Candidate::support`] (a commit on
    /// trial, module `tracker::search`, judged at the pose maintenance holds).
    pub fn acceptance_scores(&mut self, pose: &Pose, edges: &[Edge]) -> (usize, f64, f64) {
        let (_, inliers, _, explained) = self.final_score(pose, edges);
        (inliers, explained, self.edge_support(pose, edges))
    }

    /// [`Candidate::explained`] of any pose.
    pub fn explained(&mut self, pose: &Pose, edges: &[Edge]) -> f64 {
        self.final_score(pose, edges).3
    }

    /// (truncated ξ with the inlier cap over the segments in sight from the pose and long enough,
    /// inliers, segments counted, the share of them explained). A segment counts as explained, and at its
    /// α rather than the cap, in proportion to how much of it the matching edges cover, up to
    /// [`FULL_COVER`].
    pub(super) fn final_score(&mut self, pose: &Pose, edges: &[Edge]) -> (f64, usize, usize, f64) {
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
                    let w = covered_share(cover, f);
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

    /// [`Candidate::explained`] counted over the lines the matcher can resolve (`resolved_share`
    /// in this module; `initialisation.accept_resolved_lines`): the segments in sight and long
    /// enough, each explained as `final_score` counts it.
    pub fn explained_resolved(&mut self, pose: &Pose, edges: &[Edge]) -> f64 {
        let cap = self.opts.inlier_alpha_rad;
        let gate = Gate::geometric(cap);
        self.resolved.clear();
        let seen = self
            .at_pose
            .at(self.model, self.table, &Point3::from(pose.translation.vector));
        for s in seen {
            let seg = &self.model.segments[s.segment as usize];
            let pred = Predicted::new(&[seg.a, seg.b], pose, &self.centres);
            if pred.length_rad < self.opts.min_length_rad || self.resolved.len() == self.resolved.capacity() {
                continue;
            }
            let [a, b] = pred.ends_rig;
            let (Some(normal), Some(ra), Some(rb)) = (
                a.cross(&b).try_normalize(1e-12),
                a.try_normalize(1e-12),
                b.try_normalize(1e-12),
            ) else {
                continue;
            };
            let f = f64::from(s.fraction);
            let explained = match best_edge_and_cover(&pred, &self.centres, edges, &gate) {
                (Some(_), cover) => f * covered_share(cover, f),
                (None, _) => 0.0,
            };
            self.resolved.push(ResolvedLine {
                normal,
                ends: [ra, rb],
                in_sight: f,
                explained,
                root: 0,
            });
        }
        resolved_share(&mut self.resolved, cap.cos())
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
                let mut dirs = [Vector3::zeros(); crate::matching::MAX_SENSORS];
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

/// A segment in sight as the matcher sees it from a pose: its plane through the rig's centre,
/// its end rays (rig frame), the share of it in sight, the share of it explained (times the
/// share in sight, as [`Candidate::explained`] counts it) and its line's root (union–find).
#[derive(Debug, Clone, Copy)]
pub(super) struct ResolvedLine {
    pub(super) normal: Vector3<f64>,
    pub(super) ends: [Vector3<f64>; 2],
    pub(super) in_sight: f64,
    pub(super) explained: f64,
    pub(super) root: u32,
}

/// The share explained over resolved lines: `lines` whose planes lie within the gate (`cos_gate`,
/// the cosine of the inlier angle) of each other and whose arcs overlap by half the shorter are
/// one line, which weighs its members' largest share in sight and is explained as far as its
/// best explained member is. One edge matches whichever of such segments it lies along, so the
/// matcher cannot tell them apart. 0 when `lines` is empty. Quadratic in the lines, which is why
/// only the candidates about to be accepted ask for it.
pub(super) fn resolved_share(lines: &mut [ResolvedLine], cos_gate: f64) -> f64 {
    fn root(lines: &mut [ResolvedLine], mut i: usize) -> usize {
        while lines[i].root as usize != i {
            let up = lines[i].root as usize;
            lines[i].root = lines[up].root;
            i = up;
        }
        i
    }
    for (i, l) in lines.iter_mut().enumerate() {
        l.root = i as u32;
    }
    for i in 0..lines.len() {
        let (ni, [ai, bi]) = (lines[i].normal, lines[i].ends);
        // Angles along i's plane from its first end.
        let e2 = ni.cross(&ai);
        let along = |r: &Vector3<f64>| r.dot(&e2).atan2(r.dot(&ai));
        let bi_at = along(&bi);
        let (ilo, ihi) = (bi_at.min(0.0), bi_at.max(0.0));
        for j in i + 1..lines.len() {
            if ni.dot(&lines[j].normal).abs() < cos_gate {
                continue;
            }
            let [aj, bj] = lines[j].ends;
            let (ja, jb) = (along(&aj), along(&bj));
            let (jlo, jhi) = (ja.min(jb), ja.max(jb));
            if ihi.min(jhi) - ilo.max(jlo) >= 0.5 * (ihi - ilo).min(jhi - jlo) {
                let (ri, rj) = (root(lines, i), root(lines, j));
                lines[ri].root = rj as u32;
            }
        }
    }
    // Each root gathers its line's largest shares; a member's own fields are read before its
    // root's are raised, and a root is its own member.
    for i in 0..lines.len() {
        let r = root(lines, i);
        if r != i {
            let (f, e) = (lines[i].in_sight, lines[i].explained);
            lines[r].in_sight = lines[r].in_sight.max(f);
            lines[r].explained = lines[r].explained.max(e);
        }
    }
    let (mut weight, mut explained) = (0.0, 0.0);
    for (i, l) in lines.iter().enumerate() {
        if l.root as usize == i {
            weight += l.in_sight;
            explained += l.explained;
        }
    }
    if weight > 0.0 {
        explained / weight
    } else {
        0.0
    }
}

/// Share of the segment a–b in view from `pose`: of its [`SAMPLES`] sampled points, those in
/// sight (bit k of `mask`, as `at_pose` gives it) that some sensor of the rig images.
pub(super) fn in_view(view: &ViewMap, pose: &Pose, a: &Point3<f64>, b: &Point3<f64>, mask: u8) -> f64 {
    let mut n = 0;
    for k in 0..SAMPLES {
        if mask & (1 << k) != 0 && view.sees(&pose.inverse_transform_point(&sample_point(a, b, k)).coords) {
            n += 1;
        }
    }
    n as f64 / SAMPLES as f64
}

/// The share (by angle) of `edges` that one of `predicted` (seen by sensors centred at
/// `centres`) explains: plane within the gate (cos) and overlapping.
pub(super) fn support_of<'e>(
    predicted: &[Predicted],
    centres: &[Point3<f64>],
    edges: impl Iterator<Item = &'e Edge>,
    cos_gate: f64,
) -> f64 {
    length_share(edges, centres.len(), |_, e| explains(predicted, centres, e, cos_gate))
}

/// How far a segment counts as explained: the share `cover` of it that edges cover, over the
/// share `in_sight` of it in sight, up to [`FULL_COVER`] counting whole.
fn covered_share(cover: f64, in_sight: f64) -> f64 {
    (cover / (FULL_COVER * in_sight)).min(1.0)
}

/// Whether one of `predicted` explains edge `e` (of a sensor of the rig): its plane in the
/// edge's sensor within the gate (`cos_gate`) of the edge's, and overlapping it by half.
fn explains(predicted: &[Predicted], centres: &[Point3<f64>], e: &Edge, cos_gate: f64) -> bool {
    let s = e.sensor as usize;
    predicted.iter().any(|pred| {
        let nrm = &pred.normals[s];
        nrm.dot(&e.plane.normal).abs() >= cos_gate && overlap(pred, &centres[s], nrm, e) >= 0.5
    })
}

/// The share (by angle) of `edges` for which `hit(k, edge)` holds (k: the edge's place in
/// `edges`), over the edges of the rig's `sensors` (others are not counted; 0 without any).
pub(super) fn length_share<'e>(
    edges: impl Iterator<Item = &'e Edge>,
    sensors: usize,
    mut hit: impl FnMut(usize, &Edge) -> bool,
) -> f64 {
    let (mut explained, mut total) = (0.0, 0.0);
    for (k, e) in edges.enumerate() {
        if (e.sensor as usize) >= sensors {
            continue;
        }
        total += e.length_rad;
        if hit(k, e) {
            explained += e.length_rad;
        }
    }
    if total > 0.0 {
        explained / total
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};
    use omnitrack_core::rig::Rig;

    /// A line in the plane through the rig's centre with normal `tilt_deg` off +z (about x),
    /// from `from_deg` to `to_deg` round it.
    fn line(tilt_deg: f64, from_deg: f64, to_deg: f64, in_sight: f64, explained: f64) -> ResolvedLine {
        let q = UnitQuaternion::from_euler_angles(tilt_deg.to_radians(), 0.0, 0.0);
        let ray = |deg: f64| q * Vector3::new(deg.to_radians().cos(), deg.to_radians().sin(), 0.0);
        ResolvedLine {
            normal: q * Vector3::z(),
            ends: [ray(from_deg), ray(to_deg)],
            in_sight,
            explained,
            root: 0,
        }
    }

    #[test]
    fn segments_the_matcher_cannot_tell_apart_count_as_one_line() {
        let gate = 1.5f64.to_radians().cos();
        // A junction drawn twice 0.5° apart, one of the two explained, and a line elsewhere not
        // explained: one line of two explained, where a segment count says one of three.
        let mut lines = [
            line(0.0, 0.0, 40.0, 1.0, 1.0),
            line(0.5, 5.0, 35.0, 1.0, 0.0),
            line(30.0, 0.0, 40.0, 1.0, 0.0),
        ];
        assert!((resolved_share(&mut lines, gate) - 0.5).abs() < 1e-12);
        // Each line weighs its members' largest share in sight, and is explained as far as its
        // best explained member is.
        let mut lines = [
            line(0.0, 0.0, 40.0, 0.5, 0.5),
            line(0.5, 5.0, 35.0, 1.0, 0.25),
            line(30.0, 0.0, 40.0, 1.0, 0.0),
        ];
        assert!((resolved_share(&mut lines, gate) - 0.25).abs() < 1e-12);
        // Planes 3° apart (twice the inlier angle) are two lines, and so are arcs that overlap by
        // less than half the shorter (the same plane, 0–40° and 30–70°), or not at all.
        for second in [
            line(3.0, 5.0, 35.0, 1.0, 0.0),
            line(0.0, 30.0, 70.0, 1.0, 0.0),
            line(0.0, 50.0, 90.0, 1.0, 0.0),
        ] {
            let mut lines = [line(0.0, 0.0, 40.0, 1.0, 1.0), second, line(30.0, 0.0, 40.0, 1.0, 0.0)];
            assert!((resolved_share(&mut lines, gate) - 1.0 / 3.0).abs() < 1e-12);
        }
        // Chains join: 0–40° and 30–70° overlap too little, but each overlaps 15–55° enough, so
        // the three are one line, whichever order they come in.
        let mut lines = [
            line(0.0, 15.0, 55.0, 1.0, 0.0),
            line(0.3, 0.0, 40.0, 1.0, 1.0),
            line(0.6, 30.0, 70.0, 1.0, 0.0),
            line(30.0, 0.0, 40.0, 1.0, 0.0),
        ];
        assert!((resolved_share(&mut lines, gate) - 0.5).abs() < 1e-12);
        assert_eq!(resolved_share(&mut [], gate), 0.0);
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
}
