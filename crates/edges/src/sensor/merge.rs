//! Candidates of different chains that lie on one plane joined end to end: a line broken by an
//! occluder, a gap in the edgels or a junction.
//!
//! In: the [`Workspace`]'s [`Candidate`]s (from [`fit`](super::fit)). Out: the same, merged (up to
//! three passes; the dead ones dropped), each merge remembering the widest gaps it bridged; with
//! `merge_gap_evidence`, a merge happens only where the image shows the line across the gap.

use super::plane::{angle_in_plane, plane_normal, plane_residual, two_lines_apart, Moments};
use super::{Candidate, Workspace};
use crate::edge::MAX_GAPS;
use nalgebra::{Point2, Vector2, Vector3};
use omnitrack_core::geometry::arc_tangent;

/// A gradient counts as across a line when its component along the line is at most this share
/// of it (sin 10°: within 10° of the line's normal, as along a real line; texture beside a gap
/// points every way).
const GAP_ACROSS_COS: f64 = 0.174;

impl Workspace {
    /// Joins candidates of different chains that lie on one plane, end to end (a line broken by
    /// an occluder, a gap in the edgels or a junction). Polarity is not compared: an edge seen
    /// against a background that turns from darker to brighter flips it halfway (docs/decisions.md).
    #[inline(never)]
    pub(super) fn merge_across_chains(&mut self) {
        let cos_max = self.params.merge_angle_rad.cos();
        let gap_max = self.params.merge_gap_rad;
        let tol = self.params.split_tolerance_rad.sin();
        let two_line = self.params.two_line_excess;
        let min_support = self.params.merge_min_support;
        let min_evidence = self.params.merge_gap_evidence;
        // The cosine of the widest end-to-end angle `try_merge` lets through, once a pass rather
        // than once a pair tried.
        let near_cos = (1.5 * gap_max + 0.01).min(std::f64::consts::PI).cos();
        let pack = |n: &Vector3<f64>| [n.x as f32, n.y as f32, n.z as f32];
        for (k, coord) in self.normals.iter_mut().enumerate() {
            coord.clear();
            coord.extend(self.cands.iter().map(|c| pack(&c.n)[k]));
        }
        // The f32 test lets through every pair the f64 one below would.
        let cos_loose = cos_max as f32 - 1e-5;
        let len = self.cands.len();
        for pass in 0..3 {
            let mut merged_any = false;
            for i in 0..len {
                if !self.cands[i].alive {
                    continue;
                }
                // i's own frame for `try_merge`'s gap test, made when first needed and again
                // after each merge into i, rather than once a pair tried.
                let mut i_frame = None;
                // The normal test of a block of pairs at once (the compiler vectorises it):
                // nearly every pair fails it. Pairs that pass are tried in the same order as
                // one by one, and a merge, which turns i's normal, tests the rest of the
                // block again.
                let mut j = i + 1;
                while j < len {
                    let end = (j + PAIR_BLOCK).min(len);
                    let [nx, ny, nz] = &self.normals;
                    let a = [nx[i], ny[i], nz[i]];
                    let mut mask = 0u32;
                    for (k, ((bx, by), bz)) in nx[j..end].iter().zip(&ny[j..end]).zip(&nz[j..end]).enumerate() {
                        let d = (a[0] * bx + a[1] * by + a[2] * bz).abs();
                        mask |= u32::from(d >= cos_loose) << k;
                    }
                    let mut next = end;
                    while mask != 0 {
                        let jj = j + mask.trailing_zeros() as usize;
                        mask &= mask - 1;
                        // A pair whose members are unchanged since the last pass was tried then.
                        if !self.cands[jj].alive || (pass > 0 && !self.cands[i].changed && !self.cands[jj].changed) {
                            continue;
                        }
                        let (ci, cj) = (&self.cands[i], &self.cands[jj]);
                        let dot = ci.n.dot(&cj.n);
                        if dot.abs() < cos_max {
                            continue;
                        }
                        let frame = *i_frame.get_or_insert_with(|| PlaneFrame::of(ci));
                        if let Some(m) = try_merge(ci, cj, &frame, gap_max, near_cos, tol, two_line, min_support) {
                            if min_evidence > 0.0 && self.gap_evidence(&m, ci, cj, min_evidence) < min_evidence {
                                self.stats.merges_refused += 1;
                                continue;
                            }
                            self.cands[i] = m;
                            i_frame = None;
                            self.cands[jj].alive = false;
                            for (k, coord) in self.normals.iter_mut().enumerate() {
                                coord[i] = pack(&m.n)[k];
                                coord[jj] = 0.0;
                            }
                            self.stats.merged += 1;
                            merged_any = true;
                            self.cands[i].merged_now = true;
                            next = jj + 1;
                            break;
                        }
                    }
                    j = next;
                }
            }
            if !merged_any {
                break;
            }
            for c in self.cands.iter_mut() {
                c.changed = std::mem::take(&mut c.merged_now);
            }
        }
        self.cands.retain(|c| c.alive);
    }

