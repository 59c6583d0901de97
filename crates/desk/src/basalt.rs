//! Calibration in: a rig from Basalt's calibration file (`calibration.json`, the output of
//! `basalt_calibrate` and `basalt_calibrate_imu`, cereal's JSON).
//!
//! In: the JSON text, the file's name (for messages) and the camera whose frame becomes the
//! rig's (`cam0` unless asked otherwise). Out: a [`Rig`], checked by the rig file's own rules, or
//! a [`BasaltError`] naming the file, the camera and the key in one line.
//!
//! Basalt writes under `value0`: `intrinsics`, one `{camera_type, intrinsics: {…}}` per camera;
//! `resolution`, one [w, h] per camera; `T_imu_cam`, one pose per camera (`px`, `py`, `pz`,
//! `qx`, `qy`, `qz`, `qw`) taking camera coordinates to the IMU's; and IMU noise and biases,
//! which the tracker does not use. Camera types, each exactly: `ds` (fx, fy, cx, cy, xi, alpha)
//! is our `ds`; `eucm` (fx, fy, cx, cy, alpha, beta) our `eucm`; `ucm` (fx, fy, cx, cy, alpha)
//! our `eucm` with β = 1 (the same formula); `kb4` (fx, fy, cx, cy, k1, k2, k3, k4) our `kb4`;
//! `pinhole` (fx, fy, cx, cy) a pinhole. Others (`fov`, `pinhole-radtan8`, `bal`) are refused by
//! name. The rig frame is the named camera's turned to x forward, y left, z up (as for Kalibr):
//! the IMU's axes are the IMU maker's, not the rig's.

use crate::calib_rig::{assemble, pixel_size, Camera};
use nalgebra::{Quaternion, Translation3, UnitQuaternion};
use omnitrack_core::geometry::{DoubleSphere, Eucm, Kb4, Lens, Pinhole, Pose, UNIT_QUATERNION_TOLERANCE};
use omnitrack_core::rig::{Rig, RigError};
use serde_json::Value;

/// Why a Basalt calibration cannot become a rig.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BasaltError {
    #[error("{file}: not JSON: {message}")]
    NotJson { file: String, message: String },
    #[error("{file}: key '{key}': {message}")]
    Key { file: String, key: String, message: String },
    #[error(
        "{file}: cam{camera}: camera_type '{camera_type}' is not supported (omnitrack reads ds, eucm, \
         ucm, kb4 and pinhole)"
    )]
    Unsupported {
        file: String,
        camera: usize,
        camera_type: String,
    },
    #[error("{file}: --rig-frame {name}: no such camera (the calibration has {cameras})")]
    NoRigCamera {
        file: String,
        name: String,
        cameras: String,
    },
    #[error(transparent)]
    Rig(#[from] RigError),
}

/// The rig of a Basalt calibration, named `name`, in the frame of camera `rig_frame` (`camN`)
/// turned to x forward, y left, z up.
pub fn rig_from_basalt(json: &str, file: &str, name: &str, rig_frame: &str) -> Result<Rig, BasaltError> {
    let root: Value = serde_json::from_str(json).map_err(|e| BasaltError::NotJson {
        file: file.into(),
        message: e.to_string(),
    })?;
    let key_error = |key: String, message: String| BasaltError::Key {
        file: file.into(),
        key,
        message,
    };
    let top = root
        .get("value0")
        .filter(|v| v.is_object())
        .ok_or_else(|| key_error("value0".into(), "missing: not a Basalt calibration".into()))?;
    let list = |key: &str| -> Result<&Vec<Value>, BasaltError> {
        top.get(key)
            .and_then(Value::as_array)
            .filter(|a| !a.is_empty())
            .ok_or_else(|| {
                key_error(
                    format!("value0.{key}"),
                    "missing, or not a list of one entry per camera".into(),
                )
            })
    };
    let (intrinsics, resolution, poses) = (list("intrinsics")?, list("resolution")?, list("T_imu_cam")?);
    let count = intrinsics.len();
    for (key, l) in [("resolution", resolution), ("T_imu_cam", poses)] {
        if l.len() != count {
            return Err(key_error(
                format!("value0.{key}"),
                format!("{} entries for {count} cameras in value0.intrinsics", l.len()),
            ));
        }
    }
    let names: Vec<String> = (0..count).map(|i| format!("cam{i}")).collect();
    let reference = names
        .iter()
        .position(|n| n == rig_frame)
        .ok_or_else(|| BasaltError::NoRigCamera {
            file: file.into(),
            name: rig_frame.into(),
            cameras: names.join(", "),
        })?;
    let mut cameras = Vec::with_capacity(count);
    for n in 0..count {
        let lens = lens_of(&intrinsics[n], n, file)?;
        let size_key = format!("value0.resolution[{n}]");
        let size =
            numbers(&resolution[n]).ok_or_else(|| key_error(size_key.clone(), "not a list of numbers".into()))?;
        let (width, height) = pixel_size(&size).map_err(|m| key_error(size_key, m))?;
        let t_x_cam = pose(&poses[n]).map_err(|(k, m)| key_error(format!("value0.T_imu_cam[{n}]{k}"), m))?;
        cameras.push(Camera {
            lens,
            width,
            height,
            t_x_cam,
        });
    }
    Ok(assemble(name, file, cameras, reference)?)
}

