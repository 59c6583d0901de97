//! Kumar & Hanson §4: Med_R_and_T, least median of squares over lines or landmarks.
//!
//! In: [`Correspondence`]s (some may be wrong), optionally each one's landmark id, an optional
//! guess `T_world_rig`, [`SolverOptions`], a seed. Out: a [`Solution`] whose `inliers` are the
//! correspondences kept after outlier rejection and whose pose is R_and_T over them.
//!
//! Steps (§4): (1) 3-line (or 3-landmark) subsets: all of them when there are no more than the
//! Monte-Carlo count m = ⌈log(1 − P) / log(1 − (1 − ε)³)⌉, otherwise m random ones; subsets whose
//! three unit 3D line directions have |det| < `degenerate_subset_det` are skipped. (2) A pose per
//! subset by R_and_T (from the guess, or from R_then_T's rotation stage started at Horn's 12
//! tetrahedral samples, translation by eq. 9, then R_and_T), scored by the median over all lines
//! of the line's squared error (`o.error`, both end points) — precisely Rousseeuw's LMS order
//! statistic h = ⌊n/2⌋ + 2 for 3-line elemental subsets (see [`lms_rank`]); when the caller
//! expects more outliers than LMS's 50 % breakdown allows (`lms_outlier_fraction` > 1/3), the
//! ⌊(1 − ε) n⌋-th instead (least k-th squares, [`lms_rank_for`]). (3) With the least-median pose,
//! σ̂ = 1.4826 (1 + 5 / (n − 6)) √median (Rousseeuw's robust scale; from the k-th order statistic
//! when k is not the median rank), and a line is an outlier when its error's square root exceeds
//! `lms_outlier_threshold` · σ̂. (4) R_and_T on the rest, with rejection and refit repeated (σ
//! from the inliers) until the inlier set is stable.
//!
//! Scratch (per-line errors, the inlier copy) is allocated once per call; the subset loop itself
//! allocates nothing.

use super::horn::tetrahedral;
use super::kumar_hanson::{
    all_finite, line_error_of, mean_distance, pose_of, r_and_t, refine, rotation_stage, translation_stage, unknowns_of,
    Unknowns,
};
use super::{LineError, Solution, SolveError, SolverOptions};
use crate::geometry::{Correspondence, Pose};
use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};

/// The most subsets Med_R_and_T will try, whatever P and ε ask for.
const MAX_SUBSETS: u64 = 100_000;

/// The Monte-Carlo subset count of §4 (after Rousseeuw): the number of random 3-element subsets
/// needed for at least one to be outlier-free with probability `p` when a fraction `epsilon` of
/// the elements are outliers. At least 1, at most 100 000.
pub fn monte_carlo_count(p: f64, epsilon: f64) -> u64 {
    let clean = (1.0 - epsilon).powi(3);
    let m = ((1.0 - p).ln() / (1.0 - clean).ln()).ceil();
    if m.is_nan() {
        return MAX_SUBSETS;
    }
    (m.max(1.0) as u64).min(MAX_SUBSETS)
}

/// Rousseeuw's small-sample robust σ from the median squared residual (p = 6 unknowns). For
/// n ≤ 6 the correction uses n − 6 = 1.
pub fn robust_sigma(median_squared: f64, n: usize) -> f64 {
    let dof = (n as f64 - 6.0).max(1.0);
    1.4826 * (1.0 + 5.0 / dof) * median_squared.max(0.0).sqrt()
}

fn c3(n: usize) -> u64 {
    let n = n as u128;
    if n < 3 {
        0
    } else {
        (n * (n - 1) * (n - 2) / 6).min(u64::MAX as u128) as u64
    }
}

/// §4's degeneracy rule: |det| of the matrix whose rows are the three unit line directions.
fn direction_det(a: &Correspondence, b: &Correspondence, c: &Correspondence) -> f64 {
    let d = |l: &Correspondence| {
        (l.segment[1] - l.segment[0])
            .try_normalize(0.0)
            .unwrap_or_else(Vector3::zeros)
    };
    Matrix3::from_columns(&[d(a), d(b), d(c)]).determinant().abs()
}

