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
//! Per frame, each sensor's image file is read (module `image_file`) into a scratch byte buffer sized at open and
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

mod image_file;
mod index;

use super::device::{crop_into, Window};
use super::{sleep_until_or_stop, FrameSource, SourceError, SourceStats, WarningKind, WarningLimiter};
use image_file::{read_file, read_file_or_ppm, Encoded, Problem};
pub use index::FRAMES_HEADER;
use index::{FrameIndex, Row};
use omnitrack_core::frame::{FrameSet, ImageFault, SensorImage};
use omnitrack_core::rig::Rig;
use omnitrack_core::trajectory::{load_tum, Trajectory};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Warnings of one kind printed before the rest are only counted.
const WARN_LIMIT: u32 = 5;

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

        let max_pixels = rig.max_pixels();
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
    if read_file_or_ppm(path, root, file_buf, most, img)? {
        return Ok(());
    }
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
