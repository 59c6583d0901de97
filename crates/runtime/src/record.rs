//! `omnitrack record`: what a source delivers, written in the recording layout that `run`
//! replays (docs/interfaces.md, "Recording"), for replay, tuning and bug reports.
//!
//! In: a [`FrameSource`] (live cameras or a replay), an output directory that does not exist or
//! is empty, [`RecordOptions`]. Out: `DIR/rig.toml` (the source's rig), `DIR/sensorK/NNNNNN.EXT`
//! (8-bit RGB, lossless, in the [`ImageFormat`] asked: raw PPM by default, or PNG, or QOI),
//! `DIR/frames.csv` (`frame,sensor,timestamp_ns,path`, one row per valid image: a sensor's
//! dropped image has no row, as the format allows), and a [`RecordSummary`].
//!
//! Why raw PPM by default: on the rig a recording must not take the tracker's CPU. Per six-sensor
//! 512×384 frame of `lab` (`cargo bench --bench pipeline -- --format ppm`, 2026-11-29, one
//! thread's CPU clock, a shared machine at load 8–10): writing PPM costs 0.34 ms against 6.6 ms
//! for PNG (at its fastest setting) and 7.1 ms for QOI, and reading back 0.44 ms against 7.3 and
//! 5.4; PPM takes 3.5 MB a frame (106 MB/s at 30 Hz) against PNG's 1.75 and QOI's 2.4. Where the
//! disk cannot take that, `--format png` halves it for 20 % of a core at 30 Hz.
//!
//! Capture never waits for the disk: the caller's thread pulls frames into a preallocated pool
//! and hands them to a writer thread through a bounded queue; when the queue is full the frame
//! is dropped and counted (latest frames are what a bug report needs), unless
//! [`RecordOptions::lossless`] asks capture to wait (a replay re-recorded as fast as it goes).
//! The writer flushes `frames.csv` after every frame, so a crash loses at most the frame being
//! written, and a write error (a full disk) stops the recording with one line after the frames
//! already on disk.

use crossbeam::channel::{bounded, Receiver, Sender, TrySendError};
use image::codecs::png::{CompressionType, FilterType, PngEncoder};
use image::{ExtendedColorType, ImageEncoder};
use omnitrack_core::frame::FrameSet;
use omnitrack_io::capture::replay::FRAMES_HEADER;
use omnitrack_io::capture::{FrameSource, SourceError};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// The file format of the images a recording writes (each file's first bytes say which it is;
/// the replay reads all three).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ImageFormat {
    /// QOI, lossless: reads back a quarter cheaper than PNG, but is no cheaper to write and a
    /// third larger here (module doc).
    Qoi,
    /// PNG at its fastest compression, lossless: half the disk of raw, what any tool opens.
    Png,
    /// Binary PPM (`P6`), raw 8-bit RGB: no compression, the least CPU; the default (module doc).
    #[default]
    Ppm,
}

impl ImageFormat {
    /// The file name extension.
    pub fn extension(self) -> &'static str {
        match self {
            ImageFormat::Qoi => "qoi",
            ImageFormat::Png => "png",
            ImageFormat::Ppm => "ppm",
        }
    }

    /// `qoi`, `png` or `ppm`.
    pub fn parse(s: &str) -> Option<ImageFormat> {
        [ImageFormat::Qoi, ImageFormat::Png, ImageFormat::Ppm]
            .into_iter()
            .find(|f| f.extension() == s)
    }

    /// Encodes one RGB8 image of `width` × `height` into `out` (cleared first).
    pub fn encode(self, pixels: &[u8], width: u32, height: u32, out: &mut Vec<u8>) -> Result<(), String> {
        out.clear();
        match self {
            ImageFormat::Png => PngEncoder::new_with_quality(&mut *out, CompressionType::Fast, FilterType::Adaptive)
                .write_image(pixels, width, height, ExtendedColorType::Rgb8)
                .map_err(|e| e.to_string()),
            ImageFormat::Qoi => {
                let encoder = qoi::Encoder::new(pixels, width, height).map_err(|e| e.to_string())?;
                out.resize(encoder.required_buf_len(), 0);
                let n = encoder.encode_to_buf(&mut out[..]).map_err(|e| e.to_string())?;
                out.truncate(n);
                Ok(())
            }
            ImageFormat::Ppm => {
                let _ = write!(out, "P6\n{width} {height}\n255\n");
                out.extend_from_slice(pixels);
                Ok(())
            }
        }
    }
}

