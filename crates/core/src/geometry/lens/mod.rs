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
//!
//! `Radtan` is OpenCV's default camera model (`cv::projectPoints`: radial k1, k2, k3 and
//! tangential p1, p2; Kalibr's `pinhole-radtan`). Its domain is likewise limited to the radius
//! where the radial polynomial still rises (found when the lens is built), and its inverse is
//! Newton's method on the 2×2 distortion map, checked by re-projection.
//!
//! `Equirectangular` sees the whole sphere (a consumer 360° camera's panorama):
//! u = cx + fx·atan2(x, z), v = cy + fy·asin(y/ρ).
//!
//! `DoubleSphere` (Usenko et al. 2018), `Eucm` (Khomutenko et al. 2016) and `Omni` (Mei &
//! Rives 2007, with radtan distortion) are the wide-angle models of Basalt and Kalibr, read from
//! their calibrations exactly; each is used on the region where it is one-to-one, and says `None`
//! outside it.
//!
//! Files: the lens type, projection, unprojection and the Jacobian here; `kb4.rs` and `radtan.rs`
//! the two distorted models' construction, inverses and monotonic domains; `ds.rs`, `eucm.rs`
//! and `omni.rs` the three sphere models, each whole.

use nalgebra::{Matrix2x3, Point2, Unit, Vector2, Vector3};

mod ds;
mod eucm;
mod kb4;
mod omni;
mod radtan;

pub use ds::DoubleSphere;
pub use eucm::Eucm;
pub use omni::Omni;

use kb4::{distort_derivative, kb4_scale};
use radtan::radtan_normalised;
pub use radtan::RADTAN_MAX_RADIUS;

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

/// OpenCV's default lens (pinhole with radial and tangential distortion), on normalised
/// coordinates x' = x/z, y' = y/z, r² = x'² + y'²:
/// x'' = x'(1 + k1r² + k2r⁴ + k3r⁶) + 2p1x'y' + p2(r² + 2x'²),
/// y'' = y'(1 + k1r² + k2r⁴ + k3r⁶) + p1(r² + 2y'²) + 2p2x'y', u = fx·x'' + cx, v = fy·y'' + cy.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Radtan {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    /// k1, k2, p1, p2, k3 (OpenCV's order; k3 = 0 when four are given).
    pub d: [f64; 5],
    /// Largest normalised radius r up to which r·(1 + k1r² + k2r⁴ + k3r⁶) rises (capped at
    /// [`RADTAN_MAX_RADIUS`]): beyond it the polynomial folds the image back on itself.
    r_max: f64,
}

/// A panorama of the whole sphere: u = cx + fx·atan2(x, z) (longitude, 0 along the optical
/// axis), v = cy + fy·asin(y/ρ) (latitude, down positive like y). A W×H panorama has
/// fx = W/2π, fy = H/π, cx = (W−1)/2, cy = (H−1)/2.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Equirectangular {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
}

/// The lens of one sensor. One type for every lens so that the rest of the code never matches on
/// the model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Lens {
    Pinhole(Pinhole),
    Kb4(Kb4),
    Radtan(Radtan),
    Equirectangular(Equirectangular),
    DoubleSphere(DoubleSphere),
    Eucm(Eucm),
    Omni(Omni),
}

/// Why a lens could not be built from its parameters.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LensError {
    #[error("focal lengths must be finite and positive (fx = {fx}, fy = {fy})")]
    BadFocal { fx: f64, fy: f64 },
    #[error("principal point must be finite (cx = {cx}, cy = {cy})")]
    BadCentre { cx: f64, cy: f64 },
    #[error("distortion coefficients must be finite ({k:?})")]
    BadDistortion { k: Vec<f64> },
    #[error(
        "distortion {k:?} folds the image back on itself at θ = {theta_deg:.1}° (dθd/dθ ≤ 0): \
         the lens would see less than {theta_deg:.1}° off-axis"
    )]
    Folds { k: Vec<f64>, theta_deg: f64 },
    /// A sphere model's own parameter (ξ, α, β) out of its range, in words.
    #[error("{0}")]
    BadParameter(String),
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

impl Equirectangular {
    pub fn new(fx: f64, fy: f64, cx: f64, cy: f64) -> Result<Self, LensError> {
        check_intrinsics(fx, fy, cx, cy)?;
        Ok(Self { fx, fy, cx, cy })
    }

    /// The lens of a whole W×H panorama: fx = W/2π, fy = H/π, centred.
    pub fn for_panorama(width: u32, height: u32) -> Self {
        Self {
            fx: width as f64 / std::f64::consts::TAU,
            fy: height as f64 / std::f64::consts::PI,
            cx: (width as f64 - 1.0) / 2.0,
            cy: (height as f64 - 1.0) / 2.0,
        }
    }
}

