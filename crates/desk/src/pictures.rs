//! Pictures of a tracking run, as PNG files: what people look at before they read a table.
//!
//! In: the building [`Model`], trajectories and their evaluation ([`crate::eval`]), the
//! [`Rig`] and one frame's sensor images, traces of correspondence states. Out: PNG files:
//! - [`plan_view`]: ground truth beside the estimated path over the floor plan, the estimate
//!   coloured by its position error (Koch–Teller Figures 1, 10, 11);
//! - [`omni_view`]: the sensor images of one frame tiled, the model re-projected in green
//!   through each sensor's lens (Figure 12);
//! - [`error_over_time`]: position and rotation error against time;
//! - [`correspondence_states`]: the state of chosen correspondences over time (Figure 14).
//!
//! Drawing is plotters into an RGB buffer that the `image` crate encodes; text uses DejaVu Sans
//! embedded from the `dejavu` crate, so no system font is ever looked up. Every function returns
//! a [`PictureError`] naming the output file instead of panicking.

use crate::eval::PoseError;
use image::RgbImage;
use nalgebra::Point3;
use omnitrack_core::geometry::{Lens, Pose};
use omnitrack_core::trajectory::Stamped;
use omnitrack_core::{Model, Rig};
use omnitrack_io::capture::FrameSet;
pub use omnitrack_tracker::CorrespondenceState;
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::{register_font, FontStyle};
use std::error::Error;
use std::path::Path;
use std::sync::OnceLock;

/// A picture that could not be made: `path: what went wrong`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{path}: {message}")]
pub struct PictureError {
    pub path: String,
    pub message: String,
}

fn picture_error(path: &Path, message: impl Into<String>) -> PictureError {
    PictureError {
        path: path.display().to_string(),
        message: message.into(),
    }
}

type DrawResult = Result<(), Box<dyn Error>>;
type Area<'a> = DrawingArea<BitMapBackend<'a>, Shift>;

const FONT: &str = "sans-serif";
const TITLE_PX: f64 = 26.0;
const LABEL_PX: f64 = 18.0;
const TICK_PX: f64 = 15.0;
const PLAN_GREY: RGBColor = RGBColor(190, 190, 190);
const GT_COLOUR: RGBColor = RGBColor(30, 30, 30);
const UNMATCHED: RGBColor = RGBColor(150, 150, 150);
/// The re-projected model (Figure 12 draws it green).
pub const MODEL_GREEN: [u8; 3] = [40, 255, 60];

fn register_fonts() -> bool {
    static OK: OnceLock<bool> = OnceLock::new();
    *OK.get_or_init(|| {
        register_font(FONT, FontStyle::Normal, dejavu::sans::regular()).is_ok()
            && register_font(FONT, FontStyle::Bold, dejavu::sans::bold()).is_ok()
    })
}

/// Supersampling factor of the plots: drawn at this multiple of the picture size, then averaged
/// down, since plotters' bitmap backend draws without anti-aliasing.
const SS: u32 = 2;

/// A length in output pixels as drawn on the supersampled canvas.
fn s(v: u32) -> u32 {
    v * SS
}

fn si(v: i32) -> i32 {
    v * SS as i32
}

