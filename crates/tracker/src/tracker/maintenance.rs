//! Maintenance: Koch–Teller §4.2, Figure 7, one frame at a time.
//!
//! In: S_t (the correspondence table with its held edges and hue signatures), the pose at t and
//! the motion prior, the edges of frame t+1. Out: the pose at t+1 with its covariance, S_{t+1}.
//!
//! 1. Prediction: constant velocity from the last two tracked poses (KT §6.2 suggests a motion
//!    model), or the pose at t.
//! 2. Fig. 7 lines 3–5: each pending or accepted correspondence looks for its edge in the new
//!    frame: the smallest α to the segment at the predicted pose within the angular gate (10°),
//!    hue distance to the held signature below the hue gate (0.03), and overlapping the segment.
//! 3. Lines 6–10: from the accepted ones (S̄_t), s_t samples of λ (eq. 2, capped by `max_samples`
//!    and the time budget) in the consensus sampler; each sample is fitted by R_and_T (or its
//!    upright form, or the ξ simplex when `solver.method = "xi"`) from the predicted pose and
//!    scored over the rest; the winner's inliers are refitted. The time budget is a backstop set
//!    well above what `max_samples` take: where the clock decided (at 15 ms it did on the hard
//!    frames), the same recording tracked with the same seed went right in one run and wrong in
//!    the next; where the count decides, runs repeat.
//! 4. Line 11: every correspondence is checked at the new pose — observed when an edge lies
//!    within the inlier angle (and the hue gate for a held signature) — and Figure 8 updates it.
//!    Checking at the solved pose (rather than at the prediction) means an unknown correspondence
//!    is only promoted by an edge the consensus pose agrees with.
//! 5. The final fit over the observed accepted correspondences, and its covariance (KH §5).
//!    The fit weighs the lines by Cauchy's loss (`solver::refine::cauchy`, `robust_final_fit`; beyond
//!    the papers) rather than least squares: lines a coarse model places a little wrong (trims,
//!    walls drawn a few centimetres off) sit inside the inlier angle and pulled the pose with
//!    their whole squared residual. Measured (docs/decisions.md, the robust final fit): `lab` 1.62 → 1.26 cm,
//!    `corridor` 0.99 → 0.78 cm, `handheld` 1.25 → 1.00 cm; on the realistic world the worst
//!    of six tracker seeds in `corridor` 28 → 9 cm, `lab` still cascading on some seeds.
//! 6. Lines 12–13: VIS(T_{t+1}) updates S_{t+1}.
//!
//! Step 3 scores samples by `maintenance.consensus_score` (the median α² by default,
//! `solver::robust::consensus`), and a relocalisation keeps the last interval's motion for the next
//! prediction (module `relocalise`, where a failed motion prior leads).
//!
//! Nothing here allocates: all buffers belong to the [`Tracker`].

use super::relocalise::turned;
use super::Tail;
use super::Tracker;
use crate::correspondence::{CorrespondenceState, HeldEdge};
use crate::matching::{best_edge_among, Gate, Predicted};
use crate::motion_filter::{distance2, Fused, GATE_CHI2_6};
use crate::report::{FrameResult, TrackerEvent, TrackerState};
use nalgebra::{Isometry3, Matrix6, Point3, Translation3, UnitQuaternion};
use omnitrack_config::SolverMethod;
use omnitrack_core::geometry::{xi, Correspondence, Pose};
use omnitrack_edges::Edge;
use omnitrack_solver::{minimise_xi, r_and_t_refine, refine_upright, sample_count, SamplingBudget, SimplexOptions};
use std::time::{Duration, Instant};

/// A relocalised pose replaces a suspect maintenance pose only when it explains this many times
/// as much of VIS(T).
const SUSPECT_MARGIN: f64 = 1.2;

/// The smallest consensus sample: four lines over-determine a pose (three fix it, KH §4).
const SMALLEST_SAMPLE: usize = 4;

/// R_and_T on a consensus sample (and the consensus's refit of the winner's inliers) stops once
/// an iteration moves the pose by less than this (rad, and m over the lines' mean distance);
/// every other fit runs to `solver.convergence_rad` (1e-10). A sample's pose is only ranked by
/// the median α² over the rest of the set, and the frame's pose is the final fit's, started
/// from the winner: 10⁻⁶ rad is a 26,000th of the 1.5° inlier angle, and the iterations
/// below it were a seventh of the frame path's CPU on `lab` (docs/decisions.md, 2026-11-30).
const SAMPLE_CONVERGENCE_RAD: f64 = 1e-6;

