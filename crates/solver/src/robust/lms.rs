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
//! fit's own σ̂, refitted until stable, and the most likely candidate wins.
//!
//! Scratch (per-line errors, the candidates' line sets) is allocated per call, never per subset:
//! the subset loop itself allocates nothing. This solver is for `omnitrack pose` and whole-frame
//! solves; the tracker's per-frame path uses the fixed-capacity [`crate::ConsensusSampler`].

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

    /// Indices of the `h` lines with the smallest errors at `(q, s)` (into `order`), and the sum
    /// of those errors (the least-trimmed-squares objective).
    fn smallest(&mut self, q: &UnitQuaternion<f64>, s: &Vector3<f64>, h: usize, order: &mut Vec<usize>) -> f64 {
        for (e, l) in self.errors.iter_mut().zip(self.all) {
            *e = ranked_error(l, q, s, self.o.error);
        }
        order.clear();
        order.extend(0..self.all.len());
        let errors = &self.errors;
        order.select_nth_unstable_by(h - 1, |&a, &b| errors[a].total_cmp(&errors[b]));
        order.truncate(h);
        order.sort_unstable();
        order.iter().map(|&i| errors[i]).sum()
    }

    /// Rousseeuw & Van Driessen's concentration step, repeated: refit R_and_T on the `h` lines
    /// that fit the current pose best, until the trimmed sum stops falling. Each step cannot
    /// raise the trimmed sum, so this turns a noisy 3-line pose into the least-trimmed-squares
    /// pose of its basin. Returns (trimmed sum, pose).
    fn concentrate(
        &mut self,
        start: Candidate,
        h: usize,
        order: &mut Vec<usize>,
        kept: &mut Vec<Correspondence>,
    ) -> Candidate {
        let (_, mut q, mut s) = start;
        let mut sum = self.smallest(&q, &s, h, order);
        for _ in 0..MAX_C_STEPS {
            kept.clear();
            kept.extend(order.iter().map(|&i| self.all[i]));
            let Ok(r) = refine(kept, q, s, self.o) else {
                break;
            };
            let previous = order.clone();
            let next = self.smallest(&r.q, &r.s, h, order);
            if next.is_nan() || next >= sum {
                order.clone_from(&previous);
                break;
            }
            (sum, q, s) = (next, r.q, r.s);
            if *order == previous {
                break;
            }
        }
        (sum, q, s)
    }

    /// Each line's error at the fit of `set` into `self.errors`, a fitted line's standardised by
    /// its leverage (regression diagnostics). A fitted line's residual r has covariance
    /// σ²(I − H), H = J M⁻¹ Jᵀ its 2×2 block of the hat matrix, so rᵀ(I − H)⁻¹r is σ² χ²₂ for an
    /// inlier whatever its leverage. A wrong line that drags the fit towards itself has a small
    /// raw error but a large standardised one: with weak geometry, one or two such lines turned
    /// a 5-pixel pose 15° at 50 % outliers. A line outside the fit keeps its raw error: its
    /// prediction variance σ²(I + H) would widen the gate, and with few lines that let outliers
    /// in (measured: 6 lines, 30 % outliers, failures 4 % → 11 %). Lines behind their edge, or
    /// alone in fixing the fit (leverage 1), get +∞. Returns false if `set` does not fix the pose.
    fn standardised_errors(&mut self, q: &UnitQuaternion<f64>, s: &Vector3<f64>, set: &[usize]) -> bool {
        let error = self.o.error;
        let mut information = Matrix6::zeros();
        for &i in set {
            if let Some(res) = line_residuals(&self.all[i], q, s, error) {
                for k in 0..2 {
                    information.ger(res.weight[k], &res.jacobian[k], &res.jacobian[k], 1.0);
                }
            }
        }
        let Some(chol) = information.cholesky() else {
            return false;
        };
        let mut next_in_set = set.iter().peekable();
        for (i, (e, l)) in self.errors.iter_mut().zip(self.all).enumerate() {
            let fitted = next_in_set.next_if(|&&k| k == i).is_some();
            let res = line_residuals(l, q, s, error).filter(|_| !behind(l, q, s));
            let Some(res) = res else {
                *e = f64::INFINITY;
                continue;
            };
            let root = [res.weight[0].sqrt(), res.weight[1].sqrt()];
            let a = [res.jacobian[0] * root[0], res.jacobian[1] * root[1]];
            let r = Vector2::new(res.r[0] * root[0], res.r[1] * root[1]);
            let solved = [chol.solve(&a[0]), chol.solve(&a[1])];
            let hat = Matrix2::new(
                a[0].dot(&solved[0]),
                a[0].dot(&solved[1]),
                a[1].dot(&solved[0]),
                a[1].dot(&solved[1]),
            );
            if !fitted {
                *e = r.norm_squared();
                continue;
            }
            let spread = Matrix2::identity() - hat;
            *e = match spread.try_inverse() {
                Some(inv) if spread.determinant() > 1e-9 => (r.transpose() * inv * r)[0].max(0.0),
                _ => f64::INFINITY,
            };
        }
        true
    }

    /// Reweighting from one concentrated candidate: the lines whose error is within the gate,
    /// R_and_T on them, repeated until the set is stable (at most 5 refits). σ̂² starts from the
    /// h-set's errors over their degrees of freedom, made consistent for the truncation the
    /// caller's outlier fraction implies ([`start_gate`]), and is re-estimated from each new set.
    /// A set is never let shrink below h lines, or it could fit itself. Returns the fit and its set.
    fn reweight(&mut self, c: &Concentrated, kept: &mut Vec<Correspondence>) -> Option<(Solution, Vec<usize>)> {
        let o = self.o;
        let n = self.all.len();
        let h = c.set.len();
        let smallest_set = self.rank() + 1;
        let tail = gate_tail(o);
        let trimmed = c.trimmed.max(c.floor * dof(h));
        let mut set = c.set.clone();
        kept.clear();
        kept.extend(set.iter().map(|&i| self.all[i]));
        let mut sol = r_and_t(kept, Some(&pose_of(&c.q, &c.s)), o).ok()?;
        let mut gate = start_gate(trimmed, h, n, o);
        for _ in 0..5 {
            let (fq, fs) = unknowns_of(&sol.pose);
            if !self.standardised_errors(&fq, &fs, &set) {
                break;
            }
            let next: Vec<usize> = (0..n).filter(|&i| self.errors[i] <= gate).collect();
            // Fewer lines than the concentration kept would let a set fit itself (3 lines always
            // do): the caller's ε promised at least h inliers.
            if next.len() < smallest_set || next == set {
                break;
            }
            kept.clear();
            kept.extend(next.iter().map(|&i| self.all[i]));
            let Ok(fitted) = r_and_t(kept, Some(&sol.pose), o) else {
                break;
            };
            let (nq, ns) = unknowns_of(&fitted.pose);
            let sum: f64 = next
                .iter()
                .map(|&i| line_error_of(&self.all[i], &nq, &ns, o.error))
                .sum();
            let sigma2 = (sum / dof(next.len())).max(c.floor);
            gate = 2.0 * sigma2 * f2_quantile(tail, dof(next.len()));
            set = next;
            sol = fitted;
        }
        Some((sol, set))
    }

    /// Steps 3–4. The paper takes σ̂ from the least-median pose of one 3-line subset and keeps
    /// the lines within 2.5 σ̂. With noisy lines that pose is itself noisy, σ̂ from an order
    /// statistic is loose when many lines are outliers, and one wrong winner decides alone; we
    /// measured a few percent of failures at 50 % outliers from these alone. So:
    /// - the `POLISHED` best subset poses are concentrated on the h = rank + 1 lines that fit
    ///   them best (Rousseeuw & Van Driessen's FAST-LTS);
    /// - each is reweighted ([`Search::reweight`]): a line is kept when its error, as an
    ///   F(2, dof) statistic against the fit's own σ̂², is below the quantile that
    ///   `lms_outlier_threshold` (t σ per end point) picks in the large-sample limit, tail
    ///   e^(−t²); with few lines σ̂ is itself uncertain and the F quantile widens the gate rather
    ///   than throwing good lines away;
    /// - the winner has the highest likelihood over all lines: its set's errors as χ²₂ with its
    ///   σ̂², every other line an outlier with its error uniform over the error's range. A pose
    ///   that overfits h lines but explains no more loses to one that explains them all, and one
    ///   that takes in outliers pays for them in σ̂;
    /// - the winner's most doubtful fitted lines are taken out in turn and the rest refitted and
    ///   reweighted, while that finds a likelier fit: two outliers can hold a wrong pose between
    ///   them, each hiding the other from the leverage test.
    fn finish(mut self) -> Result<Solution, SolveError> {
        let o = self.o;
        let n = self.all.len();
        let h = self.rank() + 1;
        let mut order = Vec::with_capacity(n);
        let mut kept: Vec<Correspondence> = Vec::with_capacity(n);
        let mut concentrated: Vec<Concentrated> = Vec::with_capacity(POLISHED);
        for start in self.top.into_iter().flatten() {
            let (trimmed, q, s) = self.concentrate(start, h, &mut order, &mut kept);
            // A floor on σ̂ so that rounding-level residuals of noise-free data are not told apart.
            let unit = match o.error {
                LineError::E1 => mean_distance(self.all, &q, &s),
                LineError::E2 | LineError::E3 => 1.0,
            };
            concentrated.push(Concentrated {
                trimmed,
                q,
                s,
                set: order.clone(),
                unit,
                floor: (1e-9 * unit).powi(2),
            });
        }
        concentrated.sort_by(|a, b| a.trimmed.total_cmp(&b.trimmed));
        let mut fits = Vec::with_capacity(concentrated.len());
        for (k, c) in concentrated.iter().enumerate() {
            // Candidates often concentrate onto the same lines: one reweighting each.
            if concentrated[..k].iter().any(|d| d.set == c.set) {
                continue;
            }
            if let Some(fit) = self.reweight(c, &mut kept) {
                fits.push(fit);
            }
        }
        // The errors' range, for the density of an outlier's error: E2 and E3 are sums of two
        // squared sines (at most 2); E1 is E2 times a squared distance.
        let unit = concentrated.first().map_or(1.0, |c| c.unit);
        let floor = concentrated.first().map_or(0.0, |c| c.floor);
        let model = Likelihood {
            all: self.all,
            error: o.error,
            log_range: (2.0 * unit * unit).ln(),
            floor,
        };
        let mut best = fits
            .into_iter()
            .map(|f| (model.of(&f), f))
            .max_by(|a, b| a.0.total_cmp(&b.0))
            .ok_or(SolveError::NoSolution)?;
        // Two outliers can hold a pose between them that the inliers still fit within the gate,
        // each hiding the other from the leverage test (at 5 px, 50 % outliers: 2 trials in
        // 500). So the winner's most doubtful lines are each taken out in turn, the rest
        // refitted and reweighted; a fit with a higher likelihood replaces it.
        for _ in 0..DOUBT_ROUNDS {
            let (q, s) = unknowns_of(&best.1 .0.pose);
            if !self.standardised_errors(&q, &s, &best.1 .1) {
                break;
            }
            let mut improved = false;
            {
                // Only lines more extreme than the largest of m inliers' errors is, half the
                // time: for Exp(1) statistics, e / 2σ̂² > ln 2m.
                let set = &best.1 .1;
                let (q, s) = unknowns_of(&best.1 .0.pose);
                let raw: f64 = set.iter().map(|&i| line_error_of(&self.all[i], &q, &s, o.error)).sum();
                let sigma2 = (raw / dof(set.len())).max(floor);
                let notable = 2.0 * sigma2 * (2.0 * set.len() as f64).ln();
                let mut doubtful: Vec<usize> = set.iter().copied().filter(|&i| self.errors[i] > notable).collect();
                doubtful.sort_by(|&a, &b| self.errors[b].total_cmp(&self.errors[a]));
                doubtful.truncate(DOUBTFUL);
                let start = best.1 .0.pose;
                let set = best.1 .1.clone();
                for drop in doubtful {
                    let reduced: Vec<usize> = set.iter().copied().filter(|&i| i != drop).collect();
                    if reduced.len() < h {
                        break;
                    }
                    kept.clear();
                    kept.extend(reduced.iter().map(|&i| self.all[i]));
                    let Ok(fit) = r_and_t(&kept, Some(&start), o) else {
                        continue;
                    };
                    let (q, s) = unknowns_of(&fit.pose);
                    let trimmed = reduced
                        .iter()
                        .map(|&i| line_error_of(&self.all[i], &q, &s, o.error))
                        .sum();
                    let candidate = Concentrated {
                        trimmed,
                        q,
                        s,
                        set: reduced,
                        unit,
                        floor,
                    };
                    if let Some(f) = self.reweight(&candidate, &mut kept) {
                        let score = model.of(&f);
                        if score > best.0 {
                            best = (score, f);
                            improved = true;
                        }
                    }
                }
            }
            if !improved {
                break;
            }
        }
        let (_, (mut sol, set)) = best;
        sol.inliers = set;
        Ok(sol)
    }
}

