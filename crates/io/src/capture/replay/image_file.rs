//! One image file of a recording, read and decoded: the formats a recording may hold
//! (docs/interfaces.md, "Recording"), told apart by their first bytes.
//!
//! In: a path inside the recording and scratch buffers sized at open. Out: the file's bytes
//! ([`read_file`]: only a regular file inside the recording; [`read_file_or_ppm`]: a binary
//! PPM of the sensor's size straight into its image), its header ([`Encoded::open`]:
//! PNG, QOI or binary PPM/PGM) and its pixels as RGB8 ([`Encoded::decode_rgb`]) or as stored
//! ([`Encoded::read_native`]), or the [`Problem`] a warning names. The QOI and PPM/PGM paths
//! allocate nothing; the PNG decoder allocates inside the `image` crate (module doc of `replay`).

use image::codecs::png::PngDecoder;
use image::{ColorType, ImageDecoder, ImageError, Limits};
use omnitrack_core::frame::{ImageFault, SensorImage};
use std::fmt;
use std::fs::File;
use std::io::{self, Cursor, Read};
use std::path::Path;

/// Most memory the PNG decoder may use for one image's metadata chunks (guards against a corrupt
/// header asking for gigabytes).
const DECODER_MAX_ALLOC: u64 = 64 << 20;

/// What went wrong with one image, for the warning line.
#[derive(Debug)]
pub(super) enum Problem {
    Io(io::Error),
    /// A symbolic link to a file outside the recording.
    Outside,
    /// A FIFO, a device or a directory.
    NotAFile,
    /// Larger than any image of the sensor's size can be (bytes).
    TooLarge(u64),
    /// Neither a PNG, a QOI nor a binary PPM/PGM (by its first bytes).
    UnknownFormat,
    Decode(ImageError),
    Qoi(qoi::Error),
    /// A PPM or PGM header that cannot be read, or data shorter than it says.
    Pnm(&'static str),
    Size {
        found: (u32, u32),
        expected: (u32, u32),
    },
    Format(ColorType),
    /// A device frame that does not hold the sensor's crop window.
    Window {
        found: (u32, u32),
        crop: [u32; 4],
    },
}

impl fmt::Display for Problem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Problem::Io(e) if e.kind() == io::ErrorKind::NotFound => f.write_str("file not found"),
            Problem::Io(e) => write!(f, "cannot read: {e}"),
            Problem::Outside => f.write_str("a path that leads outside the recording through a link, not followed"),
            Problem::NotAFile => f.write_str("not a regular file"),
            Problem::TooLarge(n) => write!(f, "{n} bytes, more than an image of the sensor's size can be"),
            Problem::UnknownFormat => f.write_str("not a PNG, QOI or binary PPM/PGM image (by its first bytes)"),
            Problem::Decode(e) => write!(f, "not a valid PNG: {e}"),
            Problem::Qoi(e) => write!(f, "not a valid QOI image: {e}"),
            Problem::Pnm(e) => write!(f, "not a valid binary PPM/PGM image: {e}"),
            Problem::Size { found, expected } => {
                write!(
                    f,
                    "image is {}x{}, sensor is {}x{}",
                    found.0, found.1, expected.0, expected.1
                )
            }
            Problem::Window { found, crop } => write!(
                f,
                "image is {}x{}: neither the sensor's own image nor a device frame holding its crop {crop:?}",
                found.0, found.1
            ),
            Problem::Format(c) => write!(
                f,
                "pixel format {c:?} cannot be used (8-bit RGB, RGBA or grey expected)"
            ),
        }
    }
}

