//! The runtime that wires the stages together for `omnitrack run` and the demo: a frame source
//! (replay now; live drivers behind the same trait) → edge and hue extraction → tracker → the
//! caller's sink (trajectory file, pose publisher, benchmark records).
//!
//! In: a [`FrameSource`], the model and its visibility table, the tracker config, [`RunOptions`].
//! Out: one [`FrameRecord`] per frame handed to the sink (with the tracker, for its
//! correspondences), and the tracker's [`TrackerStats`] at the end.
//!
//! After start-up the loop allocates nothing of its own: the frame set, the edge detector's
//! buffers and the tracker's tables are sized once (the sink decides what it keeps).
//!
//! [`pipeline`] is the threaded device runtime (capture threads, frame pool, tracker, publishers);
//! [`record`] writes a source's frames as a recording; [`cli`] the command-line parsing both
//! binaries share.

pub mod cli;
pub mod pipeline;
pub mod record;

use omnitrack_config::TrackerConfig;
use omnitrack_core::frame::FrameSet;
use omnitrack_core::model::Model;
use omnitrack_edges::EdgeDetector;
use omnitrack_io::capture::{FrameSource, SourceError};
use omnitrack_tracker::visibility::{VisibilityError, VisibilityTable};
use omnitrack_tracker::{FrameResult, SearchVolume, Tracker, TrackerStats};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// How to run.
#[derive(Debug, Clone, PartialEq)]
pub struct RunOptions {
    /// The initial search volume (`--init`); `None` searches the whole model.
    pub hint: Option<SearchVolume>,
    /// Seed of the tracker's random sampling.
    pub seed: u64,
    /// Stop after this many frames.
    pub max_frames: Option<u64>,
}

impl Default for RunOptions {
    fn default() -> Self {
        RunOptions {
            hint: None,
            seed: 1,
            max_frames: None,
        }
    }
}

/// What happened on one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameRecord {
    pub sequence: u64,
    /// The frame's capture time (earliest valid sensor), ns; the previous frame's + 1 if no
    /// sensor delivered.
    pub timestamp_ns: u64,
    pub valid_sensors: usize,
    pub edges: usize,
    pub edge_time: Duration,
    pub track_time: Duration,
    /// Edges + tracking (capture excluded: replay decodes PNGs, a live source hands buffers).
    pub frame_time: Duration,
    pub result: FrameResult,
    /// An earlier frame's result, worked out after its time (a frame kept during a search and
    /// caught up on, `Tracker::late`): its timestamp is that frame's, its sequence the one of the
    /// frame whose processing worked it out, its counts and times zero. A trajectory wants it; a
    /// live subscriber, which has had later frames, does not.
    pub late: bool,
}

impl FrameRecord {
    /// The record of the earlier frame stamped `timestamp_ns`, whose `result` was worked out
    /// while the frame numbered `sequence` was processed.
    pub fn late(sequence: u64, timestamp_ns: u64, result: FrameResult) -> FrameRecord {
        FrameRecord {
            sequence,
            timestamp_ns,
            valid_sensors: 0,
            edges: 0,
            edge_time: Duration::ZERO,
            track_time: Duration::ZERO,
            frame_time: Duration::ZERO,
            result,
            late: true,
        }
    }
}

/// A sink's own error (an unwritable trajectory file, a closed socket, …), kept whole: the run
/// stops with it, after the frames already handed over.
pub type SinkError = Box<dyn std::error::Error + Send + Sync>;

/// Why a run stopped early.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error("{0}")]
    Source(#[from] SourceError),
    #[error("{0}")]
    Sink(SinkError),
}

