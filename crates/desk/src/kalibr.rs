//! Calibration in: a rig from Kalibr's camera chain (`camchain.yaml`, the output of
//! `kalibr_calibrate_cameras`).
//!
//! In: the YAML text, the file's name (for messages) and the camera whose frame becomes the rig's
//! (`cam0` unless asked otherwise). Out: a [`Rig`], checked by the rig file's own rules, or a
//! [`KalibrError`] naming the file, the camera and the key in one line.
//!
//! Kalibr writes, per camera `camN`: `camera_model` (`pinhole`, `omni`, `ds`, `eucm`),
//! `intrinsics` ([fu, fv, pu, pv] for pinhole), `distortion_model` (`radtan`, `equidistant`,
//! `fov`, `none`), `distortion_coeffs`, `resolution` [w, h], and from `cam1` on `T_cn_cnm1`, the
//! 4×4 transform taking points of camera n−1 into camera n. The chain is walked from the rig
//! camera both ways: T_ref_cn = T_ref_cn−1 · T_cn_cnm1⁻¹.
//!
//! Lenses, each exactly (parameter for parameter): `pinhole` + `equidistant` is OpenCV's fisheye
//! model, our `kb4`; `pinhole` + `radtan` is OpenCV's default model, our `radtan` (k1, k2, p1,
//! p2); `pinhole` + `none` is a pinhole; `omni` + `radtan` or `none` (intrinsics [ξ, fu, fv, pu,
//! pv]) is our `omni`; `ds` (intrinsics [ξ, α, fu, fv, pu, pv]) our `ds`; `eucm` ([α, β, fu,
//! fv, pu, pv]) our `eucm`. Other models (`fov`, `omni` + `equidistant`, …) are refused by name:
//! converting them would need a refit, and a refit is a calibration, not a conversion.
//!
//! The rig frame is the reference camera's frame turned to x forward (its optical axis), y left,
//! z up (its image up), with the origin at its optical centre.

use crate::calib_rig::{assemble, pixel_size, rigid, Camera};
use nalgebra::Matrix4;
use omnitrack_core::geometry::{DoubleSphere, Equirectangular, Eucm, Kb4, Lens, Omni, Pinhole, Pose, Radtan};
use omnitrack_core::rig::{Rig, RigError};
use yaml_rust2::{Yaml, YamlLoader};

/// Why a camera chain cannot become a rig.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum KalibrError {
    #[error("{file}: not YAML: {message}")]
    NotYaml { file: String, message: String },
    #[error("{file}: no cameras (expected keys cam0, cam1, …)")]
    NoCameras { file: String },
    #[error("{file}: --rig-frame {name}: no such camera (the chain has {cameras})")]
    NoRigCamera {
        file: String,
        name: String,
        cameras: String,
    },
    #[error("{file}: {camera}, key '{key}': {message}")]
    Key {
        file: String,
        camera: String,
        key: String,
        message: String,
    },
    #[error(
        "{file}: {camera}: camera model '{model}' with distortion '{distortion}' is not supported \
         (omnitrack reads pinhole with radtan, equidistant or none; omni with radtan or none; ds and \
         eucm with none)"
    )]
    Unsupported {
        file: String,
        camera: String,
        model: String,
        distortion: String,
    },
    #[error(transparent)]
    Rig(#[from] RigError),
}

/// The rig of a Kalibr camera chain, named `name`, in the frame of camera `rig_frame` turned to
/// x forward, y left, z up.
pub fn rig_from_kalibr(yaml: &str, file: &str, name: &str, rig_frame: &str) -> Result<Rig, KalibrError> {
    let docs = YamlLoader::load_from_str(yaml).map_err(|e| KalibrError::NotYaml {
        file: file.into(),
        message: e.to_string(),
    })?;
    let root = docs.first().cloned().unwrap_or(Yaml::Null);
    let mut cameras = Vec::new();
    while let Some(cam) = root[format!("cam{}", cameras.len()).as_str()].as_hash() {
        cameras.push(Yaml::Hash(cam.clone()));
    }
    if cameras.is_empty() {
        return Err(KalibrError::NoCameras { file: file.into() });
    }
    let names: Vec<String> = (0..cameras.len()).map(|i| format!("cam{i}")).collect();
    let reference = names
        .iter()
        .position(|n| n == rig_frame)
        .ok_or_else(|| KalibrError::NoRigCamera {
            file: file.into(),
            name: rig_frame.into(),
            cameras: names.join(", "),
        })?;
    let key_error = |camera: usize, key: &str, message: String| KalibrError::Key {
        file: file.into(),
        camera: names[camera].clone(),
        key: key.into(),
        message,
    };

    // T_c0_cn for every camera, from the links T_cn_cnm1.
    let mut t_c0: Vec<Pose> = vec![Pose::identity()];
    for (n, cam) in cameras.iter().enumerate().skip(1) {
        let link = matrix4(&cam["T_cn_cnm1"])
            .and_then(|m| rigid(&m))
            .map_err(|m| key_error(n, "T_cn_cnm1", m))?;
        t_c0.push(t_c0[n - 1] * link.inverse());
    }
    let mut placed = Vec::with_capacity(cameras.len());
    for (n, cam) in cameras.iter().enumerate() {
        let lens = lens_of(cam, n, file, &names)?;
        let (width, height) = numbers(&cam["resolution"], 2)
            .and_then(|r| pixel_size(&r))
            .map_err(|m| key_error(n, "resolution", m))?;
        placed.push(Camera {
            lens,
            width,
            height,
            t_x_cam: t_c0[n],
        });
    }
    Ok(assemble(name, file, placed, reference)?)
}

