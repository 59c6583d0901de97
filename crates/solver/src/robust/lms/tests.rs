//! Med_R_and_T against scenes with known answers: the closed-form three-line rotations, the
//! F-test's quantiles and leave-one-out residuals, and outlier rejection on noisy lines.

use super::finish::truncation_consistency;
use super::*;
use nalgebra::{Point3, Unit};
use omnitrack_core::geometry::EdgePlane;
use rand::Rng;

/// A pinhole observation (centre at the origin, looking down +z) of the world segment `a`–`b`
/// under `T_rig_world = (q, s)`.
fn seen(q: &UnitQuaternion<f64>, s: &Vector3<f64>, a: Point3<f64>, b: Point3<f64>) -> Correspondence {
    let (ra, rb) = (q * a.coords + s, q * b.coords + s);
    Correspondence {
        edge: EdgePlane::from_rays(Point3::origin(), &ra, &rb).expect("a plane"),
        segment: [a, b],
    }
}

fn random_scene(rng: &mut SmallRng, n: usize) -> (UnitQuaternion<f64>, Vector3<f64>, Vec<Correspondence>) {
    let q = UnitQuaternion::from_scaled_axis(Vector3::new(
        rng.random_range(-3.0..3.0),
        rng.random_range(-3.0..3.0),
        rng.random_range(-3.0..3.0),
    ));
    let s = Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), 6.0);
    let lines = (0..n)
        .map(|_| {
            // End points in front of the camera, at depth 4–8 m, put back into the world.
            let mut end = || {
                let depth = rng.random_range(4.0..8.0);
                let p = Vector3::new(rng.random_range(-0.4..0.4), rng.random_range(-0.3..0.3), 1.0) * depth;
                Point3::from(q.inverse() * (p - s))
            };
            let (a, b) = (end(), end());
            seen(&q, &s, a, b)
        })
        .collect();
    (q, s, lines)
}

#[test]
fn f2_quantile_matches_tables() {
    // Upper 1 % and 5 % points of F(2, d) from standard tables.
    assert!((f2_quantile(0.01, 10.0) - 7.559).abs() < 1e-3);
    assert!((f2_quantile(0.05, 4.0) - 6.944).abs() < 1e-3);
    // Large d: F(2, ∞) = χ²₂ / 2 ~ Exp(1), so the quantile tends to −ln(tail).
    assert!((f2_quantile(0.01, 1e7) - 0.01f64.ln().abs()).abs() < 1e-5);
}

#[test]
fn truncation_consistency_is_the_inverse_truncated_mean() {
    assert_eq!(truncation_consistency(1.0), 1.0);
    // Exp(1) below its median: E = 1 − ln 2.
    assert!((truncation_consistency(0.5) - 1.0 / (1.0 - 2f64.ln())).abs() < 1e-12);
    // Against a numerical integral at p = 0.3.
    let x = -(0.7f64).ln();
    let steps = 100_000;
    let mean: f64 = (0..steps)
        .map(|i| {
            let t = (i as f64 + 0.5) / steps as f64 * x;
            t * (-t).exp() * x / steps as f64
        })
        .sum::<f64>()
        / 0.3;
    assert!((truncation_consistency(0.3) - 1.0 / mean).abs() < 1e-6);
}

#[test]
fn a_segment_is_behind_only_when_both_ends_are() {
    let q = UnitQuaternion::identity();
    let s = Vector3::zeros();
    let c = seen(&q, &s, Point3::new(-1.0, 0.0, 5.0), Point3::new(1.0, 0.5, 6.0));
    assert!(!behind(&c, &q, &s));
    // The segment mirrored through the centre lies in the same plane, behind the camera.
    let mirrored = Correspondence {
        segment: [-c.segment[0].coords, -c.segment[1].coords].map(Point3::from),
        ..c
    };
    assert!(behind(&mirrored, &q, &s));
    assert!(
        line_error_of(&mirrored, &q, &s, LineError::E2) < 1e-20,
        "the plane cannot tell"
    );
    assert_eq!(ranked_error(&mirrored, &q, &s, LineError::E2), f64::INFINITY);
    // A long line passing beside the camera, one end behind it, is not rejected.
    let long = Correspondence {
        segment: [Point3::new(-1.0, 0.0, 5.0), Point3::new(-1.0, 0.0, -20.0)],
        ..c
    };
    assert!(!behind(&long, &q, &s));
}

