//! The Kannala–Brandt fisheye lens ([`Kb4`]): θ_d = θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸),
//! its inverse by Newton's method, and the domain over which it is monotonic.
//!
//! In: the lens's coefficients. Out: checked lenses and the helpers [`Lens`](super::Lens)
//! projects and unprojects with.

use super::*;

/// Smallest angle a KB4 lens must cover before its polynomial may turn: below this a lens is
/// useless, and a fold this early means the coefficients are wrong.
const KB4_MIN_DOMAIN: f64 = 0.35; // 20°

impl Kb4 {
    pub fn new(fx: f64, fy: f64, cx: f64, cy: f64, k: [f64; 4]) -> Result<Self, LensError> {
        check_intrinsics(fx, fy, cx, cy)?;
        if k.iter().any(|c| !c.is_finite()) {
            return Err(LensError::BadDistortion { k: k.to_vec() });
        }
        let theta_max = monotonic_limit(&k);
        if theta_max < KB4_MIN_DOMAIN {
            return Err(LensError::Folds {
                k: k.to_vec(),
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
    pub(super) fn undistort(&self, theta_d: f64) -> Option<f64> {
        if !(0.0..=self.theta_d_max).contains(&theta_d) {
            return None;
        }
        let (mut lo, mut hi) = (0.0, self.theta_max);
        let mut theta = theta_d.min(hi);
        for _ in 0..100 {
            let f = distort(&self.k, theta) - theta_d;
            // On the root: done. (Going on, the bracket's end just moved onto θ refuses the
            // zero Newton step and bisects, and the search wandered on for some fifty more
            // steps: 27 on average, where 4 reach the root; the renders and the edge stage's
            // per-pixel rays spent most of their set-up time here.)
            if f == 0.0 {
                break;
            }
            if f > 0.0 {
                hi = theta;
            } else {
                lo = theta;
            }
            let df = distort_derivative(&self.k, theta);
            let mut next = theta - f / df;
            // Newton's step is below θ's precision: θ is the root as closely as it can be.
            if next == theta {
                break;
            }
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
pub(super) fn distort(k: &[f64; 4], theta: f64) -> f64 {
    let t2 = theta * theta;
    theta * (1.0 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3]))))
}

/// dθd/dθ = 1 + 3k1θ² + 5k2θ⁴ + 7k3θ⁶ + 9k4θ⁸.
#[inline]
pub(super) fn distort_derivative(k: &[f64; 4], theta: f64) -> f64 {
    let t2 = theta * theta;
    1.0 + t2 * (3.0 * k[0] + t2 * (5.0 * k[1] + t2 * (7.0 * k[2] + t2 * 9.0 * k[3])))
}

/// First θ in (0, π] where dθd/dθ reaches zero (or π if it never does), by a fine scan and then
/// bisection. The scan step (0.1°) is far below the spacing of the derivative's roots for any
/// physical lens.
pub(super) fn monotonic_limit(k: &[f64; 4]) -> f64 {
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

/// s = θd/r, the factor taking (x, y) to normalised distorted coordinates, with its on-axis limit.
#[inline]
pub(super) fn kb4_scale(l: &Kb4, p: &Vector3<f64>) -> Option<f64> {
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
