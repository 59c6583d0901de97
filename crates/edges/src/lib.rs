//! Edge and hue extraction for the rig's sensors (Koch–Teller §4.2, §4.2.1).
//!
//! In: a [`FrameSet`] (one RGB8 image per sensor). Out: per sensor, at most
//! `EdgeConfig::max_edges_per_sensor` [`Edge`]s (the strongest), each the plane through its
//! sensor's optical centre that contains a straight 3D edge (rig frame), its pixel and ray end
//! points, angular length, strength, [`HueSignature`] and gaps (where merging bridged
//! collinear pieces that the image does not join).
//!
//! Per sensor: per colour channel, integer Sobel gradients on the channel smoothed along the
//! derivative's cross axis only (3 px wide across an edge, so a door or window reveal's two edges
//! 2–3 px apart stay apart), the strongest channel kept per pixel → non-maximum suppression →
//! edgels linked into chains (direction within ~50°) → sub-pixel edgels (Gaussian peak: parabola
//! through the log magnitudes across the gradient) unprojected to unit rays through a per-pixel
//! ray table built at start-up → planes fitted to the rays (smallest eigenvector of Σ w r rᵀ, w
//! the gradient magnitude; outliers beyond 2.5 RMS refitted out), chains split where they bend off
//! a great circle or where two planes fit a piece far better than one (two lines a pixel or two
//! apart, end to end or side by side), and neighbouring collinear pieces merged, also across
//! chains (short pieces' normals are loose, so candidates within 5° are tried; the merged fit
//! decides, under the same two-line test) → hue strips on both sides. Fisheye curvature costs
//! nothing: rays, not pixels, are fitted.
//!
//! Memory is fixed: every buffer is sized in [`EdgeDetector::new`] from the rig (resolution) and
//! the [`EdgeConfig`] (edges per sensor) and written through there
//! (`omnitrack_core::memory::resident`); [`EdgeDetector::detect`] allocates nothing, nor takes
//! memory the detector did not hold from the start. Sensors are
//! spread over a persistent pool of worker threads (the calling thread works too) fed through
//! bounded crossbeam channels.
//!
//! A bright square on a dark image from one 50° pinhole gives its four sides:
//!
//! ```
//! use omnitrack_config::EdgeConfig;
//! use omnitrack_core::{FrameSet, Rig};
//! use omnitrack_edges::EdgeDetector;
//!
//! let rig = Rig::from_toml_str(
//!     "name = \"one\"\n[[sensors]]\nid = 0\nresolution = [640, 480]\nmodel = \"pinhole\"\n\
//!      intrinsics = [686.0, 686.0, 319.5, 239.5]\nrotation_wxyz = [0.5, -0.5, 0.5, -0.5]\n\
//!      translation_m = [0.0, 0.0, 0.0]\n",
//!     "one.toml",
//! )?;
//! let mut frame = FrameSet::for_rig(&rig);
//! let image = frame.sensor_mut(0);
//! for (k, px) in image.pixels_mut().chunks_mut(3).enumerate() {
//!     let (x, y) = (k % 640, k / 640);
//!     let inside = (220..420).contains(&x) && (140..340).contains(&y);
//!     px.fill(if inside { 230 } else { 20 });
//! }
//! image.timestamp_ns = 1;
//! image.valid = true;
//! let mut detector = EdgeDetector::new(&rig, &EdgeConfig::default());
//! let edges = detector.detect(&frame);
//! // The square's sides, each about 200 px (16°) long.
//! let long: Vec<_> = edges.iter().filter(|e| e.length_rad > 0.2).collect();
//! assert_eq!(long.len(), 4, "{edges:?}");
//! # Ok::<(), omnitrack_core::rig::RigError>(())
//! ```

mod contrario;
mod gradient;
mod hue;
mod sensor;

pub use hue::{hue_of, HueSignature};
pub use sensor::ExtractionStats;

use crossbeam::channel::{bounded, Receiver, Sender};
use hue::HueTable;
use nalgebra::{Point2, Vector3};
use omnitrack_config::EdgeConfig;
use omnitrack_core::frame::{FrameSet, SensorImage};
use omnitrack_core::geometry::EdgePlane;
use omnitrack_core::rig::Rig;
use sensor::Workspace;
use std::fmt::Write as _;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

/// Unit ray (sensor frame) of every pixel of a lens, shared by the sensors that use the lens.
type RayTable = Arc<[[f32; 3]]>;

/// Gaps an [`Edge`] remembers: the widest, when merging bridged more.
pub const MAX_GAPS: usize = 4;

