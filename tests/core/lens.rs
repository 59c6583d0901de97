//! Lens geometry: round trips at random pixels and rays, Jacobians against finite differences.

use nalgebra::{Point2, Vector3};
use omnitrack::geometry::{Kb4, Lens, Pinhole};
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};

/// Angle between two directions, accurate near zero (acos is not).
fn angle(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    a.cross(b).norm().atan2(a.dot(b))
}

struct Case {
    name: &'static str,
    lens: Lens,
    width: f64,
    height: f64,
}

fn cases() -> Vec<Case> {
    vec![
        Case {
            name: "ladybug2 side (kb4, portrait)",
            lens: Lens::Kb4(Kb4::new(285.0, 285.0, 191.5, 255.5, [-0.015, 0.002, -0.0003, 0.0]).unwrap()),
            width: 384.0,
            height: 512.0,
        },
        Case {
            // Corner rays ~100° off-axis: a > 190° diagonal field of view.
            name: "wide kb4 (landscape, >190° diagonal)",
            lens: Lens::Kb4(Kb4::new(175.0, 174.2, 255.7, 191.2, [0.02, -0.005, 0.001, -0.0001]).unwrap()),
            width: 512.0,
            height: 384.0,
        },
        Case {
            name: "pinhole",
            lens: Lens::Pinhole(Pinhole::new(400.0, 401.0, 255.5, 191.5).unwrap()),
            width: 512.0,
            height: 384.0,
        },
    ]
}

#[test]
fn wide_test_lens_really_sees_past_95_degrees_at_its_corners() {
    let wide = &cases()[1];
    let corner = wide.lens.unproject(&Point2::new(-0.5, -0.5)).unwrap();
    let theta = corner.z.acos().to_degrees();
    assert!(theta > 95.0, "corner at {theta}°");
    assert!(corner.z < 0.0);
}

#[test]
fn pixel_ray_pixel_round_trip_at_10000_random_pixels() {
    let mut rng = SmallRng::seed_from_u64(7);
    for case in cases() {
        let mut worst_px: f64 = 0.0;
        let mut worst_rad: f64 = 0.0;
        for k in 0..10_000 {
            // Corners and borders first, then uniform pixels over the whole image.
            let px = match k {
                0 => Point2::new(-0.5, -0.5),
                1 => Point2::new(case.width - 0.5, case.height - 0.5),
                2 => Point2::new(-0.5, case.height - 0.5),
                3 => Point2::new(case.width - 0.5, -0.5),
                _ => Point2::new(
                    rng.random_range(-0.5..case.width - 0.5),
                    rng.random_range(-0.5..case.height - 0.5),
                ),
            };
            let ray = case
                .lens
                .unproject(&px)
                .unwrap_or_else(|| panic!("{}: no ray at {px}", case.name));
            assert!((ray.norm() - 1.0).abs() < 1e-14);
            let back = case
                .lens
                .project(&ray)
                .unwrap_or_else(|| panic!("{}: ray of {px} does not project", case.name));
            let ray2 = case.lens.unproject(&back).unwrap();
            worst_px = worst_px.max((back - px).norm());
            worst_rad = worst_rad.max(angle(&ray, &ray2));
        }
        assert!(worst_px < 1e-7, "{}: pixel error {worst_px}", case.name);
        assert!(worst_rad < 1e-9, "{}: ray error {worst_rad} rad", case.name);
    }
}

#[test]
fn ray_pixel_ray_round_trip_is_exact_to_1e_9_rad() {
    let mut rng = SmallRng::seed_from_u64(11);
    for case in cases() {
        let mut worst: f64 = 0.0;
        let mut tested = 0;
        while tested < 10_000 {
            let v = Vector3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            );
            if v.norm() < 1e-3 {
                continue;
            }
            let Some(px) = case.lens.project(&v) else { continue };
            if !(px.x >= -0.5 && px.y >= -0.5 && px.x <= case.width - 0.5 && px.y <= case.height - 0.5) {
                continue;
            }
            let ray = case.lens.unproject(&px).unwrap();
            worst = worst.max(angle(&ray, &v));
            tested += 1;
        }
        assert!(worst < 1e-9, "{}: {worst} rad", case.name);
    }
}

