use super::*;

fn noise() -> MotionNoise {
    MotionNoise {
        accel_m_s2: 2.0,
        angular_accel_rad_s2: 4.0,
        start_speed_m_s: 2.0,
        start_turn_rad_s: 6.0,
    }
}

fn pose(t: [f64; 3], r: [f64; 3]) -> Pose {
    Pose::from_parts(
        Translation3::new(t[0], t[1], t[2]),
        UnitQuaternion::from_scaled_axis(Vector3::new(r[0], r[1], r[2])),
    )
}

/// The state moved on by `dt` with every component of the error state perturbed: the error
/// transition F must map a small perturbation δx at the start to the perturbation of the
/// propagated state, as finite differences of the motion itself give it.
#[test]
fn the_error_transition_is_the_motions_jacobian() {
    let mut f0 = MotionFilter::new(noise());
    let start = pose([1.0, -2.0, 1.5], [0.1, -0.2, 1.1]);
    f0.start(&start, &Matrix6::identity(), 0);
    f0.velocity = Vector3::new(0.8, -0.3, 0.05);
    f0.angular = Vector3::new(0.2, -0.4, 2.5);
    let t = 100_000_000; // 0.1 s: a turn of a quarter radian
    let (p0, f, _) = f0.propagate(t);
    let h = 1e-6;
    for j in 0..12 {
        let mut g = f0.clone();
        let mut d = Vector12::zeros();
        d[j] = h;
        g.pose = Pose::from_parts(
            Translation3::from(g.pose.translation.vector + Vector3::new(d[0], d[1], d[2])),
            UnitQuaternion::from_scaled_axis(Vector3::new(d[3], d[4], d[5])) * g.pose.rotation,
        );
        g.velocity += Vector3::new(d[6], d[7], d[8]);
        g.angular += Vector3::new(d[9], d[10], d[11]);
        let (p1, _, _) = g.propagate(t);
        let dp = (p1.translation.vector - p0.translation.vector) / h;
        let dr = (p1.rotation * p0.rotation.inverse()).scaled_axis() / h;
        let numeric = [dp.x, dp.y, dp.z, dr.x, dr.y, dr.z];
        for (i, n) in numeric.iter().enumerate() {
            assert!(
                (f[(i, j)] - n).abs() < 1e-5,
                "F[{i},{j}] = {} against {n} by finite differences",
                f[(i, j)]
            );
        }
        // Velocities are carried unchanged.
        for i in 6..12 {
            assert_eq!(f[(i, j)], if i == j { 1.0 } else { 0.0 });
        }
    }
}

/// Noisy measurements of a rig walking and turning at a constant rate: the filter learns the
/// velocity, its prediction one frame ahead lands nearer the truth than the last measurement,
/// and its pose is nearer the truth than the measurements are.
#[test]
fn the_filter_learns_a_constant_motion_and_beats_its_measurements() {
    let mut filter = MotionFilter::new(noise());
    let v = Vector3::new(1.2, 0.3, 0.0);
    let w = Vector3::new(0.0, 0.0, 1.5);
    let truth = |k: u64| {
        let s = k as f64 / 30.0;
        pose([v.x * s, v.y * s, 1.6], [w.x * s, w.y * s, w.z * s])
    };
    let sigma_p = 0.02;
    let sigma_r = 0.01;
    let mut cov = Matrix6::zeros();
    for i in 0..3 {
        cov[(i, i)] = sigma_p * sigma_p;
        cov[(3 + i, 3 + i)] = sigma_r * sigma_r;
    }
    // A fixed sequence of offsets of about one σ, so that the test is the same every run.
    let offset = |k: u64| {
        let a = k as f64 * 2.399;
        Vector6::new(
            a.cos() * sigma_p,
            a.sin() * sigma_p,
            (a * 0.7).cos() * sigma_p,
            (a * 1.3).sin() * sigma_r,
            (a * 0.4).cos() * sigma_r,
            (a * 1.9).sin() * sigma_r,
        )
    };
    let (mut err_meas, mut err_filt, mut err_pred) = (0.0, 0.0, 0.0);
    for k in 0..90u64 {
        let t = k * 33_333_333;
        let g = truth(k);
        let o = offset(k);
        let m = Pose::from_parts(
            Translation3::from(g.translation.vector + Vector3::new(o[0], o[1], o[2])),
            UnitQuaternion::from_scaled_axis(Vector3::new(o[3], o[4], o[5])) * g.rotation,
        );
        if k == 0 {
            filter.start(&m, &cov, t);
            continue;
        }
        let (pred, _) = filter.predict(t);
        let fused = filter.update(t, &m, &cov);
        assert!(matches!(fused, Fused::Yes(_)), "frame {k}: {fused:?}");
        if k >= 30 {
            err_meas += (m.translation.vector - g.translation.vector).norm();
            err_filt += (filter.pose().translation.vector - g.translation.vector).norm();
            err_pred += (pred.translation.vector - g.translation.vector).norm();
        }
    }
    let (vel, ang) = filter.velocity();
    assert!((vel - v).norm() < 0.3, "velocity {vel:?}");
    assert!((ang - w).norm() < 0.5, "angular velocity {ang:?}");
    assert!(
        err_filt < 0.8 * err_meas,
        "filtered {err_filt} against measured {err_meas}"
    );
    assert!(
        err_pred < err_meas * 1.5,
        "predicted {err_pred} against measured {err_meas}"
    );
}