/// One observed straight edge of one sensor image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Edge {
    /// Sensor id.
    pub sensor: u8,
    /// Plane through the sensor's centre containing the edge, rig frame; `ends` are the unit
    /// rays of the two end points (in the plane); the normal is oriented as `ends[0] × ends[1]`.
    pub plane: EdgePlane,
    /// Pixel positions of the two ends on the image as it is (on the curved fisheye edge).
    pub px: [Point2<f64>; 2],
    /// Angle between the end rays (rad).
    pub length_rad: f64,
    /// Sum of the edgels' gradient magnitudes / 64 ≈ contrast (grey levels) × length (edgels).
    pub strength: f32,
    pub hue: HueSignature,
    /// Which side is brighter: +1 the left (as for [`HueSignature`]), −1 the right, 0 neither
    /// clearly (fewer than three in four edgels agree). Unlike hue it exists on a grey image,
    /// and like hue it survives a change of exposure.
    pub polarity: i8,
    /// Edgels the plane was fitted to.
    pub edgels: u32,
    /// RMS angle (rad) of the edgels' rays off the fitted plane.
    pub rms_rad: f32,
    /// Where the image does not show the edge: the stretches (rad from `ends[0]` along the
    /// edge, in order) that merging bridged between collinear pieces, such as a line broken by
    /// an occluder or by noise, or plain wall between two window tops. The plane is fitted to
    /// the pieces alone. At most the [`MAX_GAPS`] widest (the first `n_gaps`); see
    /// [`Edge::pieces`].
    pub gaps: [[f32; 2]; MAX_GAPS],
    pub n_gaps: u8,
    /// The pieces ([`Edge::pieces`]) that pass LSD's a-contrario test (rad from `ends[0]`, in
    /// order; the first `n_shown`): along each, the image gradient is across the line at more
    /// pixels than chance explains (number of false alarms below 1, [`EdgeParams::piece_nfa`]),
    /// each trimmed to its first and last such pixel with [`EdgeParams::piece_trim`]. A piece
    /// that fails is left out (the image does not show it as a line); none may pass. The edge
    /// itself, its plane and its gaps do not depend on it. See [`Edge::shown`].
    pub shown: [[f32; 2]; MAX_GAPS + 1],
    pub n_shown: u8,
}

impl Edge {
    /// The stretches the image does not show (see [`Edge::gaps`](Edge#structfield.gaps)).
    pub fn gaps(&self) -> &[[f32; 2]] {
        &self.gaps[..usize::from(self.n_gaps).min(MAX_GAPS)]
    }

    /// The stretches the image shows, from `ends[0]` to `ends[1]` (rad along the edge): one for
    /// an edge without gaps.
    pub fn pieces(&self) -> impl Iterator<Item = [f64; 2]> + '_ {
        let gaps = self.gaps();
        (0..=gaps.len()).map(move |k| {
            let from = if k == 0 { 0.0 } else { f64::from(gaps[k - 1][1]) };
            let to = gaps.get(k).map_or(self.length_rad, |g| f64::from(g[0]));
            [from, to]
        })
    }

    /// The pieces the image shows as lines, meaningful by LSD's a-contrario test (see
    /// [`Edge::shown`](Edge#structfield.shown)): a subset of [`Edge::pieces`], maybe trimmed;
    /// empty when none is.
    pub fn shown(&self) -> &[[f32; 2]] {
        &self.shown[..usize::from(self.n_shown).min(MAX_GAPS + 1)]
    }

    /// The unit ray (rig frame, from the sensor's centre) `t` rad from `ends[0]` along the edge.
    pub fn ray_at(&self, t: f64) -> Vector3<f64> {
        let e0 = self.plane.ends[0].into_inner();
        let towards = self.plane.normal.cross(&e0);
        e0 * t.cos() + towards * t.sin()
    }
}

/// Smoothing of each colour channel before the Sobel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Smoothing {
    /// None: the plain 3×3 Sobel (edges 2 px apart stay apart, but noisier directions).
    None,
    /// The binomial [1 2 1]² (a 5×5 derivative: steadier directions and sub-pixel positions,
    /// but edges closer than ~3 px blend into one).
    Full,
    /// [1 2 1] along the derivative's cross axis only: each derivative is 3 px wide across
    /// (near-parallel edges 2–3 px apart stay apart) and 5 px long along the edge.
    Along,
}

