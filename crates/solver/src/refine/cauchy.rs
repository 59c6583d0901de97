//! R_and_T for a coarse model: iteratively reweighted least squares with Cauchy's loss.
//!
//! In: correspondences (the inliers of a consensus), a start pose, [`SolverOptions`] (its
//! `edge_sigma_rad` is the least scale), a scratch buffer. Out: `T_world_rig`.
//!
//! **Why** (beyond the papers). Kumar–Hanson's R_and_T is least squares: every line inside the
//! inlier angle (3σ) pulls with its whole squared residual. A model drawn by hand or extruded
//! from a plan puts some lines a little wrong (walls a few centimetres off, openings without
//! their trims, a ceiling height rounded), and those lines sit consistently one to three σ
//! off, all pulling the same way. An M-estimator (Huber 1964) lowers their pull and keeps that
//! of the lines the model has right. Cauchy's weights w = 1 / (1 + (α / c)²) with
//! c = [`CAUCHY_C`] σ̂ (95 % of least squares' efficiency under Gaussian noise), σ̂ the robust
//! scale of the residuals (1.4826 × their median), never below the noise model's σ: on a scene
//! the model describes exactly, the weights stay near 1 and the pose is least squares'.
//!
//! Nothing here allocates; the caller's scratch holds the weights and a copy of the residuals.

use super::kumar_hanson::r_and_t_refine_weighted;
use crate::SolverOptions;
use omnitrack_core::geometry::{Correspondence, Pose};

/// Cauchy's tuning constant for 95 % asymptotic efficiency under Gaussian noise (Holland and
/// Welsch 1977).
pub const CAUCHY_C: f64 = 2.385;
/// σ over the median absolute residual for Gaussian noise (1 / Φ⁻¹(3/4)).
pub const MAD_TO_SIGMA: f64 = 1.4826;
/// Reweighting rounds at most; each is a weighted R_and_T to convergence.
const ROUNDS: usize = 4;
/// A round that moves the pose less than this (rad, and m over the lines' distance) ends it.
const SETTLED: f64 = 1e-7;

