//! Relocalisation (beyond the papers): when the motion prior fails on a frame, a local search
//! about the prediction, run off the frame path (module [`background`](crate::background)), whose
//! candidates compete with the polished prediction, the last pose and the frame's own solve;
//! [`choose`] decides, or the frame concludes as maintenance left it.
//!
//! In: the frame's [`Edge`]s, the predicted and solved poses, what the frame concludes without
//! a relocalisation (`Tail`). Out: the chosen pose (tracking continues from it with a fresh
//! S_t) or the frame's own conclusion.
//!
//! **On probation.** A relocalised pose is a search's answer on one frame, taken with less
//! evidence than a commit (no rival beaten by a margin, no confirmation frames): that is what
//! lets it answer a turn the motion model missed within a frame or two. But where one frame
//! cannot tell places apart (a 50° view of one of a room's repeated bays, a quarter-turn twin),
//! it takes the wrong one, and the next frames, failing again from there, relocalised again:
//! on the one-pinhole rig 55 of 69 relocalised frames were more than 30 cm or 3° off, 30 of
//! them in such chains, each link moving the pose up to a metre (docs/decisions.md). So a
//! relocalised frame's answer is held back until a later frame's maintenance holds the pose (a
//! good frame: enough accepted lines within the jump limits of its prediction), and then
//! published, late, as it was anyway (the search ran off the frame path). A fast turn may take
//! a few relocalised frames before maintenance holds again: up to `lost_after_frames` of them
//! wait together. When that many went unheld they are withdrawn unpublished
//! ([`TrackerStats::relocalisations_withdrawn`](crate::TrackerStats)) and the lock is lost, as
//! after that many bad frames; the searches that follow start from the last pose maintenance
//! held, with an initialisation's standard of evidence. (Withdrawing after a single unheld
//! frame also ended the wrong chains, but halved the frames held within 10 cm on the narrow
//! rig's `lab`: right chains of two or three relocalised frames are common in its turns.)

use super::{PendingSearch, Relocalisation, Tail, Tracker};
use crate::background::STARTS;
use crate::init::{Candidate, SearchVolume};
use crate::report::{FrameResult, TrackerEvent, TrackerState};
use nalgebra::{Point3, UnitQuaternion};
use omnitrack_core::geometry::Pose;
use omnitrack_edges::Edge;
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use std::time::Duration;

/// Where a relocalisation candidate stands: `plausible` (enough inliers, within reach of the
/// prediction or, on a wide rig, of the last held pose, and of the turns the rig can have
/// made), `acceptable` (plausible and explaining enough of VIS(T)), `jumps` (turned further
/// than `max_jump_deg` from the prediction).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Standing {
    plausible: bool,
    acceptable: bool,
    jumps: bool,
}

/// The relocalisation's choice, or None.
///
/// Candidates compare by [`Candidate::merit`], as the initialisation's do (explained × support
/// × (1 − blank)), not by the truncated ξ: on the realistic world (docs/decisions.md, "the realistic
/// world") casings beside every opening and one paint on every wall let
/// poses 0.3–1 m off match the lines they predict as tightly as the truth, and ranking by ξ took
/// them on 29 of 32 relocalisations of `lab` (252 cm RMSE); by merit, 1 of 19 over tracker seeds
/// 1–3 (18 / 12 / 12 cm), the default world unchanged.
///
/// The merit is a share of VIS(pose), and a place that sees few segments can match its few
/// about as well as the true place matches its many (`corridor`, frame 5076: a pose 73 cm off
/// with 22 inliers scored 4 % better than the polished prediction with 64). So on each side of
/// the turn limit the best merit wins over the best-supported candidate (most inliers, among
/// all plausible ones) only by `ratio` (its merit × `ratio` above the other's); otherwise the
/// best-supported wins, or, when it does not explain enough (a suspect frame's own pose),
/// nothing does. A candidate that turns beyond the limit must then beat one that does not by
/// `ratio` too (a symmetric corridor's quarter-turn twin explains about as much as the truth on
/// one frame).
fn choose(candidates: &[Option<(Candidate, Standing)>], ratio: f64) -> Option<Candidate> {
    let pick = |jumping: bool| -> Option<Candidate> {
        let side = || candidates.iter().flatten().filter(move |(_, s)| s.jumps == jumping);
        let (fit, _) = side()
            .filter(|(_, s)| s.acceptable)
            .max_by(|a, b| a.0.merit().total_cmp(&b.0.merit()))?;
        let (support, standing) = side()
            .filter(|(_, s)| s.plausible)
            .max_by(|a, b| a.0.inliers.cmp(&b.0.inliers).then(a.0.merit().total_cmp(&b.0.merit())))?;
        if fit.inliers < support.inliers && ratio * fit.merit() <= support.merit() {
            standing.acceptable.then_some(*support)
        } else {
            Some(*fit)
        }
    };
    match (pick(false), pick(true)) {
        (Some(k), Some(j)) if ratio * j.merit() > k.merit() => Some(j),
        (Some(k), _) => Some(k),
        (None, j) => j,
    }
}

