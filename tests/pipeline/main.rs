//! The threaded pipeline end to end on a rendered `lab` recording: every processed frame's pose
//! reaches a subscriber and equals the trajectory written by the sink; a sensor that dies mid-run
//! leaves poses flowing and shows on the status; nothing allocates on the frame path or in the
//! relocalisations over 300 frames, nor takes memory not held before; the stop flag and SIGTERM stop cleanly with the trajectory flushed; per-sensor capture
//! assembles frames by timestamp.
//!
//! One recording of 40 rendered frames is replayed back and forth (a "ping-pong" index over the
//! same PNGs, timestamps increasing) to make runs of any length with continuous motion. Tests run
//! one at a time (a lock): the allocation count is process-wide. Service names are unique per
//! test and run.
#![cfg(feature = "desk")]

#[path = "../common/mod.rs"]
mod common;
mod per_sensor;

use nalgebra::Point3;
use omnitrack::capture::device::CaptureDevice;
use omnitrack::capture::live::{FailureDetail, LiveCamera, ReadFailure};
use omnitrack::capture::{FrameSource, Pacing, ReplaySource, SourceError, SourceOptions, SourceStats};
use omnitrack::config::TrackerConfig;
use omnitrack::frame::{FrameSet, ImageFault, SensorImage};
use omnitrack::publish::{PoseSubscriber, SearchState, StatusSample, StatusSubscriber, TrackerState};
use omnitrack::runtime::pipeline::{
    inside_publish, live_sensors, run_pipeline, upstream_priority, FrameSink, PipelineOptions, PipelineThread,
    Realtime, RunEnd, Stage, TumSink,
};
use omnitrack::runtime::{FrameRecord, RunError, RunOptions, SinkError};
use omnitrack::tracker::{SearchVolume, TrackerEvent};
use omnitrack::trajectory::{load_tum, Stamped};
use omnitrack::visibility::VisibilityTable;
use omnitrack::{Model, Rig};
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, OnceLock};
use std::time::{Duration, Instant};

// ---- allocation counting -------------------------------------------------------------------

/// Counts, while `WINDOW` is open, every allocation of every thread of the process except the
/// test harness's and those marked `EXEMPT` (the replay's capture thread: its PNG decoder allocates per image). Inside
/// an iceoryx2 publish of the pipeline (`inside_publish`) they go to `PUBLISH_ALLOCS` instead.
struct Counting;

static WINDOW: AtomicBool = AtomicBool::new(false);
static ALLOCS: AtomicUsize = AtomicUsize::new(0);
static PUBLISH_ALLOCS: AtomicUsize = AtomicUsize::new(0);

thread_local! {
    static EXEMPT: Cell<bool> = const { Cell::new(false) };
}

fn count_alloc() {
    if !WINDOW.load(Ordering::Relaxed) || EXEMPT.try_with(Cell::get).unwrap_or(true) || common::on_harness_thread() {
        return;
    }
    if inside_publish() {
        PUBLISH_ALLOCS.fetch_add(1, Ordering::Relaxed);
    } else {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
    }
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count_alloc();
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        count_alloc();
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count_alloc();
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

fn exempt_capture(t: PipelineThread) {
    if let PipelineThread::Capture { .. } = t {
        EXEMPT.with(|e| e.set(true));
    }
}

// ---- fixture ---------------------------------------------------------------------------------

const RENDERED: usize = 40;

struct Fixture {
    dir: tempfile::TempDir,
    rec: PathBuf,
    model: Model,
    table: VisibilityTable,
    hint: SearchVolume,
}

/// Tests run one at a time: the allocation window is process-wide, and two pipelines would
/// share the two cores.
fn serial() -> MutexGuard<'static, ()> {
    static LOCK: Mutex<()> = Mutex::new(());
    LOCK.lock().unwrap_or_else(|e| e.into_inner())
}

fn fixture() -> &'static Fixture {
    static F: OnceLock<Fixture> = OnceLock::new();
    F.get_or_init(|| {
        let lab = common::lab_recording(RENDERED);
        let hint = SearchVolume {
            centre: Point3::from(lab.truth[0].pose.translation.vector),
            diameter_m: Some(3.0),
        };
        Fixture {
            dir: lab.dir,
            rec: lab.rec,
            model: lab.model,
            table: lab.table,
            hint,
        }
    })
}

/// A recording of `frames` frames going back and forth over the rendered ones (0, 1, …, 39, 38,
/// …, 1, 0, 1, …) with increasing timestamps: the same PNGs (hard links: a recording reads only
/// files inside its folder), a new index.
fn ping_pong(f: &Fixture, frames: usize) -> PathBuf {
    let out = f.dir.path().join(format!("pingpong-{frames}"));
    if out.join("frames.csv").exists() {
        return out;
    }
    std::fs::create_dir_all(&out).unwrap();
    std::fs::copy(f.rec.join("rig.toml"), out.join("rig.toml")).unwrap();
    let index = std::fs::read_to_string(f.rec.join("frames.csv")).unwrap();
    let mut rows: Vec<Vec<(String, u64, String)>> = vec![Vec::new(); RENDERED];
    for line in index.lines().skip(1) {
        let p: Vec<&str> = line.split(',').collect();
        let frame: usize = p[0].parse().unwrap();
        rows[frame].push((p[1].to_string(), p[2].parse().unwrap(), p[3].to_string()));
    }
    let period = rows[1][0].1 - rows[0][0].1;
    let mut csv = format!("{}\n", omnitrack::capture::replay::FRAMES_HEADER);
    let cycle = 2 * (RENDERED - 1);
    for j in 0..frames {
        let c = j % cycle;
        let src = if c < RENDERED { c } else { cycle - c };
        for (sensor, ts, path) in &rows[src] {
            let ts = j as u64 * period + (ts - rows[src][0].1);
            let linked = out.join(path);
            if !linked.exists() {
                std::fs::create_dir_all(linked.parent().unwrap()).unwrap();
                std::fs::hard_link(f.rec.join(path), &linked).unwrap();
            }
            csv.push_str(&format!("{j},{sensor},{ts},{path}\n"));
        }
    }
    std::fs::write(out.join("frames.csv"), csv).unwrap();
    out
}

