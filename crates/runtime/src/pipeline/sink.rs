//! Where processed frames go: the caller's [`FrameSink`] (any closure of a [`FrameRecord`] is
//! one), [`TumSink`] writing the TUM trajectory (the format of [`omnitrack_core::trajectory`]), and
//! the loop that feeds the sink on the caller's thread.
//!
//! In: [`FrameRecord`]s from the process thread, through a channel of
//! [`SINK_BUFFER`](super::SINK_BUFFER). Out: the sink's calls, and its first error, which stops
//! the pipeline.

use super::shared::Shared;
use super::PipelineThread;
use crate::{FrameRecord, SinkError};
use crossbeam::channel::{Receiver, RecvTimeoutError};
use omnitrack_tracker::{SearchProgress, SearchSnapshot};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

/// Where processed frames go, on the caller's thread.
pub trait FrameSink {
    /// One processed frame. An error stops the pipeline (the frames already handed over stay).
    fn frame(&mut self, record: &FrameRecord) -> Result<(), SinkError>;
    /// An earlier frame's result, worked out after later frames were handed over
    /// ([`FrameRecord::late`]: frames kept during a search). Ignored unless a sink wants it.
    fn late(&mut self, record: &FrameRecord) -> Result<(), SinkError> {
        let _ = record;
        Ok(())
    }
    /// Called once after the last frame (also after a stop or an error): flush here.
    fn finish(&mut self) -> Result<(), SinkError> {
        Ok(())
    }
    /// A search has run for more than [`PROGRESS_AFTER`] (a whole-model search takes seconds,
    /// in which no frame gets a pose): how far it has got. Called on the caller's thread, never
    /// on the frame path, at most once per [`PROGRESS_EVERY`] while it runs. Ignored unless a
    /// sink wants it.
    fn search_progress(&mut self, progress: &SearchSnapshot) {
        let _ = progress;
    }
}

/// A search is reported to [`FrameSink::search_progress`] once it has run this long ...
pub const PROGRESS_AFTER: Duration = Duration::from_secs(1);
/// ... and then at most this often.
pub const PROGRESS_EVERY: Duration = Duration::from_secs(1);

impl<F: FnMut(&FrameRecord) -> Result<(), SinkError>> FrameSink for F {
    fn frame(&mut self, record: &FrameRecord) -> Result<(), SinkError> {
        self(record)
    }
}

/// A trajectory file that could not be created or written.
#[derive(Debug, thiserror::Error)]
#[error("{}: cannot {action}: {source}", path.display())]
pub struct TrajectoryFileError {
    pub path: PathBuf,
    /// `create` or `write`.
    pub action: &'static str,
    #[source]
    pub source: std::io::Error,
}

/// How often the trajectory is forced to the disk (`fsync`): what a power cut can lose.
const SYNC_INTERVAL: std::time::Duration = std::time::Duration::from_secs(1);

/// A [`FrameSink`] writing the tracked poses as a TUM trajectory (the format of
/// [`omnitrack_core::trajectory`]).
///
/// Every pose goes to the file as it comes (one `write` of its line), so a crash of the process
/// (SIGKILL, the OOM killer) loses at most the pose in hand; the file is synced to the disk every
/// `SYNC_INTERVAL` (a second), so a power cut loses at most that much. It runs on the caller's thread,
/// never on the frame path. A pose older than the last one written (a source whose clock went
/// back) is left out and counted: a TUM file is in time order. When the file cannot be written
/// (a full disk), one line says so and the trajectory stops there, while tracking and
/// publishing go on: the poses are the product, the file a record of them. Allocation-free per
/// frame.
#[derive(Debug)]
pub struct TumSink {
    path: PathBuf,
    out: std::io::BufWriter<std::fs::File>,
    poses: u64,
    out_of_order: u64,
    last_ns: Option<u64>,
    synced: std::time::Instant,
    /// Set when a write failed: nothing more is written.
    failed: bool,
    /// Bytes of the file that hold whole lines (the header and every pose written).
    whole: u64,
}

/// Counts the bytes written through it (a TUM line's length, without formatting it twice).
struct Counted<'a, W: Write> {
    inner: &'a mut W,
    bytes: u64,
}

impl<W: Write> Write for Counted<'_, W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.bytes += n as u64;
        Ok(n)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

