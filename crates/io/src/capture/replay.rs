//! The mock camera: replays a recording from disk as if it came from the rig.
//!
//! In: a recording directory (docs/interfaces.md, "Recording"):
//!
//! ```text
//! REC/rig.toml             the rig the recording was made with (required)
//! REC/frames.csv           header `frame,sensor,timestamp_ns,path`; path relative to REC/ (required)
//! REC/sensorK/NNNNNN.png   8-bit RGB PNG per sensor per frame (or PPM, or QOI: below)
//! REC/groundtruth.tum      optional T_world_rig per frame
//! REC/model.obj            optional model the recording was made in
//! ```
//!
//! Out: [`FrameSet`]s in frame-number order through [`FrameSource`], paced at the recorded
//! timestamps ([`Pacing::RealTime`]) or as fast as decoding allows ([`Pacing::AsFastAsPossible`]).
//! The pacing waits before a frame is read, so that a stop
//! ([`FrameSource::next_frame_or_stop`]) cuts any gap short, a day's or `u64::MAX` ns, with no
//! frame half delivered.
//!
//! The index is checked in one pass at [`ReplaySource::open`], as a stream: a bad row (wrong field
//! count, non-numeric field, unknown sensor, duplicate (frame, sensor), empty path, not a line of
//! text) is skipped, counted in [`SourceStats::bad_rows`] and warned with its line number; what is
//! kept is a small entry per frame, and each frame's rows are read back from the file when it is
//! replayed, so a day-long index costs megabytes, not gigabytes (see `index`). A missing rig file,
//! index file or malformed index header is an `Err` naming the file.
//!
//! Per frame, each sensor's image file is read into a scratch byte buffer sized at open and
//! decoded straight into the frame set's preallocated RGB8 buffer. An image is a PNG, a binary
//! PPM/PGM (`P6`/`P5`, 8-bit: raw pixels, nothing to decode; `record`'s default) or a QOI (the
//! Quite OK Image format, lossless), told apart by its first bytes, whatever its name (grey, grey+alpha and RGBA images are converted to RGB in place or
//! through a second scratch buffer sized at open). A missing file or directory, a corrupt image,
//! an image of the wrong size or of 16-bit depth makes that sensor invalid for that frame,
//! counted and warned (the first few per kind); the stream goes on.
//!
//! A sensor with `crop` (several sensors cropped from one device's frame, e.g. a dual-fisheye
//! camera) takes either its own image, of its size, or the device's whole frame, whose window it
//! copies out: the rows of those sensors may all name one file, which is then decoded once per
//! frame into a buffer that grows once, at the first such frame, to the frame's size (at most
//! four times the smallest frame holding every crop). A frame that does not hold the window is a
//! wrong-size image, counted and warned.
//!
//! Allocation: per image, this module allocates the file's resolved path (the check that it
//! lies inside the recording) and nothing else of its own; the QOI and PPM/PGM decoders allocate
//! nothing. The `image` crate's PNG decoder (`png` underneath) does allocate internally each time
//! a decoder is created — its inflate state and row buffers — and offers no way to reuse them
//! across images: seven allocations per PNG image against one per QOI or PPM image
//! (`tests/io/replay.rs` counts both).

mod index;

use super::device::{crop_into, Window};
use super::{sleep_until_or_stop, FrameSource, SourceError, SourceStats, WarningKind, WarningLimiter};
use image::codecs::png::PngDecoder;
use image::{ColorType, ImageDecoder, ImageError, Limits};
use index::{FrameIndex, Row};
use omnitrack_core::frame::{FrameSet, ImageFault, SensorImage};
use omnitrack_core::rig::Rig;
use omnitrack_core::trajectory::{load_tum, Trajectory};
use std::fmt;
use std::fs::File;
use std::io::{self, Cursor, Read};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// The exact header line of `frames.csv`.
pub const FRAMES_HEADER: &str = "frame,sensor,timestamp_ns,path";

/// Warnings of one kind printed before the rest are only counted.
const WARN_LIMIT: u32 = 5;

/// Most memory the PNG decoder may use for one image's metadata chunks (guards against a corrupt
/// header asking for gigabytes).
const DECODER_MAX_ALLOC: u64 = 64 << 20;

/// How fast a recording is replayed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pacing {
    /// Each frame is delivered no earlier than its recorded time after the first frame (the
    /// earliest sensor timestamp of a frame is its time); a frame that is already late is
    /// delivered at once (no catching up by skipping).
    RealTime,
    /// No waiting: frames come as fast as they decode (benchmarks, offline evaluation).
    AsFastAsPossible,
}