fn unique(tag: &str) -> String {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos();
    format!("omnitrack-test/pipeline-{tag}/{}/{nanos}", std::process::id())
}

/// Lossless: a replay as fast as it decodes would otherwise outrun the tracker.
fn options(f: &Fixture, tag: &str) -> PipelineOptions {
    PipelineOptions {
        lossless: true,
        run: RunOptions {
            hint: Some(f.hint),
            seed: 1,
            max_frames: None,
        },
        pose_service: Some(unique(&format!("{tag}/pose"))),
        status_service: Some(unique(&format!("{tag}/status"))),
        ..PipelineOptions::default()
    }
}

fn replay(dir: &Path) -> Box<dyn FrameSource + Send> {
    Box::new(ReplaySource::open(dir, Pacing::AsFastAsPossible).unwrap())
}

/// Collects samples of a subscriber on another thread until `done` is set and the service has
/// been quiet for a while.
fn collect<T: Send + 'static>(
    receive: impl Fn() -> Option<T> + Send + 'static,
    done: Arc<AtomicBool>,
) -> std::thread::JoinHandle<Vec<T>> {
    std::thread::spawn(move || {
        let mut got = Vec::new();
        let mut quiet_since = Instant::now();
        loop {
            match receive() {
                Some(s) => {
                    got.push(s);
                    quiet_since = Instant::now();
                }
                None => {
                    if done.load(Ordering::Relaxed) && quiet_since.elapsed() > Duration::from_millis(300) {
                        return got;
                    }
                    std::thread::sleep(Duration::from_micros(200));
                }
            }
        }
    })
}

/// Keeps every record and writes the TUM trajectory.
struct Recorder {
    records: Vec<FrameRecord>,
    tum: Option<TumSink>,
    /// Sets `stop` once this many records arrived.
    stop_after: Option<(usize, Arc<AtomicBool>)>,
}

impl FrameSink for Recorder {
    fn frame(&mut self, r: &FrameRecord) -> Result<(), SinkError> {
        self.records.push(*r);
        if let Some(t) = self.tum.as_mut() {
            t.frame(r)?;
        }
        if let Some((n, stop)) = &self.stop_after {
            if self.records.len() == *n {
                stop.store(true, Ordering::Relaxed);
            }
        }
        Ok(())
    }
    fn finish(&mut self) -> Result<(), SinkError> {
        self.tum.as_mut().map_or(Ok(()), |t| t.finish())
    }
}

/// A [`Recorder`] that also keeps the late records (a search's frame and those kept during it),
/// each with the number of on-time records that came before it.
struct WithLate {
    inner: Recorder,
    late: Vec<(usize, FrameRecord)>,
}

impl FrameSink for WithLate {
    fn frame(&mut self, r: &FrameRecord) -> Result<(), SinkError> {
        self.inner.frame(r)
    }
    fn late(&mut self, r: &FrameRecord) -> Result<(), SinkError> {
        self.late.push((self.inner.records.len(), *r));
        Ok(())
    }
    fn finish(&mut self) -> Result<(), SinkError> {
        self.inner.finish()
    }
}

// ---- tests -----------------------------------------------------------------------------------

#[test]
fn every_processed_frame_is_published_and_equals_the_trajectory() {
    let _serial = serial();
    let f = fixture();
    let opts = options(f, "poses");
    let subscriber = PoseSubscriber::create(opts.pose_service.as_deref().unwrap()).unwrap();
    let done = Arc::new(AtomicBool::new(false));
    let samples = collect(move || subscriber.receive().unwrap(), Arc::clone(&done));
    let tum_path = f.dir.path().join("poses.tum");
    let mut sink = WithLate {
        inner: Recorder {
            records: Vec::new(),
            tum: Some(TumSink::create(&tum_path).unwrap()),
            stop_after: None,
        },
        late: Vec::new(),
    };
    let summary = run_pipeline(
        replay(&f.rec),
        &f.model,
        &f.table,
        &TrackerConfig::default(),
        &opts,
        &mut sink,
    )
    .unwrap();
    done.store(true, Ordering::Relaxed);
    let samples = samples.join().unwrap();
    let (records, late) = (sink.inner.records, sink.late);
    eprintln!("{summary}");

    assert_eq!(summary.reason, RunEnd::EndOfStream);
    assert_eq!(summary.frames_captured, RENDERED as u64);
    assert_eq!(summary.frames_processed, RENDERED as u64);
    assert_eq!(summary.frames_dropped, 0);
    assert_eq!(records.len() as u64, summary.frames_processed);
    assert_eq!(summary.poses_published, summary.frames_processed);
    let tracked: Vec<&FrameRecord> = records.iter().filter(|r| r.result.pose.is_some()).collect();
    assert!(
        tracked.len() * 10 >= records.len() * 8,
        "{} of {} frames tracked",
        tracked.len(),
        records.len()
    );

    // One sample per processed frame, in order, carrying the record. A frame without a pose
    // carries the newest good pose known, late ones included (between a committed search and
    // the first frame caught up on, the search's), with status lost and a finite covariance;
    // before any pose, status initializing.
    assert_eq!(samples.len(), records.len(), "one pose sample per processed frame");
    assert!(
        late.iter().any(|(_, r)| r.result.pose.is_some()),
        "the search's pose came late"
    );
    let mut last_pose = None;
    let mut late = late.iter().peekable();
    for (k, (s, r)) in samples.iter().zip(&records).enumerate() {
        while let Some((_, l)) = late.next_if(|(before, _)| *before <= k) {
            last_pose = l.result.pose.or(last_pose);
        }
        assert_eq!(s.sequence, r.sequence);
        assert_eq!(s.timestamp_ns, r.timestamp_ns);
        assert_eq!(s.inliers, r.result.inliers);
        if let Some(p) = r.result.pose {
            last_pose = Some(p);
            assert_eq!(s.pose_status(), Ok(TrackerState::Tracking));
        } else if last_pose.is_some() {
            assert_eq!(s.pose_status(), Ok(TrackerState::Lost), "frame {}", r.sequence);
            assert!(
                s.covariance[0].is_finite(),
                "frame {}: {:?}",
                r.sequence,
                s.covariance[0]
            );
        } else {
            assert_eq!(s.pose_status(), Ok(TrackerState::Initialising), "frame {}", r.sequence);
        }
        if let Some(p) = last_pose {
            let got = s.pose().unwrap();
            assert!(
                (got.translation.vector - p.translation.vector).norm() < 1e-12,
                "frame {}",
                r.sequence
            );
            assert!(got.rotation.angle_to(&p.rotation) < 1e-9);
        }
    }

    // The trajectory on disk is the tracked samples.
    let written = load_tum(&tum_path).unwrap();
    let published: Vec<&omnitrack::publish::PoseSample> = samples
        .iter()
        .filter(|s| s.pose_status() == Ok(TrackerState::Tracking))
        .collect();
    assert_eq!(written.len(), published.len());
    for (w, s) in written.iter().zip(published) {
        let p = s.pose().unwrap();
        assert_eq!(w.timestamp_ns, s.timestamp_ns);
        assert!((w.pose.translation.vector - p.translation.vector).norm() < 1e-8);
        assert!(w.pose.rotation.angle_to(&p.rotation) < 1e-9);
    }
}

