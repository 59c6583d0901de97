//! Hue signature of an edge (Koch–Teller §4.2.1): circular hue statistics of two strips, one on
//! each side of the edge, in the wrapped hue space [0, 1).

use multiversion::multiversion;

/// Entries of the cosine / sine table over the hue circle.
pub(crate) const HUE_STEPS: usize = 1024;

/// Hue mean and variance on both sides of an edge. "Left" is the side of the direction
/// (v2 − v1, −(u2 − u1)) when walking on the image from end 1 to end 2 (v down), as in the
/// `omnitrack edges` CSV.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HueSignature {
    /// Circular mean hue in [0, 1), or NaN when no pixel of the strip had a meaningful hue.
    pub left_mean: f32,
    /// Circular variance in hue units²: −2 ln R̄ / (2π)², the variance of the wrapped normal
    /// distribution with the strip's mean resultant length R̄ (≈ the ordinary variance of the
    /// hue for tight distributions, unbounded for uniform ones). NaN when nothing was kept.
    pub left_var: f32,
    pub right_mean: f32,
    pub right_var: f32,
    /// Fraction of the strip's pixels bright and saturated enough for hue to mean something.
    pub left_kept: f32,
    pub right_kept: f32,
}

impl HueSignature {
    /// No hue measured on either side (no pixel kept): an edge made by hand or from a file
    /// without hue.
    pub const NONE: HueSignature = HueSignature {
        left_mean: f32::NAN,
        left_var: f32::NAN,
        right_mean: f32::NAN,
        right_var: f32::NAN,
        left_kept: 0.0,
        right_kept: 0.0,
    };
}

/// Running sums of one strip.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct HueAcc {
    pub cos: f32,
    pub sin: f32,
    pub kept: u32,
    pub total: u32,
}

impl HueAcc {
    #[inline]
    pub fn add(&mut self, other: &HueAcc) {
        self.cos += other.cos;
        self.sin += other.sin;
        self.kept += other.kept;
        self.total += other.total;
    }

    /// The strip's hue mean, circular variance and kept fraction.
    pub fn stats(&self) -> HueStats {
        let kept = if self.total > 0 {
            self.kept as f32 / self.total as f32
        } else {
            0.0
        };
        if self.kept == 0 {
            return HueStats {
                mean: f32::NAN,
                variance: f32::NAN,
                kept,
            };
        }
        let tau = std::f32::consts::TAU;
        let mut mean = self.sin.atan2(self.cos) / tau;
        if mean < 0.0 {
            mean += 1.0;
        }
        if mean >= 1.0 {
            mean -= 1.0;
        }
        let r = ((self.cos * self.cos + self.sin * self.sin).sqrt() / self.kept as f32).clamp(1e-12, 1.0);
        let var = -2.0 * r.ln() / (tau * tau);
        HueStats {
            mean,
            variance: var.max(0.0),
            kept,
        }
    }
}

/// One hue strip summed up ([`HueAcc::stats`]), as a side of a [`HueSignature`] holds it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct HueStats {
    /// Mean hue in [0, 1); NaN when no pixel had usable hue.
    pub mean: f32,
    /// Circular variance, −2 ln R̄ / (2π)²; NaN when no pixel had usable hue.
    pub variance: f32,
    /// Fraction of the strip's pixels with usable hue.
    pub kept: f32,
}

/// Converts RGB to a hue index in [0, HUE_STEPS) when the pixel is bright and saturated enough.
#[derive(Debug, Clone)]
pub(crate) struct HueTable {
    /// (cos, sin) of every step: one load a pixel, and a fixed size, so that an index below
    /// `HUE_STEPS` needs no bounds check.
    unit: Box<[[f32; 2]; HUE_STEPS]>,
    /// Minimum max(r, g, b) in grey levels, at least 1.
    min_value: u16,
    /// Minimum saturation (max − min) / max, × 1024.
    min_sat_1024: u32,
}

impl HueTable {
    pub fn new(min_saturation: f64, min_value: f64) -> HueTable {
        let tau = std::f64::consts::TAU;
        let angle = |k: usize| tau * k as f64 / HUE_STEPS as f64;
        HueTable {
            unit: Box::new(std::array::from_fn(|k| [angle(k).cos() as f32, angle(k).sin() as f32])),
            min_value: ((min_value.clamp(0.0, 1.0) * 255.0).ceil() as u16).max(1),
            min_sat_1024: (min_saturation.clamp(0.0, 1.0) * 1024.0).ceil() as u32,
        }
    }

    /// Hue of one pixel as an index on the circle, or `None` if too dark or unsaturated: the
    /// one-pixel form of [`HueTable::classify`], which the tests check it against.
    #[cfg(test)]
    pub fn index(&self, rgb: [u8; 3]) -> Option<usize> {
        let [r, g, b] = rgb.map(i32::from);
        let max = r.max(g).max(b);
        let min = r.min(g).min(b);
        let delta = max - min;
        if (max as u16) < self.min_value || delta == 0 || (delta as u32) * 1024 < self.min_sat_1024 * max as u32 {
            return None;
        }
        // Sector formula of HSV; h6 in [-1, 5).
        let h6 = if max == r {
            (g - b) as f32 / delta as f32
        } else if max == g {
            2.0 + (b - r) as f32 / delta as f32
        } else {
            4.0 + (r - g) as f32 / delta as f32
        };
        // h6 ≥ −1, so the shifted value is positive and truncation rounds it.
        let k = (h6 * (HUE_STEPS as f32 / 6.0) + (HUE_STEPS as f32 + 0.5)) as usize;
        Some(k % HUE_STEPS)
    }