/// How to record.
#[derive(Debug, Clone)]
pub struct RecordOptions {
    /// Stop after this many frames taken from the source (written or dropped).
    pub max_frames: Option<u64>,
    /// Frames waiting for the writer before capture drops (default 8: a quarter second at 30 Hz).
    pub queue: usize,
    /// Wait for the writer instead of dropping (replays; live cameras would stall).
    pub lossless: bool,
    /// The images' file format.
    pub format: ImageFormat,
    /// Set from anywhere (a signal handler) to stop after the frame in hand; a source waiting
    /// for its next frame (a real-time replay's gap, a camera being reopened) stops waiting.
    pub stop: Arc<AtomicBool>,
}

impl Default for RecordOptions {
    fn default() -> Self {
        RecordOptions {
            max_frames: None,
            queue: 8,
            lossless: false,
            format: ImageFormat::default(),
            stop: Arc::new(AtomicBool::new(false)),
        }
    }
}

/// What a recording holds.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RecordSummary {
    /// Frames the source delivered.
    pub frames_captured: u64,
    /// Frames on disk (each with its valid images).
    pub frames_written: u64,
    /// Frames dropped because the writer was behind.
    pub frames_dropped: u64,
    /// Images written, and sensor images the source delivered as invalid (no row, no file).
    pub images_written: u64,
    pub images_invalid: u64,
}

impl std::fmt::Display for RecordSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} frames captured, {} written ({} images), {} dropped (writer behind), {} sensor images invalid",
            self.frames_captured, self.frames_written, self.images_written, self.frames_dropped, self.images_invalid
        )
    }
}

/// Why a recording stopped early or could not start.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    #[error("{}: the output directory exists and is not empty (a recording never overwrites)", .0.display())]
    NotEmpty(PathBuf),
    #[error("{}: {source}", .path.display())]
    Write { path: PathBuf, source: std::io::Error },
    #[error("{}: cannot encode the image: {message}", .path.display())]
    Encode { path: PathBuf, message: String },
    #[error("{0}")]
    Source(#[from] SourceError),
}

/// Records `source` into `out` (module doc). On an error the frames already written stay a
/// valid recording.
pub fn record(source: &mut dyn FrameSource, out: &Path, opts: &RecordOptions) -> Result<RecordSummary, RecordError> {
    let write_error = |path: &Path| {
        let path = path.to_path_buf();
        move |source| RecordError::Write { path, source }
    };
    if let Ok(mut entries) = std::fs::read_dir(out) {
        if entries.next().is_some() {
            return Err(RecordError::NotEmpty(out.to_path_buf()));
        }
    }
    let rig = source.rig().clone();
    std::fs::create_dir_all(out).map_err(write_error(out))?;
    for s in &rig.sensors {
        let dir = out.join(format!("sensor{}", s.id));
        std::fs::create_dir_all(&dir).map_err(write_error(&dir))?;
    }
    let rig_path = out.join("rig.toml");
    std::fs::write(&rig_path, rig.to_toml_string()).map_err(write_error(&rig_path))?;
    let csv_path = out.join("frames.csv");
    let mut csv = BufWriter::new(File::create(&csv_path).map_err(write_error(&csv_path))?);
    writeln!(csv, "{FRAMES_HEADER}")
        .and_then(|_| csv.flush())
        .map_err(write_error(&csv_path))?;

    let queue = opts.queue.max(1);
    let (full_tx, full_rx) = bounded::<FrameSet>(queue);
    // Queue + 2 frames, all allocated here: at most `queue` wait in the queue and one is in the
    // writer's hands, so the free channel (room for all of them) always holds one for capture,
    // and neither side ever waits on it.
    let frames = queue + 2;
    let (free_tx, free_rx) = bounded::<FrameSet>(frames);
    for _ in 0..frames {
        let _ = free_tx.send(FrameSet::for_rig(&rig));
    }
    let returns = free_tx.clone();
    let mut summary = RecordSummary::default();
    let written = std::thread::scope(|scope| {
        let format = opts.format;
        let writer = scope.spawn(move || write_frames(full_rx, free_tx, out, format, csv, csv_path));
        let captured = capture(source, opts, &full_tx, &free_rx, &returns, &mut summary);
        drop(full_tx);
        let written = writer.join().unwrap_or_else(|_| {
            Err(RecordError::Encode {
                path: out.to_path_buf(),
                message: "the writer thread panicked".into(),
            })
        });
        captured.and(written)
    });
    let (frames, images) = written?;
    summary.frames_written = frames;
    summary.images_written = images;
    Ok(summary)
}