/// File-backed [`FrameSource`]. See the module doc.
#[derive(Debug)]
pub struct ReplaySource {
    dir: PathBuf,
    /// `dir` resolved: every image read must lie under it.
    root: PathBuf,
    rig: Rig,
    pacing: Pacing,
    index: FrameIndex,
    /// The rows of the frame being read (one per sensor at most; sized at open).
    rows: Vec<Row>,
    next: usize,
    ground_truth: Option<Trajectory>,
    model_path: Option<PathBuf>,
    /// Encoded bytes of the image being decoded; sized at open, grows only for an unusually
    /// large file (and then keeps its size).
    file_buf: Vec<u8>,
    /// width × height × 4 of the largest sensor, for RGBA → RGB conversion.
    rgba_buf: Box<[u8]>,
    /// The last whole device frame decoded for sensors with a `crop` (see the module doc).
    device_frame: DeviceFrame,
    /// (when the first frame was delivered, its recorded time) for [`Pacing::RealTime`].
    clock: Option<(Instant, u64)>,
    stats: SourceStats,
    warnings: WarningLimiter,
}

impl ReplaySource {
    /// Opens a recording: reads `rig.toml`, `frames.csv`, `groundtruth.tum` if present, and notes
    /// `model.obj` if present. Errors name the file and the problem in one line.
    pub fn open(dir: &Path, pacing: Pacing) -> Result<ReplaySource, SourceError> {
        if !dir.is_dir() {
            return Err(SourceError::Io {
                path: dir.to_path_buf(),
                message: "recording directory does not exist or is not a directory".into(),
            });
        }
        let rig = Rig::load(&dir.join("rig.toml"))?;
        let mut stats = SourceStats::new(rig.sensors.len());
        let mut warnings = WarningLimiter::new(WARN_LIMIT);

        let index_path = dir.join("frames.csv");
        let index = FrameIndex::open(&index_path, dir, &rig, &mut stats, &mut warnings)?;

        let gt_path = dir.join("groundtruth.tum");
        let ground_truth = if gt_path.exists() {
            Some(load_tum(&gt_path)?)
        } else {
            None
        };
        let model_path = Some(dir.join("model.obj")).filter(|p| p.is_file());

        let max_pixels = rig
            .sensors
            .iter()
            .map(|s| s.width as usize * s.height as usize)
            .max()
            .unwrap_or(0);
        // An RGB PNG rarely exceeds its raw size plus a little; bigger files grow the buffer once.
        let file_buf = Vec::with_capacity(max_pixels * 3 + (64 << 10));
        let rgba_buf = vec![0u8; max_pixels * 4].into_boxed_slice();

        // Images are read only from inside this folder (symbolic links are followed only to it).
        let root = std::fs::canonicalize(dir).map_err(|e| SourceError::Io {
            path: dir.to_path_buf(),
            message: format!("cannot resolve the recording directory: {e}"),
        })?;
        Ok(ReplaySource {
            device_frame: DeviceFrame::for_rig(&rig),
            root,
            dir: dir.to_path_buf(),
            rows: Vec::with_capacity(rig.sensors.len()),
            rig,
            pacing,
            index,
            next: 0,
            ground_truth,
            model_path,
            file_buf,
            rgba_buf,
            clock: None,
            stats,
            warnings,
        })
    }

    /// The recording directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    pub fn pacing(&self) -> Pacing {
        self.pacing
    }

    /// Number of frames in the recording (frames with at least one valid index row).
    pub fn frame_count(&self) -> usize {
        self.index.frames().len()
    }

    /// Frames not yet delivered.
    pub fn remaining(&self) -> usize {
        self.index.frames().len() - self.next
    }

    /// `groundtruth.tum` (`T_world_rig`), if the recording has one.
    pub fn ground_truth(&self) -> Option<&Trajectory> {
        self.ground_truth.as_ref()
    }

    /// `model.obj`, if the recording has one (not loaded: capture knows nothing of models).
    pub fn model_path(&self) -> Option<&Path> {
        self.model_path.as_deref()
    }

    /// Starts again from the first frame (the real-time clock restarts too; counters go on).
    pub fn rewind(&mut self) {
        self.next = 0;
        self.clock = None;
    }

    /// Goes on from frame `frame` (the last frame's end if past it); the real-time clock restarts.
    pub fn seek(&mut self, frame: usize) {
        self.next = frame.min(self.index.frames().len());
        self.clock = None;
    }

    /// Waits until the recorded time of a frame, relative to the first delivered frame; false
    /// when `stop` said so first (the clock is then left as it was).
    fn pace(&mut self, timestamp_ns: u64, stop: &dyn Fn() -> bool) -> bool {
        if self.pacing != Pacing::RealTime {
            return true;
        }
        match self.clock {
            None => {
                self.clock = Some((Instant::now(), timestamp_ns));
                true
            }
            Some((start, t0)) => {
                // A gap beyond what the clock can hold (a corrupt timestamp) is waited out until
                // a stop, like any gap too long to see the end of.
                let target = start.checked_add(Duration::from_nanos(timestamp_ns.saturating_sub(t0)));
                sleep_until_or_stop(target, stop)
            }
        }
    }
}

