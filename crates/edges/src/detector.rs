//! The [`EdgeDetector`]: every sensor of a rig on buffers allocated once, spread over a
//! persistent pool of worker threads.
//!
//! In: the rig, the [`EdgeConfig`] and [`EdgeParams`] at start-up; a [`FrameSet`] (or one
//! [`SensorImage`]) per call. Out: the frame's [`Edge`]s sensor by sensor, strongest first within
//! a sensor, and each sensor's [`ExtractionStats`]. Every buffer is sized and written through in
//! [`EdgeDetector::new`]; [`EdgeDetector::detect`] allocates nothing. Sensors are taken off a
//! shared counter by the workers and the calling thread, fed through bounded crossbeam channels.

use crate::cpu::thread_cpu_time;
use crate::edge::Edge;
use crate::hue::HueTable;
use crate::params::EdgeParams;
use crate::sensor::{self, ExtractionStats, Scratch, Workspace};
use crossbeam::channel::{bounded, Receiver, Sender};
use omnitrack_config::EdgeConfig;
use omnitrack_core::frame::{FrameSet, SensorImage};
use omnitrack_core::rig::Rig;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

/// Unit ray (sensor frame) of every pixel of a lens, shared by the sensors that use the lens.
type RayTable = Arc<[[f32; 3]]>;

/// A frame's images, handed to the workers as a raw pointer: `detect` does not return before
/// every worker has reported that it is done with them.
#[derive(Clone, Copy)]
struct Job {
    images: *const SensorImage,
    count: usize,
}

// SAFETY: the pointer is only dereferenced while `EdgeDetector::detect` holds the borrow of the
// frame and waits for every worker's completion message; `SensorImage` is `Sync`.
unsafe impl Send for Job {}

struct Shared {
    workspaces: Box<[Mutex<Workspace>]>,
    /// One set of scratch buffers per thread (the caller's first), lent to each sensor it runs.
    scratch: Box<[Mutex<Scratch>]>,
    next: AtomicUsize,
    /// CPU time (ns) the workers spent on the current frame, added by each before it reports
    /// that it is done (the channel orders the add before the caller's read).
    worker_cpu_ns: AtomicU64,
}

impl Shared {
    /// Takes sensors off the shared counter until none is left, on thread `t`'s scratch.
    fn work(&self, job: Job, t: usize) {
        let mut scratch = self.scratch[t].lock().unwrap_or_else(|e| e.into_inner());
        loop {
            let k = self.next.fetch_add(1, Ordering::Relaxed);
            if k >= self.workspaces.len() {
                break;
            }
            let mut ws = self.workspaces[k].lock().unwrap_or_else(|e| e.into_inner());
            if k < job.count {
                // SAFETY: see `Job`.
                let img = unsafe { &*job.images.add(k) };
                ws.run(img, &mut scratch);
            } else {
                ws.edges.clear();
            }
        }
    }
}

/// Crossbeam sets up a thread-local context (and std a thread-local destructor list) the first
/// time a thread really blocks on a channel, and the list of waiting threads of a channel the
/// first time one waits on it, both of which allocate. Frames usually arrive while the threads
/// are still spinning, so that first block could fall on any later frame: force it at start-up,
/// on the thread that will wait, with a waiter registered on the empty `rx` and taken off at
/// once (`try_select` registers without waiting, where a timed receive registers only if its
/// spinning ends before the deadline). The search's threads use it too.
pub fn warm_up_blocking<T>(rx: &Receiver<T>) {
    let mut waiting = crossbeam::channel::Select::new();
    waiting.recv(rx);
    if let Ok(op) = waiting.try_select() {
        let _ = op.recv(rx);
    }
}

struct Worker {
    jobs: Option<Sender<Job>>,
    handle: Option<JoinHandle<()>>,
}

