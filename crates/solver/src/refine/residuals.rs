//! The residuals and normal equations every Kumar–Hanson refinement shares (§3.1, eqs. 16–21):
//! the line errors E1, E2, E3 (eqs. 10–12) and the point errors E_p1, E_p2 (eqs. 14–15) of one
//! observation with their Jacobians, their accumulation into eq. 21's 6×6 system, its guarded
//! Cholesky solve and the linearised iteration of steps 2–4.
//!
//! In: one correspondence (edge plane ↔ model segment) or [`PointObservation`] and the unknowns
//! `T_rig_world = (Q, s)`. Out: residuals, Jacobian rows over `(Δs, δω)` and weights; a normal
//! matrix and gradient; a `Refined` pose.
//!
//! The unknown is `T_rig_world = (Q, s)`. A segment end point P seen by a sensor centred at c has
//! the residual `n · (Q P + s − c)` (KH eq. 9 with the sensor offset). Every refinement
//! linearises about the current (Q, s) with `Q ← exp(δω) Q`, `s ← s + Δs` (eq. 16:
//! `p'' = p' + δω × p'`), so every residual row has the Jacobian `[∂/∂Δs, ∂/∂δω]`; for E1 that is
//! `[n, b]` with `b = p' × n`, and the normal equations are eq. 21's
//! `[C F; Fᵀ D] [Δs; δω] = −[c̄; d̄]`. A point is measured against an orthonormal pair u₁, u₂ ⟂ its
//! ray (see `points`), linear in Δs and δω exactly like a line end point with n replaced by u_k.
//!
//! This is the bottom of the solver: R_then_T, R_and_T, the mixed and upright fits, the
//! covariance and Med_R_and_T's ranking all build on it, and it imports none of them. Nothing
//! here allocates (fixed-size nalgebra types), so Med_R_and_T can run it thousands of times per
//! frame.

use crate::{LineError, SolveError};
use nalgebra::{Isometry3, Matrix6, Point3, Translation3, Unit, UnitQuaternion, Vector3, Vector6};
use omnitrack_core::geometry::{Correspondence, Pose};

/// Smallest ratio of a Cholesky pivot to its diagonal entry (1 − R² of that unknown regressed on
/// the earlier ones) before the normal equations count as singular (§3.1: "incremental adjustments
/// cannot be computed if the six-by-six coefficient matrix becomes singular").
const SINGULAR_PIVOT_RATIO: f64 = 1e-12;

/// The two residuals of one line under one of KH's line errors, with their Jacobians with
/// respect to `(Δs, δω)` and the weights they carry in the sum of squares.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LineResiduals {
    /// E1: `n · (Q P + s − c)` per end point (m). E2: the same (the weight divides by the
    /// distance²). E3: `r_j · m`, the image end-point ray against the predicted plane's normal.
    pub r: [f64; 2],
    /// `∂r/∂(Δs, δω)` for the update `Q ← exp(δω) Q`, `s ← s + Δs` (E2's distance held fixed).
    pub jacobian: [Vector6<f64>; 2],
    /// 1 for E1 and E3, `1 / |Q P + s − c|²` for E2 (held fixed within an iteration).
    pub weight: [f64; 2],
}

