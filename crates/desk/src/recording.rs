//! Synthetic recordings: a rig moving along a known trajectory through a building model,
//! written in the recording layout of docs/interfaces.md so that replay reads it like a real one.
//!
//! In: a rig, the model's OBJ text, a trajectory (`T_world_rig` per frame) and
//! [`RecordingOptions`]. Out: `REC/rig.toml`, `REC/frames.csv`, `REC/sensorK/NNNNNN.png`,
//! `REC/groundtruth.tum`, `REC/model.obj`, and a [`RecordingSummary`]. Every error is one line
//! naming the path. The images are the renderer's, already through JPEG when the appearance asks
//! for it (`Appearance::jpeg_quality`), then stored losslessly; `model.obj` is the model as
//! given, whatever the appearance displaced or added in the images.

use crate::render::{Appearance, ClutterCounts, FrameSpec, Renderer};
use image::codecs::png::{CompressionType, FilterType, PngEncoder};
use image::{ImageEncoder, RgbImage};
use nalgebra::Point3;
use omnitrack_core::model::Model;
use omnitrack_core::rig::Rig;
use omnitrack_core::trajectory::{to_tum_string, Trajectory};
use omnitrack_io::capture::replay::FRAMES_HEADER;
use rayon::prelude::*;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// How to make the recording.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordingOptions {
    pub appearance: Appearance,
    /// Sensor k's timestamp is the frame's plus `k × sensor_stagger_ns` (real sensors of one
    /// frame are a few ms apart). The images all show the rig at the frame's ground-truth pose.
    pub sensor_stagger_ns: u64,
}

impl Default for RecordingOptions {
    fn default() -> Self {
        RecordingOptions {
            appearance: Appearance::default(),
            sensor_stagger_ns: 700_000,
        }
    }
}

/// What was written.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordingSummary {
    pub dir: PathBuf,
    pub frames: usize,
    pub images: usize,
    /// Furniture boxes, shelves and posters placed (images only, not in model.obj).
    pub clutter: ClutterCounts,
    pub people: usize,
    /// Wall time spent ray casting and encoding/writing images.
    pub render_seconds: f64,
    pub write_seconds: f64,
}

/// A recording that could not be written: `path: what went wrong`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{path}: {message}")]
pub struct RecordingError {
    pub path: String,
    pub message: String,
}

fn err(path: &Path, message: impl std::fmt::Display) -> RecordingError {
    // One line, whatever the underlying message holds.
    let message = message.to_string().replace('\n', " ");
    RecordingError {
        path: path.display().to_string(),
        message,
    }
}

fn write_file(path: &Path, contents: &[u8]) -> Result<(), RecordingError> {
    std::fs::write(path, contents).map_err(|e| err(path, format!("cannot write: {e}")))
}

/// Encodes an image as PNG (fast compression) and writes it.
pub fn write_png(path: &Path, image: &RgbImage) -> Result<(), RecordingError> {
    let mut bytes = Vec::with_capacity(image.as_raw().len() / 2);
    PngEncoder::new_with_quality(&mut bytes, CompressionType::Fast, FilterType::Adaptive)
        .write_image(
            image.as_raw(),
            image.width(),
            image.height(),
            image::ExtendedColorType::Rgb8,
        )
        .map_err(|e| err(path, format!("cannot encode PNG: {e}")))?;
    write_file(path, &bytes)
}

/// Relative path of sensor `sensor`'s image of frame `frame`.
pub fn image_path(sensor: usize, frame: usize) -> String {
    format!("sensor{sensor}/{frame:06}.png")
}