impl TumSink {
    /// Creates (truncates) `path` and writes the header comment.
    pub fn create(path: &Path) -> Result<TumSink, TrajectoryFileError> {
        let failed = |action, source| TrajectoryFileError {
            path: path.to_path_buf(),
            action,
            source,
        };
        let f = std::fs::File::create(path).map_err(|e| failed("create", e))?;
        let mut out = std::io::BufWriter::with_capacity(4 << 10, f);
        const HEADER: &str = "# timestamp_s tx ty tz qx qy qz qw (T_world_rig)\n";
        out.write_all(HEADER.as_bytes())
            .and_then(|()| out.flush())
            .map_err(|e| failed("write", e))?;
        Ok(TumSink {
            path: path.to_path_buf(),
            out,
            poses: 0,
            out_of_order: 0,
            last_ns: None,
            synced: std::time::Instant::now(),
            failed: false,
            whole: HEADER.len() as u64,
        })
    }

    /// Poses written so far.
    pub fn poses(&self) -> u64 {
        self.poses
    }

    /// Poses left out because they were older than the last one written.
    pub fn out_of_order(&self) -> u64 {
        self.out_of_order
    }

    /// Whether writing failed (the trajectory ends at the last pose written).
    pub fn failed(&self) -> bool {
        self.failed
    }

    /// Stops the trajectory at its last whole line: a write cut short by a full disk leaves part
    /// of a line in the file (and in the buffer, which would be written again when dropped), and
    /// a reader of the file would stumble on it. The buffer is dropped unwritten and the file
    /// truncated to its whole lines.
    fn stop_writing(&mut self, source: std::io::Error) {
        self.failed = true;
        if let Ok(clone) = self.out.get_ref().try_clone() {
            let cut = std::mem::replace(&mut self.out, std::io::BufWriter::with_capacity(0, clone));
            let (file, _unwritten) = cut.into_parts();
            // A file that cannot even be truncated keeps its cut line; the reader skips it.
            let _ = file.set_len(self.whole);
        }
        let e = TrajectoryFileError {
            path: self.path.clone(),
            action: "write",
            source,
        };
        eprintln!(
            "omnitrack: {e}; the trajectory stops at its {} poses, tracking and publishing go on",
            self.poses
        );
    }
}

impl FrameSink for TumSink {
    fn frame(&mut self, r: &FrameRecord) -> Result<(), SinkError> {
        let Some(pose) = &r.result.pose else {
            return Ok(());
        };
        if self.failed {
            return Ok(());
        }
        if self.last_ns.is_some_and(|t| r.timestamp_ns <= t) {
            self.out_of_order += 1;
            return Ok(());
        }
        let stamped = omnitrack_core::trajectory::Stamped {
            timestamp_ns: r.timestamp_ns,
            pose: *pose,
        };
        let mut line = Counted {
            inner: &mut self.out,
            bytes: 0,
        };
        let written = omnitrack_core::trajectory::write_tum_line(&mut line, &stamped)
            .and_then(|()| writeln!(line))
            .map(|()| line.bytes)
            .and_then(|bytes| self.out.flush().map(|()| bytes));
        match written {
            Ok(bytes) => self.whole += bytes,
            Err(e) => {
                self.stop_writing(e);
                return Ok(());
            }
        }
        self.poses += 1;
        self.last_ns = Some(r.timestamp_ns);
        if self.synced.elapsed() >= SYNC_INTERVAL {
            self.synced = std::time::Instant::now();
            if let Err(e) = self.out.get_ref().sync_data() {
                self.stop_writing(e);
            }
        }
        Ok(())
    }

    /// A late pose belongs in the trajectory as any other: it is newer than every pose written
    /// before it (the frames it was kept with had none).
    fn late(&mut self, r: &FrameRecord) -> Result<(), SinkError> {
        self.frame(r)
    }

    fn finish(&mut self) -> Result<(), SinkError> {
        if self.failed {
            return Ok(());
        }
        if self.out_of_order > 0 {
            eprintln!(
                "omnitrack: {}: {} poses older than the one before them were left out (the source's clock went back)",
                self.path.display(),
                self.out_of_order
            );
        }
        let flushed = self.out.flush().and_then(|()| self.out.get_ref().sync_data());
        flushed.map_err(|source| -> SinkError {
            Box::new(TrajectoryFileError {
                path: self.path.clone(),
                action: "write",
                source,
            })
        })
    }
}

