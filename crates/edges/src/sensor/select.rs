//! The strongest candidates → [`Edge`]s: at most `max_edges`, strongest first, rotated into the
//! rig frame, with their pixel ends, hue, polarity, the gaps merging bridged, and the pieces the
//! image shows as lines ([`nfa`](super::nfa)).
//!
//! In: the [`Workspace`]'s merged [`Candidate`](super::Candidate)s. Out: its `edges`, and the
//! count of those the cap left out.

use super::nfa::Stretch;
use super::plane::{angle_in_plane, plane_residual};
use super::Workspace;
use crate::edge::{Edge, MAX_GAPS};
use crate::hue::HueSignature;
use nalgebra::{Point2, Unit, Vector3};
use omnitrack_core::geometry::EdgePlane;

impl Workspace {
    /// Keeps the strongest `max_edges` candidates and turns them into edges (rig frame).
    #[inline(never)]
    pub(super) fn select(&mut self) {
        let min_cos = self.min_len_rad.cos();
        self.cands.retain(|c| c.r1.dot(&c.r2) <= min_cos);
        let k = self.max_edges;
        if self.cands.len() > k {
            self.stats.capped = (self.cands.len() - k) as u32;
            if k == 0 {
                self.cands.clear();
            } else {
                self.cands
                    .select_nth_unstable_by(k - 1, |a, b| b.strength.total_cmp(&a.strength));
                self.cands.truncate(k);
            }
        }
        self.cands.sort_unstable_by(|a, b| b.strength.total_cmp(&a.strength));
        let rot = self.rotation;
        for c in &self.cands {
            let (Some(p1), Some(p2)) = (self.lens.project(&c.r1), self.lens.project(&c.r2)) else {
                continue;
            };
            let (left, right) = (c.left.stats(), c.right.stats());
            let n_rig = rot * c.n;
            let plane = EdgePlane {
                normal: Unit::new_normalize(n_rig),
                centre: self.centre,
                ends: [Unit::new_normalize(rot * c.r1), Unit::new_normalize(rot * c.r2)],
            };
            let lambda = plane_residual(&c.m, &c.n);
            let length_rad = c.r1.dot(&c.r2).clamp(-1.0, 1.0).acos();
            // The gaps as angles from r1 along the plane, in order.
            let mut gaps = [[0f32; 2]; MAX_GAPS];
            let mut n_gaps = 0;
            for g in &c.gaps[..usize::from(c.n_gaps)] {
                let along = |r: &Vector3<f64>| {
                    let r = (r - c.n * c.n.dot(r)).normalize();
                    angle_in_plane(&c.n, &c.r1, &r)
                };
                let (ta, tb) = (along(&g[0]), along(&g[1]));
                let (t0, t1) = (ta.min(tb), ta.max(tb));
                if t0 > 0.0 && t1 < length_rad && t1 > t0 {
                    gaps[n_gaps] = [t0 as f32, t1 as f32];
                    n_gaps += 1;
                }
            }
            gaps[..n_gaps].sort_unstable_by(|x, y| x[0].total_cmp(&y[0]));
            // The pieces between the gaps the image shows as lines.
            let mut shown = [[0f32; 2]; MAX_GAPS + 1];
            let mut n_shown = 0;
            for k in 0..=n_gaps {
                let from = if k == 0 { 0.0 } else { gaps[k - 1][1] };
                let to = if k == n_gaps { length_rad as f32 } else { gaps[k][0] };
                let piece = if self.params.piece_nfa {
                    self.meaningful_part(&c.n, &c.r1, f64::from(from), f64::from(to))
                } else {
                    Some(Stretch::Whole)
                };
                match piece {
                    Some(Stretch::Whole) => shown[n_shown] = [from, to],
                    Some(Stretch::Part(a, b)) => shown[n_shown] = [a as f32, b as f32],
                    None => continue,
                }
                n_shown += 1;
            }
            self.edges.push(Edge {
                sensor: self.sensor,
                plane,
                px: [Point2::new(p1.x, p1.y), Point2::new(p2.x, p2.y)],
                length_rad,
                strength: c.strength,
                hue: HueSignature {
                    left_mean: left.mean,
                    left_var: left.variance,
                    right_mean: right.mean,
                    right_var: right.variance,
                    left_kept: left.kept,
                    right_kept: right.kept,
                },
                polarity: if 4 * c.bright_left.unsigned_abs() >= 2 * c.count {
                    c.bright_left.signum() as i8
                } else {
                    0
                },
                edgels: c.count,
                rms_rad: (lambda / c.m[6].max(1e-12)).max(0.0).sqrt() as f32,
                gaps,
                n_gaps: n_gaps as u8,
                shown,
                n_shown: n_shown as u8,
            });
        }
    }
}
