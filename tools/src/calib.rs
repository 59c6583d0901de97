//! `omnitrack-desk rig from-*`: rig files from other tools' calibrations (Kalibr, Basalt, OpenCV
//! and ROS), written to a file or, with `--out -`, to standard output.
//!
//! In: the parsed subcommand. Out: the rig TOML with a header saying where it came from, and a
//! one-line summary on stderr (the sensors, their lens models, and for OpenCV how the model was
//! chosen); errors as one line.

use crate::{print_out, Failure};
use clap::Subcommand;
use omnitrack::Rig;
use std::path::{Path, PathBuf};

// The variants are the subcommands' names: `rig from-kalibr`, `rig from-basalt`, `rig from-opencv`.
#[allow(clippy::enum_variant_names)]
#[derive(Subcommand)]
pub(crate) enum RigCommand {
    /// A rig file from a Kalibr camera chain (camchain.yaml): `pinhole` cameras with
    /// `equidistant` (→ kb4), `radtan` (→ radtan) or no distortion; `omni` with `radtan` or none
    /// (→ omni); `ds` (→ ds); `eucm` (→ eucm); other models are refused by name. The rig frame is
    /// the named camera's frame turned to x forward, y left, z up.
    FromKalibr {
        /// Kalibr's camera chain (the camchain.yaml of kalibr_calibrate_cameras).
        camchain: PathBuf,
        /// Where to write the rig (`-`: standard output).
        #[arg(long, value_name = "RIG.toml")]
        out: PathBuf,
        /// The camera whose frame, turned, is the rig's.
        #[arg(long, value_name = "camN", default_value = "cam0")]
        rig_frame: String,
        /// The rig's name (default: the output file's stem).
        #[arg(long)]
        name: Option<String>,
    },
    /// A rig file from a Basalt calibration (calibration.json): camera types `ds`, `eucm`, `ucm`,
    /// `kb4` and `pinhole`, placed by `T_imu_cam`; others are refused by name. The rig frame is
    /// the named camera's frame turned to x forward, y left, z up.
    FromBasalt {
        /// Basalt's calibration (value0 with intrinsics, resolution, T_imu_cam).
        calibration: PathBuf,
        /// Where to write the rig (`-`: standard output).
        #[arg(long, value_name = "RIG.toml")]
        out: PathBuf,
        /// The camera whose frame, turned, is the rig's.
        #[arg(long, value_name = "camN", default_value = "cam0")]
        rig_frame: String,
        /// The rig's name (default: the output file's stem).
        #[arg(long)]
        name: Option<String>,
    },
    /// A one-sensor rig from an OpenCV calibration file (cv::FileStorage YAML: K or
    /// camera_matrix, D or distortion_coefficients, image_width and image_height) or a ROS
    /// camera_info YAML. The lens model is what the file says (ROS's distortion_model, OpenCV's
    /// fisheye_model, else 4 coefficients are cv::fisheye's and 5 or 8 the default model's).
    /// The rig frame is the camera's turned to x forward, y left, z up.
    FromOpencv {
        /// The calibration file.
        file: PathBuf,
        /// Where to write the rig (`-`: standard output).
        #[arg(long, value_name = "RIG.toml")]
        out: PathBuf,
        /// Override the lens model the file says.
        #[arg(long, value_enum)]
        model: Option<OpenCvLens>,
        /// The image size, when the file does not give it.
        #[arg(long, value_name = "W,H", value_parser = parse_size)]
        resolution: Option<(u32, u32)>,
        /// The rig's name (default: the output file's stem).
        #[arg(long)]
        name: Option<String>,
    },
}

/// `--model` of `rig from-opencv`.
#[derive(Clone, Copy, clap::ValueEnum)]
pub(crate) enum OpenCvLens {
    /// cv::fisheye (4 coefficients): kb4.
    Fisheye,
    /// The default model, k1, k2, p1, p2[, k3]: radtan.
    Default,
}