/// The caller's side: frames from the source into the pool and on to the writer; a frame the
/// writer cannot take goes straight back to the pool (`returns`).
fn capture(
    source: &mut dyn FrameSource,
    opts: &RecordOptions,
    full: &Sender<FrameSet>,
    free: &Receiver<FrameSet>,
    returns: &Sender<FrameSet>,
    summary: &mut RecordSummary,
) -> Result<(), RecordError> {
    while opts.max_frames.is_none_or(|m| summary.frames_captured < m) && !opts.stop.load(Ordering::Relaxed) {
        // Never empty here (see `record`); `returns` keeps the channel open.
        let Ok(mut frame) = free.recv() else { return Ok(()) };
        // A replay's wait for a distant frame, or a camera's reopening, ends at a stop.
        if !source.next_frame_or_stop(&mut frame, &|| opts.stop.load(Ordering::Relaxed))? {
            break;
        }
        summary.frames_captured += 1;
        summary.images_invalid += frame.sensors().iter().filter(|s| !s.valid).count() as u64;
        match full.try_send(frame) {
            Ok(()) => {}
            Err(TrySendError::Full(frame)) if opts.lossless => {
                if full.send(frame).is_err() {
                    // The writer stopped (its error is reported by the caller).
                    return Ok(());
                }
            }
            Err(TrySendError::Full(frame)) => {
                summary.frames_dropped += 1;
                let _ = returns.try_send(frame);
            }
            Err(TrySendError::Disconnected(_)) => return Ok(()),
        }
    }
    Ok(())
}

/// The writer thread: images and rows, `frames.csv` flushed per frame. Returns frames and images
/// written.
fn write_frames(
    full: Receiver<FrameSet>,
    free: Sender<FrameSet>,
    out: &Path,
    format: ImageFormat,
    mut csv: BufWriter<File>,
    csv_path: PathBuf,
) -> Result<(u64, u64), RecordError> {
    let (mut frames, mut images) = (0u64, 0u64);
    let mut bytes = Vec::new();
    for frame in full {
        for s in frame.sensors().iter().filter(|s| s.valid) {
            let relative = format!("sensor{}/{:06}.{}", s.sensor(), frame.sequence, format.extension());
            let path = out.join(&relative);
            format
                .encode(s.pixels(), s.width(), s.height(), &mut bytes)
                .map_err(|message| RecordError::Encode {
                    path: path.clone(),
                    message,
                })?;
            std::fs::write(&path, &bytes).map_err(|source| RecordError::Write { path, source })?;
            writeln!(csv, "{},{},{},{relative}", frame.sequence, s.sensor(), s.timestamp_ns).map_err(|source| {
                RecordError::Write {
                    path: csv_path.clone(),
                    source,
                }
            })?;
            images += 1;
        }
        csv.flush().map_err(|source| RecordError::Write {
            path: csv_path.clone(),
            source,
        })?;
        frames += 1;
        // The channel has room for every frame, so this never waits.
        let _ = free.try_send(frame);
    }
    Ok((frames, images))
}

