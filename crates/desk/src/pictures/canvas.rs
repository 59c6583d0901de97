//! The drawing machinery every picture shares: a plotters drawing closure in, a PNG file out,
//! drawn on a supersampled canvas (plotters' bitmap backend does not anti-alias) in DejaVu Sans
//! embedded from the `dejavu` crate; and the colour map errors are drawn in.

use super::{picture_error, PictureError};
use image::RgbImage;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::{register_font, FontStyle};
use std::error::Error;
use std::path::Path;
use std::sync::OnceLock;

pub(super) type DrawResult = Result<(), Box<dyn Error>>;
pub(super) type Area<'a> = DrawingArea<BitMapBackend<'a>, Shift>;

const FONT: &str = "sans-serif";
pub(super) const TITLE_PX: f64 = 26.0;
pub(super) const LABEL_PX: f64 = 18.0;
pub(super) const TICK_PX: f64 = 15.0;

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
pub(super) fn s(v: u32) -> u32 {
    v * SS
}

pub(super) fn si(v: i32) -> i32 {
    v * SS as i32
}

/// Draws on a canvas of `size`, or of `size × SS` when `supersample`, and writes it as PNG.
/// `background` (RGB8 of exactly `size`, only without supersampling) replaces the white canvas.
pub(super) fn render_png(
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
pub(super) fn font(px: f64) -> TextStyle<'static> {
    TextStyle::from((FONT, px * SS as f64).into_font())
}

pub(super) fn bold(px: f64) -> TextStyle<'static> {
    TextStyle::from((FONT, px * SS as f64, FontStyle::Bold).into_font())
}

/// Text at the canvas' own scale (for pictures drawn without supersampling).
pub(super) fn bold_1x(px: f64) -> TextStyle<'static> {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colour_map_runs_dark_to_light_and_clamps() {
        let lum = |c: RGBColor| 0.3 * c.0 as f64 + 0.59 * c.1 as f64 + 0.11 * c.2 as f64;
        let steps: Vec<f64> = (0..=10).map(|k| lum(error_colour(k as f64 / 10.0))).collect();
        assert!(steps.windows(2).all(|w| w[1] > w[0]), "{steps:?}");
        assert_eq!(error_colour(-1.0), error_colour(0.0));
        assert_eq!(error_colour(f64::INFINITY), error_colour(1.0));
        assert_eq!(error_colour(0.0), RGBColor(13, 8, 135));
    }
}
