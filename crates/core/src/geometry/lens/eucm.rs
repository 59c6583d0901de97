//! The enhanced unified camera model ([`Eucm`], Khomutenko, Garcia & Martinet 2016, Basalt's and
//! Kalibr's `eucm`): the unified model with the unit sphere stretched into an ellipsoid by β.
//! Closed form both ways, and beyond 90° off the axis. Basalt's `ucm` is this model with β = 1.
//!
//! In: fx, fy, cx, cy, α ∈ [0, 1], β > 0. Out: checked lenses with their projection,
//! unprojection and Jacobian, which [`Lens`](super::Lens) calls.
//!
//! With d = √(β(x² + y²) + z²) and den = α·d + (1−α)·z: u = fx·x/den + cx, v = fy·y/den + cy.
//! The model is used on the cone θ < θmax where it is one-to-one (den positive, the image
//! radius rising with the off-axis angle θ), found once when the lens is built, as for the
//! double sphere; for α ≤ ½ that is z > −w·d with w = α/(1−α) (where den reaches 0). A pixel
//! has a preimage when α ≤ ½ or r² ≤ 1/(β(2α−1)) (r the normalised distance from the centre)
//! and its ray lies inside the cone.

use super::ds::{one_to_one_limit, quotient_jacobian, wide_enough};
use super::*;

/// The enhanced unified camera model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Eucm {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub alpha: f64,
    pub beta: f64,
    /// cos θmax: the lens images z > cos_max·|p|.
    pub(super) cos_max: f64,
}

impl Eucm {
    pub fn new(fx: f64, fy: f64, cx: f64, cy: f64, alpha: f64, beta: f64) -> Result<Self, LensError> {
        check_intrinsics(fx, fy, cx, cy)?;
        if !(alpha.is_finite() && (0.0..=1.0).contains(&alpha)) {
            return Err(LensError::BadParameter(format!(
                "eucm: α must be in [0, 1], found {alpha}"
            )));
        }
        if !(beta.is_finite() && beta > 0.0) {
            return Err(LensError::BadParameter(format!(
                "eucm: β must be positive, found {beta}"
            )));
        }
        // den′ = α·(β−1)·sin θ·cos θ/d − (1−α)·sin θ on the unit sphere.
        let slope = |t: f64| {
            let (sin, cos) = t.sin_cos();
            let d = (beta * sin * sin + cos * cos).sqrt();
            let den = alpha * d + (1.0 - alpha) * cos;
            let dden = alpha * (beta - 1.0) * sin * cos / d - (1.0 - alpha) * sin;
            (den > 0.0).then_some(cos * den - sin * dden)
        };
        let lens = Self {
            fx,
            fy,
            cx,
            cy,
            alpha,
            beta,
            cos_max: one_to_one_limit(slope).cos(),
        };
        wide_enough(lens.max_theta(), || format!("eucm: α = {alpha}, β = {beta}"))?;
        Ok(lens)
    }

    /// The largest off-axis angle (rad) the model images.
    pub fn max_theta(&self) -> f64 {
        self.cos_max.clamp(-1.0, 1.0).acos()
    }

    /// (d, den) of a point in the valid region.
    #[inline]
    fn parts(&self, p: &Vector3<f64>) -> Option<(f64, f64)> {
        let d = (self.beta * (p.x * p.x + p.y * p.y) + p.z * p.z).sqrt();
        if !(d.is_finite() && d > 0.0) || p.z <= self.cos_max * p.norm() {
            return None;
        }
        let den = self.alpha * d + (1.0 - self.alpha) * p.z;
        (den > 0.0).then_some((d, den))
    }

    #[inline]
    pub(super) fn project(&self, p: &Vector3<f64>) -> Option<Point2<f64>> {
        let (_, den) = self.parts(p)?;
        Some(Point2::new(
            self.fx * p.x / den + self.cx,
            self.fy * p.y / den + self.cy,
        ))
    }

    #[inline]
    pub(super) fn unproject(&self, px: &Point2<f64>) -> Option<Unit<Vector3<f64>>> {
        let (mx, my) = ((px.x - self.cx) / self.fx, (px.y - self.cy) / self.fy);
        let r2 = mx * mx + my * my;
        let (a, b) = (self.alpha, self.beta);
        let root = 1.0 - (2.0 * a - 1.0) * b * r2;
        if !(r2.is_finite() && root >= 0.0) {
            return None;
        }
        let mz = (1.0 - a * a * b * r2) / (a * root.sqrt() + 1.0 - a);
        let ray = Unit::new_normalize(Vector3::new(mx, my, mz));
        // Only rays of the one-to-one region: elsewhere the pixel has no true preimage.
        (ray.z > self.cos_max && ray.iter().all(|c| c.is_finite())).then_some(ray)
    }

    /// d(pixel)/d(point): den' = α·(βx, βy, z)/d + (1−α)·e_z.
    pub(super) fn project_jacobian(&self, p: &Vector3<f64>) -> Option<Matrix2x3<f64>> {
        let (d, den) = self.parts(p)?;
        let dd = Vector3::new(self.beta * p.x, self.beta * p.y, p.z) / d;
        let dden = dd * self.alpha + Vector3::z() * (1.0 - self.alpha);
        Some(quotient_jacobian(self.fx, self.fy, p, den, &dden))
    }
}
