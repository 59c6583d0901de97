//! [`omni_view`]: one frame's sensor images, the rig and the model at a pose in; a PNG of the
//! images tiled with the model re-projected through each sensor's lens out (Koch–Teller
//! Figure 12), the projection being omnitrack-core's [`project_segments`] (the live view's too);
//! [`omni_layout`] is the tiling.

use super::canvas::{bold_1x, render_png};
use super::{picture_error, PictureError};
use image::RgbImage;
use omnitrack_core::frame::FrameSet;
use omnitrack_core::geometry::Pose;
use omnitrack_core::rig::project_segments;
use omnitrack_core::{Model, Rig};
use plotters::prelude::*;
use std::path::Path;

/// The re-projected model (Figure 12 draws it green).
pub const MODEL_GREEN: [u8; 3] = [40, 255, 60];

/// How to draw [`omni_view`].
#[derive(Debug, Clone, PartialEq)]
pub struct OmniOptions {
    /// Headline above the tiles.
    pub title: String,
    /// Tiles per row (the shipped rig's six portrait images look best in 3 × 2).
    pub columns: usize,
    /// Draw only these model segments (indices into `model.segments`, e.g. a visibility set),
    /// a cheap stand-in for occlusion; `None`: all of them, seen through walls.
    pub segments: Option<Vec<usize>>,
    /// Line colour and width (px) of the re-projected model.
    pub colour: [u8; 3],
    pub line_width: u32,
}

impl Default for OmniOptions {
    fn default() -> Self {
        Self {
            title: "Model re-projected over the sensor images".into(),
            columns: 3,
            segments: None,
            colour: MODEL_GREEN,
            line_width: 2,
        }
    }
}

/// One RGB image per sensor of a frame, in sensor order; an image the source marked invalid
/// comes out mid-grey so that it is not mistaken for a picture of the scene.
pub fn frame_images(frame: &FrameSet) -> Vec<RgbImage> {
    frame
        .sensors()
        .iter()
        .map(|s| {
            if s.valid {
                RgbImage::from_raw(s.width(), s.height(), s.pixels().to_vec())
                    .unwrap_or_else(|| RgbImage::from_pixel(s.width(), s.height(), image::Rgb([128, 128, 128])))
            } else {
                RgbImage::from_pixel(s.width(), s.height(), image::Rgb([128, 128, 128]))
            }
        })
        .collect()
}

const OMNI_GAP: u32 = 6;
const OMNI_HEADER: u32 = 44;

/// Where [`omni_view`] puts each sensor's image.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OmniLayout {
    /// Picture size in pixels.
    pub size: (u32, u32),
    /// Top-left pixel of each sensor's image, in sensor order.
    pub origins: Vec<(u32, u32)>,
}

/// The tiling of [`omni_view`]: `columns` cells per row (clamped to 1..=sensors), each as large as
/// the largest sensor image, images centred in their cells, below a title strip.
pub fn omni_layout(rig: &Rig, columns: usize) -> OmniLayout {
    let n = rig.sensors.len();
    let columns = columns.clamp(1, n.max(1));
    let rows = n.div_ceil(columns) as u32;
    let cell_w = rig.sensors.iter().map(|s| s.width).max().unwrap_or(1);
    let cell_h = rig.sensors.iter().map(|s| s.height).max().unwrap_or(1);
    let origins = rig
        .sensors
        .iter()
        .enumerate()
        .map(|(k, s)| {
            let (col, row) = ((k % columns) as u32, (k / columns) as u32);
            (
                OMNI_GAP + col * (cell_w + OMNI_GAP) + (cell_w - s.width) / 2,
                OMNI_HEADER + row * (cell_h + OMNI_GAP) + (cell_h - s.height) / 2,
            )
        })
        .collect();
    let size = (
        columns as u32 * cell_w + (columns as u32 + 1) * OMNI_GAP,
        OMNI_HEADER + rows * (cell_h + OMNI_GAP),
    );
    OmniLayout { size, origins }
}

