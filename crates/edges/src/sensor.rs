//! One sensor's edge extraction, on buffers allocated once: grey image → integer Sobel gradients →
//! non-maximum suppression → edgel chains → sub-pixel edgels unprojected to rays (per-pixel ray
//! table, bilinear) → planes through the optical centre (split where a chain bends, merge
//! collinear pieces, also across chains) → hue strips → the strongest `max_edges` edges.

use super::contrario::{self, Contrario};
use super::gradient::{bin, bin_step, gradients_and_edgels, Rows};
use super::hue::{HueAcc, HueTable};
use super::{Edge, EdgeParams, HueSignature, MAX_GAPS};
use nalgebra::{Matrix3, Point2, Point3, Unit, UnitQuaternion, Vector2, Vector3};
use omnitrack_core::geometry::{EdgePlane, Lens};
use omnitrack_core::rig::Sensor;
use omnitrack_io::capture::SensorImage;
use std::sync::Arc;
use std::time::Instant;

/// ln(max(m, 1)) of every gradient magnitude m (|gx| + |gy| ≤ 32640 < 2¹⁵), for the sub-pixel
/// peak: three logarithms per edgel were a sixth of the chain step on real photographs. Built
/// once, by the first [`Workspace::new`].
static LN_MAG: std::sync::LazyLock<Box<[f32]>> =
    std::sync::LazyLock::new(|| (0..1u32 << 15).map(|m| (m as f32).max(1.0).ln()).collect());

/// Longest chain traced in one go (a longer one is cut; the rest is traced as another chain).
const MAX_CHAIN: usize = 4096;

/// A gradient counts as across a line when its component along the line is at most this share
/// of it (sin 10°: within 10° of the line's normal, as along a real line; texture beside a gap
/// points every way).
const GAP_ACROSS_COS: f64 = 0.174;

/// Gradient units of `gx`, `gy` per grey level per pixel: a ramp of slope 1 gives 16 (the ×16
/// smoothed rows) · 4 ([1 2 1] of the Sobel) · 2 (the central difference) = 128.
const GRADIENT_PER_GREY: f64 = 128.0;

/// The a-contrario test projects every this many samples along a piece through the lens, and
/// puts those between on the chord.
const NFA_NODE: usize = 8;
// `meaningful_part` turns a ray by NFA_NODE steps as four doublings of half a step.
const _: () = assert!(NFA_NODE == 1 << 3);
/// …and tests this many samples at a time (whole chunks, one bit each in a u32).
const NFA_BATCH: usize = 4 * NFA_NODE;
const _: () = assert!(NFA_BATCH <= 32);

/// Neighbour steps (du, dv) in angular order, 45° apart.
const DIRS: [(isize, isize); 8] = [(1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1), (0, -1), (1, -1)];

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

