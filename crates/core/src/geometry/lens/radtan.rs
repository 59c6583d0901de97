//! The radial–tangential (Brown–Conrady, OpenCV `plumb_bob`) lens ([`Radtan`]): its
//! distortion, its inverse, and the radius within which it is monotonic.
//!
//! In: the lens's coefficients. Out: checked lenses and the helpers [`Lens`](super::Lens)
//! projects and unprojects with.

use super::*;

/// Largest normalised radius a radtan lens is taken to image (r = tan θ: 84°). OpenCV's model is
/// a pinhole's and meant for lenses well under 180°; its polynomial says nothing reliable so far
/// out, and the radius would otherwise be unbounded for a lens without distortion.
pub const RADTAN_MAX_RADIUS: f64 = 10.0;

/// Smallest normalised radius a radtan lens must cover before its polynomial may turn (tan 20°),
/// as for KB4: a fold this early means the coefficients are wrong.
const RADTAN_MIN_RADIUS: f64 = 0.364;

impl Radtan {
    /// From OpenCV's coefficients k1, k2, p1, p2 and, if given, k3.
    pub fn new(fx: f64, fy: f64, cx: f64, cy: f64, d: &[f64]) -> Result<Self, LensError> {
        check_intrinsics(fx, fy, cx, cy)?;
        if !(d.len() == 4 || d.len() == 5) || d.iter().any(|c| !c.is_finite()) {
            return Err(LensError::BadDistortion { k: d.to_vec() });
        }
        let mut c = [0.0; 5];
        c[..d.len()].copy_from_slice(d);
        let r_max = radtan_monotonic_limit(&c);
        if r_max < RADTAN_MIN_RADIUS {
            return Err(LensError::Folds {
                k: d.to_vec(),
                theta_deg: r_max.atan().to_degrees(),
            });
        }
        Ok(Self {
            fx,
            fy,
            cx,
            cy,
            d: c,
            r_max,
        })
    }

    /// The largest off-axis angle (rad) the model is taken to represent.
    pub fn max_theta(&self) -> f64 {
        self.r_max.atan()
    }

    /// (x'', y'') of normalised (x', y'), with d(x'', y'')/d(x', y') (rows x'', y'').
    #[inline]
    pub(super) fn distort(&self, m: Vector2<f64>) -> (Vector2<f64>, nalgebra::Matrix2<f64>) {
        let [k1, k2, p1, p2, k3] = self.d;
        let (x, y) = (m.x, m.y);
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        // d(radial)/dx = x·dr, d(radial)/dy = y·dr.
        let dr = 2.0 * k1 + r2 * (4.0 * k2 + 6.0 * k3 * r2);
        let out = Vector2::new(
            x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
            y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
        );
        let cross = dr * x * y + 2.0 * p1 * x + 2.0 * p2 * y;
        let jac = nalgebra::Matrix2::new(
            radial + dr * x * x + 2.0 * p1 * y + 6.0 * p2 * x,
            cross,
            cross,
            radial + dr * y * y + 6.0 * p1 * y + 2.0 * p2 * x,
        );
        (out, jac)
    }

    /// Normalised (x', y') with `distort` = `target`, by Newton's method from the target itself,
    /// inside the model's radius; `None` if it does not converge there.
    pub(super) fn undistort(&self, target: Vector2<f64>) -> Option<Vector2<f64>> {
        let mut m = target;
        for _ in 0..50 {
            let (f, j) = self.distort(m);
            let err = f - target;
            if err.norm() <= 1e-14 * (1.0 + target.norm()) {
                break;
            }
            let step = j.lu().solve(&err)?;
            let mut next = m - step;
            // Keep the iterate inside the domain, where the map is one-to-one.
            let r = next.norm();
            if r > self.r_max {
                next *= 0.5 * (m.norm() + self.r_max) / r;
            }
            m = next;
        }
        let (f, _) = self.distort(m);
        (m.norm() <= self.r_max && (f - target).norm() <= 1e-9 * (1.0 + target.norm())).then_some(m)
    }
}

/// First r in (0, RADTAN_MAX_RADIUS] where d/dr [r(1 + k1r² + k2r⁴ + k3r⁶)] = 1 + 3k1r² + 5k2r⁴
/// + 7k3r⁶ reaches zero, or RADTAN_MAX_RADIUS: a scan, then bisection.
pub(super) fn radtan_monotonic_limit(d: &[f64; 5]) -> f64 {
    let [k1, k2, _, _, k3] = *d;
    let slope = |r: f64| {
        let r2 = r * r;
        1.0 + r2 * (3.0 * k1 + r2 * (5.0 * k2 + r2 * 7.0 * k3))
    };
    let n = 4000;
    let step = RADTAN_MAX_RADIUS / n as f64;
    let mut prev = 0.0;
    for i in 1..=n {
        let r = i as f64 * step;
        if slope(r) <= 0.0 {
            let (mut lo, mut hi) = (prev, r);
            for _ in 0..200 {
                let mid = 0.5 * (lo + hi);
                if slope(mid) > 0.0 {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            return lo;
        }
        prev = r;
    }
    RADTAN_MAX_RADIUS
}

/// (x/z, y/z) of a point a radtan lens images: in front, within the model's radius.
#[inline]
pub(super) fn radtan_normalised(l: &Radtan, p: &Vector3<f64>) -> Option<Vector2<f64>> {
    if !(p.z > 0.0 && p.z.is_finite()) {
        return None;
    }
    let m = Vector2::new(p.x / p.z, p.y / p.z);
    (m.norm() <= l.r_max).then_some(m)
}