/// Tuning of the detector beyond [`EdgeConfig`]; `Default` is what the benchmarks measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdgeParams {
    /// Minimum L1 gradient magnitude |gx| + |gy| of an edgel: Sobel of the binomially smoothed
    /// grey image ×16 (a step of h grey levels gives ≈ 4h·16 = 64h across its peak).
    pub gradient_threshold: u16,
    /// Smoothing of each channel before the Sobel.
    pub smoothing: Smoothing,
    /// Chains shorter than this (edgels) are dropped.
    pub min_chain_edgels: usize,
    /// A chain is split where a ray deviates more than this (rad) from the great circle of the
    /// piece's end rays; pieces are merged when all their rays stay within it.
    pub split_tolerance_rad: f64,
    /// Pieces of different chains merge when their normals agree within this (rad)…
    pub merge_angle_rad: f64,
    /// …and the angular gap between them is at most this (rad)…
    pub merge_gap_rad: f64,
    /// …and the pieces cover at least this fraction of the merged edge's span (0: no check)…
    pub merge_min_support: f64,
    /// …and the image shows the line along at least this share of the gap between them (a
    /// gradient across the line within a pixel; 0: no check). Off by default: at 0.9 it raises
    /// YorkUrban precision from 17 to 30 % and recall from 63 to 68 %, and synthetic recall on
    /// most rows, but costs grey and very noisy frames 2–3 points and on the real ZInD
    /// panoramas two hinted runs settled 0.3 and 0.8 m off instead of within 10 cm (docs/decisions.md).
    pub merge_gap_evidence: f64,
    /// Distance (px) from the edge to the first pixel of each hue strip.
    pub hue_strip_offset_px: f32,
    /// At most this many positions along an edge are sampled for hue (evenly spread).
    pub hue_samples_per_edge: usize,
    /// Threads working on a frame, the calling thread included (0: available cores, at most 2).
    pub threads: usize,
    /// The two-line test, off at 0: a chain piece is cut, and two pieces are not merged, where
    /// one plane leaves more residual than two by more than noise explains and by more than
    /// lines ~2 × this × `split_tolerance_rad` apart would (0.3: ~0.6 px at the default). It
    /// keeps a wall corner and a box edge continuing it a pixel or two aside from becoming one
    /// tilted edge, and raises `lab` recall from 92.6 to 97.3 % (docs/edges.md). Below ~0.3 the pixel
    /// staircases of aliased images start to split single lines.
    pub two_line_excess: f64,
    /// Validate each piece of an edge (the CSV's `pieces`, [`Edge::shown`]) a contrario, as LSD
    /// does (Grompone von Gioi et al., IPOL 2012): keep it only where the number of pixels along
    /// it whose gradient is across the line (within 22.5°) makes its number of false alarms
    /// below 1. Off: every piece is shown. The edges themselves do not change.
    pub piece_nfa: bool,
    /// With `piece_nfa`, trim each piece to its first and last pixel whose gradient is across
    /// the line before the test (which only lowers its number of false alarms).
    pub piece_trim: bool,
}

impl Default for EdgeParams {
    fn default() -> Self {
        EdgeParams {
            gradient_threshold: 640,
            smoothing: Smoothing::Along,
            min_chain_edgels: 8,
            split_tolerance_rad: 0.2f64.to_radians(),
            merge_angle_rad: 5.0f64.to_radians(),
            merge_gap_rad: 10.0f64.to_radians(),
            merge_min_support: 0.0,
            merge_gap_evidence: 0.0,
            hue_strip_offset_px: 2.0,
            hue_samples_per_edge: 48,
            threads: 0,
            two_line_excess: 0.3,
            piece_nfa: true,
            piece_trim: true,
        }
    }
}

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
    next: AtomicUsize,
}

impl Shared {
    /// Takes sensors off the shared counter until none is left.
    fn work(&self, job: Job) {
        loop {
            let k = self.next.fetch_add(1, Ordering::Relaxed);
            if k >= self.workspaces.len() {
                break;
            }
            let mut ws = self.workspaces[k].lock().unwrap_or_else(|e| e.into_inner());
            if k < job.count {
                // SAFETY: see `Job`.
                let img = unsafe { &*job.images.add(k) };
                ws.run(img);
            } else {
                ws.edges.clear();
            }
        }
    }
}

/// Crossbeam sets up a thread-local context (and std a thread-local destructor list) the first
/// time a thread really blocks on a channel, and the list of waiting threads of a channel the
/// first time one waits on it, both of which allocate. Frames usually arrive while the threads
/// are still spinning, so that first block could fall on any later frame: force it here, at
/// start-up, with a waiter registered on the empty `rx` and taken off at once (`try_select`
/// registers without waiting, where a timed receive registers only if its spinning ends before
/// the deadline).
fn warm_up_blocking<T>(rx: &Receiver<T>) {
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
}

