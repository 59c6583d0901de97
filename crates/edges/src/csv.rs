//! The `omnitrack edges` CSV (docs/interfaces.md): edges as text, and the command's whole job
//! for one image file.
//!
//! In: [`Edge`]s and the rig (for [`edges_csv`]); or a rig, the [`EdgeConfig`], a sensor and an
//! image path (for [`edges_csv_for_image`], which runs a one-thread [`EdgeDetector`]). Out: the
//! CSV, header line first ([`EDGES_CSV_HEADER`]), or an [`EdgesCsvError`] of one line naming
//! the file.

use crate::detector::EdgeDetector;
use crate::edge::Edge;
use crate::params::EdgeParams;
use omnitrack_config::EdgeConfig;
use omnitrack_core::frame::SensorImage;
use omnitrack_core::rig::Rig;
use std::fmt::Write as _;

/// Header of the `omnitrack edges` CSV (docs/interfaces.md), then our extra columns. `pieces` is
/// empty for an edge the image shows whole (one piece, passing the a-contrario test untrimmed,
/// [`Edge::shown`]); `none` where the image shows no piece of it as a line; otherwise the pixel
/// ends of the pieces it does show, from end 1 to end 2, as `u1 v1 u2 v2` groups separated by
/// `;` (the edge's own ends are those of the whole span its plane was fitted over, across its
/// [`Edge::gaps`]).
pub const EDGES_CSV_HEADER: &str = "u1,v1,u2,v2,hue_left_mean,hue_left_var,hue_right_mean,hue_right_var,\
sensor,length_deg,strength,nx,ny,nz,hue_left_kept,hue_right_kept,pieces";

/// The `omnitrack edges` CSV of some edges (header line included). Hue means are in [0, 1) or
/// `NaN` for a strip without any pixel of meaningful hue; the normal is in the rig frame.
pub fn edges_csv(edges: &[Edge], rig: &Rig) -> String {
    let mut s = String::with_capacity(64 + edges.len() * 160);
    s.push_str(EDGES_CSV_HEADER);
    s.push('\n');
    for e in edges {
        let n = e.plane.normal;
        let h = &e.hue;
        let _ = write!(
            s,
            "{:.3},{:.3},{:.3},{:.3},{:.5},{:.6},{:.5},{:.6},{},{:.4},{:.1},{:.7},{:.7},{:.7},{:.3},{:.3},",
            e.px[0].x,
            e.px[0].y,
            e.px[1].x,
            e.px[1].y,
            h.left_mean,
            h.left_var,
            h.right_mean,
            h.right_var,
            e.sensor,
            e.length_rad.to_degrees(),
            e.strength,
            n.x,
            n.y,
            n.z,
            h.left_kept,
            h.right_kept
        );
        // The pieces shown, projected from their end rays; the outer ends are the edge's own.
        let whole = e.n_gaps == 0 && e.shown() == [[0.0, e.length_rad as f32]];
        if e.shown().is_empty() {
            s.push_str("none");
        } else if !whole {
            let sensor = rig.sensors.get(usize::from(e.sensor));
            let px = |t: f32, end: usize| -> Option<[f64; 2]> {
                if (end == 0 && t == 0.0) || (end == 1 && t == e.length_rad as f32) {
                    return Some([e.px[end].x, e.px[end].y]);
                }
                let s = sensor?;
                let ray = s.t_rig_sensor.rotation.inverse() * e.ray_at(f64::from(t));
                s.lens.project(&ray).map(|p| [p.x, p.y])
            };
            let mut first = true;
            for &[from, to] in e.shown() {
                if let (Some(a), Some(b)) = (px(from, 0), px(to, 1)) {
                    let sep = if first { "" } else { ";" };
                    first = false;
                    let _ = write!(s, "{sep}{:.3} {:.3} {:.3} {:.3}", a[0], a[1], b[0], b[1]);
                }
            }
        }
        s.push('\n');
    }
    s
}

/// Why `omnitrack edges` cannot read its image.
#[derive(Debug, thiserror::Error)]
pub enum EdgesCsvError {
    #[error("--sensor {sensor}: rig {rig:?} has sensors 0..{last}")]
    NoSuchSensor { sensor: usize, rig: String, last: usize },
    #[error("{}: cannot read image: {source}", .path.display())]
    Unreadable {
        path: std::path::PathBuf,
        source: image::ImageError,
    },
    #[error("{}: image is {width}x{height}, sensor {sensor} of rig {rig:?} is {sensor_width}x{sensor_height}", .path.display())]
    WrongSize {
        path: std::path::PathBuf,
        width: u32,
        height: u32,
        sensor: usize,
        rig: String,
        sensor_width: u32,
        sensor_height: u32,
    },
}