/// The images of `sensors` missing over `frames` (frame indices of the source).
struct FailingSensors {
    inner: ReplaySource,
    sensors: std::ops::Range<usize>,
    frames: std::ops::Range<u64>,
    frame: u64,
}

impl FrameSource for FailingSensors {
    fn rig(&self) -> &Rig {
        self.inner.rig()
    }
    fn next_frame(&mut self, out: &mut FrameSet) -> Result<bool, SourceError> {
        let more = self.inner.next_frame(out)?;
        if more && self.frames.contains(&self.frame) {
            for k in self.sensors.clone() {
                out.sensor_mut(k).set_invalid(ImageFault::Missing, 0);
            }
        }
        self.frame += u64::from(more);
        Ok(more)
    }
    fn stats(&self) -> &SourceStats {
        self.inner.stats()
    }
}

#[test]
fn a_sensor_that_dies_mid_run_shows_on_the_status_while_poses_go_on() {
    let _serial = serial();
    let f = fixture();
    const FRAMES: u64 = 80;
    const FROM: u64 = 25;
    const DEAD: usize = 3;
    let rec = ping_pong(f, FRAMES as usize);
    let opts = options(f, "dead-sensor");
    let mut cfg = TrackerConfig::default();
    cfg.budgets.status_interval_ms = 100.0;
    let status = StatusSubscriber::create(opts.status_service.as_deref().unwrap()).unwrap();
    let done = Arc::new(AtomicBool::new(false));
    let statuses = collect(move || status.receive().unwrap(), Arc::clone(&done));
    let source = FailingSensors {
        inner: ReplaySource::open(&rec, Pacing::AsFastAsPossible).unwrap(),
        sensors: DEAD..DEAD + 1,
        frames: FROM..u64::MAX,
        frame: 0,
    };
    let mut sink = Recorder {
        records: Vec::new(),
        tum: None,
        stop_after: None,
    };
    let rig_name = source.rig().name.clone();
    let source: Box<dyn FrameSource + Send> = Box::new(source);
    let summary = run_pipeline(source, &f.model, &f.table, &cfg, &opts, &mut sink).unwrap();
    done.store(true, Ordering::Relaxed);
    let statuses: Vec<StatusSample> = statuses.join().unwrap();
    eprintln!("{summary}");
    // Every status names who publishes.
    assert!(!rig_name.is_empty());
    assert!(
        statuses
            .iter()
            .all(|s| s.source() == rig_name && s.pid == std::process::id()),
        "{statuses:?}"
    );

    // Lossless: every frame reached the tracker; poses went on without the sensor.
    assert_eq!(summary.frames_processed, FRAMES);
    let after: Vec<&FrameRecord> = sink.records.iter().filter(|r| r.sequence >= FROM).collect();
    assert_eq!(after.len() as u64, FRAMES - FROM);
    assert!(after.iter().all(|r| r.valid_sensors == 5));
    let tracked_after = after.iter().filter(|r| r.result.pose.is_some()).count();
    assert!(
        tracked_after * 10 >= after.len() * 8,
        "{tracked_after} of {} frames tracked without sensor {DEAD}",
        after.len()
    );
    assert_eq!(summary.poses_published, FRAMES);

    // The counters: the dead sensor's images are faults, the others delivered.
    let s = &summary.sensors[DEAD];
    assert_eq!(s.faults, FRAMES - FROM);
    assert_eq!(s.delivered, FROM);
    for (k, other) in summary.sensors.iter().enumerate().filter(|(k, _)| *k != DEAD) {
        assert_eq!(other.delivered, FRAMES, "sensor {k}");
        assert_eq!(other.lost(), 0, "sensor {k}");
    }

    // The status said so: a rate for every sensor early on, 0 for the dead one later, and its
    // lost images counted.
    assert!(statuses.len() >= 3, "{} status samples", statuses.len());
    assert!(statuses.iter().all(|s| s.sensor_count == 6));
    assert!(
        statuses
            .iter()
            .any(|s| s.frame_rate_hz.iter().take(6).all(|&r| r > 0.0)),
        "no status with every sensor delivering: {statuses:?}"
    );
    assert!(
        statuses
            .iter()
            .any(|s| s.frame_rate_hz[DEAD] == 0.0 && (0..6).filter(|&k| k != DEAD).all(|k| s.frame_rate_hz[k] > 0.0)),
        "no status with sensor {DEAD} at 0 frames/s while the others deliver"
    );
    let last = statuses.last().unwrap();
    assert_eq!(last.frames_dropped[DEAD], FRAMES - FROM);
    assert!((0..6).filter(|&k| k != DEAD).all(|k| last.frames_dropped[k] == 0));
    assert!(last.stage_p50_us[omnitrack::publish::Stage::Edges.index()] > 0);
    assert!(last.stage_p99_us[omnitrack::publish::Stage::Frame.index()] > 0);
}