/// Runs the sink on the calling thread until the process thread closes the channel, then
/// finishes it; returns the first error. After an error the rest is still received, unused: the
/// process thread must not wait forever on a full channel.
pub(super) fn drain(sink: &mut dyn FrameSink, records: &Receiver<FrameRecord>, shared: &Shared) -> Option<SinkError> {
    shared.thread_started(PipelineThread::Sink);
    let mut sink_error: Option<SinkError> = None;
    let mut progress = ProgressWatch::default();
    loop {
        // The records, and between them a look at the search under way every tick.
        let record = match records.recv_timeout(super::TICK) {
            Ok(record) => Some(record),
            Err(RecvTimeoutError::Timeout) => None,
            Err(RecvTimeoutError::Disconnected) => break,
        };
        if sink_error.is_none() {
            if let Some(search) = shared.search.get() {
                progress.look(search, sink);
            }
        }
        let Some(record) = record else {
            continue;
        };
        if sink_error.is_none() {
            let handed = if record.late {
                sink.late(&record)
            } else {
                sink.frame(&record)
            };
            if let Err(e) = handed {
                tracing::debug!("sink failed: {e}");
                sink_error = Some(e);
                shared.halt.store(true, Ordering::Relaxed);
            }
        }
    }
    if let Err(e) = sink.finish() {
        tracing::debug!("sink failed: {e}");
        sink_error.get_or_insert(e);
    }
    sink_error
}

/// When the sink was last told of a search's progress.
#[derive(Default)]
struct ProgressWatch {
    said_at: Option<Instant>,
}

impl ProgressWatch {
    /// Tells the sink how far the search under way has got, if it has run longer than
    /// [`PROGRESS_AFTER`] and nothing was said within [`PROGRESS_EVERY`].
    fn look(&mut self, search: &SearchProgress, sink: &mut dyn FrameSink) {
        let now = Instant::now();
        if self.said_at.is_some_and(|t| now.duration_since(t) < PROGRESS_EVERY) {
            return;
        }
        let Some(snapshot) = search.snapshot() else {
            return;
        };
        if snapshot.elapsed >= PROGRESS_AFTER {
            self.said_at = Some(now);
            sink.search_progress(&snapshot);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix6;
    use omnitrack_core::geometry::Pose;
    use omnitrack_tracker::{FrameResult, TrackerState};
    use std::time::Duration;

    fn tracked(timestamp_ns: u64) -> FrameRecord {
        FrameRecord {
            sequence: timestamp_ns,
            timestamp_ns,
            valid_sensors: 1,
            edges: 0,
            edge_time: Duration::ZERO,
            track_time: Duration::ZERO,
            frame_time: Duration::ZERO,
            late: false,
            result: FrameResult {
                state: TrackerState::Tracking,
                pose: Some(Pose::translation(timestamp_ns as f64, 0.0, 1.5)),
                covariance: Matrix6::identity(),
                inliers: 10,
                states: Default::default(),
                xi_rad2: 0.0,
                explained: 1.0,
                samples: 1,
                match_time: Duration::ZERO,
                solve_time: Duration::ZERO,
                event: None,
            },
        }
    }

    /// Each pose is in the file when `frame` returns (a crash right after loses nothing), and a
    /// pose older than the last is left out and counted.
    #[test]
    fn every_pose_is_on_disk_at_once_and_in_time_order() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.tum");
        let mut sink = TumSink::create(&path).unwrap();
        for (k, t) in [10u64, 20, 15, 30].into_iter().enumerate() {
            sink.frame(&tracked(t)).unwrap();
            let lines = std::fs::read_to_string(&path).unwrap().lines().count();
            // Header, then the poses so far (the third was older than the second).
            assert_eq!(lines, 1 + [1, 2, 2, 3][k], "after the pose at {t} ns");
        }
        assert_eq!((sink.poses(), sink.out_of_order()), (3, 1));
        sink.finish().unwrap();
    }

    /// A file that cannot be written (a full disk: /dev/full) stops the trajectory, not the
    /// run: `frame` keeps answering Ok.
    #[test]
    fn a_full_disk_stops_the_trajectory_and_not_the_run() {
        let file = std::fs::OpenOptions::new().write(true).open("/dev/full").unwrap();
        let mut sink = TumSink {
            path: "/dev/full".into(),
            out: std::io::BufWriter::new(file),
            poses: 0,
            out_of_order: 0,
            last_ns: None,
            synced: std::time::Instant::now(),
            failed: false,
            whole: 0,
        };
        for t in [10, 20, 30] {
            assert!(sink.frame(&tracked(t)).is_ok());
        }
        assert!(sink.failed());
        assert_eq!(sink.poses(), 0);
        assert!(sink.finish().is_ok());
        // Creating one there fails at once, with the path and the reason in one line.
        let e = TumSink::create(Path::new("/dev/full")).unwrap_err().to_string();
        assert!(e.starts_with("/dev/full: cannot write: "), "{e}");
    }
}
