//! The motion filter (issue 47, item 4; beyond the papers, which propose a motion model in KT
//! §6.2): a constant-velocity Kalman filter on the rig's pose.
//!
//! In: a measured pose per frame with its covariance (Kumar–Hanson §5, `solver::covariance`),
//! the frame times. Out: the prediction for the next frame with its covariance (what maintenance
//! gates and starts from), and the filtered pose with its covariance (what is published).
//!
//! Why: a narrow view (one 50° pinhole turning at 7–12° a frame) sees few lines on some frames;
//! a pose fitted to four of them fixes some directions well and others hardly at all, and
//! Kumar–Hanson's covariance says which. Fused with the motion so far, such a frame still moves
//! the pose where it is informative and follows the motion where it is not, instead of being
//! refused whole (fewer than `min_inliers` lines) and coasted over blind.
//!
//! State: `T_world_rig` = (R, p), the world-frame velocity v and angular velocity ω. Error state
//! (δp, δθ, δv, δω), world frame, with R = exp(δθ) R̂ as in the published covariance
//! (docs/interfaces.md). Motion: p ← p + v dt, R ← exp(ω dt) R, v and ω driven by white
//! acceleration of spectral densities `accel²` and `angular_accel²` (per axis, per second).
//! Measurement: the pose itself, H = [I₆ 0], its innovation (p_m − p̂, log(R_m R̂ᵀ)).
//!
//! Nothing here allocates: the state is a few fixed-size matrices.

use nalgebra::{Matrix3, Matrix6, SMatrix, SVector, Translation3, UnitQuaternion, Vector3, Vector6};
use omnitrack_core::geometry::Pose;

type Matrix12 = SMatrix<f64, 12, 12>;
type Matrix12x6 = SMatrix<f64, 12, 6>;
type Vector12 = SVector<f64, 12>;

/// The 99.9 % quantile of χ² with 6 degrees of freedom: a measurement further than this (in
/// the innovation's own Mahalanobis metric) from the prediction is not the motion continuing.
pub const GATE_CHI2_6: f64 = 22.458;

/// The motion model's noise and the prior on a fresh start's velocity.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MotionNoise {
    /// √ of the linear acceleration's spectral density, m/s² per √s: the σ of the change of
    /// velocity over one second, per axis.
    pub accel_m_s2: f64,
    /// The same for the angular velocity, rad/s² per √s.
    pub angular_accel_rad_s2: f64,
    /// σ of a fresh start's unknown velocity, per axis (m/s).
    pub start_speed_m_s: f64,
    /// σ of a fresh start's unknown angular velocity, per axis (rad/s).
    pub start_turn_rad_s: f64,
}

/// What an update made of a measurement.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Fused {
    /// Fused; its squared Mahalanobis distance from the prediction.
    Yes(f64),
    /// Refused: further from the prediction than [`GATE_CHI2_6`] (the squared distance).
    Outside(f64),
    /// The measurement's covariance is not finite or not positive: nothing to fuse.
    NoInformation,
}

/// A constant-velocity filter on `T_world_rig` (module doc).
#[derive(Clone, Debug)]
pub struct MotionFilter {
    noise: MotionNoise,
    pose: Pose,
    velocity: Vector3<f64>,
    angular: Vector3<f64>,
    /// Over (δp, δθ, δv, δω).
    cov: Matrix12,
    time_ns: u64,
    started: bool,
}

/// The left Jacobian of SO(3) at φ: exp(φ + δ) ≈ exp(J(φ) δ) exp(φ).
fn left_jacobian(phi: &Vector3<f64>) -> Matrix3<f64> {
    let theta = phi.norm();
    let k = phi.cross_matrix();
    if theta < 1e-6 {
        return Matrix3::identity() + k * 0.5;
    }
    let t2 = theta * theta;
    Matrix3::identity() + k * ((1.0 - theta.cos()) / t2) + k * k * ((theta - theta.sin()) / (t2 * theta))
}

impl MotionFilter {
    pub fn new(noise: MotionNoise) -> MotionFilter {
        MotionFilter {
            noise,
            pose: Pose::identity(),
            velocity: Vector3::zeros(),
            angular: Vector3::zeros(),
            cov: Matrix12::identity(),
            time_ns: 0,
            started: false,
        }
    }

    /// Whether a start has been given since [`MotionFilter::new`] or [`MotionFilter::clear`].
    pub fn started(&self) -> bool {
        self.started
    }

    /// Forgets the state: the next frame needs a [`MotionFilter::start`].
    pub fn clear(&mut self) {
        self.started = false;
    }