    /// The share of the gap between the pieces `ci` and `cj` of the merged edge `m` along which
    /// the image shows the line: sampled every ~3 px (at most 48 times) along the merged plane's
    /// great circle, a sample shows it when a pixel within one of it has a gradient of at least
    /// half the edgel threshold pointing across the line (within [`GAP_ACROSS_COS`]). A line broken by
    /// noise, aliasing or a weak stretch keeps its gradient across the gap; collinear pieces
    /// far apart (the tops of a row of windows, texture) have plain wall between them. 1 where
    /// the pieces touch or overlap.
    fn gap_evidence(&self, m: &Candidate, ci: &Candidate, cj: &Candidate, needed: f64) -> f64 {
        let n = m.n;
        let e1 = m.r1;
        let ang = |r: &Vector3<f64>| angle_in_plane(&n, &e1, r);
        let (i0, i1) = (ang(&ci.r1).min(ang(&ci.r2)), ang(&ci.r1).max(ang(&ci.r2)));
        let (j0, j1) = (ang(&cj.r1).min(ang(&cj.r2)), ang(&cj.r1).max(ang(&cj.r2)));
        let (g0, g1) = if j0 >= i1 {
            (i1, j0)
        } else if i0 >= j1 {
            (j1, i0)
        } else {
            return 1.0;
        };
        let e2 = n.cross(&e1);
        let ray = |a: f64| e1 * a.cos() + e2 * a.sin();
        let (Some(p0), Some(p1)) = (self.lens.project(&ray(g0)), self.lens.project(&ray(g1))) else {
            return 0.0;
        };
        let chord = p1 - p0;
        let length = chord.norm();
        if length < 3.0 {
            return 1.0;
        }
        let along = chord / length;
        let samples = ((length / 3.0).ceil() as usize).clamp(2, 48);
        let threshold = i32::from(self.params.gradient_threshold) / 2;
        // Stop as soon as `needed` is out of reach: most merges tried are refused.
        let allowed_misses = ((1.0 - needed) * samples as f64).floor() as usize;
        let (mut shown, mut missed) = (0, 0);
        // Every fourth sample first: a gap of plain wall shows itself after a few samples.
        for k in (0..4).flat_map(|phase| (phase..samples).step_by(4)) {
            let a = g0 + (g1 - g0) * (k as f64 + 0.5) / samples as f64;
            let shows = self
                .lens
                .project(&ray(a))
                .is_some_and(|p| self.gradient_across(&p, &along, threshold));
            if shows {
                shown += 1;
            } else {
                missed += 1;
                if missed > allowed_misses {
                    return 0.0;
                }
            }
        }
        shown as f64 / samples as f64
    }

