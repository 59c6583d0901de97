//! Kumar & Hanson §4: Med_R_and_T, least median of squares over lines or landmarks.
//!
//! In: [`Correspondence`]s (some may be wrong), optionally each one's landmark id, an optional
//! guess `T_world_rig`, [`SolverOptions`], a seed. Out: a [`Solution`] whose `inliers` are the
//! correspondences kept after outlier rejection and whose pose is R_and_T over them.
//!
//! Steps (§4): (1) 3-line (or 3-landmark) subsets: all of them when there are no more than the
//! Monte-Carlo count m = ⌈log(1 − P) / log(1 − (1 − ε)³)⌉, otherwise m random ones; subsets whose
//! three unit 3D line directions have |det| < `degenerate_subset_det` are skipped. (2) Every pose
//! a subset allows (from the guess by R_and_T; without one, every root of R_then_T's rotation
//! stage reached from Horn's 12 tetrahedral samples, translation by eq. 9), scored by the median
//! over all lines of the line's squared error (`o.error`, both end points) — precisely
//! Rousseeuw's LMS order statistic h = ⌊n/2⌋ + 2 for 3-line elemental subsets (see [`lms_rank`]);
//! when the caller expects more outliers than LMS's 50 % breakdown allows
//! (`lms_outlier_fraction` > 1/3), the ⌊(1 − ε) n⌋-th instead (least k-th squares,
//! [`lms_rank_for`]). A line whose model segment lies behind its edge scores +∞: planes through
//! the centre cannot tell a scene from its mirror image behind the camera. (3)–(4), the outlier
//! threshold and R_and_T on the rest, are where we go past the paper (see `Search::finish`): the
//! few best poses are concentrated (FAST-LTS), their lines re-judged with an F-test from the
//! fit's own σ̂ (never below the sensor's pixel, `SolverOptions::pixel_rad`), refitted until
//! stable, the most likely candidate wins, and its lines are fitted last under Cauchy's loss at
//! their own robust scale; the covariance is §5's at the noise those lines show.
//!
//! Scratch (per-line errors, the candidates' line sets) is allocated per call, never per subset:
//! the subset loop itself allocates nothing. This solver is for `omnitrack pose` and whole-frame
//! solves; the tracker's per-frame path uses the fixed-capacity [`crate::ConsensusSampler`].

mod finish;

use crate::minimal::three_lines::three_line_rotations;
use crate::refine::horn::tetrahedral;
use crate::refine::kumar_hanson::{r_and_t, refine, rotation_stage, translation_stage};
use crate::refine::residuals::{
    all_finite, line_error_of, line_residuals, mean_distance, pose_of, unknowns_of, Unknowns,
};
use crate::{LineError, Solution, SolveError, SolverOptions};
use nalgebra::{Matrix2, Matrix3, Matrix6, Rotation3, UnitQuaternion, Vector2, Vector3};
use omnitrack_core::geometry::{Correspondence, Pose};
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

/// How many of the best subset poses are polished by concentration before one is chosen
/// (FAST-LTS's several starts): with noisy lines the order statistic of a raw 3-line pose is
/// itself noisy, and a wrong pose can win it by luck while the right one is a close second.
const POLISHED: usize = 8;

/// Concentration steps per candidate; each lowers the trimmed sum or stops, so this only bounds
/// the time (they converge in 2–4 steps).
const MAX_C_STEPS: usize = 6;

/// One subset pose: its order statistic, rotation and translation (`T_rig_world`).
type Candidate = (f64, UnitQuaternion<f64>, Vector3<f64>);

/// Whether the model segment lies wholly behind the observed edge: both end points, seen from
/// the sensor, are more than 90° from the edge's mid ray. A plane through the centre cannot tell
/// a line from its mirror image behind the camera, so without this test a 3-line subset's
/// "camera looking backwards" pose (the whole scene turned 180°) fits its lines exactly and can
/// win the order statistic when n is small. An edge spanning less than 180° has a mid ray; a
/// segment partly in front (one end behind, a long corridor line) is not rejected.
#[inline]
fn behind(l: &Correspondence, q: &UnitQuaternion<f64>, s: &Vector3<f64>) -> bool {
    let mid = l.edge.ends[0].into_inner() + l.edge.ends[1].into_inner();
    l.segment
        .iter()
        .all(|p| (q * p.coords + s - l.edge.centre.coords).dot(&mid) <= 0.0)
}

/// The error Med_R_and_T ranks: the line error, or +∞ for a line behind its edge or a NaN.
#[inline]
fn ranked_error(l: &Correspondence, q: &UnitQuaternion<f64>, s: &Vector3<f64>, error: LineError) -> f64 {
    let v = line_error_of(l, q, s, error);
    if v.is_nan() || behind(l, q, s) {
        f64::INFINITY
    } else {
        v
    }
}