    /// Starts at `pose` (covariance `cov`, replaced by a metre and a radian where not finite) at
    /// `time_ns`, the velocity unknown (the prior of [`MotionNoise`]).
    pub fn start(&mut self, pose: &Pose, cov: &Matrix6<f64>, time_ns: u64) {
        self.started = true;
        self.pose = *pose;
        self.time_ns = time_ns;
        self.velocity = Vector3::zeros();
        self.angular = Vector3::zeros();
        self.cov = Matrix12::zeros();
        self.cov.fixed_view_mut::<6, 6>(0, 0).copy_from(&sanitised(cov));
        let v2 = self.noise.start_speed_m_s.powi(2);
        let w2 = self.noise.start_turn_rad_s.powi(2);
        for i in 0..3 {
            self.cov[(6 + i, 6 + i)] = v2;
            self.cov[(9 + i, 9 + i)] = w2;
        }
    }

    /// Moves to `pose` at `time_ns` keeping the velocity and its uncertainty (a relocalisation:
    /// the rig moves on through it); starts afresh when there was no start.
    pub fn restart(&mut self, pose: &Pose, cov: &Matrix6<f64>, time_ns: u64) {
        if !self.started {
            return self.start(pose, cov, time_ns);
        }
        self.pose = *pose;
        self.time_ns = time_ns;
        let keep = self.cov.fixed_view::<6, 6>(6, 6).into_owned();
        self.cov = Matrix12::zeros();
        self.cov.fixed_view_mut::<6, 6>(0, 0).copy_from(&sanitised(cov));
        self.cov.fixed_view_mut::<6, 6>(6, 6).copy_from(&keep);
    }

    /// Takes the velocity as the motion from `earlier` (at `earlier_ns`) to the current pose,
    /// its uncertainty unchanged: a relocalised rig moves on as it moved since its last good
    /// frame.
    pub fn continue_from(&mut self, earlier: &Pose, earlier_ns: u64) {
        let dt = self.time_ns.saturating_sub(earlier_ns) as f64 * 1e-9;
        if !self.started || dt <= 0.0 {
            return;
        }
        self.velocity = (self.pose.translation.vector - earlier.translation.vector) / dt;
        self.angular = (self.pose.rotation * earlier.rotation.inverse()).scaled_axis() / dt;
    }

    /// The filtered pose at the last update.
    pub fn pose(&self) -> &Pose {
        &self.pose
    }

    /// The filtered pose's covariance over (tx, ty, tz, rx, ry, rz), world frame.
    pub fn pose_covariance(&self) -> Matrix6<f64> {
        self.cov.fixed_view::<6, 6>(0, 0).into_owned()
    }

    /// The velocity (m/s) and angular velocity (rad/s), world frame.
    pub fn velocity(&self) -> (Vector3<f64>, Vector3<f64>) {
        (self.velocity, self.angular)
    }

    /// The state moved on to `time_ns` and its error transition: (pose, F, Q).
    fn propagate(&self, time_ns: u64) -> (Pose, Matrix12, Matrix12) {
        let dt = time_ns.saturating_sub(self.time_ns) as f64 * 1e-9;
        let phi = self.angular * dt;
        let turn = UnitQuaternion::from_scaled_axis(phi);
        let pose = Pose::from_parts(
            Translation3::from(self.pose.translation.vector + self.velocity * dt),
            turn * self.pose.rotation,
        );
        let mut f = Matrix12::identity();
        let i3 = Matrix3::identity();
        f.fixed_view_mut::<3, 3>(0, 6).copy_from(&(i3 * dt));
        f.fixed_view_mut::<3, 3>(3, 3)
            .copy_from(turn.to_rotation_matrix().matrix());
        f.fixed_view_mut::<3, 3>(3, 9).copy_from(&(left_jacobian(&phi) * dt));
        let mut q = Matrix12::zeros();
        for (block, density) in [
            (0, self.noise.accel_m_s2.powi(2)),
            (3, self.noise.angular_accel_rad_s2.powi(2)),
        ] {
            let (a, b, c) = (density * dt * dt * dt / 3.0, density * dt * dt / 2.0, density * dt);
            for i in 0..3 {
                let (x, v) = (block + i, block + 6 + i);
                q[(x, x)] = a;
                q[(x, v)] = b;
                q[(v, x)] = b;
                q[(v, v)] = c;
            }
        }
        (pose, f, q)
    }