/// Draws on a canvas of `size`, or of `size × SS` when `supersample`, and writes it as PNG.
/// `background` (RGB8 of exactly `size`, only without supersampling) replaces the white canvas.
fn render_png(
    path: &Path,
    size: (u32, u32),
    supersample: bool,
    background: Option<Vec<u8>>,
    draw: impl FnOnce(&Area) -> DrawResult,
) -> Result<(), PictureError> {
    let (w, h) = size;
    if !(64..=16384).contains(&w) || !(64..=16384).contains(&h) {
        return Err(picture_error(
            path,
            format!("picture size {w}×{h} out of range 64..16384"),
        ));
    }
    if !register_fonts() {
        return Err(picture_error(path, "the embedded DejaVu font could not be loaded"));
    }
    let k = if supersample { SS } else { 1 };
    let (cw, ch) = (w * k, h * k);
    let mut buffer = match background {
        Some(b) if !supersample && b.len() == w as usize * h as usize * 3 => b,
        Some(_) => return Err(picture_error(path, "background does not match the picture size")),
        None => vec![255u8; cw as usize * ch as usize * 3],
    };
    {
        let root = BitMapBackend::with_buffer(&mut buffer, (cw, ch)).into_drawing_area();
        draw(&root).map_err(|e| picture_error(path, format!("cannot draw: {e}")))?;
        root.present()
            .map_err(|e| picture_error(path, format!("cannot draw: {e}")))?;
    }
    let canvas = RgbImage::from_raw(cw, ch, buffer).ok_or_else(|| picture_error(path, "canvas size mismatch"))?;
    let out = if supersample {
        image::imageops::resize(&canvas, w, h, image::imageops::FilterType::Triangle)
    } else {
        canvas
    };
    out.save_with_format(path, image::ImageFormat::Png)
        .map_err(|e| picture_error(path, format!("cannot write PNG: {e}")))
}

/// Text of `px` output pixels on the supersampled canvas.
fn font(px: f64) -> TextStyle<'static> {
    TextStyle::from((FONT, px * SS as f64).into_font())
}

fn bold(px: f64) -> TextStyle<'static> {
    TextStyle::from((FONT, px * SS as f64, FontStyle::Bold).into_font())
}

/// Text at the canvas' own scale (for pictures drawn without supersampling).
fn bold_1x(px: f64) -> TextStyle<'static> {
    TextStyle::from((FONT, px, FontStyle::Bold).into_font())
}

/// Plasma colour map up to 0.85 (the last yellows vanish on white), `t` in [0, 1].
pub fn error_colour(t: f64) -> RGBColor {
    const STOPS: [(f64, [u8; 3]); 10] = [
        (0.0, [13, 8, 135]),
        (0.1, [65, 4, 157]),
        (0.2, [106, 0, 168]),
        (0.3, [143, 13, 164]),
        (0.4, [177, 42, 144]),
        (0.5, [204, 71, 120]),
        (0.6, [225, 100, 98]),
        (0.7, [242, 132, 75]),
        (0.8, [252, 166, 54]),
        (0.9, [252, 206, 37]),
    ];
    let x = t.clamp(0.0, 1.0) * 0.85;
    let k = STOPS.iter().rposition(|s| s.0 <= x).unwrap_or(0).min(STOPS.len() - 2);
    let (x0, c0) = STOPS[k];
    let (x1, c1) = STOPS[k + 1];
    let f = ((x - x0) / (x1 - x0)).clamp(0.0, 1.0);
    let mix = |a: u8, b: u8| (a as f64 + (b as f64 - a as f64) * f).round() as u8;
    RGBColor(mix(c0[0], c1[0]), mix(c0[1], c1[1]), mix(c0[2], c1[2]))
}

/// How to draw [`plan_view`].
#[derive(Debug, Clone, PartialEq)]
pub struct PlanOptions {
    /// Headline above both panels.
    pub title: String,
    /// Picture size in pixels.
    pub size: (u32, u32),
    /// Top of the colour scale (m); `None`: the largest error.
    pub error_max_m: Option<f64>,
    /// Keep only model segments with both ends in this z range (m), e.g. one storey;
    /// `None`: every segment that is not vertical, projected onto the floor.
    pub z_range_m: Option<(f64, f64)>,
}

impl Default for PlanOptions {
    fn default() -> Self {
        Self {
            title: "Trajectory over the floor plan".into(),
            size: (1600, 800),
            error_max_m: None,
            z_range_m: None,
        }
    }
}

