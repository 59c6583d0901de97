//! Koch–Teller's pose refinement (§4, Fig. 7 line 8): minimise ξ (eq. 1), the mean squared angle
//! between observed and predicted edge planes, with the Nelder–Mead downhill simplex.
//!
//! In: [`Correspondence`]s, a starting `T_world_rig`, [`SimplexOptions`]. Out: the pose at the
//! minimum, ξ there (rad²), the simplex steps taken and whether the convergence test was met.
//!
//! The unknowns are offsets from the starting pose, `x = (tx, ty, tz, rx, ry, rz)`: the rig
//! position moves by `t` in the world frame and the rotation is pre-multiplied by the small
//! rotation vector `r` (world frame), `T(x) = (t0 + t, exp(r) · R0)` — the same parameters, in the
//! same order, as [`Solution::covariance`]. Everything lives in fixed-size arrays: a call
//! allocates nothing, so the tracker's consensus sampler can call it per sample.
//!
//! [`minimise_xi_upright`] is the special case of KT §5.4 (a rig held upright): only the position
//! in the ground plane (x, y) and the yaw about world z are free; height, roll and pitch stay at
//! the starting pose's.

use crate::{Solution, SolveError, SolverOptions};
use nalgebra::{Matrix3x6, Matrix6, Translation3, UnitQuaternion, Vector3};
use omnitrack_core::geometry::{xi, Correspondence, Pose};

/// Tunables of the Nelder–Mead simplex (standard coefficients: reflection 1, expansion 2,
/// contraction ½, shrink ½ — fixed, not options).
#[derive(Debug, Clone, PartialEq)]
pub struct SimplexOptions {
    /// Initial simplex edge along each rotation parameter (rad).
    pub rotation_step_rad: f64,
    /// Initial simplex edge along each translation parameter (m).
    pub translation_step_m: f64,
    /// Converged when every vertex is within this of the best one in every parameter
    /// (rad for rotations, m for translations) …
    pub x_tolerance: f64,
    /// … and the vertices' ξ values span at most this (rad²).
    pub xi_tolerance: f64,
    /// Cap on simplex steps (reflections, expansions, contractions or shrinks), restarts included.
    pub max_iterations: u32,
    /// After convergence, rebuild the simplex around the best vertex with the initial steps and
    /// continue, this many times (guards against Nelder–Mead's known stalls on a collapsed
    /// simplex; the result only ever improves).
    pub restarts: u32,
}

impl Default for SimplexOptions {
    /// 2° and 10 cm initial steps; converged at 1e-7 rad / 1e-7 m and a ξ spread of 1e-14 rad²;
    /// 3000 steps; one restart.
    fn default() -> Self {
        Self {
            rotation_step_rad: 2f64.to_radians(),
            translation_step_m: 0.10,
            x_tolerance: 1e-7,
            xi_tolerance: 1e-14,
            max_iterations: 3000,
            restarts: 1,
        }
    }
}

/// The pose at offset `x = (tx, ty, tz, rx, ry, rz)` from `start` (see the module doc).
pub fn pose_at(start: &Pose, x: &[f64; 6]) -> Pose {
    let t = start.translation.vector + Vector3::new(x[0], x[1], x[2]);
    let r = UnitQuaternion::from_scaled_axis(Vector3::new(x[3], x[4], x[5])) * start.rotation;
    Pose::from_parts(Translation3::from(t), r)
}

/// Minimises ξ over all 6 pose parameters, starting at `start`. Returns the pose at the minimum,
/// ξ there (rad²), the simplex steps taken and whether the convergence test was met before
/// `opts.max_iterations`. Allocates nothing. With no correspondences ξ is 0 everywhere and the
/// start comes back at once.
pub fn minimise_xi(c: &[Correspondence], start: &Pose, opts: &SimplexOptions) -> (Pose, f64, u32, bool) {
    let (r, t) = (opts.rotation_step_rad, opts.translation_step_m);
    let (x, f, it, conv) = nelder_mead::<6, 7>(|x| xi(c, &pose_at(start, x)), [t, t, t, r, r, r], opts);
    (pose_at(start, &x), f, it, conv)
}

/// The pose at upright offset `x = (tx, ty, yaw)` from `start`.
fn upright_pose_at(start: &Pose, x: &[f64; 3]) -> Pose {
    pose_at(start, &[x[0], x[1], 0.0, 0.0, 0.0, x[2]])
}