    /// The prediction at `time_ns` and its covariance over the pose, leaving the state as it is.
    pub fn predict(&self, time_ns: u64) -> (Pose, Matrix6<f64>) {
        let (pose, f, q) = self.propagate(time_ns);
        let cov = f * self.cov * f.transpose() + q;
        (pose, cov.fixed_view::<6, 6>(0, 0).into_owned())
    }

    /// Moves the state on to `time_ns` without a measurement (a frame with no pose).
    pub fn coast(&mut self, time_ns: u64) {
        if time_ns <= self.time_ns {
            return;
        }
        let (pose, f, q) = self.propagate(time_ns);
        self.pose = pose;
        self.cov = symmetric(f * self.cov * f.transpose() + q);
        self.time_ns = time_ns;
    }

    /// The innovation of `measured` against the prediction at `time_ns`: (p_m − p̂, log(R_m R̂ᵀ)).
    fn innovation(predicted: &Pose, measured: &Pose) -> Vector6<f64> {
        let dp = measured.translation.vector - predicted.translation.vector;
        let dr = (measured.rotation * predicted.rotation.inverse()).scaled_axis();
        Vector6::new(dp.x, dp.y, dp.z, dr.x, dr.y, dr.z)
    }

    /// Moves to `time_ns` and fuses `measured` with covariance `cov`, unless it lies outside
    /// [`GATE_CHI2_6`] or carries no information (then the state is only moved on).
    pub fn update(&mut self, time_ns: u64, measured: &Pose, cov: &Matrix6<f64>) -> Fused {
        self.coast(time_ns);
        if !usable(cov) {
            return Fused::NoInformation;
        }
        let y = Self::innovation(&self.pose, measured);
        let s = self.cov.fixed_view::<6, 6>(0, 0) + cov;
        let Some(chol) = s.cholesky() else {
            return Fused::NoInformation;
        };
        let d2 = y.dot(&chol.solve(&y));
        if !d2.is_finite() {
            return Fused::NoInformation;
        }
        if d2 > GATE_CHI2_6 {
            return Fused::Outside(d2);
        }
        // K = P Hᵀ S⁻¹ with H = [I₆ 0]: P's first six columns, solved against S.
        let pht: Matrix12x6 = self.cov.fixed_view::<12, 6>(0, 0).into_owned();
        let k: Matrix12x6 = chol.solve(&pht.transpose()).transpose();
        let dx: Vector12 = k * y;
        let rot = UnitQuaternion::from_scaled_axis(Vector3::new(dx[3], dx[4], dx[5]));
        self.pose = Pose::from_parts(
            Translation3::from(self.pose.translation.vector + Vector3::new(dx[0], dx[1], dx[2])),
            rot * self.pose.rotation,
        );
        self.velocity += Vector3::new(dx[6], dx[7], dx[8]);
        self.angular += Vector3::new(dx[9], dx[10], dx[11]);
        // Joseph form: stays positive semi-definite in floating point.
        let mut i_kh = Matrix12::identity();
        let left = i_kh.fixed_view::<12, 6>(0, 0) - k;
        i_kh.fixed_view_mut::<12, 6>(0, 0).copy_from(&left);
        self.cov = symmetric(i_kh * self.cov * i_kh.transpose() + k * cov * k.transpose());
        Fused::Yes(d2)
    }
}

/// The squared Mahalanobis distance of `measured` (covariance `cov`) from `predicted` (covariance
/// `predicted_cov`, as [`MotionFilter::predict`] gives them); `None` when `cov` carries no
/// information.
pub fn distance2(predicted: &Pose, predicted_cov: &Matrix6<f64>, measured: &Pose, cov: &Matrix6<f64>) -> Option<f64> {
    if !usable(cov) {
        return None;
    }
    let y = MotionFilter::innovation(predicted, measured);
    let chol = (predicted_cov + cov).cholesky()?;
    Some(y.dot(&chol.solve(&y)))
}

/// Whether a measurement covariance carries information: finite and positive definite.
fn usable(cov: &Matrix6<f64>) -> bool {
    cov.iter().all(|v| v.is_finite()) && cov.cholesky().is_some()
}

/// `cov` where usable, else a metre and a radian per axis (a start nothing fixes well).
fn sanitised(cov: &Matrix6<f64>) -> Matrix6<f64> {
    if usable(cov) {
        *cov
    } else {
        Matrix6::identity()
    }
}

fn symmetric(m: Matrix12) -> Matrix12 {
    (m + m.transpose()) * 0.5
}

#[cfg(test)]
mod tests;
