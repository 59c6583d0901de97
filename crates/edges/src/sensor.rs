//! One sensor's edge extraction, on buffers allocated once: grey image → integer Sobel gradients →
//! non-maximum suppression → edgel chains → sub-pixel edgels unprojected to rays (per-pixel ray
//! table, bilinear) → planes through the optical centre (split where a chain bends, merge
//! collinear pieces, also across chains) → hue strips → the strongest `max_edges` edges.
//!
//! In: one [`SensorImage`] (RGB8) and the sensor's ray table ([`ray_table`]). Out: the
//! [`Workspace`]'s `edges` (at most `max_edges`, strongest first) and its [`ExtractionStats`].
//! Each step is a file of its own, all working on the one [`Workspace`] (and the [`Scratch`] the
//! running thread lends it): [`chain`] (pixel pass →
//! chains of sub-pixel rays), [`fit`] (chains → candidate pieces), [`merge`] (collinear pieces
//! of different chains joined), [`select`] (the strongest candidates → [`Edge`]s, with
//! [`nfa`]'s a-contrario test of the pieces shown) and [`plane`] (the moments of rays and the
//! planes fitted to them, which they all share).

mod chain;
mod fit;
mod merge;
mod nfa;
mod plane;
mod select;

use super::contrario::Contrario;
use super::edge::{Edge, MAX_GAPS};
use super::gradient::{gradients_and_edgels, Rows};
use super::hue::{HueAcc, HueTable};
use super::params::EdgeParams;
use crate::cpu::thread_cpu_time;
use chain::{LN_MAG, MAX_CHAIN};
use nalgebra::{Point2, Point3, UnitQuaternion, Vector3};
use omnitrack_core::frame::SensorImage;
use omnitrack_core::geometry::Lens;
use omnitrack_core::memory::resident;
use omnitrack_core::rig::Sensor;
use plane::Moments;
use std::sync::Arc;

/// An edge piece before selection: moments of its rays, end rays, hue sums.
#[derive(Debug, Clone, Copy, Default)]
struct Candidate {
    /// Σ w r rᵀ over its edgels (xx, xy, xz, yy, yz, zz), sensor frame, and Σ w.
    m: Moments,
    count: u32,
    /// Unit normal (sensor frame), oriented as r1 × r2.
    n: Vector3<f64>,
    /// End rays (sensor frame, unit, in the plane).
    r1: Vector3<f64>,
    r2: Vector3<f64>,
    strength: f32,
    /// Angle (rad) covered by the chain pieces it is made of: its span less the gaps merging
    /// bridged.
    support: f64,
    /// Net count of edgels brighter on the left (> 0: left is the bright side).
    bright_left: i32,
    left: HueAcc,
    right: HueAcc,
    /// The widest gaps merging bridged, as the end rays of the pieces on either side.
    gaps: [[Vector3<f64>; 2]; MAX_GAPS],
    n_gaps: u8,
    alive: bool,
    /// Merged in the last pass of `merge_across_chains`, and in the current one.
    changed: bool,
    merged_now: bool,
}

/// What one sensor's extraction keeps from frame to frame (its lens and ray table, candidates,
/// edges, counters), sized at start-up; the buffers it works through are a thread's
/// [`Scratch`], lent by [`Workspace::run`].
pub(crate) struct Workspace {
    pub sensor: u8,
    w: usize,
    h: usize,
    lens: Lens,
    rotation: UnitQuaternion<f64>,
    centre: Point3<f64>,
    /// Unit ray (sensor frame) of every pixel, NaN where the lens has none; shared by sensors
    /// with the same lens.
    rays: Arc<[[f32; 3]]>,
    hue: Arc<HueTable>,
    params: EdgeParams,
    strip_px: usize,
    max_edges: usize,
    min_len_rad: f64,
    /// The thread's buffers ([`Scratch`]), lent for the length of [`Workspace::run`]; empty
    /// otherwise.
    buf: Scratch,
    cands: Vec<Candidate>,
    /// The candidates' normals packed for the pair test of `merge_across_chains` (0 once dead),
    /// one array per coordinate so that the test of a block of pairs vectorises: the test of
    /// every pair against every other reads these, not the candidates.
    normals: [Vec<f32>; 3],
    /// The a-contrario test of the pieces shown (LSD's), its table built here.
    contrario: Contrario,
    pub edges: Vec<Edge>,
    /// Counters of the last run (for benchmarks and diagnostics).
    pub stats: ExtractionStats,
}

