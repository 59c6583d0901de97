//! Lens models: sensor-frame point → pixel (`project`), pixel → unit ray (`unproject`), and the
//! 2×3 Jacobian of projection.
//!
//! In: points in the sensor frame (OpenCV camera frame: x right, y down, z along the optical axis)
//! or pixels (OpenCV convention, (0,0) is the centre of the top-left pixel).
//! Out: pixels, or unit rays in the sensor frame.
//!
//! `Kb4` is the Kannala–Brandt equidistant model exactly as OpenCV's `cv::fisheye` defines it,
//! valid beyond 90° off-axis (z < 0) for wide lenses. Its inverse is solved by a safeguarded
//! Newton iteration on the monotonic part of θ ↦ θd, which is found once when the lens is built,
//! so that unproject is exact (to ~1e-15 rad) everywhere the model is invertible and says `None`
//! where it is not, instead of returning a wrong ray.

use nalgebra::{Matrix2x3, Point2, Unit, Vector2, Vector3};

/// An ideal perspective lens: u = fx·x/z + cx, v = fy·y/z + cy.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pinhole {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
}

/// OpenCV fisheye (Kannala–Brandt, equidistant) lens: θd = θ(1 + k1θ² + k2θ⁴ + k3θ⁶ + k4θ⁸).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Kb4 {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub k: [f64; 4],
    /// Largest θ (rad) up to which θd(θ) rises monotonically (capped at π): the model's domain.
    theta_max: f64,
    /// θd(theta_max): larger distorted radii have no preimage.
    theta_d_max: f64,
}

/// The lens of one sensor. One type for every lens so that the rest of the code never matches on
/// the model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Lens {
    Pinhole(Pinhole),
    Kb4(Kb4),
}

/// Why a lens could not be built from its parameters.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LensError {
    #[error("focal lengths must be finite and positive (fx = {fx}, fy = {fy})")]
    BadFocal { fx: f64, fy: f64 },
    #[error("principal point must be finite (cx = {cx}, cy = {cy})")]
    BadCentre { cx: f64, cy: f64 },
    #[error("distortion coefficients must be finite ({k:?})")]
    BadDistortion { k: [f64; 4] },
    #[error(
        "distortion {k:?} folds the image back on itself at θ = {theta_deg:.1}° (dθd/dθ ≤ 0): \
         the lens would see less than {theta_deg:.1}° off-axis"
    )]
    Folds { k: [f64; 4], theta_deg: f64 },
}

fn check_intrinsics(fx: f64, fy: f64, cx: f64, cy: f64) -> Result<(), LensError> {
    if !(fx.is_finite() && fy.is_finite() && fx > 0.0 && fy > 0.0) {
        return Err(LensError::BadFocal { fx, fy });
    }
    if !(cx.is_finite() && cy.is_finite()) {
        return Err(LensError::BadCentre { cx, cy });
    }
    Ok(())
}

impl Pinhole {
    pub fn new(fx: f64, fy: f64, cx: f64, cy: f64) -> Result<Self, LensError> {
        check_intrinsics(fx, fy, cx, cy)?;
        Ok(Self { fx, fy, cx, cy })
    }
}

/// Smallest angle a KB4 lens must cover before its polynomial may turn: below this a lens is
/// useless, and a fold this early means the coefficients are wrong.
const KB4_MIN_DOMAIN: f64 = 0.35; // 20°

impl Kb4 {
    pub fn new(fx: f64, fy: f64, cx: f64, cy: f64, k: [f64; 4]) -> Result<Self, LensError> {
        check_intrinsics(fx, fy, cx, cy)?;
        if k.iter().any(|c| !c.is_finite()) {
            return Err(LensError::BadDistortion { k });
        }
        let theta_max = monotonic_limit(&k);
        if theta_max < KB4_MIN_DOMAIN {
            return Err(LensError::Folds {
                k,
                theta_deg: theta_max.to_degrees(),
            });
        }
        let theta_d_max = distort(&k, theta_max);
        Ok(Self {
            fx,
            fy,
            cx,
            cy,
            k,
            theta_max,
            theta_d_max,
        })
    }

    /// The largest off-axis angle (rad) the model can represent; rays beyond it do not project.
    pub fn max_theta(&self) -> f64 {
        self.theta_max
    }

