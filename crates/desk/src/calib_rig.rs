//! Calibration in, the common part: the rig of cameras calibrated elsewhere (Kalibr, Basalt,
//! OpenCV, ROS), in the frame of one of them turned to the rig's axes.
//!
//! In: each camera's lens, image size and pose `T_x_cam` in the calibration's own common frame
//! x (Kalibr's cam0, Basalt's IMU), and which camera gives the rig frame. Out: a [`Rig`] checked
//! by the rig file's own rules, or the [`RigError`] they give.
//!
//! The rig frame is the reference camera's frame turned to x forward (its optical axis), y left,
//! z up (its image up), with the origin at its optical centre (REP-103 body axes).

use nalgebra::{Matrix3, Matrix4, Rotation3, Translation3, UnitQuaternion, Vector3};
use omnitrack_core::geometry::{Lens, Pose};
use omnitrack_core::rig::{Rig, RigError, Sensor};

/// One calibrated camera.
#[derive(Debug, Clone)]
pub struct Camera {
    pub lens: Lens,
    pub width: u32,
    pub height: u32,
    /// The camera's pose in the calibration's common frame.
    pub t_x_cam: Pose,
}

/// The rig of `cameras`, named `name`, whose frame is camera `reference`'s turned; `file` names
/// the calibration in errors.
pub fn assemble(name: &str, file: &str, cameras: Vec<Camera>, reference: usize) -> Result<Rig, RigError> {
    // Rig x = the camera's z, rig y = its −x, rig z = its −y.
    let turn = UnitQuaternion::from_basis_unchecked(&[-Vector3::y(), -Vector3::z(), Vector3::x()]);
    let t_rig_x = Pose::from_parts(Translation3::identity(), turn) * cameras[reference].t_x_cam.inverse();
    let sensors = cameras
        .into_iter()
        .enumerate()
        .map(|(id, c)| Sensor {
            id,
            width: c.width,
            height: c.height,
            lens: c.lens,
            t_rig_sensor: t_rig_x * c.t_x_cam,
            device: None,
            usb_serial: None,
            crop: None,
            control: Default::default(),
        })
        .collect();
    let rig = Rig {
        name: name.into(),
        sensors,
        usb: None,
        control: Default::default(),
    };
    // Through the rig file's own checks (and its rounding of the quaternion's print): what the
    // user gets is exactly what `Rig::load` will read.
    Rig::from_toml_str(&rig.to_toml_string(), file)
}

/// The pose of a 4×4 rigid transform, refusing one that is not (a rotation to 1e-6, last row
/// 0 0 0 1): a scaled or sheared "transform" is a calibration gone wrong.
pub fn rigid(m: &Matrix4<f64>) -> Result<Pose, String> {
    let r = m.fixed_view::<3, 3>(0, 0).into_owned();
    let orthonormal = (r.transpose() * r - Matrix3::identity()).norm() < 1e-6 && (r.determinant() - 1.0).abs() < 1e-6;
    let last = m.fixed_view::<1, 4>(3, 0);
    if !orthonormal
        || (last - nalgebra::RowVector4::new(0.0, 0.0, 0.0, 1.0)).norm() > 1e-9
        || !m.iter().all(|x| x.is_finite())
    {
        return Err("not a rigid transform (its 3×3 block must be a rotation, its last row 0 0 0 1)".into());
    }
    let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    Ok(Pose::from_parts(
        Translation3::from(m.fixed_view::<3, 1>(0, 3).into_owned()),
        rotation,
    ))
}

/// `W, H` read from a calibration: whole pixel counts 1 … 65535.
pub fn pixel_size(v: &[f64]) -> Result<(u32, u32), String> {
    if v.len() != 2 || v.iter().any(|&r| !(1.0..=65535.0).contains(&r) || r.fract() != 0.0) {
        return Err(format!("must be two pixel counts, found {v:?}"));
    }
    Ok((v[0] as u32, v[1] as u32))
}
