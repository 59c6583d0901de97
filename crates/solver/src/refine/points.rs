//! Kumar & Hanson's point variants (§3, eqs. 14–15) and mixed point + line R_and_T.
//!
//! In: [`PointObservation`]s (a unit ray from a sensor centre, rig frame ↔ a world point), line
//! [`Correspondence`]s, a guess `T_world_rig`, [`SolverOptions`]. Out: a [`Solution`].
//!
//! KH's E_p1 measures a point against two vectors spanning the plane normal to its ray,
//! `(s_x, 0, −I_x)` and `(0, s_y, −I_y)`; for a generalised camera with any lens we take an
//! orthonormal pair u₁, u₂ ⟂ ray (KH's remark that they "can also be normalized"), so that
//! E_p1 = Σ (u_k · (Q P + s − c))² is the squared distance of the point from its ray, and E_p2
//! divides each term by |Q P + s − c|² (held fixed within an iteration, like E2). Each residual
//! is linear in Δs and δω exactly like a line end point with n replaced by u_k, so points and
//! lines go into the same 6×6 normal equations of eq. 21.

use super::covariance::covariance_mixed;
use super::residuals::{
    accumulate_line, accumulate_point, all_finite, iterate, pose_of, unknowns_of, PointObservation,
};
use crate::{Solution, SolveError, SolverOptions};
use omnitrack_core::geometry::{xi, Correspondence, Pose};

/// R_and_T (§3.1) over lines and points together from `guess`: lines use `o.error`, points use
/// E_p1 (eq. 14) when `o.error` is E1 and E_p2 (eq. 15) otherwise. `Solution.inliers` lists the
/// lines as 0..L and the points as L.. (L = number of lines); ξ is over the lines.
///
/// Errors: fewer than 3 observations in all → `TooFew`; singular normal equations or non-finite
/// input → `Degenerate`; a diverged iteration → `NoSolution`.
pub fn r_and_t_mixed(
    lines: &[Correspondence],
    points: &[PointObservation],
    guess: &Pose,
    o: &SolverOptions,
) -> Result<Solution, SolveError> {
    let got = lines.len() + points.len();
    if got < 3 {
        return Err(SolveError::TooFew { needed: 3, got });
    }
    let points_finite = points.iter().all(|p| {
        p.ray.iter().all(|v| v.is_finite())
            && p.centre.iter().all(|v| v.is_finite())
            && p.point.iter().all(|v| v.is_finite())
    });
    let guess_finite =
        guess.translation.vector.iter().all(|v| v.is_finite()) && guess.rotation.coords.iter().all(|v| v.is_finite());
    if !(all_finite(lines) && points_finite && guess_finite) {
        return Err(SolveError::Degenerate);
    }
    let (q, s) = unknowns_of(guess);
    let scale = {
        let sum: f64 = lines
            .iter()
            .flat_map(|l| {
                l.segment
                    .iter()
                    .map(move |p| (q * p.coords + s - l.edge.centre.coords).norm())
            })
            .chain(points.iter().map(|p| (q * p.point.coords + s - p.centre.coords).norm()))
            .sum();
        let d = sum / (2 * lines.len() + points.len()) as f64;
        if d.is_finite() && d > 1e-9 {
            d
        } else {
            1.0
        }
    };
    let error = o.error;
    let r = iterate(q, s, scale, o.max_iterations, o.convergence_rad, |q, s, h, g| {
        for l in lines {
            accumulate_line(l, q, s, error, h, g);
        }
        for p in points {
            accumulate_point(p, q, s, error, h, g);
        }
    })?;
    let pose = pose_of(&r.q, &r.s);
    Ok(Solution {
        pose,
        covariance: covariance_mixed(lines, points, &pose, o),
        inliers: (0..got).collect(),
        xi_rad2: xi(lines, &pose),
        iterations: r.iterations,
        converged: r.converged,
    })
}
