//! One sensor's edge extraction, on buffers allocated once: grey image → integer Sobel gradients →
//! non-maximum suppression → edgel chains → sub-pixel edgels unprojected to rays (per-pixel ray
//! table, bilinear) → planes through the optical centre (split where a chain bends, merge
//! collinear pieces, also across chains) → hue strips → the strongest `max_edges` edges.

use super::hue::{HueAcc, HueTable};
use super::{Edge, EdgeParams, HueSignature, Smoothing};
use crate::capture::SensorImage;
use crate::geometry::{EdgePlane, Lens};
use crate::rig::Sensor;
use nalgebra::{Matrix3, Point2, Point3, Unit, UnitQuaternion, Vector3};
use std::sync::Arc;

/// Longest chain traced in one go (a longer one is cut; the rest is traced as another chain).
const MAX_CHAIN: usize = 4096;

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
    /// Net count of edgels brighter on the left (> 0: left is the bright side).
    bright_left: i32,
    left: HueAcc,
    right: HueAcc,
    alive: bool,
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
    /// The image as three colour planes (R, G, B), u8.
    planes: Vec<u8>,
    /// A colour channel smoothed by the binomial [1 2 1]² (×16), u16; the horizontal pass goes to `hblur`.
    smooth: Vec<u16>,
    hblur: Vec<u16>,
    col_sum: Vec<i16>,
    col_diff: Vec<i16>,
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
    pub edges: Vec<Edge>,
    /// Counters of the last run (for benchmarks and diagnostics).
    pub stats: SensorStats,
}