/// An image file read into memory, its header parsed: the formats a recording may hold
/// (docs/interfaces.md, "Recording"). It lives on the stack for one image: boxing the PNG
/// decoder to even the variants out would cost an allocation per image instead.
#[allow(clippy::large_enum_variant)]
pub(super) enum Encoded<'a> {
    Png(PngDecoder<Cursor<&'a [u8]>>),
    /// QOI (the Quite OK Image format): its header, and the whole file for the decoder.
    Qoi(qoi::Header, &'a [u8]),
    /// Binary PPM (`P6`, RGB) or PGM (`P5`, grey) of maximum value 255: raw 8-bit pixels.
    Pnm {
        width: u32,
        height: u32,
        channels: usize,
        data: &'a [u8],
    },
}

impl<'a> Encoded<'a> {
    /// The image in `bytes`, its format told by its first bytes.
    pub(super) fn open(bytes: &'a [u8]) -> Result<Encoded<'a>, (ImageFault, Problem)> {
        let corrupt = |p| (ImageFault::Corrupt, p);
        if bytes.starts_with(b"\x89PNG") {
            let mut limits = Limits::default();
            limits.max_alloc = Some(DECODER_MAX_ALLOC);
            return PngDecoder::with_limits(Cursor::new(bytes), limits)
                .map(Encoded::Png)
                .map_err(|e| corrupt(Problem::Decode(e)));
        }
        if bytes.starts_with(b"qoif") {
            let header = qoi::decode_header(bytes).map_err(|e| corrupt(Problem::Qoi(e)))?;
            return Ok(Encoded::Qoi(header, bytes));
        }
        if bytes.starts_with(b"P6") || bytes.starts_with(b"P5") {
            let channels = if bytes[1] == b'6' { 3 } else { 1 };
            let (width, height, data) = pnm_header(bytes).map_err(|e| corrupt(Problem::Pnm(e)))?;
            let need = width as usize * height as usize * channels;
            if data.len() < need {
                return Err(corrupt(Problem::Pnm("fewer pixels than its header says")));
            }
            return Ok(Encoded::Pnm {
                width,
                height,
                channels,
                data: &data[..need],
            });
        }
        Err(corrupt(Problem::UnknownFormat))
    }

    pub(super) fn dimensions(&self) -> (u32, u32) {
        match self {
            Encoded::Png(d) => d.dimensions(),
            Encoded::Qoi(h, _) => (h.width, h.height),
            Encoded::Pnm { width, height, .. } => (*width, *height),
        }
    }

    /// Bytes per pixel as stored (1 grey, 2 grey + alpha, 3 RGB, 4 RGBA).
    pub(super) fn channels(&self) -> Result<usize, (ImageFault, Problem)> {
        match self {
            Encoded::Png(d) => match d.color_type() {
                ColorType::L8 => Ok(1),
                ColorType::La8 => Ok(2),
                ColorType::Rgb8 => Ok(3),
                ColorType::Rgba8 => Ok(4),
                other => Err((ImageFault::WrongFormat, Problem::Format(other))),
            },
            Encoded::Qoi(h, _) => Ok(h.channels.as_u8() as usize),
            Encoded::Pnm { channels, .. } => Ok(*channels),
        }
    }

    /// Decodes the pixels as stored into `out` (exactly width × height × channels bytes).
    pub(super) fn read_native(self, out: &mut [u8]) -> Result<(), (ImageFault, Problem)> {
        match self {
            Encoded::Png(d) => d.read_image(out).map_err(|e| (ImageFault::Corrupt, Problem::Decode(e))),
            Encoded::Qoi(_, bytes) => qoi::Decoder::new(bytes)
                .and_then(|mut d| d.decode_to_buf(out))
                .map(|_| ())
                .map_err(|e| (ImageFault::Corrupt, Problem::Qoi(e))),
            Encoded::Pnm { data, .. } => {
                out.copy_from_slice(data);
                Ok(())
            }
        }
    }

    /// Decodes an image of `img`'s size into its buffer as RGB8 (`rgba`: scratch space for a
    /// four-channel PNG).
    pub(super) fn decode_rgb(self, rgba: &mut [u8], img: &mut SensorImage) -> Result<(), (ImageFault, Problem)> {
        let n = img.width() as usize * img.height() as usize;
        let pixels = img.pixels_mut();
        match self {
            Encoded::Png(d) => decode_png_rgb(d, rgba, pixels, n),
            // QOI's decoder writes RGB whatever the file holds (alpha dropped).
            Encoded::Qoi(_, bytes) => qoi::Decoder::new(bytes)
                .map(|d| d.with_channels(qoi::Channels::Rgb))
                .and_then(|mut d| d.decode_to_buf(pixels))
                .map(|_| ())
                .map_err(|e| (ImageFault::Corrupt, Problem::Qoi(e))),
            Encoded::Pnm { channels: 3, data, .. } => {
                pixels.copy_from_slice(data);
                Ok(())
            }
            Encoded::Pnm { data, .. } => {
                for (dst, &g) in pixels.chunks_exact_mut(3).zip(data) {
                    dst.fill(g);
                }
                Ok(())
            }
        }
    }
}

/// The width, height and pixel data of a binary PPM/PGM (`P6`/`P5`, netpbm's layout: the magic,
/// then width, height and maximum value as decimal numbers separated by white space, comments
/// from `#` to the end of a line allowed between them, then one white-space byte and the
/// pixels). Only 8-bit files (maximum value 255) are taken.
fn pnm_header(bytes: &[u8]) -> Result<(u32, u32, &[u8]), &'static str> {
    let mut at = 2;
    let mut field = || -> Result<u32, &'static str> {
        loop {
            match bytes.get(at) {
                Some(b' ' | b'\t' | b'\n' | b'\r' | 0x0b | 0x0c) => at += 1,
                Some(b'#') => {
                    while bytes.get(at).is_some_and(|&b| b != b'\n') {
                        at += 1;
                    }
                }
                Some(b'0'..=b'9') => break,
                _ => return Err("header ends before width, height and maximum value"),
            }
        }
        let mut v: u32 = 0;
        while let Some(&b @ b'0'..=b'9') = bytes.get(at) {
            v = v
                .checked_mul(10)
                .and_then(|v| v.checked_add(u32::from(b - b'0')))
                .ok_or("a header number too large")?;
            at += 1;
        }
        Ok(v)
    };
    let (width, height, max) = (field()?, field()?, field()?);
    if width == 0 || height == 0 {
        return Err("zero width or height");
    }
    if max != 255 {
        return Err("not 8-bit (maximum value other than 255)");
    }
    match bytes.get(at) {
        Some(b' ' | b'\t' | b'\n' | b'\r') => Ok((width, height, &bytes[at + 1..])),
        _ => Err("no white space between the header and the pixels"),
    }
}