/// Edge + hue extraction for every sensor of a rig, on buffers allocated once.
pub struct EdgeDetector {
    shared: Arc<Shared>,
    workers: Vec<Worker>,
    done: Receiver<()>,
    all: Vec<Edge>,
    /// all[offsets[k]..offsets[k + 1]] are sensor k's edges.
    offsets: Vec<usize>,
    stats: Vec<ExtractionStats>,
    /// CPU time of the last [`EdgeDetector::detect`], every thread's.
    last_cpu: Duration,
}

impl EdgeDetector {
    /// Sizes every buffer from the rig and the config, with default [`EdgeParams`].
    pub fn new(rig: &Rig, config: &EdgeConfig) -> EdgeDetector {
        Self::with_params(rig, config, EdgeParams::default())
    }

    /// The detector a tracker needs ([`EdgeParams::for_tracking`]): the edges of
    /// [`EdgeDetector::new`], without the a-contrario test of the pieces each edge shows, which
    /// only a line detector's user reads (`omnitrack edges`, the YorkUrban benchmark). The test
    /// was 7 % of the detector's CPU on the `lab` frames (docs/edges.md).
    pub fn for_tracking(rig: &Rig, config: &EdgeConfig) -> EdgeDetector {
        Self::with_params(rig, config, EdgeParams::for_tracking())
    }

    pub fn with_params(rig: &Rig, config: &EdgeConfig, params: EdgeParams) -> EdgeDetector {
        let hue = Arc::new(HueTable::new(config.min_hue_saturation, config.min_hue_value));
        let mut tables: Vec<(omnitrack_core::geometry::Lens, u32, u32, RayTable)> = Vec::new();
        let max_edges = config.max_edges_per_sensor as usize;
        let workspaces: Box<[Mutex<Workspace>]> = rig
            .sensors
            .iter()
            .map(|s| {
                let rays = match tables
                    .iter()
                    .find(|t| t.0 == s.lens && t.1 == s.width && t.2 == s.height)
                {
                    Some(t) => t.3.clone(),
                    None => {
                        let t = sensor::ray_table(s);
                        tables.push((s.lens, s.width, s.height, t.clone()));
                        t
                    }
                };
                Mutex::new(Workspace::new(
                    s,
                    rays,
                    hue.clone(),
                    params,
                    config.hue_strip_width_px as usize,
                    max_edges,
                    config.min_edge_length_deg,
                ))
            })
            .collect();
        let n = workspaces.len();
        let threads = if params.threads == 0 {
            std::thread::available_parallelism().map_or(1, |p| p.get()).min(2)
        } else {
            params.threads
        }
        .clamp(1, n.max(1));
        let max_width = rig.sensors.iter().map(|s| s.width as usize).max().unwrap_or(0);
        let max_pixels = rig.max_pixels();
        let shared = Arc::new(Shared {
            workspaces,
            scratch: (0..threads)
                .map(|_| {
                    Mutex::new(Scratch::new(
                        max_width,
                        max_pixels,
                        &params,
                        config.hue_strip_width_px as usize,
                    ))
                })
                .collect(),
            next: AtomicUsize::new(0),
            worker_cpu_ns: AtomicU64::new(0),
        });
        let (done_tx, done) = bounded::<()>(threads);
        let workers = (1..threads)
            .map(|k| {
                let (tx, rx) = bounded::<Job>(1);
                let shared = shared.clone();
                let done_tx = done_tx.clone();
                let handle = std::thread::Builder::new()
                    .name(format!("edges-{k}"))
                    .spawn(move || {
                        warm_up_blocking(&rx);
                        let _ = done_tx.send(());
                        while let Ok(job) = rx.recv() {
                            let started = thread_cpu_time();
                            shared.work(job, k);
                            let spent = (thread_cpu_time() - started).as_nanos() as u64;
                            shared.worker_cpu_ns.fetch_add(spent, Ordering::Relaxed);
                            if done_tx.send(()).is_err() {
                                break;
                            }
                        }
                    })
                    .expect("spawn an edge worker thread");
                Worker {
                    jobs: Some(tx),
                    handle: Some(handle),
                }
            })
            .collect();
        // Wait until every worker is up, and set up this thread's channel context now.
        for _ in 1..threads {
            let _ = done.recv();
        }
        warm_up_blocking(&done);
        EdgeDetector {
            shared,
            workers,
            done,
            all: omnitrack_core::memory::resident(Vec::with_capacity(n * max_edges)),
            offsets: vec![0; n + 1],
            stats: vec![ExtractionStats::default(); n],
            last_cpu: Duration::ZERO,
        }
    }

