//! The pixel stage of edge extraction, in one pass down the image: RGB8 rows → per colour
//! channel, integer smoothing and Sobel derivatives → per pixel, the gradient of the channel where
//! it is largest (`gx`, `gy`, `mag`) → non-maximum suppression into the edgel map (`map`).
//!
//! Rows stream through small ring buffers (three rows of each intermediate per channel), so the
//! working set stays in the first-level cache and each full-size output is written once. The
//! kernels are plain loops over equal-length slices, which the compiler vectorises; the whole
//! pass is compiled for AVX2 and AVX-512BW as well as the baseline and picks the best the CPU has
//! at run time (`multiversion`), since a rig's computer may have either.

use super::params::Smoothing;
use multiversion::multiversion;

/// Ring buffers for images up to one width, sized at start-up.
pub(crate) struct Rows {
    w: usize,
    /// Planar colour rows: [slot][channel][u], three slots (rows v−1, v, v+1).
    p: Vec<u8>,
    /// The rows whose x derivative is taken (smoothed down rows under [`Smoothing::Along`]),
    /// ×16: [slot][channel][u].
    x: Vec<u16>,
    /// The rows whose y derivative is taken (smoothed across columns), ×16: [slot][channel][u].
    y: Vec<u16>,
    /// Scratch rows: horizontal passes (Full smoothing); column sums and differences, one row
    /// per channel.
    t: Vec<u16>,
    cs: Vec<i16>,
    cd: Vec<i16>,
}

impl Rows {
    pub fn new(w: usize) -> Rows {
        Rows {
            w,
            p: vec![0; 9 * w],
            x: vec![0; 9 * w],
            y: vec![0; 9 * w],
            t: vec![0; 3 * w],
            cs: vec![0; 3 * w],
            cd: vec![0; 3 * w],
        }
    }

    /// Whether rows of `w` pixels fit.
    pub fn fits(&self, w: usize) -> bool {
        w <= self.w
    }
}