/// `W,H`, two whole pixel counts.
fn parse_size(text: &str) -> Result<(u32, u32), String> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    match parts[..] {
        [w, h] => match (w.parse::<u32>(), h.parse::<u32>()) {
            (Ok(w), Ok(h)) if w > 0 && h > 0 => Ok((w, h)),
            _ => Err(format!("{text:?}: expected W,H (two positive whole numbers)")),
        },
        _ => Err(format!("{text:?}: expected W,H")),
    }
}

/// Whether `--out` is standard output.
fn is_stdout(out: &Path) -> bool {
    out.as_os_str() == "-"
}

/// Writes the rig to `out` (standard output for `-`), with a header saying where it came from,
/// and says on stderr what was written.
fn write_rig(out: &Path, rig: &Rig, header: &str, note: &str) -> Result<(), Failure> {
    let text = format!("{header}{}", rig.to_toml_string());
    let shown = if is_stdout(out) {
        print_out(&text)?;
        "standard output".to_string()
    } else {
        std::fs::write(out, text).map_err(|e| format!("{}: cannot write: {e}", out.display()))?;
        out.display().to_string()
    };
    let lenses: Vec<&str> = rig.sensors.iter().map(|s| s.lens.model_name()).collect();
    eprintln!(
        "{shown}: rig '{}', {} sensors ({}){note}",
        rig.name,
        rig.sensors.len(),
        lenses.join(", ")
    );
    Ok(())
}

/// The rig's name: given, or the output file's stem (`rig` for standard output).
fn rig_name(name: Option<String>, out: &Path) -> String {
    name.unwrap_or_else(|| match out.file_stem() {
        Some(s) if !is_stdout(out) => s.to_string_lossy().into_owned(),
        _ => "rig".into(),
    })
}

/// A calibration file's text and its name for messages.
fn read(path: &Path) -> Result<(String, String), String> {
    let shown = path.display().to_string();
    let text = omnitrack::text_file::read_text(path, omnitrack::text_file::SMALL_FILE_LIMIT)
        .map_err(|e| format!("{shown}: cannot read: {e}"))?;
    Ok((text, shown))
}

/// Runs one `rig` subcommand.
pub(crate) fn run(command: RigCommand) -> Result<(), Failure> {
    let frame_header = |tool: &str, file: &str, frame: &str| {
        format!(
            "# Converted by `omnitrack-desk rig {tool}` from {file}; rig frame: {frame} turned to\n\
             # x forward, y left, z up, origin at its optical centre.\n"
        )
    };
    match command {
        RigCommand::FromKalibr {
            camchain,
            out,
            rig_frame,
            name,
        } => {
            let (yaml, file) = read(&camchain)?;
            let rig = omnitrack::desk::kalibr::rig_from_kalibr(&yaml, &file, &rig_name(name, &out), &rig_frame)
                .map_err(|e| e.to_string());
            write_rig(&out, &rig?, &frame_header("from-kalibr", &file, &rig_frame), "")
        }
        RigCommand::FromBasalt {
            calibration,
            out,
            rig_frame,
            name,
        } => {
            let (json, file) = read(&calibration)?;
            let rig = omnitrack::desk::basalt::rig_from_basalt(&json, &file, &rig_name(name, &out), &rig_frame)
                .map_err(|e| e.to_string());
            write_rig(&out, &rig?, &frame_header("from-basalt", &file, &rig_frame), "")
        }
        RigCommand::FromOpencv {
            file,
            out,
            model,
            resolution,
            name,
        } => {
            use omnitrack::desk::opencv_calib::{rig_from_opencv, OpenCvModel};
            let (yaml, shown) = read(&file)?;
            let model = model.map(|m| match m {
                OpenCvLens::Fisheye => OpenCvModel::Fisheye,
                OpenCvLens::Default => OpenCvModel::Default,
            });
            let (rig, why) =
                rig_from_opencv(&yaml, &shown, &rig_name(name, &out), model, resolution).map_err(|e| e.to_string())?;
            write_rig(
                &out,
                &rig,
                &frame_header("from-opencv", &shown, "the camera's"),
                &format!("; lens model from {why}"),
            )
        }
    }
}
