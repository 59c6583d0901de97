//! The double sphere lens ([`DoubleSphere`], Usenko, Demmel & Cremers 2018, Basalt's and
//! Kalibr's `ds`): a point is projected onto two unit spheres ξ apart, then by a pinhole shifted
//! α/(1−α) of the way off the second sphere. Closed form both ways, and beyond 90° off the axis.
//!
//! In: fx, fy, cx, cy, ξ ∈ [−1, 1], α ∈ [0, 1]. Out: checked lenses with their projection,
//! unprojection and Jacobian, which [`Lens`](super::Lens) calls.
//!
//! With d1 = |p|, s = ξ·d1 + z, d2 = √(x² + y² + s²) and den = α·d2 + (1−α)·s:
//! u = fx·x/den + cx, v = fy·y/den + cy. The model is used on the cone θ < θmax where it is
//! one-to-one: where den stays positive and the image radius still rises with the off-axis
//! angle θ, found once when the lens is built ([`one_to_one_limit`]). The paper's closed form
//! for that region (z > −w2·d1, eq. 43) is not exact: with α = 0 (the unified model) it stops
//! at 125° where ξ = 0.7 images to 134°, so the limit is measured rather than taken from it.
//! A pixel has a preimage when α ≤ ½ or r² ≤ 1/(2α−1) (r the normalised distance from the
//! centre) and its ray lies inside the cone.

use super::*;

/// Smallest field a sphere-model lens must reach off its axis (20°), as for KB4 and radtan:
/// anything narrower means the parameters are wrong.
const SPHERE_MIN_DOMAIN: f64 = 0.35;

/// `Ok` if a lens reaching `theta` off its axis is wide enough; else `what` sees too little.
pub(super) fn wide_enough(theta: f64, what: impl FnOnce() -> String) -> Result<(), LensError> {
    if theta >= SPHERE_MIN_DOMAIN {
        return Ok(());
    }
    Err(LensError::BadParameter(format!(
        "{} sees only {:.1}° off the axis",
        what(),
        theta.to_degrees()
    )))
}

/// The double sphere lens.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DoubleSphere {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub xi: f64,
    pub alpha: f64,
    /// cos θmax: the lens images z > cos_max·|p|.
    pub(super) cos_max: f64,
}

impl DoubleSphere {
    pub fn new(fx: f64, fy: f64, cx: f64, cy: f64, xi: f64, alpha: f64) -> Result<Self, LensError> {
        check_intrinsics(fx, fy, cx, cy)?;
        if !(xi.is_finite() && (-1.0..=1.0).contains(&xi)) {
            return Err(LensError::BadParameter(format!("ds: ξ must be in [−1, 1], found {xi}")));
        }
        if !(alpha.is_finite() && (0.0..=1.0).contains(&alpha)) {
            return Err(LensError::BadParameter(format!(
                "ds: α must be in [0, 1], found {alpha}"
            )));
        }
        // den′ = −α·ξ·sin θ/d2 − (1−α)·sin θ on the unit sphere (s′ = −sin θ, d2′ = −ξ·sin θ/d2).
        let slope = |t: f64| {
            let (sin, cos) = t.sin_cos();
            let s = xi + cos;
            let d2 = (sin * sin + s * s).sqrt();
            let den = alpha * d2 + (1.0 - alpha) * s;
            let dden = -alpha * xi * sin / d2 - (1.0 - alpha) * sin;
            (den > 0.0).then_some(cos * den - sin * dden)
        };
        let lens = Self {
            fx,
            fy,
            cx,
            cy,
            xi,
            alpha,
            cos_max: one_to_one_limit(slope).cos(),
        };
        wide_enough(lens.max_theta(), || format!("ds: ξ = {xi}, α = {alpha}"))?;
        Ok(lens)
    }

    /// The largest off-axis angle (rad) the model images.
    pub fn max_theta(&self) -> f64 {
        self.cos_max.clamp(-1.0, 1.0).acos()
    }