/// The residuals of `c` at `T_rig_world = (q, s)` under `error`, or `None` for E3 when the
/// predicted plane is undefined (the transformed segment points at the sensor centre).
#[inline]
pub fn line_residuals(
    c: &Correspondence,
    q: &UnitQuaternion<f64>,
    s: &Vector3<f64>,
    error: LineError,
) -> Option<LineResiduals> {
    let n = c.edge.normal.into_inner();
    let centre = c.edge.centre.coords;
    let a1 = q * c.segment[0].coords;
    let a2 = q * c.segment[1].coords;
    match error {
        LineError::E1 | LineError::E2 => {
            let x1 = a1 + s - centre;
            let x2 = a2 + s - centre;
            let weight = match error {
                LineError::E2 => [1.0 / x1.norm_squared(), 1.0 / x2.norm_squared()],
                _ => [1.0, 1.0],
            };
            Some(LineResiduals {
                r: [n.dot(&x1), n.dot(&x2)],
                jacobian: [stack(&n, &a1.cross(&n)), stack(&n, &a2.cross(&n))],
                weight,
            })
        }
        LineError::E3 => {
            // Predicted plane through the centre and both transformed end points: normal
            // m = u / |u|, u = A × B. Its change: du = (A − B) × Δs + ([B]×[a']× − [A]×[b']×) δω,
            // dm = (I − m mᵀ) du / |u|; for the residual e · m the row is g = (I − m mᵀ) e / |u|
            // against du, i.e. ∂/∂Δs = g × (A − B), ∂/∂δω = (g × B) × a' − (g × A) × b'.
            let big_a = a1 + s - centre;
            let big_b = a2 + s - centre;
            let u = big_a.cross(&big_b);
            let len = u.norm();
            let spans_a_plane = len > 1e-12 * big_a.norm() * big_b.norm();
            if !spans_a_plane {
                return None;
            }
            let m = u / len;
            let row = |e: &Vector3<f64>| {
                let g = (e - m * m.dot(e)) / len;
                stack(
                    &g.cross(&(big_a - big_b)),
                    &(g.cross(&big_b).cross(&a1) - g.cross(&big_a).cross(&a2)),
                )
            };
            let (e1, e2) = (c.edge.ends[0].into_inner(), c.edge.ends[1].into_inner());
            Some(LineResiduals {
                r: [e1.dot(&m), e2.dot(&m)],
                jacobian: [row(&e1), row(&e2)],
                weight: [1.0, 1.0],
            })
        }
    }
}

#[inline]
fn stack(a: &Vector3<f64>, b: &Vector3<f64>) -> Vector6<f64> {
    Vector6::new(a.x, a.y, a.z, b.x, b.y, b.z)
}

/// Adds one line's rows to the normal equations (`h` = [C F; Fᵀ D], `g` = [c̄; d̄]) and returns its
/// share of the objective. An E3 line whose predicted plane is undefined adds its worst value (1
/// per end) and no rows.
#[inline]
pub(crate) fn accumulate_line(
    c: &Correspondence,
    q: &UnitQuaternion<f64>,
    s: &Vector3<f64>,
    error: LineError,
    h: &mut Matrix6<f64>,
    g: &mut Vector6<f64>,
) -> f64 {
    accumulate_line_scaled(c, q, s, error, 1.0, h, g)
}

/// [`accumulate_line`] with the line's rows (and its share of the objective) scaled by `scale`:
/// a weighted least-squares step.
#[inline]
pub(crate) fn accumulate_line_scaled(
    c: &Correspondence,
    q: &UnitQuaternion<f64>,
    s: &Vector3<f64>,
    error: LineError,
    scale: f64,
    h: &mut Matrix6<f64>,
    g: &mut Vector6<f64>,
) -> f64 {
    match line_residuals(c, q, s, error) {
        Some(res) => {
            let mut e = 0.0;
            for k in 0..2 {
                let (r, j, w) = (res.r[k], &res.jacobian[k], scale * res.weight[k]);
                add_outer_lower(h, w, j);
                g.axpy(w * r, j, 1.0);
                e += w * r * r;
            }
            e
        }
        None => 2.0 * scale,
    }
}

/// One line's rows of the normal equations at one `(q, s)`, as the products
/// [`accumulate_line`] adds there: fits of many subsets of a set from one start (the tracker's
/// consensus samples) add them instead of working every line's first step out again.
#[derive(Debug, Clone, Copy)]
pub(crate) struct LineRows {
    /// Per end point, `(w jᶜ) jʳ` in [`add_outer_lower`]'s order (column by column, from the
    /// diagonal down).
    h: [[f64; 21]; 2],
    /// Per end point, `(w r) j`: what `g.axpy(w r, j, 1)` adds.
    g: [[f64; 6]; 2],
    /// False for an E3 line whose predicted plane is undefined (it adds no rows).
    rows: bool,
}