/// Every buffer one sensor needs, sized at start-up.
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
    /// Ring buffers of the pixel pass.
    rows: Rows,
    gx: Vec<i16>,
    gy: Vec<i16>,
    /// |gx| + |gy| ≤ 2 · 4 · 4 · 4 · 255 = 32640: fits i16 (signed, so that SSE2 compares it).
    mag: Vec<i16>,
    /// 0: no edgel (or already linked); 1..=4: edgel with its gradient bin.
    map: Vec<u8>,
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
    /// Time (ns) in the pixel pass (gradients and non-maximum suppression), in linking and
    /// fitting chains (hue included), and in merging and selecting candidates.
    pub pixel_ns: u32,
    pub chain_ns: u32,
    pub merge_ns: u32,
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
        let n = w * h;
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
            rows: Rows::new(w),
            gx: vec![0; n],
            gy: vec![0; n],
            mag: vec![0; n],
            map: vec![0; n],
            fwd: Vec::with_capacity(MAX_CHAIN),
            bwd: Vec::with_capacity(MAX_CHAIN),
            pos: Vec::with_capacity(2 * MAX_CHAIN),
            grad: Vec::with_capacity(2 * MAX_CHAIN),
            emag: Vec::with_capacity(2 * MAX_CHAIN),
            ray: Vec::with_capacity(2 * MAX_CHAIN),
            prefix: Vec::with_capacity(2 * MAX_CHAIN + 1),
            stack: Vec::with_capacity(2 * MAX_CHAIN),
            pieces: Vec::with_capacity(2 * MAX_CHAIN),
            cands: Vec::with_capacity(cand_cap),
            normals: std::array::from_fn(|_| Vec::with_capacity(cand_cap)),
            // Pieces are sampled once a pixel: none is longer than a few image perimeters.
            // Trying both polarities doubles LSD's count of tests.
            contrario: Contrario::new(w, h, 2 * (w + h), 2.0),
            edges: Vec::with_capacity(max_edges),
            stats: ExtractionStats::default(),
        }
    }

    /// Detects the edges of one image into `self.edges` (cleared first). An invalid image, or
    /// one of the wrong size, yields no edges.
    pub fn run(&mut self, img: &SensorImage) {
        self.edges.clear();
        self.cands.clear();
        self.stats = ExtractionStats::default();
        if !img.valid || img.width() as usize != self.w || img.height() as usize != self.h || self.w < 3 || self.h < 3 {
            return;
        }
        // Colour gradient: per pixel, the gradient of the channel (R, G or B) where it is largest,
        // so that edges between colours of equal brightness are found too.
        let t0 = Instant::now();
        self.stats.edgels = gradients_and_edgels(
            img.pixels(),
            self.w,
            self.h,
            self.params.smoothing,
            self.params.gradient_threshold.min(i16::MAX as u16) as i16,
            &mut self.rows,
            &mut self.gx,
            &mut self.gy,
            &mut self.mag,
            &mut self.map,
        );
        let t1 = Instant::now();
        self.link(img.pixels());
        let t2 = Instant::now();
        self.merge_across_chains();
        self.select();
        let t3 = Instant::now();
        let ns = |d: std::time::Duration| d.as_nanos().min(u32::MAX as u128) as u32;
        self.stats.pixel_ns = ns(t1 - t0);
        self.stats.chain_ns = ns(t2 - t1);
        self.stats.merge_ns = ns(t3 - t2);
    }

    /// Whether the gradient axes at i and j agree within ~50° (polarity is not compared: the
    /// colour gradient's sign can flip where the dominant channel changes).
    #[inline]
    fn compatible(&self, i: usize, j: usize) -> bool {
        let (ax, ay) = (self.gx[i] as i64, self.gy[i] as i64);
        let (bx, by) = (self.gx[j] as i64, self.gy[j] as i64);
        let dot = ax * bx + ay * by;
        5 * dot * dot > 2 * (ax * ax + ay * ay) * (bx * bx + by * by)
    }

    /// Follows unlinked edgels from `start` in direction `dir`, appending to `out` (which must
    /// start empty); clears the map bit of every edgel it takes.
    fn trace(map: &mut [u8], ws: &Workspace, start: usize, mut dir: usize, out: &mut Vec<u32>, limit: usize) {
        let w = ws.w as isize;
        let mut cur = start;
        while out.len() < limit {
            let mut next = None;
            for k in [0usize, 1, 7] {
                let d = (dir + k) & 7;
                let (du, dv) = DIRS[d];
                let j = (cur as isize + dv * w + du) as usize;
                if map[j] != 0 && ws.compatible(cur, j) {
                    next = Some((j, d));
                    break;
                }
            }
            let Some((j, d)) = next else { break };
            map[j] = 0;
            out.push(j as u32);
            cur = j;
            dir = d;
        }
    }

    #[inline(never)]
    fn link(&mut self, rgb: &[u8]) {
        let (w, h) = (self.w, self.h);
        let mut map = std::mem::take(&mut self.map);
        let mut fwd = std::mem::take(&mut self.fwd);
        let mut bwd = std::mem::take(&mut self.bwd);
        // Row-major over the interior (the map's border is always 0), eight empty cells at a
        // time: most of the map is empty.
        let end = (h - 1) * w;
        let mut next = w;
        while next < end {
            let i = next;
            if i + 8 <= end {
                let mut word = [0u8; 8];
                word.copy_from_slice(&map[i..i + 8]);
                if u64::from_ne_bytes(word) == 0 {
                    next += 8;
                    continue;
                }
            }
            next += 1;
            {
                if map[i] == 0 {
                    continue;
                }
                map[i] = 0;
                let dir = tangent_octant(self.gx[i], self.gy[i]);
                fwd.clear();
                bwd.clear();
                Self::trace(&mut map, self, i, dir, &mut fwd, MAX_CHAIN - 1);
                Self::trace(&mut map, self, i, (dir + 4) & 7, &mut bwd, MAX_CHAIN - 1 - fwd.len());
                let n = fwd.len() + bwd.len() + 1;
                if n < self.params.min_chain_edgels {
                    continue;
                }
                self.stats.chains += 1;
                self.load_chain(
                    bwd.iter()
                        .rev()
                        .copied()
                        .chain(std::iter::once(i as u32))
                        .chain(fwd.iter().copied()),
                );
                self.fit_chain(rgb);
            }
        }
        self.map = map;
        self.fwd = fwd;
        self.bwd = bwd;
    }

    /// Sub-pixel positions (parabola across the gradient), gradients and rays of a chain's edgels.
    #[inline(never)]
    fn load_chain(&mut self, idx: impl Iterator<Item = u32>) {
        self.pos.clear();
        self.grad.clear();
        self.emag.clear();
        self.ray.clear();
        self.prefix.clear();
        self.prefix.push([0.0; 7]);
        let w = self.w;
        let ln = &**LN_MAG;
        let ln_of = |m: i16| ln[m.max(0) as usize];
        for i in idx {
            let i = i as usize;
            let (gx, gy) = (self.gx[i], self.gy[i]);
            let bin = bin(gx, gy);
            let (du, dv) = bin_step(bin);
            let off = dv * w as isize + du;
            let m0 = self.mag[i] as f32;
            // Gaussian sub-pixel peak: the parabola through the logarithms of the magnitudes
            // (exact for a Gaussian profile; less biased than a parabola on the magnitudes for
            // the narrow profiles of the 3-px-wide derivative).
            let (la, l0, lb) = (
                ln_of(self.mag[(i as isize - off) as usize]),
                ln_of(self.mag[i]),
                ln_of(self.mag[(i as isize + off) as usize]),
            );
            let denom = la - 2.0 * l0 + lb;
            let s = if denom < 0.0 {
                (0.5 * (la - lb) / denom).clamp(-0.5, 0.5)
            } else {
                0.0
            };
            let x = (i % w) as f32 + s * du as f32;
            let y = (i / w) as f32 + s * dv as f32;
            let Some(r) = self.ray_at(x, y) else { continue };
            self.pos.push([x, y]);
            self.grad.push([gx as f32, gy as f32]);
            self.emag.push(m0);
            self.ray.push(r);
            let p = *self.prefix.last().unwrap_or(&[0.0; 7]);
            let o = weighted_outer(&r, edgel_weight(m0));
            self.prefix.push(std::array::from_fn(|k| p[k] + o[k]));
        }
    }

    /// Bilinear interpolation of the ray table, normalised.
    #[inline]
    fn ray_at(&self, x: f32, y: f32) -> Option<Vector3<f64>> {
        let (w, h) = (self.w, self.h);
        let x = x.clamp(0.0, (w - 1) as f32);
        let y = y.clamp(0.0, (h - 1) as f32);
        let (u0, v0) = ((x as usize).min(w - 2), (y as usize).min(h - 2));
        let (fx, fy) = (x - u0 as f32, y - v0 as f32);
        let i = v0 * w + u0;
        let t = &self.rays;
        let (a, b, c, d) = (t[i], t[i + 1], t[i + w], t[i + w + 1]);
        let mut r = [0.0f64; 3];
        for k in 0..3 {
            let top = a[k] as f64 + (b[k] as f64 - a[k] as f64) * fx as f64;
            let bot = c[k] as f64 + (d[k] as f64 - c[k] as f64) * fx as f64;
            r[k] = top + (bot - top) * fy as f64;
        }
        let v = Vector3::new(r[0], r[1], r[2]);
        let n = v.norm();
        (n.is_finite() && n > 0.5).then(|| v / n)
    }

    fn moments(&self, a: usize, b: usize) -> Moments {
        let (p, q) = (&self.prefix[a], &self.prefix[b + 1]);
        std::array::from_fn(|k| q[k] - p[k])
    }

    /// Largest |n · r| over edgels a..=b.
    fn max_dev(&self, n: &Vector3<f64>, a: usize, b: usize) -> (f64, usize) {
        let mut best = (0.0, a);
        for k in a..=b {
            let d = n.dot(&self.ray[k]).abs();
            if d > best.0 {
                best = (d, k);
            }
        }
        best
    }

    #[inline(never)]
    fn fit_chain(&mut self, rgb: &[u8]) {
        let n = self.ray.len();
        let min_n = self.params.min_chain_edgels;
        if n < min_n {
            return;
        }
        let tol = self.params.split_tolerance_rad.sin();
        // Split (Douglas–Peucker on the sphere: deviation from the end rays' great circle).
        self.pieces.clear();
        self.stack.clear();
        self.stack.push((0, n as u32 - 1));
        while let Some((a, b)) = self.stack.pop() {
            let (a, b) = (a as usize, b as usize);
            if b + 1 - a < min_n {
                continue;
            }
            let c = self.ray[a].cross(&self.ray[b]);
            let cn = c.norm();
            if cn < 1e-9 {
                continue;
            }
            let (dev, k) = self.max_dev(&(c / cn), a, b);
            if dev > tol && k > a && k < b {
                self.stack.push((k as u32, b as u32));
                self.stack.push((a as u32, k as u32));
            } else {
                self.pieces.push((a as u32, b as u32));
            }
        }
        // Merge neighbouring pieces whose union is still one plane.
        let mut out = 0;
        let pieces = std::mem::take(&mut self.pieces);
        let mut pieces = pieces;
        for k in 0..pieces.len() {
            let (a, b) = pieces[k];
            if out > 0 {
                let (pa, pb) = pieces[out - 1];
                if pb >= a.saturating_sub(1) {
                    let m = self.moments(pa as usize, b as usize);
                    if let Some(nrm) = plane_normal(&m) {
                        if self.max_dev(&nrm, pa as usize, b as usize).0 <= tol {
                            pieces[out - 1] = (pa, b);
                            continue;
                        }
                    }
                }
            }
            pieces[out] = (a, b);
            out += 1;
        }
        pieces.truncate(out);
        // The chord test misses two lines that meet at a shallow angle or run side by side a
        // pixel or two apart (a wall corner continued by a box's edge): with the two-line test
        // on, each piece is also cut where two planes fit it much better than one.
        self.stack.clear();
        self.stack.extend(pieces.iter().rev().copied());
        while let Some((a, b)) = self.stack.pop() {
            if let Some(k) = self.two_lines(a as usize, b as usize) {
                self.stack.push((k as u32 + 1, b));
                self.stack.push((a, k as u32));
            } else {
                self.add_piece(a as usize, b as usize, rgb);
            }
        }
        self.pieces = pieces;
    }

    /// Where edgels a..=b are two lines rather than one (see [`two_lines_apart`]): the last
    /// edgel of the first line at the cut that lowers the residual most. None when the test is
    /// off (`EdgeParams::two_line_excess` 0).
    fn two_lines(&self, a: usize, b: usize) -> Option<usize> {
        let min_n = self.params.min_chain_edgels.max(3);
        let len = b + 1 - a;
        let excess = self.params.two_line_excess;
        if excess <= 0.0 || len < 2 * min_n {
            return None;
        }
        let m = self.moments(a, b);
        let rss = plane_residual(&m, &plane_normal(&m)?).max(0.0);
        let tol = self.params.split_tolerance_rad.sin();
        if !two_lines_apart(rss, 0.0, m[6], len, tol, excess) {
            return None;
        }
        let split_rss = |k: usize| -> f64 {
            let (ml, mr) = (self.moments(a, k), self.moments(k + 1, b));
            match (plane_normal(&ml), plane_normal(&mr)) {
                (Some(nl), Some(nr)) => plane_residual(&ml, &nl).max(0.0) + plane_residual(&mr, &nr).max(0.0),
                _ => f64::INFINITY,
            }
        };
        // Coarse scan, then every edgel around the best coarse cut.
        let (first, last) = (a + min_n - 1, b - min_n);
        let step = (len / 32).max(1);
        let mut best = (f64::INFINITY, first);
        for k in (first..=last).step_by(step) {
            let r = split_rss(k);
            if r < best.0 {
                best = (r, k);
            }
        }
        let centre = best.1;
        for k in centre.saturating_sub(step - 1).max(first)..=(centre + step - 1).min(last) {
            let r = split_rss(k);
            if r < best.0 {
                best = (r, k);
            }
        }
        two_lines_apart(rss, best.0, m[6], len, tol, excess).then_some(best.1)
    }

    /// Moments, count and plane normal of edgels a..=b without the outliers of their plane
    /// (rays more than `OUTLIER_SIGMAS` RMS off it: edgels bent by a junction or a neighbouring
    /// edge, noise), refitted at most twice.
    fn robust_fit(&self, a: usize, b: usize) -> Option<(Moments, u32, Vector3<f64>)> {
        let all = self.moments(a, b);
        let total = b + 1 - a;
        let (mut m, mut count) = (all, total);
        let mut n = plane_normal(&m)?;
        let floor = OUTLIER_FLOOR_RAD.sin();
        for _ in 0..2 {
            let rms = (plane_residual(&m, &n) / m[6]).max(0.0).sqrt();
            let cut = (OUTLIER_SIGMAS * rms).max(floor);
            let mut kept = all;
            let mut k_count = total;
            for (r, &g) in self.ray[a..=b].iter().zip(&self.emag[a..=b]) {
                if n.dot(r).abs() > cut {
                    let o = weighted_outer(r, edgel_weight(g));
                    for (x, y) in kept.iter_mut().zip(o) {
                        *x -= y;
                    }
                    k_count -= 1;
                }
            }
            if k_count == count || k_count < self.params.min_chain_edgels.max(3) {
                break;
            }
            let Some(k_n) = plane_normal(&kept) else { break };
            (m, count, n) = (kept, k_count, k_n);
        }
        Some((m, count as u32, n))
    }

    /// Fits, measures and (if long enough) records one piece of the chain as a candidate.
    #[inline(never)]
    fn add_piece(&mut self, a: usize, b: usize, rgb: &[u8]) {
        let Some((m, fitted, mut nrm)) = self.robust_fit(a, b) else {
            return;
        };
        let (ra, rb) = (self.ray[a], self.ray[b]);
        if nrm.dot(&ra.cross(&rb)) < 0.0 {
            nrm = -nrm;
        }
        let r1 = (ra - nrm * nrm.dot(&ra)).normalize();
        let r2 = (rb - nrm * nrm.dot(&rb)).normalize();
        // Pieces down to half the minimum length are kept for merging across chains; `select`
        // drops what is still short after it.
        let span = r1.dot(&r2).clamp(-1.0, 1.0).acos();
        if span < 0.5 * self.min_len_rad {
            return;
        }
        // Hue strips and polarity; left of the walk from edgel a to edgel b.
        let (pa, pb) = (self.pos[a], self.pos[b]);
        let left = [pb[1] - pa[1], -(pb[0] - pa[0])];
        let mut lacc = HueAcc::default();
        let mut racc = HueAcc::default();
        let mut bright_left = 0i32;
        let mut strength = 0.0f32;
        let count = b + 1 - a;
        let step = count.div_ceil(self.params.hue_samples_per_edge.max(1)).max(1);
        for k in a..=b {
            strength += self.emag[k];
            let g = self.grad[k];
            let side = g[0] * left[0] + g[1] * left[1];
            bright_left += if side > 0.0 { 1 } else { -1 };
            if (k - a) % step != 0 {
                continue;
            }
            let gn = (g[0] * g[0] + g[1] * g[1]).sqrt();
            if gn == 0.0 {
                continue;
            }
            let s = if side >= 0.0 { 1.0 } else { -1.0 } / gn;
            let (dx, dy) = (g[0] * s, g[1] * s); // unit, pointing to the left side
            let p = self.pos[k];
            for t in 0..self.strip_px {
                let d = self.params.hue_strip_offset_px + t as f32;
                for (sign, acc) in [(1.0f32, &mut lacc), (-1.0, &mut racc)] {
                    // +1 keeps the value positive, so truncation rounds.
                    let x = (p[0] + sign * d * dx + 1.5) as usize;
                    let y = (p[1] + sign * d * dy + 1.5) as usize;
                    if x < 1 || y < 1 || x > self.w || y > self.h {
                        continue;
                    }
                    let i = ((y - 1) * self.w + x - 1) * 3;
                    self.hue.accumulate(acc, [rgb[i], rgb[i + 1], rgb[i + 2]]);
                }
            }
        }
        let cand = Candidate {
            m,
            count: fitted,
            n: nrm,
            r1,
            r2,
            strength: strength / 64.0,
            support: span,
            bright_left,
            left: lacc,
            right: racc,
            gaps: [[Vector3::zeros(); 2]; MAX_GAPS],
            n_gaps: 0,
            alive: true,
            changed: false,
            merged_now: false,
        };
        self.stats.candidates += 1;
        if self.cands.len() < self.cands.capacity() {
            self.cands.push(cand);
        } else {
            // Full: replace the weakest if this one is stronger.
            self.stats.candidates_dropped += 1;
            let (k, weakest) = self
                .cands
                .iter()
                .enumerate()
                .min_by(|x, y| x.1.strength.total_cmp(&y.1.strength))
                .map(|(k, c)| (k, c.strength))
                .unwrap_or((0, f32::INFINITY));
            if cand.strength > weakest {
                self.cands[k] = cand;
            }
        }
    }

    /// Joins candidates of different chains that lie on one plane, end to end (a line broken by
    /// an occluder, a gap in the edgels or a junction). Polarity is not compared: an edge seen
    /// against a background that turns from darker to brighter flips it halfway (README).
    #[inline(never)]
    fn merge_across_chains(&mut self) {
        let cos_max = self.params.merge_angle_rad.cos();
        let gap_max = self.params.merge_gap_rad;
        let tol = self.params.split_tolerance_rad.sin();
        let two_line = self.params.two_line_excess;
        let min_support = self.params.merge_min_support;
        let min_evidence = self.params.merge_gap_evidence;
        let pack = |n: &Vector3<f64>| [n.x as f32, n.y as f32, n.z as f32];
        for (k, coord) in self.normals.iter_mut().enumerate() {
            coord.clear();
            coord.extend(self.cands.iter().map(|c| pack(&c.n)[k]));
        }
        // The f32 test lets through every pair the f64 one below would.
        let cos_loose = cos_max as f32 - 1e-5;
        let len = self.cands.len();
        for pass in 0..3 {
            let mut merged_any = false;
            for i in 0..len {
                if !self.cands[i].alive {
                    continue;
                }
                // The normal test of a block of pairs at once (the compiler vectorises it):
                // nearly every pair fails it. Pairs that pass are tried in the same order as
                // one by one, and a merge, which turns i's normal, tests the rest of the
                // block again.
                let mut j = i + 1;
                while j < len {
                    let end = (j + PAIR_BLOCK).min(len);
                    let [nx, ny, nz] = &self.normals;
                    let a = [nx[i], ny[i], nz[i]];
                    let mut mask = 0u32;
                    for (k, ((bx, by), bz)) in nx[j..end].iter().zip(&ny[j..end]).zip(&nz[j..end]).enumerate() {
                        let d = (a[0] * bx + a[1] * by + a[2] * bz).abs();
                        mask |= u32::from(d >= cos_loose) << k;
                    }
                    let mut next = end;
                    while mask != 0 {
                        let jj = j + mask.trailing_zeros() as usize;
                        mask &= mask - 1;
                        // A pair whose members are unchanged since the last pass was tried then.
                        if !self.cands[jj].alive || (pass > 0 && !self.cands[i].changed && !self.cands[jj].changed) {
                            continue;
                        }
                        let (ci, cj) = (&self.cands[i], &self.cands[jj]);
                        let dot = ci.n.dot(&cj.n);
                        if dot.abs() < cos_max {
                            continue;
                        }
                        if let Some(m) = try_merge(ci, cj, gap_max, tol, two_line, min_support) {
                            if min_evidence > 0.0 && self.gap_evidence(&m, ci, cj, min_evidence) < min_evidence {
                                self.stats.merges_refused += 1;
                                continue;
                            }
                            self.cands[i] = m;
                            self.cands[jj].alive = false;
                            for (k, coord) in self.normals.iter_mut().enumerate() {
                                coord[i] = pack(&m.n)[k];
                                coord[jj] = 0.0;
                            }
                            self.stats.merged += 1;
                            merged_any = true;
                            self.cands[i].merged_now = true;
                            next = jj + 1;
                            break;
                        }
                    }
                    j = next;
                }
            }
            if !merged_any {
                break;
            }
            for c in self.cands.iter_mut() {
                c.changed = std::mem::take(&mut c.merged_now);
            }
        }
        self.cands.retain(|c| c.alive);
    }

    /// The share of the gap between the pieces `ci` and `cj` of the merged edge `m` along which
    /// the image shows the line: sampled every ~3 px (at most 48 times) along the merged plane's
    /// great circle, a sample shows it when a pixel within one of it has a gradient of at least
    /// half the edgel threshold pointing across the line (within [`GAP_ACROSS_COS`]). A line broken by
    /// noise, aliasing or a weak stretch keeps its gradient across the gap; collinear pieces
    /// far apart (the tops of a row of windows, texture) have plain wall between them. 1 where
    /// the pieces touch or overlap.
    fn gap_evidence(&self, m: &Candidate, ci: &Candidate, cj: &Candidate, needed: f64) -> f64 {
        let n = m.n;
        let e1 = m.r1;
        let ang = |r: &Vector3<f64>| angle_in_plane(&n, &e1, r);
        let (i0, i1) = (ang(&ci.r1).min(ang(&ci.r2)), ang(&ci.r1).max(ang(&ci.r2)));
        let (j0, j1) = (ang(&cj.r1).min(ang(&cj.r2)), ang(&cj.r1).max(ang(&cj.r2)));
        let (g0, g1) = if j0 >= i1 {
            (i1, j0)
        } else if i0 >= j1 {
            (j1, i0)
        } else {
            return 1.0;
        };
        let e2 = n.cross(&e1);
        let ray = |a: f64| e1 * a.cos() + e2 * a.sin();
        let (Some(p0), Some(p1)) = (self.lens.project(&ray(g0)), self.lens.project(&ray(g1))) else {
            return 0.0;
        };
        let chord = p1 - p0;
        let length = chord.norm();
        if length < 3.0 {
            return 1.0;
        }
        let along = chord / length;
        let samples = ((length / 3.0).ceil() as usize).clamp(2, 48);
        let threshold = i32::from(self.params.gradient_threshold) / 2;
        // Stop as soon as `needed` is out of reach: most merges tried are refused.
        let allowed_misses = ((1.0 - needed) * samples as f64).floor() as usize;
        let (mut shown, mut missed) = (0, 0);
        // Every fourth sample first: a gap of plain wall shows itself after a few samples.
        for k in (0..4).flat_map(|phase| (phase..samples).step_by(4)) {
            let a = g0 + (g1 - g0) * (k as f64 + 0.5) / samples as f64;
            let shows = self
                .lens
                .project(&ray(a))
                .is_some_and(|p| self.gradient_across(&p, &along, threshold));
            if shows {
                shown += 1;
            } else {
                missed += 1;
                if missed > allowed_misses {
                    return 0.0;
                }
            }
        }
        shown as f64 / samples as f64
    }

    /// Whether a pixel within one of `p` has an L1 gradient of at least `threshold` pointing
    /// across the unit image direction `along` (within [`GAP_ACROSS_COS`]).
    fn gradient_across(&self, p: &Point2<f64>, along: &Vector2<f64>, threshold: i32) -> bool {
        let (x, y) = (p.x.round() as isize, p.y.round() as isize);
        for dy in -1..=1 {
            for dx in -1..=1 {
                let (u, v) = (x + dx, y + dy);
                if u < 0 || v < 0 || u >= self.w as isize || v >= self.h as isize {
                    continue;
                }
                let i = v as usize * self.w + u as usize;
                if i32::from(self.mag[i]) < threshold {
                    continue;
                }
                let (gx, gy) = (f64::from(self.gx[i]), f64::from(self.gy[i]));
                let g = (gx * gx + gy * gy).sqrt();
                if g > 0.0 && (gx * along.x + gy * along.y).abs() <= GAP_ACROSS_COS * g {
                    return true;
                }
            }
        }
        false
    }

    /// The part of the stretch `t0..t1` (rad from `e1` along the great circle of unit normal
    /// `n`, sensor frame) that the image shows as a line, by LSD's a-contrario test
    /// ([`contrario`]): sampled once a pixel along the circle as the lens images it (rays
    /// stepped around `n` and projected, every [`NFA_NODE`]th, the rest on the chords between:
    /// fisheye arcs too), a sample is aligned when the nearest pixel's gradient is at least
    /// LSD's ρ = q / sin τ and within τ = p·π = 22.5° of the normal of the projected line
    /// there, with one polarity (LSD's regions grow on one; the first to pass, else the one
    /// more samples have). With `piece_trim` the stretch is cut to its first and last aligned
    /// sample (which only lowers the number of false alarms). None when its number of false
    /// alarms is not below ε = 1.
    #[inline(never)]
    fn meaningful_part(&self, n: &Vector3<f64>, e1: &Vector3<f64>, t0: f64, t1: f64) -> Option<Stretch> {
        if t1.partial_cmp(&t0) != Some(std::cmp::Ordering::Greater) {
            return None;
        }
        let e2 = n.cross(e1);
        let ray = |a: f64| {
            let (sin, cos) = a.sin_cos();
            e1 * cos + e2 * sin
        };
        // r turned by the angle of (sin, cos) about n.
        let turn = |r: &Vector3<f64>, (sin, cos): (f64, f64)| r * cos + n.cross(r) * sin;
        let (r0, r1) = (ray(t0), ray(t1));
        let (p0, p1) = (self.lens.project(&r0)?, self.lens.project(&r1)?);
        // Its length in pixels: the chord, on a fisheye through the middle too.
        let length = match self.lens {
            Lens::Pinhole(_) => (p1 - p0).norm(),
            _ => {
                let pm = self.lens.project(&ray(0.5 * (t0 + t1)))?;
                (pm - p0).norm() + (p1 - pm).norm()
            }
        };
        if !length.is_finite() {
            return None;
        }
        // One sample a pixel, at the centres of equal steps; never more than the image's
        // perimeter twice over (the table's reach), so that the test's time is bounded whatever
        // a lens makes of a stretch.
        let samples = (length.round() as usize).clamp(1, 2 * (self.w + self.h));
        let dt = (t1 - t0) / samples as f64;
        let half = (0.5 * dt).sin_cos();
        // The turn between nodes, NFA_NODE steps = 2⁴ half steps: four doublings of the half.
        let node_turn = (0..4).fold(half, |(s, c), _| (2.0 * s * c, 1.0 - 2.0 * s * s));
        let first_ray = turn(&r0, half);
        let last_px = self.lens.project(&turn(&r1, (-half.0, half.1)));
        let cos_tau = (contrario::P * std::f64::consts::PI).cos();
        let cos2 = cos_tau * cos_tau;
        let rho = GRADIENT_PER_GREY * contrario::Q / (contrario::P * std::f64::consts::PI).sin();
        let rho2 = rho * rho;
        let (w, h) = (self.w as f64, self.h as f64);
        let trim = self.params.piece_trim;
        // Per polarity (0: gradient along the line's left-hand normal, 1: the right-hand one):
        // aligned samples, the first and the last.
        let mut count = [0u32; 2];
        let mut first = [usize::MAX; 2];
        let mut last = [0usize; 2];
        // Samples go in chunks of NFA_NODE: each chunk's first sample and the next chunk's (or
        // the last sample) are projected through the lens, those between lie on the chord (a
        // fisheye's image of a line bends by far less than a pixel over so few), and the chord
        // gives the line's direction there. A batch of chunks at a time: first every sample's
        // pixel, then their gradients (reads that do not wait on each other: the gradients are
        // mostly out of cache by now), then the tests, branch-free, one bit a sample.
        let mut ray_a = first_ray;
        let mut a = self.lens.project(&ray_a);
        let mut k0 = 0;
        let mut idx = [0usize; NFA_BATCH];
        let mut normal = [[0f32; 2]; NFA_BATCH];
        let mut g = [[0i16; 2]; NFA_BATCH];
        let (rho2_f, cos2_f) = (rho2 as f32, cos2 as f32);
        // The polarity that made the piece meaningful whatever its rest shows, if one did.
        let mut sure = None;
        while k0 < samples && sure.is_none() {
            let batch_end = (k0 + NFA_BATCH).min(samples);
            let mut c0 = k0;
            while c0 < batch_end {
                let k1 = (c0 + NFA_NODE).min(samples - 1);
                let end = (c0 + NFA_NODE).min(samples);
                let b = if k1 == samples - 1 {
                    last_px
                } else {
                    ray_a = turn(&ray_a, node_turn);
                    self.lens.project(&ray_a)
                };
                let (slots, normals) = (&mut idx[c0 - k0..end - k0], &mut normal[c0 - k0..end - k0]);
                // The chord to the next node, or the whole piece's for a last lone sample.
                let d = match (a, b) {
                    (Some(pa), Some(pb)) if k1 > c0 => Some(pb - pa),
                    (Some(_), _) if k1 == c0 => Some(p1 - p0),
                    _ => None,
                };
                match (a, d) {
                    (Some(pa), Some(d)) if d.norm() > 0.0 => {
                        let dn = d.norm();
                        let step = if k1 > c0 {
                            d / (k1 - c0) as f64
                        } else {
                            Vector2::zeros()
                        };
                        // The line's unit left-hand normal.
                        normals.fill([(-d.y / dn) as f32, (d.x / dn) as f32]);
                        let at = |j: usize| (pa.x + 0.5 + j as f64 * step.x, pa.y + 0.5 + j as f64 * step.y);
                        let inside = |(x, y): (f64, f64)| x >= 0.0 && y >= 0.0 && x < w && y < h;
                        if inside(at(0)) && inside(at(end - c0 - 1)) {
                            // All inside: in 16.16 fixed point.
                            let fixed = |v: f64| (v * 65536.0) as i64;
                            let (x0, y0) = (fixed(pa.x + 0.5), fixed(pa.y + 0.5));
                            let (sx, sy) = (fixed(step.x), fixed(step.y));
                            for (j, i) in (0i64..).zip(slots.iter_mut()) {
                                let (x, y) = ((x0 + j * sx) >> 16, (y0 + j * sy) >> 16);
                                *i = (y as usize) * self.w + x as usize;
                            }
                        } else {
                            for (j, i) in slots.iter_mut().enumerate() {
                                let (x, y) = at(j);
                                // Outside, the top-left pixel: on the border, its gradient is 0.
                                *i = if inside((x, y)) {
                                    y as usize * self.w + x as usize
                                } else {
                                    0
                                };
                            }
                        }
                    }
                    // No pixel: the top-left one, whose gradient is zero (never aligned).
                    _ => slots.fill(0),
                }
                (c0, a) = (end, b);
            }
            let m = batch_end - k0;
            for (g, &i) in g[..m].iter_mut().zip(&idx[..m]) {
                *g = [self.gx[i], self.gy[i]];
            }
            // Aligned samples of each polarity (0: gradient along the left-hand normal).
            let mut mask = [0u32; 2];
            for (j, (g, nrm)) in g[..m].iter().zip(&normal[..m]).enumerate() {
                let (gx, gy) = (f32::from(g[0]), f32::from(g[1]));
                let g2 = gx * gx + gy * gy;
                let across = gx * nrm[0] + gy * nrm[1];
                let aligned = (g2 >= rho2_f) & (across * across >= cos2_f * g2);
                let right = across < 0.0;
                mask[0] |= u32::from(aligned & !right) << j;
                mask[1] |= u32::from(aligned & right) << j;
            }
            for (s, &mk) in mask.iter().enumerate() {
                if mk == 0 {
                    continue;
                }
                count[s] += mk.count_ones();
                first[s] = first[s].min(k0 + mk.trailing_zeros() as usize);
                last[s] = k0 + 31 - mk.leading_zeros() as usize;
                // Trimmed, the piece will span at most samples − first: once that many are
                // meaningful, it is, and only its last aligned sample is still wanted.
                let most = if trim { samples - first[s] } else { samples };
                if self.contrario.meaningful(most as u32, count[s]) {
                    sure = Some(s);
                }
            }
            k0 = batch_end;
        }
        let s = sure.unwrap_or(usize::from(count[1] > count[0]));
        if count[s] == 0 {
            return None;
        }
        if sure.is_some() && trim && k0 < samples {
            // The last aligned sample of that polarity, from the far end back, one sample at a
            // time (each projected; an accepted piece usually ends on one).
            let mut r = turn(&r1, (-half.0, half.1));
            let back = dt.sin_cos();
            for k in (last[s] + 1..samples).rev() {
                if let Some(p) = self.lens.project(&r) {
                    // The line's direction there: towards the previous sample's pixel.
                    let q = self.lens.project(&turn(&r, (-back.0, back.1)));
                    if let Some(q) = q {
                        let d = p - q;
                        let dn = d.norm();
                        let (x, y) = (p.x + 0.5, p.y + 0.5);
                        if dn > 0.0 && x >= 0.0 && y >= 0.0 && x < w && y < h {
                            let i = y as usize * self.w + x as usize;
                            let (gx, gy) = (f64::from(self.gx[i]), f64::from(self.gy[i]));
                            let g2 = gx * gx + gy * gy;
                            let across = (gx * -d.y + gy * d.x) / dn;
                            if g2 >= rho2 && across * across >= cos2 * g2 && usize::from(across < 0.0) == s {
                                last[s] = k;
                                break;
                            }
                        }
                    }
                }
                r = turn(&r, (-back.0, back.1));
            }
        }
        let (a, b) = if trim { (first[s], last[s]) } else { (0, samples - 1) };
        if !self.contrario.meaningful((b + 1 - a) as u32, count[s]) {
            return None;
        }
        Some(if a == 0 && b == samples - 1 {
            Stretch::Whole
        } else {
            Stretch::Part(t0 + a as f64 * dt, t0 + (b + 1) as f64 * dt)
        })
    }

    /// Keeps the strongest `max_edges` candidates and turns them into edges (rig frame).
    #[inline(never)]
    fn select(&mut self) {
        let min_cos = self.min_len_rad.cos();
        self.cands.retain(|c| c.r1.dot(&c.r2) <= min_cos);
        let k = self.max_edges;
        if self.cands.len() > k {
            self.stats.capped = (self.cands.len() - k) as u32;
            if k == 0 {
                self.cands.clear();
            } else {
                self.cands
                    .select_nth_unstable_by(k - 1, |a, b| b.strength.total_cmp(&a.strength));
                self.cands.truncate(k);
            }
        }
        self.cands.sort_unstable_by(|a, b| b.strength.total_cmp(&a.strength));
        let rot = self.rotation;
        for c in &self.cands {
            let (Some(p1), Some(p2)) = (self.lens.project(&c.r1), self.lens.project(&c.r2)) else {
                continue;
            };
            let (lm, lv, lk) = c.left.stats();
            let (rm, rv, rk) = c.right.stats();
            let n_rig = rot * c.n;
            let plane = EdgePlane {
                normal: Unit::new_normalize(n_rig),
                centre: self.centre,
                ends: [Unit::new_normalize(rot * c.r1), Unit::new_normalize(rot * c.r2)],
            };
            let lambda = plane_residual(&c.m, &c.n);
            let length_rad = c.r1.dot(&c.r2).clamp(-1.0, 1.0).acos();
            // The gaps as angles from r1 along the plane, in order.
            let mut gaps = [[0f32; 2]; MAX_GAPS];
            let mut n_gaps = 0;
            for g in &c.gaps[..usize::from(c.n_gaps)] {
                let along = |r: &Vector3<f64>| {
                    let r = (r - c.n * c.n.dot(r)).normalize();
                    angle_in_plane(&c.n, &c.r1, &r)
                };
                let (ta, tb) = (along(&g[0]), along(&g[1]));
                let (t0, t1) = (ta.min(tb), ta.max(tb));
                if t0 > 0.0 && t1 < length_rad && t1 > t0 {
                    gaps[n_gaps] = [t0 as f32, t1 as f32];
                    n_gaps += 1;
                }
            }
            gaps[..n_gaps].sort_unstable_by(|x, y| x[0].total_cmp(&y[0]));
            // The pieces between the gaps the image shows as lines.
            let mut shown = [[0f32; 2]; MAX_GAPS + 1];
            let mut n_shown = 0;
            for k in 0..=n_gaps {
                let from = if k == 0 { 0.0 } else { gaps[k - 1][1] };
                let to = if k == n_gaps { length_rad as f32 } else { gaps[k][0] };
                let piece = if self.params.piece_nfa {
                    self.meaningful_part(&c.n, &c.r1, f64::from(from), f64::from(to))
                } else {
                    Some(Stretch::Whole)
                };
                match piece {
                    Some(Stretch::Whole) => shown[n_shown] = [from, to],
                    Some(Stretch::Part(a, b)) => shown[n_shown] = [a as f32, b as f32],
                    None => continue,
                }
                n_shown += 1;
            }
            self.edges.push(Edge {
                sensor: self.sensor,
                plane,
                px: [Point2::new(p1.x, p1.y), Point2::new(p2.x, p2.y)],
                length_rad,
                strength: c.strength,
                hue: HueSignature {
                    left_mean: lm,
                    left_var: lv,
                    right_mean: rm,
                    right_var: rv,
                    left_kept: lk,
                    right_kept: rk,
                },
                polarity: if 4 * c.bright_left.unsigned_abs() >= 2 * c.count {
                    c.bright_left.signum() as i8
                } else {
                    0
                },
                edgels: c.count,
                rms_rad: (lambda / c.m[6].max(1e-12)).max(0.0).sqrt() as f32,
                gaps,
                n_gaps: n_gaps as u8,
                shown,
                n_shown: n_shown as u8,
            });
        }
    }
}

