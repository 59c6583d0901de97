//! Koch–Teller's side of the solvers: the sample count of eq. 2 (Table 1), ξ minimised by the
//! Nelder–Mead simplex (6-DOF and upright 3-DOF, single pinhole and six-sensor rig), and the
//! anytime consensus sampler (accuracy under outliers, stop reasons, zero allocations, capacity).

use nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};
use omnitrack_core::geometry::{Correspondence, EdgePlane, Pose};
use omnitrack_core::Rig;
use omnitrack_solver::{
    minimise_xi, minimise_xi_upright, r_and_t_refine, sample_count, xi_solve, ConsensusError, ConsensusSampler,
    LineError, SampleScore, SamplingBudget, SharedStart, SimplexOptions, SolveError, SolverOptions, StopReason,
};
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use std::time::Duration;

// ---------------------------------------------------------------- synthetic observations

fn truth() -> Pose {
    Isometry3::from_parts(
        Translation3::new(2.0, -1.0, 1.6),
        UnitQuaternion::from_euler_angles(0.03, -0.05, 0.8),
    )
}

fn rig() -> Rig {
    omnitrack_testkit::shipped_rig()
}

/// A point 3–10 m in front of a camera looking along +z of its own frame, within ±0.6 rad-ish.
fn point_in_front(rng: &mut SmallRng) -> Vector3<f64> {
    let d = rng.random_range(3.0..10.0);
    Vector3::new(rng.random_range(-0.6..0.6) * d, rng.random_range(-0.6..0.6) * d, d)
}

/// An exact correspondence seen from `pose` by a sensor mounted at `t_rig_sensor`: a random
/// segment in front of that sensor, its edge plane through the sensor's centre.
fn observe(rng: &mut SmallRng, pose: &Pose, t_rig_sensor: &Pose) -> Correspondence {
    loop {
        let (a_s, b_s) = (point_in_front(rng), point_in_front(rng));
        let centre = Point3::from(t_rig_sensor.translation.vector);
        // Rays rotated into the rig frame; end points in the rig frame = centre + ray.
        let (ra, rb) = (t_rig_sensor.rotation * a_s, t_rig_sensor.rotation * b_s);
        let Some(edge) = EdgePlane::from_rays(centre, &ra, &rb) else {
            continue;
        };
        if ra.angle(&rb) < 0.1 {
            continue; // keep segments long enough to constrain something
        }
        let segment = [pose * (centre + ra), pose * (centre + rb)];
        return Correspondence { edge, segment };
    }
}

/// `n` exact correspondences for one pinhole camera at the rig origin looking along rig +x.
fn pinhole(rng: &mut SmallRng, pose: &Pose, n: usize) -> Vec<Correspondence> {
    // Camera frame (x right, y down, z forward) → rig frame (x forward, y left, z up).
    let cam = Isometry3::from_parts(
        Translation3::identity(),
        UnitQuaternion::from_basis_unchecked(&[-Vector3::y(), -Vector3::z(), Vector3::x()]),
    );
    (0..n).map(|_| observe(rng, pose, &cam)).collect()
}

/// `per_sensor` exact correspondences for every sensor of the Ladybug rig.
fn rig_observations(rng: &mut SmallRng, rig: &Rig, pose: &Pose, per_sensor: usize) -> Vec<Correspondence> {
    rig.sensors
        .iter()
        .flat_map(|s| (0..per_sensor).map(|_| s.t_rig_sensor).collect::<Vec<_>>())
        .map(|t| observe(rng, pose, &t))
        .collect()
}

/// Turns every observed normal by isotropic noise of `sigma` rad per tangent axis.
fn add_noise(rng: &mut SmallRng, c: &mut [Correspondence], sigma: f64) {
    for corr in c {
        let n = corr.edge.normal.into_inner();
        let u = n.cross(&Vector3::new(0.3, -0.5, 0.81)).normalize();
        let v = n.cross(&u);
        let perturbed = n + sigma * (gauss(rng) * u + gauss(rng) * v);
        corr.edge = corr.edge.with_normal(Unit::new_normalize(perturbed));
    }
}

