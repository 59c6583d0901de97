//! The rotation of three plane pairs: Wahba's problem (1965) by the SVD, and its upright
//! special case, the yaw alone in closed form (Koch–Teller §5.4's known vertical).
//!
//! In: three unit vectors u_k in the rig frame (edge plane normals), their partners v_k in the
//! world frame (the normals of the planes through the matched segments, seen from a cell
//! centre), and a common sign (a plane's normal is known up to its sign). Out: the rotation R
//! (rig → world, that of `T_world_rig`) with R (sign·u_k) ≈ v_k and the summed squared residual,
//! by which the caller picks the sign.
//!
//! The initialiser's pose of a sample (Koch–Teller §4.1, INIT-SEGMENT-EDGE's last step) starts
//! here; the translation follows from [`super::translation`].

use nalgebra::{Matrix3, UnitQuaternion, Vector3};

/// Wahba's problem for R (rig → world) with R (sign·u_k) ≈ v_k: the rotation and its residual.
pub fn wahba(u: &[Vector3<f64>; 3], v: &[Vector3<f64>; 3], sign: f64) -> Option<(UnitQuaternion<f64>, f64)> {
    let mut b = Matrix3::zeros();
    for k in 0..3 {
        b += v[k] * (u[k] * sign).transpose();
    }
    let svd = b.svd(true, true);
    let (uu, vt) = (svd.u?, svd.v_t?);
    let d = (uu * vt).determinant().signum();
    let r = uu * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * vt;
    let q = UnitQuaternion::from_matrix(&r);
    let residual = (0..3).map(|k| (q * (u[k] * sign) - v[k]).norm_squared()).sum();
    Some((q, residual))
}

/// The yaw ψ with Rz(ψ) (sign·u_k) ≈ v_k in the ground plane (closed form), and its residual.
pub fn yaw_fit(u: &[Vector3<f64>; 3], v: &[Vector3<f64>; 3], sign: f64) -> (UnitQuaternion<f64>, f64) {
    let (mut s, mut c) = (0.0, 0.0);
    for k in 0..3 {
        let a = u[k] * sign;
        s += a.x * v[k].y - a.y * v[k].x;
        c += a.x * v[k].x + a.y * v[k].y;
    }
    let q = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), s.atan2(c));
    let residual = (0..3).map(|k| (q * (u[k] * sign) - v[k]).norm_squared()).sum();
    (q, residual)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wahba_recovers_a_rotation_from_three_normals() {
        let truth = UnitQuaternion::from_euler_angles(0.1, -0.2, 2.0);
        let u = [
            Vector3::new(1.0, 0.2, 0.0).normalize(),
            Vector3::new(0.0, 1.0, 0.3).normalize(),
            Vector3::new(0.3, 0.0, 1.0).normalize(),
        ];
        let v = u.map(|x| truth * x);
        let (q, res) = wahba(&u, &v, 1.0).unwrap();
        assert!(q.angle_to(&truth) < 1e-9 && res < 1e-18);
        let up = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), -1.3);
        let (q, _) = yaw_fit(&u, &u.map(|x| up * x), 1.0);
        assert!(q.angle_to(&up) < 1e-12);
    }
}
