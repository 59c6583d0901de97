//! One chain's rays → candidate pieces: split where the chain bends off a great circle
//! (Douglas–Peucker on the sphere), neighbouring pieces merged back while still one plane, cut
//! again where two planes fit far better than one (the two-line test), each piece's plane refitted
//! without its outliers.
//!
//! In: the chain loaded by [`chain`](super::chain) (rays, positions, gradients, moment prefix
//! sums) and the image (for the hue strips). Out: [`Candidate`]s in the [`Workspace`], each with
//! its moments, plane, end rays, strength, polarity count and hue sums; when the buffer is full,
//! the weakest gives way.

use super::plane::{edgel_weight, plane_normal, plane_residual, two_lines_apart, weighted_outer, Moments};
use super::{Candidate, Workspace};
use crate::edge::MAX_GAPS;
use crate::hue::{HueAcc, HueTable};
use multiversion::multiversion;
use nalgebra::Vector3;

impl Workspace {
    fn moments(&self, a: usize, b: usize) -> Moments {
        let (p, q) = (&self.buf.prefix[a], &self.buf.prefix[b + 1]);
        std::array::from_fn(|k| q[k] - p[k])
    }

    /// Largest |n · r| over edgels a..=b.
    fn max_dev(&self, n: &Vector3<f64>, a: usize, b: usize) -> (f64, usize) {
        let mut best = (0.0, a);
        for k in a..=b {
            let d = n.dot(&self.buf.ray[k]).abs();
            if d > best.0 {
                best = (d, k);
            }
        }
        best
    }