/// A solved pose this far (5 cm, or 0.035 rad ≈ 2°) from the constant-velocity prediction,
/// beyond what smooth motion leaves between them, is checked against the polished prediction.
const SECOND_OPINION_M: f64 = 0.05;
const SECOND_OPINION_RAD: f64 = 0.035;

/// The largest standard deviation of a pose covariance's position block (m).
fn largest_position_sigma(cov: &Matrix6<f64>) -> f64 {
    cov.fixed_view::<3, 3>(0, 0)
        .symmetric_eigenvalues()
        .max()
        .max(0.0)
        .sqrt()
}

/// Whether the motion filter takes a frame of fewer than `min_inliers` lines whose fit is
/// within the jump limits (`Tracker::maintain`, step 5): not while relocalised frames are on
/// probation, only while the prediction's largest position σ is within `max_jump_m`, and only
/// inside the filter's gate (`gate_d2`, the fit's squared Mahalanobis distance from the
/// prediction; `None` when it cannot be formed).
fn filter_takes_few_lines(on_probation: bool, predicted_sigma_m: f64, max_jump_m: f64, gate_d2: Option<f64>) -> bool {
    !on_probation && predicted_sigma_m <= max_jump_m && gate_d2.is_some_and(|d2| d2 <= GATE_CHI2_6)
}

/// The pose and S_t the next frame will be predicted from.
fn constant_velocity(previous: &Pose, previous_t: u64, current: &Pose, current_t: u64, next_t: u64) -> Pose {
    let dt_prev = current_t.saturating_sub(previous_t) as f64;
    let dt = next_t.saturating_sub(current_t) as f64;
    if dt_prev <= 0.0 || dt <= 0.0 {
        return *current;
    }
    let f = (dt / dt_prev).min(3.0);
    // The motion from `previous` to `current` in the rig frame, scaled to the coming interval.
    let delta = previous.inverse() * current;
    let rot = UnitQuaternion::from_scaled_axis(delta.rotation.scaled_axis() * f);
    let step = Isometry3::from_parts(Translation3::from(delta.translation.vector * f), rot);
    current * step
}

/// Refits `c` from `start` with the configured solver.
fn fit(
    tracker_upright: bool,
    method: SolverMethod,
    o: &omnitrack_solver::SolverOptions,
    c: &[Correspondence],
    start: &Pose,
) -> Option<Pose> {
    if tracker_upright {
        return refine_upright(c, start, o);
    }
    match method {
        SolverMethod::Xi => {
            let opts = SimplexOptions {
                max_iterations: 400,
                restarts: 0,
                ..SimplexOptions::default()
            };
            Some(minimise_xi(c, start, &opts).0)
        }
        _ => r_and_t_refine(c, start, o),
    }
}