/// Minor page faults so far of each of the process's threads whose name starts with `prefix`
/// (`/proc/self/task/*/stat`; names are cut to 15 bytes there): pages each wrote first.
fn page_faults(prefix: &str) -> u64 {
    let mut faults = 0;
    for task in std::fs::read_dir("/proc/self/task").unwrap().flatten() {
        let Ok(stat) = std::fs::read_to_string(task.path().join("stat")) else {
            continue;
        };
        // pid (comm) state … minflt is the tenth field; comm may hold spaces.
        let (Some(open), Some(close)) = (stat.find('('), stat.rfind(')')) else {
            continue;
        };
        if stat[open + 1..close].starts_with(prefix) {
            faults += stat[close + 2..].split(' ').nth(7).unwrap().parse::<u64>().unwrap();
        }
    }
    faults
}

/// The replay, stopping once for `pause` before its frame `at`: a camera that hiccups, so that
/// the tracker finds no frame waiting, perhaps for the first time in the run.
struct Hiccup {
    inner: ReplaySource,
    frame: u64,
    at: u64,
    pause: Duration,
}

impl FrameSource for Hiccup {
    fn rig(&self) -> &Rig {
        self.inner.rig()
    }
    fn next_frame(&mut self, out: &mut FrameSet) -> Result<bool, SourceError> {
        if self.frame == self.at {
            std::thread::sleep(self.pause);
        }
        self.frame += 1;
        self.inner.next_frame(out)
    }
    fn stats(&self) -> &SourceStats {
        self.inner.stats()
    }
}

/// Nothing allocates on the frame path, nor on the search thread, over 300 frames of a recording
/// played back and forth: its turns fail the motion prior, and the tracker relocalises there on
/// its search thread (issue 50). Nor when the camera hiccups and the tracker waits for a frame
/// for the first time in the run: crossbeam allocated on a channel's first wait
/// (`pipeline::pool::warm_channel`). And the process and search threads write no memory they had
/// not written before: the buffers the searches fill are resident from start-up
/// (`omnitrack_core::memory`), so the process's memory stays as it was.
#[test]
fn nothing_allocates_on_the_frame_path_or_in_the_relocalisations_over_300_frames() {
    let _serial = serial();
    let f = fixture();
    const START: usize = 40;
    const COUNTED: usize = 300;
    let rec = ping_pong(f, START + COUNTED + 40);
    let mut opts = options(f, "alloc");
    opts.on_thread_start = Some(exempt_capture);
    let stop = Arc::clone(&opts.stop);
    // The counter itself must work, on this thread and on others.
    WINDOW.store(true, Ordering::Relaxed);
    let v = vec![1u8];
    std::thread::scope(|s| {
        s.spawn(|| drop(vec![2u8]));
    });
    WINDOW.store(false, Ordering::Relaxed);
    assert!(ALLOCS.load(Ordering::Relaxed) >= 2);
    drop(v);
    ALLOCS.store(0, Ordering::Relaxed);
    PUBLISH_ALLOCS.store(0, Ordering::Relaxed);

    /// Opens the window after START records, closes it COUNTED records later, then stops;
    /// counts the relocalisations taken up inside it (on their own frame: often a late record),
    /// and the page faults of the process and search threads over it.
    struct Window {
        records: Vec<FrameRecord>,
        stop: Arc<AtomicBool>,
        relocalised: usize,
        faults: [u64; 2],
    }
    impl Window {
        fn faults() -> [u64; 2] {
            [page_faults("omnitrack-proce"), page_faults("omnitrack-searc")]
        }
        fn note(&mut self, r: &FrameRecord) {
            if WINDOW.load(Ordering::Relaxed) && r.result.event == Some(TrackerEvent::Relocalised) {
                self.relocalised += 1;
            }
        }
    }
    impl FrameSink for Window {
        fn frame(&mut self, r: &FrameRecord) -> Result<(), SinkError> {
            self.note(r);
            self.records.push(*r);
            if self.records.len() == START {
                self.faults = Window::faults();
                WINDOW.store(true, Ordering::Relaxed);
            } else if self.records.len() == START + COUNTED {
                WINDOW.store(false, Ordering::Relaxed);
                let now = Window::faults();
                self.faults = [now[0] - self.faults[0], now[1] - self.faults[1]];
                self.stop.store(true, Ordering::Relaxed);
            }
            Ok(())
        }
        fn late(&mut self, r: &FrameRecord) -> Result<(), SinkError> {
            self.note(r);
            Ok(())
        }
    }
    let mut sink = Window {
        records: Vec::with_capacity(START + COUNTED + 100),
        stop,
        relocalised: 0,
        faults: [0; 2],
    };
    // Four frames wait in the pool at most: at a third of a second each (a debug build), two
    // seconds drain them.
    let source: Box<dyn FrameSource + Send> = Box::new(Hiccup {
        inner: ReplaySource::open(&rec, Pacing::AsFastAsPossible).unwrap(),
        frame: 0,
        at: (START + COUNTED / 2) as u64,
        pause: Duration::from_secs(2),
    });
    let summary = run_pipeline(source, &f.model, &f.table, &TrackerConfig::default(), &opts, &mut sink).unwrap();
    WINDOW.store(false, Ordering::Relaxed);
    let allocs = ALLOCS.load(Ordering::Relaxed);
    let in_publish = PUBLISH_ALLOCS.load(Ordering::Relaxed);
    eprintln!("{summary}");
    eprintln!(
        "allocation window: {COUNTED} frames, {} relocalisations, {allocs} allocations on the frame path and the search thread, \
         {in_publish} inside iceoryx2 publish; page faults: process thread {}, search thread {}",
        sink.relocalised, sink.faults[0], sink.faults[1]
    );
    assert_eq!(summary.reason, RunEnd::Stopped);
    assert!(sink.records.len() >= START + COUNTED);
    let window = &sink.records[START..START + COUNTED];
    let tracked = window.iter().filter(|r| r.result.pose.is_some()).count();
    assert!(
        tracked * 10 >= COUNTED * 8,
        "{tracked} of {COUNTED} tracked in the window"
    );
    assert!(
        sink.relocalised >= 3,
        "{} relocalisations in the window",
        sink.relocalised
    );
    assert_eq!(
        allocs, 0,
        "allocations on the frame path (process, edge workers, sink threads) and the search thread"
    );
    // iceoryx2 0.10 allocates once per sample (pose every frame, status a few times a second).
    assert!(in_publish > 0 && in_publish as u64 <= summary.poses_published + summary.status_published);
    assert_eq!(
        sink.faults,
        [0, 0],
        "pages first written in the window: process, search thread"
    );
}