/// Renders and writes a whole recording into `dir` (created if missing; files of the layout are
/// overwritten). `progress(done, total)` is called after each frame.
pub fn write_recording(
    dir: &Path,
    rig: &Rig,
    model_obj_text: &str,
    trajectory: &Trajectory,
    options: &RecordingOptions,
    mut progress: impl FnMut(usize, usize),
) -> Result<RecordingSummary, RecordingError> {
    let model_path = dir.join("model.obj");
    let model = Model::from_obj_str(model_obj_text, &model_path.display().to_string())
        .map_err(|e| err(&model_path, format!("bad model: {}", e.message)))?;
    std::fs::create_dir_all(dir).map_err(|e| err(dir, format!("cannot create directory: {e}")))?;
    for s in &rig.sensors {
        let d = dir.join(format!("sensor{}", s.id));
        std::fs::create_dir_all(&d).map_err(|e| err(&d, format!("cannot create directory: {e}")))?;
    }
    write_file(&dir.join("rig.toml"), rig.to_toml_string().as_bytes())?;
    write_file(&model_path, model_obj_text.as_bytes())?;
    write_file(&dir.join("groundtruth.tum"), to_tum_string(trajectory).as_bytes())?;

    let keep_out: Vec<Point3<f64>> = trajectory
        .iter()
        .map(|s| Point3::from(s.pose.translation.vector))
        .collect();
    let renderer = Renderer::new(&model, rig, options.appearance.clone(), &keep_out);
    let mut csv = format!("{FRAMES_HEADER}\n");
    let (mut render_seconds, mut write_seconds) = (0.0, 0.0);
    for (i, stamped) in trajectory.iter().enumerate() {
        let frame = FrameSpec {
            index: i as u64,
            timestamp_ns: stamped.timestamp_ns,
            pose: stamped.pose,
            previous: i.checked_sub(1).map(|p| trajectory[p]),
        };
        let start = Instant::now();
        let images = renderer.render_frame(&frame);
        render_seconds += start.elapsed().as_secs_f64();
        let start = Instant::now();
        images
            .par_iter()
            .zip(&rig.sensors)
            .map(|(img, s)| write_png(&dir.join(image_path(s.id, i)), img))
            .collect::<Result<Vec<()>, _>>()?;
        write_seconds += start.elapsed().as_secs_f64();
        for s in &rig.sensors {
            let ts = stamped.timestamp_ns + s.id as u64 * options.sensor_stagger_ns;
            let _ = writeln!(csv, "{i},{},{ts},{}", s.id, image_path(s.id, i));
        }
        progress(i + 1, trajectory.len());
    }
    write_file(&dir.join("frames.csv"), csv.as_bytes())?;
    let scene = renderer.scene();
    Ok(RecordingSummary {
        dir: dir.to_path_buf(),
        frames: trajectory.len(),
        images: trajectory.len() * rig.sensors.len(),
        clutter: scene.clutter_counts,
        people: scene.people.len(),
        render_seconds,
        write_seconds,
    })
}

/// Where the benchmarks cache their rendered recordings: `$OMNITRACK_CACHE`, or
/// `target/omnitrack-cache` under `project` (the repository's root). One place, so that every
/// bench finds the recordings the others rendered.
pub fn cache_root(project: &Path) -> PathBuf {
    std::env::var_os("OMNITRACK_CACHE")
        .map(PathBuf::from)
        .unwrap_or_else(|| project.join("target/omnitrack-cache"))
}

/// A rendered recording of a scenario in a cache directory, made on first use: `root/NAME-FRAMESf-seedSEED-LABEL`.
/// A recording is reused only when complete (a `complete` marker is written last), so an
/// interrupted render is redone. `progress(done, total)` is called per rendered frame. Returns
/// the directory and whether it was rendered now.
#[allow(clippy::too_many_arguments)]
pub fn cached_scenario(
    root: &Path,
    scenario: &crate::scenario::Scenario,
    frames: usize,
    seed: u64,
    label: &str,
    rig: &Rig,
    options: &RecordingOptions,
    progress: impl FnMut(usize, usize),
) -> Result<(PathBuf, bool), RecordingError> {
    let dir = root.join(format!("{}-{frames}f-seed{seed}-{label}", scenario.name));
    cached(&dir, rig, options, progress, || {
        let obj = scenario
            .model_obj()
            .map_err(|e| err(&dir, format!("cannot extrude the scenario's plan: {e}")))?;
        Ok((obj, scenario.trajectory(frames, seed)))
    })
}

/// A rendered walk through a random building ([`crate::scenario::random`]), cached like
/// [`cached_scenario`] in `root/building-SEED-FRAMESf-LABEL`; the walk's seed is the building's.
pub fn cached_building(
    root: &Path,
    building: &crate::scenario::random::RandomBuilding,
    frames: usize,
    label: &str,
    rig: &Rig,
    options: &RecordingOptions,
    progress: impl FnMut(usize, usize),
) -> Result<(PathBuf, bool), RecordingError> {
    let dir = root.join(format!("{}-{frames}f-{label}", building.name()));
    cached(&dir, rig, options, progress, || {
        Ok((building.obj.clone(), building.trajectory(frames, building.seed)))
    })
}