/// [`minimise_xi`] for an upright rig (KT §5.4): only x, y (world) and the yaw about world z are
/// free; z, roll and pitch stay those of `start`. Same returns.
pub fn minimise_xi_upright(c: &[Correspondence], start: &Pose, opts: &SimplexOptions) -> (Pose, f64, u32, bool) {
    let (r, t) = (opts.rotation_step_rad, opts.translation_step_m);
    let (x, f, it, conv) = nelder_mead::<3, 4>(|x| xi(c, &upright_pose_at(start, x)), [t, t, r], opts);
    (upright_pose_at(start, &x), f, it, conv)
}

/// ξ minimised by the simplex from `guess` over all of `c`, as a [`Solution`] (`inliers` = every
/// index; `iterations`/`converged` are the simplex's; `o.max_iterations` and
/// `o.convergence_rad` are not used — `simplex` governs the search).
///
/// Covariance: Gauss–Newton at the minimum, `Cov = σ² (JᵀJ)⁻¹` with σ = `o.edge_sigma_rad`, over
/// `(tx, ty, tz, rx, ry, rz)` in the world frame (the [`pose_at`] parameters). J is the Jacobian,
/// by central differences (step 1e-6 rad / m), of the residuals whose squares ξ averages. Since
/// α = |angle| has a kink at 0 (its derivative is undefined at a noise-free minimum), each
/// correspondence's residual is the smooth vector `n_obs × n_pred` (predicted normal's sign
/// aligned with the observed one at the minimum): its norm is sin α ≈ α, it spans the 2-D tangent
/// plane of the observed normal, and an isotropic normal error of σ per tangent axis maps onto it
/// with unit gain — so σ²(JᵀJ)⁻¹ is the first-order covariance of the pose for that noise model.
///
/// Errors: fewer than 3 correspondences ([`SolveError::TooFew`]); a non-finite ξ
/// ([`SolveError::NoSolution`]); a JᵀJ that cannot be inverted ([`SolveError::Degenerate`]).
pub fn xi_solve(
    c: &[Correspondence],
    guess: &Pose,
    o: &SolverOptions,
    simplex: &SimplexOptions,
) -> Result<Solution, SolveError> {
    if c.len() < 3 {
        return Err(SolveError::TooFew {
            needed: 3,
            got: c.len(),
        });
    }
    let (pose, xi_rad2, iterations, converged) = minimise_xi(c, guess, simplex);
    if !xi_rad2.is_finite() {
        return Err(SolveError::NoSolution);
    }
    let covariance = xi_covariance(c, &pose, o.edge_sigma_rad).ok_or(SolveError::Degenerate)?;
    Ok(Solution {
        pose,
        covariance,
        inliers: (0..c.len()).collect(),
        xi_rad2,
        iterations,
        converged,
    })
}

/// `σ² (JᵀJ)⁻¹` at `pose` over `(tx, ty, tz, rx, ry, rz)` (see [`xi_solve`]), or `None` if JᵀJ is
/// singular (or nearly: reciprocal condition below 1e-12) or a prediction is degenerate.
/// Allocates nothing.
pub fn xi_covariance(c: &[Correspondence], pose: &Pose, sigma_rad: f64) -> Option<Matrix6<f64>> {
    const H: f64 = 1e-6;
    let mut jtj = Matrix6::<f64>::zeros();
    for corr in c {
        let n = corr.edge.normal.into_inner();
        let m0 = corr.predicted_plane(pose)?.normal.into_inner();
        let sign = if n.dot(&m0) < 0.0 { -1.0 } else { 1.0 };
        let residual = |x: &[f64; 6]| -> Option<Vector3<f64>> {
            let m = corr.predicted_plane(&pose_at(pose, x))?.normal.into_inner();
            Some(n.cross(&(sign * m)))
        };
        let mut j = Matrix3x6::<f64>::zeros();
        for k in 0..6 {
            let (mut xp, mut xm) = ([0.0; 6], [0.0; 6]);
            xp[k] = H;
            xm[k] = -H;
            let d = (residual(&xp)? - residual(&xm)?) / (2.0 * H);
            j.set_column(k, &d);
        }
        jtj += j.transpose() * j;
    }
    // Symmetric positive semi-definite: Cholesky fails exactly when it is not invertible.
    let max_diag = (0..6).map(|i| jtj[(i, i)]).fold(0.0, f64::max);
    if max_diag <= 0.0 || !max_diag.is_finite() {
        return None;
    }
    let chol = jtj.cholesky()?;
    let l = chol.l();
    let min_piv = (0..6).map(|i| l[(i, i)] * l[(i, i)]).fold(f64::INFINITY, f64::min);
    if min_piv < 1e-12 * max_diag {
        return None;
    }
    let cov = chol.inverse() * (sigma_rad * sigma_rad);
    Some((cov + cov.transpose()) * 0.5)
}

