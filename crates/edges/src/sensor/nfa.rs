//! LSD's a-contrario test (Grompone von Gioi et al., IPOL 2012) of the pieces of an edge the
//! image shows as lines ([`Edge::shown`](crate::Edge::shown)).
//!
//! In: a stretch of a great circle (sensor frame) and the gradients of the last pixel pass in the
//! [`Workspace`]. Out: a [`Stretch`], all of it or the part between its first and last aligned
//! samples, when its number of false alarms is below 1; `None` otherwise.

use super::Workspace;
use crate::contrario;
use nalgebra::{Vector2, Vector3};
use omnitrack_core::geometry::Lens;

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

impl Workspace {
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
    pub(super) fn meaningful_part(&self, n: &Vector3<f64>, e1: &Vector3<f64>, t0: f64, t1: f64) -> Option<Stretch> {
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
                *g = [self.buf.gx[i], self.buf.gy[i]];
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
                            let (gx, gy) = (f64::from(self.buf.gx[i]), f64::from(self.buf.gy[i]));
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
}

/// What [`Workspace::meaningful_part`] keeps of a stretch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Stretch {
    /// All of it.
    Whole,
    /// The part between these angles.
    Part(f64, f64),
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hue::HueTable;
    use crate::params::EdgeParams;
    use crate::sensor::{ray_table, Scratch};
    use nalgebra::Point2;
    use omnitrack_core::frame::SensorImage;
    use rand::rngs::SmallRng;
    use rand::{Rng, SeedableRng};
    use std::sync::Arc;

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
            let mut scratch = Scratch::new(320, 320 * 240, &EdgeParams::default(), 5);
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
            ws.run(&img, &mut scratch);
            assert!(ws.params.piece_nfa);
            let kept = ws.with_scratch(&mut scratch, |ws| ws.meaningful_part(&n, &r1, 0.0, span));
            match kept {
                Some(Stretch::Whole) => {}
                Some(Stretch::Part(a, b)) => assert!(a < 0.02 * span && b > 0.98 * span, "{model}: {a}..{b} of {span}"),
                None => panic!("{model}: a clean line refused"),
            }
            // Short pieces of it too: 20 px is above LSD's minimum of 16 aligned pixels here.
            let short = span * 20.0 / 212.0;
            assert!(
                ws.with_scratch(&mut scratch, |ws| ws.meaningful_part(&n, &r1, 0.3, 0.3 + short))
                    .is_some(),
                "{model}: a 20 px piece refused"
            );
            // Pure noise: uniform grey levels, independent per pixel and channel.
            let mut rng = SmallRng::seed_from_u64(3);
            for trial in 0..20 {
                for v in img.pixels_mut() {
                    *v = rng.random();
                }
                img.set_valid(0);
                ws.run(&img, &mut scratch);
                for (a, b) in [(0.0, span), (0.2, 0.2 + short), (0.5, 0.5 + 2.0 * short)] {
                    assert_eq!(
                        ws.with_scratch(&mut scratch, |ws| ws.meaningful_part(&n, &r1, a, b)),
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
        let mut scratch = Scratch::new(320, 320 * 240, &EdgeParams::default(), 5);
        ws.run(&img, &mut scratch);
        let i = 100 * 320 + 150;
        // Half a grey level a pixel.
        assert_eq!((scratch.gx[i], scratch.gy[i]), ((GRADIENT_PER_GREY / 2.0) as i16, 0));
    }
}