/// Whether runs of edgels fitted by two planes with residual `two` (Σ w sin²), and by one plane
/// with residual `one`, are two lines: the rise from two planes to one (the excess) is more
/// than noise explains and more than Σ w (`excess` · `tol`)²; `weight` is Σ w, `n` the edgels,
/// `tol` the split tolerance (sine).
///
/// For two parallel lines d apart, or meeting at a kink, the excess per unit weight is
/// (w₁w₂/(w₁+w₂)²) d²: about d²/4 when the runs are equal. For one line it is noise absorbed by
/// the second plane's three degrees of freedom: the F statistic (excess / 3) / (residual /
/// (n − 6)) stays near 1, and `TWO_LINE_F` keeps a noisy short run whole. The excess floor keeps
/// one long line whole when a regular pattern (pixel staircases) makes a tiny excess significant.
fn two_lines_apart(one: f64, two: f64, weight: f64, n: usize, tol: f64, excess: f64) -> bool {
    let rise = one - two;
    let c = excess * tol;
    n > 6 && rise > c * c * weight && rise * (n - 6) as f64 > TWO_LINE_F * 3.0 * two.max(0.0)
}

/// See [`two_lines_apart`].
const TWO_LINE_F: f64 = 10.0;

/// Rays further off their piece's plane than this many RMS are left out of its fit…
const OUTLIER_SIGMAS: f64 = 2.5;
/// …but never rays within this (rad) of it.
const OUTLIER_FLOOR_RAD: f64 = 0.02 * std::f64::consts::PI / 180.0;