fn lens_of(cam: &Yaml, n: usize, file: &str, names: &[String]) -> Result<Lens, KalibrError> {
    let key_error = |key: &str, message: String| KalibrError::Key {
        file: file.into(),
        camera: names[n].clone(),
        key: key.into(),
        message,
    };
    let text = |key: &str| -> Result<String, KalibrError> {
        cam[key]
            .as_str()
            .map(str::to_string)
            .ok_or_else(|| key_error(key, "missing, or not a string".into()))
    };
    let model = text("camera_model")?;
    let distortion = match &cam["distortion_model"] {
        Yaml::BadValue | Yaml::Null => "none".to_string(),
        _ => text("distortion_model")?,
    };
    let unsupported = || KalibrError::Unsupported {
        file: file.into(),
        camera: names[n].clone(),
        // The file's own strings, escaped: a message stays one line whatever they hold.
        model: model.escape_debug().to_string(),
        distortion: distortion.escape_debug().to_string(),
    };
    // What each model's intrinsics are, in Kalibr's order, for the message of a wrong count.
    let names_of = match (model.as_str(), distortion.as_str()) {
        ("pinhole", "equidistant" | "radtan" | "none") | ("equirectangular", "none") => "fu, fv, pu, pv",
        ("omni", "radtan" | "none") => "xi, fu, fv, pu, pv",
        ("ds", "none") => "xi, alpha, fu, fv, pu, pv",
        ("eucm", "none") => "alpha, beta, fu, fv, pu, pv",
        _ => return Err(unsupported()),
    };
    let count = names_of.split(',').count();
    let i = numbers(&cam["intrinsics"], count)
        .map_err(|m| key_error("intrinsics", format!("{m} (camera model '{model}' has [{names_of}])")))?;
    let coeffs =
        |count: usize| numbers(&cam["distortion_coeffs"], count).map_err(|m| key_error("distortion_coeffs", m));
    let lens = match (model.as_str(), distortion.as_str()) {
        ("pinhole", "equidistant") => {
            let k = coeffs(4)?;
            Kb4::new(i[0], i[1], i[2], i[3], [k[0], k[1], k[2], k[3]]).map(Lens::Kb4)
        }
        ("pinhole", "radtan") => Radtan::new(i[0], i[1], i[2], i[3], &coeffs(4)?).map(Lens::Radtan),
        ("pinhole", "none") => Pinhole::new(i[0], i[1], i[2], i[3]).map(Lens::Pinhole),
        ("omni", "radtan" | "none") => {
            let d = if distortion == "radtan" {
                coeffs(4)?
            } else {
                vec![0.0; 4]
            };
            Omni::new(i[1], i[2], i[3], i[4], i[0], [d[0], d[1], d[2], d[3]]).map(Lens::Omni)
        }
        ("ds", "none") => DoubleSphere::new(i[2], i[3], i[4], i[5], i[0], i[1]).map(Lens::DoubleSphere),
        ("eucm", "none") => Eucm::new(i[2], i[3], i[4], i[5], i[0], i[1]).map(Lens::Eucm),
        // Not a Kalibr model, but what a 360° camera's stitched stream is.
        _ => Equirectangular::new(i[0], i[1], i[2], i[3]).map(Lens::Equirectangular),
    };
    lens.map_err(|e| key_error("intrinsics", e.to_string()))
}

/// `count` numbers from a YAML list (integers taken as numbers).
fn numbers(v: &Yaml, count: usize) -> Result<Vec<f64>, String> {
    let Some(list) = v.as_vec() else {
        return Err(format!("missing, or not a list of {count} numbers"));
    };
    if list.len() != count {
        return Err(format!("must have {count} numbers, found {}", list.len()));
    }
    list.iter()
        .map(|x| match x {
            Yaml::Real(_) => x
                .as_f64()
                .filter(|f| f.is_finite())
                .ok_or_else(|| "a number is not finite".to_string()),
            Yaml::Integer(i) => Ok(*i as f64),
            other => Err(format!("expected a number, found {other:?}")),
        })
        .collect()
}

/// A 4×4 matrix written as four rows of four numbers.
fn matrix4(v: &Yaml) -> Result<Matrix4<f64>, String> {
    let Some(rows) = v.as_vec() else {
        return Err("missing, or not a list of 4 rows".into());
    };
    if rows.len() != 4 {
        return Err(format!("must have 4 rows, found {}", rows.len()));
    }
    let mut m = Matrix4::zeros();
    for (r, row) in rows.iter().enumerate() {
        let row = numbers(row, 4).map_err(|e| format!("row {}: {e}", r + 1))?;
        for (c, x) in row.into_iter().enumerate() {
            m[(r, c)] = x;
        }
    }
    Ok(m)
}