/// Reads the regular file at `path` (inside `root`, at most `most` bytes) into `file_buf`.
pub(super) fn read_file(
    path: &Path,
    root: &Path,
    file_buf: &mut Vec<u8>,
    most: u64,
) -> Result<(), (ImageFault, Problem)> {
    file_buf.clear();
    open_checked(path, root, most)?
        .take(most)
        .read_to_end(file_buf)
        .map_err(|e| (ImageFault::Missing, Problem::Io(e)))?;
    Ok(())
}

/// Opens the regular file at `path` if it lies inside `root` and holds at most `most` bytes.
fn open_checked(path: &Path, root: &Path, most: u64) -> Result<File, (ImageFault, Problem)> {
    let missing = |e| (ImageFault::Missing, Problem::Io(e));
    // Only a regular file inside the recording. Every link on the path is resolved first (a
    // folder of the recording linked to /etc leads out as surely as a linked file does), and
    // what is opened is the resolved path that was checked. A FIFO (which would block the read)
    // or a device (/dev/zero, which never ends) is refused before it is opened.
    let real = std::fs::canonicalize(path).map_err(missing)?;
    if !real.starts_with(root) {
        return Err((ImageFault::Missing, Problem::Outside));
    }
    let meta = std::fs::metadata(&real).map_err(missing)?;
    if !meta.is_file() {
        return Err((ImageFault::Missing, Problem::NotAFile));
    }
    if meta.len() > most {
        return Err((ImageFault::Corrupt, Problem::TooLarge(meta.len())));
    }
    File::open(&real).map_err(missing)
}

