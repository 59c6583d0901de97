//! A-contrario validation of line pieces: the Helmholtz principle as LSD applies it (R. Grompone
//! von Gioi, J. Jakubowicz, J.-M. Morel, G. Randall, "LSD: a Line Segment Detector", Image
//! Processing On Line 2 (2012), pp. 35–55; after A. Desolneux, L. Moisan, J.-M. Morel, "Meaningful
//! alignments", IJCV 40 (2000)).
//!
//! Along a candidate segment n pixels are sampled; k of them have a gradient whose direction is
//! within p·π of the segment's normal. Under the background model (gradient directions
//! independent and uniform) k follows the binomial law B(n, p), and the segment is kept only when
//! its number of false alarms NFA = N_tests · B(n, k, p) (B the binomial tail P[X ≥ k]) is below
//! ε. All constants are LSD's published ones (paper §2–§4), none fitted to any data set:
//! p = 1/8 (τ = 22.5°), ε = 1, N_tests = (W·H)^{5/2} (the paper's count of rectangles: (W·H)² end
//! points times (W·H)^{1/2} widths), and the gradient threshold ρ = q / sin τ with q = 2 grey
//! levels below which a pixel's direction counts as undefined (never aligned).
//!
//! The test runs on every piece of every edge, so the smallest k that passes is tabulated once
//! per sample count n ([`Contrario::new`]); the per-piece test is one look-up.

/// LSD's angle tolerance as a share of π: p = τ/π with τ = 22.5° (paper §2.4, §4).
pub const P: f64 = 1.0 / 8.0;
/// LSD's ε (paper §2.5): at most one false detection per image, in expectation.
pub const LOG10_EPSILON: f64 = 0.0;
/// LSD's bound on the gradient's quantisation error, grey levels (paper §4.1, q = 2).
pub const Q: f64 = 2.0;

/// ln Γ(x), x > 0: Lanczos' approximation as LSD computes it (its `log_gamma_lanczos`, enough
/// for the binomial coefficients of the tail).
fn log_gamma_lanczos(x: f64) -> f64 {
    const Q: [f64; 7] = [
        75122.6331530,
        80916.6278952,
        36308.2951477,
        8687.24529705,
        1168.92649479,
        83.8676043424,
        2.50662827511,
    ];
    let mut a = (x + 0.5) * (x + 5.5).ln() - (x + 5.5);
    let mut b = 0.0;
    let mut xn = 1.0;
    for (n, q) in Q.iter().enumerate() {
        a -= (x + n as f64).ln();
        b += q * xn;
        xn *= x;
    }
    a + b.ln()
}

/// ln Γ(x), x > 0: Windschitl's approximation (LSD's `log_gamma_windschitl`, for x > 15).
fn log_gamma_windschitl(x: f64) -> f64 {
    0.918938533204673 + (x - 0.5) * x.ln() - x + 0.5 * x * (x * (1.0 / x).sinh() + 1.0 / (810.0 * x.powi(6))).ln()
}

/// ln Γ(x) as LSD picks it.
fn log_gamma(x: f64) -> f64 {
    if x > 15.0 {
        log_gamma_windschitl(x)
    } else {
        log_gamma_lanczos(x)
    }
}

/// −log₁₀ NFA of k aligned samples out of n with probability p each and log₁₀ N_tests `log_nt`:
/// LSD's `nfa` (paper §2.5 and its code): the first term of the binomial tail from log Γ, the
/// following ones by their ratio, stopped once the rest cannot change the result by 10 %. The
/// piece is meaningful (NFA < ε) when this exceeds −log₁₀ ε.
pub fn minus_log10_nfa(n: u32, k: u32, p: f64, log_nt: f64) -> f64 {
    const TOLERANCE: f64 = 0.1;
    if k > n || !(p > 0.0 && p < 1.0) {
        return f64::NEG_INFINITY;
    }
    if n == 0 || k == 0 {
        return -log_nt;
    }
    if n == k {
        return -log_nt - f64::from(n) * p.log10();
    }
    let (nf, kf) = (f64::from(n), f64::from(k));
    let p_term = p / (1.0 - p);
    let log1term =
        log_gamma(nf + 1.0) - log_gamma(kf + 1.0) - log_gamma(nf - kf + 1.0) + kf * p.ln() + (nf - kf) * (1.0 - p).ln();
    let mut term = log1term.exp();
    if term == 0.0 {
        // Underflow: at the end of the tail the first term is all; at its start the tail is ~1.
        return if kf > nf * p {
            -log1term / std::f64::consts::LN_10 - log_nt
        } else {
            -log_nt
        };
    }
    let mut tail = term;
    for i in k + 1..=n {
        let bin_term = f64::from(n - i + 1) / f64::from(i);
        let mult_term = bin_term * p_term;
        term *= mult_term;
        tail += term;
        if bin_term < 1.0 {
            let err = term * ((1.0 - mult_term.powi((n - i + 1) as i32)) / (1.0 - mult_term) - 1.0);
            if err < TOLERANCE * (-tail.log10() - log_nt).abs() * tail {
                break;
            }
        }
    }
    -tail.log10() - log_nt
}