/// Gradients and edgel map of an RGB8 image (`rgb`: rows of 3·w bytes). Writes rows 1..h−1,
/// columns 1..w−1 of `gx`, `gy`, `mag` and `map` (the border stays as it is: zero); returns the
/// number of edgels. `map` gets 0 (no edgel) or the gradient bin 1..=4 (see [`bin`]).
#[allow(clippy::too_many_arguments)]
#[multiversion(targets(
    "x86_64+sse3+ssse3+sse4.1+sse4.2+popcnt+avx+avx2+bmi1+bmi2+fma+lzcnt+avx512f+avx512bw+avx512cd+avx512dq+avx512vl",
    "x86_64+sse3+ssse3+sse4.1+sse4.2+popcnt+avx+avx2+bmi1+bmi2+fma+lzcnt",
    "x86_64+sse3+ssse3+sse4.1+sse4.2+popcnt",
))]
pub(crate) fn gradients_and_edgels(
    rgb: &[u8],
    w: usize,
    h: usize,
    smoothing: Smoothing,
    threshold: i16,
    rows: &mut Rows,
    gx: &mut [i16],
    gy: &mut [i16],
    mag: &mut [i16],
    map: &mut [u8],
) -> u32 {
    let n = w * h;
    if w < 3 || h < 3 || rgb.len() < 3 * n || gx.len() < n || gy.len() < n || mag.len() < n || map.len() < n {
        return 0;
    }
    debug_assert!(rows.fits(w));
    let slot = |v: usize| v % 3;
    let row = |v: usize| &rgb[3 * w * v..3 * w * (v + 1)];
    deinterleave(row(0), &mut rows.p[0..3 * w], w);
    deinterleave(row(1), &mut rows.p[3 * w..6 * w], w);
    let mut edgels = 0;
    for v in 0..h {
        // Planar rows v−1, v, v+1 (replicated at the borders) are in the ring: the smoothed rows
        // of v need them.
        if v + 1 < h && v >= 1 {
            let s = slot(v + 1);
            deinterleave(row(v + 1), &mut rows.p[3 * w * s..3 * w * (s + 1)], w);
        }
        // The image row PREFETCH_ROWS ahead asked for now: a row's work is short beside a
        // row's wait on memory, and the image is usually out of this core's caches (decoded by
        // the capture thread, or read back from a file).
        if v + PREFETCH_ROWS < h {
            prefetch_row(row(v + PREFETCH_ROWS));
        }
        let (up, mid, down) = (slot(v.saturating_sub(1)), slot(v), slot((v + 1).min(h - 1)));
        for c in 0..3 {
            let pr = |s: usize| (3 * s + c) * w..(3 * s + c + 1) * w;
            let out = slot(v) * 3 + c;
            let (pa, pb, pc) = (&rows.p[pr(up)], &rows.p[pr(mid)], &rows.p[pr(down)]);
            let xo = &mut rows.x[out * w..(out + 1) * w];
            let yo = &mut rows.y[out * w..(out + 1) * w];
            match smoothing {
                Smoothing::Along => {
                    vertical_u8(pa, pb, pc, 4, xo);
                    horizontal_u8(pb, 4, yo);
                }
                Smoothing::None => {
                    for (d, &p) in xo.iter_mut().zip(pb) {
                        *d = 16 * p as u16;
                    }
                    yo.copy_from_slice(xo);
                }
                Smoothing::Full => {
                    let (ta, rest) = rows.t.split_at_mut(w);
                    let (tb, tc) = rest.split_at_mut(w);
                    horizontal_u8(pa, 1, ta);
                    horizontal_u8(pb, 1, tb);
                    horizontal_u8(pc, 1, tc);
                    vertical_u16(ta, tb, tc, xo);
                    yo.copy_from_slice(xo);
                }
            }
        }
        // The Sobel of row s = v − 1 needs the smoothed rows s − 1, s, s + 1.
        if v >= 2 {
            let s = v - 1;
            let (a, b, c) = (slot(s - 1), slot(s), slot(s + 1));
            let span = s * w + 1..s * w + w - 1;
            for ch in 0..3 {
                let xr = |k: usize| &rows.x[(3 * k + ch) * w..(3 * k + ch + 1) * w];
                let yr = |k: usize| &rows.y[(3 * k + ch) * w..(3 * k + ch + 1) * w];
                let (x0, x1, x2, y0, y2) = (xr(a), xr(b), xr(c), yr(a), yr(c));
                let out = ch * w..(ch + 1) * w;
                column_sums(x0, x1, x2, y0, y2, &mut rows.cs[out.clone()], &mut rows.cd[out]);
            }
            // The three channels' Sobel in one loop, the largest kept in registers: gx, gy and
            // mag are written once a pixel instead of written and twice rewritten.
            let cs = |ch: usize, from: usize| &rows.cs[ch * w + from..ch * w + from + w - 2];
            let cd = |ch: usize, from: usize| &rows.cd[ch * w + from..ch * w + from + w - 2];
            sobel_rows(
                [
                    [cs(0, 0), cs(0, 2), cd(0, 0), cd(0, 1), cd(0, 2)],
                    [cs(1, 0), cs(1, 2), cd(1, 0), cd(1, 1), cd(1, 2)],
                    [cs(2, 0), cs(2, 2), cd(2, 0), cd(2, 1), cd(2, 2)],
                ],
                &mut gx[span.clone()],
                &mut gy[span.clone()],
                &mut mag[span.clone()],
            );
            // Rows s − 2..=s of `mag` are final: suppress non-maxima on row s − 1.
            if s >= 2 {
                edgels += nms_row(gx, gy, mag, map, w, s - 1, threshold);
            }
        }
    }
    // The last interior row: row h − 1 of `mag` is the zero border.
    edgels + nms_row(gx, gy, mag, map, w, h - 2, threshold)
}

/// Rows ahead of the one de-interleaved whose lines are asked for from memory.
const PREFETCH_ROWS: usize = 3;