    /// Whether a pixel within one of `p` has an L1 gradient of at least `threshold` pointing
    /// across the unit image direction `along` (within [`GAP_ACROSS_COS`]).
    fn gradient_across(&self, p: &Point2<f64>, along: &Vector2<f64>, threshold: i32) -> bool {
        let (x, y) = (p.x.round() as isize, p.y.round() as isize);
        for dy in -1..=1 {
            for dx in -1..=1 {
                let (u, v) = (x + dx, y + dy);
                if u < 0 || v < 0 || u >= self.w as isize || v >= self.h as isize {
                    continue;
                }
                let i = v as usize * self.w + u as usize;
                if i32::from(self.buf.mag[i]) < threshold {
                    continue;
                }
                let (gx, gy) = (f64::from(self.buf.gx[i]), f64::from(self.buf.gy[i]));
                let g = (gx * gx + gy * gy).sqrt();
                if g > 0.0 && (gx * along.x + gy * along.y).abs() <= GAP_ACROSS_COS * g {
                    return true;
                }
            }
        }
        false
    }
}

/// Pairs whose normals `merge_across_chains` tests at once.
const PAIR_BLOCK: usize = 32;

/// A candidate's plane as `try_merge`'s gap test measures along it: the direction 90° on from
/// r1 (n × r1), and the angle from r1 to r2.
#[derive(Clone, Copy)]
struct PlaneFrame {
    e2: Vector3<f64>,
    len: f64,
}

impl PlaneFrame {
    fn of(c: &Candidate) -> PlaneFrame {
        let e2 = c.n.cross(&c.r1);
        PlaneFrame {
            e2,
            len: arc_tangent(c.r2.dot(&e2), c.r2.dot(&c.r1)),
        }
    }
}