/// A measurement well outside the predicted uncertainty is refused and leaves the state on its
/// course; one with no information is not fused.
#[test]
fn a_jump_is_refused_and_a_measurement_without_information_is_not_fused() {
    let mut filter = MotionFilter::new(noise());
    let cov = Matrix6::from_diagonal_element(1e-4);
    filter.start(&pose([0.0, 0.0, 1.5], [0.0, 0.0, 0.0]), &cov, 0);
    for k in 1..10u64 {
        let p = pose([0.03 * k as f64, 0.0, 1.5], [0.0, 0.0, 0.0]);
        assert!(matches!(filter.update(k * 33_333_333, &p, &cov), Fused::Yes(_)));
    }
    let before = *filter.pose();
    let jump = pose([2.0, 1.0, 1.5], [0.0, 0.0, 1.5]);
    assert!(matches!(filter.update(10 * 33_333_333, &jump, &cov), Fused::Outside(d) if d > GATE_CHI2_6));
    // Moved on by the motion, not towards the jump.
    assert!((filter.pose().translation.vector.x - before.translation.vector.x - 0.03).abs() < 0.01);
    let blind = Matrix6::from_diagonal_element(f64::INFINITY);
    assert_eq!(filter.update(11 * 33_333_333, &jump, &blind), Fused::NoInformation);
    let (predicted, predicted_cov) = filter.predict(12 * 33_333_333);
    assert!(distance2(&predicted, &predicted_cov, &jump, &blind).is_none());
    let d2 = distance2(&predicted, &predicted_cov, &jump, &cov).expect("informative");
    assert!(d2 > GATE_CHI2_6);
}

/// A pose measured well in some directions and hardly in others (a wall seen face on fixes the
/// distance to it, not the position along it) moves the filter only where it is informative.
#[test]
fn a_partly_informative_measurement_moves_only_what_it_fixes() {
    let mut filter = MotionFilter::new(noise());
    let tight = Matrix6::from_diagonal_element(1e-4);
    filter.start(&pose([0.0, 0.0, 1.5], [0.0, 0.0, 0.0]), &tight, 0);
    // x fixed to a millimetre, y to 10 m: the measurement says x and y both moved 5 cm.
    let mut cov = Matrix6::from_diagonal_element(1e-6);
    cov[(1, 1)] = 100.0;
    let m = pose([0.05, 0.05, 1.5], [0.0, 0.0, 0.0]);
    assert!(matches!(filter.update(33_333_333, &m, &cov), Fused::Yes(_)));
    let p = filter.pose().translation.vector;
    assert!((p.x - 0.05).abs() < 0.005, "x follows the measurement: {}", p.x);
    assert!(p.y.abs() < 0.005, "y stays with the prediction: {}", p.y);
}

/// Coasting grows the pose's uncertainty as the motion model says: with the velocity known
/// exactly, the position variance after dt is accel² dt³ / 3.
#[test]
fn coasting_grows_the_uncertainty_by_the_motion_models_noise() {
    let mut filter = MotionFilter::new(noise());
    filter.start(&Pose::identity(), &Matrix6::zeros(), 0);
    filter.cov = Matrix12::zeros();
    filter.coast(500_000_000);
    let dt: f64 = 0.5;
    let c = filter.pose_covariance();
    assert!((c[(0, 0)] - 4.0 * dt.powi(3) / 3.0).abs() < 1e-12);
    assert!((c[(3, 3)] - 16.0 * dt.powi(3) / 3.0).abs() < 1e-12);
    // A frame from the past moves nothing.
    filter.coast(100);
    assert_eq!(filter.pose_covariance(), c);
}

#[test]
fn left_jacobian_matches_finite_differences() {
    let phi = Vector3::new(0.3, -0.5, 0.9);
    let j = left_jacobian(&phi);
    let base = UnitQuaternion::from_scaled_axis(phi);
    let h = 1e-7;
    for k in 0..3 {
        let mut d = Vector3::zeros();
        d[k] = h;
        let moved = UnitQuaternion::from_scaled_axis(phi + d);
        let col = (moved * base.inverse()).scaled_axis() / h;
        assert!(
            (col - j.column(k)).norm() < 1e-5,
            "column {k}: {col:?} against {:?}",
            j.column(k)
        );
    }
}
