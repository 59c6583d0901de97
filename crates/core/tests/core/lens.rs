//! Lens geometry: round trips at random pixels and rays, Jacobians against finite differences.

use nalgebra::{Point2, Vector3};
use omnitrack_core::geometry::{DoubleSphere, Equirectangular, Eucm, Kb4, Lens, Omni, Pinhole, Radtan};
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
        Case {
            // Basalt's double-sphere calibration of EuRoC's cam0 (α > ½: a bounded image).
            name: "ds (Basalt, EuRoC cam0)",
            lens: Lens::DoubleSphere(ds_euroc()),
            width: 752.0,
            height: 480.0,
        },
        Case {
            // TUM-VI's 195° fisheye as Basalt calibrates it: corners ~120° off the axis.
            name: "ds (Basalt, TUM-VI, corners past 115°)",
            lens: Lens::DoubleSphere(ds_tumvi()),
            width: 512.0,
            height: 512.0,
        },
        Case {
            // A bounded image (α > ½) whose rim lies just outside the corners, 120° off the axis.
            name: "eucm (α > ½, corners past 115°)",
            lens: Lens::Eucm(Eucm::new(200.0, 199.9, 254.97, 256.9, 0.6313, 1.0377).unwrap()),
            width: 512.0,
            height: 512.0,
        },
        Case {
            name: "eucm (α < ½: unbounded image)",
            lens: Lens::Eucm(Eucm::new(300.0, 300.0, 319.5, 239.5, 0.4, 1.3).unwrap()),
            width: 640.0,
            height: 480.0,
        },
        Case {
            // Kalibr's omni-radtan as its EuRoC-like sample gives it.
            name: "omni-radtan (ξ < 1)",
            lens: Lens::Omni(omni_radtan()),
            width: 752.0,
            height: 480.0,
        },
        Case {
            // ξ > 1: folds at acos(−1/ξ) = 146°; the corners see ~133° off the axis.
            name: "omni (ξ = 1.2, corners past 130°)",
            lens: Lens::Omni(Omni::new(320.0, 320.0, 319.5, 319.5, 1.2, [0.0; 4]).unwrap()),
            width: 640.0,
            height: 640.0,
        },
    ]
}

fn ds_euroc() -> DoubleSphere {
    DoubleSphere::new(
        349.7560023050409,
        348.72454229977037,
        365.89440762590149,
        249.32995565708704,
        -0.2409573942178872,
        0.566996899163044,
    )
    .unwrap()
}

fn ds_tumvi() -> DoubleSphere {
    DoubleSphere::new(
        158.28600034966977,
        158.2743455478755,
        254.96116578191653,
        256.8894394501779,
        -0.17213086034353243,
        0.5931177593944744,
    )
    .unwrap()
}