/// Index (0-based) of the order statistic Med_R_and_T minimises: Rousseeuw's LMS uses the h-th
/// smallest squared residual, h = ⌊n/2⌋ + ⌊(p + 1)/2⌋, with p the size of an elemental subset;
/// here p = 3 lines, so h = ⌊n/2⌋ + 2 (the median plus one or two). Taking exactly the median
/// would let a wrong pose that fits only its own 3 lines exactly tie with the true one when
/// n ≤ 6; with h it must fit more lines than its subset. Breakdown: (n − h + 1)/n → 50 %.
pub fn lms_rank(n: usize) -> usize {
    (n / 2 + 1).min(n.saturating_sub(1))
}

/// The order statistic actually minimised for an expected outlier fraction `epsilon`: Rousseeuw's
/// [`lms_rank`] while at least h lines can be expected to be inliers, and the ⌊(1 − ε) n⌋-th (but
/// never fewer than 4 lines, so a subset cannot win on its own 3) when more outliers are
/// expected. This is least-k-th-squares: it lets Med_R_and_T reach past LMS's 50 % breakdown
/// when the caller says how many outliers to expect.
pub fn lms_rank_for(n: usize, epsilon: f64) -> usize {
    let expected_inliers = ((1.0 - epsilon.clamp(0.0, 0.95)) * n as f64).floor() as usize;
    lms_rank(n).min(expected_inliers.max(4) - 1).min(n.saturating_sub(1))
}

/// Φ⁻¹(p), the standard normal quantile (Acklam's rational approximation, relative error
/// < 1.2e-9), for the consistency factor of an order-statistic scale.
fn normal_quantile(p: f64) -> f64 {
    const A: [f64; 6] = [
        -39.69683028665376,
        220.9460984245205,
        -275.9285104469687,
        138.357751867269,
        -30.66479806614716,
        2.506628277459239,
    ];
    const B: [f64; 5] = [
        -54.47609879822406,
        161.5858368580409,
        -155.6989798598866,
        66.80131188771972,
        -13.28068155288572,
    ];
    const C: [f64; 6] = [
        -0.007784894002430293,
        -0.3223964580411365,
        -2.400758277161838,
        -2.549732539343734,
        4.374664141464968,
        2.938163982698783,
    ];
    const D: [f64; 4] = [
        0.007784695709041462,
        0.3224671290700398,
        2.445134137142996,
        3.754408661907416,
    ];
    let p = p.clamp(1e-12, 1.0 - 1e-12);
    let tail = |q: f64| {
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    };
    if p < 0.02425 {
        tail((-2.0 * p.ln()).sqrt())
    } else if p > 1.0 - 0.02425 {
        -tail((-2.0 * (1.0 - p).ln()).sqrt())
    } else {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    }
}

/// Robust σ from the `k`-th smallest (1-based) of `n` squared line errors, read as the k/n
/// quantile of |error|. When some of the n are outliers this overestimates σ (the k smallest are
/// then a lower quantile of the inliers), never underestimates it, so the first rejection is
/// loose rather than throwing good lines away; the refits in `finish` then tighten σ from the
/// inliers. Unlike the median, the k-th statistic stays inside the inliers up to ε = 1 − k/n.
fn order_statistic_sigma(kth_squared: f64, k: usize, n: usize) -> f64 {
    let quantile = (k as f64 / n.max(1) as f64).clamp(0.25, 0.95);
    kth_squared.max(0.0).sqrt() / normal_quantile(0.5 + 0.5 * quantile)
}

/// The least-median search state: the best pose so far and the per-line error scratch.
struct Search<'a> {
    all: &'a [Correspondence],
    o: &'a SolverOptions,
    guess: Option<Unknowns>,
    errors: Vec<f64>,
    best: Option<(f64, UnitQuaternion<f64>, Vector3<f64>)>,
}

