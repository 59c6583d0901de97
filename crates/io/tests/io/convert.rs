//! The pixel conversions of the live sources, on images built here.

use image::codecs::jpeg::JpegEncoder;
use image::ExtendedColorType;
use omnitrack_core::frame::ImageFault;
use omnitrack_io::capture::convert::{
    bayer_to_rgb, bgr_to_rgb, grey_to_rgb, jpeg_to_rgb, rgb_to_rgb, yuv422_to_rgb, BayerPattern, ConvertError,
    YuvOrder, YuvRange,
};

fn out(w: u32, h: u32) -> Vec<u8> {
    vec![0u8; (w * h * 3) as usize]
}

#[test]
fn rgb_and_bgr_copy_rows_and_skip_stride_padding() {
    let (w, h, stride) = (3u32, 2u32, 11usize);
    let mut src = vec![0xEEu8; stride * 2];
    for y in 0..2 {
        for i in 0..9 {
            src[y * stride + i] = (y * 9 + i) as u8;
        }
    }
    let mut o = out(w, h);
    rgb_to_rgb(&src, w, h, stride, &mut o).unwrap();
    assert_eq!(o, (0..18).collect::<Vec<u8>>());
    bgr_to_rgb(&src, w, h, stride, &mut o).unwrap();
    assert_eq!(&o[..6], &[2, 1, 0, 5, 4, 3]);
    assert_eq!(&o[9..12], &[11, 10, 9]);
    // The last row needs only its packed bytes, not the whole stride.
    rgb_to_rgb(&src[..stride + 9], w, h, stride, &mut o).unwrap();
}

#[test]
fn grey_is_replicated() {
    let src = [0u8, 100, 255, 7];
    let mut o = out(2, 2);
    grey_to_rgb(&src, 2, 2, 2, &mut o).unwrap();
    assert_eq!(o, vec![0, 0, 0, 100, 100, 100, 255, 255, 255, 7, 7, 7]);
}

fn yuv_one(y: u8, u: u8, v: u8, range: YuvRange) -> [u8; 3] {
    let src = [y, u, y, v];
    let mut o = out(2, 1);
    yuv422_to_rgb(&src, 2, 1, 4, YuvOrder::Yuyv, range, &mut o).unwrap();
    assert_eq!(o[..3], o[3..], "both pixels of a pair share U and V");
    [o[0], o[1], o[2]]
}

fn close(a: [u8; 3], b: [u8; 3], tol: i32) -> bool {
    a.iter().zip(&b).all(|(&x, &y)| (x as i32 - y as i32).abs() <= tol)
}

#[test]
fn yuv_bt601_limited_and_full_range() {
    assert_eq!(yuv_one(235, 128, 128, YuvRange::Limited), [255, 255, 255]);
    assert_eq!(yuv_one(16, 128, 128, YuvRange::Limited), [0, 0, 0]);
    assert_eq!(yuv_one(126, 128, 128, YuvRange::Limited), [128, 128, 128]);
    // BT.601 limited-range primaries.
    assert!(close(yuv_one(81, 90, 240, YuvRange::Limited), [255, 0, 0], 2));
    assert!(close(yuv_one(145, 54, 34, YuvRange::Limited), [0, 255, 0], 2));
    assert!(close(yuv_one(41, 240, 110, YuvRange::Limited), [0, 0, 255], 2));
    // Full range: grey is itself; JPEG's red.
    assert_eq!(yuv_one(128, 128, 128, YuvRange::Full), [128, 128, 128]);
    assert_eq!(yuv_one(0, 128, 128, YuvRange::Full), [0, 0, 0]);
    assert_eq!(yuv_one(255, 128, 128, YuvRange::Full), [255, 255, 255]);
    assert!(close(yuv_one(76, 85, 255, YuvRange::Full), [254, 0, 0], 2));
}

#[test]
fn yuv_byte_orders_and_per_pixel_luma() {
    // Two pixels of different Y, one chroma pair: YUYV and UYVY carry the same.
    let yuyv = [50u8, 128, 200, 128];
    let uyvy = [128u8, 50, 128, 200];
    let (mut a, mut b) = (out(2, 1), out(2, 1));
    yuv422_to_rgb(&yuyv, 2, 1, 4, YuvOrder::Yuyv, YuvRange::Full, &mut a).unwrap();
    yuv422_to_rgb(&uyvy, 2, 1, 4, YuvOrder::Uyvy, YuvRange::Full, &mut b).unwrap();
    assert_eq!(a, b);
    assert_eq!(a, vec![50, 50, 50, 200, 200, 200]);
}

#[test]
fn bad_inputs_are_errors_with_their_fault() {
    let mut o = out(2, 2);
    let e = yuv422_to_rgb(&[0; 12], 3, 2, 6, YuvOrder::Yuyv, YuvRange::Full, &mut out(3, 2)).unwrap_err();
    assert_eq!(e, ConvertError::OddWidth { width: 3 });
    assert_eq!(e.fault(), ImageFault::WrongFormat);
    let e = grey_to_rgb(&[0; 3], 2, 2, 2, &mut o).unwrap_err();
    assert_eq!(e, ConvertError::Truncated { needed: 4, found: 3 });
    assert_eq!(e.fault(), ImageFault::Corrupt);
    let e = grey_to_rgb(&[0; 4], 2, 2, 1, &mut o).unwrap_err();
    assert_eq!(e.fault(), ImageFault::WrongFormat);
    let e = grey_to_rgb(&[0; 4], 2, 2, 2, &mut o[..5]).unwrap_err();
    assert_eq!(e.fault(), ImageFault::WrongSize);
    let e = rgb_to_rgb(&[], 0, 2, 0, &mut []).unwrap_err();
    assert_eq!(e, ConvertError::BadSize { width: 0, height: 2 });
    let e = bayer_to_rgb(&[0; 2], 2, 1, 2, BayerPattern::Rggb, &mut out(2, 1)).unwrap_err();
    assert_eq!(e.fault(), ImageFault::WrongSize);
    // Messages are one line.
    assert!(!e.to_string().contains('\n'));
}