    /// Number of threads working on a frame (the caller's included).
    pub fn threads(&self) -> usize {
        self.workers.len() + 1
    }

    /// Detects the edges of every sensor of the frame; returns them all, sensor by sensor,
    /// strongest first within a sensor. Invalid images, images of the wrong size and sensors
    /// missing from the frame yield no edges. Allocates nothing (call it from the thread that
    /// built the detector: on another thread crossbeam sets up its per-thread context, once, at
    /// the first blocking wait).
    pub fn detect(&mut self, frame: &FrameSet) -> &[Edge] {
        let started = thread_cpu_time();
        self.shared.worker_cpu_ns.store(0, Ordering::Relaxed);
        let images = frame.sensors();
        let job = Job {
            images: images.as_ptr(),
            count: images.len(),
        };
        self.shared.next.store(0, Ordering::Relaxed);
        let mut sent = 0;
        for w in &self.workers {
            if let Some(tx) = &w.jobs {
                if tx.send(job).is_ok() {
                    sent += 1;
                }
            }
        }
        self.shared.work(job, 0);
        for _ in 0..sent {
            // A worker that died (panicked) drops its sender only after it stopped touching the
            // frame, so returning afterwards is still sound.
            if self.done.recv().is_err() {
                panic!("an edge worker thread died");
            }
        }
        self.collect();
        let workers = Duration::from_nanos(self.shared.worker_cpu_ns.load(Ordering::Relaxed));
        self.last_cpu = thread_cpu_time().saturating_sub(started) + workers;
        &self.all
    }

    /// CPU time (thread clocks) the last [`EdgeDetector::detect`] cost: the calling thread's
    /// over the whole call (its share of the sensors, handing out the frame, gathering the
    /// edges) plus each worker's on that frame. Zero before the first.
    pub fn last_cpu(&self) -> Duration {
        self.last_cpu
    }

    /// Detects the edges of one sensor image on the calling thread.
    pub fn detect_sensor(&mut self, image: &SensorImage) -> &[Edge] {
        let k = image.sensor();
        assert!(k < self.shared.workspaces.len(), "sensor {k} is not in the rig");
        {
            let mut ws = self.shared.workspaces[k].lock().unwrap_or_else(|e| e.into_inner());
            let mut scratch = self.shared.scratch[0].lock().unwrap_or_else(|e| e.into_inner());
            ws.run(image, &mut scratch);
        }
        self.collect();
        self.sensor_edges(k)
    }

    fn collect(&mut self) {
        self.all.clear();
        for (k, ws) in self.shared.workspaces.iter().enumerate() {
            let ws = ws.lock().unwrap_or_else(|e| e.into_inner());
            self.offsets[k] = self.all.len();
            self.all.extend_from_slice(&ws.edges);
            self.stats[k] = ws.stats;
        }
        let n = self.shared.workspaces.len();
        self.offsets[n] = self.all.len();
    }

    /// Edges of the last detection.
    pub fn edges(&self) -> &[Edge] {
        &self.all
    }

    /// Sensor `k`'s edges of the last detection.
    pub fn sensor_edges(&self, k: usize) -> &[Edge] {
        &self.all[self.offsets[k]..self.offsets[k + 1]]
    }

    /// Sensor `k`'s counters of the last detection.
    pub fn sensor_stats(&self, k: usize) -> ExtractionStats {
        self.stats[k]
    }
}

impl Drop for EdgeDetector {
    fn drop(&mut self) {
        for w in &mut self.workers {
            w.jobs = None;
        }
        for w in &mut self.workers {
            if let Some(h) = w.handle.take() {
                let _ = h.join();
            }
        }
    }
}