    /// θ from θd by Newton's method kept inside a shrinking bracket [lo, hi] ⊂ [0, θmax], where
    /// θd(θ) is strictly increasing, so the root is unique and the iteration cannot escape.
    fn undistort(&self, theta_d: f64) -> Option<f64> {
        if !(0.0..=self.theta_d_max).contains(&theta_d) {
            return None;
        }
        let (mut lo, mut hi) = (0.0, self.theta_max);
        let mut theta = theta_d.min(hi);
        for _ in 0..100 {
            let f = distort(&self.k, theta) - theta_d;
            if f > 0.0 {
                hi = theta;
            } else {
                lo = theta;
            }
            let df = distort_derivative(&self.k, theta);
            let mut next = theta - f / df;
            if !(next > lo && next < hi && next.is_finite()) {
                next = 0.5 * (lo + hi);
            }
            let step = (next - theta).abs();
            theta = next;
            if step < 1e-15 || hi - lo < 1e-15 {
                break;
            }
        }
        Some(theta)
    }
}

/// θd(θ) = θ(1 + k1θ² + k2θ⁴ + k3θ⁶ + k4θ⁸).
#[inline]
fn distort(k: &[f64; 4], theta: f64) -> f64 {
    let t2 = theta * theta;
    theta * (1.0 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3]))))
}

/// dθd/dθ = 1 + 3k1θ² + 5k2θ⁴ + 7k3θ⁶ + 9k4θ⁸.
#[inline]
fn distort_derivative(k: &[f64; 4], theta: f64) -> f64 {
    let t2 = theta * theta;
    1.0 + t2 * (3.0 * k[0] + t2 * (5.0 * k[1] + t2 * (7.0 * k[2] + t2 * 9.0 * k[3])))
}

