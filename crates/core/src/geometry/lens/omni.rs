//! The unified omnidirectional lens with radial–tangential distortion ([`Omni`], Mei & Rives
//! 2007, Kalibr's `omni` camera with `radtan` or no distortion): a point is projected onto the
//! unit sphere, then by a pinhole ξ behind the sphere's centre, then distorted as OpenCV's
//! default model does.
//!
//! In: fx, fy, cx, cy, ξ ≥ 0, k1, k2, p1, p2. Out: checked lenses with their projection,
//! unprojection and Jacobian, which [`Lens`](super::Lens) calls.
//!
//! With ρ = |p| and s = z + ξ·ρ: (x', y') = (x/s, y/s), distorted by [`Radtan`]'s polynomial
//! into (x'', y''), u = fx·x'' + cx, v = fy·y'' + cy. The sphere's projection is one-to-one on
//! z/ρ > −min(ξ, 1/ξ); the distortion is used up to the radius where its polynomial still rises
//! (as for `radtan`, at most r = 10): the lens's domain is where both hold.

use super::ds::wide_enough;
use super::*;

/// The unified (Mei) lens with radtan distortion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Omni {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub xi: f64,
    /// The distortion on the sphere's normalised plane: a [`Radtan`] of unit focal length
    /// centred on 0 (k1, k2, p1, p2; k3 = 0).
    pub radtan: Radtan,
    /// Largest θ the lens images.
    pub(super) theta_max: f64,
}

impl Omni {
    /// From Kalibr's ξ and radtan coefficients k1, k2, p1, p2 (all zero: no distortion).
    pub fn new(fx: f64, fy: f64, cx: f64, cy: f64, xi: f64, d: [f64; 4]) -> Result<Self, LensError> {
        check_intrinsics(fx, fy, cx, cy)?;
        if !(xi.is_finite() && xi >= 0.0) {
            return Err(LensError::BadParameter(format!(
                "omni: ξ must be finite and ≥ 0, found {xi}"
            )));
        }
        let radtan = Radtan::new(1.0, 1.0, 0.0, 0.0, &d)?;
        // θ where the sphere's projection stops being one-to-one …
        let sphere = (-xi.min(1.0 / xi)).acos();
        // … and where its normalised radius sin θ / (cos θ + ξ), rising up to there, leaves the
        // distortion's domain: bisection.
        let radius = |t: f64| t.sin() / (t.cos() + xi);
        let theta_max = if radius(sphere * (1.0 - 1e-12)) <= radtan.r_max {
            sphere
        } else {
            let (mut lo, mut hi) = (0.0, sphere);
            for _ in 0..200 {
                let mid = 0.5 * (lo + hi);
                if radius(mid) <= radtan.r_max {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            lo
        };
        wide_enough(theta_max, || format!("omni: ξ = {xi} with distortion {d:?}"))?;
        Ok(Self {
            fx,
            fy,
            cx,
            cy,
            xi,
            radtan,
            theta_max,
        })
    }

    /// The largest off-axis angle (rad) the model images.
    pub fn max_theta(&self) -> f64 {
        self.theta_max
    }

    /// (x', y') and s of a point in the lens's domain.
    #[inline]
    fn normalised(&self, p: &Vector3<f64>) -> Option<(Vector2<f64>, f64, f64)> {
        let rho = p.norm();
        if !(rho.is_finite() && rho > 0.0) {
            return None;
        }
        let theta = p.xy().norm().atan2(p.z);
        if theta > self.theta_max {
            return None;
        }
        let s = p.z + self.xi * rho;
        if s.is_nan() || s <= 0.0 {
            return None;
        }
        Some((Vector2::new(p.x / s, p.y / s), s, rho))
    }

    #[inline]
    pub(super) fn project(&self, p: &Vector3<f64>) -> Option<Point2<f64>> {
        let (m, _, _) = self.normalised(p)?;
        let (d, _) = self.radtan.distort(m);
        Some(Point2::new(self.fx * d.x + self.cx, self.fy * d.y + self.cy))
    }

    #[inline]
    pub(super) fn unproject(&self, px: &Point2<f64>) -> Option<Unit<Vector3<f64>>> {
        let target = Vector2::new((px.x - self.cx) / self.fx, (px.y - self.cy) / self.fy);
        if !target.iter().all(|c| c.is_finite()) {
            return None;
        }
        let m = self.radtan.undistort(target)?;
        // The point of the unit sphere over m: the larger root of Mei's lifting, the one-to-one side.
        let r2 = m.norm_squared();
        let disc = 1.0 + (1.0 - self.xi * self.xi) * r2;
        if disc < 0.0 {
            return None;
        }
        let f = (self.xi + disc.sqrt()) / (1.0 + r2);
        let ray = Unit::new_normalize(Vector3::new(f * m.x, f * m.y, f - self.xi));
        let theta = ray.xy().norm().atan2(ray.z);
        (theta <= self.theta_max && ray.iter().all(|c| c.is_finite())).then_some(ray)
    }

    /// d(pixel)/d(point) = F · d(distort)/dm · dm/dp, with dm/dp = (e_x, e_y)/s − m·s'ᵀ/s and
    /// s' = e_z + ξ·p/ρ.
    pub(super) fn project_jacobian(&self, p: &Vector3<f64>) -> Option<Matrix2x3<f64>> {
        let (m, s, rho) = self.normalised(p)?;
        let (_, jd) = self.radtan.distort(m);
        let ds = Vector3::z() + p * (self.xi / rho);
        let is = 1.0 / s;
        let jm = Matrix2x3::new(
            is - m.x * ds.x * is,
            -m.x * ds.y * is,
            -m.x * ds.z * is,
            -m.y * ds.x * is,
            is - m.y * ds.y * is,
            -m.y * ds.z * is,
        );
        let f = nalgebra::Matrix2::new(self.fx, 0.0, 0.0, self.fy);
        Some(f * jd * jm)
    }
}
