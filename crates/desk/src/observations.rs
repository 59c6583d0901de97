//! Synthetic correspondences straight from the model, with the paper's noise model, so that the
//! pose-solver benchmarks need no images (Koch–Teller §5.1).
//!
//! In: a model, a rig, a true pose `T_world_rig`, a visibility test, [`NoiseModel`]. Out:
//! [`Correspondence`]s — each a model segment and the edge plane a sensor would observe for it —
//! perturbed as §5.1 describes: edge noise (σ = 0.5°), "clutter" by removing 25 % of the
//! correspondences and adding σ = 2° to the rest, plus optional gross outliers (edges matched to
//! the wrong segment) for the robust solvers. Also says which were made outliers.

use nalgebra::{Point3, Unit, UnitQuaternion, Vector3};
use omnitrack_core::geometry::{Correspondence, EdgePlane, Pose};
use omnitrack_core::{Model, Rig};
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};

/// The perturbations applied to exact observations.
#[derive(Debug, Clone, PartialEq)]
pub struct NoiseModel {
    /// σ (degrees) of the rotation of every observed edge plane about an axis in the plane.
    pub edge_sigma_deg: f64,
    /// Fraction of correspondences removed as if lost in clutter.
    pub clutter_drop_fraction: f64,
    /// σ (degrees) added to the remaining ones when clutter is simulated (0 = no clutter).
    pub clutter_sigma_deg: f64,
    /// Fraction of the kept correspondences whose edge is replaced by another segment's edge.
    pub outlier_fraction: f64,
    /// Segments whose visible part subtends less than this (degrees) are not observed.
    pub min_angular_length_deg: f64,
    /// Segments further than this (m) are not observed.
    pub max_range_m: f64,
}

impl Default for NoiseModel {
    fn default() -> Self {
        Self {
            edge_sigma_deg: 0.5,
            clutter_drop_fraction: 0.0,
            clutter_sigma_deg: 0.0,
            outlier_fraction: 0.0,
            min_angular_length_deg: 2.0,
            max_range_m: 30.0,
        }
    }
}

impl NoiseModel {
    /// Koch–Teller §5.1 with clutter: σ = 0.5°, 25 % removed, σ = 2° added to the rest.
    pub fn paper_clutter() -> Self {
        Self {
            clutter_drop_fraction: 0.25,
            clutter_sigma_deg: 2.0,
            ..Self::default()
        }
    }
}

/// Generated correspondences and the ground truth about them.
#[derive(Debug, Clone)]
pub struct SyntheticObservations {
    pub correspondences: Vec<Correspondence>,
    /// For each correspondence, whether it was made a gross outlier.
    pub outlier: Vec<bool>,
    /// For each correspondence, the model segment and sensor it came from.
    pub segment: Vec<u32>,
    pub sensor: Vec<u8>,
}

/// Samples along a segment when looking for its visible part.
const SAMPLES: usize = 48;

/// Observes every model segment from `t_world_rig`: for each, the sensor that sees the longest
/// part of it (sample points inside the image, within range, passing `visible(sensor centre in
/// world, point)`), then the noise model. Deterministic for a seed.
pub fn observe(
    model: &Model,
    rig: &Rig,
    t_world_rig: &Pose,
    noise: &NoiseModel,
    seed: u64,
    visible: &dyn Fn(&Point3<f64>, &Point3<f64>) -> bool,
) -> SyntheticObservations {
    let mut rng = SmallRng::seed_from_u64(seed);
    let mut out = SyntheticObservations {
        correspondences: vec![],
        outlier: vec![],
        segment: vec![],
        sensor: vec![],
    };
    let min_angle = noise.min_angular_length_deg.to_radians();
    for (si, seg) in model.segments.iter().enumerate() {
        let mut best: Option<(f64, usize)> = None;
        for sensor in &rig.sensors {
            let centre_world = t_world_rig * sensor.centre();
            let mut first: Option<Vector3<f64>> = None;
            let mut last: Option<Vector3<f64>> = None;
            for k in 0..SAMPLES {
                let p = seg.a + (seg.b - seg.a) * ((k as f64 + 0.5) / SAMPLES as f64);
                let p_rig = t_world_rig.inverse_transform_point(&p);
                if (p - centre_world).norm() > noise.max_range_m
                    || sensor.project_from_rig(&p_rig).is_none()
                    || !visible(&centre_world, &p)
                {
                    continue;
                }
                let ray = p_rig - sensor.centre();
                first.get_or_insert(ray);
                last = Some(ray);
            }
            if let (Some(f), Some(l)) = (first, last) {
                let angle = f.cross(&l).norm().atan2(f.dot(&l));
                if angle >= min_angle && best.is_none_or(|(a, _)| angle > a) {
                    best = Some((angle, sensor.id));
                }
            }
        }
        let Some((_, sensor)) = best else { continue };
        if rng.random::<f64>() < noise.clutter_drop_fraction {
            continue;
        }
        let centre = rig.sensors[sensor].centre();
        let a = t_world_rig.inverse_transform_point(&seg.a) - centre;
        let b = t_world_rig.inverse_transform_point(&seg.b) - centre;
        let Some(edge) = EdgePlane::from_rays(centre, &a, &b) else {
            continue;
        };
        let sigma = (noise.edge_sigma_deg.powi(2) + noise.clutter_sigma_deg.powi(2))
            .sqrt()
            .to_radians();
        let edge = edge.with_normal(tilt(&edge.normal, sigma * gaussian(&mut rng), &mut rng));
        out.correspondences.push(Correspondence {
            edge,
            segment: [seg.a, seg.b],
        });
        out.outlier.push(false);
        out.segment.push(si as u32);
        out.sensor.push(sensor as u8);
    }
    // Gross outliers: pair an edge with a different, randomly chosen segment of the model.
    let n = out.correspondences.len();
    if n >= 2 && noise.outlier_fraction > 0.0 {
        let count = ((noise.outlier_fraction * n as f64).round() as usize).min(n);
        let mut order: Vec<usize> = (0..n).collect();
        for i in 0..count {
            let j = rng.random_range(i..n);
            order.swap(i, j);
        }
        for &i in &order[..count] {
            let mut other = rng.random_range(0..model.segments.len());
            if other as u32 == out.segment[i] {
                other = (other + 1) % model.segments.len();
            }
            let s = &model.segments[other];
            out.correspondences[i].segment = [s.a, s.b];
            out.outlier[i] = true;
        }
    }
    out
}

