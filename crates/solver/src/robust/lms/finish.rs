//! Steps (3)–(4) of the parent module, where we go past the paper: the few best poses of the
//! subsets concentrated (FAST-LTS C-steps), their lines re-judged with an F-test from the fit's
//! own σ̂ (never below the sensor's pixel), refitted until stable, the most likely candidate
//! kept, and its lines fitted last by Cauchy's loss at their own robust scale, with the
//! covariance of that fit at the noise its lines show.
//!
//! In: the subset search's best poses ([`Search`](super::Search)). Out: the [`Solution`] with
//! its inliers.

use super::*;
use crate::refine::cauchy::CAUCHY_C;
use crate::refine::covariance::covariance;
use crate::refine::kumar_hanson::r_and_t_refine_weighted;
use omnitrack_core::geometry::xi;

/// How many of the winner's most doubtful lines are each tried without, and how many times
/// that search repeats while it finds a better fit.
const DOUBTFUL: usize = 3;

const DOUBT_ROUNDS: usize = 3;

/// Reweighting rounds of the final Cauchy fit at most; each is a weighted R_and_T to convergence.
const FINAL_ROUNDS: u32 = 8;
/// A round of the final fit that turns the pose less than this (rad), and moves it less than
/// this times the lines' mean distance, ends it.
const FINAL_SETTLED: f64 = 1e-9;

/// The σ² of a line error's two residuals from the median of the errors: a line's error over σ²
/// is χ²₂, whose median is 2 ln 2 (so this is the MAD's consistency for two residuals a line).
fn sigma2_from_median(median: f64) -> f64 {
    median / (2.0 * std::f64::consts::LN_2)
}

/// The floor under σ̂² (in the units of the line error, `unit` its square root's): the sensor's
/// pixel, or a rounding-level 1e-9 when the caller did not give the pixel.
pub(super) fn sigma2_floor(o: &SolverOptions, unit: f64) -> f64 {
    (o.pixel_rad.max(1e-9) * unit).powi(2)
}

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
pub(super) fn truncation_consistency(p: f64) -> f64 {
    if p >= 1.0 {
        return 1.0;
    }
    let p = p.max(1e-3);
    let x = -(1.0 - p).ln();
    1.0 / (1.0 - x * (1.0 - p) / p)
}