#[cfg(test)]
mod tests {
    use super::*;
    use omnitrack_core::rig::Rig;
    use omnitrack_io::capture::SourceStats;

    /// Frames as fast as a loop can make them: far faster than PNGs are written.
    struct Flood {
        rig: Rig,
        stats: SourceStats,
        left: u64,
    }

    impl FrameSource for Flood {
        fn rig(&self) -> &Rig {
            &self.rig
        }
        fn next_frame(&mut self, out: &mut FrameSet) -> Result<bool, SourceError> {
            if self.left == 0 {
                return Ok(false);
            }
            self.left -= 1;
            out.sequence = 1000 - self.left;
            let t = out.sequence * 1_000;
            for s in out.sensors_mut() {
                s.pixels_mut().fill((self.left % 251) as u8);
                s.set_valid(t);
            }
            Ok(true)
        }
        fn stats(&self) -> &SourceStats {
            &self.stats
        }
    }

    fn flood(frames: u64) -> Flood {
        let rig = Rig::from_toml_str(
            "name = \"one\"\n[[sensors]]\nid = 0\nresolution = [320, 240]\nmodel = \"pinhole\"\n\
             intrinsics = [300.0, 300.0, 159.5, 119.5]\nrotation_wxyz = [0.5, -0.5, 0.5, -0.5]\n\
             translation_m = [0.0, 0.0, 0.0]\n",
            "one.toml",
        )
        .unwrap();
        Flood {
            stats: SourceStats::new(1),
            rig,
            left: frames,
        }
    }

    /// A source faster than the disk: capture never waits, the frames the writer cannot take are
    /// dropped and counted, and the recording ends (no frame is ever lost to the pool).
    #[test]
    fn a_source_faster_than_the_disk_drops_and_counts_and_never_waits() {
        let dir = tempfile::tempdir().unwrap();
        let opts = RecordOptions {
            queue: 1,
            ..RecordOptions::default()
        };
        let s = record(&mut flood(400), &dir.path().join("rec"), &opts).unwrap();
        assert_eq!(s.frames_captured, 400);
        assert_eq!(s.frames_written + s.frames_dropped, 400, "{s}");
        assert!(s.frames_dropped > 0, "{s}");
        assert_eq!(s.images_written, s.frames_written);
        let rows = std::fs::read_to_string(dir.path().join("rec/frames.csv"))
            .unwrap()
            .lines()
            .count();
        assert_eq!(rows as u64, 1 + s.frames_written);
        // Lossless, every frame is written.
        let opts = RecordOptions {
            queue: 1,
            lossless: true,
            ..RecordOptions::default()
        };
        let s = record(&mut flood(50), &dir.path().join("all"), &opts).unwrap();
        assert_eq!((s.frames_written, s.frames_dropped), (50, 0));
        // A folder with something in it is never written into.
        let e = record(&mut flood(1), &dir.path().join("all"), &opts)
            .unwrap_err()
            .to_string();
        assert!(e.contains("exists and is not empty"), "{e}");
    }

