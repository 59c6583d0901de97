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

use super::horn::rotation_samples;
use super::{covariance::covariance, LineError, Solution, SolveError, SolverOptions};
use nalgebra::{Isometry3, Matrix3, Matrix6, Translation3, UnitQuaternion, Vector3, Vector6};
use omnitrack_core::geometry::{xi, Correspondence, Pose};

/// Smallest ratio of a Cholesky pivot to its diagonal entry (1 − R² of that unknown regressed on
/// the earlier ones) before the normal equations count as singular (§3.1: "incremental adjustments
/// cannot be computed if the six-by-six coefficient matrix becomes singular").
const SINGULAR_PIVOT_RATIO: f64 = 1e-12;

/// The two residuals of one line under one of KH's line errors, with their Jacobians with
/// respect to `(Δs, δω)` and the weights they carry in the sum of squares.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LineResiduals {
    /// E1: `n · (Q P + s − c)` per end point (m). E2: the same (the weight divides by the
    /// distance²). E3: `r_j · m`, the image end-point ray against the predicted plane's normal.
    pub r: [f64; 2],
    /// `∂r/∂(Δs, δω)` for the update `Q ← exp(δω) Q`, `s ← s + Δs` (E2's distance held fixed).
    pub jacobian: [Vector6<f64>; 2],
    /// 1 for E1 and E3, `1 / |Q P + s − c|²` for E2 (held fixed within an iteration).
    pub weight: [f64; 2],
}

/// The residuals of `c` at `T_rig_world = (q, s)` under `error`, or `None` for E3 when the
/// predicted plane is undefined (the transformed segment points at the sensor centre).
#[inline]
pub fn line_residuals(
    c: &Correspondence,
    q: &UnitQuaternion<f64>,
    s: &Vector3<f64>,
    error: LineError,
) -> Option<LineResiduals> {
    let n = c.edge.normal.into_inner();
    let centre = c.edge.centre.coords;
    let a1 = q * c.segment[0].coords;
    let a2 = q * c.segment[1].coords;
    match error {
        LineError::E1 | LineError::E2 => {
            let x1 = a1 + s - centre;
            let x2 = a2 + s - centre;
            let weight = match error {
                LineError::E2 => [1.0 / x1.norm_squared(), 1.0 / x2.norm_squared()],
                _ => [1.0, 1.0],
            };
            Some(LineResiduals {
                r: [n.dot(&x1), n.dot(&x2)],
                jacobian: [stack(&n, &a1.cross(&n)), stack(&n, &a2.cross(&n))],
                weight,
            })
        }
        LineError::E3 => {
            // Predicted plane through the centre and both transformed end points: normal
            // m = u / |u|, u = A × B. Its change: du = (A − B) × Δs + ([B]×[a']× − [A]×[b']×) δω,
            // dm = (I − m mᵀ) du / |u|; for the residual e · m the row is g = (I − m mᵀ) e / |u|
            // against du, i.e. ∂/∂Δs = g × (A − B), ∂/∂δω = (g × B) × a' − (g × A) × b'.
            let big_a = a1 + s - centre;
            let big_b = a2 + s - centre;
            let u = big_a.cross(&big_b);
            let len = u.norm();
            let spans_a_plane = len > 1e-12 * big_a.norm() * big_b.norm();
            if !spans_a_plane {
                return None;
            }
            let m = u / len;
            let row = |e: &Vector3<f64>| {
                let g = (e - m * m.dot(e)) / len;
                stack(
                    &g.cross(&(big_a - big_b)),
                    &(g.cross(&big_b).cross(&a1) - g.cross(&big_a).cross(&a2)),
                )
            };
            let (e1, e2) = (c.edge.ends[0].into_inner(), c.edge.ends[1].into_inner());
            Some(LineResiduals {
                r: [e1.dot(&m), e2.dot(&m)],
                jacobian: [row(&e1), row(&e2)],
                weight: [1.0, 1.0],
            })
        }
    }
}

#[inline]
fn stack(a: &Vector3<f64>, b: &Vector3<f64>) -> Vector6<f64> {
    Vector6::new(a.x, a.y, a.z, b.x, b.y, b.z)
}

/// Adds one line's rows to the normal equations (`h` = [C F; Fᵀ D], `g` = [c̄; d̄]) and returns its
/// share of the objective. An E3 line whose predicted plane is undefined adds its worst value (1
/// per end) and no rows.
#[inline]
pub(crate) fn accumulate_line(
    c: &Correspondence,
    q: &UnitQuaternion<f64>,
    s: &Vector3<f64>,
    error: LineError,
    h: &mut Matrix6<f64>,
    g: &mut Vector6<f64>,
) -> f64 {
    accumulate_line_scaled(c, q, s, error, 1.0, h, g)
}