/// Nelder–Mead on `N` parameters with `M = N + 1` vertices, in fixed-size arrays. The initial
/// simplex is `x0` plus `steps[i]` along each axis. Returns (best x, f there, steps, converged).
fn nelder_mead<const N: usize, const M: usize>(
    mut f: impl FnMut(&[f64; N]) -> f64,
    steps: [f64; N],
    opts: &SimplexOptions,
) -> ([f64; N], f64, u32, bool) {
    debug_assert_eq!(M, N + 1);
    // Non-finite values (degenerate predictions cannot produce them, but be safe) rank worst.
    let mut eval = |x: &[f64; N]| {
        let v = f(x);
        if v.is_nan() {
            f64::INFINITY
        } else {
            v
        }
    };
    let mut verts = [[0.0; N]; M];
    let mut vals = [0.0; M];
    let mut best = [0.0; N];
    let mut best_f = eval(&best);
    let mut iterations = 0u32;
    let mut converged = false;
    for _round in 0..=opts.restarts {
        // Build the simplex around the best point so far.
        verts[0] = best;
        vals[0] = best_f;
        for i in 0..N {
            verts[i + 1] = best;
            verts[i + 1][i] += steps[i];
            vals[i + 1] = eval(&verts[i + 1]);
        }
        converged = false;
        while iterations < opts.max_iterations {
            // Order: vertex 0 best, vertex N worst (insertion sort; M ≤ 7).
            for i in 1..M {
                let mut j = i;
                while j > 0 && vals[j] < vals[j - 1] {
                    vals.swap(j, j - 1);
                    verts.swap(j, j - 1);
                    j -= 1;
                }
            }
            let size = verts[1..]
                .iter()
                .flat_map(|v| v.iter().zip(&verts[0]).map(|(a, b)| (a - b).abs()))
                .fold(0.0, f64::max);
            if size <= opts.x_tolerance && vals[N] - vals[0] <= opts.xi_tolerance {
                converged = true;
                break;
            }
            iterations += 1;
            let mut centroid = [0.0; N];
            for v in &verts[..N] {
                for k in 0..N {
                    centroid[k] += v[k] / N as f64;
                }
            }
            let along = |t: f64| -> [f64; N] {
                let mut x = [0.0; N];
                for k in 0..N {
                    x[k] = centroid[k] + t * (verts[N][k] - centroid[k]);
                }
                x
            };
            let xr = along(-1.0);
            let fr = eval(&xr);
            if fr < vals[0] {
                let xe = along(-2.0);
                let fe = eval(&xe);
                (verts[N], vals[N]) = if fe < fr { (xe, fe) } else { (xr, fr) };
            } else if fr < vals[N - 1] {
                (verts[N], vals[N]) = (xr, fr);
            } else {
                let (xc, fc, accept) = if fr < vals[N] {
                    // Outside contraction.
                    let xc = along(-0.5);
                    let fc = eval(&xc);
                    (xc, fc, fc <= fr)
                } else {
                    // Inside contraction.
                    let xc = along(0.5);
                    let fc = eval(&xc);
                    (xc, fc, fc < vals[N])
                };
                if accept {
                    (verts[N], vals[N]) = (xc, fc);
                } else {
                    // Shrink towards the best vertex.
                    let v0 = verts[0];
                    for i in 1..M {
                        for (x, b) in verts[i].iter_mut().zip(&v0) {
                            *x = b + 0.5 * (*x - b);
                        }
                        vals[i] = eval(&verts[i]);
                    }
                }
            }
        }
        let bi = (0..M).fold(0, |b, i| if vals[i] < vals[b] { i } else { b });
        if vals[bi] <= best_f {
            best = verts[bi];
            best_f = vals[bi];
        }
        if !converged {
            break;
        }
    }
    (best, best_f, iterations, converged)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nelder_mead_finds_the_minimum_of_a_quadratic() {
        let opts = SimplexOptions {
            x_tolerance: 1e-9,
            xi_tolerance: 1e-18,
            ..Default::default()
        };
        let (x, f, _, conv) = nelder_mead::<3, 4>(
            |x| (x[0] - 1.0).powi(2) + 10.0 * (x[1] + 2.0).powi(2) + (x[2] - 0.5).powi(2) + 3.0,
            [0.1; 3],
            &opts,
        );
        assert!(conv);
        assert!((f - 3.0).abs() < 1e-15);
        assert!((x[0] - 1.0).abs() < 1e-8 && (x[1] + 2.0).abs() < 1e-8 && (x[2] - 0.5).abs() < 1e-8);
    }
}