/// What the last edge extraction of one sensor image saw (not `capture::SensorStats`, which counts
/// what a sensor delivered).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ExtractionStats {
    pub edgels: u32,
    pub chains: u32,
    pub candidates: u32,
    /// Candidates dropped because the candidate buffer was full of stronger ones.
    pub candidates_dropped: u32,
    pub merged: u32,
    /// Merges refused because the image does not show the line across the gap.
    pub merges_refused: u32,
    /// Edges dropped by the cap on edges per sensor.
    pub capped: u32,
    /// CPU time (ns, the thread's clock: [`thread_cpu_time`](crate::thread_cpu_time)) in the
    /// pixel pass (gradients and non-maximum suppression), in linking and fitting chains (hue
    /// strips included), in merging candidates across chains, and in selecting the strongest
    /// (the a-contrario test of their pieces included).
    pub pixel_ns: u32,
    pub chain_ns: u32,
    pub merge_ns: u32,
    pub select_ns: u32,
}

impl Workspace {
    pub fn new(
        sensor: &Sensor,
        rays: Arc<[[f32; 3]]>,
        hue: Arc<HueTable>,
        params: EdgeParams,
        strip_px: usize,
        max_edges: usize,
        min_len_deg: f64,
    ) -> Workspace {
        let (w, h) = (sensor.width as usize, sensor.height as usize);
        let cand_cap = (max_edges * 4).max(64);
        std::sync::LazyLock::force(&LN_MAG);
        Workspace {
            sensor: sensor.id as u8,
            w,
            h,
            lens: sensor.lens,
            rotation: sensor.t_rig_sensor.rotation,
            centre: sensor.centre(),
            rays,
            hue,
            params,
            strip_px,
            max_edges,
            min_len_rad: min_len_deg.to_radians(),
            buf: Scratch::empty(),
            cands: resident(Vec::with_capacity(cand_cap)),
            normals: std::array::from_fn(|_| resident(Vec::with_capacity(cand_cap))),
            // Pieces are sampled once a pixel: none is longer than a few image perimeters.
            // Trying both polarities doubles LSD's count of tests.
            contrario: Contrario::new(w, h, 2 * (w + h), 2.0),
            edges: resident(Vec::with_capacity(max_edges)),
            stats: ExtractionStats::default(),
        }
    }

    /// Detects the edges of one image into `self.edges` (cleared first), on the calling
    /// thread's `scratch` (made for at least this sensor's size). An invalid image, or one of
    /// the wrong size, yields no edges.
    pub fn run(&mut self, img: &SensorImage, scratch: &mut Scratch) {
        scratch.prepare(self.w, self.h);
        self.with_scratch(scratch, |ws| ws.run_lent(img));
    }

    /// Runs `f` with `scratch` lent to this workspace (after [`Workspace::run`], the maps it
    /// filled hold this sensor's gradients).
    fn with_scratch<R>(&mut self, scratch: &mut Scratch, f: impl FnOnce(&mut Workspace) -> R) -> R {
        std::mem::swap(&mut self.buf, scratch);
        let r = f(self);
        std::mem::swap(&mut self.buf, scratch);
        r
    }

    fn run_lent(&mut self, img: &SensorImage) {
        self.edges.clear();
        self.cands.clear();
        self.stats = ExtractionStats::default();
        if !img.valid || img.width() as usize != self.w || img.height() as usize != self.h || self.w < 3 || self.h < 3 {
            return;
        }
        // Colour gradient: per pixel, the gradient of the channel (R, G or B) where it is largest,
        // so that edges between colours of equal brightness are found too.
        let t0 = thread_cpu_time();
        self.stats.edgels = gradients_and_edgels(
            img.pixels(),
            self.w,
            self.h,
            self.params.smoothing,
            self.params.gradient_threshold.min(i16::MAX as u16) as i16,
            &mut self.buf.rows,
            &mut self.buf.gx,
            &mut self.buf.gy,
            &mut self.buf.mag,
            &mut self.buf.map,
        );
        let t1 = thread_cpu_time();
        self.link(img.pixels());
        let t2 = thread_cpu_time();
        self.merge_across_chains();
        let t3 = thread_cpu_time();
        self.select();
        let t4 = thread_cpu_time();
        let ns = |d: std::time::Duration| d.as_nanos().min(u32::MAX as u128) as u32;
        self.stats.pixel_ns = ns(t1 - t0);
        self.stats.chain_ns = ns(t2 - t1);
        self.stats.merge_ns = ns(t3 - t2);
        self.stats.select_ns = ns(t4 - t3);
    }
}

