//! How many random samples the tracker draws (Koch–Teller eq. 2, Table 1).
//!
//! In: the sample size λ, the number q = |S̄_t| of accepted correspondences, the assumed outlier
//! percentage b and the wanted probability of success. Out: s_t, the least number n of draws of
//! λ out of q such that `(1 − C((1 − b/100) q, λ) / C(q, λ))ⁿ ≤ 1 − success` — the odds that
//! every one of n samples holds at least one outlier fall to 1 − success.
//!
//! (The paper prints the binomial's upper argument as "1 − b/100" and the unknown as p; the
//! unknown is n and the argument is the number of inliers (1 − b/100)·q — with that reading its
//! Table 1 comes out exactly, as the tests check.)

/// KT eq. 2: the minimum number of samples of `lambda` correspondences out of `set_size` so that
/// at least one is outlier-free with probability `success`, assuming `outlier_percent` % outliers.
///
/// - The number of inliers `(1 − b/100)·q` is floored when it is not an integer (the worst case:
///   never assume more inliers than there are); a relative 1e-9 is added first so that products
///   such as 0.7 · 30 that land a rounding error below an integer are not floored away.
/// - The ratio C(k, λ)/C(q, λ) is computed as the product Π_{i<λ} (k − i)/(q − i), which cannot
///   overflow for any λ.
/// - Saturates at `u64::MAX` ("no number of samples suffices") when λ exceeds the inliers (or
///   the set), when the ratio underflows to 0, or when `success ≥ 1` with outliers possible.
/// - Returns 0 when `success ≤ 0`, and 1 when every λ-subset is outlier-free (λ = 0 or b ≤ 0)
///   and `success > 0`.
/// - `outlier_percent` is clamped to [0, 100]; a NaN argument gives `u64::MAX`.
pub fn sample_count(lambda: usize, set_size: usize, outlier_percent: f64, success: f64) -> u64 {
    if outlier_percent.is_nan() || success.is_nan() {
        return u64::MAX;
    }
    if success <= 0.0 {
        return 0;
    }
    let q = set_size as f64;
    let b = outlier_percent.clamp(0.0, 100.0);
    let inliers = ((1.0 - b / 100.0) * q * (1.0 + 1e-9)).floor().min(q);
    if lambda > set_size || lambda as f64 > inliers {
        return u64::MAX;
    }
    // P(one sample is outlier-free) = C(k, λ) / C(q, λ).
    let p_clean: f64 = (0..lambda).map(|i| (inliers - i as f64) / (q - i as f64)).product();
    if p_clean >= 1.0 {
        return 1;
    }
    if p_clean <= 0.0 || success >= 1.0 {
        return u64::MAX;
    }
    // (1 − p)ⁿ ≤ 1 − s  ⇔  n ≥ ln(1 − s) / ln(1 − p); ln_1p keeps tiny p accurate.
    let n = ((-success).ln_1p() / (-p_clean).ln_1p()).ceil();
    if n.is_nan() || n >= u64::MAX as f64 {
        return u64::MAX;
    }
    (n as u64).max(1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn edge_cases() {
        assert_eq!(sample_count(10, 30, 0.0, 0.95), 1);
        assert_eq!(sample_count(0, 30, 50.0, 0.95), 1);
        assert_eq!(sample_count(10, 30, 70.0, 0.95), u64::MAX); // 9 inliers < λ
        assert_eq!(sample_count(31, 30, 0.0, 0.95), u64::MAX);
        assert_eq!(sample_count(10, 30, 30.0, 0.0), 0);
        assert_eq!(sample_count(10, 30, 30.0, 1.0), u64::MAX);
        assert_eq!(sample_count(3, 10, 25.0, 0.95), sample_count(3, 10, 30.0, 0.95)); // 7.5 → 7
        assert_eq!(sample_count(1, 10, 50.0, 0.75), 2); // (1/2)² = 1/4
    }
}