/// The floor-plan lines of a model: non-vertical segments projected onto the x–y plane.
fn plan_lines(model: &Model, z_range: Option<(f64, f64)>) -> Vec<[(f64, f64); 2]> {
    model
        .segments
        .iter()
        .filter(|s| s.direction().z.abs() < 0.95)
        .filter(|s| z_range.is_none_or(|(lo, hi)| [s.a.z, s.b.z].iter().all(|z| (lo..=hi).contains(z))))
        .map(|s| [(s.a.x, s.a.y), (s.b.x, s.b.y)])
        .collect()
}

/// Widens `x`, `y` ranges so that one metre spans as many pixels across as up (equal aspect).
fn equal_aspect(x: (f64, f64), y: (f64, f64), pixels: (u32, u32)) -> ((f64, f64), (f64, f64)) {
    let (w, h) = (pixels.0.max(1) as f64, pixels.1.max(1) as f64);
    let scale = ((x.1 - x.0) / w).max((y.1 - y.0) / h);
    let (cx, cy) = ((x.0 + x.1) / 2.0, (y.0 + y.1) / 2.0);
    (
        (cx - scale * w / 2.0, cx + scale * w / 2.0),
        (cy - scale * h / 2.0, cy + scale * h / 2.0),
    )
}

/// Ground truth (left) beside the estimate (right) over the floor plan of `model`, metres on
/// both axes at equal scale, the estimate coloured by its position error with a colour bar.
///
/// `estimate_error_m` holds one entry per estimated pose (`None` where the pose was not
/// associated; [`crate::eval::Evaluation::position_error_per_estimate`] makes it), or is
/// empty to draw the estimate in one colour. Draw an aligned evaluation's estimate through
/// [`crate::eval::transformed`] first.
pub fn plan_view(
    path: &Path,
    model: &Model,
    ground_truth: &[Stamped],
    estimate: &[Stamped],
    estimate_error_m: &[Option<f64>],
    options: &PlanOptions,
) -> Result<(), PictureError> {
    if !estimate_error_m.is_empty() && estimate_error_m.len() != estimate.len() {
        return Err(picture_error(
            path,
            format!(
                "{} position errors for {} estimated poses",
                estimate_error_m.len(),
                estimate.len()
            ),
        ));
    }
    let lines = plan_lines(model, options.z_range_m);
    let xy = |s: &Stamped| (s.pose.translation.x, s.pose.translation.y);
    let points: Vec<(f64, f64)> = lines
        .iter()
        .flatten()
        .copied()
        .chain(ground_truth.iter().map(xy))
        .chain(estimate.iter().map(xy))
        .filter(|p| p.0.is_finite() && p.1.is_finite())
        .collect();
    if points.is_empty() {
        return Err(picture_error(path, "nothing to draw: no plan segments and no poses"));
    }
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for p in &points {
        (x0, x1, y0, y1) = (x0.min(p.0), x1.max(p.0), y0.min(p.1), y1.max(p.1));
    }
    let pad = 0.04 * (x1 - x0).max(y1 - y0).max(1.0);
    let (bx, by) = ((x0 - pad, x1 + pad), (y0 - pad, y1 + pad));

    let errors: Vec<f64> = estimate_error_m
        .iter()
        .flatten()
        .copied()
        .filter(|e| e.is_finite())
        .collect();
    let max_err = options
        .error_max_m
        .filter(|m| m.is_finite() && *m > 0.0)
        .unwrap_or_else(|| errors.iter().copied().fold(0.0, f64::max))
        .max(1e-3);
    let coloured = !errors.is_empty();

    render_png(path, options.size, true, None, |root| {
        root.fill(&WHITE)?;
        let area = root.margin(s(8), 0, 0, 0).titled(&options.title, bold(TITLE_PX))?;
        let (w, _) = area.dim_in_pixel();
        let bar_w = if coloured { s(120) } else { 0 };
        let (panels, bar) = area.split_horizontally(w.saturating_sub(bar_w));
        let halves = panels.split_evenly((1, 2));
        let subtitle = if coloured {
            "estimate, coloured by position error (○ start, ■ end)"
        } else {
            "estimate (○ start, ■ end)"
        };
        let (margin, x_label, y_label) = (s(12), s(48), s(64));
        for (k, half) in halves.iter().enumerate() {
            let half = half.titled(
                if k == 0 {
                    "ground truth (○ start, ■ end)"
                } else {
                    subtitle
                },
                font(LABEL_PX + 2.0),
            )?;
            let (pw, ph) = half.dim_in_pixel();
            let plot_px = (
                pw.saturating_sub(2 * margin + y_label),
                ph.saturating_sub(2 * margin + x_label),
            );
            let (rx, ry) = equal_aspect(bx, by, plot_px);
            let mut chart = ChartBuilder::on(&half)
                .margin(margin)
                .x_label_area_size(x_label)
                .y_label_area_size(y_label)
                .build_cartesian_2d(rx.0..rx.1, ry.0..ry.1)?;
            chart
                .configure_mesh()
                .axis_style(RGBColor(70, 70, 70).stroke_width(s(1)))
                .set_all_tick_mark_size(s(4))
                .light_line_style(RGBColor(240, 240, 240))
                .bold_line_style(RGBColor(225, 225, 225))
                .x_desc("x (m)")
                .y_desc("y (m)")
                .label_style(font(TICK_PX))
                .axis_desc_style(font(LABEL_PX))
                .draw()?;
            chart.draw_series(
                lines
                    .iter()
                    .map(|l| PathElement::new(l.to_vec(), PLAN_GREY.stroke_width(s(2)))),
            )?;
            let gt: Vec<(f64, f64)> = ground_truth.iter().map(xy).collect();
            if k == 0 {
                chart.draw_series(std::iter::once(PathElement::new(
                    gt.clone(),
                    GT_COLOUR.stroke_width(s(3)),
                )))?;
                draw_ends(&mut chart, &gt)?;
                continue;
            }
            // The ground truth faintly under the estimate, so that a miss is visible at a glance.
            chart.draw_series(std::iter::once(PathElement::new(
                gt,
                RGBColor(120, 120, 120).stroke_width(s(1)),
            )))?;
            let est: Vec<(f64, f64)> = estimate.iter().map(xy).collect();
            let colour_of = |e: Option<f64>| match e {
                Some(e) if e.is_finite() => error_colour(e / max_err),
                _ => UNMATCHED,
            };
            chart.draw_series(est.windows(2).enumerate().map(|(i, seg)| {
                let c = if coloured {
                    let e = match (estimate_error_m[i], estimate_error_m[i + 1]) {
                        (Some(a), Some(b)) => Some((a + b) / 2.0),
                        (a, b) => a.or(b),
                    };
                    colour_of(e)
                } else {
                    RGBColor(200, 40, 40)
                };
                PathElement::new(seg.to_vec(), c.stroke_width(s(3)))
            }))?;
            if coloured {
                chart.draw_series(
                    est.iter()
                        .zip(estimate_error_m)
                        .map(|(p, e)| Circle::new(*p, s(3), colour_of(*e).filled())),
                )?;
            }
            draw_ends(&mut chart, &est)?;
        }
        if coloured {
            colour_bar(&bar, max_err * 100.0, "position error (cm)")?;
        }
        Ok(())
    })
}