/// Weighted second moments of rays: Σ w r rᵀ as (xx, xy, xz, yy, yz, zz), then Σ w.
type Moments = [f64; 7];

/// w r rᵀ as (xx, xy, xz, yy, yz, zz) and w.
#[inline]
fn weighted_outer(r: &Vector3<f64>, w: f64) -> Moments {
    let (x, y, z) = (w * r.x, w * r.y, w * r.z);
    [x * r.x, x * r.y, x * r.z, y * r.y, y * r.z, z * r.z, w]
}

/// Weight of an edgel in the plane fits: proportional to its gradient magnitude (contrast), so
/// that faint edgels (noise, a weak neighbouring edge bleeding in) pull less.
#[inline]
fn edgel_weight(mag: f32) -> f64 {
    mag as f64 / 1024.0
}

/// Unit normal of the plane through the origin best fitting rays with moments `m`: the
/// eigenvector of the smallest eigenvalue λ₁ of M = Σ w r rᵀ.
///
/// Rays of an edge lie close to a plane, so λ₁ is tiny beside λ₂ ≤ λ₃, and the adjugate
/// adj M = λ₂λ₃ v₁v₁ᵀ + λ₁λ₃ v₂v₂ᵀ + λ₁λ₂ v₃v₃ᵀ is v₁v₁ᵀ up to a part λ₁/λ₂ as large: its longest
/// column is v₁ to that relative error, and each further product with adj M squares it (inverse
/// iteration without a solve). A fraction of a general symmetric eigen-decomposition's cost,
/// which matters because every piece and every merge of every frame fits a plane. Degenerate
/// moments (rank ≤ 1: one ray direction) fall back to the full decomposition.
fn plane_normal(m: &Moments) -> Option<Vector3<f64>> {
    let r0 = Vector3::new(m[0], m[1], m[2]);
    let r1 = Vector3::new(m[1], m[3], m[4]);
    let r2 = Vector3::new(m[2], m[4], m[5]);
    let cols = [r1.cross(&r2), r2.cross(&r0), r0.cross(&r1)];
    let norms = cols.map(|c| c.norm_squared());
    let k = if norms[0] >= norms[1] && norms[0] >= norms[2] {
        0
    } else if norms[1] >= norms[2] {
        1
    } else {
        2
    };
    let scale = m[0] + m[3] + m[5];
    if !(norms[k].is_finite() && norms[k] > 1e-28 * scale.powi(4)) {
        return plane_normal_eigen(m);
    }
    let mut v = cols[k] / norms[k].sqrt();
    for _ in 0..2 {
        let next = cols[0] * v.x + cols[1] * v.y + cols[2] * v.z;
        let n = next.norm();
        if !(n.is_finite() && n > 0.0) {
            break;
        }
        v = next / n;
    }
    Some(v)
}

