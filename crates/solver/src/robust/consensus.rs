//! The tracker's robust estimator: random consensus sampling (Koch–Teller §4.2.3, Fig. 7 lines
//! 6–10), "anytime".
//!
//! In: the accepted correspondences S̄_t, the pose at frame t as the guess, a [`SamplingBudget`]
//! (s_t from eq. 2 — see [`super::sampling::sample_count`] — a time budget and the inlier angle),
//! a random generator and the refinement to use (a `fit` closure: R_and_T or the ξ simplex).
//! Out: a [`ConsensusOutcome`]: the pose, ξ over the inliers, the number of samples drawn, why
//! sampling stopped, and the inlier indices (in a buffer of the sampler).
//!
//! Per sample: λ correspondences drawn without replacement, `fit` from the guess, scored by ξ
//! over the remaining correspondences; the lowest score wins. Then the inliers (α below the
//! inlier angle) at the winning pose are refitted (from that pose) and the inliers recomputed.
//!
//! **Deviation from the paper (scoring).** KT score a sample by plain ξ over the remaining
//! correspondences. One gross outlier contributes α² up to (π/2)² ≈ 2.5 rad², against ~1e-4 rad²
//! for an inlier with 0.5° noise, so plain ξ ranks samples by which outliers happen to fit least
//! badly rather than by how many inliers agree. We truncate each term at the inlier angle:
//! score = (1/m) Σ min(α², α_in²) (an MSAC-style cost). Inliers still count by their residuals,
//! every outlier counts the same bounded amount, and a pose that explains more correspondences
//! always wins over one that explains fewer by a margin.
//!
//! [`SampleScore::Median`] scores by the median α² instead (Kumar–Hanson §4's least median of
//! squares; `maintenance.consensus_score = "median"`). The cap is the papers' 3σ for 0.5° edges;
//! on sharper edges (a 50° pinhole resolves 0.08° a pixel) a pose slid along a narrow view's
//! loosely fixed direction keeps every right line near 0.5° and its few wrong ones inside the
//! cap, and the truncated score prefers it to the true pose, where the right lines sit at
//! 0.05° and the wrong ones fall out. The median has no cap. Measured (docs/decisions.md, the
//! median consensus and the one-sensor pinhole rig): it stops that slide and tightens the default world (`lab`
//! 1.26 → 1.13 cm, `corridor` 0.78 → 0.67, `handheld` 1.00 → 0.87); on the realistic world it
//! ends the cascades only together with the motion carried through relocalisations (the
//! tracker's; alone, one run of six cascaded). The tracker's default. It needs the
//! correspondences left out of a sample to be mostly right: a sample of 6 from 12 with three
//! wrong leaves a median that a wrong pose can win (the tracker samples half of a small set).
//!
//! Everything is sized at construction ([`ConsensusSampler::new`]); [`ConsensusSampler::run`]
//! allocates nothing (provided `fit` does not), which the tests count.

use crate::SolveError;
use omnitrack_core::geometry::{xi, Correspondence, Pose};
use omnitrack_core::memory::resident;
use rand::rngs::SmallRng;
use rand::Rng;
use serde::{Deserialize, Serialize};
use std::time::{Duration, Instant};

/// How a sample's pose is scored over the correspondences left out of it (lowest wins).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SampleScore {
    /// (1/m) Σ min(α², α_in²): MSAC's truncated squares (module doc).
    Truncated,
    /// The median α²: Kumar–Hanson §4's least median of squares (Med_R_and_T's criterion,
    /// after Rousseeuw). No cap: where the edges are sharper than the inlier angle, a pose slid
    /// along a narrow view's loosely fixed direction that keeps every line inside the cap
    /// scores worse than the true pose, whose few wrong matches fall far out (module doc).
    Median,
}

/// What one [`ConsensusSampler::run`] may spend.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SamplingBudget {
    /// s_t: samples to draw (KT eq. 2); further capped by the sampler's `max_samples`. At least
    /// one sample is drawn even if this is 0.
    pub max_samples: u64,
    /// Sampling stops once this much time has passed since the call began (checked after every
    /// sample; at least one sample is always drawn, and the final refit comes on top).
    pub time_budget: Duration,
    /// A correspondence is an inlier when its α (rad) at the pose is below this; also the
    /// truncation of the sample score (module doc).
    pub inlier_alpha_rad: f64,
    pub score: SampleScore,
}

