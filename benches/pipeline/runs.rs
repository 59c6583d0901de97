//! One run of the pipeline for the bench: the replay as a timed frame source (paced or not,
//! standing still until tracking where asked), the pipeline run over it with a sink that notes
//! each pose's delivery, and the helpers the runs share (recordings re-recorded in another image
//! format, the load average).
//!
//! In: a recording, its model and table, the tracker's config and the run's options. Out: a
//! [`Run`] with the pipeline's summary and the latencies.

use omnitrack::capture::{FrameSource, Pacing, ReplaySource, SourceError, SourceStats};
use omnitrack::config::TrackerConfig;
use omnitrack::frame::FrameSet;
use omnitrack::publish::{PoseSubscriber, TrackerState};
use omnitrack::runtime::pipeline::{run_pipeline, PipelineOptions, PipelineSummary};
use omnitrack::runtime::record::{record, ImageFormat, RecordOptions};
use omnitrack::runtime::{FrameRecord, RunOptions};
use omnitrack::tracker::SearchVolume;
use omnitrack::visibility::VisibilityTable;
use omnitrack::{Model, Rig};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};

/// Nanoseconds since the bench started (one clock for capture and subscriber threads).
pub(crate) fn now_ns() -> u64 {
    static EPOCH: OnceLock<Instant> = OnceLock::new();
    EPOCH.get_or_init(Instant::now).elapsed().as_nanos() as u64
}

/// Frames the standing-still run holds frame 0 at most (10 s at 30 Hz) before walking anyway.
pub(crate) const MAX_HOLD: usize = 300;

/// The replay, optionally paced at a wall-clock rate, noting when each frame was handed over.
/// With `hold`, the rig stands still (frame 0 again and again) until the flag is set (by the
/// sink, once tracking), then walks; frames are re-stamped `n × period` by delivery.
pub(crate) struct Timed {
    pub(crate) inner: ReplaySource,
    pub(crate) pace: Option<Duration>,
    pub(crate) start: Option<Instant>,
    pub(crate) handed: Arc<Vec<AtomicU64>>,
    pub(crate) n: usize,
    pub(crate) hold: Option<Arc<AtomicBool>>,
    pub(crate) period_ns: u64,
}

impl FrameSource for Timed {
    fn rig(&self) -> &Rig {
        self.inner.rig()
    }
    fn next_frame(&mut self, out: &mut FrameSet) -> Result<bool, SourceError> {
        if let Some(pace) = self.pace {
            let start = *self.start.get_or_insert_with(Instant::now);
            let due = start + pace * self.n as u32;
            if let Some(wait) = due.checked_duration_since(Instant::now()) {
                std::thread::sleep(wait);
            }
        }
        // At most `MAX_HOLD` frames: a place the tracker cannot commit at from its first
        // frame alone (a corridor's doorways) would otherwise hold the run forever.
        let holding = self.hold.as_ref().is_some_and(|h| !h.load(Ordering::Relaxed)) && self.n < MAX_HOLD;
        if holding {
            self.inner.rewind();
        }
        let more = self.inner.next_frame(out)?;
        if more && self.hold.is_some() {
            let ts = self.n as u64 * self.period_ns;
            for img in out.sensors_mut().iter_mut().filter(|i| i.valid) {
                img.set_valid(ts);
            }
        }
        if more {
            if let Some(slot) = self.handed.get(self.n) {
                slot.store(now_ns(), Ordering::Relaxed);
            }
            self.n += 1;
        }
        Ok(more)
    }
    fn stats(&self) -> &SourceStats {
        self.inner.stats()
    }
}

pub(crate) struct Run {
    pub(crate) name: &'static str,
    pub(crate) summary: PipelineSummary,
    /// Capture → pose received, ms, tracking frames.
    pub(crate) latency: Vec<f64>,
    /// Capture → pose received of the first frame (initialisation search), ms.
    pub(crate) init_ms: f64,
    pub(crate) received: usize,
    /// With the live view beside the run: its summary and the messages its client received.
    pub(crate) view: Option<(omnitrack_view::Summary, u64)>,
}