/// [`accumulate_line`] with the line's rows (and its share of the objective) scaled by `scale`:
/// a weighted least-squares step.
#[inline]
pub(crate) fn accumulate_line_scaled(
    c: &Correspondence,
    q: &UnitQuaternion<f64>,
    s: &Vector3<f64>,
    error: LineError,
    scale: f64,
    h: &mut Matrix6<f64>,
    g: &mut Vector6<f64>,
) -> f64 {
    match line_residuals(c, q, s, error) {
        Some(res) => {
            let mut e = 0.0;
            for k in 0..2 {
                let (r, j, w) = (res.r[k], &res.jacobian[k], scale * res.weight[k]);
                h.ger(w, j, j, 1.0);
                g.axpy(w * r, j, 1.0);
                e += w * r * r;
            }
            e
        }
        None => 2.0 * scale,
    }
}

/// The objective of `error` over `c` at `(q, s)` (no normal equations).
pub(crate) fn line_error(c: &[Correspondence], q: &UnitQuaternion<f64>, s: &Vector3<f64>, error: LineError) -> f64 {
    c.iter().map(|l| line_error_of(l, q, s, error)).sum()
}

/// One line's share of the objective (both end points): [`line_residuals`]' weighted squares,
/// without the Jacobians. Med_R_and_T ranks every line at every subset pose with this, where
/// E3's Jacobian rows would be most of the cost.
#[inline]
pub(crate) fn line_error_of(c: &Correspondence, q: &UnitQuaternion<f64>, s: &Vector3<f64>, error: LineError) -> f64 {
    let centre = c.edge.centre.coords;
    let x1 = q * c.segment[0].coords + s - centre;
    let x2 = q * c.segment[1].coords + s - centre;
    match error {
        LineError::E1 | LineError::E2 => {
            let n = c.edge.normal.into_inner();
            let (r1, r2) = (n.dot(&x1), n.dot(&x2));
            match error {
                LineError::E2 => r1 * r1 / x1.norm_squared() + r2 * r2 / x2.norm_squared(),
                _ => r1 * r1 + r2 * r2,
            }
        }
        LineError::E3 => {
            let u = x1.cross(&x2);
            let len2 = u.norm_squared();
            // The plane test of `line_residuals`, squared; a NaN fails it as there.
            let spans_a_plane = len2 > 1e-24 * x1.norm_squared() * x2.norm_squared();
            if !spans_a_plane {
                return 2.0;
            }
            let (r1, r2) = (c.edge.ends[0].dot(&u), c.edge.ends[1].dot(&u));
            (r1 * r1 + r2 * r2) / len2
        }
    }
}

/// Result of one linearised refinement.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Refined {
    pub q: UnitQuaternion<f64>,
    pub s: Vector3<f64>,
    pub iterations: u32,
    pub converged: bool,
}

/// Whether a Cholesky factor's diagonal entry `l_ii` leaves its unknown determined: L_ii² is the
/// Schur-complement pivot, what unknown i adds beyond the earlier ones (false for NaN).
#[inline]
fn pivot_ok(l_ii: f64, h_ii: f64) -> bool {
    l_ii * l_ii > SINGULAR_PIVOT_RATIO * h_ii
}