fn gauss(rng: &mut SmallRng) -> f64 {
    // Box–Muller.
    let u1: f64 = rng.random_range(f64::EPSILON..1.0);
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// `pose` moved by `angle` about a random axis and `dist` along a random direction (world).
fn offset(rng: &mut SmallRng, pose: &Pose, angle: f64, dist: f64) -> Pose {
    let axis = Unit::new_normalize(Vector3::new(gauss(rng), gauss(rng), gauss(rng)));
    let dir = Vector3::new(gauss(rng), gauss(rng), gauss(rng)).normalize();
    Isometry3::from_parts(
        Translation3::from(pose.translation.vector + dist * dir),
        UnitQuaternion::from_axis_angle(&axis, angle) * pose.rotation,
    )
}

/// (rotation error rad, translation error m).
fn errors(a: &Pose, b: &Pose) -> (f64, f64) {
    (
        (a.rotation * b.rotation.inverse()).angle(),
        (a.translation.vector - b.translation.vector).norm(),
    )
}

fn tight() -> SimplexOptions {
    SimplexOptions {
        x_tolerance: 1e-9,
        xi_tolerance: 1e-20,
        max_iterations: 20_000,
        ..Default::default()
    }
}

// ---------------------------------------------------------------- eq. 2, Table 1

#[test]
fn sample_count_reproduces_table_1_exactly() {
    let table: [(f64, [u64; 4]); 3] = [
        (10.0, [10, 9, 9, 8]),
        (30.0, [254, 193, 167, 152]),
        (50.0, [29971, 13743, 9413, 7516]),
    ];
    for (b, row) in table {
        for (q, want) in [30, 40, 50, 60].into_iter().zip(row) {
            assert_eq!(sample_count(10, q, b, 0.95), want, "b = {b} %, |S| = {q}");
        }
    }
    // Saturation when a sample cannot be outlier-free.
    assert_eq!(sample_count(10, 12, 50.0, 0.95), u64::MAX);
}

// ---------------------------------------------------------------- the simplex

/// `minimise_xi` or `minimise_xi_upright`.
type Minimiser = fn(&[Correspondence], &Pose, &SimplexOptions) -> (Pose, f64, u32, bool);

fn assert_recovers(name: &str, c: &[Correspondence], start: &Pose, minimise: Minimiser) {
    let (r0, t0) = errors(start, &truth());
    let (pose, xi, iterations, converged) = minimise(c, start, &tight());
    let (r, t) = errors(&pose, &truth());
    println!(
        "{name}: start {:.2}° / {:.3} m → {r:.2e} rad / {t:.2e} m, ξ = {xi:.2e} rad², {iterations} steps, converged {converged}",
        r0.to_degrees(),
        t0
    );
    assert!(converged, "{name}: did not converge in {iterations} steps");
    assert!(r <= 1e-6 && t <= 1e-6, "{name}: error {r:e} rad / {t:e} m");
    assert!(xi < 1e-12, "{name}: ξ = {xi:e}");
}

#[test]
fn simplex_recovers_an_exact_pose_for_a_pinhole_camera() {
    let mut rng = SmallRng::seed_from_u64(1);
    let c = pinhole(&mut rng, &truth(), 12);
    for _ in 0..3 {
        let start = offset(&mut rng, &truth(), 3f64.to_radians(), 0.20);
        assert_recovers("pinhole 6-DOF", &c, &start, minimise_xi);
    }
}

#[test]
fn simplex_recovers_an_exact_pose_for_the_six_sensor_rig() {
    let mut rng = SmallRng::seed_from_u64(2);
    let c = rig_observations(&mut rng, &rig(), &truth(), 2);
    assert_eq!(c.len(), 12);
    for _ in 0..3 {
        let start = offset(&mut rng, &truth(), 3f64.to_radians(), 0.20);
        assert_recovers("rig 6-DOF", &c, &start, minimise_xi);
    }
}

#[test]
fn upright_simplex_recovers_x_y_and_yaw() {
    let mut rng = SmallRng::seed_from_u64(3);
    for (name, c) in [
        ("pinhole upright", pinhole(&mut rng, &truth(), 10)),
        ("rig upright", rig_observations(&mut rng, &rig(), &truth(), 2)),
    ] {
        // Off by 3° of yaw and 20 cm in the ground plane; height, roll, pitch right.
        let p = truth();
        let start = Isometry3::from_parts(
            Translation3::from(p.translation.vector + Vector3::new(0.12, -0.16, 0.0)),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), -3f64.to_radians()) * p.rotation,
        );
        assert_recovers(name, &c, &start, minimise_xi_upright);
        // The upright search cannot move what it holds fixed.
        let (pose, ..) = minimise_xi_upright(&c, &start, &SimplexOptions::default());
        assert_eq!(pose.translation.z, start.translation.z);
    }
}

