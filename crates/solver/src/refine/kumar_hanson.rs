//! Kumar & Hanson 1989 §2–§3: R_then_T and R_and_T for a generalised camera.
//!
//! In: [`Correspondence`]s (edge plane through its sensor's centre, rig frame ↔ world segment),
//! an optional guess `T_world_rig`, [`SolverOptions`]. Out: a [`Solution`] (pose, §5 covariance,
//! all indices as inliers, Koch–Teller ξ).
//!
//! The unknown is `T_rig_world = (Q, s)`. A segment end point P seen by a sensor centred at c has
//! the residual `n · (Q P + s − c)` (KH eq. 9 with the sensor offset). Both methods linearise
//! about the current (Q, s) with `Q ← exp(δω) Q`, `s ← s + Δs` (eq. 16: `p'' = p' + δω × p'`),
//! so every residual row has the Jacobian `[∂/∂Δs, ∂/∂δω]`; for E1 that is `[n, b]` with
//! `b = p' × n`, and the normal equations are eq. 21's `[C F; Fᵀ D] [Δs; δω] = −[c̄; d̄]`.
//!
//! Nothing in an iteration allocates: fixed-size nalgebra types only, so that Med_R_and_T can run
//! it thousands of times per frame.

use super::covariance::covariance;
use super::horn::rotation_samples;
use super::residuals::{
    accumulate_line, accumulate_line_scaled, all_finite, iterate, line_distance, line_error, mean_distance,
    mean_of_distances, pivot_ok, pose_of, unknowns_of, LineRows, Refined,
};
use crate::{LineError, Solution, SolveError, SolverOptions};
use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use omnitrack_core::geometry::{xi, Correspondence, Pose};
use omnitrack_core::memory::resident;

fn check_input(c: &[Correspondence], guess: Option<&Pose>) -> Result<(), SolveError> {
    if c.len() < 3 {
        return Err(SolveError::TooFew {
            needed: 3,
            got: c.len(),
        });
    }
    let guess_ok = guess.is_none_or(|p| {
        p.translation.vector.iter().all(|v| v.is_finite()) && p.rotation.coords.iter().all(|v| v.is_finite())
    });
    if !all_finite(c) || !guess_ok {
        return Err(SolveError::Degenerate);
    }
    Ok(())
}

/// Unit direction of a model segment (world frame); zero for a zero-length segment.
#[inline]
fn direction(c: &Correspondence) -> Vector3<f64> {
    (c.segment[1] - c.segment[0])
        .try_normalize(0.0)
        .unwrap_or_else(Vector3::zeros)
}

/// R_then_T's rotation stage: minimises E_R = Σ (n · Q d)² (eqs. 8, 13) by the same linearised
/// iteration (`n · (Qd + δω × Qd)`, row `Qd × n`), starting from `q`. Returns the rotation, the
/// iteration count and whether it converged; `None` if the 3×3 system is singular.
pub(crate) fn rotation_stage(
    c: &[Correspondence],
    mut q: UnitQuaternion<f64>,
    max_iterations: u32,
    convergence_rad: f64,
) -> Option<(UnitQuaternion<f64>, u32, bool)> {
    let mut iterations = 0;
    while iterations < max_iterations {
        let mut h = Matrix3::zeros();
        let mut g = Vector3::zeros();
        for l in c {
            let n = l.edge.normal.into_inner();
            let d = q * direction(l);
            let j = d.cross(&n);
            h.ger(1.0, &j, &j, 1.0);
            g.axpy(n.dot(&d), &j, 1.0);
        }
        let chol = h.cholesky()?;
        let l = chol.l_dirty();
        if (0..3).any(|i| !pivot_ok(l[(i, i)], h[(i, i)])) {
            return None;
        }
        let dw = chol.solve(&-g);
        if !dw.iter().all(|v| v.is_finite()) {
            return None;
        }
        q = UnitQuaternion::from_scaled_axis(dw) * q;
        iterations += 1;
        if dw.norm() < convergence_rad {
            return Some((q, iterations, true));
        }
    }
    Some((q, iterations, false))
}

