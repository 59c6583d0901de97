//! Pixel conversions from what cameras deliver into the pipeline's RGB8 buffers.
//!
//! In: one camera image as raw bytes — packed RGB or BGR, 8-bit grey, YUV 4:2:2 (YUYV or UYVY
//! byte order, BT.601 limited or full range), 8-bit Bayer mosaics (RGGB, GRBG, GBRG, BGGR), or a
//! JPEG (MJPEG) frame — with its width, height and row stride (bytes from one row to the next,
//! at least the packed row size; drivers and cameras pad rows).
//! Out: the image written into a caller-owned RGB8 buffer of exactly `width * height * 3` bytes
//! (a [`SensorImage`](omnitrack_core::frame::SensorImage)'s pixels), row-major, no padding.
//!
//! These are pure functions, compiled with every feature set so that they are always tested; the
//! live sources (`v4l2` behind the cargo feature `v4l`, `usb` behind `usb`, and the
//! [`u3v`](super::u3v) parser) only choose which one to call. None panics on bad input: a buffer
//! too short for the stated size, a stride smaller than a row, an odd width for 4:2:2, an output
//! buffer of the wrong length, or an undecodable JPEG is a [`ConvertError`], which names the
//! [`ImageFault`] a source records for the sensor.
//!
//! Colour: YUV uses the BT.601 matrix in integer arithmetic (8 fractional bits, rounded),
//! [`YuvRange::Limited`] for video-range data (Y 16..235, what V4L2's YUYV usually is) and
//! [`YuvRange::Full`] for JPEG-style full range. Bayer mosaics are demosaiced bilinearly
//! (each missing colour is the mean of the 2 or 4 nearest samples of that colour), with the image
//! mirrored at its borders so that edge pixels have the same neighbours' colours; a uniform
//! colour and any linear ramp are reproduced exactly away from rounding.
//!
//! Allocation: none, except inside the `image` crate's JPEG decoder, which copies the compressed
//! frame into a buffer of its own and allocates its decoding state per frame (it offers no reuse).

use image::codecs::jpeg::JpegDecoder;
use image::{ColorType, ImageDecoder};
use omnitrack_core::frame::ImageFault;
use std::fmt;
use std::io::Cursor;

/// Why an image could not be converted. Small and `Copy`: no message is built per frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ConvertError {
    /// Width or height is zero (or too small for the format: Bayer needs 2 × 2).
    BadSize { width: u32, height: u32 },
    /// The output buffer is not `width * height * 3` bytes.
    OutputSize { expected: usize, found: usize },
    /// The row stride is smaller than one packed row.
    Stride { stride: usize, row_bytes: usize },
    /// The source has fewer bytes than `stride * (height - 1) + row_bytes`.
    Truncated { needed: usize, found: usize },
    /// YUV 4:2:2 needs an even width (two pixels share one U and one V).
    OddWidth { width: u32 },
    /// The JPEG data cannot be decoded.
    JpegCorrupt,
    /// The JPEG decodes to another size than the sensor's.
    JpegSize { width: u32, height: u32 },
    /// The JPEG has a colour type other than RGB or grey (e.g. CMYK, with alpha).
    JpegColour,
}

impl ConvertError {
    /// The fault a source records for the sensor when this happens.
    pub fn fault(&self) -> ImageFault {
        match self {
            ConvertError::Truncated { .. } | ConvertError::JpegCorrupt => ImageFault::Corrupt,
            ConvertError::BadSize { .. } | ConvertError::OutputSize { .. } | ConvertError::JpegSize { .. } => {
                ImageFault::WrongSize
            }
            ConvertError::Stride { .. } | ConvertError::OddWidth { .. } | ConvertError::JpegColour => {
                ImageFault::WrongFormat
            }
        }
    }
}

impl fmt::Display for ConvertError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ConvertError::BadSize { width, height } => write!(f, "image size {width}x{height} is too small"),
            ConvertError::OutputSize { expected, found } => {
                write!(f, "output buffer has {found} bytes, expected {expected}")
            }
            ConvertError::Stride { stride, row_bytes } => {
                write!(f, "row stride {stride} is smaller than a row of {row_bytes} bytes")
            }
            ConvertError::Truncated { needed, found } => write!(f, "image data has {found} bytes, needs {needed}"),
            ConvertError::OddWidth { width } => write!(f, "YUV 4:2:2 needs an even width, found {width}"),
            ConvertError::JpegCorrupt => f.write_str("JPEG frame cannot be decoded"),
            ConvertError::JpegSize { width, height } => write!(f, "JPEG frame is {width}x{height}"),
            ConvertError::JpegColour => f.write_str("JPEG frame is neither RGB nor grey"),
        }
    }
}

impl std::error::Error for ConvertError {}

/// The colour of the top-left 2 × 2 cell of a Bayer mosaic, row by row (`Rggb`: R G / G B).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BayerPattern {
    Rggb,
    Grbg,
    Gbrg,
    Bggr,
}