/// A refinement for [`ConsensusSampler::run`]: `fit(set, lines, start)`, `set[k]` being
/// correspondence `lines[k]` of the run's.
pub type SampleFit<'f> = dyn FnMut(&[Correspondence], &[usize], &Pose) -> Option<Pose> + 'f;

/// Why sampling stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopReason {
    /// All `min(budget.max_samples, sampler max_samples)` samples were drawn.
    SampleCount,
    /// The time budget ran out first.
    TimeBudget,
}

/// The result of a [`ConsensusSampler::run`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConsensusOutcome {
    /// `T_world_rig` after the refit on the inliers.
    pub pose: Pose,
    /// Plain KT ξ (eq. 1, rad²) over the inliers at `pose` (0 if there are none).
    pub xi_rad2: f64,
    /// The truncated score (module doc) of the best sample, over its remaining correspondences.
    pub best_sample_score: f64,
    /// Samples drawn (fits attempted, including those whose fit returned `None`).
    pub samples: u64,
    pub stop: StopReason,
    /// How many inliers: the first `inlier_count` entries of the sampler's inlier buffer.
    pub inlier_count: usize,
    /// Whether the refit on the inliers was run and kept (otherwise `pose` is the best sample's).
    pub refitted: bool,
}

impl ConsensusOutcome {
    /// The inlier indices (ascending, into the `c` given to `run`). Valid until the sampler's
    /// next `run`, which overwrites the buffer.
    pub fn inliers<'s>(&self, sampler: &'s ConsensusSampler) -> &'s [usize] {
        &sampler.inliers[..self.inlier_count]
    }
}

/// Why a [`ConsensusSampler::run`] failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ConsensusError {
    #[error("{got} correspondences exceed the consensus sampler's capacity of {capacity} (set at construction)")]
    CapacityExceeded { capacity: usize, got: usize },
    #[error(transparent)]
    Solve(#[from] SolveError),
}

/// Random consensus sampling with every buffer allocated once. See the module doc.
#[derive(Debug, Clone)]
pub struct ConsensusSampler {
    capacity: usize,
    lambda: usize,
    max_samples: u64,
    /// A permutation of 0..n; a partial Fisher–Yates shuffle puts each sample in its first λ.
    order: Vec<usize>,
    /// The current sample's correspondences, contiguous for `fit` (length λ).
    sample: Vec<Correspondence>,
    /// Inlier indices (length `capacity`; the first `inlier_count` are valid).
    inliers: Vec<usize>,
    /// The inliers' correspondences, contiguous for the refit (length `capacity`).
    inlier_set: Vec<Correspondence>,
    /// α² of a pose's correspondences, or the ratios that order them, for
    /// [`SampleScore::Median`] (length `capacity` each).
    squares: Vec<f64>,
    spare: Vec<f64>,
}

impl ConsensusSampler {
    /// A sampler for up to `capacity` correspondences per run, samples of `lambda`, at most
    /// `max_samples` samples per run (whatever the budget asks).
    ///
    /// # Panics
    /// If `lambda` is 0 or exceeds `capacity` (a configuration error, caught at start-up).
    pub fn new(capacity: usize, lambda: usize, max_samples: u64) -> Self {
        assert!(
            lambda >= 1 && lambda <= capacity,
            "consensus sampler: λ = {lambda} must be in 1..={capacity} (the capacity)"
        );
        let filler = Correspondence {
            edge: omnitrack_core::geometry::EdgePlane {
                normal: nalgebra::Vector3::z_axis(),
                centre: nalgebra::Point3::origin(),
                ends: [nalgebra::Vector3::x_axis(), nalgebra::Vector3::y_axis()],
            },
            segment: [nalgebra::Point3::origin(); 2],
        };
        Self {
            capacity,
            lambda,
            max_samples,
            // Resident from the start (`omnitrack_core::memory`): a frame with more
            // correspondences than any before would otherwise take new memory.
            order: resident(vec![0; capacity]),
            sample: vec![filler; lambda],
            inliers: resident(vec![0; capacity]),
            inlier_set: vec![filler; capacity],
            squares: resident(vec![0.0; capacity]),
            spare: resident(vec![0.0; capacity]),
        }
    }

    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// λ, the correspondences per sample.
    pub fn lambda(&self) -> usize {
        self.lambda
    }