/// R_then_T's translation stage: eq. 9 at both end points of every line, `n · s = −n · (Q P − c)`,
/// by linear least squares (E_T of eq. 13). `None` if the lines do not fix the translation.
pub(crate) fn translation_stage(c: &[Correspondence], q: &UnitQuaternion<f64>) -> Option<Vector3<f64>> {
    let mut h = Matrix3::zeros();
    let mut g = Vector3::zeros();
    for l in c {
        let n = l.edge.normal.into_inner();
        for p in &l.segment {
            h.ger(1.0, &n, &n, 1.0);
            g.axpy(n.dot(&(q * p.coords - l.edge.centre.coords)), &n, 1.0);
        }
    }
    let chol = h.cholesky()?;
    let l = chol.l_dirty();
    if (0..3).any(|i| !pivot_ok(l[(i, i)], h[(i, i)])) {
        return None;
    }
    let s = chol.solve(&-g);
    s.iter().all(|v| v.is_finite()).then_some(s)
}

/// One R_then_T run: rotation, translation, E1 there, and the rotation stage's iteration count and
/// convergence.
struct RThenT {
    q: UnitQuaternion<f64>,
    s: Vector3<f64>,
    e1: f64,
    iterations: u32,
    converged: bool,
}

/// R_then_T from one starting rotation: rotation stage, then translation; with its E1.
fn r_then_t_from(c: &[Correspondence], q0: UnitQuaternion<f64>, o: &SolverOptions) -> Option<RThenT> {
    r_then_t_to(c, q0, o.max_iterations, o.convergence_rad)
}

/// Starts for R_and_T need not be polished: R_and_T finishes them (and a start that is still
/// wandering after this many steps is rarely the one that wins).
const START_ITERATIONS: u32 = 15;
const START_CONVERGENCE_RAD: f64 = 1e-6;

fn r_then_t_to(
    c: &[Correspondence],
    q0: UnitQuaternion<f64>,
    max_iterations: u32,
    convergence_rad: f64,
) -> Option<RThenT> {
    let (q, iterations, converged) = rotation_stage(c, q0, max_iterations, convergence_rad)?;
    let s = translation_stage(c, &q)?;
    let e1 = line_error(c, &q, &s, LineError::E1);
    e1.is_finite().then_some(RThenT {
        q,
        s,
        e1,
        iterations,
        converged,
    })
}

/// Kumar–Hanson R_then_T: the rotation from eq. 8 (E_R, linearised iteration on δω composed as a
/// quaternion), then the translation from eq. 9 by linear least squares over both end points of
/// every line (with each sensor's centre). With a guess, the rotation starts from the guess's;
/// without one it starts from each of Horn's `o.initial_rotation_samples` rotations and keeps the
/// result with the lowest E1 after the translation stage (E_R alone cannot choose among the
/// rotations a few lines allow).
pub fn r_then_t(c: &[Correspondence], guess: Option<&Pose>, o: &SolverOptions) -> Result<Solution, SolveError> {
    check_input(c, guess)?;
    let best = match guess {
        Some(p) => r_then_t_from(c, unknowns_of(p).0, o),
        None => rotation_samples(o.initial_rotation_samples)
            .iter()
            .filter_map(|q0| r_then_t_from(c, *q0, o))
            .min_by(|a, b| a.e1.total_cmp(&b.e1)),
    };
    let r = best.ok_or(SolveError::Degenerate)?;
    Ok(solution(c, &r.q, &r.s, r.iterations, r.converged, o))
}

fn solution(
    c: &[Correspondence],
    q: &UnitQuaternion<f64>,
    s: &Vector3<f64>,
    iterations: u32,
    converged: bool,
    o: &SolverOptions,
) -> Solution {
    let pose = pose_of(q, s);
    Solution {
        pose,
        covariance: covariance(c, &pose, o),
        inliers: (0..c.len()).collect(),
        xi_rad2: xi(c, &pose),
        iterations,
        converged,
    }
}

/// R_and_T's iteration (§3.1) from `guess` over `c`: the pose only, without the covariance, ξ
/// or inlier list of [`r_and_t`], so that it allocates nothing (the tracker's sampling loop calls
/// it per sample). `None` if the normal equations are singular or the iteration diverges.
pub fn r_and_t_refine(c: &[Correspondence], guess: &Pose, o: &SolverOptions) -> Option<Pose> {
    if c.len() < 3 {
        return None;
    }
    let (q, s) = unknowns_of(guess);
    refine(c, q, s, o).ok().map(|r| pose_of(&r.q, &r.s))
}