/// The buffers one sensor's extraction works through and leaves nothing in: the pixel pass's
/// full-image maps and ring buffers, and one chain's edgels and pieces. One set per thread
/// rather than per sensor: a thread runs its sensors one after another, so its set (1.4 MB of
/// maps at 512×384) stays in its core's cache from one sensor to the next, where six sets (one
/// a sensor) were each fetched back from memory once a frame.
pub(crate) struct Scratch {
    rows: Rows,
    gx: Vec<i16>,
    gy: Vec<i16>,
    /// |gx| + |gy| ≤ 2 · 4 · 4 · 4 · 255 = 32640: fits i16 (signed, so that SSE2 compares it).
    mag: Vec<i16>,
    /// 0: no edgel (or already linked); 1..=4: edgel with its gradient bin.
    map: Vec<u8>,
    /// The image size the maps were last used at: the pass writes only the interior, and
    /// linking relies on a zero border.
    size: (usize, usize),
    fwd: Vec<u32>,
    bwd: Vec<u32>,
    // One chain, structure of arrays.
    pos: Vec<[f32; 2]>,
    grad: Vec<[f32; 2]>,
    emag: Vec<f32>,
    ray: Vec<Vector3<f64>>,
    prefix: Vec<Moments>,
    stack: Vec<(u32, u32)>,
    pieces: Vec<(u32, u32)>,
    /// One piece's hue-strip samples (x, y, and the unit step (dx, dy) to the left), and its
    /// strip pixels as [t][side][sample]: their byte offsets into the image, then their hues
    /// ([`HueTable::classify`]).
    samples: [Vec<f32>; 4],
    strip: Vec<u32>,
    strip_hues: Vec<u32>,
}

impl Scratch {
    /// Buffers for images of at most `max_pixels` pixels in rows of at most `max_width`,
    /// resident from the start (`omnitrack_core::memory`): a chain or a frame longer than any
    /// before would otherwise take new memory on the frame path.
    pub fn new(max_width: usize, max_pixels: usize, params: &EdgeParams, strip_px: usize) -> Scratch {
        let samples = params.hue_samples_per_edge.max(1);
        Scratch {
            rows: Rows::new(max_width),
            gx: resident(vec![0; max_pixels]),
            gy: resident(vec![0; max_pixels]),
            mag: resident(vec![0; max_pixels]),
            map: resident(vec![0; max_pixels]),
            size: (0, 0),
            fwd: resident(Vec::with_capacity(MAX_CHAIN)),
            bwd: resident(Vec::with_capacity(MAX_CHAIN)),
            pos: resident(Vec::with_capacity(2 * MAX_CHAIN)),
            grad: resident(Vec::with_capacity(2 * MAX_CHAIN)),
            emag: resident(Vec::with_capacity(2 * MAX_CHAIN)),
            ray: resident(Vec::with_capacity(2 * MAX_CHAIN)),
            prefix: resident(Vec::with_capacity(2 * MAX_CHAIN + 1)),
            stack: resident(Vec::with_capacity(2 * MAX_CHAIN)),
            pieces: resident(Vec::with_capacity(2 * MAX_CHAIN)),
            samples: std::array::from_fn(|_| resident(Vec::with_capacity(samples))),
            strip: resident(Vec::with_capacity(2 * strip_px * samples)),
            strip_hues: resident(Vec::with_capacity(2 * strip_px * samples)),
        }
    }

    /// What a workspace holds while no thread has lent it a set (allocates nothing).
    fn empty() -> Scratch {
        Scratch {
            rows: Rows::new(0),
            gx: Vec::new(),
            gy: Vec::new(),
            mag: Vec::new(),
            map: Vec::new(),
            size: (0, 0),
            fwd: Vec::new(),
            bwd: Vec::new(),
            pos: Vec::new(),
            grad: Vec::new(),
            emag: Vec::new(),
            ray: Vec::new(),
            prefix: Vec::new(),
            stack: Vec::new(),
            pieces: Vec::new(),
            samples: std::array::from_fn(|_| Vec::new()),
            strip: Vec::new(),
            strip_hues: Vec::new(),
        }
    }

    /// Clears the maps when the image size changes (a rig of sensors of several sizes), so
    /// that a border is zero whatever image used the maps before.
    fn prepare(&mut self, w: usize, h: usize) {
        assert!(
            w * h <= self.map.len() && self.rows.fits(w),
            "edge scratch of {} pixels for a {w}×{h} image",
            self.map.len()
        );
        if self.size != (w, h) {
            self.gx.fill(0);
            self.gy.fill(0);
            self.mag.fill(0);
            self.map.fill(0);
            self.size = (w, h);
        }
    }
}

/// The per-pixel ray table (sensor frame) of a sensor's lens.
pub(crate) fn ray_table(sensor: &Sensor) -> Arc<[[f32; 3]]> {
    let (w, h) = (sensor.width as usize, sensor.height as usize);
    let mut t = vec![[f32::NAN; 3]; w * h];
    for v in 0..h {
        for u in 0..w {
            if let Some(r) = sensor.lens.unproject(&Point2::new(u as f64, v as f64)) {
                t[v * w + u] = [r.x as f32, r.y as f32, r.z as f32];
            }
        }
    }
    t.into()
}