/// Asks the memory system for every line of `bytes` (a hint: it reads nothing and cannot fault).
#[inline(always)]
fn prefetch_row(bytes: &[u8]) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        for at in (0..bytes.len())
            .step_by(64)
            .chain(std::iter::once(bytes.len().saturating_sub(1)))
        {
            // SAFETY: every address is inside `bytes`; a prefetch only hints the cache.
            unsafe { _mm_prefetch::<_MM_HINT_T0>(bytes.as_ptr().add(at).cast::<i8>()) };
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = bytes;
}

/// RGB8 row → three planar rows (R, G, B) of length w.
#[inline(always)]
fn deinterleave(rgb: &[u8], out: &mut [u8], w: usize) {
    let (r, rest) = out.split_at_mut(w);
    let (g, b) = rest.split_at_mut(w);
    for (((p, r), g), b) in rgb[..3 * w]
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

/// `scale` · [1 2 1] down three rows.
#[inline(always)]
fn vertical_u8(a: &[u8], b: &[u8], c: &[u8], scale: u16, out: &mut [u16]) {
    let n = out.len().min(a.len()).min(b.len()).min(c.len());
    let (a, b, c, out) = (&a[..n], &b[..n], &c[..n], &mut out[..n]);
    for u in 0..n {
        out[u] = scale * (a[u] as u16 + 2 * b[u] as u16 + c[u] as u16);
    }
}

/// [1 2 1] down three rows.
#[inline(always)]
fn vertical_u16(a: &[u16], b: &[u16], c: &[u16], out: &mut [u16]) {
    let n = out.len().min(a.len()).min(b.len()).min(c.len());
    let (a, b, c, out) = (&a[..n], &b[..n], &c[..n], &mut out[..n]);
    for u in 0..n {
        out[u] = a[u] + 2 * b[u] + c[u];
    }
}

/// The Sobel's vertical halves: [1 2 1] down the x rows, [−1 0 1] down the y rows. Each value is
/// at most 4 · 16 · 255 = 16320, so it fits i16.
#[inline(always)]
fn column_sums(x0: &[u16], x1: &[u16], x2: &[u16], y0: &[u16], y2: &[u16], cs: &mut [i16], cd: &mut [i16]) {
    let n = cs
        .len()
        .min(cd.len())
        .min(x0.len())
        .min(x1.len())
        .min(x2.len())
        .min(y0.len())
        .min(y2.len());
    let (x0, x1, x2, y0, y2) = (&x0[..n], &x1[..n], &x2[..n], &y0[..n], &y2[..n]);
    let (cs, cd) = (&mut cs[..n], &mut cd[..n]);
    for u in 0..n {
        cs[u] = (x0[u] + 2 * x1[u] + x2[u]) as i16;
        cd[u] = y2[u] as i16 - y0[u] as i16;
    }
}

/// `scale` · [1 2 1] across columns, the border replicated.
#[inline(always)]
fn horizontal_u8(src: &[u8], scale: u16, out: &mut [u16]) {
    let w = src.len().min(out.len());
    if w < 3 {
        return;
    }
    let n = w - 2;
    let (a, b, c) = (&src[..n], &src[1..n + 1], &src[2..n + 2]);
    let o = &mut out[1..n + 1];
    for u in 0..n {
        o[u] = scale * (a[u] as u16 + 2 * b[u] as u16 + c[u] as u16);
    }
    out[0] = 4 * scale * src[0] as u16;
    out[w - 1] = 4 * scale * src[w - 1] as u16;
}

/// One row of the Sobel of each of three channels (per channel: column sums at u − 1 and u + 1,
/// differences at u − 1, u, u + 1, as slices of equal length); per pixel the gradient of the
/// channel with the largest L1 magnitude, the first of equals.
#[inline(always)]
fn sobel_rows(ch: [[&[i16]; 5]; 3], gx: &mut [i16], gy: &mut [i16], mag: &mut [i16]) {
    let n = ch
        .iter()
        .flatten()
        .map(|s| s.len())
        .fold(gx.len().min(gy.len()).min(mag.len()), usize::min);
    let [[r0, r1, r2, r3, r4], [g0, g1, g2, g3, g4], [b0, b1, b2, b3, b4]] = ch;
    let (r0, r1, r2, r3, r4) = (&r0[..n], &r1[..n], &r2[..n], &r3[..n], &r4[..n]);
    let (g0, g1, g2, g3, g4) = (&g0[..n], &g1[..n], &g2[..n], &g3[..n], &g4[..n]);
    let (b0, b1, b2, b3, b4) = (&b0[..n], &b1[..n], &b2[..n], &b3[..n], &b4[..n]);
    let (gx, gy, mag) = (&mut gx[..n], &mut gy[..n], &mut mag[..n]);
    #[inline(always)]
    fn sobel(s0: i16, s2: i16, d0: i16, d1: i16, d2: i16) -> (i16, i16, i16) {
        let x = s2.wrapping_sub(s0);
        let y = d0.wrapping_add(d1.wrapping_mul(2)).wrapping_add(d2);
        (x, y, x.wrapping_abs().wrapping_add(y.wrapping_abs()))
    }
    #[inline(always)]
    fn larger(a: (i16, i16, i16), b: (i16, i16, i16)) -> (i16, i16, i16) {
        let keep = ((b.2 > a.2) as i16).wrapping_neg();
        (
            (b.0 & keep) | (a.0 & !keep),
            (b.1 & keep) | (a.1 & !keep),
            (b.2 & keep) | (a.2 & !keep),
        )
    }
    for u in 0..n {
        let r = sobel(r0[u], r1[u], r2[u], r3[u], r4[u]);
        let g = sobel(g0[u], g1[u], g2[u], g3[u], g4[u]);
        let b = sobel(b0[u], b1[u], b2[u], b3[u], b4[u]);
        let (x, y, m) = larger(larger(r, g), b);
        gx[u] = x;
        gy[u] = y;
        mag[u] = m;
    }
}

/// Gradient bin: 1 horizontal gradient, 2 vertical, 3 diagonal with gx·gy > 0, 4 the other.
#[inline(always)]
pub(crate) fn bin(gx: i16, gy: i16) -> u8 {
    let (ax, ay) = (gx.unsigned_abs(), gy.unsigned_abs());
    // tan 22.5° ≈ 0.4142 ≈ 53/128 ([`tan_below`]).
    if ay <= tan_below(ax) {
        1
    } else if ax <= tan_below(ay) {
        2
    } else if (gx > 0) == (gy > 0) {
        3
    } else {
        4
    }
}

/// Pixel offset (du, dv) of the gradient direction of a bin.
#[inline(always)]
pub(crate) fn bin_step(bin: u8) -> (isize, isize) {
    match bin {
        1 => (1, 0),
        2 => (0, 1),
        3 => (1, 1),
        _ => (1, -1),
    }
}

/// Non-maximum suppression of row v (columns 1..w−1) across the gradient's bin: an edgel is at
/// least `threshold`, larger than its neighbour on one side and no smaller than the other.
/// Branch-free within a block of [`NMS_BLOCK`] pixels (all four neighbour pairs are read, the
/// bin's is kept), so that it vectorises; a block without a magnitude at the threshold is
/// skipped.
#[inline(always)]
fn nms_row(gx: &[i16], gy: &[i16], mag: &[i16], map: &mut [u8], w: usize, v: usize, threshold: i16) -> u32 {
    let n = w - 2;
    let i0 = v * w + 1;
    let (m, gx, gy) = (&mag[i0..i0 + n], &gx[i0..i0 + n], &gy[i0..i0 + n]);
    let (left, right) = (&mag[i0 - 1..i0 - 1 + n], &mag[i0 + 1..i0 + 1 + n]);
    let (up, down) = (&mag[i0 - w..i0 - w + n], &mag[i0 + w..i0 + w + n]);
    let (up_left, down_right) = (&mag[i0 - w - 1..i0 - w - 1 + n], &mag[i0 + w + 1..i0 + w + 1 + n]);
    let (down_left, up_right) = (&mag[i0 + w - 1..i0 + w - 1 + n], &mag[i0 - w + 1..i0 - w + 1 + n]);
    let out = &mut map[i0..i0 + n];
    let mut count = 0u32;
    // A block without a magnitude at the threshold holds no edgel: most of a row is flat.
    for c in (0..n).step_by(NMS_BLOCK) {
        let e = (c + NMS_BLOCK).min(n);
        // The block's largest magnitude: a lane-wise maximum, where an or of compares was
        // compiled eight lanes at a time.
        if m[c..e].iter().fold(i16::MIN, |a, &x| a.max(x)) >= threshold {
            count += nms_block(
                gx, gy, m, left, right, up, down, up_left, down_right, down_left, up_right, out, c, e, threshold,
            );
        } else {
            out[c..e].fill(0);
        }
    }
    count
}

/// ⌊b · 53/128⌋, so that a · 128 ≤ b · 53 ⇔ a ≤ tan_below(b) (the bins' tan 22.5° test of
/// [`bin`]) for integers: the high half of b · (53 · 512), which fits 32 bits for every u16 and
/// compiles to one 16-bit multiply-high a lane (twice the pixels an instruction of the 32-bit
/// products it replaces).
#[inline(always)]
fn tan_below(b: u16) -> u16 {
    ((u32::from(b) * (53 * 512)) >> 16) as u16
}

/// Pixels a row's non-maximum suppression tests at once, when any of them is at the threshold.
const NMS_BLOCK: usize = 64;

/// [`nms_row`] on the pixels c..e of its row (slices as there).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn nms_block(
    gx: &[i16],
    gy: &[i16],
    m: &[i16],
    left: &[i16],
    right: &[i16],
    up: &[i16],
    down: &[i16],
    up_left: &[i16],
    down_right: &[i16],
    down_left: &[i16],
    up_right: &[i16],
    out: &mut [u8],
    c: usize,
    e: usize,
    threshold: i16,
) -> u32 {
    let (gx, gy, m, out) = (&gx[c..e], &gy[c..e], &m[c..e], &mut out[c..e]);
    let (left, right, up, down) = (&left[c..e], &right[c..e], &up[c..e], &down[c..e]);
    let (up_left, down_right, down_left, up_right) =
        (&up_left[c..e], &down_right[c..e], &down_left[c..e], &up_right[c..e]);
    let n = e - c;
    let mut count = 0u32;
    for u in 0..n {
        let (x, y) = (gx[u], gy[u]);
        let (ax, ay) = (x.unsigned_abs(), y.unsigned_abs());
        // Non-short-circuit `&` / `|` on bools and arithmetic bins keep the loop free of
        // branches and gathers; [`tan_below`] keeps the bins' tests in 16-bit lanes.
        let horizontal = ay <= tan_below(ax);
        let vertical = !horizontal & (ax <= tan_below(ay));
        let diagonal = !horizontal & !vertical;
        let rising = diagonal & ((x > 0) == (y > 0));
        let falling = diagonal & !rising;
        let mu = m[u];
        let peak = (horizontal & (mu > left[u]) & (mu >= right[u]))
            | (vertical & (mu > up[u]) & (mu >= down[u]))
            | (rising & (mu > up_left[u]) & (mu >= down_right[u]))
            | (falling & (mu > down_left[u]) & (mu >= up_right[u]));
        let keep = peak & (mu >= threshold);
        let bin = 1 + (!horizontal) as u8 + diagonal as u8 + falling as u8;
        out[u] = keep as u8 * bin;
        count += keep as u32;
    }
    count
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `tan_below(b)` is the largest a with a · 128 ≤ b · 53, for every b.
    #[test]
    fn tan_below_is_the_bins_test() {
        for b in 0..=u16::MAX {
            let a = u32::from(tan_below(b));
            let b = u32::from(b);
            assert!(a * 128 <= b * 53 && (a + 1) * 128 > b * 53, "b = {b}: {a}");
        }
    }
}
