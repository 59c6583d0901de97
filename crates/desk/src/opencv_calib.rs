//! Calibration in: a one-sensor rig from an OpenCV calibration file (`cv::FileStorage` YAML) or
//! a ROS `camera_info` YAML (`camera_calibration_parsers`, what `camera_calibration` saves).
//!
//! In: the YAML text as `cv::FileStorage` writes it (`%YAML` header, `!!opencv-matrix` nodes with
//! `rows`, `cols`, `dt`, `data`) or as ROS writes it (the same keys, plain `rows`/`cols`/`data`
//! maps, and `distortion_model`), the file's name for messages, the lens model if the caller
//! overrides the file, and the image size when the file does not give it. Out: a [`Rig`] of one
//! sensor whose frame, turned to x forward, y left, z up, is the rig's, with how its lens model
//! was chosen; or an [`OpenCvError`] naming the file and the key in one line.
//!
//! Keys: the camera matrix as `K` or `camera_matrix` (3×3, zero skew), the distortion as `D` or
//! `distortion_coefficients`, the size as `image_width` and `image_height`. The lens model is
//! what the file says: ROS's `distortion_model` (`plumb_bob` and `rational_polynomial` are
//! OpenCV's default model, `equidistant` its fisheye), else the `fisheye_model` flag OpenCV's
//! calibration tutorial writes, else the number of coefficients: 4 are `cv::fisheye`'s (the
//! default model always writes 5 or more), 5 or 8 the default model's. `cv::fisheye`'s four
//! coefficients are our `kb4`; the default model's k1, k2, p1, p2[, k3] are `radtan`, and its 8
//! (the rational model) are read when k4, k5, k6 are 0 (then it is the same lens); the
//! thin-prism and tilted models (12, 14 numbers) are refused.

use crate::calib_rig::{assemble, Camera};
use omnitrack_core::geometry::{Kb4, Lens, Pose, Radtan};
use omnitrack_core::rig::{Rig, RigError};
use yaml_rust2::{Yaml, YamlLoader};

/// Which of OpenCV's models the coefficients are (to override what the file says).
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

/// The rig (named `name`) of one camera calibrated by OpenCV or ROS, and how its lens model was
/// chosen (`model` overrides the file).
pub fn rig_from_opencv(
    yaml: &str,
    file: &str,
    name: &str,
    model: Option<OpenCvModel>,
    size: Option<(u32, u32)>,
) -> Result<(Rig, String), OpenCvError> {
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
    let (model, why) = match model {
        Some(m) => (m, "as --model says".to_string()),
        None => model_of(&root, d.len()).map_err(|(key, m)| key_error(&key, m))?,
    };
    let lens = match (model, d.len()) {
        (OpenCvModel::Fisheye, 4) => Kb4::new(fx, fy, cx, cy, [d[0], d[1], d[2], d[3]]).map(Lens::Kb4),
        (OpenCvModel::Default, 4 | 5) => Radtan::new(fx, fy, cx, cy, &d).map(Lens::Radtan),
        // The rational model without its denominator is the five-coefficient one.
        (OpenCvModel::Default, 8) if d[5..].iter().all(|&c| c == 0.0) => {
            Radtan::new(fx, fy, cx, cy, &d[..5]).map(Lens::Radtan)
        }
        (OpenCvModel::Default, 8) => {
            return Err(key_error(
                &d_key,
                format!(
                    "8 coefficients with k4, k5, k6 = {:?}: OpenCV's rational model is not read (recalibrate \
                     with the default 5 coefficients, or cv::fisheye)",
                    &d[5..]
                ),
            ));
        }
        (OpenCvModel::Fisheye, n) => {
            return Err(key_error(
                &d_key,
                format!("a fisheye lens (cv::fisheye, {why}) has 4 coefficients, found {n}"),
            ));
        }
        (OpenCvModel::Default, n) => {
            return Err(key_error(
                &d_key,
                format!("{n} coefficients: only k1, k2, p1, p2[, k3] are read (the thin-prism and tilt terms are not)"),
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
    let camera = Camera {
        lens,
        width,
        height,
        t_x_cam: Pose::identity(),
    };
    Ok((assemble(name, file, vec![camera], 0)?, why))
}

/// The model the file says its coefficients are, and where it says so: ROS's
/// `distortion_model`, OpenCV's tutorial's `fisheye_model`, or the count of coefficients.
fn model_of(root: &Yaml, count: usize) -> Result<(OpenCvModel, String), (String, String)> {
    match &root["distortion_model"] {
        Yaml::BadValue | Yaml::Null => {}
        Yaml::String(s) => {
            let model = match s.as_str() {
                "plumb_bob" | "rational_polynomial" => OpenCvModel::Default,
                "equidistant" | "fisheye" => OpenCvModel::Fisheye,
                other => {
                    return Err((
                        "distortion_model".into(),
                        format!(
                            "'{}' is not read (plumb_bob, rational_polynomial or equidistant)",
                            other.escape_debug()
                        ),
                    ))
                }
            };
            return Ok((model, format!("distortion_model: {s}")));
        }
        _ => return Err(("distortion_model".into(), "must be a string such as plumb_bob".into())),
    }
    match &root["fisheye_model"] {
        Yaml::BadValue | Yaml::Null => {}
        Yaml::Integer(i) if *i == 0 || *i == 1 => {
            let model = if *i == 1 {
                OpenCvModel::Fisheye
            } else {
                OpenCvModel::Default
            };
            return Ok((model, format!("fisheye_model: {i}")));
        }
        Yaml::Boolean(b) => {
            let model = if *b { OpenCvModel::Fisheye } else { OpenCvModel::Default };
            return Ok((model, format!("fisheye_model: {b}")));
        }
        _ => return Err(("fisheye_model".into(), "must be 0 or 1".into())),
    }
    Ok(match count {
        4 => (
            OpenCvModel::Fisheye,
            "4 coefficients: cv::fisheye's (--model default reads them as k1, k2, p1, p2)".into(),
        ),
        n => (OpenCvModel::Default, format!("{n} coefficients: the default model's")),
    })
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