fn cached(
    dir: &Path,
    rig: &Rig,
    options: &RecordingOptions,
    progress: impl FnMut(usize, usize),
    make: impl FnOnce() -> Result<(String, Trajectory), RecordingError>,
) -> Result<(PathBuf, bool), RecordingError> {
    let marker = dir.join("complete");
    if marker.exists() {
        return Ok((dir.to_path_buf(), false));
    }
    let (obj, trajectory) = make()?;
    write_recording(dir, rig, &obj, &trajectory, options, progress)?;
    write_file(&marker, b"")?;
    Ok((dir.to_path_buf(), true))
}

/// A recording of `src` as a one-device camera would have made it: each frame's sensor images
/// side by side in one image (`frames/NNNNNN.png`, sensors left to right, top-aligned), every
/// sensor a `crop` of that frame on the shared `device`, and every row of a frame naming the same
/// file (with the sensor's own timestamp). What a dual-fisheye 360° camera delivers, made from a
/// rendered per-sensor recording. Ground truth and model are copied; the images stay lossless,
/// so tracking `out` sees exactly the pixels of `src`. Made once: a `complete` marker is written
/// last and a complete `out` is reused. Returns whether it was made now.
pub fn join_sensors(src: &Path, out: &Path, device: &str) -> Result<bool, RecordingError> {
    let marker = out.join("complete");
    if marker.exists() {
        return Ok(false);
    }
    let mut rig = Rig::load(&src.join("rig.toml")).map_err(|e| err(src, e))?;
    let mut x = 0;
    for s in rig.sensors.iter_mut() {
        s.device = Some(device.to_string());
        s.usb_serial = None;
        s.crop = Some([x, 0, s.width, s.height]);
        x += s.width;
    }
    let (width, height) = (x, rig.sensors.iter().map(|s| s.height).max().unwrap_or(0));
    let frames_dir = out.join("frames");
    std::fs::create_dir_all(&frames_dir).map_err(|e| err(&frames_dir, format!("cannot create directory: {e}")))?;
    write_file(&out.join("rig.toml"), rig.to_toml_string().as_bytes())?;
    for name in ["groundtruth.tum", "model.obj"] {
        if src.join(name).is_file() {
            std::fs::copy(src.join(name), out.join(name))
                .map_err(|e| err(&out.join(name), format!("cannot copy: {e}")))?;
        }
    }
    let index_path = src.join("frames.csv");
    let index = std::fs::read_to_string(&index_path).map_err(|e| err(&index_path, format!("cannot read: {e}")))?;
    // frame → [(sensor, timestamp, path)]
    let mut frames: std::collections::BTreeMap<u64, Vec<(usize, u64, String)>> = Default::default();
    for (n, line) in index.lines().enumerate().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let parsed = match f.as_slice() {
            [frame, sensor, ts, path] => frame
                .parse()
                .ok()
                .zip(sensor.parse().ok())
                .zip(ts.parse().ok())
                .map(|((a, b), c)| (a, b, c, path.to_string())),
            _ => None,
        };
        let Some((frame, sensor, ts, path)) = parsed else {
            return Err(err(&index_path, format!("line {}: not {FRAMES_HEADER}", n + 1)));
        };
        frames.entry(frame).or_default().push((sensor, ts, path));
    }
    let mut csv = format!("{FRAMES_HEADER}\n");
    for (frame, rows) in &frames {
        let mut joined = RgbImage::new(width, height);
        for (sensor, _, path) in rows {
            let Some([x, _, _, _]) = rig.sensors.get(*sensor).and_then(|s| s.crop) else {
                return Err(err(
                    &index_path,
                    format!("frame {frame}: no sensor {sensor} in the rig"),
                ));
            };
            let p = src.join(path);
            let img = image::open(&p)
                .map_err(|e| err(&p, format!("cannot read: {e}")))?
                .to_rgb8();
            image::imageops::replace(&mut joined, &img, i64::from(x), 0);
        }
        let name = format!("frames/{frame:06}.png");
        write_png(&out.join(&name), &joined)?;
        for (sensor, ts, _) in rows {
            let _ = writeln!(csv, "{frame},{sensor},{ts},{name}");
        }
    }
    write_file(&out.join("frames.csv"), csv.as_bytes())?;
    write_file(&marker, b"")?;
    Ok(true)
}