impl Lens {
    /// The model's name in a rig file: `pinhole`, `kb4`, `radtan`, `equirectangular`, `ds`,
    /// `eucm` or `omni`.
    pub fn model_name(&self) -> &'static str {
        match self {
            Lens::Pinhole(_) => "pinhole",
            Lens::Kb4(_) => "kb4",
            Lens::Radtan(_) => "radtan",
            Lens::Equirectangular(_) => "equirectangular",
            Lens::DoubleSphere(_) => "ds",
            Lens::Eucm(_) => "eucm",
            Lens::Omni(_) => "omni",
        }
    }

    /// The parameters beyond fx, fy, cx, cy, as the rig file's `distortion` lists them (none
    /// for `pinhole` and `equirectangular`).
    pub fn parameters(&self) -> Option<Vec<f64>> {
        match self {
            Lens::Pinhole(_) | Lens::Equirectangular(_) => None,
            Lens::Kb4(l) => Some(l.k.to_vec()),
            // Four coefficients when k3 is 0, as OpenCV and Kalibr write them.
            Lens::Radtan(l) => Some(l.d[..if l.d[4] == 0.0 { 4 } else { 5 }].to_vec()),
            Lens::DoubleSphere(l) => Some(vec![l.xi, l.alpha]),
            Lens::Eucm(l) => Some(vec![l.alpha, l.beta]),
            Lens::Omni(l) => Some(vec![l.xi, l.radtan.d[0], l.radtan.d[1], l.radtan.d[2], l.radtan.d[3]]),
        }
    }

    /// The same lens for an image resampled by `scale` (0.5: 2×2 binning): focal lengths scale,
    /// and the principal point moves with pixel centres, c' = (c + ½)·scale − ½.
    pub fn resampled(&self, scale: f64) -> Lens {
        let c = |c: f64| (c + 0.5) * scale - 0.5;
        match *self {
            Lens::Pinhole(l) => Lens::Pinhole(Pinhole {
                fx: l.fx * scale,
                fy: l.fy * scale,
                cx: c(l.cx),
                cy: c(l.cy),
            }),
            Lens::Kb4(l) => Lens::Kb4(Kb4 {
                fx: l.fx * scale,
                fy: l.fy * scale,
                cx: c(l.cx),
                cy: c(l.cy),
                ..l
            }),
            Lens::Radtan(l) => Lens::Radtan(Radtan {
                fx: l.fx * scale,
                fy: l.fy * scale,
                cx: c(l.cx),
                cy: c(l.cy),
                ..l
            }),
            Lens::Equirectangular(l) => Lens::Equirectangular(Equirectangular {
                fx: l.fx * scale,
                fy: l.fy * scale,
                cx: c(l.cx),
                cy: c(l.cy),
            }),
            Lens::DoubleSphere(l) => Lens::DoubleSphere(DoubleSphere {
                fx: l.fx * scale,
                fy: l.fy * scale,
                cx: c(l.cx),
                cy: c(l.cy),
                ..l
            }),
            Lens::Eucm(l) => Lens::Eucm(Eucm {
                fx: l.fx * scale,
                fy: l.fy * scale,
                cx: c(l.cx),
                cy: c(l.cy),
                ..l
            }),
            Lens::Omni(l) => Lens::Omni(Omni {
                fx: l.fx * scale,
                fy: l.fy * scale,
                cx: c(l.cx),
                cy: c(l.cy),
                ..l
            }),
        }
    }

    pub fn fx(&self) -> f64 {
        match self {
            Lens::Pinhole(l) => l.fx,
            Lens::Kb4(l) => l.fx,
            Lens::Radtan(l) => l.fx,
            Lens::Equirectangular(l) => l.fx,
            Lens::DoubleSphere(l) => l.fx,
            Lens::Eucm(l) => l.fx,
            Lens::Omni(l) => l.fx,
        }
    }
    pub fn fy(&self) -> f64 {
        match self {
            Lens::Pinhole(l) => l.fy,
            Lens::Kb4(l) => l.fy,
            Lens::Radtan(l) => l.fy,
            Lens::Equirectangular(l) => l.fy,
            Lens::DoubleSphere(l) => l.fy,
            Lens::Eucm(l) => l.fy,
            Lens::Omni(l) => l.fy,
        }
    }
    pub fn principal_point(&self) -> Point2<f64> {
        match self {
            Lens::Pinhole(l) => Point2::new(l.cx, l.cy),
            Lens::Kb4(l) => Point2::new(l.cx, l.cy),
            Lens::Radtan(l) => Point2::new(l.cx, l.cy),
            Lens::Equirectangular(l) => Point2::new(l.cx, l.cy),
            Lens::DoubleSphere(l) => Point2::new(l.cx, l.cy),
            Lens::Eucm(l) => Point2::new(l.cx, l.cy),
            Lens::Omni(l) => Point2::new(l.cx, l.cy),
        }
    }

    /// Largest angle (rad) between the optical axis and a ray the lens can image, ignoring the
    /// sensor's borders: π/2 for a pinhole, the model's monotonic domain for KB4 and radtan, its
    /// one-to-one region for the sphere models, π for a panorama.
    pub fn max_theta(&self) -> f64 {
        match self {
            Lens::Pinhole(_) => std::f64::consts::FRAC_PI_2,
            Lens::Kb4(l) => l.theta_max,
            Lens::Radtan(l) => l.max_theta(),
            Lens::Equirectangular(_) => std::f64::consts::PI,
            Lens::DoubleSphere(l) => l.max_theta(),
            Lens::Eucm(l) => l.max_theta(),
            Lens::Omni(l) => l.max_theta(),
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
            Lens::Radtan(l) => {
                let m = radtan_normalised(l, p)?;
                let (d, _) = l.distort(m);
                Some(Point2::new(l.fx * d.x + l.cx, l.fy * d.y + l.cy))
            }
            Lens::Equirectangular(l) => {
                let rho = p.norm();
                if !(rho.is_finite() && rho > 0.0) {
                    return None;
                }
                let lat = (p.y / rho).clamp(-1.0, 1.0).asin();
                Some(Point2::new(l.cx + l.fx * p.x.atan2(p.z), l.cy + l.fy * lat))
            }
            Lens::DoubleSphere(l) => l.project(p),
            Lens::Eucm(l) => l.project(p),
            Lens::Omni(l) => l.project(p),
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
            Lens::Radtan(l) => {
                let target = Vector2::new((px.x - l.cx) / l.fx, (px.y - l.cy) / l.fy);
                if !target.iter().all(|c| c.is_finite()) {
                    return None;
                }
                let m = l.undistort(target)?;
                Some(Unit::new_normalize(Vector3::new(m.x, m.y, 1.0)))
            }
            Lens::Equirectangular(l) => {
                let lon = (px.x - l.cx) / l.fx;
                let lat = (px.y - l.cy) / l.fy;
                use std::f64::consts::{FRAC_PI_2, PI};
                if !(lon.abs() <= PI && lat.abs() <= FRAC_PI_2) {
                    return None;
                }
                let (sl, cl) = lat.sin_cos();
                let (so, co) = lon.sin_cos();
                Some(Unit::new_normalize(Vector3::new(cl * so, sl, cl * co)))
            }
            Lens::DoubleSphere(l) => l.unproject(px),
            Lens::Eucm(l) => l.unproject(px),
            Lens::Omni(l) => l.unproject(px),
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
            Lens::Radtan(l) => {
                // pixel ← (x'', y'') ← (x', y') = (x/z, y/z).
                let m = radtan_normalised(l, p)?;
                let (_, jd) = l.distort(m);
                let iz = 1.0 / p.z;
                let jm = Matrix2x3::new(iz, 0.0, -m.x * iz, 0.0, iz, -m.y * iz);
                let f = nalgebra::Matrix2::new(l.fx, 0.0, 0.0, l.fy);
                Some(f * jd * jm)
            }
            Lens::Equirectangular(l) => {
                // d atan2(x, z) = (z dx − x dz) / h², d asin(y/ρ) = (h² dy − y (x dx + z dz)) / (ρ² h)
                // with h² = x² + z²: singular at the poles, where longitude is undefined.
                let h2 = p.x * p.x + p.z * p.z;
                let rho2 = h2 + p.y * p.y;
                let h = h2.sqrt();
                if !(h > 1e-12 * rho2.sqrt() && rho2.is_finite()) {
                    return None;
                }
                let a = 1.0 / (rho2 * h);
                Some(Matrix2x3::new(
                    l.fx * p.z / h2,
                    0.0,
                    -l.fx * p.x / h2,
                    -l.fy * p.y * p.x * a,
                    l.fy * h2 * a,
                    -l.fy * p.y * p.z * a,
                ))
            }
            Lens::DoubleSphere(l) => l.project_jacobian(p),
            Lens::Eucm(l) => l.project_jacobian(p),
            Lens::Omni(l) => l.project_jacobian(p),
        }
    }
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