type PlanChart<'a, 'b> = ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// A hollow circle at the start and a filled square at the end of a path.
fn draw_ends(chart: &mut PlanChart, path: &[(f64, f64)]) -> DrawResult {
    if let (Some(first), Some(last)) = (path.first(), path.last()) {
        chart.draw_series(std::iter::once(Circle::new(*first, s(7), BLACK.stroke_width(s(2)))))?;
        chart.draw_series(std::iter::once(
            EmptyElement::at(*last) + Rectangle::new([(si(-5), si(-5)), (si(5), si(5))], BLACK.filled()),
        ))?;
    }
    Ok(())
}

/// A vertical colour bar from 0 to `max` with labelled ticks.
fn colour_bar(area: &Area, max: f64, label: &str) -> DrawResult {
    let (_, h) = area.dim_in_pixel();
    let mut chart = ChartBuilder::on(area)
        .margin_top(s(40))
        .margin_bottom((h / 5).max(s(60)))
        .margin_right(s(8))
        .y_label_area_size(s(80))
        .build_cartesian_2d(0.0..1.0, 0.0..max)?;
    chart
        .configure_mesh()
        .axis_style(RGBColor(70, 70, 70).stroke_width(s(1)))
        .set_all_tick_mark_size(s(4))
        .disable_mesh()
        .disable_x_axis()
        .y_desc(label)
        .y_labels(8)
        .label_style(font(TICK_PX))
        .axis_desc_style(font(LABEL_PX))
        .draw()?;
    const STEPS: usize = 200;
    chart.draw_series((0..STEPS).map(|k| {
        let (a, b) = (k as f64 / STEPS as f64, (k + 1) as f64 / STEPS as f64);
        Rectangle::new([(0.0, a * max), (1.0, b * max)], error_colour((a + b) / 2.0).filled())
    }))?;
    Ok(())
}

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