impl LineRows {
    pub(crate) const NONE: LineRows = LineRows {
        h: [[0.0; 21]; 2],
        g: [[0.0; 6]; 2],
        rows: false,
    };

    /// `c`'s rows at `(q, s)` under `error`, as [`accumulate_line`] computes them.
    pub(crate) fn at(c: &Correspondence, q: &UnitQuaternion<f64>, s: &Vector3<f64>, error: LineError) -> LineRows {
        let Some(res) = line_residuals(c, q, s, error) else {
            return LineRows::NONE;
        };
        let mut rows = LineRows {
            rows: true,
            ..LineRows::NONE
        };
        for k in 0..2 {
            // `accumulate_line`'s weight is `1.0 * weight`, the weight itself.
            let (r, j, w) = (res.r[k], &res.jacobian[k], res.weight[k]);
            let mut i = 0;
            for c in 0..6 {
                let a = w * j[c];
                for r in c..6 {
                    rows.h[k][i] = a * j[r];
                    i += 1;
                }
            }
            let wr = w * r;
            for (gi, ji) in rows.g[k].iter_mut().zip(j.iter()) {
                *gi = wr * ji;
            }
        }
        rows
    }

    /// Adds the rows to `h` and `g` as [`accumulate_line`] would at their `(q, s)`: the same
    /// sums in the same order, so the same bits (axpy's `p · 1 + 1 · g` is `g + p` exactly).
    #[inline]
    pub(crate) fn add_to(&self, h: &mut Matrix6<f64>, g: &mut Vector6<f64>) {
        if !self.rows {
            return;
        }
        for k in 0..2 {
            let mut i = 0;
            for c in 0..6 {
                for r in c..6 {
                    h[(r, c)] += self.h[k][i];
                    i += 1;
                }
            }
            for (gi, p) in g.iter_mut().zip(self.g[k].iter()) {
                *gi += p;
            }
        }
    }
}

/// The objective of `error` over `c` at `(q, s)` (no normal equations).
pub(crate) fn line_error(c: &[Correspondence], q: &UnitQuaternion<f64>, s: &Vector3<f64>, error: LineError) -> f64 {
    c.iter().map(|l| line_error_of(l, q, s, error)).sum()
}

/// One line's share of the objective (both end points): [`line_residuals`]' weighted squares,
/// without the Jacobians. Med_R_and_T ranks every line at every subset pose with this, where
/// E3's Jacobian rows would be most of the cost.
#[inline]
pub(crate) fn line_error_of(c: &Correspondence, q: &UnitQuaternion<f64>, s: &Vector3<f64>, error: LineError) -> f64 {
    let centre = c.edge.centre.coords;
    let x1 = q * c.segment[0].coords + s - centre;
    let x2 = q * c.segment[1].coords + s - centre;
    match error {
        LineError::E1 | LineError::E2 => {
            let n = c.edge.normal.into_inner();
            let (r1, r2) = (n.dot(&x1), n.dot(&x2));
            match error {
                LineError::E2 => r1 * r1 / x1.norm_squared() + r2 * r2 / x2.norm_squared(),
                _ => r1 * r1 + r2 * r2,
            }
        }
        LineError::E3 => {
            let u = x1.cross(&x2);
            let len2 = u.norm_squared();
            // The plane test of `line_residuals`, squared; a NaN fails it as there.
            let spans_a_plane = len2 > 1e-24 * x1.norm_squared() * x2.norm_squared();
            if !spans_a_plane {
                return 2.0;
            }
            let (r1, r2) = (c.edge.ends[0].dot(&u), c.edge.ends[1].dot(&u));
            (r1 * r1 + r2 * r2) / len2
        }
    }
}

/// Result of one linearised refinement.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Refined {
    pub q: UnitQuaternion<f64>,
    pub s: Vector3<f64>,
    pub iterations: u32,
    pub converged: bool,
}