/// [`r_and_t_refine`] for fits of many subsets of one set of lines from one start (the tracker's
/// consensus samples, every one from the predicted pose): each line's first step there (its rows
/// of the normal equations and its distance) is worked out once, in [`Self::prepare`], and a fit
/// adds its lines' instead of computing them again (its distances and the first of its few
/// iterations: 5 % of the tracker's frame path, docs/decisions.md). The answers are
/// `r_and_t_refine`'s bit for bit: the same numbers summed in the same order.
///
/// Sized at construction; nothing allocates afterwards.
#[derive(Debug, Clone)]
pub struct SharedStart {
    /// Per line of the prepared set: its rows at the start, and its [`line_distance`] there.
    lines: Vec<(LineRows, f64)>,
    /// The prepared start, its unknowns and the error the rows are of; `None` before a
    /// [`Self::prepare`] or after one whose set exceeded the capacity.
    start: Option<(Pose, UnitQuaternion<f64>, Vector3<f64>, LineError)>,
}

impl SharedStart {
    /// Room for sets of up to `capacity` lines.
    pub fn new(capacity: usize) -> Self {
        Self {
            lines: resident(vec![(LineRows::NONE, 0.0); capacity]),
            start: None,
        }
    }

    /// Works out every line of `c` at `start` under `error`. A set beyond the capacity prepares
    /// nothing, and [`Self::refine`] then computes every fit in full.
    pub fn prepare(&mut self, c: &[Correspondence], start: &Pose, error: LineError) {
        self.start = None;
        if c.len() > self.lines.len() {
            return;
        }
        let (q, s) = unknowns_of(start);
        for (slot, l) in self.lines.iter_mut().zip(c) {
            *slot = (LineRows::at(l, &q, &s, error), line_distance(l, &q, &s));
        }
        self.start = Some((*start, q, s, error));
    }

    /// [`r_and_t_refine`] of `c` from `guess`, where `c[k]` is line `lines[k]` of the set last
    /// prepared: from its rows when `guess` is (bit for bit) the prepared start and `o.error` its
    /// error, in full otherwise.
    pub fn refine(&self, c: &[Correspondence], lines: &[usize], guess: &Pose, o: &SolverOptions) -> Option<Pose> {
        let prepared = self
            .start
            .filter(|(start, _, _, error)| *error == o.error && lines.len() == c.len() && same_bits(start, guess));
        let Some((_, q, s, error)) = prepared else {
            return r_and_t_refine(c, guess, o);
        };
        if c.len() < 3 {
            return None;
        }
        let scale = mean_of_distances(lines.iter().map(|&i| self.lines[i].1).sum(), c.len());
        let mut first = true;
        iterate(q, s, scale, o.max_iterations, o.convergence_rad, |q, s, h, g| {
            if std::mem::take(&mut first) {
                for &i in lines {
                    self.lines[i].0.add_to(h, g);
                }
            } else {
                for l in c {
                    accumulate_line(l, q, s, error, h, g);
                }
            }
        })
        .ok()
        .map(|r| pose_of(&r.q, &r.s))
    }
}

/// Whether two poses are the same numbers (not merely equal: 0 and −0 differ).
fn same_bits(a: &Pose, b: &Pose) -> bool {
    let bits = |p: &Pose| {
        let (t, q) = (p.translation.vector, p.rotation.coords);
        [t.x, t.y, t.z, q.x, q.y, q.z, q.w].map(f64::to_bits)
    };
    bits(a) == bits(b)
}

/// R_and_T's iteration (§3.1) from `(q, s)` over `c` with `o.error`; no covariance, no ξ.
pub(crate) fn refine(
    c: &[Correspondence],
    q: UnitQuaternion<f64>,
    s: Vector3<f64>,
    o: &SolverOptions,
) -> Result<Refined, SolveError> {
    let scale = mean_distance(c, &q, &s);
    let error = o.error;
    iterate(q, s, scale, o.max_iterations, o.convergence_rad, |q, s, h, g| {
        for l in c {
            accumulate_line(l, q, s, error, h, g);
        }
    })
}