impl FrameSource for ReplaySource {
    fn rig(&self) -> &Rig {
        &self.rig
    }

    fn next_frame(&mut self, out: &mut FrameSet) -> Result<bool, SourceError> {
        self.next_frame_or_stop(out, &|| false)
    }

    fn next_frame_or_stop(&mut self, out: &mut FrameSet, stop: &dyn Fn() -> bool) -> Result<bool, SourceError> {
        if !out.fits(&self.rig) {
            return Err(SourceError::FrameSetMismatch {
                rig: self.rig.name.clone(),
            });
        }
        let Some(&entry) = self.index.frames().get(self.next) else {
            return Ok(false);
        };
        let (frame, frame_time) = (entry.frame, entry.timestamp_ns);
        if !self.pace(frame_time, stop) {
            return Ok(false);
        }
        let used = self.index.rows(&entry, &mut self.rows)?;
        self.next += 1;

        for img in out.sensors_mut() {
            img.set_invalid(ImageFault::Dropped, 0);
        }
        self.device_frame.forget();
        for row in &self.rows[..used] {
            let img = out.sensor_mut(row.sensor);
            let loaded = match self.rig.sensors[row.sensor].crop {
                None => load_image(&row.path, &self.root, &mut self.file_buf, &mut self.rgba_buf, img),
                Some(crop) => load_window(
                    &row.path,
                    &self.root,
                    &mut self.file_buf,
                    &mut self.rgba_buf,
                    &mut self.device_frame,
                    crop,
                    img,
                ),
            };
            match loaded {
                Ok(()) => {
                    img.set_valid(row.timestamp_ns);
                    self.stats.sensors[row.sensor].delivered += 1;
                }
                Err((fault, problem)) => {
                    img.set_invalid(fault, row.timestamp_ns);
                    self.stats.sensors[row.sensor].count(fault);
                    self.warnings.warn(
                        &mut self.stats,
                        WarningKind::Image(fault),
                        format_args!(
                            "{}: frame {frame}, sensor {}: {problem}; sensor skipped for this frame",
                            row.path.display(),
                            row.sensor
                        ),
                    );
                }
            }
        }
        for (stats, img) in self.stats.sensors.iter_mut().zip(out.sensors()) {
            if img.fault == Some(ImageFault::Dropped) {
                stats.dropped += 1;
            }
        }
        out.sequence = frame;
        self.stats.frames_delivered += 1;
        Ok(true)
    }

    fn stats(&self) -> &SourceStats {
        &self.stats
    }
}