/// The frames capture posts before the tracker may take one in
/// `the_latest_frame_wins_and_every_drop_is_counted`.
const AHEAD: u64 = 8;
/// A pipeline that made capture wait for the tracker never gets `AHEAD` frames ahead: the process
/// thread stops waiting after this long, and the test fails on nothing dropped (not on a hang).
const AHEAD_BACKSTOP: Duration = Duration::from_secs(60);
/// Whether capture has posted [`AHEAD`] frames (the process thread waits for it, [`wait_for_capture`]).
static AHEAD_GATE: (Mutex<bool>, Condvar) = (Mutex::new(false), Condvar::new());

/// A replay that opens [`AHEAD_GATE`] when it is asked for frame [`AHEAD`]: capture reads a frame,
/// posts it, then reads the next, so by then frames 0 to `AHEAD - 1` were all posted.
struct Ahead(ReplaySource, u64);

impl FrameSource for Ahead {
    fn rig(&self) -> &Rig {
        self.0.rig()
    }
    fn next_frame(&mut self, out: &mut FrameSet) -> Result<bool, SourceError> {
        if self.1 == AHEAD {
            *AHEAD_GATE.0.lock().unwrap() = true;
            AHEAD_GATE.1.notify_all();
        }
        self.1 += 1;
        self.0.next_frame(out)
    }
    fn stats(&self) -> &SourceStats {
        self.0.stats()
    }
}

/// The process thread takes no frame before capture is [`AHEAD`] frames ahead.
fn wait_for_capture(t: PipelineThread) {
    if t == PipelineThread::Process {
        let open = AHEAD_GATE.0.lock().unwrap();
        let _ = AHEAD_GATE
            .1
            .wait_timeout_while(open, AHEAD_BACKSTOP, |open| !*open)
            .unwrap();
    }
}

/// Capture outruns the tracker, by construction rather than by the machine's speed (under load
/// the tracker once kept up with the replay and nothing was dropped): the process thread takes
/// its first frame only once capture has posted [`AHEAD`] frames into a hand-over of one, so at
/// least `AHEAD - 1` were replaced, each counted; after that the replay goes as fast as it decodes.
#[test]
fn the_latest_frame_wins_and_every_drop_is_counted() {
    let _serial = serial();
    let f = fixture();
    let mut opts = options(f, "latest");
    opts.lossless = false;
    opts.pose_service = None;
    opts.status_service = None;
    opts.on_thread_start = Some(wait_for_capture);
    *AHEAD_GATE.0.lock().unwrap() = false;
    let mut sink = Recorder {
        records: Vec::new(),
        tum: None,
        stop_after: None,
    };
    let source: Box<dyn FrameSource + Send> =
        Box::new(Ahead(ReplaySource::open(&f.rec, Pacing::AsFastAsPossible).unwrap(), 0));
    let summary = run_pipeline(source, &f.model, &f.table, &TrackerConfig::default(), &opts, &mut sink).unwrap();
    eprintln!("{summary}");
    assert_eq!(summary.reason, RunEnd::EndOfStream);
    assert_eq!(summary.frames_captured, RENDERED as u64);
    assert!(
        summary.frames_dropped >= AHEAD - 1,
        "{} dropped",
        summary.frames_dropped
    );
    assert_eq!(summary.frames_processed + summary.frames_dropped, RENDERED as u64);
    assert_eq!(sink.records.len() as u64, summary.frames_processed);
    // Sequence numbers are capture order: gaps are the drops. The tracker's first frame is the
    // newest of those posted while it waited, and the last one posted is never dropped.
    assert!(sink.records.windows(2).all(|w| w[0].sequence < w[1].sequence));
    assert!(
        sink.records[0].sequence >= AHEAD - 1,
        "first processed: {}",
        sink.records[0].sequence
    );
    assert_eq!(sink.records.last().unwrap().sequence, RENDERED as u64 - 1);
    for (k, s) in summary.sensors.iter().enumerate() {
        assert_eq!(s.delivered, summary.frames_processed, "sensor {k}");
        assert_eq!(s.overwritten, summary.frames_dropped, "sensor {k}");
        assert_eq!(s.lost(), summary.frames_dropped, "sensor {k}");
    }
    assert_eq!(summary.poses_published, 0);
}

#[test]
fn the_stop_flag_ends_the_run_with_the_trajectory_flushed() {
    let _serial = serial();
    let f = fixture();
    let opts = options(f, "stop");
    let tum_path = f.dir.path().join("stopped.tum");
    let mut sink = Recorder {
        records: Vec::new(),
        tum: Some(TumSink::create(&tum_path).unwrap()),
        stop_after: Some((15, Arc::clone(&opts.stop))),
    };
    let started = Instant::now();
    let summary = run_pipeline(
        replay(&ping_pong(f, 200)),
        &f.model,
        &f.table,
        &TrackerConfig::default(),
        &opts,
        &mut sink,
    )
    .unwrap();
    eprintln!("{summary} (stopped in {:?})", started.elapsed());
    assert_eq!(summary.reason, RunEnd::Stopped);
    assert!(summary.frames_processed < 100, "{}", summary.frames_processed);
    // The sink got every processed frame, and the file holds every tracked one.
    assert_eq!(sink.records.len() as u64, summary.frames_processed);
    let tracked: Vec<Stamped> = sink
        .records
        .iter()
        .filter_map(|r| {
            r.result.pose.map(|pose| Stamped {
                timestamp_ns: r.timestamp_ns,
                pose,
            })
        })
        .collect();
    assert!(!tracked.is_empty());
    let written = load_tum(&tum_path).unwrap();
    assert_eq!(written.len(), tracked.len());
    for (w, t) in written.iter().zip(&tracked) {
        assert_eq!(w.timestamp_ns, t.timestamp_ns);
        assert!((w.pose.translation.vector - t.pose.translation.vector).norm() < 1e-8);
    }
}