#[test]
fn kb4_unproject_matches_an_independent_bisection_of_the_opencv_polynomial() {
    let k = [0.02, -0.005, 0.001, -0.0001];
    let lens = Kb4::new(175.0, 174.2, 255.7, 191.2, k).unwrap();
    let theta_d = |t: f64| t * (1.0 + k[0] * t.powi(2) + k[1] * t.powi(4) + k[2] * t.powi(6) + k[3] * t.powi(8));
    for &(u, v) in &[(-0.5, -0.5), (511.5, 383.5), (300.0, 20.0), (255.7, 191.2 + 1e-7)] {
        let m: (f64, f64) = ((u - 255.7) / 175.0, (v - 191.2) / 174.2);
        let td = (m.0 * m.0 + m.1 * m.1).sqrt();
        let (mut lo, mut hi) = (0.0, std::f64::consts::PI);
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if theta_d(mid) < td {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let ray = Lens::Kb4(lens).unproject(&Point2::new(u, v)).unwrap();
        let theta = ray.xy().norm().atan2(ray.z);
        assert!((theta - lo).abs() < 1e-12, "θ {theta} vs {lo} at ({u}, {v})");
    }
}

#[test]
fn projection_jacobian_matches_central_differences() {
    let mut rng = SmallRng::seed_from_u64(3);
    for case in cases() {
        let mut checked = 0;
        let mut near_axis = 0;
        while checked < 2000 {
            // Mix generic points with points within a hair of the optical axis.
            let axis = checked % 10 == 0;
            let v = if axis {
                Vector3::new(
                    rng.random_range(-1e-10..1e-10),
                    rng.random_range(-1e-10..1e-10),
                    rng.random_range(0.5..5.0),
                )
            } else {
                Vector3::new(
                    rng.random_range(-3.0..3.0),
                    rng.random_range(-3.0..3.0),
                    rng.random_range(-3.0..3.0),
                )
            };
            let Some(j) = case.lens.project_jacobian(&v) else {
                continue;
            };
            let h = 1e-6 * v.norm();
            let mut fd = nalgebra::Matrix2x3::zeros();
            let mut ok = true;
            for c in 0..3 {
                let mut dv = Vector3::zeros();
                dv[c] = h;
                match (case.lens.project(&(v + dv)), case.lens.project(&(v - dv))) {
                    (Some(p), Some(m)) => fd.set_column(c, &((p - m) / (2.0 * h))),
                    _ => ok = false,
                }
            }
            if !ok {
                continue;
            }
            let scale = j.norm().max(1.0);
            assert!((j - fd).norm() < 1e-5 * scale, "{} at {v:?}:\n{j}\nvs\n{fd}", case.name);
            checked += 1;
            near_axis += axis as usize;
        }
        assert!(near_axis >= 100);
    }
}

#[test]
fn points_outside_the_model_domain_do_not_project() {
    let pin = Lens::Pinhole(Pinhole::new(400.0, 400.0, 256.0, 192.0).unwrap());
    assert!(pin.project(&Vector3::new(0.1, 0.0, 0.0)).is_none());
    assert!(pin.project_jacobian(&Vector3::new(0.1, 0.0, -1.0)).is_none());
    let kb = Lens::Kb4(Kb4::new(285.0, 285.0, 191.5, 255.5, [-0.015, 0.002, -0.0003, 0.0]).unwrap());
    assert!(
        kb.project(&Vector3::new(0.0, 0.0, -1.0)).is_none(),
        "straight behind has no pixel"
    );
    assert!(kb.project(&Vector3::zeros()).is_none());
    assert!(kb.unproject(&Point2::new(f64::NAN, 0.0)).is_none());
}