/// Pixels per radian the lens reaches at most (fisheye ≈ f; a pinhole grows towards its edge).
fn pixels_per_radian(lens: &Lens) -> f64 {
    let f = lens.fx().max(lens.fy());
    match lens {
        Lens::Pinhole(_) => 3.0 * f,
        _ => 1.5 * f,
    }
}

/// The polylines (in the sensor's pixels) of the model segments as one sensor sees them at
/// `t_world_rig`: each segment sampled every ~2 px or finer, broken where it leaves the image.
pub fn project_segments(
    rig: &Rig,
    sensor: usize,
    model: &Model,
    t_world_rig: &Pose,
    segments: Option<&[usize]>,
) -> Vec<Vec<(f64, f64)>> {
    let Some(s) = rig.sensors.get(sensor) else {
        return Vec::new();
    };
    let t_rig_world = t_world_rig.inverse();
    let centre = s.centre();
    let density = pixels_per_radian(&s.lens);
    let jump = 0.25 * s.width.min(s.height) as f64;
    let all: Vec<usize>;
    let chosen = match segments {
        Some(ids) => ids,
        None => {
            all = (0..model.segments.len()).collect();
            &all
        }
    };
    let mut out = Vec::new();
    for seg in chosen.iter().filter_map(|&i| model.segments.get(i)) {
        let a = t_rig_world.transform_point(&seg.a);
        let b = t_rig_world.transform_point(&seg.b);
        let (ra, rb) = (a - centre, b - centre);
        let angle = if ra.norm() < 1e-9 || rb.norm() < 1e-9 {
            std::f64::consts::PI
        } else {
            ra.angle(&rb)
        };
        // Two samples per pixel of arc, so that curved fisheye images of lines stay smooth.
        let n = ((angle * density).ceil() as usize).clamp(2, 20_000);
        let mut run: Vec<(f64, f64)> = Vec::new();
        for k in 0..=n {
            let t = k as f64 / n as f64;
            let p = Point3::from(a.coords * (1.0 - t) + b.coords * t);
            match s.project_from_rig(&p) {
                Some(px) => {
                    let q = (px.x, px.y);
                    if let Some(last) = run.last() {
                        if (last.0 - q.0).hypot(last.1 - q.1) > jump {
                            out.push(std::mem::take(&mut run));
                        }
                    }
                    run.push(q);
                }
                None if run.len() > 1 => out.push(std::mem::take(&mut run)),
                None => run.clear(),
            }
        }
        if run.len() > 1 {
            out.push(run);
        }
    }
    out
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
    let runs: Vec<Vec<Vec<(f64, f64)>>> = (0..rig.sensors.len())
        .map(|k| project_segments(rig, k, model, t_world_rig, options.segments.as_deref()))
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
                let pts: Vec<(i32, i32)> = run.iter().map(|p| (p.0.round() as i32, p.1.round() as i32)).collect();
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

/// One error series for [`error_over_time`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ErrorTrace<'a> {
    /// Legend text, e.g. "ATE" or "tracker, LMS".
    pub label: &'a str,
    /// Per-pose errors ([`crate::eval::ErrorSeries::per_pose`]).
    pub errors: &'a [PoseError],
}