impl BayerPattern {
    /// Column and row parity of the red sample in each 2 × 2 cell (blue is at the other corner).
    fn red_at(self) -> (usize, usize) {
        match self {
            BayerPattern::Rggb => (0, 0),
            BayerPattern::Grbg => (1, 0),
            BayerPattern::Gbrg => (0, 1),
            BayerPattern::Bggr => (1, 1),
        }
    }
}

/// Byte order of packed YUV 4:2:2: two pixels in four bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum YuvOrder {
    /// Y0 U Y1 V (V4L2 `YUYV`, PFNC `YUV422_8`, `YCbCr422_8`).
    Yuyv,
    /// U Y0 V Y1 (V4L2 `UYVY`, PFNC `YUV422_8_UYVY`, `YCbCr422_8_CbYCrY`).
    Uyvy,
}

/// Value range of YUV data (both BT.601).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum YuvRange {
    /// Video range: Y 16..=235, U and V 16..=240.
    Limited,
    /// Full range: Y, U and V 0..=255 (JPEG / JFIF).
    Full,
}

/// Checks sizes shared by every raw format; returns the packed row size.
fn check(
    src: &[u8],
    width: u32,
    height: u32,
    stride: usize,
    bytes_per_pixel: usize,
    out: &[u8],
) -> Result<usize, ConvertError> {
    if width == 0 || height == 0 {
        return Err(ConvertError::BadSize { width, height });
    }
    let expected = width as usize * height as usize * 3;
    if out.len() != expected {
        return Err(ConvertError::OutputSize {
            expected,
            found: out.len(),
        });
    }
    let row_bytes = width as usize * bytes_per_pixel;
    if stride < row_bytes {
        return Err(ConvertError::Stride { stride, row_bytes });
    }
    let needed = stride * (height as usize - 1) + row_bytes;
    if src.len() < needed {
        return Err(ConvertError::Truncated {
            needed,
            found: src.len(),
        });
    }
    Ok(row_bytes)
}

/// Rows of the source (each `row_bytes` long) paired with rows of the output.
fn rows<'a>(
    src: &'a [u8],
    stride: usize,
    row_bytes: usize,
    out: &'a mut [u8],
    width: u32,
) -> impl Iterator<Item = (&'a [u8], &'a mut [u8])> {
    out.chunks_exact_mut(width as usize * 3)
        .enumerate()
        .map(move |(y, o)| (&src[y * stride..y * stride + row_bytes], o))
}

/// Packed RGB8 (V4L2 `RGB3`, PFNC `RGB8`) with row stride into `out`.
pub fn rgb_to_rgb(src: &[u8], width: u32, height: u32, stride: usize, out: &mut [u8]) -> Result<(), ConvertError> {
    let row_bytes = check(src, width, height, stride, 3, out)?;
    for (s, o) in rows(src, stride, row_bytes, out, width) {
        o.copy_from_slice(s);
    }
    Ok(())
}

/// Packed BGR8 (V4L2 `BGR3`, PFNC `BGR8`) with row stride into RGB8 `out`.
pub fn bgr_to_rgb(src: &[u8], width: u32, height: u32, stride: usize, out: &mut [u8]) -> Result<(), ConvertError> {
    let row_bytes = check(src, width, height, stride, 3, out)?;
    for (s, o) in rows(src, stride, row_bytes, out, width) {
        for (sp, op) in s.chunks_exact(3).zip(o.chunks_exact_mut(3)) {
            op[0] = sp[2];
            op[1] = sp[1];
            op[2] = sp[0];
        }
    }
    Ok(())
}

/// 8-bit grey (V4L2 `GREY`, PFNC `Mono8`) into RGB8 `out` (R = G = B).
pub fn grey_to_rgb(src: &[u8], width: u32, height: u32, stride: usize, out: &mut [u8]) -> Result<(), ConvertError> {
    let row_bytes = check(src, width, height, stride, 1, out)?;
    for (s, o) in rows(src, stride, row_bytes, out, width) {
        for (&g, op) in s.iter().zip(o.chunks_exact_mut(3)) {
            op.fill(g);
        }
    }
    Ok(())
}

#[inline]
fn clamp_u8(v: i32) -> u8 {
    v.clamp(0, 255) as u8
}

/// One YUV sample to RGB, BT.601, 8 fractional bits.
#[inline]
fn yuv_pixel(y: u8, u: u8, v: u8, range: YuvRange) -> [u8; 3] {
    let d = u as i32 - 128;
    let e = v as i32 - 128;
    match range {
        YuvRange::Limited => {
            let c = 298 * (y as i32 - 16) + 128;
            [
                clamp_u8((c + 409 * e) >> 8),
                clamp_u8((c - 100 * d - 208 * e) >> 8),
                clamp_u8((c + 516 * d) >> 8),
            ]
        }
        YuvRange::Full => {
            let c = 256 * y as i32 + 128;
            [
                clamp_u8((c + 359 * e) >> 8),
                clamp_u8((c - 88 * d - 183 * e) >> 8),
                clamp_u8((c + 454 * d) >> 8),
            ]
        }
    }
}