    /// Every format writes what the replay reads back pixel for pixel (lossless), under its
    /// own extension; QOI is smaller than raw.
    #[test]
    fn every_format_replays_to_the_pixels_recorded() {
        use omnitrack_io::capture::{Pacing, ReplaySource};
        let dir = tempfile::tempdir().unwrap();
        let mut sizes = Vec::new();
        for format in [ImageFormat::Qoi, ImageFormat::Png, ImageFormat::Ppm] {
            let out = dir.path().join(format.extension());
            let opts = RecordOptions {
                lossless: true,
                format,
                ..RecordOptions::default()
            };
            // Patterned pixels (a flood's are flat): frame f, byte i holds (i * 7 + i / 320 + f).
            struct Pattern(Flood);
            impl FrameSource for Pattern {
                fn rig(&self) -> &Rig {
                    self.0.rig()
                }
                fn next_frame(&mut self, out: &mut FrameSet) -> Result<bool, SourceError> {
                    let more = self.0.next_frame(out)?;
                    let f = out.sequence;
                    for s in out.sensors_mut() {
                        for (i, p) in s.pixels_mut().iter_mut().enumerate() {
                            *p = (i as u64 * 7 + i as u64 / 320 + f) as u8;
                        }
                    }
                    Ok(more)
                }
                fn stats(&self) -> &SourceStats {
                    self.0.stats()
                }
            }
            let s = record(&mut Pattern(flood(3)), &out, &opts).unwrap();
            assert_eq!((s.frames_written, s.images_written), (3, 3), "{format:?}");
            let csv = std::fs::read_to_string(out.join("frames.csv")).unwrap();
            assert!(
                csv.lines()
                    .skip(1)
                    .all(|l| l.ends_with(&format!(".{}", format.extension()))),
                "{csv}"
            );
            let mut replay = ReplaySource::open(&out, Pacing::AsFastAsPossible).unwrap();
            let mut frame = FrameSet::for_rig(replay.rig());
            let mut frames = 0;
            while replay.next_frame(&mut frame).unwrap() {
                let f = frame.sequence;
                let img = frame.sensor(0);
                assert!(img.valid, "{format:?}");
                let wrong = img
                    .pixels()
                    .iter()
                    .enumerate()
                    .filter(|&(i, &p)| p != (i as u64 * 7 + i as u64 / 320 + f) as u8)
                    .count();
                assert_eq!(wrong, 0, "{format:?} frame {f}");
                frames += 1;
            }
            assert_eq!(frames, 3);
            let bytes: u64 = std::fs::read_dir(out.join("sensor0"))
                .unwrap()
                .map(|e| e.unwrap().metadata().unwrap().len())
                .sum();
            sizes.push(bytes);
        }
        assert!(sizes[0] < sizes[2], "QOI {} bytes, raw {}", sizes[0], sizes[2]);
        assert_eq!(ImageFormat::parse("ppm"), Some(ImageFormat::Ppm));
        assert_eq!(ImageFormat::parse("jpeg"), None);
    }

    /// Issue 50: recording a real-time replay that waits 40 s for its next frame stops within
    /// a slice of the stop, not when the frame comes.
    #[test]
    fn a_stop_ends_the_wait_for_a_distant_frame() {
        use omnitrack_io::capture::{Pacing, ReplaySource};
        let dir = tempfile::tempdir().unwrap();
        let src = dir.path().join("src");
        record(&mut flood(1), &src, &RecordOptions::default()).unwrap();
        let index = src.join("frames.csv");
        let text = std::fs::read_to_string(&index).unwrap();
        let row: Vec<&str> = text.lines().nth(1).unwrap().split(',').collect();
        let next = row[0].parse::<u64>().unwrap() + 1;
        let far = row[2].parse::<u64>().unwrap() + 40_000_000_000;
        std::fs::write(&index, format!("{text}{next},0,{far},{}\n", row[3])).unwrap();
        let mut replay = ReplaySource::open(&src, Pacing::RealTime).unwrap();
        let opts = RecordOptions::default();
        let stop = Arc::clone(&opts.stop);
        let started = std::time::Instant::now();
        let s = std::thread::scope(|scope| {
            scope.spawn(|| {
                std::thread::sleep(std::time::Duration::from_millis(100));
                stop.store(true, Ordering::Relaxed);
            });
            record(&mut replay, &dir.path().join("out"), &opts).unwrap()
        });
        let took = started.elapsed();
        assert_eq!((s.frames_captured, s.frames_written), (1, 1), "{s}");
        assert!(took < std::time::Duration::from_secs(3), "stopped after {took:?}");
    }
}