#[test]
fn three_line_rotations_find_the_truth_and_nearly_every_root() {
    let mut rng = SmallRng::seed_from_u64(5);
    let mut found_truth = 0;
    let mut tried = 0;
    let (mut covered, mut reference_roots) = (0, 0);
    for _ in 0..300 {
        let (q, _, lines) = random_scene(&mut rng, 3);
        let sub = [lines[0], lines[1], lines[2]];
        if direction_det(&sub[0], &sub[1], &sub[2]) < 0.05 {
            continue;
        }
        tried += 1;
        let mut roots = [Matrix3::zeros(); 12];
        let count = three_line_rotations(&sub, &mut roots);
        let d = |l: &Correspondence| (l.segment[1] - l.segment[0]).normalize();
        // Roots, but for a complex pair's real part now and then (a least-squares rotation).
        let not_roots = roots[..count]
            .iter()
            .filter(|r| sub.iter().any(|l| l.edge.normal.dot(&(*r * d(l))).abs() > 1e-9))
            .count();
        assert!(not_roots <= 1, "{not_roots} of {count} are not roots");
        for r in &roots[..count] {
            assert!(
                (r.transpose() * r - Matrix3::identity()).norm() < 1e-9,
                "not a rotation"
            );
        }
        let truth = *q.to_rotation_matrix().matrix();
        if roots[..count].iter().any(|r| (r - truth).norm() < 1e-6) {
            found_truth += 1;
        }
        // Reference: the exact roots Gauss–Newton reaches from 60 icosahedral starts.
        let mut reference: Vec<Matrix3<f64>> = Vec::new();
        for q0 in crate::refine::horn::icosahedral() {
            if let Some((g, _, _)) = rotation_stage(&sub, *q0, 100, 1e-12) {
                let g = *g.to_rotation_matrix().matrix();
                let residual: f64 = sub.iter().map(|l| l.edge.normal.dot(&(g * d(l))).powi(2)).sum();
                if residual < 1e-20 && reference.iter().all(|r| (r - g).norm() > 1e-5) {
                    reference.push(g);
                }
            }
        }
        reference_roots += reference.len();
        if !roots[..count].iter().any(|r| (r - truth).norm() < 1e-6) {
            let in_ref = reference.iter().any(|r| (r - truth).norm() < 1e-6);
            let rows: Vec<Vector3<f64>> = sub.iter().map(|l| (truth * d(l)).cross(&l.edge.normal)).collect();
            let det = rows[0].dot(&rows[1].cross(&rows[2]));
            let nearest = roots[..count]
                .iter()
                .map(|r| (r - truth).norm())
                .fold(f64::INFINITY, f64::min);
            eprintln!("truth missed: in reference {in_ref}, det at truth {det:.3e}, count {count}, nearest {nearest:.3e}, refs {}", reference.len());
        }
        covered += reference
            .iter()
            .filter(|g| roots[..count].iter().any(|r| (*r - **g).norm() < 1e-5))
            .count();
    }
    eprintln!("{covered} of {reference_roots} reference roots found");
    assert!(tried > 200);
    assert_eq!(found_truth, tried, "the true rotation is always among the roots");
    assert!(covered as f64 >= 0.95 * reference_roots as f64, "too few roots found");
}

#[test]
fn three_line_rotations_handle_perpendicular_lines() {
    // A building's lines run along three perpendicular axes; the closed form then meets
    // dependent constraints (its γ terms vanish) and must still return the truth.
    let mut rng = SmallRng::seed_from_u64(3);
    for _ in 0..50 {
        let (q, s, _) = random_scene(&mut rng, 0);
        let centre = q.inverse() * (Vector3::new(0.0, 0.0, 6.0) - s);
        let mut sub = Vec::new();
        for axis in [Vector3::x(), Vector3::y(), Vector3::z()] {
            let offset = Vector3::new(
                rng.random_range(-1.5..1.5),
                rng.random_range(-1.5..1.5),
                rng.random_range(-1.5..1.5),
            );
            let mid = Point3::from(centre + offset);
            sub.push(seen(&q, &s, mid - axis * 0.8, mid + axis * 0.8));
        }
        let sub = [sub[0], sub[1], sub[2]];
        let mut roots = [Matrix3::zeros(); 12];
        let count = three_line_rotations(&sub, &mut roots);
        let truth = *q.to_rotation_matrix().matrix();
        assert!(
            roots[..count].iter().any(|r| (r - truth).norm() < 1e-8),
            "truth not among {count} roots"
        );
    }
}