/// Packed YUV 4:2:2 (V4L2 `YUYV` / `UYVY`, PFNC `YUV422_8` and kin) into RGB8 `out`.
pub fn yuv422_to_rgb(
    src: &[u8],
    width: u32,
    height: u32,
    stride: usize,
    order: YuvOrder,
    range: YuvRange,
    out: &mut [u8],
) -> Result<(), ConvertError> {
    let row_bytes = check(src, width, height, stride, 2, out)?;
    if width % 2 != 0 {
        return Err(ConvertError::OddWidth { width });
    }
    for (s, o) in rows(src, stride, row_bytes, out, width) {
        for (q, op) in s.chunks_exact(4).zip(o.chunks_exact_mut(6)) {
            let (y0, u, y1, v) = match order {
                YuvOrder::Yuyv => (q[0], q[1], q[2], q[3]),
                YuvOrder::Uyvy => (q[1], q[0], q[3], q[2]),
            };
            op[..3].copy_from_slice(&yuv_pixel(y0, u, v, range));
            op[3..].copy_from_slice(&yuv_pixel(y1, u, v, range));
        }
    }
    Ok(())
}

/// 8-bit Bayer mosaic (V4L2 `RGGB`, `GRBG`, `GBRG`, `BA81`; PFNC `BayerRG8` and kin) into RGB8
/// `out`, bilinear. Needs at least 2 × 2 pixels.
pub fn bayer_to_rgb(
    src: &[u8],
    width: u32,
    height: u32,
    stride: usize,
    pattern: BayerPattern,
    out: &mut [u8],
) -> Result<(), ConvertError> {
    check(src, width, height, stride, 1, out)?;
    if width < 2 || height < 2 {
        return Err(ConvertError::BadSize { width, height });
    }
    let (w, h) = (width as usize, height as usize);
    let (rx, ry) = pattern.red_at();
    // Mirrored neighbour index: the mirror keeps the parity of the neighbour, so its colour.
    let prev = |i: usize| if i == 0 { 1 } else { i - 1 };
    let next = |i: usize, n: usize| if i + 1 == n { n - 2 } else { i + 1 };
    let avg2 = |a: u8, b: u8| (a as u16 + b as u16).div_ceil(2) as u8;
    let avg4 = |a: u8, b: u8, c: u8, d: u8| ((a as u16 + b as u16 + c as u16 + d as u16 + 2) / 4) as u8;
    for (y, o) in out.chunks_exact_mut(w * 3).enumerate() {
        let up = &src[prev(y) * stride..][..w];
        let row = &src[y * stride..][..w];
        let down = &src[next(y, h) * stride..][..w];
        let py = y & 1;
        for (x, op) in o.chunks_exact_mut(3).enumerate() {
            let (xm, xp) = (prev(x), next(x, w));
            let c = row[x];
            let px = x & 1;
            let cross = || avg4(row[xm], row[xp], up[x], down[x]);
            let diag = || avg4(up[xm], up[xp], down[xm], down[xp]);
            let horiz = || avg2(row[xm], row[xp]);
            let vert = || avg2(up[x], down[x]);
            let rgb = if (px, py) == (rx, ry) {
                [c, cross(), diag()]
            } else if (px, py) == (1 - rx, 1 - ry) {
                [diag(), cross(), c]
            } else if py == ry {
                // Green on a red row: red left and right, blue above and below.
                [horiz(), c, vert()]
            } else {
                [vert(), c, horiz()]
            };
            op.copy_from_slice(&rgb);
        }
    }
    Ok(())
}

/// One JPEG frame (V4L2 `MJPG`; UVC frames without Huffman tables get the standard ones) into
/// RGB8 `out`; it must decode to exactly `width × height`. Grey JPEGs are expanded to RGB.
pub fn jpeg_to_rgb(src: &[u8], width: u32, height: u32, out: &mut [u8]) -> Result<(), ConvertError> {
    if width == 0 || height == 0 {
        return Err(ConvertError::BadSize { width, height });
    }
    let expected = width as usize * height as usize * 3;
    if out.len() != expected {
        return Err(ConvertError::OutputSize {
            expected,
            found: out.len(),
        });
    }
    let decoder = JpegDecoder::new(Cursor::new(src)).map_err(|_| ConvertError::JpegCorrupt)?;
    let (w, h) = decoder.dimensions();
    if (w, h) != (width, height) {
        return Err(ConvertError::JpegSize { width: w, height: h });
    }
    match decoder.color_type() {
        ColorType::Rgb8 => decoder.read_image(out).map_err(|_| ConvertError::JpegCorrupt),
        ColorType::L8 => {
            let n = w as usize * h as usize;
            decoder
                .read_image(&mut out[..n])
                .map_err(|_| ConvertError::JpegCorrupt)?;
            // Expand in place from the end, so that no grey byte is overwritten before it is read.
            for i in (0..n).rev() {
                let g = out[i];
                out[3 * i..3 * i + 3].fill(g);
            }
            Ok(())
        }
        _ => Err(ConvertError::JpegColour),
    }
}
