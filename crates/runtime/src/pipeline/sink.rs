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
use crossbeam::channel::Receiver;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;

/// Where processed frames go, on the caller's thread.
pub trait FrameSink {
    /// One processed frame. An error stops the pipeline (the frames already handed over stay).
    fn frame(&mut self, record: &FrameRecord) -> Result<(), SinkError>;
    /// Called once after the last frame (also after a stop or an error): flush here.
    fn finish(&mut self) -> Result<(), SinkError> {
        Ok(())
    }
}

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

/// A [`FrameSink`] writing the tracked poses as a TUM trajectory (the format of
/// [`omnitrack_core::trajectory`]), buffered, flushed at [`FrameSink::finish`]. Allocation-free per frame.
#[derive(Debug)]
pub struct TumSink {
    path: PathBuf,
    out: std::io::BufWriter<std::fs::File>,
    poses: u64,
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
        let mut out = std::io::BufWriter::with_capacity(64 << 10, f);
        writeln!(out, "# timestamp_s tx ty tz qx qy qz qw (T_world_rig)").map_err(|e| failed("write", e))?;
        Ok(TumSink {
            path: path.to_path_buf(),
            out,
            poses: 0,
        })
    }

    /// Poses written so far.
    pub fn poses(&self) -> u64 {
        self.poses
    }

    fn write_failed(&self, source: std::io::Error) -> SinkError {
        Box::new(TrajectoryFileError {
            path: self.path.clone(),
            action: "write",
            source,
        })
    }
}

impl FrameSink for TumSink {
    fn frame(&mut self, r: &FrameRecord) -> Result<(), SinkError> {
        let Some(pose) = &r.result.pose else {
            return Ok(());
        };
        let stamped = omnitrack_core::trajectory::Stamped {
            timestamp_ns: r.timestamp_ns,
            pose: *pose,
        };
        if let Err(e) =
            omnitrack_core::trajectory::write_tum_line(&mut self.out, &stamped).and_then(|()| writeln!(self.out))
        {
            return Err(self.write_failed(e));
        }
        self.poses += 1;
        Ok(())
    }

    fn finish(&mut self) -> Result<(), SinkError> {
        self.out.flush().map_err(|e| self.write_failed(e))
    }
}

/// Runs the sink on the calling thread until the process thread closes the channel, then
/// finishes it; returns the first error. After an error the rest is still received, unused: the
/// process thread must not wait forever on a full channel.
pub(super) fn drain(sink: &mut dyn FrameSink, records: &Receiver<FrameRecord>, shared: &Shared) -> Option<SinkError> {
    shared.thread_started(PipelineThread::Sink);
    let mut sink_error: Option<SinkError> = None;
    for record in records.iter() {
        if sink_error.is_none() {
            if let Err(e) = sink.frame(&record) {
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