    pub fn max_samples(&self) -> u64 {
        self.max_samples
    }

    /// Runs KT's sampling on `c` from `guess` (module doc). `fit(set, lines, start)` refines a
    /// pose on `set` from `start` (`None`: no usable pose), `set[k]` being `c[lines[k]]` (so that a
    /// fit can use what it worked out per correspondence of `c` beforehand); it is called once
    /// per sample (from `guess`) and once for the refit (from the best sample's pose, skipped when there are fewer than λ
    /// inliers). The refit is kept unless its truncated score over all of `c` is worse than the
    /// best sample's.
    ///
    /// Errors: more than `capacity` correspondences ([`ConsensusError::CapacityExceeded`]);
    /// fewer than λ ([`SolveError::TooFew`]); no sample gave a pose ([`SolveError::NoSolution`]).
    pub fn run(
        &mut self,
        c: &[Correspondence],
        guess: &Pose,
        budget: &SamplingBudget,
        rng: &mut SmallRng,
        fit: &mut SampleFit<'_>,
    ) -> Result<ConsensusOutcome, ConsensusError> {
        self.run_sized(self.lambda, c, guess, budget, rng, fit)
    }

    /// [`Self::run`] with samples of `lambda` correspondences (at most the λ the sampler was
    /// built for): a set barely larger than λ leaves no outlier out of any sample, so a caller
    /// with few correspondences samples fewer.
    pub fn run_sized(
        &mut self,
        lambda: usize,
        c: &[Correspondence],
        guess: &Pose,
        budget: &SamplingBudget,
        rng: &mut SmallRng,
        fit: &mut SampleFit<'_>,
    ) -> Result<ConsensusOutcome, ConsensusError> {
        let started = Instant::now();
        let n = c.len();
        if n > self.capacity {
            return Err(ConsensusError::CapacityExceeded {
                capacity: self.capacity,
                got: n,
            });
        }
        let lambda = lambda.clamp(1, self.lambda);
        if n < lambda {
            return Err(SolveError::TooFew { needed: lambda, got: n }.into());
        }
        let cap2 = budget.inlier_alpha_rad * budget.inlier_alpha_rad;
        let max_samples = budget.max_samples.min(self.max_samples);
        let order = &mut self.order[..n];
        for (i, o) in order.iter_mut().enumerate() {
            *o = i;
        }

        let mut best: Option<(Pose, f64)> = None;
        // tan² α beyond which a correspondence's α surely exceeds the best sample's median
        // (`median_square`): a sample with half of its rest (rounded up) beyond it cannot win.
        let mut beaten = f64::INFINITY;
        let mut samples = 0u64;
        let stop = loop {
            if samples >= max_samples.max(1) {
                break StopReason::SampleCount;
            }
            if samples > 0 && started.elapsed() >= budget.time_budget {
                break StopReason::TimeBudget;
            }
            samples += 1;
            // Partial Fisher–Yates: order[..λ] becomes a uniform λ-subset, order[λ..] the rest.
            for i in 0..lambda {
                let j = rng.random_range(i..n);
                order.swap(i, j);
            }
            for (s, &i) in self.sample.iter_mut().zip(order[..lambda].iter()) {
                *s = c[i];
            }
            let Some(pose) = fit(&self.sample[..lambda], &order[..lambda], guess) else {
                continue;
            };
            let Some(scored) = score(
                (&mut self.squares, &mut self.spare),
                budget.score,
                order[lambda..].iter().map(|&i| &c[i]),
                &pose,
                cap2,
                beaten,
            ) else {
                continue;
            };
            if scored.score.is_finite() && best.as_ref().is_none_or(|(_, b)| scored.score < *b) {
                best = Some((pose, scored.score));
                beaten = scored.exceeded;
            }
        };
        let (best_pose, best_sample_score) = best.ok_or(SolveError::NoSolution)?;

        // Inliers at the best sample's pose, refit on them, inliers again.
        let mut count = self.collect_inliers(c, &best_pose, budget.inlier_alpha_rad);
        let mut pose = best_pose;
        let mut refitted = false;
        if count >= lambda {
            if let Some(refit) = fit(&self.inlier_set[..count], &self.inliers[..count], &best_pose) {
                let mut over_all = |pose: &Pose| {
                    let all = score(
                        (&mut self.squares, &mut self.spare),
                        budget.score,
                        c.iter(),
                        pose,
                        cap2,
                        f64::INFINITY,
                    );
                    all.map_or(f64::INFINITY, |s| s.score)
                };
                let all_best = over_all(&best_pose);
                let all_refit = over_all(&refit);
                if all_refit <= all_best {
                    pose = refit;
                    refitted = true;
                    count = self.collect_inliers(c, &pose, budget.inlier_alpha_rad);
                }
            }
        }
        Ok(ConsensusOutcome {
            pose,
            xi_rad2: xi(&self.inlier_set[..count], &pose),
            best_sample_score,
            samples,
            stop,
            inlier_count: count,
            refitted,
        })
    }