/// R_and_T's iteration (§3.1) from `guess` over `c`, line i's rows weighted by `w[i]` (weighted
/// least squares; `w` as long as `c`). `None` as [`r_and_t_refine`].
pub fn r_and_t_refine_weighted(c: &[Correspondence], w: &[f64], guess: &Pose, o: &SolverOptions) -> Option<Pose> {
    if c.len() < 3 || w.len() != c.len() {
        return None;
    }
    let (q, s) = unknowns_of(guess);
    let scale = mean_distance(c, &q, &s);
    let error = o.error;
    iterate(q, s, scale, o.max_iterations, o.convergence_rad, |q, s, h, g| {
        for (l, &wl) in c.iter().zip(w) {
            accumulate_line_scaled(l, q, s, error, wl, h, g);
        }
    })
    .ok()
    .map(|r| pose_of(&r.q, &r.s))
}

/// How many of the best distinct R_then_T starts R_and_T refines when there is no guess.
const NO_GUESS_REFINEMENTS: usize = 4;
/// Two R_then_T results closer than this (rad) are the same start.
const SAME_ROTATION_RAD: f64 = 1e-3;

/// §3.2 without a guess: R_then_T from each of Horn's samples (a coarse rotation stage: at most
/// 15 steps, to 1e-6 rad), then a short R_and_T from each of the best few distinct results (lowest
/// E1 first); the one with the lowest objective is refined to convergence.
pub(crate) fn no_guess(c: &[Correspondence], o: &SolverOptions) -> Result<Refined, SolveError> {
    // Fixed-capacity candidate table on the stack (Horn's largest set has 60 elements).
    let mut starts = [(f64::INFINITY, UnitQuaternion::identity(), Vector3::zeros()); 60];
    let mut count = 0;
    for q0 in rotation_samples(o.initial_rotation_samples) {
        let start = r_then_t_to(
            c,
            *q0,
            o.max_iterations.min(START_ITERATIONS),
            o.convergence_rad.max(START_CONVERGENCE_RAD),
        );
        if let Some(RThenT { q, s, e1: e, .. }) = start {
            if let Some(k) = starts[..count]
                .iter()
                .position(|x| x.1.angle_to(&q) < SAME_ROTATION_RAD)
            {
                if e < starts[k].0 {
                    starts[k] = (e, q, s);
                }
            } else if count < starts.len() {
                starts[count] = (e, q, s);
                count += 1;
            }
        }
    }
    let starts = &mut starts[..count];
    starts.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    // Each start gets a short R_and_T (it either settles within a few steps or is not the one);
    // the winner is then refined to `o.convergence_rad`.
    let coarse = SolverOptions {
        max_iterations: o.max_iterations.min(START_ITERATIONS),
        convergence_rad: o.convergence_rad.max(START_CONVERGENCE_RAD),
        ..o.clone()
    };
    let mut best: Option<(f64, Refined)> = None;
    for &(_, q, s) in starts.iter().take(NO_GUESS_REFINEMENTS) {
        if let Ok(r) = refine(c, q, s, &coarse) {
            let e = line_error(c, &r.q, &r.s, o.error);
            if e.is_finite() && best.as_ref().is_none_or(|b| e < b.0) {
                best = Some((e, r));
            }
        }
    }
    match best {
        Some((_, r)) => refine(c, r.q, r.s, o),
        None if count == 0 => Err(SolveError::Degenerate),
        None => Err(SolveError::NoSolution),
    }
}

/// Kumar–Hanson R_and_T (§3.1): rotation and translation together, minimising `o.error` (E1, E2
/// or E3) by linearising about `(Q, s)`, solving eq. 21's 6×6 system by Cholesky, composing δω
/// as a quaternion and adding Δs, until the step is below `o.convergence_rad` or after
/// `o.max_iterations`. Without a guess (§3.2): R_then_T from each of Horn's samples, then R_and_T
/// from the best distinct starts; the lowest objective wins.
///
/// Errors: fewer than 3 lines → `TooFew`; singular normal equations (e.g. all lines parallel) or
/// non-finite input → `Degenerate`; a diverged iteration → `NoSolution`.
pub fn r_and_t(c: &[Correspondence], guess: Option<&Pose>, o: &SolverOptions) -> Result<Solution, SolveError> {
    check_input(c, guess)?;
    let r = match guess {
        Some(p) => {
            let (q, s) = unknowns_of(p);
            refine(c, q, s, o)?
        }
        None => no_guess(c, o)?,
    };
    Ok(solution(c, &r.q, &r.s, r.iterations, r.converged, o))
}
