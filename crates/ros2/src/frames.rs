//! REP-105 frames: the tracker's pose of the rig in the building's frame (`map`) becomes the pose
//! of the robot's `base_link` in `map`, and, where the robot has odometry, the `map → odom`
//! transform that puts its `odom → base_link` where the tracker saw it.
//!
//! - The rig is mounted on the robot at `T_base_rig` (`--rig-in-base`; identity when the rig
//!   frame is `base_link`, as on a helmet). `T_map_base = T_map_rig · T_base_rig⁻¹`.
//! - omnitrack's covariance is over (tx, ty, tz, rx, ry, rz) with the rotation a small-angle
//!   vector about the world's (map's) axes: ROS's order and convention for a
//!   `PoseWithCovariance` in `header.frame_id`. Moving the point from the rig's origin to the
//!   base's by the lever arm `a = R_map_rig · t_rig_base` adds `δθ × a` to the position error:
//!   `Σ_base = J Σ_rig Jᵀ`, `J = [[I, −[a]×], [0, I]]`; the rotation block is unchanged.
//! - `T_map_odom = T_map_base(t) · T_odom_base(t)⁻¹`, with `T_odom_base(t)` the robot's odometry
//!   at the pose's own stamp `t`, interpolated between the two `/tf` samples around it (linear
//!   in translation, spherical in rotation), or the newest one when `t` is at most the tolerance
//!   past it. A pose with no odometry around its stamp gets no `map → odom` (counted), since a
//!   transform from another instant would move the robot by its motion in between.

use crate::msg;
use nalgebra::{Isometry3, Matrix6, Quaternion, Translation3, UnitQuaternion, Vector3};
use std::collections::VecDeque;

/// A rigid transform: `T_a_b` maps coordinates in frame b to frame a.
pub type Iso = Isometry3<f64>;

/// The tracker's `T_world_rig` and covariance from its sample.
pub fn rig_pose(s: &omnitrack_io::publish::PoseSample) -> Option<(Iso, Matrix6<f64>)> {
    let pose = s.pose().ok()?;
    Some((pose, s.covariance_matrix()))
}

/// `T_map_base` and its covariance from `T_map_rig`, its covariance and `T_base_rig`.
pub fn base_pose(map_rig: &Iso, cov_rig: &Matrix6<f64>, base_rig: &Iso) -> (Iso, Matrix6<f64>) {
    let rig_base = base_rig.inverse();
    let map_base = map_rig * rig_base;
    let a = map_rig.rotation * rig_base.translation.vector;
    let mut j = Matrix6::identity();
    j.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-a.cross_matrix()));
    (map_base, j * cov_rig * j.transpose())
}

/// A pose as ROS writes it (quaternion x, y, z, w).
pub fn to_msg_pose(p: &Iso) -> msg::Pose {
    let t = p.translation.vector;
    let q = p.rotation.quaternion();
    msg::Pose {
        position: msg::Point { x: t.x, y: t.y, z: t.z },
        orientation: msg::Quaternion {
            x: q.i,
            y: q.j,
            z: q.k,
            w: q.w,
        },
    }
}

/// The transform of a `/tf` message, or `None` when it is not finite or its quaternion not unit
/// (within 1e-3: what a message passed through text keeps).
pub fn from_msg_transform(t: &msg::Transform) -> Option<Iso> {
    let v = Vector3::new(t.translation.x, t.translation.y, t.translation.z);
    let q = Quaternion::new(t.rotation.w, t.rotation.x, t.rotation.y, t.rotation.z);
    let finite = v.iter().chain(q.coords.iter()).all(|c| c.is_finite());
    (finite && (q.norm() - 1.0).abs() < 1e-3)
        .then(|| Isometry3::from_parts(Translation3::from(v), UnitQuaternion::from_quaternion(q)))
}

/// A transform as ROS writes it.
pub fn to_msg_transform(p: &Iso) -> msg::Transform {
    let m = to_msg_pose(p);
    msg::Transform {
        translation: m.position,
        rotation: m.orientation,
    }
}