    /// Fills `inliers` / `inlier_set` with the correspondences whose α at `pose` is below
    /// `alpha`; returns how many.
    fn collect_inliers(&mut self, c: &[Correspondence], pose: &Pose, alpha: f64) -> usize {
        let mut count = 0;
        for (i, corr) in c.iter().enumerate() {
            if corr.alpha(pose) < alpha {
                self.inliers[count] = i;
                self.inlier_set[count] = *corr;
                count += 1;
            }
        }
        count
    }
}

/// A sample's score, and for a median the tan² α beyond which a correspondence's α surely
/// exceeds it (infinite where that is not known).
#[derive(Debug, Clone, Copy)]
struct Scored {
    score: f64,
    exceeded: f64,
}

/// `kind` of score of `pose` over `set` (`buffers`: two of the sampler's, as long as `set`), or
/// `None` for a median that cannot be below the best so far: half of `set` (rounded up) has a
/// tan² α beyond `beaten` (that best's [`Scored::exceeded`]).
fn score<'a>(
    buffers: (&mut [f64], &mut [f64]),
    kind: SampleScore,
    set: impl ExactSizeIterator<Item = &'a Correspondence> + Clone,
    pose: &Pose,
    cap2: f64,
    beaten: f64,
) -> Option<Scored> {
    match kind {
        SampleScore::Truncated => Some(Scored {
            score: truncated_score(set, pose, cap2),
            exceeded: f64::INFINITY,
        }),
        SampleScore::Median => median_square(buffers.0, buffers.1, set, pose, beaten),
    }
}

/// Pivots (tan² α of the median's rank) beyond which [`median_square`] takes every α: within
/// 1e-8 rad of π/2, where a relative band of [`MEDIAN_BAND`] is too few ulps of α to be safe.
const MEDIAN_TAN2_LIMIT: f64 = 1e16;
/// The relative width of [`median_square`]'s band about the pivot's tan α ...
const MEDIAN_BAND: f64 = 1e-6;
/// ... and its least half-width: [`Correspondence::alpha_tan2`] and α's own terms agree to a few
/// 10⁻¹⁶ rad of angle, more than a relative band holds where α is tiny.
const MEDIAN_BAND_FLOOR: f64 = 1e-12;