/// [`plane_normal`] by a full symmetric eigen-decomposition.
fn plane_normal_eigen(m: &Moments) -> Option<Vector3<f64>> {
    let mat = Matrix3::new(m[0], m[1], m[2], m[1], m[3], m[4], m[2], m[4], m[5]);
    let e = mat.symmetric_eigen();
    let k = e.eigenvalues.imin();
    let v: Vector3<f64> = e.eigenvectors.column(k).into_owned();
    let n = v.norm();
    (n.is_finite() && n > 0.5).then(|| v / n)
}

/// Direction index into [`DIRS`] of the edge tangent (the gradient turned by +90°: (−gy, gx)),
/// the nearest of the eight 45° steps.
#[inline]
fn tangent_octant(gx: i16, gy: i16) -> usize {
    let (x, y) = (-(gy as i32), gx as i32);
    let (ax, ay) = (x.unsigned_abs(), y.unsigned_abs());
    // tan 22.5° ≈ 53/128, as in the gradient bins.
    if ay * 128 <= ax * 53 {
        if x > 0 {
            0
        } else {
            4
        }
    } else if ax * 128 <= ay * 53 {
        if y > 0 {
            2
        } else {
            6
        }
    } else {
        match (x > 0, y > 0) {
            (true, true) => 1,
            (false, true) => 3,
            (false, false) => 5,
            (true, false) => 7,
        }
    }
}