#[test]
fn standardised_errors_are_leave_one_out_residuals() {
    // For least squares, (I − H)⁻¹ r is the residual the line would have if it were left out
    // of the fit, so rᵀ(I − H)⁻¹r = r · r₍ᵢ₎: checked against real leave-one-out refits.
    let o = SolverOptions {
        error: LineError::E2,
        ..SolverOptions::default()
    };
    let mut rng = SmallRng::seed_from_u64(21);
    let (q, s, exact) = random_scene(&mut rng, 12);
    let noisy: Vec<Correspondence> = exact
        .iter()
        .map(|c| {
            let tilt = Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), 0.0) * 2e-3;
            Correspondence {
                edge: c
                    .edge
                    .with_normal(Unit::new_normalize(c.edge.normal.into_inner() + tilt)),
                ..*c
            }
        })
        .collect();
    let start = pose_of(&q, &s);
    let full = r_and_t(&noisy, Some(&start), &o).unwrap();
    let (fq, fs) = unknowns_of(&full.pose);
    let set: Vec<usize> = (0..noisy.len()).collect();
    let mut search = Search::new(&noisy, &o, None);
    assert!(search.standardised_errors(&fq, &fs, &set));
    let weighted = |l: &Correspondence, q: &UnitQuaternion<f64>, s: &Vector3<f64>| {
        let res = line_residuals(l, q, s, LineError::E2).unwrap();
        Vector2::new(res.r[0] * res.weight[0].sqrt(), res.r[1] * res.weight[1].sqrt())
    };
    for i in 0..noisy.len() {
        let others: Vec<Correspondence> = (0..noisy.len()).filter(|&k| k != i).map(|k| noisy[k]).collect();
        let without = r_and_t(&others, Some(&full.pose), &o).unwrap();
        let (wq, ws) = unknowns_of(&without.pose);
        let expected = weighted(&noisy[i], &fq, &fs).dot(&weighted(&noisy[i], &wq, &ws));
        let got = search.errors[i];
        assert!(
            (got - expected).abs() <= 0.02 * expected.abs() + 1e-12,
            "line {i}: {got:e} against leave-one-out {expected:e}"
        );
        assert!(got >= weighted(&noisy[i], &fq, &fs).norm_squared() * (1.0 - 1e-9));
    }
}

#[test]
fn noisy_lines_without_outliers_are_all_kept() {
    // 1 px of end-point noise at f = 800 px, told to expect up to 50 % outliers: the gate
    // must come from the fit's own scale without throwing good lines away (a loose order
    // statistic or an overfitted h-set used to drop one line in ten).
    let o = SolverOptions {
        error: LineError::E2,
        lms_outlier_fraction: 0.5,
        lms_success_probability: 0.999,
        ..SolverOptions::default()
    };
    let mut rng = SmallRng::seed_from_u64(9);
    let mut dropped = 0;
    for trial in 0..40 {
        let (q, s, exact) = random_scene(&mut rng, 10);
        let noisy: Vec<Correspondence> = exact
            .iter()
            .map(|c| {
                let mut jitter = |r: &Unit<Vector3<f64>>| {
                    let v = r.into_inner() / r.z;
                    let j = Vector3::new(rng.random_range(-1.7..1.7), rng.random_range(-1.7..1.7), 0.0) / 800.0;
                    v + j
                };
                let (a, b) = (jitter(&c.edge.ends[0]), jitter(&c.edge.ends[1]));
                Correspondence {
                    edge: EdgePlane::from_rays(Point3::origin(), &a, &b).unwrap(),
                    ..*c
                }
            })
            .collect();
        let sol = med_r_and_t(&noisy, None, &o, trial).unwrap();
        let (q_est, s_est) = unknowns_of(&sol.pose);
        assert!(q_est.angle_to(&q) < 1f64.to_radians(), "trial {trial}: wrong pose");
        assert!((s_est - s).norm() < 0.2, "trial {trial}: wrong position");
        dropped += 10 - sol.inliers.len();
    }
    assert!(dropped <= 2, "{dropped} of 400 good lines rejected");
}