/// `pose` turned by `angle` (rad) about the world vertical through its position.
pub(super) fn turned(pose: &Pose, angle: f64) -> Pose {
    if angle == 0.0 {
        return *pose;
    }
    let r = UnitQuaternion::from_axis_angle(&nalgebra::Vector3::z_axis(), angle);
    Pose::from_parts(pose.translation, r * pose.rotation)
}

impl Tracker<'_> {
    /// A local search around `predicted` (diameter `relocalise_diameter_m`); on success (a
    /// candidate explaining at least `min_explained` of VIS(T)) the tracker continues from the
    /// found pose with a fresh S_t, as after initialisation. A bad frame takes any plausible
    /// candidate (`min_explained` 0): a view poorer than before, such as sensors covered, must
    /// not stop the tracker from finding its place again. The search keeps to the turns the rig
    /// can have made since the last good frame; the prediction, the last pose, the frame's
    /// `solved` pose, its rotation at the predicted position and the prediction turned by ± one
    /// gate width, each polished, compete with its candidates, and [`choose`] decides
    /// ([`Tracker::conclude_relocalisation`]).
    ///
    /// The search and the polishes run off the frame path (module `background`), and are taken
    /// up `relocalise_time_budget_ms` later on the frames' clock; `tail` is what the frame
    /// concludes when no candidate wins. Returns false when relocalisation is off.
    pub(super) fn start_relocalise(
        &mut self,
        edges: &[Edge],
        predicted: &Pose,
        solved: Option<&Pose>,
        timestamp_ns: u64,
        min_explained: f64,
        tail: Tail,
    ) -> bool {
        let d = self.cfg.maintenance.relocalise_diameter_m;
        if d <= 0.0 {
            return false;
        }
        let Some(mut job) = self.job.take() else {
            return false;
        };
        let volume = SearchVolume {
            centre: Point3::from(predicted.translation.vector),
            diameter_m: Some(d),
        };
        let budget = Duration::from_secs_f64(self.cfg.maintenance.relocalise_time_budget_ms.max(0.0) / 1e3);
        let turn_limit = self.max_turn_rad(timestamp_ns);
        let turned_from = self.last_good.map_or(predicted.rotation, |p| p.rotation);
        let i = &self.cfg.initialisation;
        let breadth = (
            i.edges_considered as usize,
            i.segments_considered as usize,
            i.samples_per_cell as usize,
        );
        // The heading is near the prediction's: its quarter-turn twins are not searched.
        let rng = SmallRng::seed_from_u64(self.rng.random());
        job.prepare(
            edges,
            volume,
            budget,
            breadth,
            false,
            Some((turned_from, turn_limit)),
            rng,
        );
        // Besides the search's best few (the tracker asks for three), polished: the prediction,
        // the last pose, this frame's solved pose and the starts below. The search may find
        // only a twin of the place (a symmetric corridor seen a quarter turn away), and where a
        // turn stopped short the prediction overshoots into a local minimum a few degrees off
        // that the last pose does not fall into.
        // Lines fix the rotation by their directions alone (R_then_T), while a repeated
        // structure leaves the translation along it free: a solve that slid to a neighbouring
        // doorway often has the turn right, so its rotation is also tried at the predicted
        // position.
        let reseated = solved.map(|s| Pose::from_parts(predicted.translation, s.rotation));
        // A turn faster than the motion model expects leaves the prediction a gate width or
        // more off, where polishing stays in a local minimum: the prediction turned by ± one
        // gate width is polished too.
        let gate = self.cfg.maintenance.angular_gate_deg.to_radians();
        job.set_starts([
            Some(*predicted),
            Some(self.pose),
            solved.copied(),
            reseated,
            Some(turned(predicted, gate)),
            Some(turned(predicted, -gate)),
        ]);
        let pending = PendingSearch {
            started_ns: timestamp_ns,
            due_ns: timestamp_ns.saturating_add(u64::try_from(budget.as_nanos()).unwrap_or(u64::MAX)),
            volume,
            grown: false,
            turn_limit: Some((turned_from, turn_limit)),
            floor: min_explained,
            relocalisation: Some(Relocalisation {
                predicted: *predicted,
                held: self.last_good.filter(|_| !self.narrow).map(|p| p.translation.vector),
                turned_from,
                turn_limit,
                floor: min_explained,
                diameter_m: d,
                last_time: self.last_time,
                tail,
            }),
        };
        self.launch(job, pending);
        true
    }

    /// Takes up a relocalisation on its own frame (stamped `timestamp_ns`): the candidate
    /// [`choose`] picks is committed there, or the frame concludes as it would have without one.
    pub(super) fn conclude_relocalisation(&mut self, reloc: Relocalisation, timestamp_ns: u64) -> FrameResult {
        // The frame's own view of time, as when the search was started.
        self.last_time = reloc.last_time;
        let Some(job) = self.collect_search() else {
            return self.conclude(reloc.tail);
        };
        let (found, report) = job.result();
        if report.cancelled {
            // Cut short by a stop: the frame concludes as maintenance left it.
            self.stats.searches_cancelled += 1;
            self.job = Some(job);
            return self.conclude(reloc.tail);
        }
        self.stats.search_backstops += u64::from(report.backstop);
        let mut candidates = [None; 3 + STARTS];
        for (slot, c) in candidates[..3].iter_mut().zip(found) {
            *slot = Some(*c);
        }
        candidates[3..].copy_from_slice(job.polished());
        let m = &self.cfg.maintenance;
        let predicted = &reloc.predicted;
        // Within reach of the prediction, or (a wide rig) of where maintenance last held the
        // pose: a rig that stopped or turned back is behind the constant-velocity prediction,
        // not ahead of it (a walk reversed between two 5 Hz frames put the truth 1.09 m from
        // the prediction and 0.84 m from the last held pose, and a slid pose near the
        // prediction was taken). Not a narrow rig: its one view's look-alikes near the last
        // pose got in (one 50° pinhole's `corridor`: 5.3 → 11.1 % of frames 30 cm off;
        // docs/decisions.md, 2026-12-01).
        let reach = 0.5 * reloc.diameter_m + m.max_jump_m;
        let within_reach = |p: &Pose| {
            let at = p.translation.vector;
            (at - predicted.translation.vector).norm() <= reach || reloc.held.is_some_and(|h| (at - h).norm() <= reach)
        };
        let jump_rad = m.max_jump_deg.to_radians();
        let standings = candidates.map(|c| {
            c.map(|c| {
                let plausible = c.inliers >= m.min_inliers as usize
                    && within_reach(&c.pose)
                    && c.pose.rotation.angle_to(&reloc.turned_from) <= reloc.turn_limit;
                let standing = Standing {
                    plausible,
                    acceptable: plausible && c.explained >= reloc.floor,
                    jumps: c.pose.rotation.angle_to(&predicted.rotation) > jump_rad,
                };
                (c, standing)
            })
        });
        let Some(best) = choose(&standings, self.cfg.initialisation.clear_winner_ratio) else {
            self.job = Some(job);
            return self.conclude(reloc.tail);
        };
        self.stats.relocalisations += 1;
        // The rig moves on through a relocalisation: the motion from the last good pose to the
        // found one continues, so that the next frame is predicted where the rig will be, not
        // where it was (at 5 Hz a walking rig is 20 cm on, and the gates matched the wrong
        // edges there). Carrying over the interval before instead, as this did until
        // 2026-11-27, keeps a rig that turned back (or stopped) predicted the old way: every
        // following frame failed and relocalised in turn (`tests/pipeline`, a recording played
        // back and forth).
        let since = self
            .last_good
            .map(|p| (p, self.last_good_time))
            .filter(|(_, t)| *t < timestamp_ns);
        let held = since;
        let mut r = self.commit(&best.pose, job.edges(), timestamp_ns);
        self.job = Some(job);
        if let Some((p, t)) = since {
            self.previous = since;
            self.filter.continue_from(&p, t);
        }
        r.event = Some(TrackerEvent::Relocalised);
        r.match_time += reloc.tail.result.match_time;
        r.solve_time = reloc.tail.result.solve_time;
        r.samples += reloc.tail.result.samples;
        // On probation (module doc): the answer waits for a frame to hold the pose.
        let mut shown = FrameResult::empty(TrackerState::Tracking);
        shown.match_time = r.match_time;
        shown.solve_time = r.solve_time;
        shown.samples = r.samples;
        if self.probation.links.is_empty() {
            self.probation.held = held;
        }
        if self.probation.links.push((timestamp_ns, r)).is_err() {
            // Longer than any configured chain: the oldest link goes unpublished.
            self.probation.links.remove(0);
            self.stats.relocalisations_withdrawn += 1;
            let _ = self.probation.links.push((timestamp_ns, r));
        }
        shown
    }

    /// How many relocalised frames may wait for a frame that holds their pose: as many as the
    /// bad frames that lose the lock.
    pub(super) fn probation_limit(&self) -> usize {
        (self.cfg.maintenance.lost_after_frames as usize).clamp(1, super::PROBATION_LINKS)
    }

    /// A frame held the pose: the relocalised frames (or the re-initialisation on trial) before
    /// it are published (late).
    pub(super) fn release_probation(&mut self) {
        for k in 0..self.probation.links.len() {
            let (t, r) = self.probation.links[k];
            self.note_late(t, r);
        }
        self.probation.links.clear();
        self.probation.trial = None;
    }

    /// The relocalised frames no frame held (or the re-initialisation on trial) are withdrawn
    /// unpublished; the searches that follow start from the last pose maintenance held before
    /// them, and after a withdrawn re-initialisation over the doubled volume (module `search`,
    /// "On trial").
    pub(super) fn withdraw_probation(&mut self) {
        if self.probation.links.is_empty() {
            return;
        }
        match self.probation.trial.take() {
            Some(trial) if trial.first => {
                self.stats.commits_withdrawn += 1;
                self.explained_ref = trial.explained_ref;
            }
            Some(trial) => {
                self.stats.reinitialisations_withdrawn += self.probation.links.len() as u64;
                self.explained_ref = trial.explained_ref;
                self.volume_level = trial.volume_level + 1;
                self.widen = false;
            }
            None => self.stats.relocalisations_withdrawn += self.probation.links.len() as u64,
        }
        self.probation.links.clear();
        if let Some((pose, t)) = self.probation.held.take() {
            self.last_good = Some(pose);
            self.last_good_time = t;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Translation3;

    /// A candidate whose merit is `merit`.
    fn cand(x: f64, merit: f64, inliers: usize) -> Candidate {
        Candidate {
            pose: Pose::from_parts(Translation3::new(x, 0.0, 0.0), UnitQuaternion::identity()),
            score: 1e-4,
            inliers,
            xi_rad2: 1e-4,
            explained: merit,
            support: 1.0,
            blank: 0.0,
        }
    }

    const OK: Standing = Standing {
        plausible: true,
        acceptable: true,
        jumps: false,
    };

    fn winner(c: &[Option<(Candidate, Standing)>]) -> Option<f64> {
        choose(c, 0.8).map(|c| c.pose.translation.x)
    }

    #[test]
    fn a_few_segments_matched_slightly_better_lose_to_many() {
        // The corridor's failure: 22 inliers explaining 4 % more than the prediction's 64.
        let c = [Some((cand(0.0, 0.50, 64), OK)), Some((cand(0.73, 0.52, 22), OK)), None];
        assert_eq!(winner(&c), Some(0.0));
        // Clearly more (0.8 × its merit above the other's), fewer inliers still win.
        let c = [Some((cand(0.0, 0.50, 64), OK)), Some((cand(0.73, 0.65, 22), OK))];
        assert_eq!(winner(&c), Some(0.73));
        // More inliers and more merit: no contest.
        let c = [Some((cand(0.0, 0.50, 64), OK)), Some((cand(0.73, 0.51, 70), OK))];
        assert_eq!(winner(&c), Some(0.73));
    }

    #[test]
    fn a_better_supported_pose_that_explains_too_little_vetoes_the_replacement() {
        // A suspect frame: its own pose (70 inliers) does not explain enough to be taken, and
        // a place seeing few segments (29) is not clearly better: nothing replaces the frame.
        let own = Standing {
            acceptable: false,
            ..OK
        };
        let c = [Some((cand(0.0, 0.50, 70), own)), Some((cand(0.55, 0.55, 29), OK))];
        assert_eq!(winner(&c), None);
        // Implausible candidates neither win nor veto.
        let far = Standing {
            plausible: false,
            acceptable: false,
            jumps: false,
        };
        let c = [Some((cand(0.0, 0.50, 70), far)), Some((cand(0.55, 0.55, 29), OK))];
        assert_eq!(winner(&c), Some(0.55));
    }

    #[test]
    fn a_turn_beyond_the_limit_must_win_clearly() {
        let jump = Standing { jumps: true, ..OK };
        let c = [Some((cand(0.0, 0.50, 60), OK)), Some((cand(0.4, 0.56, 60), jump))];
        assert_eq!(winner(&c), Some(0.0));
        let c = [Some((cand(0.0, 0.50, 60), OK)), Some((cand(0.4, 0.66, 60), jump))];
        assert_eq!(winner(&c), Some(0.4));
        // With nothing that continues the motion, the best jump is taken.
        let c = [None, Some((cand(0.4, 0.56, 60), jump))];
        assert_eq!(winner(&c), Some(0.4));
        assert_eq!(winner(&[None, None]), None);
    }
}