    #[inline(never)]
    pub(super) fn fit_chain(&mut self, rgb: &[u8]) {
        let n = self.buf.ray.len();
        let min_n = self.params.min_chain_edgels;
        if n < min_n {
            return;
        }
        let tol = self.params.split_tolerance_rad.sin();
        // Split (Douglas–Peucker on the sphere: deviation from the end rays' great circle).
        self.buf.pieces.clear();
        self.buf.stack.clear();
        self.buf.stack.push((0, n as u32 - 1));
        while let Some((a, b)) = self.buf.stack.pop() {
            let (a, b) = (a as usize, b as usize);
            if b + 1 - a < min_n {
                continue;
            }
            let c = self.buf.ray[a].cross(&self.buf.ray[b]);
            let cn = c.norm();
            if cn < 1e-9 {
                continue;
            }
            let (dev, k) = self.max_dev(&(c / cn), a, b);
            if dev > tol && k > a && k < b {
                self.buf.stack.push((k as u32, b as u32));
                self.buf.stack.push((a as u32, k as u32));
            } else {
                self.buf.pieces.push((a as u32, b as u32));
            }
        }
        // Merge neighbouring pieces whose union is still one plane.
        let mut out = 0;
        let pieces = std::mem::take(&mut self.buf.pieces);
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
        self.buf.stack.clear();
        self.buf.stack.extend(pieces.iter().rev().copied());
        while let Some((a, b)) = self.buf.stack.pop() {
            if let Some(k) = self.two_lines(a as usize, b as usize) {
                self.buf.stack.push((k as u32 + 1, b));
                self.buf.stack.push((a, k as u32));
            } else {
                self.add_piece(a as usize, b as usize, rgb);
            }
        }
        self.buf.pieces = pieces;
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
            for (r, &g) in self.buf.ray[a..=b].iter().zip(&self.buf.emag[a..=b]) {
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
        let (ra, rb) = (self.buf.ray[a], self.buf.ray[b]);
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
        let (pa, pb) = (self.buf.pos[a], self.buf.pos[b]);
        let left = [pb[1] - pa[1], -(pb[0] - pa[0])];
        let mut lacc = HueAcc::default();
        let mut racc = HueAcc::default();
        let mut bright_left = 0i32;
        let mut strength = 0.0f32;
        let count = b + 1 - a;
        let step = count.div_ceil(self.params.hue_samples_per_edge.max(1)).max(1);
        // The strips in four passes, each over a whole piece: the samples (a position and the
        // unit step to the left); every strip pixel's place in the image (`OUTSIDE` off it),
        // laid out [t][side][sample] so that the passes over samples vectorise; their
        // colours, each asked for from memory before any is read (the image is out of cache
        // after the pixel pass, and a strip across a near-horizontal edge reads a new row a
        // pixel: read one after the other, those reads were most of this function's time,
        // perf, YorkUrban); then their hues ([`HueTable::classify`], vectorised), summed in
        // the order one pass per pixel had: sample by sample, left and right in turn, out from
        // the edge. Computed one pixel after the other, the strips were a fifth of the
        // detector's CPU on `lab`.
        let [sx, sy, sdx, sdy] = &mut self.buf.samples;
        for v in [&mut *sx, &mut *sy, &mut *sdx, &mut *sdy] {
            v.clear();
        }
        for k in a..=b {
            strength += self.buf.emag[k];
            let g = self.buf.grad[k];
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
            // (dx, dy): unit, pointing to the left side.
            let p = self.buf.pos[k];
            sx.push(p[0]);
            sy.push(p[1]);
            sdx.push(g[0] * s);
            sdy.push(g[1] * s);
        }
        let ns = sx.len();
        let mut strip = std::mem::take(&mut self.buf.strip);
        strip.clear();
        strip.resize(2 * self.strip_px * ns, OUTSIDE);
        for (t, sides) in strip.chunks_exact_mut(2 * ns.max(1)).enumerate() {
            let d = self.params.hue_strip_offset_px + t as f32;
            let (l, r) = sides.split_at_mut(ns);
            // The right side's p − d·(dx, dy) is p + (−d)·(dx, dy) to the bit.
            strip_offsets([sx, sy, sdx, sdy], d, self.w, self.h, l);
            strip_offsets([sx, sy, sdx, sdy], -d, self.w, self.h, r);
        }
        for &i in &strip {
            if i != OUTSIDE {
                prefetch(rgb, i as usize);
            }
        }
        let mut hues = std::mem::take(&mut self.buf.strip_hues);
        hues.clear();
        hues.extend(strip.iter().map(|&i| {
            let i = i as usize;
            match rgb.get(i..i.wrapping_add(3)) {
                Some(&[r, g, b]) => HueTable::pack(r, g, b),
                _ => HueTable::PACKED_OUTSIDE,
            }
        }));
        self.hue.classify(&mut hues);
        for k in 0..ns {
            for t in 0..self.strip_px {
                self.hue.add(&mut lacc, hues[2 * t * ns + k]);
                self.hue.add(&mut racc, hues[(2 * t + 1) * ns + k]);
            }
        }
        self.buf.strip_hues = hues;
        self.buf.strip = strip;
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
}

/// A strip pixel off the image.
const OUTSIDE: u32 = u32::MAX;

/// The byte offsets in the image of one strip pixel per sample (`samples`: x, y, and the unit
/// step (dx, dy) to the left, one array each), `d` steps to the left (negative: to the right);
/// [`OUTSIDE`] where that is off the image. Branch-free, and compiled like the pixel pass for
/// the vector units a CPU has: a pixel at a time, the strips' places (with their prefetches)
/// were about half of the strips' cost (0.55 of 1.1 ms of CPU a `lab` frame).
#[multiversion(targets(
    "x86_64+sse3+ssse3+sse4.1+sse4.2+popcnt+avx+avx2+bmi1+bmi2+fma+lzcnt+avx512f+avx512bw+avx512cd+avx512dq+avx512vl",
    "x86_64+sse3+ssse3+sse4.1+sse4.2+popcnt+avx+avx2+bmi1+bmi2+fma+lzcnt",
    "x86_64+sse3+ssse3+sse4.1+sse4.2+popcnt",
))]
fn strip_offsets(samples: [&[f32]; 4], d: f32, w: usize, h: usize, out: &mut [u32]) {
    let n = samples.iter().map(|s| s.len()).fold(out.len(), usize::min);
    let [px, py, dx, dy] = samples.map(|s| &s[..n]);
    let out = &mut out[..n];
    let (wf, hf) = ((w + 1) as f32, (h + 1) as f32);
    // A rig's image has at most `MAX_SENSOR_PIXELS` (2²⁶) pixels, so a strip pixel's byte
    // offset fits i32.
    let wi = w as i32;
    for k in 0..n {
        // +1 keeps the value positive, so truncation rounds. The pixel is on the image when the
        // truncated value is in 1..=w (1..=h): when the value is in [1, w + 1), which the float
        // compares decide (NaN fails them too), and which makes the cast exact. (w + 1 and h + 1
        // are exact in f32 below 2²⁴ px; a wider image, which f32 positions cannot address
        // pixel by pixel anyway, could differ at its far border.)
        let x = (px[k] + d * dx[k]) + 1.5;
        let y = (py[k] + d * dy[k]) + 1.5;
        let on = (x >= 1.0) & (y >= 1.0) & (x < wf) & (y < hf);
        // Off the image, pixel (1, 1) stands in, so that every lane's truncation is defined.
        let (x, y) = if on { (x, y) } else { (1.0, 1.0) };
        // SAFETY: x and y are finite, in [1, 2²⁶ + 1): i32 holds their truncations.
        let (xi, yi): (i32, i32) = unsafe { (x.to_int_unchecked(), y.to_int_unchecked()) };
        let i = ((yi - 1) * wi + xi - 1) * 3;
        out[k] = if on { i as u32 } else { OUTSIDE };
    }
}