/// `x y z qx qy qz qw` (ROS's order, as `static_transform_publisher` takes it): `--rig-in-base`.
pub fn parse_transform(s: &str) -> Result<Iso, String> {
    let v: Vec<f64> = s
        .split(|c: char| c == ',' || c.is_whitespace())
        .filter(|p| !p.is_empty())
        .map(|p| p.parse::<f64>().map_err(|_| format!("'{p}' is not a number")))
        .collect::<Result<_, _>>()?;
    let [x, y, z, qx, qy, qz, qw] = v[..] else {
        return Err(format!("7 numbers x,y,z,qx,qy,qz,qw are needed, found {}", v.len()));
    };
    let t = msg::Transform {
        translation: msg::Point { x, y, z },
        rotation: msg::Quaternion {
            x: qx,
            y: qy,
            z: qz,
            w: qw,
        },
    };
    from_msg_transform(&t).ok_or_else(|| {
        let n = (qx * qx + qy * qy + qz * qz + qw * qw).sqrt();
        format!("the quaternion ({qx}, {qy}, {qz}, {qw}) has norm {n}, not 1")
    })
}

/// How far back the odometry is kept.
pub const ODOM_KEEP_NS: i64 = 10_000_000_000;

/// Why a pose got no `map → odom`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OdomMiss {
    /// No `odom → base_link` was received yet.
    None,
    /// The pose is older than the oldest odometry kept.
    Before,
    /// The pose is newer than the newest odometry by more than the tolerance.
    After,
}

impl OdomMiss {
    pub fn as_str(self) -> &'static str {
        match self {
            OdomMiss::None => "no odometry received yet",
            OdomMiss::Before => "the pose is older than the odometry kept",
            OdomMiss::After => "no odometry as recent as the pose",
        }
    }
}

/// The robot's recent `T_odom_base`, by ROS stamp (ns).
#[derive(Debug, Default)]
pub struct Odometry {
    samples: VecDeque<(i64, Iso)>,
}

impl Odometry {
    /// Adds a sample; one out of order is put in its place, and what is older than
    /// [`ODOM_KEEP_NS`] before the newest is forgotten.
    pub fn push(&mut self, stamp_ns: i64, odom_base: Iso) {
        let at = self.samples.partition_point(|(t, _)| *t <= stamp_ns);
        if at > 0 && self.samples[at - 1].0 == stamp_ns {
            self.samples[at - 1].1 = odom_base;
        } else {
            self.samples.insert(at, (stamp_ns, odom_base));
        }
        let newest = self.samples.back().map_or(stamp_ns, |s| s.0);
        while self.samples.front().is_some_and(|(t, _)| newest - t > ODOM_KEEP_NS) {
            self.samples.pop_front();
        }
    }

    /// `T_odom_base` at `stamp_ns`: interpolated between the samples around it, or the newest
    /// when `stamp_ns` is at most `tolerance_ns` past it.
    pub fn at(&self, stamp_ns: i64, tolerance_ns: i64) -> Result<Iso, OdomMiss> {
        let (&(first, _), &(last, newest)) = self.samples.front().zip(self.samples.back()).ok_or(OdomMiss::None)?;
        if stamp_ns >= last {
            return if stamp_ns - last <= tolerance_ns {
                Ok(newest)
            } else {
                Err(OdomMiss::After)
            };
        }
        if stamp_ns < first {
            return Err(OdomMiss::Before);
        }
        let i = self.samples.partition_point(|(t, _)| *t <= stamp_ns);
        let (t0, a) = self.samples[i - 1];
        let (t1, b) = self.samples[i];
        let f = (stamp_ns - t0) as f64 / (t1 - t0) as f64;
        Ok(a.lerp_slerp(&b, f))
    }
}

/// `T_map_odom = T_map_base · T_odom_base⁻¹`.
pub fn map_odom(map_base: &Iso, odom_base: &Iso) -> Iso {
    map_base * odom_base.inverse()
}

/// A `/tf` frame name as tf2 compares it (ROS 2 frame ids carry no leading slash).
pub fn frame_name(id: &str) -> &str {
    id.trim_start_matches('/')
}

#[cfg(test)]
mod tests {
    use super::*;