/// First θ in (0, π] where dθd/dθ reaches zero (or π if it never does), by a fine scan and then
/// bisection. The scan step (0.1°) is far below the spacing of the derivative's roots for any
/// physical lens.
fn monotonic_limit(k: &[f64; 4]) -> f64 {
    let n = 1800;
    let step = std::f64::consts::PI / n as f64;
    let mut prev = 0.0;
    for i in 1..=n {
        let theta = i as f64 * step;
        if distort_derivative(k, theta) <= 0.0 {
            let (mut lo, mut hi) = (prev, theta);
            for _ in 0..200 {
                let mid = 0.5 * (lo + hi);
                if distort_derivative(k, mid) > 0.0 {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            return lo;
        }
        prev = theta;
    }
    std::f64::consts::PI
}

impl Lens {
    pub fn fx(&self) -> f64 {
        match self {
            Lens::Pinhole(l) => l.fx,
            Lens::Kb4(l) => l.fx,
        }
    }
    pub fn fy(&self) -> f64 {
        match self {
            Lens::Pinhole(l) => l.fy,
            Lens::Kb4(l) => l.fy,
        }
    }
    pub fn principal_point(&self) -> Point2<f64> {
        match self {
            Lens::Pinhole(l) => Point2::new(l.cx, l.cy),
            Lens::Kb4(l) => Point2::new(l.cx, l.cy),
        }
    }

    /// Largest angle (rad) between the optical axis and a ray the lens can image, ignoring the
    /// sensor's borders: π/2 for a pinhole, the model's monotonic domain for KB4.
    pub fn max_theta(&self) -> f64 {
        match self {
            Lens::Pinhole(_) => std::f64::consts::FRAC_PI_2,
            Lens::Kb4(l) => l.theta_max,
        }
    }

    /// Pixel of a sensor-frame point, or `None` if the lens cannot image it (behind a pinhole,
    /// beyond a fisheye's domain, or at the centre of projection).
    #[inline]
    pub fn project(&self, p: &Vector3<f64>) -> Option<Point2<f64>> {
        match self {
            Lens::Pinhole(l) => {
                if p.z <= 0.0 || !p.z.is_finite() {
                    return None;
                }
                Some(Point2::new(l.fx * p.x / p.z + l.cx, l.fy * p.y / p.z + l.cy))
            }
            Lens::Kb4(l) => {
                let s = kb4_scale(l, p)?;
                Some(Point2::new(l.fx * s * p.x + l.cx, l.fy * s * p.y + l.cy))
            }
        }
    }

    /// Unit ray (sensor frame) through a pixel, or `None` where the lens model has no preimage.
    /// The pixel need not lie inside the image.
    #[inline]
    pub fn unproject(&self, px: &Point2<f64>) -> Option<Unit<Vector3<f64>>> {
        match self {
            Lens::Pinhole(l) => {
                let v = Vector3::new((px.x - l.cx) / l.fx, (px.y - l.cy) / l.fy, 1.0);
                v.iter().all(|c| c.is_finite()).then(|| Unit::new_normalize(v))
            }
            Lens::Kb4(l) => {
                let m = Vector2::new((px.x - l.cx) / l.fx, (px.y - l.cy) / l.fy);
                let theta_d = m.norm();
                if !theta_d.is_finite() {
                    return None;
                }
                if theta_d == 0.0 {
                    return Some(Vector3::z_axis());
                }
                let theta = l.undistort(theta_d)?;
                let (sin, cos) = theta.sin_cos();
                let dir = m / theta_d * sin;
                Some(Unit::new_unchecked(Vector3::new(dir.x, dir.y, cos)))
            }
        }
    }

    /// d(pixel)/d(point) at a sensor-frame point, or `None` where `project` is `None`.
    pub fn project_jacobian(&self, p: &Vector3<f64>) -> Option<Matrix2x3<f64>> {
        match self {
            Lens::Pinhole(l) => {
                if p.z <= 0.0 || !p.z.is_finite() {
                    return None;
                }
                let iz = 1.0 / p.z;
                Some(Matrix2x3::new(
                    l.fx * iz,
                    0.0,
                    -l.fx * p.x * iz * iz,
                    0.0,
                    l.fy * iz,
                    -l.fy * p.y * iz * iz,
                ))
            }
            Lens::Kb4(l) => {
                // u = fx·s(r, z)·x + cx with s = θd(θ)/r, θ = atan2(r, z), r = √(x² + y²).
                let s = kb4_scale(l, p)?;
                let r2 = p.x * p.x + p.y * p.y;
                let r = r2.sqrt();
                let rho2 = r2 + p.z * p.z;
                let (ds_dr, ds_dz) = if r < 1e-9 * rho2.sqrt() {
                    // On the axis s is even in r (ds/dr → 0) and s → θd'(0)/z = 1/z.
                    (0.0, -1.0 / (p.z * p.z))
                } else {
                    let theta = r.atan2(p.z);
                    let dtd = distort_derivative(&l.k, theta);
                    let dtheta_dr = p.z / rho2;
                    let dtheta_dz = -r / rho2;
                    ((dtd * dtheta_dr - s) / r, dtd * dtheta_dz / r)
                };
                let (dr_dx, dr_dy) = if r > 0.0 { (p.x / r, p.y / r) } else { (0.0, 0.0) };
                Some(Matrix2x3::new(
                    l.fx * (s + p.x * ds_dr * dr_dx),
                    l.fx * p.x * ds_dr * dr_dy,
                    l.fx * p.x * ds_dz,
                    l.fy * p.y * ds_dr * dr_dx,
                    l.fy * (s + p.y * ds_dr * dr_dy),
                    l.fy * p.y * ds_dz,
                ))
            }
        }
    }
}

/// s = θd/r, the factor taking (x, y) to normalised distorted coordinates, with its on-axis limit.
#[inline]
fn kb4_scale(l: &Kb4, p: &Vector3<f64>) -> Option<f64> {
    let r = (p.x * p.x + p.y * p.y).sqrt();
    if !(r.is_finite() && p.z.is_finite()) {
        return None;
    }
    let rho = (r * r + p.z * p.z).sqrt();
    if rho == 0.0 {
        return None;
    }
    if r < 1e-9 * rho {
        // θ ≈ r/z near the axis; straight behind the lens there is no direction to image.
        return (p.z > 0.0).then(|| 1.0 / p.z);
    }
    let theta = r.atan2(p.z);
    if theta > l.theta_max {
        return None;
    }
    Some(distort(&l.k, theta) / r)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn folding_distortion_is_rejected() {
        // dθd/dθ = 1 − 3θ² vanishes at θ ≈ 33°.
        let e = Kb4::new(300.0, 300.0, 256.0, 192.0, [-1.0, 0.0, 0.0, 0.0]).unwrap();
        assert!((e.max_theta() - (1.0f64 / 3.0).sqrt()).abs() < 1e-12);
        assert!(matches!(
            Kb4::new(300.0, 300.0, 256.0, 192.0, [-3.0, 0.0, 0.0, 0.0]),
            Err(LensError::Folds { .. })
        ));
        assert!(Kb4::new(0.0, 300.0, 256.0, 192.0, [0.0; 4]).is_err());
        assert!(Kb4::new(300.0, 300.0, f64::NAN, 192.0, [0.0; 4]).is_err());
    }

    #[test]
    fn beyond_the_domain_is_none_not_wrong() {
        let k = Kb4::new(300.0, 300.0, 256.0, 192.0, [-1.0, 0.0, 0.0, 0.0]).unwrap();
        let lens = Lens::Kb4(k);
        let far = Point2::new(256.0 + 300.0 * (k.theta_d_max + 0.01), 192.0);
        assert!(lens.unproject(&far).is_none());
        let behind = Vector3::new(1.0, 0.0, -1.0);
        assert!(lens.project(&behind).is_none());
        assert!(Lens::Pinhole(Pinhole::new(1.0, 1.0, 0.0, 0.0).unwrap())
            .project(&Vector3::new(0.0, 0.0, -1.0))
            .is_none());
    }
}