/// Whether a Cholesky factor's diagonal entry `l_ii` leaves its unknown determined: L_ii² is the
/// Schur-complement pivot, what unknown i adds beyond the earlier ones (false for NaN).
#[inline]
pub(crate) fn pivot_ok(l_ii: f64, h_ii: f64) -> bool {
    l_ii * l_ii > SINGULAR_PIVOT_RATIO * h_ii
}

/// `h += w j jᵀ` on the lower triangle and the diagonal only: the normal equations' matrix as
/// [`solve6`] reads it. Each entry is the one `h.ger(w, j, j, 1.0)` gives (`h + (w jᶜ) jʳ`, the
/// same operations in the same order), so the solves are bit for bit those of the full update;
/// the upper triangle, which no solve reads, is left as it was. Half the work of `ger`, and
/// without its views (the tracker's consensus runs it for every line of every iteration of about
/// a hundred samples a frame).
#[inline(always)]
pub(crate) fn add_outer_lower(h: &mut Matrix6<f64>, w: f64, j: &Vector6<f64>) {
    for c in 0..6 {
        let a = w * j[c];
        for r in c..6 {
            h[(r, c)] += a * j[r];
        }
    }
}

/// Solves the 6×6 normal equations `h x = −g` by Cholesky, refusing a (numerically) singular `h`.
/// Reads the lower triangle and the diagonal of `h` only.
///
/// The factorisation and the two triangular solves are nalgebra's (`Cholesky::new`, `solve`:
/// the same operations in the same order, so the same bits), written out for a fixed 6×6: through
/// nalgebra's generic column views they were a third of the tracker's consensus (a perf profile
/// of `cargo bench --bench tracking`, docs/decisions.md).
#[inline]
pub(crate) fn solve6(h: &Matrix6<f64>, g: &Vector6<f64>) -> Option<Vector6<f64>> {
    let mut l = *h;
    for j in 0..6 {
        for k in 0..j {
            let factor = -l[(j, k)];
            for i in j..6 {
                l[(i, j)] += factor * l[(i, k)];
            }
        }
        let diag = l[(j, j)];
        // `try_sqrt` of simba: none for a negative or NaN diagonal; nalgebra refuses a zero one.
        if diag.is_nan() || diag <= 0.0 {
            return None;
        }
        let denom = diag.sqrt();
        l[(j, j)] = denom;
        for i in j + 1..6 {
            l[(i, j)] /= denom;
        }
    }
    for i in 0..6 {
        if !pivot_ok(l[(i, i)], h[(i, i)]) {
            return None;
        }
    }
    let mut x = -g;
    // L y = −g, then Lᵀ x = y (nalgebra's dot starts from zero and adds the products in order).
    for i in 0..6 {
        let coeff = x[i] / l[(i, i)];
        x[i] = coeff;
        for k in i + 1..6 {
            x[k] += -coeff * l[(k, i)];
        }
    }
    for i in (0..6).rev() {
        let mut dot = 0.0;
        for k in i + 1..6 {
            dot += l[(k, i)] * x[k];
        }
        x[i] = (x[i] - dot) / l[(i, i)];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// KH §3.1 steps 2–4 for any residual set: `accumulate(q, s, h, g)` fills the normal equations at
/// `(q, s)`. Stops when the step (|δω| in rad, |Δs| / `scale` as its rad-equivalent) drops below
/// `o.convergence_rad` or after `o.max_iterations` steps.
#[inline]
pub(crate) fn iterate<F>(
    mut q: UnitQuaternion<f64>,
    mut s: Vector3<f64>,
    scale: f64,
    max_iterations: u32,
    convergence_rad: f64,
    mut accumulate: F,
) -> Result<Refined, SolveError>
where
    F: FnMut(&UnitQuaternion<f64>, &Vector3<f64>, &mut Matrix6<f64>, &mut Vector6<f64>),
{
    let mut iterations = 0;
    let mut converged = false;
    while iterations < max_iterations {
        let mut h = Matrix6::zeros();
        let mut g = Vector6::zeros();
        accumulate(&q, &s, &mut h, &mut g);
        let x = solve6(&h, &g).ok_or(SolveError::Degenerate)?;
        let ds = Vector3::new(x[0], x[1], x[2]);
        let dw = Vector3::new(x[3], x[4], x[5]);
        // Step 3: compose δω as a quaternion (so Q stays a rotation), add Δs.
        q = UnitQuaternion::from_scaled_axis(dw) * q;
        s += ds;
        iterations += 1;
        if dw.norm().max(ds.norm() / scale) < convergence_rad {
            converged = true;
            break;
        }
    }
    if !(q.coords.iter().all(|v| v.is_finite()) && s.iter().all(|v| v.is_finite())) {
        return Err(SolveError::NoSolution);
    }
    Ok(Refined {
        q,
        s,
        iterations,
        converged,
    })
}

/// Mean distance of the segment end points from their sensor centres at `(q, s)`: the lever arm
/// that turns a translation step into its rad-equivalent.
pub(crate) fn mean_distance(c: &[Correspondence], q: &UnitQuaternion<f64>, s: &Vector3<f64>) -> f64 {
    mean_of_distances(c.iter().map(|l| line_distance(l, q, s)).sum(), c.len())
}

/// One line's share of [`mean_distance`]'s sum: its two end points' distances from its centre.
#[inline]
pub(crate) fn line_distance(l: &Correspondence, q: &UnitQuaternion<f64>, s: &Vector3<f64>) -> f64 {
    l.segment
        .iter()
        .map(|p| (q * p.coords + s - l.edge.centre.coords).norm())
        .sum::<f64>()
}

/// [`mean_distance`] of `lines` lines from the sum of their [`line_distance`]s.
#[inline]
pub(crate) fn mean_of_distances(sum: f64, lines: usize) -> f64 {
    let d = sum / (2 * lines).max(1) as f64;
    if d.is_finite() && d > 1e-9 {
        d
    } else {
        1.0
    }
}

/// Whether every number of every correspondence is finite (solvers refuse the rest).
pub(crate) fn all_finite(c: &[Correspondence]) -> bool {
    c.iter().all(|l| {
        let e = &l.edge;
        e.normal.iter().all(|v| v.is_finite())
            && e.centre.iter().all(|v| v.is_finite())
            && e.ends.iter().all(|r| r.iter().all(|v| v.is_finite()))
            && l.segment.iter().all(|p| p.iter().all(|v| v.is_finite()))
    })
}

/// `T_rig_world` of a `T_world_rig`.
#[inline]
pub(crate) fn unknowns_of(t_world_rig: &Pose) -> Unknowns {
    let inv = t_world_rig.inverse();
    (inv.rotation, inv.translation.vector)
}

/// `T_world_rig` of the unknowns `T_rig_world = (q, s)`.
#[inline]
pub(crate) fn pose_of(q: &UnitQuaternion<f64>, s: &Vector3<f64>) -> Pose {
    Isometry3::from_parts(Translation3::from(*s), *q).inverse()
}

/// The unknowns `T_rig_world = (Q, s)`.
pub(crate) type Unknowns = (UnitQuaternion<f64>, Vector3<f64>);

/// A point landmark seen by one sensor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointObservation {
    /// Unit ray from the sensor centre towards the point, rig frame.
    pub ray: Unit<Vector3<f64>>,
    /// The sensor's optical centre, rig frame.
    pub centre: Point3<f64>,
    /// The point, world frame.
    pub point: Point3<f64>,
}

/// An orthonormal pair perpendicular to `ray` (the normalised basis of eq. 14).
#[inline]
pub fn perpendicular_basis(ray: &Vector3<f64>) -> [Vector3<f64>; 2] {
    let a = ray.abs();
    let other = if a.x <= a.y && a.x <= a.z {
        Vector3::x()
    } else if a.y <= a.z {
        Vector3::y()
    } else {
        Vector3::z()
    };
    let u1 = ray.cross(&other).normalize();
    [u1, ray.cross(&u1)]
}

/// The two residuals of a point at `T_rig_world = (q, s)`: E_p1 when `error` is E1, E_p2
/// otherwise, with Jacobians over (Δs, δω); and, per residual, the vector `a_k` with which a
/// small change δ of the ray moves it (`a_k · δ`, for the covariance).
#[inline]
pub fn point_residuals(
    p: &PointObservation,
    q: &UnitQuaternion<f64>,
    s: &Vector3<f64>,
    error: LineError,
) -> Option<(LineResiduals, [Vector3<f64>; 2])> {
    let ray = p.ray.into_inner();
    let u = perpendicular_basis(&ray);
    let rotated = q * p.point.coords;
    let x = rotated + s - p.centre.coords;
    let w = match error {
        LineError::E1 => 1.0,
        LineError::E2 | LineError::E3 => 1.0 / x.norm_squared(),
    };
    let row = |u: &Vector3<f64>| {
        let b = rotated.cross(u);
        Vector6::new(u.x, u.y, u.z, b.x, b.y, b.z)
    };
    let res = LineResiduals {
        r: [u[0].dot(&x), u[1].dot(&x)],
        jacobian: [row(&u[0]), row(&u[1])],
        weight: [w, w],
    };
    // Turning the ray by δ ⟂ ray carries its basis along: u_k' ≈ u_k − ray (u_k · δ).
    let depth = ray.dot(&x);
    (res.r.iter().all(|v| v.is_finite())).then_some((res, [-depth * u[0], -depth * u[1]]))
}

pub(crate) fn accumulate_point(
    p: &PointObservation,
    q: &UnitQuaternion<f64>,
    s: &Vector3<f64>,
    error: LineError,
    h: &mut Matrix6<f64>,
    g: &mut Vector6<f64>,
) {
    if let Some((res, _)) = point_residuals(p, q, s, error) {
        for k in 0..2 {
            add_outer_lower(h, res.weight[k], &res.jacobian[k]);
            g.axpy(res.weight[k] * res.r[k], &res.jacobian[k], 1.0);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;
    use omnitrack_core::geometry::EdgePlane;
    use rand::rngs::SmallRng;
    use rand::{Rng, SeedableRng};

    /// The ranking shortcut must be the refinement's objective: the weighted squares of
    /// [`line_residuals`], for every error, including lines that point at the centre.
    #[test]
    fn line_error_of_is_the_residuals_weighted_squares() {
        let mut rng = SmallRng::seed_from_u64(7);
        let v = |rng: &mut SmallRng, r: f64| Vector3::from_fn(|_, _| rng.random_range(-r..r));
        for _ in 0..500 {
            let centre = Point3::from(v(&mut rng, 0.2));
            let edge = EdgePlane::from_rays(centre, &v(&mut rng, 1.0), &v(&mut rng, 1.0)).unwrap();
            let segment = [Point3::from(v(&mut rng, 5.0)), Point3::from(v(&mut rng, 5.0))];
            let c = Correspondence { edge, segment };
            let q = UnitQuaternion::from_scaled_axis(v(&mut rng, 3.0));
            let s = v(&mut rng, 2.0);
            for e in [LineError::E1, LineError::E2, LineError::E3] {
                let full = match line_residuals(&c, &q, &s, e) {
                    Some(r) => (0..2).map(|k| r.weight[k] * r.r[k] * r.r[k]).sum(),
                    None => 2.0,
                };
                let fast = line_error_of(&c, &q, &s, e);
                assert!((full - fast).abs() <= 1e-12 * (1.0 + full), "{e:?}: {full} vs {fast}");
            }
        }
        // A segment through the centre spans no plane: E3's worst value, as in the refinement.
        let edge = EdgePlane::from_rays(Point3::origin(), &Vector3::x(), &Vector3::y()).unwrap();
        let (q, s) = (UnitQuaternion::identity(), Vector3::zeros());
        let through = Correspondence {
            edge,
            segment: [Point3::new(1.0, 1.0, 1.0), Point3::new(2.0, 2.0, 2.0)],
        };
        assert!(line_residuals(&through, &q, &s, LineError::E3).is_none());
        assert_eq!(line_error_of(&through, &q, &s, LineError::E3), 2.0);
    }

    /// nalgebra's solve, as `solve6` was written before: the reference it must equal bit for bit.
    fn solve6_nalgebra(h: &Matrix6<f64>, g: &Vector6<f64>) -> Option<Vector6<f64>> {
        let chol = h.cholesky()?;
        let l = chol.l_dirty();
        for i in 0..6 {
            if !pivot_ok(l[(i, i)], h[(i, i)]) {
                return None;
            }
        }
        let x = chol.solve(&-g);
        x.iter().all(|v| v.is_finite()).then_some(x)
    }

    /// The written-out normal equations give nalgebra's answers to the last bit (the tracker's
    /// poses are compared bit for bit across the change, `cargo bench --bench tracking`): on
    /// line sets of every error, on few lines (singular), and on a matrix with a zero, a negative
    /// and a NaN pivot.
    #[test]
    fn the_normal_equations_are_solved_bit_for_bit_as_nalgebra_solves_them() {
        let mut rng = SmallRng::seed_from_u64(11);
        let v = |rng: &mut SmallRng, r: f64| Vector3::from_fn(|_, _| rng.random_range(-r..r));
        let bits = |x: Option<Vector6<f64>>| x.map(|x| x.map(f64::to_bits));
        let mut solved = 0;
        for trial in 0..2000 {
            let (q, s) = (UnitQuaternion::from_scaled_axis(v(&mut rng, 3.0)), v(&mut rng, 2.0));
            let error = [LineError::E1, LineError::E2, LineError::E3][trial % 3];
            let (mut lower, mut full) = (Matrix6::zeros(), Matrix6::zeros());
            let (mut g_lower, mut g_full) = (Vector6::zeros(), Vector6::zeros());
            for _ in 0..1 + trial % 12 {
                let centre = Point3::from(v(&mut rng, 0.2));
                let Some(edge) = EdgePlane::from_rays(centre, &v(&mut rng, 1.0), &v(&mut rng, 1.0)) else {
                    continue;
                };
                let segment = [Point3::from(v(&mut rng, 5.0)), Point3::from(v(&mut rng, 5.0))];
                let c = Correspondence { edge, segment };
                let w = rng.random_range(0.1..2.0);
                accumulate_line_scaled(&c, &q, &s, error, w, &mut lower, &mut g_lower);
                if let Some(res) = line_residuals(&c, &q, &s, error) {
                    for k in 0..2 {
                        let wk = w * res.weight[k];
                        full.ger(wk, &res.jacobian[k], &res.jacobian[k], 1.0);
                        g_full.axpy(wk * res.r[k], &res.jacobian[k], 1.0);
                    }
                }
            }
            for c in 0..6 {
                for r in c..6 {
                    assert_eq!(lower[(r, c)].to_bits(), full[(r, c)].to_bits());
                }
            }
            assert_eq!(g_lower.map(f64::to_bits), g_full.map(f64::to_bits));
            let ours = solve6(&lower, &g_lower);
            assert_eq!(bits(ours), bits(solve6_nalgebra(&full, &g_full)), "trial {trial}");
            solved += usize::from(ours.is_some());
        }
        assert!(
            solved > 1000,
            "{solved} of 2000 solved: the test needs well-posed systems"
        );
        for bad in [0.0, -1.0, f64::NAN] {
            let mut h = Matrix6::identity();
            h[(3, 3)] = bad;
            assert_eq!(solve6(&h, &Vector6::repeat(1.0)), None);
            assert_eq!(solve6_nalgebra(&h, &Vector6::repeat(1.0)), None);
        }
    }
}