#[test]
fn xi_solve_covariance_matches_the_scatter_of_noisy_solutions() {
    let mut rng = SmallRng::seed_from_u64(4);
    let exact = rig_observations(&mut rng, &rig(), &truth(), 4);
    let sigma = 0.5f64.to_radians();
    let o = SolverOptions {
        edge_sigma_rad: sigma,
        ..Default::default()
    };
    let simplex = SimplexOptions::default();
    let sol = xi_solve(&exact, &offset(&mut rng, &truth(), 0.02, 0.05), &o, &simplex).unwrap();
    assert_eq!(sol.inliers, (0..exact.len()).collect::<Vec<_>>());
    let cov = sol.covariance;
    assert!((cov - cov.transpose()).norm() < 1e-12 * cov.norm());
    assert!(cov.cholesky().is_some(), "covariance not positive definite");
    // Monte Carlo: the scatter of the parameters (tx, ty, tz, rx, ry, rz) should match.
    let trials = 60;
    let mut sq = [0.0f64; 6];
    for _ in 0..trials {
        let mut c = exact.clone();
        add_noise(&mut rng, &mut c, sigma);
        let (p, ..) = minimise_xi(&c, &truth(), &simplex);
        let dt = p.translation.vector - truth().translation.vector;
        let dr = (p.rotation * truth().rotation.inverse()).scaled_axis();
        for k in 0..3 {
            sq[k] += dt[k] * dt[k] / trials as f64;
            sq[k + 3] += dr[k] * dr[k] / trials as f64;
        }
    }
    for k in 0..6 {
        let ratio = (sq[k] / cov[(k, k)]).sqrt();
        println!(
            "parameter {k}: empirical σ / predicted σ = {ratio:.2} (predicted {:.2e})",
            cov[(k, k)].sqrt()
        );
        assert!((0.6..1.6).contains(&ratio), "parameter {k}: ratio {ratio}");
    }
    assert_eq!(
        xi_solve(&exact[..2], &truth(), &o, &simplex),
        Err(SolveError::TooFew { needed: 3, got: 2 })
    );
}

// ---------------------------------------------------------------- consensus sampling

const LAMBDA: usize = 10;

/// 40 correspondences over the rig, σ = 0.5° noise, 30 % (12) gross outliers: edges paired with
/// another correspondence's segment. Returns them and the outlier indices.
fn cluttered(rng: &mut SmallRng) -> (Vec<Correspondence>, Vec<usize>) {
    let rig = rig();
    let mut c: Vec<Correspondence> = (0..40)
        .map(|i| observe(rng, &truth(), &rig.sensors[i % rig.sensors.len()].t_rig_sensor))
        .collect();
    add_noise(rng, &mut c, 0.5f64.to_radians());
    let mut outliers = Vec::new();
    while outliers.len() < 12 {
        let i = rng.random_range(0..40);
        if !outliers.contains(&i) {
            outliers.push(i);
        }
    }
    outliers.sort();
    let segments: Vec<_> = c.iter().map(|x| x.segment).collect();
    for &i in &outliers {
        let j = (i + rng.random_range(1..40)) % 40;
        c[i].segment = segments[j];
    }
    (c, outliers)
}