/// The median α² of `set` at `pose`: the square of the α of rank m/2 (0-based) among the m,
/// exactly as selecting it among every α² gives it, with an arc tangent for a few of them only;
/// `None`, early, once half of `set` (rounded up) has a tan² α beyond `beaten`.
///
/// α rises with tan α, so the correspondences are ranked by tan² α
/// ([`Correspondence::alpha_tan2`], without the arc tangent, square roots or the normalisation
/// of α's own) and the element of rank m/2 found; the α of every element whose tan α lies
/// within a relative [`MEDIAN_BAND`] (and at least [`MEDIAN_BAND_FLOOR`]) of it, itself
/// included, is then computed, and the median is the one of the right rank among those (the
/// elements below the band counted). Outside the band the tangents differ from the pivot's by a
/// millionth, far more than the arc tangent's error (under an ulp) and the tangents' rounding can
/// reorder, so no α outside it can take the median's rank; inside it the α themselves decide,
/// as before. Where that margin is not assured (a pivot beyond [`MEDIAN_TAN2_LIMIT`], infinite or
/// NaN) every α is computed, as before. The arc tangent was about half of the consensus's
/// scoring, which takes the median over the rest of the set for every one of a frame's
/// hundred-odd samples.
///
/// The same margin past the band's top bounds the median from above: an element whose tan² α
/// is beyond [`Scored::exceeded`] has a larger α than the median. Once m − m/2 of another
/// sample's m are beyond the best median's bound, at most m/2 can be below it, so that sample's
/// median (rank m/2) is at least the best's and cannot replace it (the sampler keeps strictly
/// lower scores), whatever the rest holds: its scoring stops there.
fn median_square<'a>(
    keys: &mut [f64],
    spare: &mut [f64],
    set: impl ExactSizeIterator<Item = &'a Correspondence> + Clone,
    pose: &Pose,
    beaten: f64,
) -> Option<Scored> {
    let m = set.len();
    let rank = m / 2;
    let (mut nan, mut above) = (false, 0);
    for (slot, corr) in keys.iter_mut().zip(set.clone()) {
        let key = corr.alpha_tan2(pose);
        *slot = key;
        nan |= key.is_nan();
        if key > beaten {
            above += 1;
            if above == m - rank {
                return None;
            }
        }
    }
    if m == 0 {
        return Some(Scored {
            score: 0.0,
            exceeded: f64::INFINITY,
        });
    }
    spare[..m].copy_from_slice(&keys[..m]);
    let (_, pivot, _) = spare[..m].select_nth_unstable_by(rank, f64::total_cmp);
    let pivot = *pivot;
    if nan || pivot.is_nan() || pivot > MEDIAN_TAN2_LIMIT {
        for (slot, corr) in spare.iter_mut().zip(set) {
            *slot = corr.alpha(pose).powi(2);
        }
        let (_, median, _) = spare[..m].select_nth_unstable_by(rank, f64::total_cmp);
        return Some(Scored {
            score: *median,
            exceeded: f64::INFINITY,
        });
    }
    let tan = pivot.sqrt();
    let low = tan * (1.0 - MEDIAN_BAND) - MEDIAN_BAND_FLOOR;
    let high = tan * (1.0 + MEDIAN_BAND) + MEDIAN_BAND_FLOOR;
    let low2 = if low > 0.0 { low * low } else { f64::NEG_INFINITY };
    let high2 = high * high;
    let (mut below, mut band) = (0, 0);
    for (key, corr) in keys[..m].iter().zip(set) {
        if *key < low2 {
            below += 1;
        } else if *key <= high2 {
            spare[band] = corr.alpha(pose).powi(2);
            band += 1;
        }
    }
    let (_, median, _) = spare[..band].select_nth_unstable_by(rank - below, f64::total_cmp);
    let exceeded = high * (1.0 + MEDIAN_BAND) + MEDIAN_BAND_FLOOR;
    Some(Scored {
        score: *median,
        exceeded: exceeded * exceeded,
    })
}