const SERIES_COLOURS: [RGBColor; 5] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
    RGBColor(255, 127, 14),
];

/// Splits a time series where consecutive samples are further apart than five typical steps,
/// so that a lost stretch shows as a gap rather than a straight line across it.
fn split_at_gaps(points: &[(f64, f64)]) -> Vec<Vec<(f64, f64)>> {
    let mut steps: Vec<f64> = points.windows(2).map(|w| w[1].0 - w[0].0).collect();
    steps.sort_by(f64::total_cmp);
    let typical = steps.get(steps.len() / 2).copied().unwrap_or(f64::INFINITY);
    let mut out: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
    for (i, p) in points.iter().enumerate() {
        if i > 0 && p.0 - points[i - 1].0 > 5.0 * typical {
            out.push(Vec::new());
        }
        if let Some(run) = out.last_mut() {
            run.push(*p);
        }
    }
    out
}

/// Position error (cm, top) and rotation error (degrees, bottom) against time (s, from the
/// earliest pose of all series), one line per trace, with its RMSE in the legend.
pub fn error_over_time(path: &Path, title: &str, traces: &[ErrorTrace], size: (u32, u32)) -> Result<(), PictureError> {
    let t0 = traces
        .iter()
        .flat_map(|t| t.errors.iter().map(|e| e.timestamp_ns))
        .min()
        .ok_or_else(|| picture_error(path, "no errors to draw"))?;
    let secs = |e: &PoseError| (e.timestamp_ns - t0) as f64 * 1e-9;
    let t_max = traces
        .iter()
        .flat_map(|t| t.errors.iter().map(secs))
        .fold(0.0, f64::max)
        .max(1e-3);
    type Pick = fn(&PoseError) -> f64;
    let panels: [(&str, &str, Pick); 2] = [
        ("position error (cm)", "cm", |e| e.translation_m * 100.0),
        ("rotation error (deg)", "°", |e| e.rotation_deg),
    ];
    render_png(path, size, true, None, |root| {
        root.fill(&WHITE)?;
        let area = root.margin(s(8), 0, 0, 0).titled(title, bold(TITLE_PX))?;
        let halves = area.split_evenly((2, 1));
        for ((desc, unit, pick), half) in panels.iter().zip(&halves) {
            let y_max = traces
                .iter()
                .flat_map(|t| t.errors.iter().map(pick))
                .filter(|v| v.is_finite())
                .fold(0.0, f64::max);
            let y_max = if y_max > 0.0 { y_max * 1.1 } else { 1.0 };
            let mut chart = ChartBuilder::on(half)
                .margin(s(14))
                .x_label_area_size(s(46))
                .y_label_area_size(s(70))
                .build_cartesian_2d(0.0..t_max, 0.0..y_max)?;
            chart
                .configure_mesh()
                .axis_style(RGBColor(70, 70, 70).stroke_width(s(1)))
                .set_all_tick_mark_size(s(4))
                .light_line_style(RGBColor(240, 240, 240))
                .bold_line_style(RGBColor(222, 222, 222))
                .x_desc("time (s)")
                .y_desc(*desc)
                .label_style(font(TICK_PX))
                .axis_desc_style(font(LABEL_PX))
                .draw()?;
            for (k, trace) in traces.iter().enumerate() {
                let colour = SERIES_COLOURS[k % SERIES_COLOURS.len()];
                let points: Vec<(f64, f64)> = trace.errors.iter().map(|e| (secs(e), pick(e))).collect();
                let values: Vec<f64> = points.iter().map(|p| p.1).collect();
                let rmse = crate::eval::Stats::of(&values).map(|s| s.rmse).unwrap_or(0.0);
                let label = format!("{}  (RMSE {rmse:.2} {unit})", trace.label);
                let mut first = true;
                for run in split_at_gaps(&points) {
                    let series = chart.draw_series(LineSeries::new(run, colour.stroke_width(s(2))))?;
                    if std::mem::take(&mut first) {
                        series.label(label.clone()).legend(move |(x, y)| {
                            PathElement::new(vec![(x, y), (x + si(24), y)], colour.stroke_width(s(3)))
                        });
                    }
                }
            }
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::UpperRight)
                .legend_area_size(s(34))
                .margin(s(10))
                .label_font(font(TICK_PX + 1.0))
                .background_style(WHITE.mix(0.85))
                .border_style(RGBColor(180, 180, 180))
                .draw()?;
        }
        Ok(())
    })
}