/// nᵀ M n: the sum of squared sines of the rays' angles off the plane.
fn plane_residual(m: &Moments, n: &Vector3<f64>) -> f64 {
    let mat = Matrix3::new(m[0], m[1], m[2], m[1], m[3], m[4], m[2], m[4], m[5]);
    n.dot(&(mat * n))
}

/// Angle of ray `r` around the plane normal `n`, from the reference direction `e1`.
#[inline]
fn angle_in_plane(n: &Vector3<f64>, e1: &Vector3<f64>, r: &Vector3<f64>) -> f64 {
    let e2 = n.cross(e1);
    r.dot(&e2).atan2(r.dot(e1))
}

/// What [`Workspace::meaningful_part`] keeps of a stretch.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Stretch {
    /// All of it.
    Whole,
    /// The part between these angles.
    Part(f64, f64),
}

/// Pairs whose normals `merge_across_chains` tests at once.
const PAIR_BLOCK: usize = 32;

fn try_merge(
    ci: &Candidate,
    cj: &Candidate,
    gap_max: f64,
    tol: f64,
    two_line: f64,
    min_support: f64,
) -> Option<Candidate> {
    // Orient j like i.
    let di = ci.r2 - ci.r1;
    let same = di.dot(&(cj.r2 - cj.r1)) >= 0.0;
    let (jr1, jr2, jl, jr, jb) = if same {
        (cj.r1, cj.r2, cj.left, cj.right, cj.bright_left)
    } else {
        (cj.r2, cj.r1, cj.right, cj.left, -cj.bright_left)
    };
    // Cheapest reject: the nearest ends further apart than any gap or overlap allowed (pairs
    // on one line far apart are most of those tried).
    let near = ci
        .r1
        .dot(&jr1)
        .max(ci.r1.dot(&jr2))
        .max(ci.r2.dot(&jr1))
        .max(ci.r2.dot(&jr2));
    if near < (1.5 * gap_max + 0.01).min(std::f64::consts::PI).cos() {
        return None;
    }
    // Cheap reject before the eigen-decomposition: the gap measured along i's own plane.
    {
        let e2 = ci.n.cross(&ci.r1);
        let ang = |r: &Vector3<f64>| r.dot(&e2).atan2(r.dot(&ci.r1));
        let ilen = ang(&ci.r2);
        let (a1, a2) = (ang(&jr1), ang(&jr2));
        let (lo, hi) = (a1.min(a2), a1.max(a2));
        let gap = if lo > ilen { lo - ilen } else { -hi };
        if gap > 1.5 * gap_max + 0.01 {
            return None;
        }
    }
    let m: Moments = std::array::from_fn(|k| ci.m[k] + cj.m[k]);
    let mut n = plane_normal(&m)?;
    if n.dot(&ci.n) < 0.0 {
        n = -n;
    }
    // Every end ray must lie on the merged plane, and the fit must stay tight.
    for r in [ci.r1, ci.r2, jr1, jr2] {
        if n.dot(&r).abs() > tol {
            return None;
        }
    }
    let count = ci.count + cj.count;
    let rss = plane_residual(&m, &n);
    if rss / m[6] > tol * tol * 0.25 {
        return None;
    }
    // Nor, with the two-line test on, may it be two lines side by side or at a kink.
    let two = plane_residual(&ci.m, &ci.n) + plane_residual(&cj.m, &cj.n);
    if two_line > 0.0 && two_lines_apart(rss, two, m[6], count as usize, tol, two_line) {
        return None;
    }
    // Intervals along the great circle: must not overlap (beyond a sliver), gap small.
    let e1 = (ci.r1 - n * n.dot(&ci.r1)).normalize();
    let ia = (0.0, angle_in_plane(&n, &e1, &ci.r2));
    let ja = (angle_in_plane(&n, &e1, &jr1), angle_in_plane(&n, &e1, &jr2));
    // i runs in increasing angle (ia.1 > 0 for a short arc oriented r1→r2 about n).
    if ia.1 <= 0.0 || ja.1 <= ja.0 {
        return None;
    }
    let gap = if ja.0 >= ia.1 - 1e-9 {
        ja.0 - ia.1
    } else if ja.1 <= ia.0 + 1e-9 {
        ia.0 - ja.1
    } else {
        // Overlapping: allow only a sliver (junction re-tracing).
        let overlap = ia.1.min(ja.1) - ia.0.max(ja.0);
        -overlap
    };
    if gap > gap_max || gap < -0.25 * gap_max.min((ia.1 - ia.0).min(ja.1 - ja.0)) {
        return None;
    }
    let lo = if ja.0 < ia.0 { jr1 } else { ci.r1 };
    let hi = if ja.1 > ia.1 { jr2 } else { ci.r2 };
    let r1 = (lo - n * n.dot(&lo)).normalize();
    let r2 = (hi - n * n.dot(&hi)).normalize();
    // Mostly edge: the pieces must cover `min_support` of the merged span, so that short
    // collinear pieces far apart (a row of windows, tiles, texture) do not chain up into one
    // long edge across what lies between them.
    let support = ci.support + cj.support - (-gap).max(0.0);
    if support < min_support * r1.dot(&r2).clamp(-1.0, 1.0).acos() {
        return None;
    }
    // The gaps: both pieces' own, and the one between them.
    let mut gaps = ci.gaps;
    let mut n_gaps = usize::from(ci.n_gaps);
    let between = (gap > 0.0).then_some(if ja.0 >= ia.1 - 1e-9 {
        [ci.r2, jr1]
    } else {
        [jr2, ci.r1]
    });
    for g in cj.gaps[..usize::from(cj.n_gaps)].iter().copied().chain(between) {
        keep_widest(&mut gaps, &mut n_gaps, g);
    }
    let mut left = ci.left;
    left.add(&jl);
    let mut right = ci.right;
    right.add(&jr);
    Some(Candidate {
        m,
        count,
        n,
        r1,
        r2,
        strength: ci.strength + cj.strength,
        support,
        bright_left: ci.bright_left + jb,
        left,
        right,
        gaps,
        n_gaps: n_gaps as u8,
        alive: true,
        changed: false,
        merged_now: false,
    })
}