/// (1/m) Σ min(α², cap²) over `set` (0 for an empty set).
fn truncated_score<'a>(set: impl Iterator<Item = &'a Correspondence>, pose: &Pose, cap2: f64) -> f64 {
    let (mut sum, mut m) = (0.0, 0usize);
    for corr in set {
        sum += corr.alpha(pose).powi(2).min(cap2);
        m += 1;
    }
    if m == 0 {
        0.0
    } else {
        sum / m as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
    use omnitrack_core::geometry::EdgePlane;
    use rand::SeedableRng;

    /// The median over every α², as it was taken before [`median_square`].
    fn plain_median(set: &[Correspondence], pose: &Pose) -> f64 {
        let mut squares: Vec<f64> = set.iter().map(|c| c.alpha(pose).powi(2)).collect();
        let m = squares.len();
        *squares.select_nth_unstable_by(m / 2, f64::total_cmp).1
    }

    /// The median from the tangents and a band of arc tangents is the plain one bit for bit: on
    /// sets of every size with inliers and outliers, exact and nearly exact lines (α of 10⁻¹⁶ to
    /// 10⁻¹⁰), twins (equal tangents) and near-twins, segments through the centre (π/2), planes
    /// at right angles, and every α equal. A scoring stopped early by the last set's bound is
    /// one whose plain median is no lower than the last set's.
    #[test]
    fn the_median_from_tangents_is_the_plain_median_bit_for_bit() {
        let mut rng = SmallRng::seed_from_u64(5);
        let v = |rng: &mut SmallRng, r: f64| Vector3::from_fn(|_, _| rng.random_range(-r..r));
        let pose = Isometry3::from_parts(
            Translation3::new(0.5, -1.0, 1.4),
            UnitQuaternion::from_euler_angles(0.02, -0.03, 0.7),
        );
        let (mut ratios, mut spare) = (vec![0.0; 64], vec![0.0; 64]);
        let mut last = Scored {
            score: f64::INFINITY,
            exceeded: f64::INFINITY,
        };
        let mut stopped = 0;
        for trial in 0..3000 {
            let n = 1 + trial % 40;
            let mut set = Vec::with_capacity(n);
            while set.len() < n {
                let seg = [Point3::from(v(&mut rng, 6.0)), Point3::from(v(&mut rng, 6.0))];
                let c = Point3::from(v(&mut rng, 0.05));
                let a = pose.inverse_transform_point(&seg[0]) - c;
                let b = pose.inverse_transform_point(&seg[1]) - c;
                let Some(mut edge) = EdgePlane::from_rays(c, &a, &b) else {
                    continue;
                };
                // Inliers within a degree, outliers anywhere; now and then exactly at right angles.
                let tilt = match rng.random_range(0..12) {
                    0..=5 => rng.random_range(0.0..0.02),
                    6..=8 => rng.random_range(0.0..1.6),
                    9 => 0.0,
                    10 => rng.random_range(0.0..1e-10),
                    _ => std::f64::consts::FRAC_PI_2,
                };
                let axis = nalgebra::Unit::new_normalize(edge.normal.cross(&v(&mut rng, 1.0)));
                edge.normal = UnitQuaternion::from_axis_angle(&axis, tilt) * edge.normal;
                set.push(Correspondence { edge, segment: seg });
                // Twins and near-twins: equal or nearly equal ratios about the median.
                if rng.random_range(0..4) == 0 && set.len() < n {
                    let mut twin = *set.last().unwrap();
                    if rng.random_range(0..2) == 0 {
                        twin.segment[1] += Vector3::new(1e-13, 0.0, 0.0);
                    }
                    set.push(twin);
                }
            }
            if trial % 7 == 0 {
                // A segment through its sensor's centre: no predicted plane, α = π/2.
                let c = set[0].edge.centre;
                let through = pose.transform_point(&c);
                set[0].segment = [through, through + pose.rotation * Vector3::new(1.0, 2.0, 0.5)];
            }
            let plain = plain_median(&set, &pose);
            let got = median_square(&mut ratios, &mut spare, set.iter(), &pose, f64::INFINITY).unwrap();
            assert_eq!(got.score.to_bits(), plain.to_bits(), "trial {trial}, {n} lines");
            match median_square(&mut ratios, &mut spare, set.iter(), &pose, last.exceeded) {
                Some(early) => assert_eq!(early.score.to_bits(), plain.to_bits(), "trial {trial}, bounded"),
                None => {
                    stopped += 1;
                    assert!(
                        !plain.is_finite() || plain >= last.score,
                        "trial {trial}: {plain} < {}",
                        last.score
                    );
                }
            }
            last = got;
        }
        assert!(stopped > 300, "{stopped} of 3000 stopped early");
        // Every α the same (a set of twins): the band holds them all.
        let one = {
            let c = Point3::new(0.02, 0.0, 0.0);
            let seg = [Point3::new(4.0, 1.0, 0.0), Point3::new(4.0, 1.0, 2.5)];
            let a = pose.inverse_transform_point(&seg[0]) - c;
            let b = pose.inverse_transform_point(&seg[1]) - c;
            Correspondence {
                edge: EdgePlane::from_rays(c, &a, &b)
                    .unwrap()
                    .with_normal(nalgebra::Vector3::z_axis()),
                segment: seg,
            }
        };
        let twins = [one; 9];
        let got = median_square(&mut ratios, &mut spare, twins.iter(), &pose, f64::INFINITY).unwrap();
        assert_eq!(got.score.to_bits(), plain_median(&twins, &pose).to_bits());
    }
}