/// `omnitrack edges --rig R --sensor K IMAGE`: loads the image, checks it against the rig's
/// sensor and returns the CSV; errors are one line naming the file.
pub fn edges_csv_for_image(
    rig: &Rig,
    config: &EdgeConfig,
    sensor: usize,
    path: &std::path::Path,
) -> Result<String, EdgesCsvError> {
    let Some(s) = rig.sensors.get(sensor) else {
        return Err(EdgesCsvError::NoSuchSensor {
            sensor,
            rig: rig.name.clone(),
            last: rig.sensors.len().saturating_sub(1),
        });
    };
    let unreadable = |source| EdgesCsvError::Unreadable {
        path: path.to_path_buf(),
        source,
    };
    // Only a regular file no larger than any image of the sensor's size can be (4 bytes a pixel
    // and 1 MiB): a FIFO would block the read for ever, and /dev/zero never ends.
    let most = 4 * u64::from(s.width) * u64::from(s.height) + (1 << 20);
    omnitrack_core::text_file::regular_file_len(path, most).map_err(|e| unreadable(image::ImageError::IoError(e)))?;
    let reader = || {
        image::ImageReader::open(path)
            .map_err(|e| unreadable(image::ImageError::IoError(e)))?
            .with_guessed_format()
            .map_err(|e| unreadable(image::ImageError::IoError(e)))
    };
    // The size from the header, before decoding: a huge image is refused, not decoded.
    let (width, height) = reader()?.into_dimensions().map_err(unreadable)?;
    if width != s.width || height != s.height {
        return Err(EdgesCsvError::WrongSize {
            path: path.to_path_buf(),
            width,
            height,
            sensor,
            rig: rig.name.clone(),
            sensor_width: s.width,
            sensor_height: s.height,
        });
    }
    let img = reader()?.decode().map_err(unreadable)?.to_rgb8();
    let mut si = SensorImage::new(sensor, s.width, s.height);
    si.pixels_mut().copy_from_slice(img.as_raw());
    si.set_valid(0);
    let params = EdgeParams {
        threads: 1,
        ..EdgeParams::default()
    };
    let mut det = EdgeDetector::with_params(rig, config, params);
    Ok(edges_csv(det.detect_sensor(&si), rig))
}

#[cfg(test)]
mod csv_errors {
    use super::*;

    /// Each way `omnitrack edges` can be handed the wrong image is one line naming it.
    #[test]
    fn a_wrong_sensor_file_or_size_is_named() {
        let rig = Rig::from_toml_str(
            "name = \"one\"\n[[sensors]]\nid = 0\nresolution = [8, 6]\nmodel = \"pinhole\"\n\
             intrinsics = [8.0, 8.0, 3.5, 2.5]\nrotation_wxyz = [1.0, 0.0, 0.0, 0.0]\n\
             translation_m = [0.0, 0.0, 0.0]\n",
            "one.toml",
        )
        .unwrap();
        let config = EdgeConfig::default();
        let dir = tempfile::tempdir().unwrap();
        let small = dir.path().join("small.png");
        image::RgbImage::new(4, 3).save(&small).unwrap();
        let right = dir.path().join("right.png");
        image::RgbImage::new(8, 6).save(&right).unwrap();

        let e = edges_csv_for_image(&rig, &config, 1, &right).unwrap_err();
        assert_eq!(e.to_string(), "--sensor 1: rig \"one\" has sensors 0..0");
        let missing = dir.path().join("missing.png");
        let e = edges_csv_for_image(&rig, &config, 0, &missing).unwrap_err();
        assert!(
            e.to_string()
                .starts_with(&format!("{}: cannot read image: ", missing.display())),
            "{e}"
        );
        let e = edges_csv_for_image(&rig, &config, 0, &small).unwrap_err();
        assert_eq!(
            e.to_string(),
            format!("{}: image is 4x3, sensor 0 of rig \"one\" is 8x6", small.display())
        );
        // A blank image of the right size has no edges: the header alone.
        let csv = edges_csv_for_image(&rig, &config, 0, &right).unwrap();
        assert_eq!(csv.lines().count(), 1, "{csv}");
    }
}