/// The numbers of a JSON list (`None` if it holds anything else).
fn numbers(v: &Value) -> Option<Vec<f64>> {
    v.as_array()?.iter().map(Value::as_f64).collect()
}

/// The lens of one `value0.intrinsics[n]` entry.
fn lens_of(entry: &Value, n: usize, file: &str) -> Result<Lens, BasaltError> {
    let key_error = |key: &str, message: String| BasaltError::Key {
        file: file.into(),
        key: format!("value0.intrinsics[{n}].{key}"),
        message,
    };
    let camera_type = entry
        .get("camera_type")
        .and_then(Value::as_str)
        .ok_or_else(|| key_error("camera_type", "missing, or not a string".into()))?;
    let expected: &[&str] = match camera_type {
        "ds" => &["fx", "fy", "cx", "cy", "xi", "alpha"],
        "eucm" => &["fx", "fy", "cx", "cy", "alpha", "beta"],
        "ucm" => &["fx", "fy", "cx", "cy", "alpha"],
        "kb4" => &["fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4"],
        "pinhole" => &["fx", "fy", "cx", "cy"],
        other => {
            return Err(BasaltError::Unsupported {
                file: file.into(),
                camera: n,
                camera_type: other.escape_debug().to_string(),
            })
        }
    };
    let params = entry
        .get("intrinsics")
        .and_then(Value::as_object)
        .ok_or_else(|| key_error("intrinsics", "missing, or not an object".into()))?;
    if let Some(extra) = params.keys().find(|k| !expected.contains(&k.as_str())) {
        return Err(key_error(
            "intrinsics",
            format!(
                "unexpected '{}' for camera_type '{camera_type}' (it has {})",
                extra.escape_debug(),
                expected.join(", ")
            ),
        ));
    }
    let p = expected
        .iter()
        .map(|k| {
            params
                .get(*k)
                .and_then(Value::as_f64)
                .ok_or_else(|| key_error(&format!("intrinsics.{k}"), "missing, or not a number".into()))
        })
        .collect::<Result<Vec<f64>, _>>()?;
    match camera_type {
        "ds" => DoubleSphere::new(p[0], p[1], p[2], p[3], p[4], p[5]).map(Lens::DoubleSphere),
        "eucm" => Eucm::new(p[0], p[1], p[2], p[3], p[4], p[5]).map(Lens::Eucm),
        "ucm" => Eucm::new(p[0], p[1], p[2], p[3], p[4], 1.0).map(Lens::Eucm),
        "kb4" => Kb4::new(p[0], p[1], p[2], p[3], [p[4], p[5], p[6], p[7]]).map(Lens::Kb4),
        _ => Pinhole::new(p[0], p[1], p[2], p[3]).map(Lens::Pinhole),
    }
    .map_err(|e| key_error("intrinsics", e.to_string()))
}

/// `T_imu_cam` of one camera: `px`, `py`, `pz` and a unit `qx`, `qy`, `qz`, `qw`; on error the
/// key's suffix and the message.
fn pose(v: &Value) -> Result<Pose, (String, String)> {
    let get = |k: &str| {
        v.get(k)
            .and_then(Value::as_f64)
            .ok_or_else(|| (format!(".{k}"), "missing, or not a number".to_string()))
    };
    let t = [get("px")?, get("py")?, get("pz")?];
    let q = Quaternion::new(get("qw")?, get("qx")?, get("qy")?, get("qz")?);
    if (q.norm() - 1.0).abs() > UNIT_QUATERNION_TOLERANCE {
        return Err((String::new(), format!("quaternion is not unit (norm {:.9})", q.norm())));
    }
    Ok(Pose::from_parts(
        Translation3::new(t[0], t[1], t[2]),
        UnitQuaternion::from_quaternion(q),
    ))
}