fn budget(max_samples: u64, time_budget: Duration) -> SamplingBudget {
    SamplingBudget {
        max_samples,
        time_budget,
        inlier_alpha_rad: 1.5f64.to_radians(),
        score: SampleScore::Truncated,
    }
}

fn simplex_fit() -> impl FnMut(&[Correspondence], &[usize], &Pose) -> Option<Pose> {
    let opts = SimplexOptions {
        x_tolerance: 1e-6,
        ..Default::default()
    };
    move |set: &[Correspondence], _: &[usize], start: &Pose| Some(minimise_xi(set, start, &opts).0)
}

/// Eq. 2 with 95 % success means about 1 run in 20 draws no outlier-free sample and fails: in a
/// throwaway release run over 40 seeds, exactly the 2 runs without a clean sample failed (the
/// other 38 met 0.5° / 5 cm with every outlier flagged). The seeds here are fixed.
#[test]
fn consensus_recovers_the_pose_through_30_percent_outliers() {
    let s_t = sample_count(LAMBDA, 40, 30.0, 0.95);
    assert_eq!(s_t, 193);
    let mut sampler = ConsensusSampler::new(64, LAMBDA, 1000);
    // MSAC's truncated squares and Kumar–Hanson's least median of squares alike.
    for (seed, score) in [10, 11]
        .into_iter()
        .flat_map(|s| [(s, SampleScore::Truncated), (s, SampleScore::Median)])
    {
        let mut rng = SmallRng::seed_from_u64(seed);
        let (c, outliers) = cluttered(&mut rng);
        // Frame-to-frame motion: the guess is off by 1° and 5 cm.
        let guess = offset(&mut rng, &truth(), 1f64.to_radians(), 0.05);
        let b = SamplingBudget {
            score,
            ..budget(s_t, Duration::from_secs(600))
        };
        let out = sampler.run(&c, &guess, &b, &mut rng, &mut simplex_fit()).unwrap();
        let (r, t) = errors(&out.pose, &truth());
        let inliers = out.inliers(&sampler);
        let flagged = outliers.iter().filter(|i| !inliers.contains(i)).count();
        let kept = inliers.iter().filter(|i| !outliers.contains(i)).count();
        println!(
            "seed {seed}, {score:?}: {} samples ({:?}), error {:.3}° / {:.1} mm, {flagged}/12 outliers flagged, \
             {kept}/28 inliers kept, ξ(inliers) = {:.2e} rad², refitted {}",
            out.samples,
            out.stop,
            r.to_degrees(),
            t * 1e3,
            out.xi_rad2,
            out.refitted
        );
        assert_eq!(out.stop, StopReason::SampleCount);
        assert_eq!(out.samples, s_t);
        assert!(
            r <= 0.5f64.to_radians() && t <= 0.05,
            "{score:?}: error {:.3}° / {t:.3} m",
            r.to_degrees()
        );
        assert!(
            flagged >= 11,
            "{score:?}: only {flagged} of 12 outliers flagged (≥ 90 % needed)"
        );
        assert!(inliers.windows(2).all(|w| w[0] < w[1]));
        assert_eq!(out.inlier_count, inliers.len());
    }
}