impl EdgeDetector {
    /// Sizes every buffer from the rig and the config, with default [`EdgeParams`].
    pub fn new(rig: &Rig, config: &EdgeConfig) -> EdgeDetector {
        Self::with_params(rig, config, EdgeParams::default())
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
        let shared = Arc::new(Shared {
            workspaces,
            next: AtomicUsize::new(0),
        });
        let threads = if params.threads == 0 {
            std::thread::available_parallelism().map_or(1, |p| p.get()).min(2)
        } else {
            params.threads
        }
        .clamp(1, n.max(1));
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
                            shared.work(job);
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
        self.shared.work(job);
        for _ in 0..sent {
            // A worker that died (panicked) drops its sender only after it stopped touching the
            // frame, so returning afterwards is still sound.
            if self.done.recv().is_err() {
                panic!("an edge worker thread died");
            }
        }
        self.collect();
        &self.all
    }

    /// Detects the edges of one sensor image on the calling thread.
    pub fn detect_sensor(&mut self, image: &SensorImage) -> &[Edge] {
        let k = image.sensor();
        assert!(k < self.shared.workspaces.len(), "sensor {k} is not in the rig");
        {
            let mut ws = self.shared.workspaces[k].lock().unwrap_or_else(|e| e.into_inner());
            ws.run(image);
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

/// Header of the `omnitrack edges` CSV (docs/interfaces.md), then our extra columns. `pieces` is
/// empty for an edge the image shows whole (one piece, passing the a-contrario test untrimmed,
/// [`Edge::shown`]); `none` where the image shows no piece of it as a line; otherwise the pixel
/// ends of the pieces it does show, from end 1 to end 2, as `u1 v1 u2 v2` groups separated by
/// `;` (the edge's own ends are those of the whole span its plane was fitted over, across its
/// [`Edge::gaps`]).
pub const EDGES_CSV_HEADER: &str = "u1,v1,u2,v2,hue_left_mean,hue_left_var,hue_right_mean,hue_right_var,\
sensor,length_deg,strength,nx,ny,nz,hue_left_kept,hue_right_kept,pieces";

/// The `omnitrack edges` CSV of some edges (header line included). Hue means are in [0, 1) or
/// `NaN` for a strip without any pixel of meaningful hue; the normal is in the rig frame.
pub fn edges_csv(edges: &[Edge], rig: &Rig) -> String {
    let mut s = String::with_capacity(64 + edges.len() * 160);
    s.push_str(EDGES_CSV_HEADER);
    s.push('\n');
    for e in edges {
        let n = e.plane.normal;
        let h = &e.hue;
        let _ = write!(
            s,
            "{:.3},{:.3},{:.3},{:.3},{:.5},{:.6},{:.5},{:.6},{},{:.4},{:.1},{:.7},{:.7},{:.7},{:.3},{:.3},",
            e.px[0].x,
            e.px[0].y,
            e.px[1].x,
            e.px[1].y,
            h.left_mean,
            h.left_var,
            h.right_mean,
            h.right_var,
            e.sensor,
            e.length_rad.to_degrees(),
            e.strength,
            n.x,
            n.y,
            n.z,
            h.left_kept,
            h.right_kept
        );
        // The pieces shown, projected from their end rays; the outer ends are the edge's own.
        let whole = e.n_gaps == 0 && e.shown() == [[0.0, e.length_rad as f32]];
        if e.shown().is_empty() {
            s.push_str("none");
        } else if !whole {
            let sensor = rig.sensors.get(usize::from(e.sensor));
            let px = |t: f32, end: usize| -> Option<[f64; 2]> {
                if (end == 0 && t == 0.0) || (end == 1 && t == e.length_rad as f32) {
                    return Some([e.px[end].x, e.px[end].y]);
                }
                let s = sensor?;
                let ray = s.t_rig_sensor.rotation.inverse() * e.ray_at(f64::from(t));
                s.lens.project(&ray).map(|p| [p.x, p.y])
            };
            let mut first = true;
            for &[from, to] in e.shown() {
                if let (Some(a), Some(b)) = (px(from, 0), px(to, 1)) {
                    let sep = if first { "" } else { ";" };
                    first = false;
                    let _ = write!(s, "{sep}{:.3} {:.3} {:.3} {:.3}", a[0], a[1], b[0], b[1]);
                }
            }
        }
        s.push('\n');
    }
    s
}

/// Why `omnitrack edges` cannot read its image.
#[derive(Debug, thiserror::Error)]
pub enum EdgesCsvError {
    #[error("--sensor {sensor}: rig {rig:?} has sensors 0..{last}")]
    NoSuchSensor { sensor: usize, rig: String, last: usize },
    #[error("{}: cannot read image: {source}", .path.display())]
    Unreadable {
        path: std::path::PathBuf,
        source: image::ImageError,
    },
    #[error("{}: image is {width}x{height}, sensor {sensor} of rig {rig:?} is {sensor_width}x{sensor_height}", .path.display())]
    WrongSize {
        path: std::path::PathBuf,
        width: u32,
        height: u32,
        sensor: usize,
        rig: String,
        sensor_width: u32,
        sensor_height: u32,
    },
}

/// `omnitrack edges --rig R --sensor K IMAGE`: loads the image, checks it against the rig's
/// sensor and returns the CSV; errors are one line naming the file.
pub fn edges_csv_for_image(
    rig: &Rig,
    config: &EdgeConfig,
    sensor: usize,
    path: &std::path::Path,
) -> Result<String, EdgesCsvError> {
    let Some(s) = rig.sensors.get(sensor) else {
        return Err(EdgesCsvError::NoSuchSensor {
            sensor,
            rig: rig.name.clone(),
            last: rig.sensors.len().saturating_sub(1),
        });
    };
    let unreadable = |source| EdgesCsvError::Unreadable {
        path: path.to_path_buf(),
        source,
    };
    // Only a regular file no larger than any image of the sensor's size can be (4 bytes a pixel
    // and 1 MiB): a FIFO would block the read for ever, and /dev/zero never ends.
    let most = 4 * u64::from(s.width) * u64::from(s.height) + (1 << 20);
    omnitrack_core::text_file::regular_file_len(path, most).map_err(|e| unreadable(image::ImageError::IoError(e)))?;
    let reader = || {
        image::ImageReader::open(path)
            .map_err(|e| unreadable(image::ImageError::IoError(e)))?
            .with_guessed_format()
            .map_err(|e| unreadable(image::ImageError::IoError(e)))
    };
    // The size from the header, before decoding: a huge image is refused, not decoded.
    let (width, height) = reader()?.into_dimensions().map_err(unreadable)?;
    if width != s.width || height != s.height {
        return Err(EdgesCsvError::WrongSize {
            path: path.to_path_buf(),
            width,
            height,
            sensor,
            rig: rig.name.clone(),
            sensor_width: s.width,
            sensor_height: s.height,
        });
    }
    let img = reader()?.decode().map_err(unreadable)?.to_rgb8();
    let mut si = SensorImage::new(sensor, s.width, s.height);
    si.pixels_mut().copy_from_slice(img.as_raw());
    si.set_valid(0);
    let params = EdgeParams {
        threads: 1,
        ..EdgeParams::default()
    };
    let mut det = EdgeDetector::with_params(rig, config, params);
    Ok(edges_csv(det.detect_sensor(&si), rig))
}

#[cfg(test)]
mod csv_errors {
    use super::*;

    /// Each way `omnitrack edges` can be handed the wrong image is one line naming it.
    #[test]
    fn a_wrong_sensor_file_or_size_is_named() {
        let rig = Rig::from_toml_str(
            "name = \"one\"\n[[sensors]]\nid = 0\nresolution = [8, 6]\nmodel = \"pinhole\"\n\
             intrinsics = [8.0, 8.0, 3.5, 2.5]\nrotation_wxyz = [1.0, 0.0, 0.0, 0.0]\n\
             translation_m = [0.0, 0.0, 0.0]\n",
            "one.toml",
        )
        .unwrap();
        let config = EdgeConfig::default();
        let dir = tempfile::tempdir().unwrap();
        let small = dir.path().join("small.png");
        image::RgbImage::new(4, 3).save(&small).unwrap();
        let right = dir.path().join("right.png");
        image::RgbImage::new(8, 6).save(&right).unwrap();

        let e = edges_csv_for_image(&rig, &config, 1, &right).unwrap_err();
        assert_eq!(e.to_string(), "--sensor 1: rig \"one\" has sensors 0..0");
        let missing = dir.path().join("missing.png");
        let e = edges_csv_for_image(&rig, &config, 0, &missing).unwrap_err();
        assert!(
            e.to_string()
                .starts_with(&format!("{}: cannot read image: ", missing.display())),
            "{e}"
        );
        let e = edges_csv_for_image(&rig, &config, 0, &small).unwrap_err();
        assert_eq!(
            e.to_string(),
            format!("{}: image is 4x3, sensor 0 of rig \"one\" is 8x6", small.display())
        );
        // A blank image of the right size has no edges: the header alone.
        let csv = edges_csv_for_image(&rig, &config, 0, &right).unwrap();
        assert_eq!(csv.lines().count(), 1, "{csv}");
    }
}