#[allow(clippy::too_many_arguments)]
pub(crate) fn run(
    name: &'static str,
    rec: &Path,
    model: &Model,
    table: &VisibilityTable,
    cfg: &TrackerConfig,
    hint: SearchVolume,
    frames: usize,
    pace: Option<Duration>,
    lossless: bool,
    stand_still_to_start: bool,
    view: bool,
) -> Run {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos();
    let service = format!("omnitrack-bench/pipeline/{}/{nanos}", std::process::id());
    let handed: Arc<Vec<AtomicU64>> = Arc::new((0..frames + 1000).map(|_| AtomicU64::new(0)).collect());
    let tracking = Arc::new(AtomicBool::new(false));
    let inner = ReplaySource::open(rec, Pacing::AsFastAsPossible).unwrap();
    let truth = inner.ground_truth().unwrap();
    let period_ns = truth[1].timestamp_ns - truth[0].timestamp_ns;
    let source = Timed {
        inner,
        pace,
        start: None,
        handed: Arc::clone(&handed),
        n: 0,
        hold: stand_still_to_start.then(|| Arc::clone(&tracking)),
        period_ns,
    };
    let subscriber = PoseSubscriber::create(&format!("{service}/pose")).unwrap();
    let view = view.then(|| crate::view::start(&service, rec));
    let done = Arc::new(AtomicBool::new(false));
    let done2 = Arc::clone(&done);
    // (sequence, tracking, received ns) per sample.
    let receiver = std::thread::spawn(move || {
        let mut got = Vec::with_capacity(frames + 8);
        let mut quiet = Instant::now();
        loop {
            match subscriber.wait(Duration::from_millis(50)).unwrap() {
                Some(s) => {
                    got.push((s.sequence, s.pose_status() == Ok(TrackerState::Tracking), now_ns()));
                    quiet = Instant::now();
                }
                None if done2.load(Ordering::Relaxed) && quiet.elapsed() > Duration::from_millis(300) => return got,
                None => {}
            }
        }
    });
    let opts = PipelineOptions {
        run: RunOptions {
            hint: Some(hint),
            seed: 1,
            max_frames: None,
        },
        pose_service: Some(format!("{service}/pose")),
        status_service: Some(format!("{service}/status")),
        lossless,
        ..PipelineOptions::default()
    };
    let mut sink = |r: &FrameRecord| {
        if r.result.pose.is_some() {
            tracking.store(true, Ordering::Relaxed);
        }
        Ok(())
    };
    let source: Box<dyn FrameSource + Send> = Box::new(source);
    let summary = run_pipeline(source, model, table, cfg, &opts, &mut sink).unwrap();
    done.store(true, Ordering::Relaxed);
    let got = receiver.join().unwrap();
    let view = view.map(crate::view::View::finish);
    let mut latency = Vec::new();
    let mut init_ms = f64::NAN;
    let mut tracking_started = false;
    for &(seq, tracking, received) in &got {
        let Some(h) = handed.get(seq as usize).map(|a| a.load(Ordering::Relaxed)) else {
            continue;
        };
        let ms = received.saturating_sub(h) as f64 / 1e6;
        if init_ms.is_nan() {
            // The first frame processed: the initialisation search.
            init_ms = ms;
            continue;
        }
        tracking_started |= tracking;
        if tracking_started {
            latency.push(ms);
        }
    }
    latency.sort_by(f64::total_cmp);
    Run {
        name,
        summary,
        latency,
        init_ms,
        received: got.len(),
        view,
    }
}

/// The recording `rec` with its images re-recorded as `format`, made once beside it (through a
/// scratch directory renamed when complete) with the ground truth copied.
pub(crate) fn converted(rec: &Path, format: ImageFormat) -> PathBuf {
    let mut name = rec.file_name().unwrap().to_os_string();
    name.push(format!(".{}", format.extension()));
    let out = rec.with_file_name(name);
    if out.join("frames.csv").is_file() {
        return out;
    }
    let scratch = out.with_extension("partial");
    let _ = std::fs::remove_dir_all(&scratch);
    let mut source = ReplaySource::open(rec, Pacing::AsFastAsPossible).unwrap();
    let opts = RecordOptions {
        lossless: true,
        format,
        ..RecordOptions::default()
    };
    let summary = record(&mut source, &scratch, &opts).unwrap();
    eprintln!("re-recorded {} as {}: {summary}", rec.display(), format.extension());
    std::fs::copy(rec.join("groundtruth.tum"), scratch.join("groundtruth.tum")).unwrap();
    std::fs::rename(&scratch, &out).unwrap();
    out
}

/// `/proc/loadavg`'s three averages.
pub(crate) fn load_average() -> String {
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    load.split_whitespace().take(3).collect::<Vec<_>>().join(" ")
}