/// The sensor images of one frame tiled in one picture, labelled with their sensor ids, with
/// the model segments re-projected through each sensor's lens at `t_world_rig` (Figure 12).
/// `images` holds one image per sensor of `rig`, in sensor order, each of that sensor's size
/// ([`frame_images`] makes them from a [`FrameSet`]).
pub fn omni_view(
    path: &Path,
    rig: &Rig,
    images: &[RgbImage],
    model: &Model,
    t_world_rig: &Pose,
    options: &OmniOptions,
) -> Result<(), PictureError> {
    if images.len() != rig.sensors.len() {
        return Err(picture_error(
            path,
            format!(
                "{} images for the {} sensors of rig {}",
                images.len(),
                rig.sensors.len(),
                rig.name
            ),
        ));
    }
    for (img, s) in images.iter().zip(&rig.sensors) {
        if img.dimensions() != (s.width, s.height) {
            return Err(picture_error(
                path,
                format!(
                    "image of sensor {} is {}×{}, the rig says {}×{}",
                    s.id,
                    img.width(),
                    img.height(),
                    s.width,
                    s.height
                ),
            ));
        }
    }
    if let Some(bad) = options.segments.iter().flatten().find(|&&i| i >= model.segments.len()) {
        return Err(picture_error(
            path,
            format!("segment {bad} does not exist (the model has {})", model.segments.len()),
        ));
    }
    if images.is_empty() {
        return Err(picture_error(path, "the rig has no sensors"));
    }
    let layout = omni_layout(rig, options.columns);
    let (width, height) = layout.size;
    if width > 16384 || height > 16384 {
        return Err(picture_error(path, format!("tiled picture would be {width}×{height}")));
    }
    let mut canvas = RgbImage::from_pixel(width, height, image::Rgb([24, 24, 24]));
    for (img, &(x0, y0)) in images.iter().zip(&layout.origins) {
        image::imageops::replace(&mut canvas, img, i64::from(x0), i64::from(y0));
    }
    let t_rig_world = t_world_rig.inverse();
    let all: Vec<usize>;
    let chosen = match options.segments.as_deref() {
        Some(ids) => ids,
        None => {
            all = (0..model.segments.len()).collect();
            &all
        }
    };
    // Samples a pixel apart or closer: the fisheye's curves stay smooth at the line's width.
    let runs: Vec<_> = rig
        .sensors
        .iter()
        .map(|sensor| {
            let segments = chosen.iter().map(|&i| &model.segments[i]).map(|s| (s.a, s.b));
            project_segments(sensor, &t_rig_world, segments, 1.0)
        })
        .collect();
    let [r, g, b] = options.colour;
    let line = RGBColor(r, g, b).stroke_width(options.line_width.max(1));
    render_png(path, (width, height), false, Some(canvas.into_raw()), |root| {
        let t = t_world_rig.translation.vector;
        let title = format!(
            "{}   (rig at x {:.2}, y {:.2}, z {:.2} m)",
            options.title, t.x, t.y, t.z
        );
        root.draw_text(&title, &bold_1x(22.0).color(&WHITE), (OMNI_GAP as i32 + 4, 10))?;
        for (k, sensor_runs) in runs.iter().enumerate() {
            let (x0, y0) = layout.origins[k];
            let (w, h) = images[k].dimensions();
            let tile = root.clone().shrink((x0 as i32, y0 as i32), (w as i32, h as i32));
            for run in sensor_runs {
                // Pixel centres sit at integers (docs/interfaces.md), as plotters' pixel grid does.
                let pts: Vec<(i32, i32)> = run.iter().map(|p| (p.x.round() as i32, p.y.round() as i32)).collect();
                tile.draw(&PathElement::new(pts, line))?;
            }
            tile.draw(&Rectangle::new(
                [(6, 6), (110, 34)],
                RGBColor(0, 0, 0).mix(0.6).filled(),
            ))?;
            tile.draw_text(
                &format!("sensor {}", rig.sensors[k].id),
                &bold_1x(18.0).color(&WHITE),
                (14, 10),
            )?;
        }
        Ok(())
    })
}
