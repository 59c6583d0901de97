//! The moments of rays and the planes through the optical centre fitted to them, shared by every
//! step: a plane's normal (the smallest eigenvector of Σ w r rᵀ, w the gradient magnitude), its
//! residual, angles along it, and the two-line test.
//!
//! In: rays (unit, sensor frame) and their weights, or their summed [`Moments`]. Out: normals,
//! residuals (Σ w sin² off the plane), angles, and whether runs of edgels are two lines.

use nalgebra::{Matrix3, Vector3};
use omnitrack_core::geometry::arc_tangent;

/// Whether runs of edgels fitted by two planes with residual `two` (Σ w sin²), and by one plane
/// with residual `one`, are two lines: the rise from two planes to one (the excess) is more
/// than noise explains and more than Σ w (`excess` · `tol`)²; `weight` is Σ w, `n` the edgels,
/// `tol` the split tolerance (sine).
///
/// For two parallel lines d apart, or meeting at a kink, the excess per unit weight is
/// (w₁w₂/(w₁+w₂)²) d²: about d²/4 when the runs are equal. For one line it is noise absorbed by
/// the second plane's three degrees of freedom: the F statistic (excess / 3) / (residual /
/// (n − 6)) stays near 1, and `TWO_LINE_F` keeps a noisy short run whole. The excess floor keeps
/// one long line whole when a regular pattern (pixel staircases) makes a tiny excess significant.
pub(super) fn two_lines_apart(one: f64, two: f64, weight: f64, n: usize, tol: f64, excess: f64) -> bool {
    let rise = one - two;
    let c = excess * tol;
    n > 6 && rise > c * c * weight && rise * (n - 6) as f64 > TWO_LINE_F * 3.0 * two.max(0.0)
}

/// See [`two_lines_apart`].
pub(super) const TWO_LINE_F: f64 = 10.0;

/// Weighted second moments of rays: Σ w r rᵀ as (xx, xy, xz, yy, yz, zz), then Σ w.
pub(super) type Moments = [f64; 7];

/// w r rᵀ as (xx, xy, xz, yy, yz, zz) and w.
#[inline]
pub(super) fn weighted_outer(r: &Vector3<f64>, w: f64) -> Moments {
    let (x, y, z) = (w * r.x, w * r.y, w * r.z);
    [x * r.x, x * r.y, x * r.z, y * r.y, y * r.z, z * r.z, w]
}

/// Weight of an edgel in the plane fits: proportional to its gradient magnitude (contrast), so
/// that faint edgels (noise, a weak neighbouring edge bleeding in) pull less.
#[inline]
pub(super) fn edgel_weight(mag: f32) -> f64 {
    mag as f64 / 1024.0
}

/// Unit normal of the plane through the origin best fitting rays with moments `m`: the
/// eigenvector of the smallest eigenvalue λ₁ of M = Σ w r rᵀ.
///
/// Rays of an edge lie close to a plane, so λ₁ is tiny beside λ₂ ≤ λ₃, and the adjugate
/// adj M = λ₂λ₃ v₁v₁ᵀ + λ₁λ₃ v₂v₂ᵀ + λ₁λ₂ v₃v₃ᵀ is v₁v₁ᵀ up to a part λ₁/λ₂ as large: its longest
/// column is v₁ to that relative error, and each further product with adj M squares it (inverse
/// iteration without a solve). A fraction of a general symmetric eigen-decomposition's cost,
/// which matters because every piece and every merge of every frame fits a plane. Degenerate
/// moments (rank ≤ 1: one ray direction) fall back to the full decomposition.
pub(super) fn plane_normal(m: &Moments) -> Option<Vector3<f64>> {
    let r0 = Vector3::new(m[0], m[1], m[2]);
    let r1 = Vector3::new(m[1], m[3], m[4]);
    let r2 = Vector3::new(m[2], m[4], m[5]);
    let cols = [r1.cross(&r2), r2.cross(&r0), r0.cross(&r1)];
    let norms = cols.map(|c| c.norm_squared());
    let k = if norms[0] >= norms[1] && norms[0] >= norms[2] {
        0
    } else if norms[1] >= norms[2] {
        1
    } else {
        2
    };
    let scale = m[0] + m[3] + m[5];
    if !(norms[k].is_finite() && norms[k] > 1e-28 * scale.powi(4)) {
        return plane_normal_eigen(m);
    }
    let mut v = cols[k] / norms[k].sqrt();
    for _ in 0..2 {
        let next = cols[0] * v.x + cols[1] * v.y + cols[2] * v.z;
        let n = next.norm();
        if !(n.is_finite() && n > 0.0) {
            break;
        }
        v = next / n;
    }
    Some(v)
}

