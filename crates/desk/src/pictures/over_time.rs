//! Pictures against time: per-pose errors in, [`error_over_time`] out (position and rotation
//! error, one line per trace); traces of correspondence states in, [`correspondence_states`] out
//! (Koch–Teller Figure 14).

use super::canvas::{bold, font, render_png, s, si, LABEL_PX, TICK_PX, TITLE_PX};
use super::{picture_error, PictureError};
use crate::eval::PoseError;
use omnitrack_tracker::CorrespondenceState;
use plotters::prelude::*;
use std::path::Path;

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
    fn gaps_split_a_series() {
        let pts: Vec<(f64, f64)> = [0.0, 0.1, 0.2, 0.3, 2.0, 2.1].iter().map(|&t| (t, 1.0)).collect();
        let runs = split_at_gaps(&pts);
        assert_eq!(runs.iter().map(Vec::len).collect::<Vec<_>>(), vec![4, 2]);
        assert!(split_at_gaps(&[]).iter().all(Vec::is_empty));
    }
}
