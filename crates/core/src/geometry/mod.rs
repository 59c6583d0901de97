//! The maths everything else stands on: poses, quaternions in our file order, lenses.
//!
//! In: numbers. Out: nalgebra types. This module imports nothing of capture, runtime, publishing
//! or I/O (the dependency rules of docs/design.md, "Layers"), so the solvers and tests can use it
//! anywhere.

pub mod angle;
pub mod lens;
pub mod observation;

pub use angle::arc_tangent;

pub use lens::{DoubleSphere, Equirectangular, Eucm, Kb4, Lens, LensError, Omni, Pinhole, Radtan};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
pub use observation::{xi, Correspondence, EdgePlane};

/// A rigid transform `T_a_b` taking coordinates in frame b to frame a: `p_a = R p_b + t`.
/// The tracker's output is `Pose` = `T_world_rig`; a sensor's mounting is `T_rig_sensor`.
pub type Pose = Isometry3<f64>;

/// How far from 1 a quaternion read from a file may be before it is an error rather than
/// rounding in the file's decimal digits.
pub const UNIT_QUATERNION_TOLERANCE: f64 = 1e-6;

/// Numbers read from a file (rig, trajectory, pose message, command line) that are not a pose.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PoseError {
    #[error("quaternion {0:?} has a non-finite component")]
    NonFiniteRotation([f64; 4]),
    #[error("quaternion {q:?} is not unit (norm {norm:.9})")]
    NotUnit { q: [f64; 4], norm: f64 },
    #[error("translation {0:?} has a non-finite component")]
    NonFiniteTranslation([f64; 3]),
}

/// Builds a rotation from `[w, x, y, z]`, refusing non-finite values and a norm further than
/// [`UNIT_QUATERNION_TOLERANCE`] from 1 (then renormalising the rest away).
pub fn rotation_from_wxyz(q: [f64; 4]) -> Result<UnitQuaternion<f64>, PoseError> {
    if q.iter().any(|c| !c.is_finite()) {
        return Err(PoseError::NonFiniteRotation(q));
    }
    let quat = Quaternion::new(q[0], q[1], q[2], q[3]);
    let norm = quat.norm();
    if (norm - 1.0).abs() > UNIT_QUATERNION_TOLERANCE {
        return Err(PoseError::NotUnit { q, norm });
    }
    Ok(UnitQuaternion::from_quaternion(quat))
}

/// `[w, x, y, z]` of a rotation, with w ≥ 0 so that each rotation has one spelling.
pub fn rotation_to_wxyz(r: &UnitQuaternion<f64>) -> [f64; 4] {
    let q = r.quaternion();
    let s = if q.w < 0.0 { -1.0 } else { 1.0 };
    [s * q.w, s * q.i, s * q.j, s * q.k]
}

/// A pose from a translation and a `[w, x, y, z]` rotation.
pub fn pose_from_parts(t: [f64; 3], q_wxyz: [f64; 4]) -> Result<Pose, PoseError> {
    if t.iter().any(|c| !c.is_finite()) {
        return Err(PoseError::NonFiniteTranslation(t));
    }
    Ok(Isometry3::from_parts(
        Translation3::from(Vector3::from(t)),
        rotation_from_wxyz(q_wxyz)?,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quaternion_round_trip_and_validation() {
        let r = UnitQuaternion::from_euler_angles(0.1, -0.7, 2.9);
        let back = rotation_from_wxyz(rotation_to_wxyz(&r)).unwrap();
        assert!(back.angle_to(&r) < 1e-14);
        assert!(rotation_to_wxyz(&r)[0] >= 0.0);
        let not_unit = rotation_from_wxyz([1.0, 0.0, 0.0, 0.1]).unwrap_err();
        assert!(matches!(not_unit, PoseError::NotUnit { .. }));
        assert!(not_unit.to_string().contains("not unit"));
        let nan = rotation_from_wxyz([f64::NAN, 0.0, 0.0, 0.0]).unwrap_err();
        assert!(matches!(nan, PoseError::NonFiniteRotation(_)));
        assert!(nan.to_string().contains("non-finite"));
        assert!(matches!(
            pose_from_parts([f64::INFINITY, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]),
            Err(PoseError::NonFiniteTranslation(_))
        ));
        let p = pose_from_parts([1.0, 2.0, 3.0], [0.0, 0.0, 0.0, 1.0]).unwrap();
        let x = p * nalgebra::Point3::new(1.0, 0.0, 0.0);
        assert!((x - nalgebra::Point3::new(0.0, 2.0, 3.0)).norm() < 1e-15);
    }
}