/// `frame`: `ci`'s [`PlaneFrame`]; `near_cos`: cos(min(1.5 `gap_max` + 0.01, π)), the cheapest
/// reject's bound.
#[allow(clippy::too_many_arguments)]
fn try_merge(
    ci: &Candidate,
    cj: &Candidate,
    frame: &PlaneFrame,
    gap_max: f64,
    near_cos: f64,
    tol: f64,
    two_line: f64,
    min_support: f64,
) -> Option<Candidate> {
    // Orient j like i.
    let di = ci.r2 - ci.r1;
    let same = di.dot(&(cj.r2 - cj.r1)) >= 0.0;
    let (jr1, jr2, jl, jr, jb) = if same {
        (cj.r1, cj.r2, cj.left, cj.right, cj.bright_left)
    } else {
        (cj.r2, cj.r1, cj.right, cj.left, -cj.bright_left)
    };
    // Cheapest reject: the nearest ends further apart than any gap or overlap allowed (pairs
    // on one line far apart are most of those tried).
    let near = ci
        .r1
        .dot(&jr1)
        .max(ci.r1.dot(&jr2))
        .max(ci.r2.dot(&jr1))
        .max(ci.r2.dot(&jr2));
    if near < near_cos {
        return None;
    }
    // Cheap reject before the eigen-decomposition: the gap measured along i's own plane.
    {
        let ang = |r: &Vector3<f64>| arc_tangent(r.dot(&frame.e2), r.dot(&ci.r1));
        let ilen = frame.len;
        let (a1, a2) = (ang(&jr1), ang(&jr2));
        let (lo, hi) = (a1.min(a2), a1.max(a2));
        let gap = if lo > ilen { lo - ilen } else { -hi };
        if gap > 1.5 * gap_max + 0.01 {
            return None;
        }
    }
    let m: Moments = std::array::from_fn(|k| ci.m[k] + cj.m[k]);
    let mut n = plane_normal(&m)?;
    if n.dot(&ci.n) < 0.0 {
        n = -n;
    }
    // Every end ray must lie on the merged plane, and the fit must stay tight.
    for r in [ci.r1, ci.r2, jr1, jr2] {
        if n.dot(&r).abs() > tol {
            return None;
        }
    }
    let count = ci.count + cj.count;
    let rss = plane_residual(&m, &n);
    if rss / m[6] > tol * tol * 0.25 {
        return None;
    }
    // Nor, with the two-line test on, may it be two lines side by side or at a kink.
    let two = plane_residual(&ci.m, &ci.n) + plane_residual(&cj.m, &cj.n);
    if two_line > 0.0 && two_lines_apart(rss, two, m[6], count as usize, tol, two_line) {
        return None;
    }
    // Intervals along the great circle: must not overlap (beyond a sliver), gap small.
    let e1 = (ci.r1 - n * n.dot(&ci.r1)).normalize();
    let ia = (0.0, angle_in_plane(&n, &e1, &ci.r2));
    let ja = (angle_in_plane(&n, &e1, &jr1), angle_in_plane(&n, &e1, &jr2));
    // i runs in increasing angle (ia.1 > 0 for a short arc oriented r1→r2 about n).
    if ia.1 <= 0.0 || ja.1 <= ja.0 {
        return None;
    }
    let gap = if ja.0 >= ia.1 - 1e-9 {
        ja.0 - ia.1
    } else if ja.1 <= ia.0 + 1e-9 {
        ia.0 - ja.1
    } else {
        // Overlapping: allow only a sliver (junction re-tracing).
        let overlap = ia.1.min(ja.1) - ia.0.max(ja.0);
        -overlap
    };
    if gap > gap_max || gap < -0.25 * gap_max.min((ia.1 - ia.0).min(ja.1 - ja.0)) {
        return None;
    }
    let lo = if ja.0 < ia.0 { jr1 } else { ci.r1 };
    let hi = if ja.1 > ia.1 { jr2 } else { ci.r2 };
    let r1 = (lo - n * n.dot(&lo)).normalize();
    let r2 = (hi - n * n.dot(&hi)).normalize();
    // Mostly edge: the pieces must cover `min_support` of the merged span, so that short
    // collinear pieces far apart (a row of windows, tiles, texture) do not chain up into one
    // long edge across what lies between them.
    let support = ci.support + cj.support - (-gap).max(0.0);
    if support < min_support * r1.dot(&r2).clamp(-1.0, 1.0).acos() {
        return None;
    }
    // The gaps: both pieces' own, and the one between them.
    let mut gaps = ci.gaps;
    let mut n_gaps = usize::from(ci.n_gaps);
    let between = (gap > 0.0).then_some(if ja.0 >= ia.1 - 1e-9 {
        [ci.r2, jr1]
    } else {
        [jr2, ci.r1]
    });
    for g in cj.gaps[..usize::from(cj.n_gaps)].iter().copied().chain(between) {
        keep_widest(&mut gaps, &mut n_gaps, g);
    }
    let mut left = ci.left;
    left.add(&jl);
    let mut right = ci.right;
    right.add(&jr);
    Some(Candidate {
        m,
        count,
        n,
        r1,
        r2,
        strength: ci.strength + cj.strength,
        support,
        bright_left: ci.bright_left + jb,
        left,
        right,
        gaps,
        n_gaps: n_gaps as u8,
        alive: true,
        changed: false,
        merged_now: false,
    })
}

/// Adds the gap `g` (its two end rays) to the first `n` of `gaps`, or, when they are full, in
/// place of the narrowest if it is wider: a gap left out counts as seen, as every gap did before
/// edges kept them.
fn keep_widest(gaps: &mut [[Vector3<f64>; 2]; MAX_GAPS], n: &mut usize, g: [Vector3<f64>; 2]) {
    if *n < MAX_GAPS {
        gaps[*n] = g;
        *n += 1;
        return;
    }
    // Cosines: the narrowest gap has the largest.
    let (k, narrowest) = gaps
        .iter()
        .enumerate()
        .map(|(k, x)| (k, x[0].dot(&x[1])))
        .fold((0, f64::NEG_INFINITY), |a, b| if b.1 > a.1 { b } else { a });
    if g[0].dot(&g[1]) < narrowest {
        gaps[k] = g;
    }
}