/// Standard normal by Box–Muller.
fn gaussian(rng: &mut SmallRng) -> f64 {
    let u1: f64 = 1.0 - rng.random::<f64>();
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// Rotates a normal by `angle` about a uniformly random axis perpendicular to it.
fn tilt(n: &Unit<Vector3<f64>>, angle: f64, rng: &mut SmallRng) -> Unit<Vector3<f64>> {
    let helper = if n.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
    let u = n.cross(&helper).normalize();
    let v = n.cross(&u);
    let phi = rng.random::<f64>() * std::f64::consts::TAU;
    let axis = Unit::new_normalize(u * phi.cos() + v * phi.sin());
    UnitQuaternion::from_axis_angle(&axis, angle) * *n
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Isometry3;
    use omnitrack_core::geometry::xi;

    fn room() -> Model {
        // A 6 × 4 × 2.5 m room: 12 segments.
        Model::from_obj_str(
            "v 0 0 0\nv 6 0 0\nv 6 4 0\nv 0 4 0\nv 0 0 2.5\nv 6 0 2.5\nv 6 4 2.5\nv 0 4 2.5\n\
             f 1 2 3 4\nf 5 8 7 6\nf 1 5 6 2\nf 2 6 7 3\nf 3 7 8 4\nf 4 8 5 1\n",
            "room.obj",
        )
        .unwrap()
    }

    fn rig() -> Rig {
        Rig::load(std::path::Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../firmware_config/ladybug2.toml"
        )))
        .unwrap()
    }

    #[test]
    fn noiseless_observations_fit_the_true_pose_exactly() {
        let pose = Isometry3::new(Vector3::new(2.5, 1.5, 1.2), Vector3::new(0.0, 0.0, 0.7));
        let noise = NoiseModel {
            edge_sigma_deg: 0.0,
            ..NoiseModel::default()
        };
        let obs = observe(&room(), &rig(), &pose, &noise, 1, &|_, _| true);
        assert!(obs.correspondences.len() >= 10, "{} seen", obs.correspondences.len());
        assert!(xi(&obs.correspondences, &pose) < 1e-20);
        let off = Isometry3::new(Vector3::new(2.6, 1.5, 1.2), Vector3::new(0.0, 0.0, 0.7));
        assert!(xi(&obs.correspondences, &off) > 1e-6);
    }

    #[test]
    fn paper_noise_gives_the_paper_spread_and_clutter_drops_a_quarter() {
        let pose = Isometry3::new(Vector3::new(2.0, 2.0, 1.2), Vector3::new(0.0, 0.0, 0.3));
        let model = room();
        let rig = rig();
        let mut alphas = Vec::new();
        let mut kept = 0;
        let mut total = 0;
        for seed in 0..400 {
            let clean = observe(&model, &rig, &pose, &NoiseModel::default(), seed, &|_, _| true);
            alphas.extend(clean.correspondences.iter().map(|c| c.alpha(&pose)));
            total += clean.correspondences.len();
            kept += observe(&model, &rig, &pose, &NoiseModel::paper_clutter(), seed, &|_, _| true)
                .correspondences
                .len();
        }
        // The tilt is a 1-D Gaussian angle: RMS α = σ.
        let rms = (alphas.iter().map(|a| a * a).sum::<f64>() / alphas.len() as f64)
            .sqrt()
            .to_degrees();
        assert!((rms - 0.5).abs() < 0.03, "rms {rms}°");
        let fraction = kept as f64 / total as f64;
        assert!((fraction - 0.75).abs() < 0.03, "kept {fraction}");
    }

    #[test]
    fn outliers_are_marked_and_occluded_segments_unseen() {
        let pose = Isometry3::new(Vector3::new(2.0, 2.0, 1.2), Vector3::new(0.0, 0.0, 0.3));
        let noise = NoiseModel {
            outlier_fraction: 0.5,
            edge_sigma_deg: 0.0,
            ..NoiseModel::default()
        };
        let obs = observe(&room(), &rig(), &pose, &noise, 9, &|_, _| true);
        let n = obs.correspondences.len();
        assert_eq!(
            obs.outlier.iter().filter(|&&o| o).count(),
            (n as f64 * 0.5).round() as usize
        );
        for (c, &o) in obs.correspondences.iter().zip(&obs.outlier) {
            if !o {
                assert!(c.alpha(&pose) < 1e-9, "an inlier without noise fits exactly");
            }
        }
        assert!(obs
            .correspondences
            .iter()
            .zip(&obs.outlier)
            .any(|(c, &o)| o && c.alpha(&pose) > 0.01));
        let none = observe(&room(), &rig(), &pose, &noise, 9, &|_, p| p.z > 10.0);
        assert!(none.correspondences.is_empty());
    }
}