    fn iso(t: [f64; 3], axis: [f64; 3], angle: f64) -> Iso {
        Isometry3::from_parts(
            Translation3::new(t[0], t[1], t[2]),
            UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_normalize(Vector3::from(axis)), angle),
        )
    }

    #[test]
    fn the_base_pose_moves_by_the_lever_arm_and_its_covariance_with_it() {
        let map_rig = iso([4.0, -1.0, 1.5], [0.0, 0.0, 1.0], 0.7);
        // The rig 0.3 m ahead of and 1.2 m above the base, turned 10° down.
        let base_rig = iso([0.3, 0.0, 1.2], [0.0, 1.0, 0.0], 10f64.to_radians());
        let mut cov = Matrix6::zeros();
        // Only the yaw is uncertain: the base, away from the rig, moves sideways with it.
        cov[(5, 5)] = 0.01;
        let (map_base, cov_base) = base_pose(&map_rig, &cov, &base_rig);
        assert!((map_base * base_rig)
            .translation
            .vector
            .relative_eq(&map_rig.translation.vector, 1e-12, 1e-12));
        // Numerically: turn the rig by a small yaw about the world's z, see where the base goes.
        let e = 1e-6;
        let turned = Isometry3::from_parts(
            map_rig.translation,
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), e) * map_rig.rotation,
        );
        let (moved, _) = base_pose(&turned, &cov, &base_rig);
        let d = (moved.translation.vector - map_base.translation.vector) / e;
        for r in 0..3 {
            for c in 0..3 {
                let expected = d[r] * d[c] * 0.01;
                assert!((cov_base[(r, c)] - expected).abs() < 1e-8, "({r},{c}) {cov_base}");
            }
            assert!((cov_base[(r, 5)] - d[r] * 0.01).abs() < 1e-8);
        }
        assert_eq!(cov_base[(5, 5)], 0.01);
        // Rig frame = base frame: nothing changes.
        let (same, same_cov) = base_pose(&map_rig, &cov, &Isometry3::identity());
        assert_eq!((same, same_cov), (map_rig, cov));
    }

    #[test]
    fn map_odom_puts_the_robots_odometry_where_the_tracker_saw_it() {
        let map_base = iso([10.0, 5.0, 0.0], [0.0, 0.0, 1.0], 1.0);
        let odom_base = iso([2.0, -1.0, 0.0], [0.0, 0.0, 1.0], 0.25);
        let m = map_odom(&map_base, &odom_base);
        assert!((m * odom_base)
            .to_homogeneous()
            .relative_eq(&map_base.to_homogeneous(), 1e-12, 1e-12));
    }

    #[test]
    fn odometry_is_interpolated_at_the_poses_stamp_and_missing_odometry_is_named() {
        let mut o = Odometry::default();
        assert_eq!(o.at(0, 0), Err(OdomMiss::None));
        o.push(2_000, iso([2.0, 0.0, 0.0], [0.0, 0.0, 1.0], 0.2));
        o.push(1_000, iso([1.0, 0.0, 0.0], [0.0, 0.0, 1.0], 0.0)); // out of order
        let mid = o.at(1_250, 0).unwrap();
        assert!((mid.translation.x - 1.25).abs() < 1e-12);
        assert!((mid.rotation.angle() - 0.05).abs() < 1e-12);
        assert_eq!(o.at(999, 0), Err(OdomMiss::Before));
        assert_eq!(o.at(2_100, 50), Err(OdomMiss::After));
        assert!((o.at(2_040, 50).unwrap().translation.x - 2.0).abs() < 1e-12);
        o.push(2_000 + ODOM_KEEP_NS + 1, Isometry3::identity());
        assert_eq!(
            o.at(1_500, 0),
            Err(OdomMiss::Before),
            "older than 10 s before the newest"
        );
    }

    #[test]
    fn a_transform_on_the_command_line_is_seven_numbers_with_a_unit_quaternion() {
        let t = parse_transform("0.3,0,1.2, 0 0 0 1").unwrap();
        assert_eq!(t.translation.vector, Vector3::new(0.3, 0.0, 1.2));
        assert_eq!(
            parse_transform("1 2 3").unwrap_err(),
            "7 numbers x,y,z,qx,qy,qz,qw are needed, found 3"
        );
        assert_eq!(parse_transform("1 2 3 0 0 0 x").unwrap_err(), "'x' is not a number");
        assert_eq!(
            parse_transform("0 0 0 0 0 0 2").unwrap_err(),
            "the quaternion (0, 0, 0, 2) has norm 2, not 1"
        );
        let m = to_msg_transform(&t);
        assert_eq!(from_msg_transform(&m), Some(t));
        assert_eq!(frame_name("/odom"), "odom");
    }
}
