//! Lens geometry: round trips at random pixels and rays, Jacobians against finite differences.

use nalgebra::{Point2, Vector3};
use omnitrack_core::geometry::{Equirectangular, Kb4, Lens, Pinhole, Radtan};
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
        Case {
            // EuRoC's cam0 as Kalibr calibrated it, with a k3 added.
            name: "radtan (EuRoC cam0)",
            lens: Lens::Radtan(radtan_euroc()),
            width: 752.0,
            height: 480.0,
        },
        Case {
            name: "equirectangular 1024×512",
            lens: Lens::Equirectangular(Equirectangular::for_panorama(1024, 512)),
            width: 1024.0,
            height: 512.0,
        },
    ]
}

fn radtan_euroc() -> Radtan {
    Radtan::new(
        458.654,
        457.296,
        367.215,
        248.375,
        &[-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05, 0.0012],
    )
    .unwrap()
}

/// Pixels of `cv2.projectPoints` (OpenCV 5.0, identity pose) for the lens of [`radtan_euroc`].
#[test]
fn radtan_projects_as_opencv_does() {
    let lens = Lens::Radtan(radtan_euroc());
    let opencv = [
        ([0.3, -0.2, 1.0], [499.905931297956, 160.188503567068]),
        ([-1.2, 0.7, 2.5], [164.750090691070, 366.158630851779]),
        ([0.01, 0.02, 0.9], [372.310314991826, 258.535501883420]),
        ([2.0, 1.5, 1.7], [769.508670286854, 549.380293017169]),
        ([-0.5, -0.45, 0.6], [75.718565846670, -13.092864250613]),
    ];
    for (p, px) in opencv {
        let got = lens.project(&Vector3::from(p)).unwrap();
        assert!((got - Point2::from(px)).norm() < 1e-9, "{p:?}: {got} vs {px:?}");
    }
}

#[test]
fn equirectangular_sees_the_whole_sphere_with_its_seam_behind() {
    let lens = Lens::Equirectangular(Equirectangular::for_panorama(1024, 512));
    // Straight ahead is the centre; straight behind is the seam at both side borders.
    let ahead = lens.project(&Vector3::new(0.0, 0.0, 2.0)).unwrap();
    assert!((ahead - Point2::new(511.5, 255.5)).norm() < 1e-12);
    let left = lens.project(&Vector3::new(-1e-9, 0.0, -1.0)).unwrap();
    let right = lens.project(&Vector3::new(1e-9, 0.0, -1.0)).unwrap();
    assert!(
        (left.x + 0.5).abs() < 1e-6 && (right.x - 1023.5).abs() < 1e-6,
        "{left} {right}"
    );
    // Up (−y, the camera frame's y points down) is the top row.
    let up = lens.project(&Vector3::new(0.0, -1.0, 0.0)).unwrap();
    assert!((up.y + 0.5).abs() < 1e-12);
    assert_eq!(lens.max_theta(), std::f64::consts::PI);
    assert!(
        lens.unproject(&Point2::new(511.5, 600.0)).is_none(),
        "below the bottom pole"
    );
}

#[test]
fn a_folding_radtan_polynomial_is_refused_and_its_fold_is_not_imaged() {
    // 1 + 3k1r² = 0 at r = 1/√3 (30°) for k1 = −1: refused (folds before 20° would be), …
    assert!(Radtan::new(400.0, 400.0, 320.0, 240.0, &[-3.0, 0.0, 0.0, 0.0]).is_err());
    assert!(
        Radtan::new(400.0, 400.0, 320.0, 240.0, &[0.1, 0.0, 0.0]).is_err(),
        "three numbers"
    );
    // … and a lens folding at 30° images nothing beyond it.
    let lens = Lens::Radtan(Radtan::new(400.0, 400.0, 320.0, 240.0, &[-1.0, 0.0, 0.0, 0.0]).unwrap());
    assert!((lens.max_theta() - (1.0f64 / 3.0).sqrt().atan()).abs() < 1e-9);
    assert!(lens.project(&Vector3::new(0.5, 0.0, 1.0)).is_some());
    assert!(lens.project(&Vector3::new(0.7, 0.0, 1.0)).is_none());
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
