//! [`plan_view`]: trajectories and their position errors in, a PNG of ground truth beside the
//! estimate over the model's floor plan out (Koch–Teller Figures 1, 10, 11).

use super::canvas::{bold, error_colour, font, render_png, s, si, Area, DrawResult, LABEL_PX, TICK_PX, TITLE_PX};
use super::{picture_error, PictureError};
use omnitrack_core::trajectory::Stamped;
use omnitrack_core::Model;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use std::path::Path;

const PLAN_GREY: RGBColor = RGBColor(190, 190, 190);
const GT_COLOUR: RGBColor = RGBColor(30, 30, 30);
const UNMATCHED: RGBColor = RGBColor(150, 150, 150);

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
}