/// A Bayer mosaic of an RGB image: each pixel keeps the channel its filter passes.
fn mosaic(rgb: &dyn Fn(usize, usize) -> [u8; 3], w: usize, h: usize, pattern: BayerPattern) -> Vec<u8> {
    let (rx, ry) = match pattern {
        BayerPattern::Rggb => (0, 0),
        BayerPattern::Grbg => (1, 0),
        BayerPattern::Gbrg => (0, 1),
        BayerPattern::Bggr => (1, 1),
    };
    let mut m = vec![0u8; w * h];
    for y in 0..h {
        for x in 0..w {
            let c = rgb(x, y);
            let (px, py) = (x & 1, y & 1);
            m[y * w + x] = if (px, py) == (rx, ry) {
                c[0]
            } else if (px, py) == (1 - rx, 1 - ry) {
                c[2]
            } else {
                c[1]
            };
        }
    }
    m
}

const PATTERNS: [BayerPattern; 4] = [
    BayerPattern::Rggb,
    BayerPattern::Grbg,
    BayerPattern::Gbrg,
    BayerPattern::Bggr,
];

#[test]
fn bayer_uniform_colour_is_exact_everywhere_including_borders() {
    let (w, h) = (7usize, 5usize); // odd sizes: borders of both parities
    for pattern in PATTERNS {
        let m = mosaic(&|_, _| [200, 100, 50], w, h, pattern);
        let mut o = out(w as u32, h as u32);
        bayer_to_rgb(&m, w as u32, h as u32, w, pattern, &mut o).unwrap();
        assert!(o.chunks(3).all(|p| p == [200, 100, 50]), "{pattern:?}");
    }
}

#[test]
fn bayer_linear_ramps_are_exact_in_the_interior() {
    let (w, h) = (10usize, 8usize);
    let ramp = |x: usize, y: usize| {
        [
            (10 + 4 * x + 2 * y) as u8,
            (20 + 2 * x + 4 * y) as u8,
            (200 - 6 * x - 2 * y) as u8,
        ]
    };
    for pattern in PATTERNS {
        let m = mosaic(&ramp, w, h, pattern);
        // With a stride wider than the row.
        let stride = w + 3;
        let mut src = vec![0u8; stride * h];
        for y in 0..h {
            src[y * stride..y * stride + w].copy_from_slice(&m[y * w..(y + 1) * w]);
        }
        let mut o = out(w as u32, h as u32);
        bayer_to_rgb(&src, w as u32, h as u32, stride, pattern, &mut o).unwrap();
        for y in 1..h - 1 {
            for x in 1..w - 1 {
                let got = &o[(y * w + x) * 3..][..3];
                assert_eq!(got, ramp(x, y), "{pattern:?} at ({x}, {y})");
            }
        }
    }
}

fn encode_jpeg(data: &[u8], w: u32, h: u32, colour: ExtendedColorType) -> Vec<u8> {
    let mut bytes = Vec::new();
    JpegEncoder::new_with_quality(&mut bytes, 95)
        .encode(data, w, h, colour)
        .unwrap();
    bytes
}

#[test]
fn jpeg_decodes_into_the_buffer_and_checks_its_size() {
    let (w, h) = (32u32, 16u32);
    let rgb: Vec<u8> = (0..w * h)
        .flat_map(|i| {
            let (x, y) = (i % w, i / w);
            [(x * 8) as u8, (y * 16) as u8, 128]
        })
        .collect();
    let jpeg = encode_jpeg(&rgb, w, h, ExtendedColorType::Rgb8);
    let mut o = out(w, h);
    jpeg_to_rgb(&jpeg, w, h, &mut o).unwrap();
    let worst = o
        .iter()
        .zip(&rgb)
        .map(|(&a, &b)| (a as i32 - b as i32).abs())
        .max()
        .unwrap();
    assert!(worst <= 24, "largest JPEG error {worst}");

    let e = jpeg_to_rgb(&jpeg, 16, 16, &mut out(16, 16)).unwrap_err();
    assert_eq!(e, ConvertError::JpegSize { width: 32, height: 16 });
    assert_eq!(e.fault(), ImageFault::WrongSize);
    let e = jpeg_to_rgb(&jpeg[..20], w, h, &mut o).unwrap_err();
    assert_eq!(e.fault(), ImageFault::Corrupt);
    let e = jpeg_to_rgb(b"not a jpeg at all", w, h, &mut o).unwrap_err();
    assert_eq!(e, ConvertError::JpegCorrupt);
}

#[test]
fn grey_jpeg_is_expanded_to_rgb() {
    let (w, h) = (16u32, 8u32);
    let grey = vec![90u8; (w * h) as usize];
    let jpeg = encode_jpeg(&grey, w, h, ExtendedColorType::L8);
    let mut o = out(w, h);
    jpeg_to_rgb(&jpeg, w, h, &mut o).unwrap();
    assert!(o
        .chunks(3)
        .all(|p| p[0] == p[1] && p[1] == p[2] && (p[0] as i32 - 90).abs() <= 2));
}