    /// A strip pixel's colour as [`HueTable::classify`] takes it.
    #[inline(always)]
    pub fn pack(r: u8, g: u8, b: u8) -> u32 {
        u32::from(r) | u32::from(g) << 8 | u32::from(b) << 16 | 1 << 24
    }

    /// A strip pixel off the image, as [`HueTable::classify`] takes it.
    pub const PACKED_OUTSIDE: u32 = 0;

    /// Packed strip pixels ([`HueTable::pack`], [`HueTable::PACKED_OUTSIDE`]) → their hues, as
    /// [`HueTable::add`] takes them: bit 0 on the image, bit 1 kept (bright and saturated
    /// enough), bits 2.. the hue's index on the circle (HSV's sector formula; h6 in [−1, 5)).
    /// Branch-free over a whole piece's strips, so that it vectorises: a pixel at a time, the
    /// hues were about half of the strips' cost (0.54 of 1.1 ms of CPU a `lab` frame).
    pub fn classify(&self, pixels: &mut [u32]) {
        hue_codes(self.min_value, self.min_sat_1024, pixels);
    }

    /// Adds one pixel's hue ([`HueTable::classify`]) to a strip's sums.
    #[inline(always)]
    pub fn add(&self, acc: &mut HueAcc, code: u32) {
        acc.total += code & 1;
        if code & 2 != 0 {
            acc.kept += 1;
            let [c, s] = self.unit[(code >> 2) as usize % HUE_STEPS];
            acc.cos += c;
            acc.sin += s;
        }
    }
}

/// [`HueTable::classify`], compiled like the pixel pass for the vector units a CPU has.
#[multiversion(targets(
    "x86_64+sse3+ssse3+sse4.1+sse4.2+popcnt+avx+avx2+bmi1+bmi2+fma+lzcnt+avx512f+avx512bw+avx512cd+avx512dq+avx512vl",
    "x86_64+sse3+ssse3+sse4.1+sse4.2+popcnt+avx+avx2+bmi1+bmi2+fma+lzcnt",
    "x86_64+sse3+ssse3+sse4.1+sse4.2+popcnt",
))]
fn hue_codes(min_value: u16, min_sat_1024: u32, pixels: &mut [u32]) {
    for p in pixels.iter_mut() {
        let v = *p;
        let (r, g, b) = ((v & 255) as i32, ((v >> 8) & 255) as i32, ((v >> 16) & 255) as i32);
        let on = (v >> 24) & 1;
        let max = r.max(g).max(b);
        let min = r.min(g).min(b);
        let delta = max - min;
        // `index`'s tests, as one mask.
        let kept = (on != 0)
            & (max >= i32::from(min_value))
            & (delta != 0)
            & ((delta as u32) * 1024 >= min_sat_1024 * max as u32);
        // `index`'s sectors, in its order. 0.0 + the quotient is the quotient: it is never
        // −0.0 (an integer over a positive one).
        let (base, num) = if max == r {
            (0.0, g - b)
        } else if max == g {
            (2.0, b - r)
        } else {
            (4.0, r - g)
        };
        let h6 = base + num as f32 / delta.max(1) as f32;
        // Positive for every kept pixel (h6 ≥ −1), where the i32 and usize truncations agree.
        let x = h6 * (HUE_STEPS as f32 / 6.0) + (HUE_STEPS as f32 + 0.5);
        // SAFETY: |num| ≤ 255 and delta ≥ 1, so h6 is finite in [−255, 259] and x in about
        // [−42600, 45300]: i32 holds its truncation. (The checked cast, which saturates, went
        // lane by lane.)
        let k = unsafe { x.to_int_unchecked::<i32>() } as u32 % HUE_STEPS as u32;
        *p = on | u32::from(kept) << 1 | k << 2;
    }
}

/// HSV hue in [0, 1) of an RGB pixel (no thresholds), for tests and tools.
pub fn hue_of(rgb: [u8; 3]) -> Option<f64> {
    let [r, g, b] = rgb.map(f64::from);
    let max = r.max(g).max(b);
    let min = r.min(g).min(b);
    let d = max - min;
    if d == 0.0 {
        return None;
    }
    let h6 = if max == r {
        (g - b) / d
    } else if max == g {
        2.0 + (b - r) / d
    } else {
        4.0 + (r - g) / d
    };
    Some((h6 / 6.0).rem_euclid(1.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The vectorised hues are [`HueTable::index`]'s, for every colour, at the tracker's
    /// thresholds and at none; a pixel off the image counts for nothing.
    #[test]
    fn classify_gives_the_index_of_every_colour() {
        for table in [HueTable::new(0.15, 0.10), HueTable::new(0.0, 0.0)] {
            let mut codes: Vec<u32> = (0..1u32 << 24)
                .map(|c| HueTable::pack((c >> 16) as u8, (c >> 8) as u8, c as u8))
                .collect();
            table.classify(&mut codes);
            for (c, &code) in codes.iter().enumerate() {
                let px = [(c >> 16) as u8, (c >> 8) as u8, c as u8];
                let want = match table.index(px) {
                    Some(k) => 3 | (k as u32) << 2,
                    None => 1,
                };
                // Not kept: the index bits are not read.
                let got = if code & 2 != 0 { code } else { code & 3 };
                assert_eq!(got, want, "{px:?}");
            }
            let mut off = [HueTable::PACKED_OUTSIDE];
            table.classify(&mut off);
            let mut acc = HueAcc::default();
            table.add(&mut acc, off[0]);
            assert_eq!(acc, HueAcc::default());
        }
    }
}
