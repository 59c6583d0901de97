//! Calibration in: a one-sensor rig from an OpenCV calibration file (`cv::FileStorage` YAML).
//!
//! In: the YAML text as `cv::FileStorage` writes it (`%YAML` header, `!!opencv-matrix` nodes with
//! `rows`, `cols`, `dt`, `data`), the file's name for messages, the lens model the coefficients
//! belong to, and the image size when the file does not give it. Out: a [`Rig`] of one sensor
//! whose frame, turned to x forward, y left, z up, is the rig's; or an [`OpenCvError`] naming
//! the file and the key in one line.
//!
//! Keys: the camera matrix as `K` or `camera_matrix` (3×3, zero skew), the distortion as `D` or
//! `distortion_coefficients`, the size as `image_width` and `image_height` (OpenCV's calibration
//! sample writes these). `cv::fisheye::calibrate`'s four coefficients are our `kb4`; the default
//! model's four or five (k1, k2, p1, p2[, k3]) are `radtan`. Four numbers fit both models, so the
//! caller says which; the rational and thin-prism models (8, 12 or 14 numbers) are refused.

use nalgebra::{Translation3, UnitQuaternion, Vector3};
use omnitrack_core::geometry::{Kb4, Lens, Pose, Radtan};
use omnitrack_core::rig::{Rig, RigError, Sensor};
use yaml_rust2::{Yaml, YamlLoader};

/// Which of OpenCV's models the coefficients are.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OpenCvModel {
    /// `cv::fisheye`: four coefficients, our `kb4`.
    Fisheye,
    /// The default model (`cv::calibrateCamera`): four or five, our `radtan`.
    Default,
}

/// Why an OpenCV calibration file cannot become a rig.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OpenCvError {
    #[error("{file}: not YAML: {message}")]
    NotYaml { file: String, message: String },
    #[error("{file}, key '{key}': {message}")]
    Key { file: String, key: String, message: String },
    #[error("{file}: no image size: the file has no image_width and image_height, give --resolution W,H")]
    NoSize { file: String },
    #[error(transparent)]
    Rig(#[from] RigError),
}

/// The rig (named `name`) of one camera calibrated by OpenCV.
pub fn rig_from_opencv(
    yaml: &str,
    file: &str,
    name: &str,
    model: OpenCvModel,
    size: Option<(u32, u32)>,
) -> Result<Rig, OpenCvError> {
    // OpenCV writes a `%YAML:1.0` directive (before 4.x) that YAML parsers refuse, or `%YAML 1.2`.
    let body = match yaml.trim_start().strip_prefix("%YAML") {
        Some(rest) => rest.split_once('\n').map_or("", |(_, b)| b),
        None => yaml,
    };
    let docs = YamlLoader::load_from_str(body).map_err(|e| OpenCvError::NotYaml {
        file: file.into(),
        message: e.to_string(),
    })?;
    let root = docs.first().cloned().unwrap_or(Yaml::Null);
    let key_error = |key: &str, message: String| OpenCvError::Key {
        file: file.into(),
        key: key.into(),
        message,
    };
    let (k_key, k) = matrix(&root, &["K", "camera_matrix"]).map_err(|(key, m)| key_error(&key, m))?;
    if k.len() != 9 {
        return Err(key_error(&k_key, format!("must be 3×3, has {} numbers", k.len())));
    }
    if k[1] != 0.0 || k[3] != 0.0 || k[6] != 0.0 || k[7] != 0.0 || k[8] != 1.0 {
        return Err(key_error(&k_key, "must be [fx 0 cx; 0 fy cy; 0 0 1] (no skew)".into()));
    }
    let (d_key, d) = matrix(&root, &["D", "distortion_coefficients"]).map_err(|(key, m)| key_error(&key, m))?;
    let (fx, fy, cx, cy) = (k[0], k[4], k[2], k[5]);
    let lens = match (model, d.len()) {
        (OpenCvModel::Fisheye, 4) => Kb4::new(fx, fy, cx, cy, [d[0], d[1], d[2], d[3]]).map(Lens::Kb4),
        (OpenCvModel::Default, 4 | 5) => Radtan::new(fx, fy, cx, cy, &d).map(Lens::Radtan),
        (OpenCvModel::Fisheye, n) => {
            return Err(key_error(
                &d_key,
                format!("a fisheye lens has 4 coefficients, found {n}"),
            ));
        }
        (OpenCvModel::Default, n) => {
            return Err(key_error(
                &d_key,
                format!(
                    "{n} coefficients: only k1, k2, p1, p2[, k3] are read (the rational and thin-prism terms are not)"
                ),
            ));
        }
    }
    .map_err(|e| key_error(&d_key, e.to_string()))?;
    let (width, height) = match size {
        Some(s) => s,
        None => {
            let dim = |key: &str| {
                root[key]
                    .as_i64()
                    .filter(|&v| (1..=65535).contains(&v))
                    .map(|v| v as u32)
            };
            match (dim("image_width"), dim("image_height")) {
                (Some(w), Some(h)) => (w, h),
                _ => return Err(OpenCvError::NoSize { file: file.into() }),
            }
        }
    };
    // The camera's frame turned: rig x = its z, rig y = its −x, rig z = its −y.
    let turn = UnitQuaternion::from_basis_unchecked(&[-Vector3::y(), -Vector3::z(), Vector3::x()]);
    let rig = Rig {
        name: name.into(),
        sensors: vec![Sensor {
            id: 0,
            width,
            height,
            lens,
            t_rig_sensor: Pose::from_parts(Translation3::identity(), turn),
            device: None,
            usb_serial: None,
            crop: None,
        }],
        usb: None,
    };
    Ok(Rig::from_toml_str(&rig.to_toml_string(), file)?)
}

/// The numbers of the first of `keys` present, an `!!opencv-matrix` (its `data`, checked against
/// `rows` × `cols`) or a plain list; the key found with them.
fn matrix(root: &Yaml, keys: &[&str]) -> Result<(String, Vec<f64>), (String, String)> {
    let Some((key, node)) = keys.iter().find_map(|k| {
        let n = &root[*k];
        (!matches!(n, Yaml::BadValue | Yaml::Null)).then_some((k.to_string(), n))
    }) else {
        return Err((keys.join("' or '"), "missing".into()));
    };
    let fail = |m: String| (key.clone(), m);
    let (list, expected) = match node {
        Yaml::Hash(_) => {
            let dim = |k: &str| node[k].as_i64().filter(|&v| v > 0);
            let expected = match (dim("rows"), dim("cols")) {
                (Some(r), Some(c)) => Some((r * c) as usize),
                _ => return Err(fail("an opencv-matrix needs rows and cols".into())),
            };
            (&node["data"], expected)
        }
        other => (other, None),
    };
    let Some(items) = list.as_vec() else {
        return Err(fail("expected a matrix or a list of numbers".into()));
    };
    let numbers = items
        .iter()
        .map(|x| match x {
            Yaml::Integer(i) => Some(*i as f64),
            _ => x.as_f64().filter(|f| f.is_finite()),
        })
        .collect::<Option<Vec<f64>>>()
        .ok_or_else(|| fail("a value is not a finite number".into()))?;
    if let Some(n) = expected.filter(|&n| n != numbers.len()) {
        return Err(fail(format!(
            "rows × cols = {n} but data has {} numbers",
            numbers.len()
        )));
    }
    Ok((key, numbers))
}