/// Asks the memory system for the line holding `bytes[i]` and the two after it (a hint).
#[inline(always)]
fn prefetch(bytes: &[u8], i: usize) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        // A prefetch of any address is a hint that cannot fault, so the address is not
        // checked against the slice (wrapping arithmetic: no out-of-bounds pointer is made).
        let at = bytes.as_ptr().wrapping_add(i);
        // SAFETY: see above.
        unsafe { _mm_prefetch::<_MM_HINT_T0>(at.cast::<i8>()) };
        // The second line only where the pixel straddles two (2 pixels in 64): a prefetch is
        // an instruction of its own, and there are some 35,000 strip pixels a `lab` image.
        if (at as usize & 63) >= 62 {
            // SAFETY: see above.
            unsafe { _mm_prefetch::<_MM_HINT_T0>(at.wrapping_add(2).cast::<i8>()) };
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (bytes, i);
}

/// Rays further off their piece's plane than this many RMS are left out of its fit…
const OUTLIER_SIGMAS: f64 = 2.5;
/// …but never rays within this (rad) of it.
const OUTLIER_FLOOR_RAD: f64 = 0.02 * std::f64::consts::PI / 180.0;

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::SmallRng;
    use rand::{Rng, SeedableRng};

    /// The vectorised strip places are those of the one-pixel-at-a-time form, on and off the
    /// image (past each border, and NaN).
    #[test]
    fn strip_offsets_match_one_pixel_at_a_time() {
        let (w, h) = (512usize, 384usize);
        let mut rng = SmallRng::seed_from_u64(3);
        let n = 4000;
        let mut s: [Vec<f32>; 4] = std::array::from_fn(|_| Vec::new());
        for k in 0..n {
            let a: f32 = rng.random_range(0.0..std::f32::consts::TAU);
            s[0].push(if k % 97 == 0 {
                f32::NAN
            } else {
                rng.random_range(-8.0..w as f32 + 8.0)
            });
            s[1].push(rng.random_range(-8.0..h as f32 + 8.0));
            s[2].push(a.cos());
            s[3].push(a.sin());
        }
        for d in [2.0f32, 6.0, -2.0, -6.0] {
            let mut out = vec![0; n];
            strip_offsets([&s[0], &s[1], &s[2], &s[3]], d, w, h, &mut out);
            for k in 0..n {
                let (x, y) = ((s[0][k] + d * s[2][k]) + 1.5, (s[1][k] + d * s[3][k]) + 1.5);
                let want = if x >= 1.0 && y >= 1.0 && x < (w + 1) as f32 && y < (h + 1) as f32 {
                    (((y as usize - 1) * w + x as usize - 1) * 3) as u32
                } else {
                    OUTSIDE
                };
                assert_eq!(out[k], want, "sample {k}, d {d}");
            }
        }
    }
}
