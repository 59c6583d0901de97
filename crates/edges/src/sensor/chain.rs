//! The pixel pass's edgels linked into chains, and each chain's edgels turned into rays.
//!
//! In: the gradient and edgel maps of [`gradients_and_edgels`](crate::gradient::gradients_and_edgels)
//! in the [`Workspace`]. Out: per chain of at least `min_chain_edgels` edgels (neighbours whose
//! gradient axes agree within ~50°), its sub-pixel positions (Gaussian peak across the
//! gradient), gradients, magnitudes, unit rays (bilinear in the per-pixel ray table) and the
//! prefix sums of their moments, handed to [`fit`](super::fit) one chain at a time.

use super::plane::{edgel_weight, weighted_outer};
use super::Workspace;
use crate::gradient::{bin, bin_step};
use nalgebra::Vector3;

/// ln(max(m, 1)) of every gradient magnitude m (|gx| + |gy| ≤ 32640 < 2¹⁵), for the sub-pixel
/// peak: three logarithms per edgel were a sixth of the chain step on real photographs. Built
/// once, by the first [`Workspace::new`].
pub(super) static LN_MAG: std::sync::LazyLock<Box<[f32]>> =
    std::sync::LazyLock::new(|| (0..1u32 << 15).map(|m| (m as f32).max(1.0).ln()).collect());

/// Empty map cells [`Workspace::link`] skips at once (one vector compare).
const SCAN_RUN: usize = 32;

/// Longest chain traced in one go (a longer one is cut; the rest is traced as another chain).
pub(super) const MAX_CHAIN: usize = 4096;

/// Neighbour steps (du, dv) in angular order, 45° apart.
const DIRS: [(isize, isize); 8] = [(1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1), (0, -1), (1, -1)];