/// A narrow view's set: 12 correspondences, three of them wrong. No sample of λ = 10 can leave
/// all three out; one sample of 6 (the tracker's half of the set) in 11 does, and the consensus
/// finds the pose and flags all three.
#[test]
fn consensus_with_smaller_samples_rejects_the_wrong_matches_of_a_small_set() {
    let rig = rig();
    let mut sampler = ConsensusSampler::new(64, LAMBDA, 1000);
    for seed in [20, 21, 22] {
        let mut rng = SmallRng::seed_from_u64(seed);
        let mut c: Vec<Correspondence> = (0..12)
            .map(|i| observe(&mut rng, &truth(), &rig.sensors[i % rig.sensors.len()].t_rig_sensor))
            .collect();
        add_noise(&mut rng, &mut c, 0.5f64.to_radians());
        // Three edges paired with each other's segments.
        let (s3, s8) = (c[3].segment, c[8].segment);
        c[3].segment = c[10].segment;
        c[8].segment = s3;
        c[10].segment = s8;
        let wrong = [3usize, 8, 10];
        let lambda = 6;
        // More samples than eq. 2 asks (24 at 30 %: 90 % odds of a clean one), so that the
        // fixed seeds do not decide the test.
        let s_t = 8 * sample_count(lambda, c.len(), 30.0, 0.95);
        let guess = offset(&mut rng, &truth(), 1f64.to_radians(), 0.05);
        let out = sampler
            .run_sized(
                lambda,
                &c,
                &guess,
                &budget(s_t, Duration::from_secs(600)),
                &mut rng,
                &mut simplex_fit(),
            )
            .unwrap();
        let inliers = out.inliers(&sampler).to_vec();
        let flagged = wrong.iter().filter(|i| !inliers.contains(i)).count();
        assert_eq!(flagged, 3, "seed {seed}: {flagged} of 3 wrong matches flagged");
        assert_eq!(inliers.len(), 9, "seed {seed}: every right match kept");
        // Nine noisy lines (0.5°) fix the pose only to a few centimetres.
        let (r, t) = errors(&out.pose, &truth());
        assert!(
            r <= 1f64.to_radians() && t <= 0.15,
            "seed {seed}: error {:.3}° / {t:.3} m",
            r.to_degrees()
        );
    }
}

#[test]
fn consensus_stops_on_its_time_budget() {
    let mut rng = SmallRng::seed_from_u64(12);
    let (c, _) = cluttered(&mut rng);
    let mut sampler = ConsensusSampler::new(40, LAMBDA, 1000);
    let out = sampler
        .run(
            &c,
            &truth(),
            &budget(193, Duration::from_nanos(1)),
            &mut rng,
            &mut simplex_fit(),
        )
        .unwrap();
    assert_eq!(out.stop, StopReason::TimeBudget);
    assert_eq!(out.samples, 1);
    // The sampler's own cap bounds the budget's sample count.
    let mut capped = ConsensusSampler::new(40, LAMBDA, 5);
    let out = capped
        .run(
            &c,
            &truth(),
            &budget(193, Duration::from_secs(600)),
            &mut rng,
            &mut simplex_fit(),
        )
        .unwrap();
    assert_eq!((out.stop, out.samples), (StopReason::SampleCount, 5));
}

/// The bits of a pose, for comparing fits exactly.
fn bits(p: &Pose) -> [u64; 7] {
    let (t, q) = (p.translation.vector, p.rotation.coords);
    [t.x, t.y, t.z, q.x, q.y, q.z, q.w].map(f64::to_bits)
}

