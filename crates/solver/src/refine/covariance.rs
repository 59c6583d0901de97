//! Kumar & Hanson §5 (eqs. 23–40) for our observation: the covariance of a solved pose.
//!
//! In: the correspondences a pose was fitted to, that pose (`T_world_rig`), [`SolverOptions`]
//! (`error` picks the normal equations, `edge_sigma_rad` the noise). Out: the 6×6 covariance over
//! (tx, ty, tz, rx, ry, rz) of `T_world_rig`: the rig position in the world and a small rotation
//! vector in the world frame (`T_world_rig ← exp(δθ) T_world_rig`).
//!
//! Noise model. KH perturb an image line's (ρ, θ); for an edge plane those become rotations of
//! its normal n about the edge's mid-point ray m (Δθ: δn ∥ m × n) and about the in-plane
//! perpendicular n × m (Δρ: δn ∥ m). Both have σ = `edge_sigma_rad` and are independent, so
//! δn ~ N(0, σ² (I − n nᵀ)). Each residual of the fit changes to first order by `a · δn`
//! (E1/E2: a = Q P + s − c, KH's `ΔN · p_c`; E3: the observed end ray, which moves with the
//! plane). As in eqs. 29–35 the solution moves by `x = −H⁻¹ Σ w J (a · δn)` with H = [C F; Fᵀ D]
//! the normal matrix at the solution, so Cov(Δs, δω) = H⁻¹ (Σ_lines σ² K P Kᵀ) H⁻¹ with
//! K = Σ_k w_k J_k a_kᵀ over the line's two residuals and P = I − n nᵀ: eqs. 39–40 in matrix form,
//! keeping the cross terms. Point observations (see `points`) add the same with the ray in the
//! place of n. Last, the rig-frame (Δs, δω) of `T_rig_world` maps linearly to the world frame.
//!
//! Valid near the true pose only (KH's caveat): the analysis is local.

use super::residuals::{line_residuals, point_residuals, unknowns_of, PointObservation};
use crate::{LineError, SolverOptions};
use nalgebra::{Matrix3, Matrix6, Matrix6x3, Vector3};
use omnitrack_core::geometry::{Correspondence, Pose};

/// The covariance of `pose` fitted to `c` with `o.error` under edge-normal noise of σ =
/// `o.edge_sigma_rad`, over (tx, ty, tz, rx, ry, rz) in the world frame. A pose the lines do not
/// fix gets infinite variances.
pub fn covariance(c: &[Correspondence], pose: &Pose, o: &SolverOptions) -> Matrix6<f64> {
    covariance_mixed(c, &[], pose, o)
}

/// [`covariance`] for lines plus point observations (each ray with σ = `o.edge_sigma_rad` in
/// both directions perpendicular to it).
pub fn covariance_mixed(
    lines: &[Correspondence],
    points: &[PointObservation],
    pose: &Pose,
    o: &SolverOptions,
) -> Matrix6<f64> {
    let (q, s) = unknowns_of(pose);
    let sigma2 = o.edge_sigma_rad * o.edge_sigma_rad;
    let mut h = Matrix6::zeros();
    let mut m = Matrix6::zeros();
    for l in lines {
        let Some(res) = line_residuals(l, &q, &s, o.error) else {
            continue;
        };
        let n = l.edge.normal.into_inner();
        let a = match o.error {
            LineError::E1 | LineError::E2 => l.segment.map(|p| q * p.coords + s - l.edge.centre.coords),
            LineError::E3 => {
                // r_j = e_j · m; e_j is moved into the noisy plane along n: δe_j = −n (δn · e_j).
                let big_a = q * l.segment[0].coords + s - l.edge.centre.coords;
                let big_b = q * l.segment[1].coords + s - l.edge.centre.coords;
                let sign = n.dot(&big_a.cross(&big_b)).signum();
                l.edge.ends.map(|e| -sign * e.into_inner())
            }
        };
        add_block(&mut h, &mut m, &res.jacobian, &res.weight, &a, &n, sigma2);
    }
    for p in points {
        let Some((res, a)) = point_residuals(p, &q, &s, o.error) else {
            continue;
        };
        let ray = p.ray.into_inner();
        // The two residuals share the ray's noise, so they go in as one block.
        add_block(&mut h, &mut m, &res.jacobian, &res.weight, &a, &ray, sigma2);
    }
    let Some(h_inv) = h.cholesky().map(|c| c.inverse()) else {
        return Matrix6::from_diagonal_element(f64::INFINITY);
    };
    if !h_inv.iter().all(|v| v.is_finite()) {
        return Matrix6::from_diagonal_element(f64::INFINITY);
    }
    let cov_rig = h_inv * m * h_inv;
    // (Δs, δω) of T_rig_world = (Q, s) → (δt, δθ) of T_world_rig = (Qᵀ, −Qᵀ s):
    // δt = −Qᵀ Δs − Qᵀ [s]× δω, δθ = −Qᵀ δω.
    let qt = q.inverse().to_rotation_matrix().into_inner();
    let mut g = Matrix6::zeros();
    g.fixed_view_mut::<3, 3>(0, 0).copy_from(&-qt);
    g.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-qt * s.cross_matrix()));
    g.fixed_view_mut::<3, 3>(3, 3).copy_from(&-qt);
    let cov = g * cov_rig * g.transpose();
    (cov + cov.transpose()) * 0.5
}

/// Adds one noise source's residuals (rows `j`, weights `w`) to H, and `σ² K P Kᵀ` to the middle term, where the noise
/// vector δ (normal or ray `axis`) has covariance σ² (I − axis axisᵀ) and moves residual k by
/// `a_k · δ`.
fn add_block<const N: usize>(
    h: &mut Matrix6<f64>,
    m: &mut Matrix6<f64>,
    j: &[nalgebra::Vector6<f64>; N],
    w: &[f64; N],
    a: &[Vector3<f64>; N],
    axis: &Vector3<f64>,
    sigma2: f64,
) {
    let mut k = Matrix6x3::zeros();
    for i in 0..N {
        h.ger(w[i], &j[i], &j[i], 1.0);
        k.ger(w[i], &j[i], &a[i], 1.0);
    }
    let p = Matrix3::identity() - axis * axis.transpose();
    *m += k * p * k.transpose() * sigma2;
}