impl Search<'_> {
    /// The LMS objective at `(q, s)`: the `lms_rank`-th smallest squared line error over all lines.
    fn median(&mut self, q: &UnitQuaternion<f64>, s: &Vector3<f64>) -> f64 {
        for (e, l) in self.errors.iter_mut().zip(self.all) {
            let v = line_error_of(l, q, s, self.o.error);
            *e = if v.is_nan() { f64::INFINITY } else { v };
        }
        let h = lms_rank_for(self.errors.len(), self.o.lms_outlier_fraction);
        *self.errors.select_nth_unstable_by(h, f64::total_cmp).1
    }

    fn consider(&mut self, q: UnitQuaternion<f64>, s: Vector3<f64>) {
        let med = self.median(&q, &s);
        if med.is_finite() && self.best.is_none_or(|b| med < b.0) {
            self.best = Some((med, q, s));
        }
    }

    /// Step 2 for one subset: its pose(s) by R_and_T, each scored by the median over all lines.
    fn subset(&mut self, sub: &[Correspondence]) {
        let o = self.o;
        if let Some((q, s)) = self.guess {
            if let Ok(r) = refine(sub, q, s, o) {
                self.consider(r.q, r.s);
            }
            return;
        }
        // No guess: a few rotation-stage starts (a 3-line subset allows several rotations, so
        // every distinct one is kept and the median over all lines chooses).
        let mut seen = [UnitQuaternion::identity(); 12];
        let mut count = 0;
        for q0 in tetrahedral() {
            let coarse = rotation_stage(sub, *q0, o.max_iterations.min(15), o.convergence_rad.max(1e-6));
            let Some((q, _, _)) = coarse else {
                continue;
            };
            if seen[..count].iter().any(|p| p.angle_to(&q) < 1e-3) {
                continue;
            }
            seen[count] = q;
            count += 1;
            // Three lines fix the rotation exactly (three constraints, three unknowns) and eq. 9
            // then fixes the translation, so the subset's pose needs no R_and_T polish before it
            // is scored: only the winner is refined, on all its inliers.
            let Some(s) = translation_stage(sub, &q) else {
                continue;
            };
            self.consider(q, s);
        }
    }

    /// Steps 3–4: outliers from the least-median pose, then R_and_T on the inliers. The scale
    /// comes from the same order statistic that was minimised (with the default ε this is the
    /// paper's median rule); the rejection and refit are repeated with σ re-estimated (by the
    /// same median rule) over the inliers until the inlier set stops changing (at most 4 passes), so that an outlier that
    /// slipped under the first, robust but loose, threshold is caught once the fit is clean.
    fn finish(mut self) -> Result<Solution, SolveError> {
        let (_, q, s) = self.best.ok_or(SolveError::NoSolution)?;
        let o = self.o;
        let n = self.all.len();
        for (e, l) in self.errors.iter_mut().zip(self.all) {
            *e = line_error_of(l, &q, &s, o.error);
        }
        let k = lms_rank_for(n, o.lms_outlier_fraction);
        let kth = *self.errors.select_nth_unstable_by(k, f64::total_cmp).1;
        // A floor on σ̂ so that rounding-level residuals of noise-free data are not told apart.
        let unit = match o.error {
            LineError::E1 => mean_distance(self.all, &q, &s),
            LineError::E2 | LineError::E3 => 1.0,
        };
        let floor = 1e-9 * unit;
        let mut sigma = if k == lms_rank(n) && o.lms_outlier_fraction <= 1.0 / 3.0 {
            let med = *self.errors.select_nth_unstable_by(n / 2, f64::total_cmp).1;
            robust_sigma(med, n)
        } else {
            order_statistic_sigma(kth, k + 1, n)
        }
        .max(floor);
        let mut pose = pose_of(&q, &s);
        let mut inliers: Vec<usize> = Vec::new();
        let mut sol = None;
        for _ in 0..4 {
            let limit = o.lms_outlier_threshold * sigma;
            let (uq, us) = unknowns_of(&pose);
            let next: Vec<usize> = (0..n)
                .filter(|&i| line_error_of(&self.all[i], &uq, &us, o.error).sqrt() <= limit)
                .collect();
            if next.len() < 3 {
                break;
            }
            if next == inliers && sol.is_some() {
                break;
            }
            inliers = next;
            let kept: Vec<Correspondence> = inliers.iter().map(|&i| self.all[i]).collect();
            let fitted = r_and_t(&kept, Some(&pose), o)?;
            pose = fitted.pose;
            let (fq, fs) = unknowns_of(&pose);
            // The paper's median scale again, now over the current inliers at the refitted pose:
            // robust to the few outliers a loose first threshold may have let in.
            let mut errs: Vec<f64> = kept.iter().map(|l| line_error_of(l, &fq, &fs, o.error)).collect();
            let mid = errs.len() / 2;
            let med = *errs.select_nth_unstable_by(mid, f64::total_cmp).1;
            sigma = robust_sigma(med, kept.len()).max(floor);
            sol = Some(fitted);
        }
        let mut sol = sol.ok_or(SolveError::NoSolution)?;
        sol.inliers = inliers;
        Ok(sol)
    }
}