#[test]
fn sigterm_stops_the_run_cleanly() {
    let _serial = serial();
    let f = fixture();
    let mut opts = options(f, "sigterm");
    opts.handle_signals = true;
    struct RaiseAfter(usize, usize);
    impl FrameSink for RaiseAfter {
        fn frame(&mut self, _: &FrameRecord) -> Result<(), SinkError> {
            self.0 += 1;
            if self.0 == self.1 {
                signal_hook::low_level::raise(signal_hook::consts::SIGTERM).unwrap();
            }
            Ok(())
        }
    }
    let summary = run_pipeline(
        replay(&ping_pong(f, 200)),
        &f.model,
        &f.table,
        &TrackerConfig::default(),
        &opts,
        &mut RaiseAfter(0, 5),
    )
    .unwrap();
    assert_eq!(summary.reason, RunEnd::Stopped);
    assert!(opts.stop.load(Ordering::Relaxed));
    assert!(summary.frames_processed < 100);
}

/// A sink that cannot take more: the run stops with the sink's own error, whole (its type and
/// message), and the frames it took before stay taken.
#[test]
fn a_sink_error_stops_the_run_and_comes_back_whole() {
    let _serial = serial();
    let f = fixture();
    let opts = options(f, "sinkerr");
    #[derive(Debug)]
    struct Full;
    impl std::fmt::Display for Full {
        fn fmt(&self, out: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            out.write_str("disk full")
        }
    }
    impl std::error::Error for Full {}
    let mut taken = 0usize;
    let mut sink = |_: &FrameRecord| -> Result<(), SinkError> {
        taken += 1;
        if taken == 3 {
            return Err(Box::new(Full));
        }
        Ok(())
    };
    let err = run_pipeline(
        replay(&ping_pong(f, 200)),
        &f.model,
        &f.table,
        &TrackerConfig::default(),
        &opts,
        &mut sink,
    )
    .unwrap_err();
    match err {
        RunError::Sink(e) => {
            assert!(e.is::<Full>(), "the sink's error type is kept: {e:?}");
            assert_eq!(e.to_string(), "disk full");
        }
        other => panic!("expected the sink's error, got {other}"),
    }
    assert_eq!(taken, 3, "no frame is handed over after the sink failed");
}

#[test]
fn a_search_volume_without_a_valid_node_says_so_on_the_status() {
    let _serial = serial();
    let f = fixture();
    let mut opts = options(f, "widened");
    // Twenty metres above the lab: no valid node within the hint's 0.5 m.
    let mut centre = f.hint.centre;
    centre.z += 20.0;
    opts.run.hint = Some(SearchVolume {
        centre,
        diameter_m: Some(0.5),
    });
    opts.run.max_frames = Some(1);
    let mut cfg = TrackerConfig::default();
    cfg.budgets.status_interval_ms = 20.0;
    // No candidate can pass an acceptance test asking more inliers than a frame has edges, so
    // the run stays without a pose (the widened search's one clear candidate would commit).
    cfg.maintenance.min_inliers = 100_000;
    let status = StatusSubscriber::create(opts.status_service.as_deref().unwrap()).unwrap();
    let done = Arc::new(AtomicBool::new(false));
    let statuses = collect(move || status.receive().unwrap(), Arc::clone(&done));
    let mut sink = Recorder {
        records: Vec::new(),
        tum: None,
        stop_after: None,
    };
    let summary = run_pipeline(replay(&f.rec), &f.model, &f.table, &cfg, &opts, &mut sink).unwrap();
    done.store(true, Ordering::Relaxed);
    let statuses: Vec<StatusSample> = statuses.join().unwrap();
    assert!(summary.frames_processed >= 1);
    // The last status (sent at stop) tells why there is no pose: the volume was widened.
    let last = statuses.last().expect("a status at stop");
    assert_eq!(SearchState::try_from(last.search), Ok(SearchState::Widened), "{last:?}");
    assert!(
        last.search_widened_to_m > 0.5,
        "widened to {} m",
        last.search_widened_to_m
    );
    // Before any search the status says so.
    assert_eq!(SearchState::try_from(statuses[0].search), Ok(SearchState::None));
}

/// Runs the fixture's recording through the pipeline with the default config into a
/// [`Recorder`] (stopping after `stop_after` records, if given); prints the summary and
/// returns it.
fn run_recorded(
    f: &Fixture,
    opts: &PipelineOptions,
    stop_after: Option<usize>,
) -> omnitrack::runtime::pipeline::PipelineSummary {
    let mut sink = Recorder {
        records: Vec::new(),
        tum: None,
        stop_after: stop_after.map(|n| (n, Arc::clone(&opts.stop))),
    };
    let summary = run_pipeline(
        replay(&f.rec),
        &f.model,
        &f.table,
        &TrackerConfig::default(),
        opts,
        &mut sink,
    )
    .unwrap();
    eprintln!("{summary}");
    summary
}

/// A lossless run with `max_frames` reads exactly that many frames: every frame read is
/// processed, none dropped or left (it read two ahead, counting one "dropped": "10 processed of
/// 12 captured, 1 dropped", issue 49). A stop leaves what was read unprocessed as `left`, not
/// dropped, and the counts still add up.
#[test]
fn a_lossless_run_reads_exactly_the_frames_it_processes() {
    let _serial = serial();
    let f = fixture();
    let mut opts = options(f, "exact");
    opts.pose_service = None;
    opts.status_service = None;
    opts.run.max_frames = Some(10);
    let summary = run_recorded(f, &opts, None);
    assert_eq!(summary.reason, RunEnd::MaxFrames);
    assert_eq!(
        (
            summary.frames_captured,
            summary.frames_processed,
            summary.frames_dropped,
            summary.frames_left
        ),
        (10, 10, 0, 0)
    );
    for (k, s) in summary.sensors.iter().enumerate() {
        assert_eq!((s.delivered, s.lost()), (10, 0), "sensor {k}: {s:?}");
    }
    let text = summary.to_string();
    assert!(
        text.starts_with("10 frames processed of 10 captured") && text.contains(", 0 dropped;"),
        "{text}"
    );

    // Stopped after 5 records: whatever capture had read beyond them is left, never dropped.
    let opts = options(f, "exact-stop");
    let summary = run_recorded(f, &opts, Some(5));
    assert_eq!(summary.reason, RunEnd::Stopped);
    assert_eq!(summary.frames_dropped, 0);
    assert_eq!(
        summary.frames_captured,
        summary.frames_processed + summary.frames_left,
        "{summary}"
    );
    for (k, s) in summary.sensors.iter().enumerate() {
        assert_eq!(s.overwritten, 0, "sensor {k}: {s:?}");
        assert_eq!(s.delivered + s.left, summary.frames_captured, "sensor {k}: {s:?}");
    }
}