/// The colour of a correspondence state in the pictures.
fn state_colour(state: CorrespondenceState) -> RGBColor {
    match state {
        CorrespondenceState::Unknown => RGBColor(215, 215, 215),
        CorrespondenceState::Pending => RGBColor(245, 170, 40),
        CorrespondenceState::Accepted => RGBColor(40, 160, 70),
    }
}

/// One correspondence's states over time for [`correspondence_states`].
#[derive(Debug, Clone, PartialEq)]
pub struct StateTrace {
    /// Row label, e.g. "segment 12 / sensor 3".
    pub label: String,
    /// `(time_s, state)` in time order; each state holds until the next sample.
    pub samples: Vec<(f64, CorrespondenceState)>,
}

/// Coloured horizontal bands, one row per trace, showing each correspondence's state over time
/// (Figure 14). The last sample of every trace holds until the latest sample of all traces plus
/// one typical step.
pub fn correspondence_states(
    path: &Path,
    title: &str,
    traces: &[StateTrace],
    size: (u32, u32),
) -> Result<(), PictureError> {
    if traces.iter().all(|t| t.samples.is_empty()) {
        return Err(picture_error(path, "no correspondence states to draw"));
    }
    for t in traces {
        if t.samples.iter().any(|s| !s.0.is_finite()) || t.samples.windows(2).any(|w| w[1].0 < w[0].0) {
            return Err(picture_error(
                path,
                format!("trace '{}': times must be finite and in order", t.label),
            ));
        }
    }
    let times = || traces.iter().flat_map(|t| t.samples.iter().map(|s| s.0));
    let t_start = times().fold(f64::INFINITY, f64::min);
    let last = times().fold(f64::NEG_INFINITY, f64::max);
    let mut steps: Vec<f64> = traces
        .iter()
        .flat_map(|t| t.samples.windows(2).map(|w| w[1].0 - w[0].0))
        .filter(|d| *d > 0.0)
        .collect();
    steps.sort_by(f64::total_cmp);
    let step = steps.get(steps.len() / 2).copied().unwrap_or(1.0);
    let t_end = last + step;
    let n = traces.len();
    render_png(path, size, true, None, |root| {
        root.fill(&WHITE)?;
        let area = root.margin(s(8), 0, 0, 0).titled(title, bold(TITLE_PX))?;
        let (legend, body) = area.split_vertically(s(40));
        let mut x = si(80);
        for state in [
            CorrespondenceState::Unknown,
            CorrespondenceState::Pending,
            CorrespondenceState::Accepted,
        ] {
            let square = [(x, si(10)), (x + si(28), si(30))];
            legend.draw(&Rectangle::new(square, state_colour(state).filled()))?;
            legend.draw(&Rectangle::new(square, RGBColor(120, 120, 120).stroke_width(s(1))))?;
            legend.draw_text(state.name(), &font(LABEL_PX), (x + si(36), si(16)))?;
            x += si(170);
        }
        let label_w = traces
            .iter()
            .map(|t| {
                root.estimate_text_size(&t.label, &font(TICK_PX + 1.0))
                    .map(|size| size.0)
                    .unwrap_or(s(100))
            })
            .max()
            .unwrap_or(s(60))
            + s(24);
        let mut chart = ChartBuilder::on(&body)
            .margin(s(14))
            .x_label_area_size(s(46))
            .y_label_area_size(label_w)
            .build_cartesian_2d(t_start..t_end, 0.0..n as f64)?;
        chart
            .configure_mesh()
            .axis_style(RGBColor(70, 70, 70).stroke_width(s(1)))
            .set_all_tick_mark_size(s(4))
            .disable_y_mesh()
            .disable_y_axis()
            .light_line_style(RGBColor(245, 245, 245))
            .bold_line_style(RGBColor(225, 225, 225))
            .x_desc("time (s)")
            .label_style(font(TICK_PX))
            .axis_desc_style(font(LABEL_PX))
            .draw()?;
        for (row, trace) in traces.iter().enumerate() {
            // Row 0 at the top, as a list reads.
            let y_top = (n - row) as f64 - 0.12;
            let y_bottom = (n - row - 1) as f64 + 0.12;
            chart.draw_series(trace.samples.iter().enumerate().map(|(i, &(t, state))| {
                let next = trace.samples.get(i + 1).map(|s| s.0).unwrap_or(t_end);
                Rectangle::new([(t, y_bottom), (next, y_top)], state_colour(state).filled())
            }))?;
            let (px, py) = chart.backend_coord(&(t_start, (n - row) as f64 - 0.5));
            let style = font(TICK_PX + 1.0).pos(plotters::style::text_anchor::Pos::new(
                plotters::style::text_anchor::HPos::Right,
                plotters::style::text_anchor::VPos::Center,
            ));
            root.draw_text(&trace.label, &style, (px - si(10), py))?;
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equal_aspect_gives_metres_the_same_pixels_both_ways() {
        let ((x0, x1), (y0, y1)) = equal_aspect((0.0, 10.0), (0.0, 2.0), (500, 400));
        assert!(((x1 - x0) / 500.0 - (y1 - y0) / 400.0).abs() < 1e-12);
        assert!(x0 <= 0.0 && x1 >= 10.0 && y0 <= 0.0 && y1 >= 2.0);
        assert!((x1 - x0 - 10.0).abs() < 1e-12, "the wider extent is kept");
    }

    #[test]
    fn colour_map_runs_dark_to_light_and_clamps() {
        let lum = |c: RGBColor| 0.3 * c.0 as f64 + 0.59 * c.1 as f64 + 0.11 * c.2 as f64;
        let steps: Vec<f64> = (0..=10).map(|k| lum(error_colour(k as f64 / 10.0))).collect();
        assert!(steps.windows(2).all(|w| w[1] > w[0]), "{steps:?}");
        assert_eq!(error_colour(-1.0), error_colour(0.0));
        assert_eq!(error_colour(f64::INFINITY), error_colour(1.0));
        assert_eq!(error_colour(0.0), RGBColor(13, 8, 135));
    }

    #[test]
    fn gaps_split_a_series() {
        let pts: Vec<(f64, f64)> = [0.0, 0.1, 0.2, 0.3, 2.0, 2.1].iter().map(|&t| (t, 1.0)).collect();
        let runs = split_at_gaps(&pts);
        assert_eq!(runs.iter().map(Vec::len).collect::<Vec<_>>(), vec![4, 2]);
        assert!(split_at_gaps(&[]).iter().all(Vec::is_empty));
    }
}