/// F(2, d)'s upper quantile at tail probability `tail` (closed form for 2 numerator degrees of
/// freedom: P(F > x) = (1 + 2x / d)^(−d/2)).
fn f2_quantile(tail: f64, dof: f64) -> f64 {
    0.5 * dof * (tail.powf(-2.0 / dof) - 1.0)
}

/// The least-median search state: the best poses so far and the per-line scratch.
struct Search<'a> {
    all: &'a [Correspondence],
    o: &'a SolverOptions,
    guess: Option<Unknowns>,
    errors: Vec<f64>,
    /// The `POLISHED` best distinct candidates, best first.
    top: [Option<Candidate>; POLISHED],
}

impl Search<'_> {
    fn new<'a>(all: &'a [Correspondence], o: &'a SolverOptions, guess: Option<Unknowns>) -> Search<'a> {
        Search {
            all,
            o,
            guess,
            errors: vec![0.0; all.len()],
            top: [None; POLISHED],
        }
    }

    /// The order statistic minimised (see [`lms_rank_for`]): 0-based rank.
    fn rank(&self) -> usize {
        lms_rank_for(self.all.len(), self.o.lms_outlier_fraction)
    }

    /// The LMS objective at `(q, s)`: the `lms_rank`-th smallest squared line error over all
    /// lines, or +∞ as soon as more than n − rank − 1 lines exceed `bound` (the pose cannot then
    /// beat the candidates already held, and most subset poses are wrong ones).
    fn median(&mut self, q: &UnitQuaternion<f64>, s: &Vector3<f64>, bound: f64) -> f64 {
        let h = self.rank();
        let allowed = self.all.len() - h - 1;
        let mut over = 0;
        for (e, l) in self.errors.iter_mut().zip(self.all) {
            *e = ranked_error(l, q, s, self.o.error);
            if *e > bound {
                over += 1;
                if over > allowed {
                    return f64::INFINITY;
                }
            }
        }
        *self.errors.select_nth_unstable_by(h, f64::total_cmp).1
    }

    fn consider(&mut self, q: UnitQuaternion<f64>, s: Vector3<f64>) {
        let bound = self.top[POLISHED - 1].map_or(f64::INFINITY, |c| c.0);
        let med = self.median(&q, &s, bound);
        if !med.is_finite() {
            return;
        }
        // The same pose found from another subset is one candidate, not two.
        let scale = 1.0 + s.norm();
        let same = |c: &Candidate| c.1.angle_to(&q) < 1e-2 && (c.2 - s).norm() < 1e-2 * scale;
        let slot = match self.top.iter().position(|c| c.as_ref().is_some_and(same)) {
            Some(i) if self.top[i].is_some_and(|c| c.0 <= med) => return,
            Some(i) => i,
            None => match self.top.iter().position(|c| c.is_none_or(|c| med < c.0)) {
                Some(_) => POLISHED - 1,
                None => return,
            },
        };
        self.top[slot] = Some((med, q, s));
        self.top.sort_by(|a, b| {
            a.map_or(f64::INFINITY, |c| c.0)
                .total_cmp(&b.map_or(f64::INFINITY, |c| c.0))
        });
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
        // No guess: every rotation the subset allows (three lines have up to 8), each scored by
        // the order statistic over all lines. A landmark subset has more than three lines and
        // is overdetermined: R_then_T's rotation stage from each start, distinct minima kept.
        let mut roots = [UnitQuaternion::identity(); 12];
        let count = if let [a, b, c] = sub {
            let mut matrices = [Matrix3::zeros(); 12];
            let count = three_line_rotations(&[*a, *b, *c], &mut matrices);
            for (q, r) in roots.iter_mut().zip(&matrices[..count]) {
                *q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*r));
            }
            count
        } else {
            let mut count = 0;
            for q0 in tetrahedral() {
                let coarse = rotation_stage(sub, *q0, o.max_iterations.min(15), o.convergence_rad.max(1e-6));
                if let Some((q, _, _)) = coarse.filter(|(q, _, _)| roots[..count].iter().all(|p| p.angle_to(q) >= 1e-3))
                {
                    roots[count] = q;
                    count += 1;
                }
            }
            count
        };
        for q in &roots[..count] {
            // The rotation fixes eq. 9's translation, so a subset's pose needs no R_and_T polish
            // before it is scored: only the winners are refined, on their inliers.
            let Some(s) = translation_stage(sub, q) else {
                continue;
            };
            self.consider(*q, s);
        }
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
    let mut search = Search::new(c, o, guess);
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
    let mut search = Search::new(c, o, guess);
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

#[cfg(test)]
mod tests;