impl Tracker<'_> {
    /// Fig. 7 lines 3–10 from the prediction `predicted`: the correspondence update (angular and
    /// hue gates) and the robust pose of S̄. Returns the pose and the samples drawn.
    fn match_and_solve(&mut self, edges: &[Edge], predicted: &Pose) -> (Option<Pose>, u64, Duration) {
        let started = Instant::now();
        let mcfg = self.cfg.maintenance.clone();
        let upright = self.cfg.motion.upright;
        let method = self.cfg.solver.method;
        let inlier_rad = mcfg.inlier_angle_deg.to_radians();
        let min_len = self.cfg.edges.min_edge_length_deg.to_radians();
        // 2. Correspondence update at the prediction.
        let gate_cos = mcfg.angular_gate_deg.to_radians().cos();
        let hue_gate = mcfg.hue_gate as f32;
        let n_tracks = self.tracks.tracks().len();
        self.set.clear();
        self.set_track.clear();
        let mut pending_matches = 0;
        for i in 0..n_tracks {
            self.matched[i] = None;
            let t = self.tracks.tracks()[i];
            let Some(held) = t.edge else { continue };
            let seg = &self.model.segments[t.segment as usize];
            let ends = [seg.a, seg.b];
            let pred = Predicted::new(&ends, predicted, &self.centres);
            if pred.length_rad < min_len {
                continue;
            }
            let gate = Gate {
                cos_alpha: gate_cos,
                min_overlap: 0.5,
                hue: Some((held.hue, hue_gate)),
                polarity: held.bright_normal(),
            };
            if let Some((e, a)) = best_edge_among(&pred, &self.centres, edges, &self.edge_normals, &gate) {
                self.matched[i] = Some((e as u32, a));
                if t.state == CorrespondenceState::Accepted {
                    self.set.push(Correspondence {
                        edge: edges[e].plane,
                        segment: ends,
                    });
                    self.set_track.push(i);
                } else {
                    pending_matches += 1;
                }
            }
        }
        // Too few accepted (e.g. soon after a commit far from where S_0 was seen): the pending
        // matches join, still to be checked by the consensus.
        if self.set.len() < mcfg.min_inliers as usize && pending_matches > 0 {
            for i in 0..n_tracks {
                let t = self.tracks.tracks()[i];
                if t.state != CorrespondenceState::Pending {
                    continue;
                }
                if let Some((e, _)) = self.matched[i] {
                    let seg = &self.model.segments[t.segment as usize];
                    self.set.push(Correspondence {
                        edge: edges[e as usize].plane,
                        segment: [seg.a, seg.b],
                    });
                    self.set_track.push(i);
                }
            }
        }
        let match_time = started.elapsed();
        // 3. Robust pose from S̄.
        // λ, or half the set when that is smaller (never below SMALLEST_SAMPLE): a sample of λ
        // from a set of λ + 2 leaves at most two correspondences out, so a narrow view that holds
        // ten would never leave its one wrong match out of any sample.
        let lambda = self
            .sampler
            .lambda()
            .min(self.set.len() / 2)
            .max(SMALLEST_SAMPLE.min(self.sampler.lambda()));
        let mut samples = 0;
        let solved: Option<Pose> = if self.set.len() >= lambda + 2 {
            let s_t = sample_count(lambda, self.set.len(), mcfg.outlier_percent, mcfg.success_probability);
            let budget = SamplingBudget {
                max_samples: s_t,
                time_budget: Duration::from_secs_f64(mcfg.time_budget_ms / 1e3),
                inlier_alpha_rad: inlier_rad,
                score: mcfg.consensus_score,
            };
            let solver = omnitrack_solver::SolverOptions {
                convergence_rad: self.solver.convergence_rad.max(SAMPLE_CONVERGENCE_RAD),
                ..self.solver.clone()
            };
            // Every sample's fit starts from the prediction: where the fit is R_and_T's, each
            // line's first step there is worked out once for all of them (`SharedStart`).
            let shared = (!upright && method != SolverMethod::Xi).then(|| {
                self.shared_start.prepare(&self.set, predicted, solver.error);
                &self.shared_start
            });
            let mut f = |c: &[Correspondence], lines: &[usize], start: &Pose| match shared {
                Some(shared) => shared.refine(c, lines, start, &solver),
                None => fit(upright, method, &solver, c, start),
            };
            match self
                .sampler
                .run_sized(lambda, &self.set, predicted, &budget, &mut self.rng, &mut f)
            {
                Ok(out) => {
                    samples = out.samples;
                    Some(out.pose)
                }
                Err(_) => None,
            }
        } else if self.set.len() >= 4 {
            fit(upright, method, &self.solver, &self.set, predicted)
        } else {
            None
        };

        (solved, samples, match_time)
    }

    /// How many held correspondences have an edge within the inlier angle (and hue gate) at
    /// `pose`: the support a solved pose has before Figure 8 runs. Each one's edge is kept in
    /// `support_at` (`None` where there is none, or the track was not looked at): the
    /// observations of step 4 at the same pose are these.
    fn consistent_count(&mut self, edges: &[Edge], pose: &Pose) -> usize {
        let m = &self.cfg.maintenance;
        let cos = m.inlier_angle_deg.to_radians().cos();
        let min_len = self.cfg.edges.min_edge_length_deg.to_radians();
        let mut n = 0;
        for (i, t) in self.tracks.tracks().iter().enumerate() {
            self.support_at[i] = None;
            let Some(held) = t.edge else { continue };
            let seg = &self.model.segments[t.segment as usize];
            let pred = Predicted::new(&[seg.a, seg.b], pose, &self.centres);
            if pred.length_rad < min_len {
                continue;
            }
            let gate = Gate {
                cos_alpha: cos,
                min_overlap: 0.5,
                hue: Some((held.hue, m.hue_gate as f32)),
                polarity: held.bright_normal(),
            };
            if let Some((e, a)) = best_edge_among(&pred, &self.centres, edges, &self.edge_normals, &gate) {
                self.support_at[i] = Some((e as u32, a));
                n += 1;
            }
        }
        n
    }

    /// Figure 7 for one frame.
    pub(super) fn maintain(&mut self, edges: &[Edge], timestamp_ns: u64) -> FrameResult {
        let mcfg = self.cfg.maintenance.clone();
        let k = mcfg.accept_after_frames;
        let upright = self.cfg.motion.upright;
        let method = self.cfg.solver.method;
        let inlier_rad = mcfg.inlier_angle_deg.to_radians();
        let min_len = self.cfg.edges.min_edge_length_deg.to_radians();

        self.edge_normals.fill(edges);

        // 1. Prediction.
        let forecast = (self.cfg.motion.filter && self.filter.started()).then(|| self.filter.predict(timestamp_ns));
        let mut predicted = match (self.cfg.maintenance.constant_velocity_prior, self.previous) {
            _ if forecast.is_some() => forecast.map_or(self.pose, |(p, _)| p),
            (true, Some((prev, prev_t))) if prev_t < self.last_time => {
                constant_velocity(&prev, prev_t, &self.pose, self.last_time, timestamp_ns)
            }
            _ => self.pose,
        };
        // The turn since the last frame as the image shows it, where it does (module
        // `frame_rotation`, docs/decisions.md 2026-11-30): R₁ = R₀ Qᵀ, the motion model's turn
        // Q₀ = R̂₁ᵀ R₀ its prior. Not for a narrow rig: in a narrow view a turn and a step move
        // the lines alike, and on one 50° pinhole it added wrong frames.
        if self.cfg.motion.frame_rotation && !self.narrow {
            let r0 = self.pose.rotation;
            let prior = predicted.rotation.inverse() * r0;
            let measured =
                self.frame_rotation
                    .measure(edges, &prior, min_len, inlier_rad, self.last_time, timestamp_ns);
            // Only where the two disagree by more than the inlier angle (a turn the motion
            // model did not expect): walking straight at 5 Hz, a step of 20 cm moves the planes
            // of lines a few metres away by degrees, which a turn fitted to planes takes for a
            // turn (0.1–1.1° off on `corridor`), and taking the image's turn on every frame let
            // a stretch of it slide 45–76 cm.
            if let Some(turn) = measured.filter(|t| t.rotation.angle_to(&prior) > inlier_rad) {
                predicted = Pose::from_parts(predicted.translation, r0 * turn.rotation.inverse());
                self.stats.frame_turns += 1;
            }
        }

        // 2–3 from the prediction; if its pose does not hold (too few consistent correspondences),
        // again from the last pose and from the prediction turned about the vertical by ± one and
        // two gate widths: a turn faster (or stopping sooner) than the motion model expects moves
        // every plane out of the gate at once.
        let solve_started = Instant::now();
        let mut samples = 0;
        let mut match_time = Duration::ZERO;
        let mut solved = None;
        let mut prior = predicted;
        let gate_rad = mcfg.angular_gate_deg.to_radians();
        // A pose that keeps nine tenths of the last frame's inliers is taken at once;
        // otherwise every turn is tried and the best supported pose wins.
        let enough = (mcfg.min_inliers as usize).max(9 * self.last_inliers as usize / 10);
        let mut best_support = 0;
        // Starts: the prediction, the last pose (a turn or a walk that stopped short), then
        // the prediction turned about the vertical.
        let last = self.pose;
        for attempt in 0..6 {
            let start = match attempt {
                0 => predicted,
                1 => last,
                a => turned(&predicted, [1.0, -1.0, 2.0, -2.0][a - 2] * gate_rad),
            };
            let (pose, n, m) = self.match_and_solve(edges, &start);
            samples += n;
            match_time += m;
            if let Some(p) = pose {
                let support = self.consistent_count(edges, &p);
                if support > best_support || solved.is_none() {
                    best_support = support;
                    solved = Some(p);
                    prior = start;
                    std::mem::swap(&mut self.support_at, &mut self.support_solved);
                }
                if support >= enough {
                    break;
                }
            }
        }
        // A solve that moved well away from the prediction may have taken a repeated
        // structure's neighbour (a door jamb's two corners a wall's thickness apart, matched
        // across): S̄ agrees with itself there, but VIS(T) as a whole does not. Poses near the
        // prediction, refitted, compete by the search's measure over all of VIS(T): the
        // prediction; the solve's rotation at the predicted position (in a turn the prediction
        // lags, and the solve often has the turn nearer right but has slid along the
        // structure); and the prediction turned about the vertical by the refit's reach either
        // way (a head turn the motion model missed by more than that reach leaves the
        // prediction outside the refit's basin, and without hues to sign the edges the solve
        // slid 20–30 cm on such turns: docs/decisions.md, 2026-12-01, the grey `lab`).
        // `support_solved` holds the held correspondences' edges at `solved` until another pose
        // replaces it.
        let mut solved_support_known = solved.is_some();
        if let Some(p) = solved {
            let moved = (p.translation.vector - predicted.translation.vector).norm();
            let turn = p.rotation.angle_to(&predicted.rotation);
            if moved > SECOND_OPINION_M || turn > SECOND_OPINION_RAD {
                let reseated = Pose::from_parts(predicted.translation, p.rotation);
                let reach = self.init.polish_reach_rad();
                let starts = [
                    predicted,
                    reseated,
                    turned(&predicted, reach),
                    turned(&predicted, -reach),
                ];
                // Each start refitted without the search's simplex: the solve competing is not
                // simplex-polished either, and the winner gets maintenance's final fit below.
                // The solve stands only as a clear winner: where it and a refit near the
                // prediction are alike by the search's measure, the motion model decides, and
                // the refit continues the motion. (The other way round, a refit replaced the
                // solve only when it was the clear winner, and a still rig seeing the same
                // image frame after frame was solved 7–30 cm along a curtain wall's mullions and
                // ended 32–54 cm off: docs/decisions.md, 2026-12-02, "the second opinion's
                // burden".) Not for a narrow rig: one 50° view fixes a refit over VIS(T) only to
                // decimetres along it, and the refit near a lagging prediction held one pinhole
                // on fewer frames (the same entry).
                let ratio = self.cfg.initialisation.clear_winner_ratio;
                let solve_score = self.init.score(&p, edges);
                let bar = if self.narrow {
                    ratio * solve_score
                } else {
                    solve_score / ratio
                };
                let mut best: Option<(Pose, f64)> = None;
                for start in &starts {
                    if let Some((pose, score)) = self.init.refit_score(start, edges) {
                        if score < bar && best.is_none_or(|b| score < b.1) {
                            best = Some((pose, score));
                        }
                    }
                }
                if let Some((pose, _)) = best {
                    self.stats.second_opinions += 1;
                    solved = Some(pose);
                    solved_support_known = false;
                    prior = predicted;
                }
            }
        }
        let hue_gate = mcfg.hue_gate as f32;
        let n_tracks = self.tracks.tracks().len();

        // 4. Observations at the solved pose and Figure 8.
        let mut result = FrameResult::empty(TrackerState::Tracking);
        result.samples = samples;
        let check_pose = solved.unwrap_or(predicted);
        let tight = inlier_rad.cos();
        self.set.clear();
        self.set_track.clear();
        let (mut eligible, mut seen) = (0u32, 0u32);
        for i in 0..n_tracks {
            let t = self.tracks.tracks()[i];
            let seg = &self.model.segments[t.segment as usize];
            let ends = [seg.a, seg.b];
            let pred = Predicted::new(&ends, &check_pose, &self.centres);
            let observed = if solved.is_some() && pred.length_rad >= min_len {
                eligible += 1;
                if solved_support_known && t.edge.is_some() {
                    // `consistent_count` matched it at this pose with this gate already.
                    self.support_solved[i].map(|(e, a)| (e as usize, a))
                } else {
                    let gate = Gate {
                        cos_alpha: tight,
                        min_overlap: 0.5,
                        hue: t.edge.map(|h| (h.hue, hue_gate)),
                        polarity: t.edge.and_then(|h| h.bright_normal()),
                    };
                    best_edge_among(&pred, &self.centres, edges, &self.edge_normals, &gate)
                }
            } else {
                None
            };
            let track = &mut self.tracks.tracks_mut()[i];
            match observed {
                Some((e, _)) => {
                    seen += 1;
                    let was_accepted = track.state == CorrespondenceState::Accepted;
                    track.observe(HeldEdge::from(&edges[e]), k);
                    if was_accepted || track.state == CorrespondenceState::Accepted {
                        self.set.push(Correspondence {
                            edge: edges[e].plane,
                            segment: ends,
                        });
                        self.set_track.push(i);
                    }
                }
                None => track.miss(k),
            }
        }

        result.explained = if eligible > 0 {
            seen as f32 / eligible as f32
        } else {
            0.0
        };

        // 5. Final fit and the health of the frame.
        let mut pose = solved;
        if let Some(p) = pose {
            if self.set.len() >= 4 {
                // Weighed by Cauchy's loss where configured: lines a coarse model places a
                // little wrong pull less (`solver::refine::cauchy`).
                pose = if mcfg.robust_final_fit && !upright && method == SolverMethod::RAndT {
                    omnitrack_solver::r_and_t_cauchy(&self.set, &p, &self.solver, &mut self.robust_scratch)
                } else {
                    fit(upright, method, &self.solver, &self.set, &p)
                }
                .or(Some(p));
            }
        }
        let max_jump_rad = mcfg.max_jump_deg.to_radians();
        let within_jump = |p: &Pose| {
            (p.translation.vector - prior.translation.vector).norm() <= mcfg.max_jump_m
                && p.rotation.angle_to(&prior.rotation) <= max_jump_rad
        };
        let mut good = pose.is_some_and(|p| self.set.len() >= mcfg.min_inliers as usize && within_jump(&p));
        // A fit outside the motion filter's gate is taken as a stop or a turn the motion model
        // did not expect (the filter restarts there, moving as it moved since the last frame),
        // but only where the rig could have walked to it: one further from the last good pose
        // than `motion.max_speed_m_s` reaches in the time since is a slide onto parallel
        // structure, and a bad frame. (FZK-Haus, walking: a fit 0.30 m from the last pose in a
        // 0.1 s frame, 0.35 m off the prediction, restarted the filter at 3 m/s, and the pose
        // slid 1.9 m in 13 frames along the walls: docs/decisions.md.)
        if let (true, Some(p), Some((_, predicted_cov))) = (good, pose.as_ref(), &forecast) {
            if self.faster_than_a_walk(p, timestamp_ns) {
                let cov = self.measured_covariance(p);
                if distance2(&predicted, predicted_cov, p, &cov).is_some_and(|d2| d2 > GATE_CHI2_6) {
                    good = false;
                    self.stats.too_fast += 1;
                }
            }
        }
        // Fewer lines than `min_inliers` fix the pose in some directions and hardly in others;
        // with the motion filter such a frame is fused where its lines are informative
        // (their covariance says where), provided it continues the motion (inside the filter's
        // gate) and the prediction is sharper than the jump limit it is judged by (its position
        // σ within `max_jump_m`; a third of it refused most of a narrow rig's frames, whose
        // few-line fits leave the filter at σ 0.2–0.4 m: docs/decisions.md). Not while
        // relocalised frames are on probation: the prediction is then the unconfirmed
        // relocalised pose itself, and a few lines agreeing with it are no evidence for it
        // (module `relocalise`).
        let on_probation = !self.probation.links.is_empty();
        if let (false, Some((_, predicted_cov))) = (good, &forecast) {
            if let Some(p) = pose.filter(|p| self.set.len() >= SMALLEST_SAMPLE && within_jump(p)) {
                let cov = self.measured_covariance(&p);
                let d2 = distance2(&predicted, predicted_cov, &p, &cov);
                if filter_takes_few_lines(on_probation, largest_position_sigma(predicted_cov), mcfg.max_jump_m, d2) {
                    good = true;
                    self.stats.filtered_few_lines += 1;
                }
            }
        }
        // A pose that explains far less of VIS(T) than the frames before it may have slid off
        // the building (a doorway turn that took most correspondences out of view) while moving
        // less than the jump limits, or the view may just be poorer (people, clutter): a local
        // search decides, and replaces the pose only with one that explains clearly more (by
        // the search's own measure, without the hue gate).
        // Relocalised poses on probation are published when this frame holds the pose; when
        // as many relocalised frames as lose the lock went unheld, they are withdrawn and the
        // lock is lost (module `relocalise`). A re-initialisation on trial is withdrawn by the
        // first frame that does not hold it (module `search`, "On trial").
        // A commit on trial for more frames holds this one back too.
        let mut holding_trial = false;
        if !self.probation.links.is_empty() {
            let passes = good && pose.is_some_and(|p| self.trial_passes(&p, edges));
            if passes {
                match self.probation.trial.as_mut() {
                    Some(t) if t.frames_left > 1 => {
                        t.frames_left -= 1;
                        holding_trial = true;
                    }
                    _ => self.release_probation(),
                }
            } else if self.probation.trial.is_some() || self.probation.links.len() >= self.probation_limit() {
                let mut r = self.lose_lock();
                r.solve_time = solve_started.elapsed().saturating_sub(match_time);
                r.match_time = match_time;
                r.samples = samples;
                return r;
            }
        }
        // (A frame that held a commit on trial passed the search's acceptance test: stronger
        // evidence than the running mean's floor.)
        let suspect = good && !holding_trial && (result.explained as f64) < self.explained_floor(0);
        if !good || suspect {
            // When the prior failed (typically a turn faster than the motion model expects,
            // which moves every plane out of the angular gate), the initialisation's triplet
            // matching searches a small volume around the prediction: it needs no rotation.
            let own = match (&pose, suspect) {
                (Some(p), true) => SUSPECT_MARGIN * self.init.explained(p, edges),
                _ => 0.0,
            };
            result.solve_time = solve_started.elapsed().saturating_sub(match_time);
            result.match_time = match_time;
            // What the frame is when no better pose is found nearby: a suspect frame stands.
            let tail = Tail {
                result,
                pose,
                good: suspect,
                predicted,
                timestamp_ns,
            };
            if self.start_relocalise(edges, &predicted, pose.as_ref(), timestamp_ns, own, tail) {
                // Under way: this frame is answered when it is taken up (module `background`).
                let mut r = FrameResult::empty(TrackerState::Tracking);
                r.match_time = match_time;
                r.solve_time = result.solve_time;
                r.samples = samples;
                return r;
            }
            good = suspect;
        }
        result.solve_time = solve_started.elapsed().saturating_sub(match_time);
        result.match_time = match_time;
        let concluded = self.conclude(Tail {
            result,
            pose,
            good,
            predicted,
            timestamp_ns,
        });
        if holding_trial {
            // Links are at most `confirm_frames`, fewer than their capacity (module `search`).
            let _ = self.probation.links.push((timestamp_ns, concluded));
            let mut shown = FrameResult::empty(TrackerState::Tracking);
            shown.match_time = concluded.match_time;
            shown.solve_time = concluded.solve_time;
            shown.samples = concluded.samples;
            return shown;
        }
        concluded
    }

    /// Fig. 7's end for a frame whose pose is `good` or not: S_{t+1}, the pose and its
    /// covariance, or a bad frame coasting on the prediction (and, after `lost_after_frames`
    /// of them, the loss).
    pub(super) fn conclude(&mut self, tail: Tail) -> FrameResult {
        let Tail {
            mut result,
            pose,
            good,
            predicted,
            timestamp_ns,
        } = tail;
        let lost_after_frames = self.cfg.maintenance.lost_after_frames;
        result.states = self.state_counts();
        if good {
            let measured = pose.expect("a good frame has a pose");
            self.bad_frames = 0;
            self.note_explained(result.explained as f64);
            result.inliers = self.set.len() as u32;
            self.last_inliers = result.inliers;
            result.covariance = self.measured_covariance(&measured);
            result.xi_rad2 = xi(&self.set, &measured);
            let p = if self.cfg.motion.filter {
                let (p, cov) = self.fuse(&measured, &result.covariance, timestamp_ns);
                result.covariance = cov;
                p
            } else {
                measured
            };
            result.pose = Some(p);
            self.previous = Some((self.pose, self.last_time));
            self.pose = p;
            self.last_good = Some(p);
            self.last_good_time = timestamp_ns;
            // 6. VIS(T_{t+1}).
            if let Some(set) = self.table.query(&Point3::from(p.translation.vector)) {
                self.tracks.update_visible(set.segments);
            }
        } else {
            self.bad_frames += 1;
            // Coast on the prediction so that the gate follows the motion.
            self.previous = Some((self.pose, self.last_time));
            self.pose = predicted;
            self.filter.coast(timestamp_ns);
            if self.bad_frames >= lost_after_frames {
                let lost = self.lose_lock();
                result.state = lost.state;
                result.event = lost.event;
            }
        }
        result
    }

    /// Whether the rig would have moved from the last good pose to `p` faster than
    /// `motion.max_speed_m_s` (0: no limit) by `timestamp_ns`.
    fn faster_than_a_walk(&self, p: &Pose, timestamp_ns: u64) -> bool {
        let max_speed = self.cfg.motion.max_speed_m_s;
        let Some(held) = self.last_good.filter(|_| max_speed > 0.0) else {
            return false;
        };
        let dt = timestamp_ns.saturating_sub(self.last_good_time) as f64 * 1e-9;
        (p.translation.vector - held.translation.vector).norm() > max_speed * dt
    }

    /// The lock is lost: the next frames search, around `last_good`.
    pub(super) fn lose_lock(&mut self) -> FrameResult {
        let first = self.probation.trial.is_some_and(|t| t.first);
        self.withdraw_probation();
        if first {
            // A first commit its trial did not hold was never published: the tracker
            // initialises again, as if it had not been made (module `search`, "Frames
            // agreeing").
            self.state = TrackerState::Initialising;
            self.last_good = None;
            self.search_attempts = 0;
            self.confirm_count = 0;
            self.tracks.clear();
            return FrameResult::empty(TrackerState::Initialising);
        }
        self.state = TrackerState::Lost;
        self.stats.losses += 1;
        self.search_attempts = 0;
        self.confirm_count = 0;
        self.tracks.clear();
        let mut result = FrameResult::empty(TrackerState::Lost);
        result.event = Some(TrackerEvent::LostLock);
        result
    }

    /// A good frame's `measured` pose (covariance `cov`) through the motion filter: the fused
    /// pose and its covariance. A frame outside the filter's gate that maintenance
    /// nevertheless trusts (enough lines, within the jump limits: a stop or a turn the motion
    /// model did not expect) restarts the filter there, moving as it moved since the last frame.
    fn fuse(&mut self, measured: &Pose, cov: &Matrix6<f64>, timestamp_ns: u64) -> (Pose, Matrix6<f64>) {
        if !self.filter.started() {
            self.filter.start(measured, cov, timestamp_ns);
            return (*measured, *cov);
        }
        match self.filter.update(timestamp_ns, measured, cov) {
            Fused::Yes(_) => (*self.filter.pose(), self.filter.pose_covariance()),
            Fused::Outside(_) | Fused::NoInformation => {
                self.filter.start(measured, cov, timestamp_ns);
                self.filter.continue_from(&self.pose, self.last_time);
                (*measured, *cov)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frame_of_few_lines_is_taken_only_off_probation_with_a_sharp_prediction_inside_the_gate() {
        let inside = Some(0.5 * GATE_CHI2_6);
        // A narrow rig's prediction (σ 0.2–0.4 m) within the 0.5 m jump limit: taken.
        assert!(filter_takes_few_lines(false, 0.3, 0.5, inside));
        // The same frame right after a relocalisation: the prediction is the relocalised pose
        // itself, and the frame is no evidence for it.
        assert!(!filter_takes_few_lines(true, 0.3, 0.5, inside));
        // A prediction vaguer than the jump limit, a fit outside the gate, no gate at all.
        assert!(!filter_takes_few_lines(false, 0.6, 0.5, inside));
        assert!(!filter_takes_few_lines(false, 0.3, 0.5, Some(2.0 * GATE_CHI2_6)));
        assert!(!filter_takes_few_lines(false, 0.3, 0.5, None));
    }
}