fn omni_radtan() -> Omni {
    Omni::new(764.1, 763.4, 367.2, 248.4, 0.9, [-0.26, 0.071, 0.00019, 1.8e-05]).unwrap()
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
            // Where a lens's image is unbounded, a point at its border lands 10⁸ px out, and
            // central differences there are no reference.
            if case.lens.project(&v).is_none_or(|p| p.coords.norm() > 1e5) {
                continue;
            }
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

/// Every ray the model images, not only those landing on a sensor: 20,000 directions uniform
/// over the lens's whole field (past 90° where it reaches there, up to a hair inside its
/// border) go to a pixel and back to within 1e-9 rad.
#[test]
fn ray_pixel_ray_round_trip_over_the_whole_field_of_view() {
    let mut rng = SmallRng::seed_from_u64(17);
    for case in cases() {
        let reach = case.lens.max_theta();
        let mut worst: f64 = 0.0;
        let mut widest: f64 = 0.0;
        for _ in 0..20_000 {
            // cos θ uniform on [cos(reach·(1 − 1e-4)), 1]: uniform on the sphere's cap.
            let lo = (reach * (1.0 - 1e-4)).cos();
            let c: f64 = rng.random_range(lo..1.0);
            let phi: f64 = rng.random_range(-std::f64::consts::PI..std::f64::consts::PI);
            let s = (1.0 - c * c).sqrt();
            let v = Vector3::new(s * phi.cos(), s * phi.sin(), c);
            let px = case
                .lens
                .project(&v)
                .unwrap_or_else(|| panic!("{}: θ = {:.2}° does not project", case.name, c.acos().to_degrees()));
            let ray = case
                .lens
                .unproject(&px)
                .unwrap_or_else(|| panic!("{}: no ray at {px} (θ = {:.2}°)", case.name, c.acos().to_degrees()));
            worst = worst.max(angle(&ray, &v));
            widest = widest.max(c.acos());
        }
        assert!(worst < 1e-9, "{}: {worst} rad", case.name);
        assert!(widest > 0.999 * reach, "{}", case.name);
    }
}

/// The sphere models' borders: beyond the one-to-one region nothing projects, and pixels with
/// no preimage (past a bounded image's rim) give no ray; fields as the formulas give them.
#[test]
fn sphere_models_image_exactly_their_one_to_one_region() {
    // The field by brute force: the first θ (10⁻⁵ rad steps) where a unit ray's image radius
    // stops rising or its denominator stops being positive.
    let brute = |radius: &dyn Fn(f64) -> Option<f64>| {
        let mut prev = 0.0;
        for i in 1..=314_160 {
            let t = i as f64 * 1e-5;
            match radius(t) {
                Some(r) if r > prev => prev = r,
                _ => return t - 1e-5,
            }
        }
        std::f64::consts::PI
    };
    let ds_radius = |xi: f64, a: f64| {
        move |t: f64| {
            let (s, c) = (t.sin(), t.cos());
            let den = a * (s * s + (xi + c).powi(2)).sqrt() + (1.0 - a) * (xi + c);
            (den > 0.0).then(|| s / den)
        }
    };
    let eucm_radius = |a: f64, b: f64| {
        move |t: f64| {
            let (s, c) = (t.sin(), t.cos());
            let den = a * (b * s * s + c * c).sqrt() + (1.0 - a) * c;
            (den > 0.0).then(|| s / den)
        }
    };
    let tumvi = ds_tumvi();
    let ds = Lens::DoubleSphere(tumvi);
    for (lens, expected) in [
        (ds, brute(&ds_radius(tumvi.xi, tumvi.alpha))),
        (
            Lens::DoubleSphere(DoubleSphere::new(300.0, 300.0, 0.0, 0.0, 0.7, 0.3).unwrap()),
            brute(&ds_radius(0.7, 0.3)),
        ),
        (
            Lens::Eucm(Eucm::new(300.0, 300.0, 0.0, 0.0, 0.6313, 1.0377).unwrap()),
            brute(&eucm_radius(0.6313, 1.0377)),
        ),
        (
            Lens::Eucm(Eucm::new(300.0, 300.0, 0.0, 0.0, 0.4, 1.3).unwrap()),
            brute(&eucm_radius(0.4, 1.3)),
        ),
    ] {
        assert!(
            (lens.max_theta() - expected).abs() < 2e-5,
            "{lens:?}: {} vs {expected}",
            lens.max_theta()
        );
    }
    // TUM-VI's lens is one-to-one to 126.1° (the paper's closed form, z > −w2·d1, says 125.2°).
    assert!(
        (ds.max_theta().to_degrees() - 126.12).abs() < 0.01,
        "{}",
        ds.max_theta().to_degrees()
    );
    let eucm = Lens::Eucm(Eucm::new(300.0, 300.0, 320.0, 240.0, 0.5, 2.0).unwrap());
    assert!(
        eucm.max_theta() > std::f64::consts::PI - 1e-6,
        "α = ½ sees all but straight behind"
    );
    let omni = Lens::Omni(Omni::new(320.0, 320.0, 320.0, 320.0, 1.2, [0.0; 4]).unwrap());
    assert!((omni.max_theta() - (-1.0f64 / 1.2).acos()).abs() < 1e-12);
    for lens in [
        ds,
        Lens::Eucm(Eucm::new(158.0, 157.9, 255.0, 257.0, 0.6313, 1.0377).unwrap()),
        omni,
    ] {
        let t = lens.max_theta() + 1e-6;
        let beyond = Vector3::new(t.sin(), 0.0, t.cos());
        assert!(lens.project(&beyond).is_none(), "{lens:?}");
        assert!(lens.project_jacobian(&beyond).is_none(), "{lens:?}");
        // A pixel far outside any image circle has no ray.
        assert!(lens.unproject(&Point2::new(1e5, 0.0)).is_none(), "{lens:?}");
        assert!(lens.project(&Vector3::zeros()).is_none());
        assert!(lens.unproject(&Point2::new(f64::NAN, 0.0)).is_none());
    }
    // Parameters out of their ranges are refused, each naming the model and the parameter.
    for (e, says) in [
        (
            DoubleSphere::new(300.0, 300.0, 0.0, 0.0, 1.5, 0.5).unwrap_err(),
            "ds: ξ must be in [−1, 1]",
        ),
        (
            DoubleSphere::new(300.0, 300.0, 0.0, 0.0, 0.0, -0.1).unwrap_err(),
            "ds: α must be in [0, 1]",
        ),
        (
            Eucm::new(300.0, 300.0, 0.0, 0.0, 0.5, 0.0).unwrap_err(),
            "eucm: β must be positive",
        ),
        (
            Eucm::new(300.0, 300.0, 0.0, 0.0, f64::NAN, 1.0).unwrap_err(),
            "eucm: α must be in [0, 1]",
        ),
        (
            Omni::new(300.0, 300.0, 0.0, 0.0, -0.5, [0.0; 4]).unwrap_err(),
            "omni: ξ must be finite and ≥ 0",
        ),
        (
            DoubleSphere::new(0.0, 300.0, 0.0, 0.0, 0.0, 0.5).unwrap_err(),
            "focal lengths",
        ),
    ] {
        assert!(e.to_string().contains(says), "{e} should say {says:?}");
    }
}

/// The models are each other's special cases (Usenko et al. 2018, section 3): a double sphere
/// with α = 0 is the unified model of the same ξ; EUCM with β = 1 is the unified model with
/// ξ = α/(1−α) and focal length f/(1−α); with α = 0 it is a pinhole. Each pair projects alike.
#[test]
fn the_sphere_models_agree_where_they_are_the_same_model() {
    let mut rng = SmallRng::seed_from_u64(23);
    let pairs = [
        (
            Lens::DoubleSphere(DoubleSphere::new(300.0, 290.0, 320.0, 240.0, 0.7, 0.0).unwrap()),
            Lens::Omni(Omni::new(300.0, 290.0, 320.0, 240.0, 0.7, [0.0; 4]).unwrap()),
        ),
        (
            Lens::Eucm(Eucm::new(300.0, 290.0, 320.0, 240.0, 0.6, 1.0).unwrap()),
            Lens::Omni(Omni::new(750.0, 725.0, 320.0, 240.0, 1.5, [0.0; 4]).unwrap()),
        ),
        (
            Lens::Eucm(Eucm::new(300.0, 290.0, 320.0, 240.0, 0.0, 1.7).unwrap()),
            Lens::Pinhole(Pinhole::new(300.0, 290.0, 320.0, 240.0).unwrap()),
        ),
    ];
    for (a, b) in pairs {
        if !matches!(a, Lens::DoubleSphere(_)) {
            assert!((a.max_theta() - b.max_theta()).abs() < 1e-9, "{a:?} {b:?}");
        }
        for _ in 0..2000 {
            let v = Vector3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            );
            match (a.project(&v), b.project(&v)) {
                (Some(p), Some(q)) => assert!((p - q).norm() < 1e-8 * (1.0 + p.coords.norm()), "{p} vs {q}"),
                (None, None) => {}
                // Beyond the narrower field (omni's distortion is used to r = 10 only), or on
                // the border itself, where one of the two may round the other way.
                (p, q) => assert!(
                    v.xy().norm().atan2(v.z) > a.max_theta().min(b.max_theta()) - 1e-9,
                    "{a:?} / {b:?} at {v:?}: {p:?} vs {q:?}"
                ),
            }
        }
    }
}