/// Solves the 6×6 normal equations `h x = −g` by Cholesky, refusing a (numerically) singular `h`.
#[inline]
pub(crate) fn solve6(h: &Matrix6<f64>, g: &Vector6<f64>) -> Option<Vector6<f64>> {
    let chol = h.cholesky()?;
    let l = chol.l_dirty();
    for i in 0..6 {
        if !pivot_ok(l[(i, i)], h[(i, i)]) {
            return None;
        }
    }
    let x = chol.solve(&-g);
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// KH §3.1 steps 2–4 for any residual set: `accumulate(q, s, h, g)` fills the normal equations at
/// `(q, s)`. Stops when the step (|δω| in rad, |Δs| / `scale` as its rad-equivalent) drops below
/// `o.convergence_rad` or after `o.max_iterations` steps.
#[inline]
pub(crate) fn iterate<F>(
    mut q: UnitQuaternion<f64>,
    mut s: Vector3<f64>,
    scale: f64,
    max_iterations: u32,
    convergence_rad: f64,
    mut accumulate: F,
) -> Result<Refined, SolveError>
where
    F: FnMut(&UnitQuaternion<f64>, &Vector3<f64>, &mut Matrix6<f64>, &mut Vector6<f64>),
{
    let mut iterations = 0;
    let mut converged = false;
    while iterations < max_iterations {
        let mut h = Matrix6::zeros();
        let mut g = Vector6::zeros();
        accumulate(&q, &s, &mut h, &mut g);
        let x = solve6(&h, &g).ok_or(SolveError::Degenerate)?;
        let ds = Vector3::new(x[0], x[1], x[2]);
        let dw = Vector3::new(x[3], x[4], x[5]);
        // Step 3: compose δω as a quaternion (so Q stays a rotation), add Δs.
        q = UnitQuaternion::from_scaled_axis(dw) * q;
        s += ds;
        iterations += 1;
        if dw.norm().max(ds.norm() / scale) < convergence_rad {
            converged = true;
            break;
        }
    }
    if !(q.coords.iter().all(|v| v.is_finite()) && s.iter().all(|v| v.is_finite())) {
        return Err(SolveError::NoSolution);
    }
    Ok(Refined {
        q,
        s,
        iterations,
        converged,
    })
}

/// Mean distance of the segment end points from their sensor centres at `(q, s)`: the lever arm
/// that turns a translation step into its rad-equivalent.
pub(crate) fn mean_distance(c: &[Correspondence], q: &UnitQuaternion<f64>, s: &Vector3<f64>) -> f64 {
    let sum: f64 = c
        .iter()
        .map(|l| {
            l.segment
                .iter()
                .map(|p| (q * p.coords + s - l.edge.centre.coords).norm())
                .sum::<f64>()
        })
        .sum();
    let d = sum / (2 * c.len()).max(1) as f64;
    if d.is_finite() && d > 1e-9 {
        d
    } else {
        1.0
    }
}

/// Whether every number of every correspondence is finite (solvers refuse the rest).
pub(crate) fn all_finite(c: &[Correspondence]) -> bool {
    c.iter().all(|l| {
        let e = &l.edge;
        e.normal.iter().all(|v| v.is_finite())
            && e.centre.iter().all(|v| v.is_finite())
            && e.ends.iter().all(|r| r.iter().all(|v| v.is_finite()))
            && l.segment.iter().all(|p| p.iter().all(|v| v.is_finite()))
    })
}

/// `T_rig_world` of a `T_world_rig`.
#[inline]
pub(crate) fn unknowns_of(t_world_rig: &Pose) -> Unknowns {
    let inv = t_world_rig.inverse();
    (inv.rotation, inv.translation.vector)
}

/// `T_world_rig` of the unknowns `T_rig_world = (q, s)`.
#[inline]
pub(crate) fn pose_of(q: &UnitQuaternion<f64>, s: &Vector3<f64>) -> Pose {
    Isometry3::from_parts(Translation3::from(*s), *q).inverse()
}

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

/// The unknowns `T_rig_world = (Q, s)`.
pub(crate) type Unknowns = (UnitQuaternion<f64>, Vector3<f64>);

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

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;
    use omnitrack_core::geometry::EdgePlane;
    use rand::rngs::SmallRng;
    use rand::{Rng, SeedableRng};

    /// The ranking shortcut must be the refinement's objective: the weighted squares of
    /// [`line_residuals`], for every error, including lines that point at the centre.
    #[test]
    fn line_error_of_is_the_residuals_weighted_squares() {
        let mut rng = SmallRng::seed_from_u64(7);
        let v = |rng: &mut SmallRng, r: f64| Vector3::from_fn(|_, _| rng.random_range(-r..r));
        for _ in 0..500 {
            let centre = Point3::from(v(&mut rng, 0.2));
            let edge = EdgePlane::from_rays(centre, &v(&mut rng, 1.0), &v(&mut rng, 1.0)).unwrap();
            let segment = [Point3::from(v(&mut rng, 5.0)), Point3::from(v(&mut rng, 5.0))];
            let c = Correspondence { edge, segment };
            let q = UnitQuaternion::from_scaled_axis(v(&mut rng, 3.0));
            let s = v(&mut rng, 2.0);
            for e in [LineError::E1, LineError::E2, LineError::E3] {
                let full = match line_residuals(&c, &q, &s, e) {
                    Some(r) => (0..2).map(|k| r.weight[k] * r.r[k] * r.r[k]).sum(),
                    None => 2.0,
                };
                let fast = line_error_of(&c, &q, &s, e);
                assert!((full - fast).abs() <= 1e-12 * (1.0 + full), "{e:?}: {full} vs {fast}");
            }
        }
        // A segment through the centre spans no plane: E3's worst value, as in the refinement.
        let edge = EdgePlane::from_rays(Point3::origin(), &Vector3::x(), &Vector3::y()).unwrap();
        let (q, s) = (UnitQuaternion::identity(), Vector3::zeros());
        let through = Correspondence {
            edge,
            segment: [Point3::new(1.0, 1.0, 1.0), Point3::new(2.0, 2.0, 2.0)],
        };
        assert!(line_residuals(&through, &q, &s, LineError::E3).is_none());
        assert_eq!(line_error_of(&through, &q, &s, LineError::E3), 2.0);
    }
}