/// Cauchy IRLS from `guess` over `c` (module doc). `scratch` must hold 2 × `c.len()` numbers.
/// `None` when R_and_T finds no pose (too few or degenerate lines) or the scratch is short.
pub fn r_and_t_cauchy(c: &[Correspondence], guess: &Pose, o: &SolverOptions, scratch: &mut [f64]) -> Option<Pose> {
    let n = c.len();
    if n < 3 || scratch.len() < 2 * n {
        return None;
    }
    let (weights, residuals) = scratch[..2 * n].split_at_mut(n);
    let mut pose = *guess;
    for _ in 0..ROUNDS {
        for (r, l) in residuals.iter_mut().zip(c) {
            *r = l.alpha(&pose);
        }
        for (w, r) in weights.iter_mut().zip(residuals.iter()) {
            *w = *r;
        }
        // The median residual (`weights` holds the copy that selection reorders).
        let (_, median, _) = weights.select_nth_unstable_by(n / 2, f64::total_cmp);
        let sigma = (MAD_TO_SIGMA * *median).max(o.edge_sigma_rad);
        let c2 = (CAUCHY_C * sigma).powi(2);
        for (w, r) in weights.iter_mut().zip(residuals.iter()) {
            *w = 1.0 / (1.0 + r * r / c2);
        }
        let next = r_and_t_refine_weighted(c, weights, &pose, o)?;
        let moved = next.rotation.angle_to(&pose.rotation) + (next.translation.vector - pose.translation.vector).norm();
        pose = next;
        if moved < SETTLED {
            break;
        }
    }
    Some(pose)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Point3, Translation3, Unit, UnitQuaternion, Vector3};
    use omnitrack_core::geometry::EdgePlane;

    /// Lines of a box room seen from `truth`, each observed exactly.
    fn room(truth: &Pose) -> Vec<Correspondence> {
        let mut c = Vec::new();
        let (x0, x1, y0, y1, z0, z1) = (-2.0, 3.0, -2.5, 2.0, 0.0, 2.6);
        let corners = [(x0, y0), (x1, y0), (x1, y1), (x0, y1)];
        for k in 0..4 {
            let (a, b) = (corners[k], corners[(k + 1) % 4]);
            for z in [z0, z1] {
                c.push([Point3::new(a.0, a.1, z), Point3::new(b.0, b.1, z)]);
            }
            c.push([Point3::new(a.0, a.1, z0), Point3::new(a.0, a.1, z1)]);
            // A door's jambs and head in each wall.
            let t = |f: f64| (a.0 + (b.0 - a.0) * f, a.1 + (b.1 - a.1) * f);
            let (p, q) = (t(0.3), t(0.5));
            c.push([Point3::new(p.0, p.1, z0), Point3::new(p.0, p.1, 2.0)]);
            c.push([Point3::new(q.0, q.1, z0), Point3::new(q.0, q.1, 2.0)]);
            c.push([Point3::new(p.0, p.1, 2.0), Point3::new(q.0, q.1, 2.0)]);
        }
        c.into_iter()
            .map(|segment| {
                let (a, b) = (
                    truth.inverse_transform_point(&segment[0]).coords,
                    truth.inverse_transform_point(&segment[1]).coords,
                );
                let edge = EdgePlane {
                    normal: Unit::new_normalize(a.cross(&b)),
                    centre: Point3::origin(),
                    ends: [Unit::new_normalize(a), Unit::new_normalize(b)],
                };
                Correspondence { edge, segment }
            })
            .collect()
    }

    fn truth() -> Pose {
        Pose::from_parts(
            Translation3::new(0.4, -0.3, 1.5),
            UnitQuaternion::from_euler_angles(0.01, -0.02, 0.7),
        )
    }

    fn error(p: &Pose, t: &Pose) -> f64 {
        (p.translation.vector - t.translation.vector).norm()
    }

    #[test]
    fn an_exact_scene_gives_the_least_squares_pose() {
        let t = truth();
        let c = room(&t);
        let start = Pose::from_parts(Translation3::new(0.45, -0.25, 1.52), t.rotation);
        let mut scratch = vec![0.0; 2 * c.len()];
        let o = SolverOptions::default();
        let p = r_and_t_cauchy(&c, &start, &o, &mut scratch).expect("pose");
        assert!(error(&p, &t) < 1e-6, "{}", error(&p, &t));
        assert!(p.rotation.angle_to(&t.rotation) < 1e-6);
    }

    /// Three lines of one door drawn 8 cm off (its trims, not its opening): least squares is
    /// pulled towards them, the Cauchy fit half as far.
    #[test]
    fn lines_the_model_places_a_little_wrong_pull_less() {
        let t = truth();
        let mut c = room(&t);
        let shift = Vector3::new(0.08, 0.0, 0.0);
        // The first wall's door (lines 3, 4, 5) observed as if it stood 8 cm along x.
        for l in &mut c[3..6] {
            let (a, b) = (
                t.inverse_transform_point(&(l.segment[0] + shift)).coords,
                t.inverse_transform_point(&(l.segment[1] + shift)).coords,
            );
            l.edge.normal = Unit::new_normalize(a.cross(&b));
            l.edge.ends = [Unit::new_normalize(a), Unit::new_normalize(b)];
        }
        let o = SolverOptions::default();
        let ls = crate::r_and_t_refine(&c, &t, &o).expect("least squares");
        let mut scratch = vec![0.0; 2 * c.len()];
        let robust = r_and_t_cauchy(&c, &t, &o, &mut scratch).expect("cauchy");
        assert!(
            error(&robust, &t) < 0.6 * error(&ls, &t),
            "cauchy {} m, least squares {} m",
            error(&robust, &t),
            error(&ls, &t)
        );
    }

    #[test]
    fn short_scratch_or_too_few_lines_give_none() {
        let t = truth();
        let c = room(&t);
        let o = SolverOptions::default();
        assert!(r_and_t_cauchy(&c, &t, &o, &mut [0.0; 3]).is_none());
        assert!(r_and_t_cauchy(&c[..2], &t, &o, &mut [0.0; 4]).is_none());
    }
}