fn check(c: &[Correspondence], guess: Option<&Pose>) -> Result<Option<Unknowns>, SolveError> {
    if c.len() < 3 {
        return Err(SolveError::TooFew {
            needed: 3,
            got: c.len(),
        });
    }
    let guess = guess.map(unknowns_of);
    let guess_ok = guess.is_none_or(|(q, s)| q.coords.iter().all(|v| v.is_finite()) && s.iter().all(|v| v.is_finite()));
    if !all_finite(c) || !guess_ok {
        return Err(SolveError::Degenerate);
    }
    Ok(guess)
}

/// Med_R_and_T, line version (§4): least median of squares over 3-line subsets, outlier
/// rejection, R_and_T on the inliers. `seed` drives the random subsets (used only when C(n, 3)
/// exceeds the Monte-Carlo count).
///
/// Errors: fewer than 3 lines → `TooFew`; non-finite input → `Degenerate`; no subset gave a pose,
/// or fewer than 3 inliers → `NoSolution`.
pub fn med_r_and_t(
    c: &[Correspondence],
    guess: Option<&Pose>,
    o: &SolverOptions,
    seed: u64,
) -> Result<Solution, SolveError> {
    let guess = check(c, guess)?;
    let n = c.len();
    let mut search = Search {
        all: c,
        o,
        guess,
        errors: vec![0.0; n],
        best: None,
    };
    let wanted = monte_carlo_count(o.lms_success_probability, o.lms_outlier_fraction);
    let degenerate = |i: usize, j: usize, k: usize| direction_det(&c[i], &c[j], &c[k]) < o.degenerate_subset_det;
    if c3(n) <= wanted {
        for i in 0..n {
            for j in i + 1..n {
                for k in j + 1..n {
                    if !degenerate(i, j, k) {
                        search.subset(&[c[i], c[j], c[k]]);
                    }
                }
            }
        }
    } else {
        let mut rng = SmallRng::seed_from_u64(seed);
        let (mut done, mut draws) = (0u64, 0u64);
        // Degenerate draws are redrawn, within a cap so that an all-parallel input terminates.
        while done < wanted && draws < 20 * wanted + 100 {
            draws += 1;
            let i = rng.random_range(0..n);
            let j = rng.random_range(0..n);
            let k = rng.random_range(0..n);
            if i == j || j == k || i == k || degenerate(i, j, k) {
                continue;
            }
            done += 1;
            search.subset(&[c[i], c[j], c[k]]);
        }
    }
    search.finish()
}

/// Med_R_and_T, landmark version (§4): as [`med_r_and_t`] but the subsets are 3 landmarks (the
/// union of their lines), `landmark_of[i]` naming the landmark of `c[i]`. With fewer than 3
/// landmarks the one subset is all of them. Outliers are still judged line by line.
///
/// Panics if `landmark_of.len() != c.len()` (a caller bug).
pub fn med_r_and_t_landmarks(
    c: &[Correspondence],
    landmark_of: &[u32],
    guess: Option<&Pose>,
    o: &SolverOptions,
    seed: u64,
) -> Result<Solution, SolveError> {
    assert_eq!(landmark_of.len(), c.len(), "one landmark id per correspondence");
    let guess = check(c, guess)?;
    let n = c.len();
    let mut ids: Vec<u32> = landmark_of.to_vec();
    ids.sort_unstable();
    ids.dedup();
    let m = ids.len();
    let mut search = Search {
        all: c,
        o,
        guess,
        errors: vec![0.0; n],
        best: None,
    };
    let mut union: Vec<Correspondence> = Vec::with_capacity(n);
    let mut run = |search: &mut Search, chosen: &[u32]| {
        union.clear();
        union.extend(
            c.iter()
                .zip(landmark_of)
                .filter(|(_, id)| chosen.contains(id))
                .map(|(l, _)| *l),
        );
        if union.len() >= 3 {
            search.subset(&union);
        }
    };
    let wanted = monte_carlo_count(o.lms_success_probability, o.lms_outlier_fraction);
    if m < 3 {
        run(&mut search, &ids);
    } else if c3(m) <= wanted {
        for i in 0..m {
            for j in i + 1..m {
                for k in j + 1..m {
                    run(&mut search, &[ids[i], ids[j], ids[k]]);
                }
            }
        }
    } else {
        let mut rng = SmallRng::seed_from_u64(seed);
        let mut done = 0u64;
        while done < wanted {
            let i = rng.random_range(0..m);
            let j = rng.random_range(0..m);
            let k = rng.random_range(0..m);
            if i == j || j == k || i == k {
                continue;
            }
            done += 1;
            run(&mut search, &[ids[i], ids[j], ids[k]]);
        }
    }
    search.finish()
}