/// A search longer than a second is reported to the sink, on the sink's thread, about once a
/// second while it runs: never before its first second, never twice within a second, its work
/// growing; and not after it ends.
#[test]
fn a_long_search_reports_its_progress_about_once_a_second() {
    let _serial = serial();
    let f = fixture();
    let mut opts = options(f, "progress");
    opts.pose_service = None;
    opts.status_service = None;
    // The whole model, with a budget of 3 s of the reference machine's time (6 s of one core's
    // work, its lanes on two cores): seconds on any machine (half that took 1.16 s of the debug
    // build's time once the grid skipped sensors, under the 1.2 s this test needs).
    opts.run.hint = None;
    opts.run.max_frames = Some(2);
    let mut cfg = TrackerConfig::default();
    cfg.initialisation.whole_model_time_budget_ms = 3000.0;

    struct Progress {
        started: Instant,
        calls: Vec<(Instant, omnitrack::runtime::pipeline::SearchSnapshot)>,
        records: usize,
        sink_thread: Option<std::thread::ThreadId>,
        wrong_thread: bool,
    }
    impl FrameSink for Progress {
        fn frame(&mut self, _: &FrameRecord) -> Result<(), SinkError> {
            self.records += 1;
            Ok(())
        }
        fn search_progress(&mut self, p: &omnitrack::runtime::pipeline::SearchSnapshot) {
            let me = std::thread::current().id();
            self.wrong_thread |= self.sink_thread.is_some_and(|t| t != me);
            self.calls.push((Instant::now(), *p));
        }
    }
    let mut sink = Progress {
        started: Instant::now(),
        calls: Vec::new(),
        records: 0,
        sink_thread: Some(std::thread::current().id()),
        wrong_thread: false,
    };
    let summary = run_pipeline(replay(&f.rec), &f.model, &f.table, &cfg, &opts, &mut sink).unwrap();
    let took = sink.started.elapsed();
    let search = summary.tracker.first_search.expect("a search ran");
    eprintln!(
        "{} progress calls over a {search:?} search ({took:?} in all): {:?}",
        sink.calls.len(),
        sink.calls
            .iter()
            .map(|(_, p)| (p.elapsed, p.work_done))
            .collect::<Vec<_>>()
    );
    assert!(!sink.wrong_thread, "progress reported off the sink's thread");
    assert!(search > Duration::from_millis(1200), "{search:?}: too short to test");
    assert!(!sink.calls.is_empty(), "a {search:?} search said nothing");
    // About once a second: at most one per started second of the search, and one in its last
    // two seconds at the latest.
    assert!(
        sink.calls.len() as f64 <= search.as_secs_f64() + 1.0,
        "{} calls in {search:?}",
        sink.calls.len()
    );
    for w in sink.calls.windows(2) {
        assert!(
            w[1].0 - w[0].0 >= Duration::from_millis(950),
            "two calls {:?} apart",
            w[1].0 - w[0].0
        );
        assert!(w[1].1.work_done >= w[0].1.work_done && w[1].1.elapsed > w[0].1.elapsed);
    }
    for (_, p) in &sink.calls {
        assert!(p.elapsed >= Duration::from_secs(1), "{p:?}");
        assert_eq!(p.kind, Some(omnitrack::publish::SearchKind::Initialisation), "{p:?}");
        assert_eq!(p.diameter_m, None, "the whole model: {p:?}");
        assert_eq!(p.work_budget, 3_000_000, "{p:?}");
        assert!(p.work_done <= 2 * p.work_budget, "{p:?}");
    }
    assert!(sink.calls.last().unwrap().1.work_done > 0);
    assert_eq!(sink.records, 2);
}

/// A pose service that cannot be opened (here: the name is taken by a service of another
/// message type) stops the run before its first frame, and the summary says why; with
/// `require_services` off the run goes on without it.
#[test]
fn a_service_that_cannot_be_opened_stops_the_run_before_its_first_frame() {
    let _serial = serial();
    let f = fixture();
    let mut opts = options(f, "taken");
    let taken = opts.pose_service.clone().unwrap();
    let _other = omnitrack::publish::StatusPublisher::create(&taken).unwrap();
    opts.run.max_frames = Some(3);
    let cfg = TrackerConfig::default();
    let mut sink = Recorder {
        records: Vec::new(),
        tum: None,
        stop_after: None,
    };
    let summary = run_pipeline(replay(&f.rec), &f.model, &f.table, &cfg, &opts, &mut sink).unwrap();
    assert!(summary.publisher_error.is_some());
    assert_eq!(summary.frames_processed, 0);
    opts.require_services = false;
    let summary = run_pipeline(replay(&f.rec), &f.model, &f.table, &cfg, &opts, &mut sink).unwrap();
    assert!(summary.publisher_error.is_some());
    assert_eq!(summary.frames_processed, 3);
}

/// (thread name as the kernel keeps it, SCHED_FIFO?, real-time priority) of every thread of
/// this process, from `/proc/self/task/*/stat` (fields 40 `rt_priority` and 41 `policy`).
fn thread_policies() -> Vec<(String, bool, u32)> {
    let mut out = Vec::new();
    for task in std::fs::read_dir("/proc/self/task").unwrap().flatten() {
        let (Ok(comm), Ok(stat)) = (
            std::fs::read_to_string(task.path().join("comm")),
            std::fs::read_to_string(task.path().join("stat")),
        ) else {
            continue; // the thread ended meanwhile
        };
        // Fields from the third on follow the last ')' (the name may hold spaces and parens).
        let rest: Vec<&str> = stat[stat.rfind(')').unwrap() + 1..].split_whitespace().collect();
        let rt_priority: u32 = rest[40 - 3].parse().unwrap();
        let policy: u32 = rest[41 - 3].parse().unwrap();
        out.push((comm.trim().to_string(), policy == 1, rt_priority));
    }
    out
}