impl Workspace {
    /// Whether the gradient axes at i and j agree within ~50° (polarity is not compared: the
    /// colour gradient's sign can flip where the dominant channel changes).
    #[inline]
    fn compatible(&self, i: usize, j: usize) -> bool {
        let (ax, ay) = (self.buf.gx[i] as i64, self.buf.gy[i] as i64);
        let (bx, by) = (self.buf.gx[j] as i64, self.buf.gy[j] as i64);
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
    pub(super) fn link(&mut self, rgb: &[u8]) {
        let (w, h) = (self.w, self.h);
        let mut map = std::mem::take(&mut self.buf.map);
        let mut fwd = std::mem::take(&mut self.buf.fwd);
        let mut bwd = std::mem::take(&mut self.buf.bwd);
        // Row-major over the interior (the map's border is always 0): the first edgel at or
        // after `next`, found a word at a time (most of the map is empty), and within a word by
        // its lowest set byte rather than a cell at a time.
        let end = (h - 1) * w;
        let mut next = w;
        while next < end {
            if next + SCAN_RUN <= end && map[next..next + SCAN_RUN].iter().fold(0, |a, &c| a | c) == 0 {
                next += SCAN_RUN;
                continue;
            }
            if next + 8 <= end {
                let mut word = [0u8; 8];
                word.copy_from_slice(&map[next..next + 8]);
                // Little-endian: the lowest set byte is the first cell in the map.
                let word = u64::from_le_bytes(word);
                if word == 0 {
                    next += 8;
                    continue;
                }
                next += (word.trailing_zeros() / 8) as usize;
            }
            let i = next;
            next += 1;
            {
                if map[i] == 0 {
                    continue;
                }
                map[i] = 0;
                let dir = tangent_octant(self.buf.gx[i], self.buf.gy[i]);
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
        self.buf.map = map;
        self.buf.fwd = fwd;
        self.buf.bwd = bwd;
    }

    /// Sub-pixel positions (parabola across the gradient), gradients and rays of a chain's edgels.
    ///
    /// Two passes: the first finds every edgel's sub-pixel position and asks for the ray-table
    /// lines its bilinear interpolation will read; the second interpolates. The table (12 bytes a
    /// pixel, 3.7 MB at 640×480) is mostly out of cache by now, and one pass that waited on each
    /// edgel's lines in turn spent a third of the chain step there (perf, YorkUrban); asked for a
    /// whole chain ahead, the lines arrive while the positions are still being computed.
    #[inline(never)]
    fn load_chain(&mut self, idx: impl Iterator<Item = u32>) {
        self.buf.pos.clear();
        self.buf.grad.clear();
        self.buf.emag.clear();
        self.buf.ray.clear();
        self.buf.prefix.clear();
        self.buf.prefix.push([0.0; 7]);
        let (w, h) = (self.w, self.h);
        let ln = &**LN_MAG;
        let ln_of = |m: i16| ln[m.max(0) as usize];
        for i in idx {
            let i = i as usize;
            let (gx, gy) = (self.buf.gx[i], self.buf.gy[i]);
            let bin = bin(gx, gy);
            let (du, dv) = bin_step(bin);
            let off = dv * w as isize + du;
            let m0 = self.buf.mag[i] as f32;
            // Gaussian sub-pixel peak: the parabola through the logarithms of the magnitudes
            // (exact for a Gaussian profile; less biased than a parabola on the magnitudes for
            // the narrow profiles of the 3-px-wide derivative).
            let (la, l0, lb) = (
                ln_of(self.buf.mag[(i as isize - off) as usize]),
                ln_of(self.buf.mag[i]),
                ln_of(self.buf.mag[(i as isize + off) as usize]),
            );
            let denom = la - 2.0 * l0 + lb;
            let s = if denom < 0.0 {
                (0.5 * (la - lb) / denom).clamp(-0.5, 0.5)
            } else {
                0.0
            };
            let x = (i % w) as f32 + s * du as f32;
            let y = (i / w) as f32 + s * dv as f32;
            prefetch_rays(&self.rays, table_corner(x, y, w, h), w);
            self.buf.pos.push([x, y]);
            self.buf.grad.push([gx as f32, gy as f32]);
            self.buf.emag.push(m0);
        }
        // Edgels without a ray (outside the lens's image) are dropped, the rest keep their order.
        let mut kept = 0;
        for k in 0..self.buf.pos.len() {
            let [x, y] = self.buf.pos[k];
            let Some(r) = self.ray_at(x, y) else { continue };
            self.buf.pos[kept] = self.buf.pos[k];
            self.buf.grad[kept] = self.buf.grad[k];
            self.buf.emag[kept] = self.buf.emag[k];
            kept += 1;
            self.buf.ray.push(r);
        }
        self.buf.pos.truncate(kept);
        self.buf.grad.truncate(kept);
        self.buf.emag.truncate(kept);
        // The running sums apart from the rays: each ray (a square root and divisions) is then
        // independent of the one before, and the processor overlaps them, where one loop made
        // every ray wait behind the previous edgel's sums.
        let mut p = [0.0; 7];
        for (r, &m0) in self.buf.ray.iter().zip(&self.buf.emag) {
            let o = weighted_outer(r, edgel_weight(m0));
            p = std::array::from_fn(|k| p[k] + o[k]);
            self.buf.prefix.push(p);
        }
    }

    /// Bilinear interpolation of the ray table, normalised.
    #[inline]
    fn ray_at(&self, x: f32, y: f32) -> Option<Vector3<f64>> {
        let (w, h) = (self.w, self.h);
        let (i, fx, fy) = table_corner(x, y, w, h);
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
}

/// The ray-table index of the top-left of the four pixels around (x, y) (clamped into the
/// image), and the bilinear weights' fractions.
#[inline(always)]
fn table_corner(x: f32, y: f32, w: usize, h: usize) -> (usize, f32, f32) {
    let x = x.clamp(0.0, (w - 1) as f32);
    let y = y.clamp(0.0, (h - 1) as f32);
    let (u0, v0) = ((x as usize).min(w - 2), (y as usize).min(h - 2));
    (v0 * w + u0, x - u0 as f32, y - v0 as f32)
}

/// Asks the memory system for the lines holding the table entries at `i`, `i + 1`, `i + w` and
/// `i + w + 1` (a hint: it reads nothing and cannot fault).
#[inline(always)]
fn prefetch_rays(table: &[[f32; 3]], (i, _, _): (usize, f32, f32), w: usize) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        let base = table.as_ptr().cast::<i8>();
        for at in [i, i + w] {
            // The pair's first and last byte: 24 bytes may straddle two lines.
            let (first, last) = (12 * at, 12 * at + 23);
            if last < 12 * table.len() {
                // SAFETY: both addresses are inside `table`; a prefetch only hints the cache.
                unsafe {
                    _mm_prefetch::<_MM_HINT_T0>(base.add(first));
                    _mm_prefetch::<_MM_HINT_T0>(base.add(last));
                }
            }
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (table, i, w);
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

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::SmallRng;
    use rand::{Rng, SeedableRng};

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