    /// (d1, s, d2, den) of a point in the valid region.
    #[inline]
    fn parts(&self, p: &Vector3<f64>) -> Option<(f64, f64, f64, f64)> {
        let d1 = p.norm();
        if !(d1.is_finite() && d1 > 0.0) || p.z <= self.cos_max * d1 {
            return None;
        }
        let s = self.xi * d1 + p.z;
        let d2 = (p.x * p.x + p.y * p.y + s * s).sqrt();
        let den = self.alpha * d2 + (1.0 - self.alpha) * s;
        (den > 0.0).then_some((d1, s, d2, den))
    }

    #[inline]
    pub(super) fn project(&self, p: &Vector3<f64>) -> Option<Point2<f64>> {
        let (_, _, _, den) = self.parts(p)?;
        Some(Point2::new(
            self.fx * p.x / den + self.cx,
            self.fy * p.y / den + self.cy,
        ))
    }

    #[inline]
    pub(super) fn unproject(&self, px: &Point2<f64>) -> Option<Unit<Vector3<f64>>> {
        let (mx, my) = ((px.x - self.cx) / self.fx, (px.y - self.cy) / self.fy);
        let r2 = mx * mx + my * my;
        let a = self.alpha;
        let root = 1.0 - (2.0 * a - 1.0) * r2;
        if !(r2.is_finite() && root >= 0.0) {
            return None;
        }
        let mz = (1.0 - a * a * r2) / (a * root.sqrt() + 1.0 - a);
        let k = (mz * self.xi + (mz * mz + (1.0 - self.xi * self.xi) * r2).sqrt()) / (mz * mz + r2);
        let ray = Unit::new_normalize(Vector3::new(k * mx, k * my, k * mz - self.xi));
        // Only rays of the one-to-one region: elsewhere the pixel has no true preimage.
        (ray.z > self.cos_max && ray.iter().all(|c| c.is_finite())).then_some(ray)
    }

    /// d(pixel)/d(point): den' = α·d2' + (1−α)·s', s' = ξ·p/d1 + e_z, d2' = (x, y, 0)/d2 + s·s'/d2.
    pub(super) fn project_jacobian(&self, p: &Vector3<f64>) -> Option<Matrix2x3<f64>> {
        let (d1, s, d2, den) = self.parts(p)?;
        let ds = p * (self.xi / d1) + Vector3::z();
        let dd2 = (Vector3::new(p.x, p.y, 0.0) + ds * s) / d2;
        let dden = dd2 * self.alpha + ds * (1.0 - self.alpha);
        Some(quotient_jacobian(self.fx, self.fy, p, den, &dden))
    }
}

/// The Jacobian of (fx·x/den, fy·y/den) given den and its gradient.
#[inline]
pub(super) fn quotient_jacobian(fx: f64, fy: f64, p: &Vector3<f64>, den: f64, dden: &Vector3<f64>) -> Matrix2x3<f64> {
    let i = 1.0 / den;
    let ux = -p.x * i * i;
    let vy = -p.y * i * i;
    Matrix2x3::new(
        fx * (i + ux * dden.x),
        fx * ux * dden.y,
        fx * ux * dden.z,
        fy * vy * dden.x,
        fy * (i + vy * dden.y),
        fy * vy * dden.z,
    )
}

/// The largest θ in (0, π] up to which a unit ray's normalised image radius m(θ) = sin θ / den(θ)
/// is defined and rising. `slope(θ)` is `None` where den(θ) ≤ 0, else cos θ·den − sin θ·den′,
/// which has the sign of m′: a scan in 0.05° steps, then bisection on that sign to 1e-15 rad.
/// For every physical lens the border is far wider than a step.
pub(super) fn one_to_one_limit(slope: impl Fn(f64) -> Option<f64>) -> f64 {
    let rising = |t: f64| matches!(slope(t), Some(g) if g > 0.0);
    let n = 3600;
    let step = std::f64::consts::PI / n as f64;
    for i in 1..=n {
        let theta = i as f64 * step;
        if !rising(theta) {
            let (mut lo, mut hi) = (theta - step, theta);
            for _ in 0..60 {
                let mid = 0.5 * (lo + hi);
                if rising(mid) {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            return lo;
        }
    }
    std::f64::consts::PI
}