/// The smallest number of aligned samples that makes n samples meaningful, for every n up to a
/// bound fixed at start-up.
pub struct Contrario {
    /// log₁₀ N_tests.
    log_nt: f64,
    /// k_min[n]; n + 1 where no k does.
    k_min: Vec<u32>,
}

impl Contrario {
    /// For an image of `w`×`h` pixels and pieces of up to `max_n` samples (longer ones are
    /// tested without the table). `tests_factor` multiplies LSD's (W·H)^{5/2} for choices the
    /// caller makes per segment on top of LSD's (e.g. 2 for trying both polarities).
    pub fn new(w: usize, h: usize, max_n: usize, tests_factor: f64) -> Contrario {
        let log_nt = 2.5 * ((w * h).max(1) as f64).log10() + tests_factor.max(1.0).log10();
        let mut k_min = Vec::with_capacity(max_n + 1);
        let mut k = 0u32;
        for n in 0..=max_n as u32 {
            // k_min never decreases with n: one more sample, aligned or not, can only add to the
            // tail of the same k.
            while k <= n && minus_log10_nfa(n, k, P, log_nt) <= -LOG10_EPSILON {
                k += 1;
            }
            k_min.push(k);
            if k > n {
                // None passes yet; the next n starts from here too.
                k = n + 1;
            }
        }
        Contrario { log_nt, k_min }
    }

    /// log₁₀ N_tests.
    #[cfg(test)]
    pub fn log_nt(&self) -> f64 {
        self.log_nt
    }

    /// Whether k aligned samples out of n are meaningful: NFA < ε.
    #[inline]
    pub fn meaningful(&self, n: u32, k: u32) -> bool {
        match self.k_min.get(n as usize) {
            Some(&m) => k >= m,
            None => minus_log10_nfa(n, k, P, self.log_nt) > -LOG10_EPSILON,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Exact −log₁₀ of the binomial tail by summing every term in log space.
    fn exact(n: u32, k: u32, p: f64) -> f64 {
        let ln_choose = |n: u32, i: u32| -> f64 { (1..=i).map(|j| (f64::from(n - i + j) / f64::from(j)).ln()).sum() };
        let terms: Vec<f64> = (k..=n)
            .map(|i| ln_choose(n, i) + f64::from(i) * p.ln() + f64::from(n - i) * (1.0 - p).ln())
            .collect();
        let top = terms.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        let sum: f64 = terms.iter().map(|t| (t - top).exp()).sum();
        -(top + sum.ln()) / std::f64::consts::LN_10
    }

    #[test]
    fn the_tail_matches_the_exact_sum() {
        for &(n, k) in &[
            (20u32, 18u32),
            (40, 20),
            (100, 30),
            (400, 90),
            (30, 5),
            (16, 16),
            (800, 150),
        ] {
            let got = minus_log10_nfa(n, k, P, 0.0);
            let want = exact(n, k, P);
            // LSD accepts 10 % of error on the NFA: 0.05 in log₁₀ and a little more.
            assert!(
                (got - want).abs() < 0.01 + 0.05 * want.abs(),
                "n {n} k {k}: {got} vs {want}"
            );
        }
    }

    #[test]
    fn the_table_agrees_with_the_formula() {
        let c = Contrario::new(640, 480, 300, 1.0);
        // 640×480: log₁₀ N_tests = 2.5 · 5.487 = 13.72; all of n aligned needs n ≥ 16 (8¹⁶ ≈ 10^14.4).
        assert!(!c.meaningful(15, 15));
        assert!(c.meaningful(16, 16));
        for n in [16u32, 20, 40, 80, 160, 299] {
            for k in 0..=n {
                assert_eq!(
                    c.meaningful(n, k),
                    minus_log10_nfa(n, k, P, c.log_nt()) > 0.0,
                    "n {n} k {k}"
                );
            }
        }
        // Beyond the table, the formula itself.
        assert!(c.meaningful(1000, 400) && !c.meaningful(1000, 130));
    }
}