/// A fit from the shared first step is R_and_T's from scratch, bit for bit: for every line
/// error, on samples with and without outliers, from the prepared start and from another one,
/// and through the consensus sampler (sample fits and the refit).
#[test]
fn shared_start_fits_are_r_and_t_refine_bit_for_bit() {
    let mut rng = SmallRng::seed_from_u64(14);
    let (c, _) = cluttered(&mut rng);
    let mut shared = SharedStart::new(40);
    for error in [LineError::E1, LineError::E2, LineError::E3] {
        let o = SolverOptions {
            error,
            convergence_rad: 1e-6,
            ..SolverOptions::default()
        };
        let guess = offset(&mut rng, &truth(), 2f64.to_radians(), 0.1);
        shared.prepare(&c, &guess, error);
        for trial in 0..300 {
            let n = 3 + trial % 12;
            let mut lines: Vec<usize> = (0..c.len()).collect();
            for i in 0..n {
                let j = rng.random_range(i..c.len());
                lines.swap(i, j);
            }
            lines.truncate(n);
            let set: Vec<Correspondence> = lines.iter().map(|&i| c[i]).collect();
            let elsewhere = offset(&mut rng, &guess, 0.01, 0.01);
            for start in [guess, elsewhere] {
                let want = r_and_t_refine(&set, &start, &o);
                let got = shared.refine(&set, &lines, &start, &o);
                assert_eq!(
                    got.map(|p| bits(&p)),
                    want.map(|p| bits(&p)),
                    "{error:?}, trial {trial}"
                );
            }
        }
        let o_other = SolverOptions {
            error: if error == LineError::E1 {
                LineError::E2
            } else {
                LineError::E1
            },
            ..o.clone()
        };
        let want = r_and_t_refine(&c[..10], &guess, &o_other);
        let got = shared.refine(&c[..10], &(0..10).collect::<Vec<_>>(), &guess, &o_other);
        assert_eq!(
            got.map(|p| bits(&p)),
            want.map(|p| bits(&p)),
            "{error:?} rows, another error"
        );

        let b = SamplingBudget {
            score: SampleScore::Median,
            ..budget(60, Duration::from_secs(600))
        };
        let mut sampler = ConsensusSampler::new(40, LAMBDA, 1000);
        let seed = rng.random();
        let plain = sampler
            .run(
                &c,
                &guess,
                &b,
                &mut SmallRng::seed_from_u64(seed),
                &mut |set, _, start| r_and_t_refine(set, start, &o),
            )
            .unwrap();
        let from_shared = sampler
            .run(
                &c,
                &guess,
                &b,
                &mut SmallRng::seed_from_u64(seed),
                &mut |set, lines, start| shared.refine(set, lines, start, &o),
            )
            .unwrap();
        assert_eq!(bits(&from_shared.pose), bits(&plain.pose), "{error:?} consensus");
        assert_eq!(
            (from_shared.samples, from_shared.inlier_count),
            (plain.samples, plain.inlier_count)
        );
    }
    // A set beyond the capacity prepares nothing; its fits are computed in full.
    let mut small = SharedStart::new(8);
    small.prepare(&c, &truth(), LineError::E2);
    let o = SolverOptions {
        error: LineError::E2,
        ..SolverOptions::default()
    };
    let want = r_and_t_refine(&c[..10], &truth(), &o);
    let got = small.refine(&c[..10], &(0..10).collect::<Vec<_>>(), &truth(), &o);
    assert_eq!(got.map(|p| bits(&p)), want.map(|p| bits(&p)));
}

#[test]
fn consensus_run_allocates_nothing_after_construction() {
    let mut rng = SmallRng::seed_from_u64(13);
    let (c, _) = cluttered(&mut rng);
    let mut sampler = ConsensusSampler::new(40, LAMBDA, 1000);
    let mut fit = simplex_fit();
    let b = budget(30, Duration::from_secs(600));
    for _ in 0..2 {
        let (out, allocations) =
            omnitrack_testkit::allocations_in(|| sampler.run(&c, &truth(), &b, &mut rng, &mut fit));
        let out = out.unwrap();
        assert_eq!(out.samples, 30);
        assert_eq!(allocations, 0, "run allocated {allocations} times");
    }
    // The counter does count (the test could fail): a Vec allocates.
    let (v, allocations) = omnitrack_testkit::allocations_in(|| vec![1u8; 16]);
    assert_eq!(v.len(), 16);
    assert_eq!(allocations, 1);
}

#[test]
fn consensus_refuses_more_correspondences_than_its_capacity() {
    let mut rng = SmallRng::seed_from_u64(14);
    let (c, _) = cluttered(&mut rng);
    let mut sampler = ConsensusSampler::new(20, LAMBDA, 1000);
    let err = sampler
        .run(
            &c,
            &truth(),
            &budget(10, Duration::from_secs(1)),
            &mut rng,
            &mut simplex_fit(),
        )
        .unwrap_err();
    assert_eq!(err, ConsensusError::CapacityExceeded { capacity: 20, got: 40 });
    assert!(err.to_string().contains("capacity of 20"), "{err}");
    let err = sampler
        .run(
            &c[..5],
            &truth(),
            &budget(10, Duration::from_secs(1)),
            &mut rng,
            &mut simplex_fit(),
        )
        .unwrap_err();
    assert_eq!(err, ConsensusError::Solve(SolveError::TooFew { needed: 10, got: 5 }));
}