/// Runs the tracker over `source` until it ends (or `max_frames`), handing every frame to
/// `sink`. A sink error stops the run (after the frames already handed over).
///
/// This loop runs the tracker on the caller's thread, so its sink sees the tracker too (its
/// correspondences and states, for pictures and evaluations). The device pipeline's
/// [`pipeline::FrameSink`] gets the records alone: there the tracker runs on a thread of its own.
pub fn track(
    source: &mut dyn FrameSource,
    model: &Model,
    table: &VisibilityTable,
    cfg: &TrackerConfig,
    opts: &RunOptions,
    sink: &mut dyn FnMut(&FrameRecord, &Tracker) -> Result<(), SinkError>,
) -> Result<TrackerStats, RunError> {
    let rig = source.rig().clone();
    let mut frame = FrameSet::for_rig(&rig);
    let mut detector = EdgeDetector::for_tracking(&rig, &cfg.edges);
    let mut tracker = Tracker::new(&rig, model, table, cfg, opts.hint, opts.seed);
    let mut sequence = 0u64;
    let mut last_ts = 0u64;
    while opts.max_frames.is_none_or(|m| sequence < m) {
        if !source.next_frame(&mut frame)? {
            break;
        }
        let timestamp_ns = frame.timestamp_ns().unwrap_or(last_ts + 1);
        last_ts = timestamp_ns;
        let started = Instant::now();
        let edges = detector.detect(&frame);
        let edge_time = started.elapsed();
        let result = tracker.process(edges, timestamp_ns);
        let frame_time = started.elapsed();
        let record = FrameRecord {
            sequence,
            timestamp_ns,
            valid_sensors: frame.valid_count(),
            edges: edges.len(),
            edge_time,
            track_time: frame_time - edge_time,
            frame_time,
            result,
            late: false,
        };
        for &(t, r) in tracker.late() {
            sink(&FrameRecord::late(sequence, t, r), &tracker).map_err(RunError::Sink)?;
        }
        sequence += 1;
        sink(&record, &tracker).map_err(RunError::Sink)?;
    }
    // A search still under way, and the frames kept meanwhile, are worked out now.
    tracker.finish();
    for &(t, r) in tracker.late() {
        sink(&FrameRecord::late(sequence, t, r), &tracker).map_err(RunError::Sink)?;
    }
    Ok(*tracker.stats())
}

/// The visibility table for `model`: `explicit` if given (checked against the model); otherwise
/// the cache beside the model (`MODEL.vis`) if it is current (this model, these `[visibility]`
/// settings); otherwise built now (desk builds
/// only) and cached there when the directory is writable. Returns the table and a line saying
/// where it came from.
pub fn load_or_build_table(
    model_path: &Path,
    model: &Model,
    explicit: Option<&Path>,
    cfg: &TrackerConfig,
) -> Result<(VisibilityTable, String), VisibilityError> {
    if let Some(path) = explicit {
        let t = VisibilityTable::load(path, model)?;
        return Ok((t, format!("visibility table {}", path.display())));
    }
    let cache = cache_path(model_path);
    let stale = match VisibilityTable::load(&cache, model) {
        Ok(t) => match t.header.differs_from(&cfg.visibility) {
            None => return Ok((t, format!("visibility table {} (cached)", cache.display()))),
            Some(why) => Some(why),
        },
        Err(_) => None,
    };
    let (table, origin) = build_and_cache(model_path, model, &cache, cfg).map_err(|e| match (&stale, e) {
        // A device build cannot rebuild: say why the table beside the model was not used.
        (Some(why), VisibilityError::Invalid { file, message }) => VisibilityError::Invalid {
            file,
            message: format!("{message} (the cached table was built with other settings: {why})"),
        },
        (_, e) => e,
    })?;
    Ok(match stale {
        Some(why) => (table, format!("{origin} (the cached table had other settings: {why})")),
        None => (table, origin),
    })
}

/// `MODEL.obj` → `MODEL.vis`.
pub fn cache_path(model_path: &Path) -> PathBuf {
    model_path.with_extension("vis")
}

#[cfg(feature = "desk")]
fn build_and_cache(
    model_path: &Path,
    model: &Model,
    cache: &Path,
    cfg: &TrackerConfig,
) -> Result<(VisibilityTable, String), VisibilityError> {
    use omnitrack_tracker::visibility::build::{build_table, check_build, BuildOptions};
    let mut opts = BuildOptions::from_config(&cfg.visibility);
    check_build(model, &opts).map_err(|message| VisibilityError::Invalid {
        file: cache.display().to_string(),
        message,
    })?;
    opts.progress = true;
    let recorded = std::fs::canonicalize(model_path).unwrap_or_else(|_| model_path.to_path_buf());
    let started = Instant::now();
    let table = build_table(model, &recorded.display().to_string(), &opts);
    let took = started.elapsed().as_secs_f64();
    match table.save(cache) {
        Ok(()) => Ok((
            table,
            format!("visibility table built in {took:.1} s, cached at {}", cache.display()),
        )),
        Err(e) => Ok((
            table,
            format!("visibility table built in {took:.1} s (not cached: {e})"),
        )),
    }
}

#[cfg(not(feature = "desk"))]
fn build_and_cache(
    model_path: &Path,
    _model: &Model,
    cache: &Path,
    _cfg: &TrackerConfig,
) -> Result<(VisibilityTable, String), VisibilityError> {
    Err(VisibilityError::Invalid {
        file: model_path.display().to_string(),
        message: format!(
            "no --visibility given and no current cache at {}; this device build cannot build one: \
             run `omnitrack visibility build --model {} --out {}` on a desk build",
            cache.display(),
            model_path.display(),
            cache.display()
        ),
    })
}