/// Adds the gap `g` (its two end rays) to the first `n` of `gaps`, or, when they are full, in
/// place of the narrowest if it is wider: a gap left out counts as seen, as every gap did before
/// edges kept them.
fn keep_widest(gaps: &mut [[Vector3<f64>; 2]; MAX_GAPS], n: &mut usize, g: [Vector3<f64>; 2]) {
    if *n < MAX_GAPS {
        gaps[*n] = g;
        *n += 1;
        return;
    }
    // Cosines: the narrowest gap has the largest.
    let (k, narrowest) = gaps
        .iter()
        .enumerate()
        .map(|(k, x)| (k, x[0].dot(&x[1])))
        .fold((0, f64::NEG_INFINITY), |a, b| if b.1 > a.1 { b } else { a });
    if g[0].dot(&g[1]) < narrowest {
        gaps[k] = g;
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

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::SmallRng;
    use rand::{Rng, SeedableRng};

    /// The adjugate's normal is the smallest eigenvector, on rays from short and long arcs of
    /// random great circles with noise off the plane, down to pieces of a few edgels.
    #[test]
    fn plane_normal_matches_the_eigen_decomposition() {
        let mut rng = SmallRng::seed_from_u64(5);
        let mut worst = 0.0f64;
        for trial in 0..2000 {
            let n = Unit::new_normalize(Vector3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            ));
            let e1 = n.cross(&Vector3::new(0.3, -0.5, 0.8)).normalize();
            let e2 = n.cross(&e1);
            let length = [0.02f64, 0.1, 0.5, 2.0][trial % 4];
            let noise = [0.0f64, 1e-5, 1e-4, 1e-3][(trial / 4) % 4];
            let count = [5usize, 12, 80][(trial / 16) % 3];
            let start = rng.random_range(0.0..6.0);
            let mut m: Moments = [0.0; 7];
            for k in 0..count {
                let a = start + length * k as f64 / (count - 1) as f64;
                let off = noise * rng.random_range(-1.0..1.0);
                let r = (e1 * a.cos() + e2 * a.sin() + n.into_inner() * off).normalize();
                let o = weighted_outer(&r, rng.random_range(0.5..2.0));
                for (x, y) in m.iter_mut().zip(o) {
                    *x += y;
                }
            }
            let fast = plane_normal(&m).expect("a normal");
            let slow = plane_normal_eigen(&m).expect("a normal");
            let angle = fast.cross(&slow).norm().min(1.0).asin();
            // The normal is only defined to about noise / length: compare there.
            worst = worst.max(angle * length / (noise + 1e-9 * length));
            // Both minimise nᵀMn: the fast one is never worse than the decomposition.
            assert!(
                plane_residual(&m, &fast) <= plane_residual(&m, &slow) * (1.0 + 1e-9) + 1e-14 * m[6],
                "trial {trial} len {length} noise {noise} count {count}: {:e} vs {:e}, angle {angle:e}",
                plane_residual(&m, &fast),
                plane_residual(&m, &slow)
            );
        }
        assert!(worst < 1e-2, "worst angle {worst:e}, relative to noise / length");
    }

    /// One ray direction only: no plane, and no panic.
    #[test]
    fn plane_normal_of_degenerate_moments_falls_back() {
        let r = Vector3::new(0.0, 0.6, 0.8);
        let m = weighted_outer(&r, 3.0);
        let n = plane_normal(&m).expect("some plane through the ray");
        assert!(n.dot(&r).abs() < 1e-9);
        // No rays at all: whatever comes back is a unit vector, never NaN.
        if let Some(v) = plane_normal(&[0.0; 7]) {
            assert!((v.norm() - 1.0).abs() < 1e-9);
        }
    }

    /// A one-sensor rig of 320×240 through a pinhole or an equidistant fisheye.
    fn workspace(model: &str) -> Workspace {
        let text = format!(
            "name = \"nfa\"\n\n[[sensors]]\nid = 0\nresolution = [320, 240]\nmodel = \"{model}\"\n\
intrinsics = [150.0, 150.0, 159.5, 119.5]\n{}rotation_wxyz = [1.0, 0.0, 0.0, 0.0]\ntranslation_m = [0.0, 0.0, 0.0]\n",
            if model == "kb4" {
                "distortion = [0.0, 0.0, 0.0, 0.0]\n"
            } else {
                ""
            }
        );
        let rig = omnitrack_core::rig::Rig::from_toml_str(&text, "(test rig)").expect("rig");
        let s = &rig.sensors[0];
        Workspace::new(
            s,
            ray_table(s),
            Arc::new(HueTable::new(0.15, 0.1)),
            EdgeParams::default(),
            5,
            64,
            2.0,
        )
    }

    /// The a-contrario test keeps a clean line (straight in space: curved on the fisheye) and
    /// refuses the same stretch on pure noise, on a pinhole and on a fisheye.
    #[test]
    fn a_contrario_keeps_a_line_and_refuses_noise() {
        for model in ["pinhole", "kb4"] {
            let mut ws = workspace(model);
            // The stretch tested: the great circle through the rays of two pixels, well inside.
            let r1 = ws.lens.unproject(&Point2::new(60.0, 70.0)).expect("ray").into_inner();
            let r2 = ws.lens.unproject(&Point2::new(250.0, 160.0)).expect("ray").into_inner();
            let n = r1.cross(&r2).normalize();
            let span = r1.dot(&r2).acos();
            let mut img = SensorImage::new(0, 320, 240);
            // A clean edge on that plane: 60 grey levels on one side, 180 on the other.
            for (k, px) in img.pixels_mut().chunks_exact_mut(3).enumerate() {
                let p = Point2::new((k % 320) as f64, (k / 320) as f64);
                let r = ws.lens.unproject(&p).expect("ray");
                px.fill(if n.dot(&r) > 0.0 { 180 } else { 60 });
            }
            img.set_valid(0);
            ws.run(&img);
            assert!(ws.params.piece_nfa);
            let kept = ws.meaningful_part(&n, &r1, 0.0, span);
            match kept {
                Some(Stretch::Whole) => {}
                Some(Stretch::Part(a, b)) => assert!(a < 0.02 * span && b > 0.98 * span, "{model}: {a}..{b} of {span}"),
                None => panic!("{model}: a clean line refused"),
            }
            // Short pieces of it too: 20 px is above LSD's minimum of 16 aligned pixels here.
            let short = span * 20.0 / 212.0;
            assert!(
                ws.meaningful_part(&n, &r1, 0.3, 0.3 + short).is_some(),
                "{model}: a 20 px piece refused"
            );
            // Pure noise: uniform grey levels, independent per pixel and channel.
            let mut rng = SmallRng::seed_from_u64(3);
            for trial in 0..20 {
                for v in img.pixels_mut() {
                    *v = rng.random();
                }
                img.set_valid(0);
                ws.run(&img);
                for (a, b) in [(0.0, span), (0.2, 0.2 + short), (0.5, 0.5 + 2.0 * short)] {
                    assert_eq!(
                        ws.meaningful_part(&n, &r1, a, b),
                        None,
                        "{model} trial {trial}: noise kept at {a}..{b}"
                    );
                }
            }
        }
    }

    /// `GRADIENT_PER_GREY`: a ramp of one grey level a pixel gives 128.
    #[test]
    fn the_gradient_of_a_unit_ramp() {
        let mut ws = workspace("pinhole");
        let mut img = SensorImage::new(0, 320, 240);
        for (k, px) in img.pixels_mut().chunks_exact_mut(3).enumerate() {
            px.fill((k % 320 / 2 + 20) as u8);
        }
        img.set_valid(0);
        ws.run(&img);
        let i = 100 * 320 + 150;
        // Half a grey level a pixel.
        assert_eq!((ws.gx[i], ws.gy[i]), ((GRADIENT_PER_GREY / 2.0) as i16, 0));
    }

    /// The integer octant of the tangent is the rounded angle of (−gy, gx).
    #[test]
    fn tangent_octant_rounds_the_tangent_angle() {
        let mut rng = SmallRng::seed_from_u64(9);
        for _ in 0..20000 {
            let gx: i16 = rng.random_range(-4000..4000);
            let gy: i16 = rng.random_range(-4000..4000);
            if gx == 0 && gy == 0 {
                continue;
            }
            let a = (gx as f64).atan2(-(gy as f64));
            let exact = a / std::f64::consts::FRAC_PI_4;
            // 53/128 stands for tan 22.5°: at most 2e-4 rad off the true boundaries.
            if (exact - exact.round()).abs() > 0.5 - 1e-3 {
                continue;
            }
            let want = (exact.round() as i64).rem_euclid(8) as usize;
            assert_eq!(tangent_octant(gx, gy), want, "gx {gx} gy {gy}");
        }
    }
}