/// What went wrong with one image, for the warning line.
#[derive(Debug)]
enum Problem {
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

/// Reads the image at `path` (PNG, QOI or binary PPM/PGM, told apart by its first bytes) into
/// `img`'s buffer as RGB8. `file_buf` and `rgba` are scratch space sized at open. Leaves `img`'s
/// flags alone (the caller sets them).
fn load_image(
    path: &Path,
    root: &Path,
    file_buf: &mut Vec<u8>,
    rgba: &mut [u8],
    img: &mut SensorImage,
) -> Result<(), (ImageFault, Problem)> {
    // An image file is never much larger than its raw pixels: past this it is not the sensor's.
    let most = 4 * u64::from(img.width()) * u64::from(img.height()) + (1 << 20);
    read_file(path, root, file_buf, most)?;
    let encoded = Encoded::open(file_buf)?;
    let found = encoded.dimensions();
    let expected = (img.width(), img.height());
    if found != expected {
        return Err((ImageFault::WrongSize, Problem::Size { found, expected }));
    }
    encoded.decode_rgb(rgba, img)
}

/// The image of a sensor with `crop` at `path`: either its own image (of the sensor's size,
/// e.g. recorded by `omnitrack record`) or the whole frame of its device, whose window is copied
/// out. The frame is decoded once per recorded frame however many sensors' rows name its file.
fn load_window(
    path: &Path,
    root: &Path,
    file_buf: &mut Vec<u8>,
    rgba: &mut [u8],
    device: &mut DeviceFrame,
    crop: [u32; 4],
    img: &mut SensorImage,
) -> Result<(), (ImageFault, Problem)> {
    let [x, y, width, height] = crop;
    let window = Window {
        sensor: img.sensor(),
        x,
        y,
        width,
        height,
    };
    let fits = |w: u32, h: u32| {
        u64::from(x) + u64::from(width) <= u64::from(w) && u64::from(y) + u64::from(height) <= u64::from(h)
    };
    if device.holds(path) {
        if !fits(device.width, device.height) {
            let found = (device.width, device.height);
            return Err((ImageFault::WrongSize, Problem::Window { found, crop }));
        }
        crop_into(&device.pixels, device.width, device.channels, &window, img);
        return Ok(());
    }
    read_file(path, root, file_buf, 4 * device.max_pixels + (1 << 20))?;
    let encoded = Encoded::open(file_buf)?;
    let found = encoded.dimensions();
    if found == (img.width(), img.height()) {
        return encoded.decode_rgb(rgba, img);
    }
    let pixels = u64::from(found.0) * u64::from(found.1);
    if !fits(found.0, found.1) || pixels > device.max_pixels {
        return Err((ImageFault::WrongSize, Problem::Window { found, crop }));
    }
    let channels = encoded.channels()?;
    let bytes = pixels as usize * channels;
    if device.pixels.len() < bytes {
        // Once, at the first device frame (then kept): its size is not known before.
        device.pixels.resize(bytes, 0);
    }
    encoded.read_native(&mut device.pixels[..bytes])?;
    device.path.clear();
    device.path.push(path);
    (device.width, device.height, device.channels) = (found.0, found.1, channels);
    device.valid = true;
    crop_into(&device.pixels, device.width, channels, &window, img);
    Ok(())
}

/// An image file read into memory, its header parsed: the formats a recording may hold
/// (docs/interfaces.md, "Recording"). It lives on the stack for one image: boxing the PNG
/// decoder to even the variants out would cost an allocation per image instead.
#[allow(clippy::large_enum_variant)]
enum Encoded<'a> {
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
    fn open(bytes: &'a [u8]) -> Result<Encoded<'a>, (ImageFault, Problem)> {
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

    fn dimensions(&self) -> (u32, u32) {
        match self {
            Encoded::Png(d) => d.dimensions(),
            Encoded::Qoi(h, _) => (h.width, h.height),
            Encoded::Pnm { width, height, .. } => (*width, *height),
        }
    }

    /// Bytes per pixel as stored (1 grey, 2 grey + alpha, 3 RGB, 4 RGBA).
    fn channels(&self) -> Result<usize, (ImageFault, Problem)> {
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
    fn read_native(self, out: &mut [u8]) -> Result<(), (ImageFault, Problem)> {
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
    fn decode_rgb(self, rgba: &mut [u8], img: &mut SensorImage) -> Result<(), (ImageFault, Problem)> {
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

/// The device frame shared by the cropped sensors of one recorded frame.
#[derive(Debug)]
struct DeviceFrame {
    /// Whether `pixels` holds the frame at `path` of the frame being read.
    valid: bool,
    path: PathBuf,
    width: u32,
    height: u32,
    channels: usize,
    /// 8-bit pixels as decoded (1–4 channels); grows once, at the first device frame.
    pixels: Vec<u8>,
    /// Largest device frame accepted (pixels): four times the smallest frame holding every crop
    /// of the rig, so that a wrong file cannot make the replay decode gigabytes.
    max_pixels: u64,
}

impl DeviceFrame {
    fn for_rig(rig: &Rig) -> DeviceFrame {
        let crops = rig.sensors.iter().filter_map(|s| s.crop);
        let w = crops.clone().map(|[x, _, w, _]| u64::from(x + w)).max().unwrap_or(0);
        let h = crops.map(|[_, y, _, h]| u64::from(y + h)).max().unwrap_or(0);
        DeviceFrame {
            valid: false,
            path: PathBuf::new(),
            width: 0,
            height: 0,
            channels: 3,
            pixels: Vec::new(),
            max_pixels: 4 * w * h,
        }
    }

    fn forget(&mut self) {
        self.valid = false;
    }

    fn holds(&self, path: &Path) -> bool {
        self.valid && self.path == path
    }
}

/// Reads the regular file at `path` (inside `root`, at most `most` bytes) into `file_buf`.
fn read_file(path: &Path, root: &Path, file_buf: &mut Vec<u8>, most: u64) -> Result<(), (ImageFault, Problem)> {
    file_buf.clear();
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
    File::open(&real)
        .and_then(|f| f.take(most).read_to_end(file_buf))
        .map_err(missing)?;
    Ok(())
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