/// [`plane_normal`] by a full symmetric eigen-decomposition.
fn plane_normal_eigen(m: &Moments) -> Option<Vector3<f64>> {
    let mat = Matrix3::new(m[0], m[1], m[2], m[1], m[3], m[4], m[2], m[4], m[5]);
    let e = mat.symmetric_eigen();
    let k = e.eigenvalues.imin();
    let v: Vector3<f64> = e.eigenvectors.column(k).into_owned();
    let n = v.norm();
    (n.is_finite() && n > 0.5).then(|| v / n)
}

/// nᵀ M n: the sum of squared sines of the rays' angles off the plane.
pub(super) fn plane_residual(m: &Moments, n: &Vector3<f64>) -> f64 {
    let mat = Matrix3::new(m[0], m[1], m[2], m[1], m[3], m[4], m[2], m[4], m[5]);
    n.dot(&(mat * n))
}

/// Angle of ray `r` around the plane normal `n`, from the reference direction `e1`.
#[inline]
pub(super) fn angle_in_plane(n: &Vector3<f64>, e1: &Vector3<f64>, r: &Vector3<f64>) -> f64 {
    let e2 = n.cross(e1);
    arc_tangent(r.dot(&e2), r.dot(e1))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Unit;
    use rand::rngs::SmallRng;
    use rand::{Rng, SeedableRng};

    /// The adjugate's normal is the smallest eigenvector, on rays from short and long arcs of
    /// random great circles with noise off the plane, down to pieces of a few edgels.
    #[test]
    fn plane_normal_matches_the_eigen_decomposition() {
        let mut rng = SmallRng::seed_from_u64(5);
        let mut worst = 0.0f64;
        for trial in 0..2000 {
            let n = Unit::new_normalize(Vector3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            ));
            let e1 = n.cross(&Vector3::new(0.3, -0.5, 0.8)).normalize();
            let e2 = n.cross(&e1);
            let length = [0.02f64, 0.1, 0.5, 2.0][trial % 4];
            let noise = [0.0f64, 1e-5, 1e-4, 1e-3][(trial / 4) % 4];
            let count = [5usize, 12, 80][(trial / 16) % 3];
            let start = rng.random_range(0.0..6.0);
            let mut m: Moments = [0.0; 7];
            for k in 0..count {
                let a = start + length * k as f64 / (count - 1) as f64;
                let off = noise * rng.random_range(-1.0..1.0);
                let r = (e1 * a.cos() + e2 * a.sin() + n.into_inner() * off).normalize();
                let o = weighted_outer(&r, rng.random_range(0.5..2.0));
                for (x, y) in m.iter_mut().zip(o) {
                    *x += y;
                }
            }
            let fast = plane_normal(&m).expect("a normal");
            let slow = plane_normal_eigen(&m).expect("a normal");
            let angle = fast.cross(&slow).norm().min(1.0).asin();
            // The normal is only defined to about noise / length: compare there.
            worst = worst.max(angle * length / (noise + 1e-9 * length));
            // Both minimise nᵀMn: the fast one is never worse than the decomposition.
            assert!(
                plane_residual(&m, &fast) <= plane_residual(&m, &slow) * (1.0 + 1e-9) + 1e-14 * m[6],
                "trial {trial} len {length} noise {noise} count {count}: {:e} vs {:e}, angle {angle:e}",
                plane_residual(&m, &fast),
                plane_residual(&m, &slow)
            );
        }
        assert!(worst < 1e-2, "worst angle {worst:e}, relative to noise / length");
    }

    /// One ray direction only: no plane, and no panic.
    #[test]
    fn plane_normal_of_degenerate_moments_falls_back() {
        let r = Vector3::new(0.0, 0.6, 0.8);
        let m = weighted_outer(&r, 3.0);
        let n = plane_normal(&m).expect("some plane through the ray");
        assert!(n.dot(&r).abs() < 1e-9);
        // No rays at all: whatever comes back is a unit vector, never NaN.
        if let Some(v) = plane_normal(&[0.0; 7]) {
            assert!((v.norm() - 1.0).abs() < 1e-9);
        }
    }
}