/// What the last run of one sensor saw.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SensorStats {
    pub edgels: u32,
    pub chains: u32,
    pub candidates: u32,
    /// Candidates dropped because the candidate buffer was full of stronger ones.
    pub candidates_dropped: u32,
    pub merged: u32,
    /// Edges dropped by the cap on edges per sensor.
    pub capped: u32,
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
            planes: vec![0; 3 * n],
            smooth: vec![0; n],
            hblur: vec![0; n],
            col_sum: vec![0; w],
            col_diff: vec![0; w],
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
            edges: Vec::with_capacity(max_edges),
            stats: SensorStats::default(),
        }
    }

    /// Detects the edges of one image into `self.edges` (cleared first). An invalid image, or
    /// one of the wrong size, yields no edges.
    pub fn run(&mut self, img: &SensorImage) {
        self.edges.clear();
        self.cands.clear();
        self.stats = SensorStats::default();
        if !img.valid || img.width() as usize != self.w || img.height() as usize != self.h || self.w < 3 || self.h < 3 {
            return;
        }
        // Colour gradient: per pixel, the gradient of the channel (R, G or B) where it is largest,
        // so that edges between colours of equal brightness are found too.
        self.planes(img.pixels());
        for c in 0..3 {
            self.smooth(c);
            self.sobel(c > 0);
        }
        self.nms();
        self.link(img.pixels());
        self.merge_across_chains();
        self.select();
    }

    /// Splits the RGB image into three planes.
    #[inline(never)]
    fn planes(&mut self, rgb: &[u8]) {
        let n = self.w * self.h;
        let (r, rest) = self.planes.split_at_mut(n);
        let (g, b) = rest.split_at_mut(n);
        for (((p, r), g), b) in rgb
            .chunks_exact(3)
            .zip(r.iter_mut())
            .zip(g.iter_mut())
            .zip(b.iter_mut())
        {
            *r = p[0];
            *g = p[1];
            *b = p[2];
        }
    }

    /// Plane `c` smoothed for the Sobel (×16, u16): `hblur` by the binomial [1 2 1] across
    /// columns (×4), `smooth` down rows. With [`Smoothing::Along`] `smooth` is the vertical pass
    /// of the plane itself, so that the Sobel's x derivative is taken of `smooth` (smoothing along
    /// a vertical edge only) and its y derivative of `hblur`; with [`Smoothing::Full`] `smooth`
    /// is the vertical pass of `hblur` (the binomial [1 2 1]², both derivatives of it). Borders
    /// replicate.
    #[inline(never)]
    fn smooth(&mut self, c: usize) {
        let (w, h) = (self.w, self.h);
        let n = w - 2;
        let plane = &self.planes[c * w * h..(c + 1) * w * h];
        let mode = self.params.smoothing;
        if mode == Smoothing::None {
            for (d, &p) in self.smooth.iter_mut().zip(plane) {
                *d = 16 * p as u16;
            }
            return;
        }
        let hscale: u16 = if mode == Smoothing::Along { 4 } else { 1 };
        for (src, dst) in plane.chunks_exact(w).zip(self.hblur.chunks_exact_mut(w)) {
            let (a, b, cc) = (&src[..n], &src[1..n + 1], &src[2..n + 2]);
            let out = &mut dst[1..n + 1];
            for u in 0..n {
                out[u] = hscale * (a[u] as u16 + 2 * b[u] as u16 + cc[u] as u16);
            }
            dst[0] = 4 * hscale * src[0] as u16;
            dst[w - 1] = 4 * hscale * src[w - 1] as u16;
        }
        if mode == Smoothing::Along {
            for v in 0..h {
                let (r0, r2) = (v.saturating_sub(1), (v + 1).min(h - 1));
                let a = &plane[r0 * w..r0 * w + w];
                let b = &plane[v * w..v * w + w];
                let c = &plane[r2 * w..r2 * w + w];
                let out = &mut self.smooth[v * w..v * w + w];
                for u in 0..w {
                    out[u] = 4 * (a[u] as u16 + 2 * b[u] as u16 + c[u] as u16);
                }
            }
            return;
        }
        for v in 0..h {
            let (r0, r2) = (v.saturating_sub(1), (v + 1).min(h - 1));
            let a = &self.hblur[r0 * w..r0 * w + w];
            let b = &self.hblur[v * w..v * w + w];
            let c = &self.hblur[r2 * w..r2 * w + w];
            let out = &mut self.smooth[v * w..v * w + w];
            for u in 0..w {
                out[u] = a[u] + 2 * b[u] + c[u];
            }
        }
    }

    /// Integer 3×3 Sobel on the smoothed channel (so a 5×5 derivative), separable: the x
    /// derivative of `smooth`, the y derivative of `hblur` under [`Smoothing::Along`], else of
    /// `smooth` too; with `fold` a pixel keeps the earlier channels' gradient unless this one's
    /// is larger. Border rows and columns stay 0.
    #[inline(never)]
    fn sobel(&mut self, fold: bool) {
        let w = self.w;
        let n = w - 2;
        let ysrc = if self.params.smoothing == Smoothing::Along {
            &self.hblur
        } else {
            &self.smooth
        };
        for v in 1..self.h - 1 {
            let r0 = &self.smooth[(v - 1) * w..(v - 1) * w + w];
            let r1 = &self.smooth[v * w..v * w + w];
            let r2 = &self.smooth[(v + 1) * w..(v + 1) * w + w];
            let y0 = &ysrc[(v - 1) * w..(v - 1) * w + w];
            let y2 = &ysrc[(v + 1) * w..(v + 1) * w + w];
            let cs = &mut self.col_sum[..w];
            let cd = &mut self.col_diff[..w];
            for u in 0..w {
                cs[u] = r0[u] as i16 + 2 * r1[u] as i16 + r2[u] as i16;
                cd[u] = y2[u] as i16 - y0[u] as i16;
            }
            let (s0, s2) = (&self.col_sum[..n], &self.col_sum[2..n + 2]);
            let (d0, d1, d2) = (&self.col_diff[..n], &self.col_diff[1..n + 1], &self.col_diff[2..n + 2]);
            let gx = &mut self.gx[v * w + 1..v * w + 1 + n];
            let gy = &mut self.gy[v * w + 1..v * w + 1 + n];
            let mag = &mut self.mag[v * w + 1..v * w + 1 + n];
            sobel_row(s0, s2, d0, d1, d2, gx, gy, mag, fold);
        }
    }

    /// Gradient bin: 1 horizontal gradient, 2 vertical, 3 diagonal with gx·gy > 0, 4 the other.
    #[inline]
    fn bin(gx: i16, gy: i16) -> u8 {
        let (ax, ay) = (gx.unsigned_abs() as u32, gy.unsigned_abs() as u32);
        // tan 22.5° ≈ 0.4142 ≈ 53/128.
        if ay * 128 <= ax * 53 {
            1
        } else if ax * 128 <= ay * 53 {
            2
        } else if (gx > 0) == (gy > 0) {
            3
        } else {
            4
        }
    }

    /// Index offset of the gradient direction of a bin.
    #[inline]
    fn bin_step(&self, bin: u8) -> (isize, isize) {
        match bin {
            1 => (1, 0),
            2 => (0, 1),
            3 => (1, 1),
            _ => (1, -1),
        }
    }

    #[inline(never)]
    fn nms(&mut self) {
        let w = self.w;
        let thr = self.params.gradient_threshold.min(i16::MAX as u16) as i16;
        let mut count = 0u32;
        for v in 1..self.h - 1 {
            let row = v * w;
            for u in 1..w - 1 {
                let i = row + u;
                let m = self.mag[i];
                if m < thr {
                    self.map[i] = 0;
                    continue;
                }
                let bin = Self::bin(self.gx[i], self.gy[i]);
                let (du, dv) = self.bin_step(bin);
                let off = dv * w as isize + du;
                let a = self.mag[(i as isize - off) as usize];
                let b = self.mag[(i as isize + off) as usize];
                let keep = m > a && m >= b;
                self.map[i] = if keep { bin } else { 0 };
                count += keep as u32;
            }
        }
        self.stats.edgels = count;
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
        for v in 1..h - 1 {
            for u in 1..w - 1 {
                let i = v * w + u;
                if map[i] == 0 {
                    continue;
                }
                map[i] = 0;
                // Tangent = gradient turned by +90°: (−gy, gx).
                let (gx, gy) = (self.gx[i] as f64, self.gy[i] as f64);
                let a = gx.atan2(-gy);
                let dir = ((a / std::f64::consts::FRAC_PI_4).round() as i64).rem_euclid(8) as usize;
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
        for i in idx {
            let i = i as usize;
            let (gx, gy) = (self.gx[i], self.gy[i]);
            let bin = Self::bin(gx, gy);
            let (du, dv) = self.bin_step(bin);
            let off = dv * w as isize + du;
            let m0 = self.mag[i] as f32;
            let ma = self.mag[(i as isize - off) as usize] as f32;
            let mb = self.mag[(i as isize + off) as usize] as f32;
            // Gaussian sub-pixel peak: the parabola through the logarithms of the magnitudes
            // (exact for a Gaussian profile; less biased than a parabola on the magnitudes for
            // the narrow profiles of the 3-px-wide derivative).
            let (la, l0, lb) = (ma.max(1.0).ln(), m0.max(1.0).ln(), mb.max(1.0).ln());
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
        for &(a, b) in &pieces {
            self.add_piece(a as usize, b as usize, rgb);
        }
        self.pieces = pieces;
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
        if r1.dot(&r2).clamp(-1.0, 1.0).acos() < 0.5 * self.min_len_rad {
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
            bright_left,
            left: lacc,
            right: racc,
            alive: true,
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
    /// an occluder, a gap in the edgels or a junction), same polarity.
    #[inline(never)]
    fn merge_across_chains(&mut self) {
        let cos_max = self.params.merge_angle_rad.cos();
        let gap_max = self.params.merge_gap_rad;
        let tol = self.params.split_tolerance_rad.sin();
        for _pass in 0..3 {
            let mut merged_any = false;
            for i in 0..self.cands.len() {
                if !self.cands[i].alive {
                    continue;
                }
                for j in i + 1..self.cands.len() {
                    if !self.cands[j].alive {
                        continue;
                    }
                    let (ci, cj) = (&self.cands[i], &self.cands[j]);
                    let dot = ci.n.dot(&cj.n);
                    if dot.abs() < cos_max {
                        continue;
                    }
                    if let Some(m) = try_merge(ci, cj, gap_max, tol) {
                        self.cands[i] = m;
                        self.cands[j].alive = false;
                        self.stats.merged += 1;
                        merged_any = true;
                    }
                }
            }
            if !merged_any {
                break;
            }
        }
        self.cands.retain(|c| c.alive);
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
            self.edges.push(Edge {
                sensor: self.sensor,
                plane,
                px: [Point2::new(p1.x, p1.y), Point2::new(p2.x, p2.y)],
                length_rad: c.r1.dot(&c.r2).clamp(-1.0, 1.0).acos(),
                strength: c.strength,
                hue: HueSignature {
                    left_mean: lm,
                    left_var: lv,
                    right_mean: rm,
                    right_var: rv,
                    left_kept: lk,
                    right_kept: rk,
                },
                edgels: c.count,
                rms_rad: (lambda / c.m[6].max(1e-12)).max(0.0).sqrt() as f32,
            });
        }
    }
}

/// One row of the Sobel on the vertical sums `s` and differences `d` (u ± 1 as slices of equal
/// length); with `fold` a pixel keeps its earlier gradient unless the new one is larger. A free
/// function over slices, so that the compiler knows they do not alias and vectorises it.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn sobel_row(
    s0: &[i16],
    s2: &[i16],
    d0: &[i16],
    d1: &[i16],
    d2: &[i16],
    gx: &mut [i16],
    gy: &mut [i16],
    mag: &mut [i16],
    fold: bool,
) {
    let n = gx
        .len()
        .min(gy.len())
        .min(mag.len())
        .min(s0.len())
        .min(s2.len())
        .min(d0.len())
        .min(d1.len())
        .min(d2.len());
    let (s0, s2, d0, d1, d2) = (&s0[..n], &s2[..n], &d0[..n], &d1[..n], &d2[..n]);
    let (gx, gy, mag) = (&mut gx[..n], &mut gy[..n], &mut mag[..n]);
    if fold {
        for u in 0..n {
            let x = s2[u].wrapping_sub(s0[u]);
            let y = d0[u].wrapping_add(d1[u].wrapping_mul(2)).wrapping_add(d2[u]);
            let m = x.wrapping_abs().wrapping_add(y.wrapping_abs());
            let keep = ((m > mag[u]) as i16).wrapping_neg();
            gx[u] = (x & keep) | (gx[u] & !keep);
            gy[u] = (y & keep) | (gy[u] & !keep);
            mag[u] = (m & keep) | (mag[u] & !keep);
        }
    } else {
        for u in 0..n {
            let x = s2[u].wrapping_sub(s0[u]);
            let y = d0[u].wrapping_add(d1[u].wrapping_mul(2)).wrapping_add(d2[u]);
            gx[u] = x;
            gy[u] = y;
            mag[u] = x.wrapping_abs().wrapping_add(y.wrapping_abs());
        }
    }
}

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
/// eigenvector of the smallest eigenvalue of Σ r rᵀ.
fn plane_normal(m: &Moments) -> Option<Vector3<f64>> {
    let mat = Matrix3::new(m[0], m[1], m[2], m[1], m[3], m[4], m[2], m[4], m[5]);
    let e = mat.symmetric_eigen();
    let k = e.eigenvalues.imin();
    let v: Vector3<f64> = e.eigenvectors.column(k).into_owned();
    let n = v.norm();
    (n.is_finite() && n > 0.5).then(|| v / n)
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

fn try_merge(ci: &Candidate, cj: &Candidate, gap_max: f64, tol: f64) -> Option<Candidate> {
    // Orient j like i.
    let di = ci.r2 - ci.r1;
    let same = di.dot(&(cj.r2 - cj.r1)) >= 0.0;
    let (jr1, jr2, jl, jr, jb) = if same {
        (cj.r1, cj.r2, cj.left, cj.right, cj.bright_left)
    } else {
        (cj.r2, cj.r1, cj.right, cj.left, -cj.bright_left)
    };
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
    if plane_residual(&m, &n) / m[6] > tol * tol * 0.25 {
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
        bright_left: ci.bright_left + jb,
        left,
        right,
        alive: true,
    })
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