#[test]
fn the_frame_path_runs_at_realtime_priority_where_allowed_and_the_searches_do_not() {
    let _serial = serial();
    let f = fixture();
    let shipped = TrackerConfig::default().budgets.realtime_priority;
    assert!(shipped > 0);
    for (priority, lossless) in [(shipped, false), (0, false), (shipped, true)] {
        let mut cfg = TrackerConfig::default();
        cfg.budgets.realtime_priority = priority;
        let mut opts = options(f, "realtime");
        opts.lossless = lossless;
        opts.pose_service = None;
        opts.status_service = None;
        // The threads are sampled on the fifth frame: a few more are enough.
        opts.run.max_frames = Some(8);
        // Sampled mid-run, from the sink's thread (the caller's: never changed).
        struct Sample(Vec<(String, bool, u32)>, usize);
        impl FrameSink for Sample {
            fn frame(&mut self, _: &FrameRecord) -> Result<(), SinkError> {
                self.1 += 1;
                if self.1 == 5 {
                    self.0 = thread_policies();
                }
                Ok(())
            }
        }
        let mut sink = Sample(Vec::new(), 0);
        // Paced at the recorded rate, so that the capture thread is still there on the fifth
        // frame: as fast as it decodes, latest-wins capture can read the whole recording and
        // end while the first frames are still being tracked.
        let source: Box<dyn FrameSource + Send> = Box::new(ReplaySource::open(&f.rec, Pacing::RealTime).unwrap());
        let summary = run_pipeline(source, &f.model, &f.table, &cfg, &opts, &mut sink).unwrap();
        eprintln!(
            "realtime_priority {priority}, lossless {lossless}: {} — {:?}",
            summary.realtime, sink.0
        );
        let named = |prefix: &str| -> Vec<(bool, u32)> {
            sink.0
                .iter()
                .filter(|(n, ..)| n.starts_with(prefix))
                .map(|&(_, fifo, p)| (fifo, p))
                .collect()
        };
        let tracking = [named("omnitrack-proc"), named("edges-")].concat();
        let capture = named("omnitrack-capt");
        assert!(tracking.len() >= 2 && !capture.is_empty(), "{:?}", sink.0);
        let frame_path = [tracking.clone(), capture.clone()].concat();
        let searches = named("omnitrack-sear");
        assert!(!searches.is_empty(), "{:?}", sink.0);
        assert!(searches.iter().all(|&s| s == (false, 0)), "searches: {searches:?}");
        let me = thread_policies();
        assert!(
            me.iter()
                .filter(|(n, ..)| n.starts_with("the_frame_path"))
                .all(|&(_, fifo, _)| !fifo),
            "the caller's thread is left alone"
        );
        match &summary.realtime {
            Realtime::Granted(p) => {
                assert!(!lossless);
                assert_eq!(*p, priority);
                assert!(tracking.iter().all(|&t| t == (true, u32::from(*p))), "{tracking:?}");
                assert!(
                    capture.iter().all(|&t| t == (true, u32::from(upstream_priority(*p)))),
                    "{capture:?}"
                );
            }
            Realtime::Refused { priority: p, reason } => {
                assert!(!lossless);
                assert_eq!(*p, priority);
                assert!(!reason.is_empty());
                assert!(frame_path.iter().all(|&(fifo, _)| !fifo), "{frame_path:?}");
            }
            Realtime::Off | Realtime::Lossless => {
                assert_eq!(summary.realtime == Realtime::Lossless, lossless && priority > 0);
                assert!(priority == 0 || lossless);
                assert!(frame_path.iter().all(|&t| t == (false, 0)), "{frame_path:?}");
            }
        }
    }
}

#[test]
fn frames_without_a_pose_publish_the_last_one_with_its_covariance_grown_for_the_time_since() {
    let _serial = serial();
    let f = fixture();
    const FRAMES: u64 = 60;
    const FROM: u64 = 30;
    const TO: u64 = 32;
    let rec = ping_pong(f, FRAMES as usize);
    let opts = options(f, "blackout");
    let cfg = TrackerConfig::default();
    let subscriber = PoseSubscriber::create(opts.pose_service.as_deref().unwrap()).unwrap();
    let done = Arc::new(AtomicBool::new(false));
    let samples = collect(move || subscriber.receive().unwrap(), Arc::clone(&done));
    // Every sensor dark: nothing to track.
    let inner = ReplaySource::open(&rec, Pacing::AsFastAsPossible).unwrap();
    let source = FailingSensors {
        sensors: 0..inner.rig().sensors.len(),
        inner,
        frames: FROM..TO,
        frame: 0,
    };
    let mut sink = Recorder {
        records: Vec::new(),
        tum: None,
        stop_after: None,
    };
    let source: Box<dyn FrameSource + Send> = Box::new(source);
    let summary = run_pipeline(source, &f.model, &f.table, &cfg, &opts, &mut sink).unwrap();
    done.store(true, Ordering::Relaxed);
    let samples = samples.join().unwrap();
    eprintln!("{summary}");
    assert_eq!(samples.len() as u64, FRAMES);
    let good = &samples[FROM as usize - 1];
    assert_eq!(
        good.pose_status(),
        Ok(TrackerState::Tracking),
        "tracking before the blackout"
    );
    let speed = cfg.motion.max_speed_m_s;
    let turn = cfg.motion.max_turn_rate_deg_s.to_radians();
    let mut last_sd = 0.0;
    for s in &samples[FROM as usize..TO as usize] {
        assert_ne!(s.pose_status(), Ok(TrackerState::Tracking));
        assert_eq!(s.position_m, good.position_m);
        assert_eq!(s.rotation_wxyz, good.rotation_wxyz);
        let dt = (s.timestamp_ns - good.timestamp_ns) as f64 * 1e-9;
        for k in 0..3 {
            let (p, r) = (7 * k, 7 * (k + 3));
            assert!((s.covariance[p] - (good.covariance[p] + (speed * dt).powi(2))).abs() < 1e-9);
            assert!((s.covariance[r] - (good.covariance[r] + (turn * dt).powi(2))).abs() < 1e-9);
        }
        let sd = s.covariance[0].sqrt();
        assert!(sd.is_finite() && sd > last_sd, "σx {sd} m after {dt} s");
        last_sd = sd;
    }
    // Tracking again after it.
    assert!(samples[TO as usize..]
        .iter()
        .any(|s| s.pose_status() == Ok(TrackerState::Tracking)));
}