/// How many of the winner's most doubtful lines are each tried without, and how many times
/// that search repeats while it finds a better fit.
const DOUBTFUL: usize = 3;
const DOUBT_ROUNDS: usize = 3;

/// The log-likelihood that picks among candidate fits: the fitted lines' errors as χ²₂ at the
/// fit's own σ̂², every other line an outlier with its error uniform over the error's range.
struct Likelihood<'a> {
    all: &'a [Correspondence],
    error: LineError,
    log_range: f64,
    floor: f64,
}

impl Likelihood<'_> {
    fn of(&self, (sol, set): &(Solution, Vec<usize>)) -> f64 {
        let (q, s) = unknowns_of(&sol.pose);
        let errors = set.iter().map(|&i| ranked_error(&self.all[i], &q, &s, self.error));
        let sigma2 = (errors.clone().sum::<f64>() / dof(set.len())).max(self.floor);
        let inliers: f64 = errors.map(|e| -(2.0 * sigma2).ln() - e / (2.0 * sigma2)).sum();
        let log_likelihood = inliers - (self.all.len() - set.len()) as f64 * self.log_range;
        if log_likelihood.is_nan() {
            f64::NEG_INFINITY
        } else {
            log_likelihood
        }
    }
}

/// A candidate after concentration: its trimmed sum, pose (`T_rig_world`), h-set and σ̂² floor.
struct Concentrated {
    trimmed: f64,
    q: UnitQuaternion<f64>,
    s: Vector3<f64>,
    set: Vec<usize>,
    /// The unit of a line error's square root: 1 for the angular errors E2 and E3, the mean
    /// distance for E1.
    unit: f64,
    floor: f64,
}