/// Bytes of a file read before its format is known: a binary PPM's header (magic, three numbers
/// and comments) fits with room to spare.
const HEADER_PEEK: u64 = 4096;

/// Reads the file at `path` (checked as [`read_file`] does) into `file_buf`, except that a
/// binary RGB PPM of `img`'s size goes straight into `img`'s pixels: its header is read, then
/// its pixels, with no copy through `file_buf`. The copy cost a replay of six 512×384 images a
/// frame as much CPU as reading the files (perf, `lab` lossless). Returns whether `img` was
/// filled; if not, `file_buf` holds the whole file, for [`Encoded::open`].
pub(super) fn read_file_or_ppm(
    path: &Path,
    root: &Path,
    file_buf: &mut Vec<u8>,
    most: u64,
    img: &mut SensorImage,
) -> Result<bool, (ImageFault, Problem)> {
    let missing = |e| (ImageFault::Missing, Problem::Io(e));
    file_buf.clear();
    let mut file = open_checked(path, root, most)?;
    (&mut file)
        .take(HEADER_PEEK.min(most))
        .read_to_end(file_buf)
        .map_err(missing)?;
    let pixels_at = match pnm_header(file_buf) {
        Ok((w, h, data)) if file_buf.starts_with(b"P6") && (w, h) == (img.width(), img.height()) => {
            file_buf.len() - data.len()
        }
        // Anything else (another format, size or kind of PNM, a header longer than the peek,
        // a damaged one) is read whole and judged by `Encoded::open` as before.
        _ => {
            let rest = most.saturating_sub(file_buf.len() as u64);
            file.take(rest).read_to_end(file_buf).map_err(missing)?;
            return Ok(false);
        }
    };
    let pixels = img.pixels_mut();
    let have = (file_buf.len() - pixels_at).min(pixels.len());
    pixels[..have].copy_from_slice(&file_buf[pixels_at..pixels_at + have]);
    match file.read_exact(&mut pixels[have..]) {
        Ok(()) => Ok(true),
        Err(e) if e.kind() == io::ErrorKind::UnexpectedEof => {
            Err((ImageFault::Corrupt, Problem::Pnm("fewer pixels than its header says")))
        }
        Err(e) => Err(missing(e)),
    }
}

/// Decodes a PNG of `n` pixels into `pixels` as RGB8 (grey, grey + alpha and RGBA converted).
fn decode_png_rgb(
    decoder: PngDecoder<Cursor<&[u8]>>,
    rgba: &mut [u8],
    pixels: &mut [u8],
    n: usize,
) -> Result<(), (ImageFault, Problem)> {
    let corrupt = |e: ImageError| (ImageFault::Corrupt, Problem::Decode(e));
    match decoder.color_type() {
        ColorType::Rgb8 => decoder.read_image(pixels).map_err(corrupt),
        ColorType::L8 => {
            decoder.read_image(&mut pixels[..n]).map_err(corrupt)?;
            // Expand in place from the back: pixel i's source byte (i) is never overwritten before
            // it is read, since writes for pixels ≥ i land at 3i.. ≥ i.
            for i in (0..n).rev() {
                let g = pixels[i];
                pixels[3 * i..3 * i + 3].fill(g);
            }
            Ok(())
        }
        ColorType::La8 => {
            decoder.read_image(&mut pixels[..2 * n]).map_err(corrupt)?;
            // Same in-place expansion: pixel i reads 2i, writes 3i..3i+3 (≥ 2i + 1 for i ≥ 1).
            for i in (0..n).rev() {
                let g = pixels[2 * i];
                pixels[3 * i..3 * i + 3].fill(g);
            }
            Ok(())
        }
        ColorType::Rgba8 => {
            let src = &mut rgba[..4 * n];
            decoder.read_image(src).map_err(corrupt)?;
            for (dst, src) in pixels.chunks_exact_mut(3).zip(src.chunks_exact(4)) {
                dst.copy_from_slice(&src[..3]);
            }
            Ok(())
        }
        other => Err((ImageFault::WrongFormat, Problem::Format(other))),
    }
}