impl Search<'_> {
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
    pub(super) fn standardised_errors(&mut self, q: &UnitQuaternion<f64>, s: &Vector3<f64>, set: &[usize]) -> bool {
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
    pub(super) fn finish(mut self) -> Result<Solution, SolveError> {
        let o = self.o;
        let n = self.all.len();
        let h = self.rank() + 1;
        let mut order = Vec::with_capacity(n);
        let mut kept: Vec<Correspondence> = Vec::with_capacity(n);
        let mut concentrated: Vec<Concentrated> = Vec::with_capacity(POLISHED);
        for start in self.top.into_iter().flatten() {
            let (trimmed, q, s) = self.concentrate(start, h, &mut order, &mut kept);
            // A floor on σ̂: the sensor's pixel, so that a line a pixel or two off is not cut
            // because most lines fit to a fraction of one (real line errors have heavier tails
            // than a Gaussian of the bulk's σ̂); without the pixel, so that rounding-level
            // residuals of noise-free data are not told apart.
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
                floor: sigma2_floor(o, unit),
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
        kept.clear();
        kept.extend(set.iter().map(|&i| self.all[i]));
        if let Some(fit) = final_fit(&kept, &sol.pose, o, unit) {
            sol = fit;
        }
        sol.inliers = set;
        Ok(sol)
    }
}

/// The last fit of the kept lines: R_and_T under Cauchy's loss (iteratively reweighted) at the
/// scale c = [`CAUCHY_C`] σ̂, σ̂ from the median of the lines' errors, with the §5 covariance at
/// the noise these lines show. `None` if a weighted R_and_T fails (the caller keeps its
/// least-squares fit).
///
/// Why a loss and not least squares: the gate keeps lines up to a few σ̂ (or pixels) off, and
/// real line errors have heavier tails than a Gaussian, so under least squares the few lines two
/// or three σ̂ off pull with their whole squared error. A narrower gate throws them away (the
/// 2.5 σ̂ gate without the pixel floor kept 83–94 % of the Oxford VGG lines, and the floored
/// gate with least squares was less precise still); Cauchy's weights 1 / (1 + (r / c)²) keep
/// them and lower their pull, at 95 % of least squares' efficiency when the errors are Gaussian
/// after all. The scale is the lines' own robust σ̂, not the gate's floored one: the floor says
/// which lines may be outliers, the data how far a good line usually is.
///
/// Why not the configured `edge_sigma_rad` for the covariance: that is a model of the tracker's
/// edges, and on real hand-matched lines it predicted fifteen times the observed spread. Here σ
/// is the noise of these very lines, as an M-estimator's variance has it (Huber 1981, §7.6): the
/// mean of ψ² over the residuals' degrees of freedom, divided by the square of ψ′'s mean, which
/// makes a loss that down-weights the tails pay for it in spread.
fn final_fit(kept: &[Correspondence], start: &Pose, o: &SolverOptions, unit: f64) -> Option<Solution> {
    let m = kept.len();
    if m < 4 {
        return None;
    }
    let numerical_floor = (1e-9 * unit).powi(2);
    let (q0, s0) = unknowns_of(start);
    let distance = mean_distance(kept, &q0, &s0);
    let mut pose = *start;
    let mut errors = vec![0.0; m];
    let mut weights = vec![1.0; m];
    let mut sorted = vec![0.0; m];
    let (mut rounds, mut converged, mut c2) = (0, false, numerical_floor);
    while rounds < FINAL_ROUNDS {
        let (q, s) = unknowns_of(&pose);
        for (e, l) in errors.iter_mut().zip(kept) {
            *e = line_error_of(l, &q, &s, o.error);
        }
        sorted.copy_from_slice(&errors);
        let (_, median, _) = sorted.select_nth_unstable_by(m / 2, f64::total_cmp);
        c2 = CAUCHY_C * CAUCHY_C * sigma2_from_median(*median).max(numerical_floor);
        for (w, e) in weights.iter_mut().zip(&errors) {
            *w = cauchy_weight(*e, c2);
        }
        let next = r_and_t_refine_weighted(kept, &weights, &pose, o)?;
        rounds += 1;
        let turned = next.rotation.angle_to(&pose.rotation);
        let moved = (next.translation.vector - pose.translation.vector).norm() / distance;
        pose = next;
        if turned.max(moved) < FINAL_SETTLED {
            converged = true;
            break;
        }
    }
    let (q, s) = unknowns_of(&pose);
    let (mut sum_psi2, mut sum_slope) = (0.0, 0.0);
    for l in kept {
        let e = line_error_of(l, &q, &s, o.error);
        let w = cauchy_weight(e, c2);
        // ψ(r) = w r for each of the line's two residuals, ψ′(r) = w² (1 − r² / c²).
        sum_psi2 += w * w * e;
        sum_slope += w * w * (1.0 - 0.5 * e / c2);
    }
    let residuals = 2.0 * m as f64;
    let mean_slope = (sum_slope / m as f64).max(1e-3);
    let sigma2 = sum_psi2 / (residuals - 6.0) / (mean_slope * mean_slope);
    // E1's errors are distances; the covariance's σ is an angle of the edge's normal.
    let noise = SolverOptions {
        edge_sigma_rad: sigma2.max(numerical_floor).sqrt() / unit,
        ..o.clone()
    };
    Some(Solution {
        pose,
        covariance: covariance(kept, &pose, &noise),
        inliers: Vec::new(),
        xi_rad2: xi(kept, &pose),
        iterations: rounds,
        converged,
    })
}

/// Cauchy's weight of a line whose error (the sum of its two squared residuals) is `e`, at the
/// squared scale `c2`: that of its residuals' mean square, so both ends weigh alike.
fn cauchy_weight(e: f64, c2: f64) -> f64 {
    1.0 / (1.0 + 0.5 * e / c2)
}