/// Degrees of freedom of a fit to `m` lines: two residuals each, six unknowns (at least 1).
fn dof(m: usize) -> f64 {
    (2 * m).saturating_sub(6).max(1) as f64
}

/// How many of `n` lines the caller's outlier fraction leaves as inliers (at least `h`).
fn expected_inliers(n: usize, h: usize, o: &SolverOptions) -> f64 {
    ((1.0 - o.lms_outlier_fraction.clamp(0.0, 0.95)) * n as f64).max(h as f64)
}

/// The F(2, dof) tail probability of the inlier gate: the one at which, with σ known, the gate is
/// `lms_outlier_threshold` σ per end point (χ²₂ / 2 ~ Exp(1), so the tail is e^(−t²)).
fn gate_tail(o: &SolverOptions) -> f64 {
    (-o.lms_outlier_threshold.powi(2)).exp()
}

/// The first inlier gate on a line's error, from the trimmed sum of the `h` best-fitting of `n`
/// lines: σ̂² over their degrees of freedom, made consistent for the truncation the caller's
/// outlier fraction implies, times the F(2, dof) quantile.
fn start_gate(trimmed: f64, h: usize, n: usize, o: &SolverOptions) -> f64 {
    let sigma2 = trimmed / dof(h) * truncation_consistency(h as f64 / expected_inliers(n, h, o));
    2.0 * sigma2 * f2_quantile(gate_tail(o), dof(h))
}

/// 1 / E[X | X below its p-quantile] for X = χ²₂ / 2 ~ Exp(1): the factor that makes a variance
/// estimated from the fraction `p` of smallest squared errors consistent (LTS's consistency
/// factor, for two residuals per line). 1 at p = 1.
fn truncation_consistency(p: f64) -> f64 {
    if p >= 1.0 {
        return 1.0;
    }
    let p = p.max(1e-3);
    let x = -(1.0 - p).ln();
    1.0 / (1.0 - x * (1.0 - p) / p)
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
