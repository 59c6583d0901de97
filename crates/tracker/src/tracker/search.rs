//! The searches' scheduling and the commit decision (the crate's doc, "States": Initialising
//! and Lost): which volume a search covers and with what budget and breadth, when its result is
//! taken up (module [`background`](crate::background)), which of its candidates pass the
//! acceptance test, and when the candidates weighed over the next frames are told apart well
//! enough to commit one.
//!
//! Before the first pose, the volume is the hint grown by the walk the rig may have made since
//! it (module `hint_age`), and a grown volume commits only what a search that looked at all of
//! it found.
//!
//! Two pieces of evidence beyond the clear-winner ratio (docs/tracker.md, "Repeated
//! structure" and "How it works"): a rival within the ratio is beaten when the edges exactly one
//! of the two explains side with the best (the *disputed* edges), and a search that looked at
//! every cell of its volume may accept by the share explained over *resolved lines*
//! (`Initialiser::explained_resolved`).
//!
//! **Frames agreeing.** One frame's verdict can flip with the sensor noise: walking through
//! FZK-Haus, a search committed a quarter-turn twin 2.8 m off on its own frame, where two frames
//! later it explains 13 % of the frame's edges (the test asks 15 %) and the truth 62 %. So every
//! commit is on trial until `confirm_frames` frames in all passed the search's acceptance test at
//! it (its search frame and the confirmation frames it won count): maintenance tracks it on the
//! next frames, each must hold it and pass the test at the pose it holds, and only then are its
//! frames published, late. A first commit its trial does not hold is withdrawn unpublished and
//! the tracker initialises again (`TrackerStats::commits_withdrawn`). Maintenance carries the
//! pose through the rig's motion with its prediction; polishing each candidate afresh on the
//! next frames from where it stood does not (a commit that waited for confirmation frames so
//! committed a pose 33 cm behind the rig in the 5 Hz `lab` test: docs/decisions.md, 2026-12-02).
//!
//! **On trial.** After a loss the rig walked on unseen, and the volume about the last held pose
//! may not hold it any more; its best look-alike can then pass every test, since the rival that
//! would refuse it (the truth) lies outside (the walk back after blind frames: a look-alike 1.04 m
//! off, explaining 0.65 of what it predicts, where the truth outside explains 0.88). So a
//! re-initialisation after a loss is published only once the next frame's maintenance holds the
//! pose, as a relocalised pose is (module `relocalise`, "On probation"); the first frame that
//! does not hold it withdraws it unpublished, the lock is lost again, and the next search covers
//! the doubled volume about the last pose held before the loss, where the truth and the
//! look-alike compete. (It is on trial for at least that one frame, and for as many as
//! "Frames agreeing" asks.) (In the walk back the next frame did not hold the look-alike: the rig's
//! motion moved the image's lines where the look-alike's do not go. A look-alike a still rig
//! sees would hold; the trial does not replace the search's own evidence.)
//!
//! In: a frame's [`Edge`]s while not tracking, a finished search's candidates. Out: a committed
//! pose (tracking starts at it) or none yet; never one from a search a stop cut short
//! ([`Tracker::stop_searches_on`]).

use super::{Confirming, PendingSearch, Tracker, Trial};
use crate::background::{SearchJob, STARTS};
use crate::init::{self, Candidate, SearchVolume};
use crate::report::{FrameResult, SearchKind, TrackerEvent, TrackerState, Weighed};
use nalgebra::Point3;
use omnitrack_config::TrackerConfig;
use omnitrack_core::geometry::Pose;
use omnitrack_edges::Edge;
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use std::time::{Duration, Instant};

/// The search's acceptance test: enough inliers, and the pose and the frame explaining each
/// other well enough both ways (`accept_explained_fraction` of the segments it predicts,
/// `accept_support_fraction` of the frame's longest edges).
fn acceptable(cfg: &TrackerConfig, c: &Candidate) -> bool {
    passes_acceptance(cfg, c.inliers, c.explained, c.support)
}

/// [`acceptable`] of a pose's inliers, share explained and support.
fn passes_acceptance(cfg: &TrackerConfig, inliers: usize, explained: f64, support: f64) -> bool {
    let i = &cfg.initialisation;
    inliers >= cfg.maintenance.min_inliers as usize
        && explained >= i.accept_explained_fraction
        && support >= i.accept_support_fraction
}

/// Candidates this close to each other are one basin (m, rad): the margin of a clear winner
/// is over the others.
const BASIN_M: f64 = 0.6;
const BASIN_RAD: f64 = 0.175;

/// A committed pose may lie this far outside the search volume (m): the truth at the volume's
/// edge polishes a few centimetres either way.
const VOLUME_SLACK_M: f64 = 0.1;

/// At most this many candidates of a search are accepted by resolved lines. Accepted ones are
/// clear winners, so they lie in one basin, and more of one basin would add nothing; the bound
/// keeps the quadratic count off the frame path.
const RESOLVED_MAX: usize = 4;

/// Whether `pose` lies in `volume` (within [`VOLUME_SLACK_M`] of it).
fn within(volume: &SearchVolume, pose: &Pose) -> bool {
    volume
        .diameter_m
        .is_none_or(|d| (pose.translation.vector - volume.centre.coords).norm() <= 0.5 * d + VOLUME_SLACK_M)
}

/// Of the `edges` at least `min_len` long (rad): the length only `a` explains, the length only
/// `b` explains (per edge, `a[k]` and `b[k]`) and the length of all of them.
fn disputed_lengths(edges: &[Edge], a: &[bool], b: &[bool], min_len: f64) -> (f64, f64, f64) {
    let (mut only_a, mut only_b, mut total) = (0.0, 0.0, 0.0);
    for ((e, &x), &y) in edges.iter().zip(a).zip(b) {
        if e.length_rad < min_len {
            continue;
        }
        total += e.length_rad;
        match (x, y) {
            (true, false) => only_a += e.length_rad,
            (false, true) => only_b += e.length_rad,
            _ => {}
        }
    }
    (only_a, only_b, total)
}

/// Keeps the sweep's best distinct candidates so far (by merit, the carried ones as
/// polished on this frame among them) to be polished again on the next search's frame.
fn carry<'c>(carried: &mut [Option<Pose>; STARTS], candidates: impl Iterator<Item = &'c Candidate>) {
    let mut best: [Option<Candidate>; STARTS] = [None; STARTS];
    for c in candidates {
        if best
            .iter()
            .flatten()
            .any(|b| init::same_pose(&b.pose, &c.pose, BASIN_M, BASIN_RAD))
        {
            continue;
        }
        // Into the list, best merit first, the worst falling off its end.
        let mut item = Some(*c);
        for slot in best.iter_mut() {
            match (slot.as_ref(), item.as_ref()) {
                (None, _) => {
                    *slot = item.take();
                    break;
                }
                (Some(b), Some(i)) if i.merit() > b.merit() => std::mem::swap(slot, &mut item),
                _ => {}
            }
        }
    }
    for (slot, c) in carried.iter_mut().zip(best) {
        *slot = c.map(|c| c.pose);
    }
}

impl<'m> Tracker<'m> {
    /// Whether a search is under way.
    pub fn searching(&self) -> bool {
        self.pending.is_some()
    }

    /// The search under way, if any: why frames are not being tracked just now.
    pub fn search_under_way(&self) -> Option<SearchKind> {
        let pending = self.pending.as_ref()?;
        Some(if pending.relocalisation.is_some() {
            SearchKind::Relocalisation
        } else if self.state == TrackerState::Initialising {
            SearchKind::Initialisation
        } else {
            SearchKind::Reinitialisation
        })
    }

    /// Starts a search of the current state's volume on this frame's `edges` (module
    /// `background`).
    pub(super) fn start_search(&mut self, edges: &[Edge], timestamp_ns: u64) {
        let Some(mut job) = self.job.take() else {
            return;
        };
        let volume = self.search_volume();
        let budget = self.search_budget();
        let i = &self.cfg.initialisation;
        let breadth = if self.widen {
            (
                i.wide_edges_considered as usize,
                i.wide_segments_considered as usize,
                i.wide_samples_per_cell as usize,
            )
        } else {
            (
                i.edges_considered as usize,
                i.segments_considered as usize,
                i.samples_per_cell as usize,
            )
        };
        // After a loss the rig cannot have turned further than its turn rate allows since
        // the last good frame: the mirror twin of a symmetric room is refused.
        let turn_limit = match (self.state, self.last_good) {
            (TrackerState::Lost, Some(p)) => Some((p.rotation, self.max_turn_rad(timestamp_ns))),
            _ => None,
        };
        // After a loss, a candidate must also explain about as much as the frames before
        // it did; the requirement relaxes with every failed attempt, since the rig may
        // have walked somewhere that is seen less well.
        let floor = match self.state {
            TrackerState::Lost => self.explained_floor(self.search_attempts),
            _ => 0.0,
        };
        // Quarter-turn twins are worth searching only where any heading is plausible.
        let yaw_twins = turn_limit.is_none_or(|(_, limit)| limit >= std::f64::consts::PI);
        let rng = SmallRng::seed_from_u64(self.rng.random());
        job.prepare(edges, volume, budget, breadth, yaw_twins, turn_limit, rng);
        if self.cfg.initialisation.sweep_volume {
            job.set_sweep_from(self.sweep_from_m);
            job.set_starts(self.carried);
        }
        let pending = PendingSearch {
            started_ns: timestamp_ns,
            due_ns: timestamp_ns.saturating_add(u64::try_from(budget.as_nanos()).unwrap_or(u64::MAX)),
            volume,
            grown: self.hint_grown_m() > 0.0,
            turn_limit,
            floor,
            relocalisation: None,
        };
        self.launch(job, pending);
    }

    /// The budget of the search the current state would start: the whole model's or a volume's.
    pub(super) fn search_budget(&self) -> Duration {
        let budget_ms = if self.search_volume().diameter_m.is_none() {
            self.cfg.initialisation.whole_model_time_budget_ms
        } else {
            self.cfg.initialisation.time_budget_ms
        };
        Duration::from_secs_f64(budget_ms.max(0.0) / 1e3)
    }

    /// Sends a prepared job to the worker (or runs it here without one) and marks it under way.
    pub(super) fn launch(&mut self, mut job: Box<SearchJob<'m>>, pending: PendingSearch) {
        // The job is at home only here: the owner's stop flags given since reach it now.
        for stop in &self.stops {
            job.add_cancel(stop);
        }
        self.pending = Some(pending);
        self.stats.searches += 1;
        self.progress.set_kind(self.search_under_way());
        match &self.link {
            Some(link) => {
                if let Err(e) = link.jobs.send(job) {
                    // The worker is gone: search here.
                    self.link = None;
                    let mut job = e.into_inner();
                    job.run();
                    self.job = Some(job);
                }
            }
            None => {
                job.run();
                self.job = Some(job);
            }
        }
    }

    /// Whether the search under way is done (its job at home, or back from the worker now).
    pub(super) fn search_done(&mut self) -> bool {
        if self.job.is_some() {
            return true;
        }
        let Some(link) = self.link.as_ref() else {
            return true;
        };
        match link.done.try_recv() {
            Ok(job) => {
                self.job = Some(job);
                true
            }
            Err(crossbeam::channel::TryRecvError::Empty) => false,
            // The worker is gone: `collect_search` says so.
            Err(crossbeam::channel::TryRecvError::Disconnected) => true,
        }
    }

    /// The finished job of the search under way: at home already, or back from the worker
    /// (waiting for it, counted, if it is not done).
    pub(super) fn collect_search(&mut self) -> Option<Box<SearchJob<'m>>> {
        if let Some(job) = self.job.take() {
            return Some(job);
        }
        let link = self.link.as_ref()?;
        if let Ok(job) = link.done.try_recv() {
            return Some(job);
        }
        let waited = Instant::now();
        let job = link.done.recv().ok();
        self.stats.search_waits += 1;
        self.stats.search_wait_time += waited.elapsed();
        if job.is_none() {
            self.link = None;
        }
        job
    }

    /// The candidates being weighed while initialising: pose, mean merit so far
    /// ([`Candidate::merit`], higher is better), frames scored, and whether it is still in the
    /// running.
    pub fn candidates(&self) -> impl Iterator<Item = Weighed> + '_ {
        self.confirming[..self.confirm_count].iter().map(|c| Weighed {
            pose: c.pose,
            merit: c.merit_sum / c.frames.max(1) as f64,
            frames: c.frames,
            alive: c.alive,
        })
    }

    /// Figure 5 (started here, run off the frame path and taken up by [`Tracker::adopt`]) plus
    /// the confirmation of candidates over the next frames.
    pub(super) fn initialise(&mut self, edges: &[Edge], timestamp_ns: u64) -> FrameResult {
        let started = Instant::now();
        let mut result = FrameResult::empty(self.state);
        if self.confirm_count == 0 {
            self.start_search(edges, timestamp_ns);
            result.match_time = started.elapsed();
            return result;
        }
        // Each confirmation frame applies the search's acceptance test again: a candidate that
        // explains less than `accept_explained_fraction` of what it predicts here is dropped,
        // and when none is left the next frame searches afresh. (The wrong commits in `lab`'s
        // initialisation trials were candidates that barely passed on the search frame and
        // failed it on the next while the truth was never found.) One accepted by resolved
        // lines is judged by them again.
        for k in 0..self.confirm_count {
            if !self.confirming[k].alive {
                continue;
            }
            let polished = self.init.polish(&self.confirming[k].pose, edges);
            let passes = polished.is_some_and(|c| {
                acceptable(&self.cfg, &c) || (self.confirming[k].resolved && self.resolved_acceptable(&c, edges))
            });
            match polished {
                Some(c) if passes => {
                    let slot = &mut self.confirming[k];
                    slot.pose = c.pose;
                    slot.merit_sum += c.merit();
                    slot.frames += 1;
                }
                _ => self.confirming[k].alive = false,
            }
        }
        let mut result = self.decide(edges, timestamp_ns, result);
        result.match_time = started.elapsed();
        result
    }

    /// Takes up a finished search on its own frame: an initialisation's or a relocalisation's.
    pub(super) fn take_up(&mut self, pending: PendingSearch) -> FrameResult {
        let result = match pending.relocalisation {
            Some(r) => self.conclude_relocalisation(r, pending.started_ns),
            None => self.adopt(pending),
        };
        self.last_time = pending.started_ns;
        result
    }

    /// Takes up a finished initialisation search on its own frame (the job holds that frame's edges): its
    /// acceptable candidates go to confirmation, and a clear decision commits there and then.
    fn adopt(&mut self, pending: PendingSearch) -> FrameResult {
        let mut result = FrameResult::empty(self.state);
        let Some(job) = self.collect_search() else {
            return result;
        };
        let PendingSearch {
            volume,
            grown,
            turn_limit,
            floor,
            started_ns,
            ..
        } = pending;
        let (found, report) = job.result();
        let report = *report;
        // A sweep's later search judges its own candidates together with the earlier
        // searches' best, polished again on this frame (`carried`; none without a sweep).
        let polished = job.polished();
        let candidates = || found.iter().chain(polished.iter().flatten());
        if report.cancelled {
            // Cut short by a stop: nothing of it is judged, and the search state stays as it
            // was (the tracker is going away).
            self.stats.searches_cancelled += 1;
            self.job = Some(job);
            self.last_time = started_ns;
            return result;
        }
        // A volume without a valid node was searched out to the nearest ones.
        let volume = SearchVolume {
            diameter_m: report.widened_to_m.or(volume.diameter_m),
            ..volume
        };
        let plausible = |c: &Candidate| turn_limit.is_none_or(|(r, limit)| c.pose.rotation.angle_to(&r) <= limit);
        // And it must be a clear winner: every other candidate of the search that is not in
        // its basin (the same place turned, or a step away) explains at most
        // `clear_winner_ratio` of what it explains. Repeated structure (the twin turned a
        // half or quarter round, the next door along) is refused by evidence; "no pose yet"
        // is better than a wrong one.
        let ratio = self.cfg.initialisation.clear_winner_ratio;
        // A rival within the ratio may still be beaten by evidence: the best does at least as
        // well by each of the merit's three parts (explained, support, blank), and the edges
        // exactly one of the two explains side with it (`disputed_share_max`). Only the best
        // can win so.
        let best = candidates().max_by(|a, b| a.merit().total_cmp(&b.merit())).copied();
        let disputes_won = best.is_some_and(|b| {
            candidates()
                .filter(|o| !init::same_pose(&o.pose, &b.pose, BASIN_M, BASIN_RAD))
                .filter(|o| o.merit() > ratio * b.merit())
                .all(|o| {
                    b.explained >= o.explained
                        && b.support >= o.support
                        && b.blank <= o.blank
                        && self.wins_dispute(&b.pose, &o.pose, job.edges())
                })
        });
        let clear = |c: &Candidate| {
            let is_best = best.is_some_and(|b| b.pose == c.pose);
            candidates()
                .filter(|o| !init::same_pose(&o.pose, &c.pose, BASIN_M, BASIN_RAD))
                .all(|o| o.merit() <= ratio * c.merit() || (is_best && disputes_won))
        };
        // And it must lie in the volume searched (the polish may carry a start beyond it): a
        // hint says where the rig is. Candidates outside still count as rivals above.
        let inside = |c: &Candidate| within(&volume, &c.pose);
        // A hint grown by the walk the rig may have made since (module `hint_age`) is judged
        // only when the search looked at every cell of it: the part left unlooked at may hold
        // the rig, and with it the rival that would refuse what the rest offers (the door along
        // a corridor, module `hint_age`).
        let looked_at_all = !grown || report.plan_cells_scanned >= report.plan_cells_in_volume;
        // A search that looked at every cell of its volume saw every rival there, and may accept
        // by the share explained over the lines the matcher resolves
        // (`initialisation.accept_resolved_lines`): asked only of the candidates that pass every
        // other test, since it is quadratic in the segments in sight. (From a part of a volume,
        // FZK-Haus committed a look-alike 1.13 m off so: the truth that would have refused it lay
        // in the cells not reached.)
        let mut resolved = [None::<Pose>; RESOLVED_MAX];
        if self.cfg.initialisation.accept_resolved_lines && report.plan_cells_scanned >= report.plan_cells_in_volume {
            let mut n = 0;
            for c in candidates() {
                if n == RESOLVED_MAX {
                    break;
                }
                let near_miss = c.explained < self.cfg.initialisation.accept_explained_fraction
                    && plausible(c)
                    && c.explained >= floor
                    && inside(c)
                    && clear(c)
                    && looked_at_all;
                if near_miss && self.resolved_acceptable(c, job.edges()) {
                    resolved[n] = Some(c.pose);
                    n += 1;
                }
            }
        }
        let by_resolved = |c: &Candidate| resolved.contains(&Some(c.pose));
        let accepted = |c: &&Candidate| {
            (acceptable(&self.cfg, c) || by_resolved(c))
                && plausible(c)
                && c.explained >= floor
                && inside(c)
                && clear(c)
                && looked_at_all
        };
        // With `sweep_volume`, a search that ran out of budget before it looked at every cell
        // of its volume decides nothing: the next one goes on from the nearest cell it left (a sweep), its
        // best candidates carried along, at the same breadth and volume; only the search that
        // ends the sweep judges, with every part's best as rivals. (Judged part by part, a
        // sweep of the lab committed a pose 1.6 m off, the next doorway along, before it had
        // reached the truth: a part of a volume does not hold the rivals that refuse it.)
        //
        // A failed search over the whole volume is repeated once more broadly; if that fails
        // too, the volume doubles and the breadth is normal again (widening a large volume
        // only lets the time budget cover fewer cells).
        let sweep = self.cfg.initialisation.sweep_volume;
        let sweeping = sweep && report.swept_to_m.is_some_and(|m| m > self.sweep_from_m);
        let failed = sweeping || !candidates().any(|c| accepted(&c));
        if failed && sweep {
            carry(&mut self.carried, candidates());
        }
        if sweeping {
            self.sweep_from_m = report.swept_to_m.unwrap_or(0.0);
        } else {
            self.sweep_from_m = 0.0;
            if failed && self.widen {
                self.volume_level += 1;
            }
            self.widen = failed && !self.widen;
        }
        let mut n = 0;
        for c in candidates()
            .filter(accepted)
            .filter(|_| !sweeping)
            .take(self.confirming.len())
        {
            self.confirming[n] = Confirming {
                pose: c.pose,
                merit_sum: c.merit(),
                frames: 1,
                alive: true,
                resolved: !acceptable(&self.cfg, c),
            };
            n += 1;
        }
        self.confirm_count = n;
        if self.search_attempts > 0 || self.stats.first_search.is_some() {
            self.stats.reinitialisations += 1;
        }
        self.search_attempts += 1;
        self.stats.search_time += report.elapsed;
        self.stats.plan_cells_in_volume += report.plan_cells_in_volume as u64;
        self.stats.plan_cells_scanned += report.plan_cells_scanned as u64;
        self.stats.search_backstops += u64::from(report.backstop);
        self.stats.first_search.get_or_insert(report.elapsed);
        result.event = Some(TrackerEvent::Searched(report));
        if n > 0 {
            result = self.decide(job.edges(), started_ns, result);
        }
        self.job = Some(job);
        self.last_time = started_ns;
        result
    }

    /// Whether `c` passes the acceptance test with its share explained counted over resolved
    /// lines ([`Initialiser::explained_resolved`]) in place of [`Candidate::explained`].
    fn resolved_acceptable(&mut self, c: &Candidate, edges: &[Edge]) -> bool {
        let resolved = Candidate {
            explained: self.init.explained_resolved(&c.pose, edges),
            ..*c
        };
        acceptable(&self.cfg, &resolved)
    }

    /// Whether a frame's `measured` pose passes the acceptance test of the commit on trial
    /// (module doc, "Frames agreeing"); true with no commit on trial (a relocalisation's probation
    /// asks only that maintenance holds the pose).
    pub(super) fn trial_passes(&mut self, measured: &Pose, edges: &[Edge]) -> bool {
        let Some(trial) = self.probation.trial else {
            return true;
        };
        let (inliers, explained, support) = self.init.acceptance_scores(measured, edges);
        passes_acceptance(&self.cfg, inliers, explained, support)
            || (trial.resolved
                && passes_acceptance(
                    &self.cfg,
                    inliers,
                    self.init.explained_resolved(measured, edges),
                    support,
                ))
    }

    /// Whether `best` beats `rival` on the frame's `edges` by the edges exactly one of the two
    /// explains (`initialisation.disputed_share_max`, `disputed_min_fraction`).
    fn wins_dispute(&mut self, best: &Pose, rival: &Pose, edges: &[Edge]) -> bool {
        let i = &self.cfg.initialisation;
        let (share_max, min_fraction) = (i.disputed_share_max, i.disputed_min_fraction);
        if share_max <= 0.0 {
            return false;
        }
        let [a, b] = &mut self.explained_by;
        self.init.edges_explained(best, edges, a);
        self.init.edges_explained(rival, edges, b);
        let min_len = self.cfg.edges.min_edge_length_deg.to_radians();
        let (only_best, only_rival, total) = disputed_lengths(edges, a, b, min_len);
        let disputed = only_best + only_rival;
        disputed > 0.0 && disputed >= min_fraction * total && only_rival <= share_max * disputed
    }

    /// Whether the candidates under confirmation are told apart (and, for a narrow rig, agreed
    /// on): the winner is committed on this frame, or, when they cannot be told apart, the next
    /// frame searches afresh. `result` is this frame's answer so far.
    pub(super) fn decide(&mut self, edges: &[Edge], timestamp_ns: u64, mut result: FrameResult) -> FrameResult {
        let alive = self.confirming[..self.confirm_count].iter().filter(|c| c.alive).count();
        let frames = self.confirming[..self.confirm_count]
            .iter()
            .filter(|c| c.alive)
            .map(|c| c.frames)
            .max()
            .unwrap_or(0);
        let decided = alive == 1 || self.clear_winner();
        // A narrow rig's search that decided counts towards agreement: it commits only once
        // `narrow_rig_searches` decided searches in a row chose the same place.
        let agreement = match (decided, self.narrow) {
            (true, true) => {
                let best = self.best_confirming().map(|(_, c)| c.pose);
                let n = match (self.agreed, best) {
                    (Some((place, n)), Some(p)) if init::same_pose(&p, &place, BASIN_M, BASIN_RAD) => n + 1,
                    _ => 1,
                };
                self.agreed = best.map(|p| (p, n));
                n
            }
            _ => u32::MAX,
        };
        if alive == 0 || (frames >= self.cfg.initialisation.confirm_frames && !decided) {
            // Nothing left, or the frames did not tell the candidates apart: search afresh. Two
            // places that stayed alike are the ambiguity a narrow rig's agreement waits out.
            if alive > 1 {
                self.agreed = None;
            }
            self.confirm_count = 0;
        } else if decided && agreement < self.cfg.initialisation.narrow_rig_searches {
            // Not yet agreed: search afresh.
            self.confirm_count = 0;
        } else if decided {
            self.agreed = None;
            let (k, winner) = self.best_confirming().expect("one candidate is alive");
            let changed_mind = k != 0;
            if changed_mind {
                self.stats.changed_mind += 1;
            }
            let candidates = self.confirm_count;
            self.confirm_count = 0;
            // On trial until `confirm_frames` frames passed the acceptance test at it, the
            // confirmation frames it already passed counted; a re-initialisation after a loss
            // for at least the next frame (module doc, "On trial").
            let lost = self.state == TrackerState::Lost;
            let frames_left = self
                .cfg
                .initialisation
                .confirm_frames
                .saturating_sub(winner.frames)
                .max(u32::from(lost))
                .min(super::PROBATION_LINKS as u32 - 1);
            let trial = (frames_left > 0).then(|| {
                (
                    self.last_good.filter(|_| lost).map(|p| (p, self.last_good_time)),
                    Trial {
                        explained_ref: self.explained_ref,
                        volume_level: self.volume_level,
                        frames_left,
                        first: !lost,
                        resolved: winner.resolved,
                    },
                )
            });
            let searched = result.event;
            result = self.commit(&winner.pose, edges, timestamp_ns);
            result.event = Some(TrackerEvent::Committed {
                candidates,
                changed_mind,
            });
            if let Some((held, trial)) = trial {
                result = self.on_trial(held, trial, result, searched, timestamp_ns);
            }
        }
        result
    }

    /// A commit goes on trial (module doc, "On trial"): its frame's answer `committed` waits
    /// for the next frames' maintenance to hold the pose (`Trial::frames_left`), and this frame
    /// shows only its search's report (`searched`). `held` is the last pose maintenance held
    /// before a loss.
    fn on_trial(
        &mut self,
        held: Option<(Pose, u64)>,
        trial: Trial,
        committed: FrameResult,
        searched: Option<TrackerEvent>,
        timestamp_ns: u64,
    ) -> FrameResult {
        self.probation.links.clear();
        self.probation.held = held;
        self.probation.trial = Some(trial);
        // One link: a probation is empty while the lock is lost.
        let _ = self.probation.links.push((timestamp_ns, committed));
        let mut shown = FrameResult::empty(TrackerState::Tracking);
        shown.event = searched;
        shown
    }

    /// The live candidate with the best mean merit, and its index (0: the search's own best).
    fn best_confirming(&self) -> Option<(usize, Confirming)> {
        self.confirming[..self.confirm_count]
            .iter()
            .enumerate()
            .filter(|(_, c)| c.alive)
            .max_by(|a, b| (a.1.merit_sum / a.1.frames as f64).total_cmp(&(b.1.merit_sum / b.1.frames as f64)))
            .map(|(k, c)| (k, *c))
    }

    /// Whether the best candidate so far beats every other outside its basin by the configured
    /// margin (their mean merit at most `clear_winner_ratio` × its): no further frames are needed
    /// to decide. Candidates in its basin (the same place a few centimetres or a degree apart,
    /// as the search's own clear-winner test counts them) are the same answer, not rivals: they
    /// score alike on every frame, and counting them kept the tracker searching afresh forever
    /// where the search had found nothing but the truth (ZInD `pano_33`).
    fn clear_winner(&self) -> bool {
        let live = || self.confirming[..self.confirm_count].iter().filter(|c| c.alive);
        let mean = |c: &Confirming| c.merit_sum / c.frames.max(1) as f64;
        let Some(best) = live().max_by(|a, b| mean(a).total_cmp(&mean(b))) else {
            return false;
        };
        let ratio = self.cfg.initialisation.clear_winner_ratio;
        live()
            .filter(|c| !init::same_pose(&c.pose, &best.pose, BASIN_M, BASIN_RAD))
            .all(|c| mean(c) <= ratio * mean(best))
    }

    /// Where to search now: the hint or the whole model at first; after a loss, around the
    /// last good pose, the volume doubling in diameter with every failed attempt.
    pub(super) fn search_volume(&self) -> SearchVolume {
        match (self.state, self.last_good) {
            (TrackerState::Lost, Some(p)) => {
                let base = self.cfg.initialisation.search_diameter_m;
                let grow = 2f64.powi(self.volume_level.min(6) as i32);
                SearchVolume {
                    centre: Point3::from(p.translation.vector),
                    diameter_m: Some(base * grow).filter(|d| *d < 64.0 * base),
                }
            }
            _ => match self.hint {
                // The hint grown by the walk the rig may have made since (module `hint_age`).
                Some(h) => SearchVolume {
                    diameter_m: h.diameter_m.map(|d| d + self.hint_grown_m()),
                    ..h
                },
                None => SearchVolume {
                    centre: Point3::origin(),
                    diameter_m: None,
                },
            },
        }
    }

    /// How much a hint's diameter has grown (m): twice the way the rig may have walked since
    /// the hint's frame at `motion.max_speed_m_s` (module `hint_age`).
    fn hint_grown_m(&self) -> f64 {
        match (self.state, self.hint) {
            (TrackerState::Initialising, Some(h)) if h.diameter_m.is_some() => {
                2.0 * self.cfg.motion.max_speed_m_s.max(0.0) * self.hint_age.moving_s()
            }
            _ => 0.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{disputed_lengths, within, SearchVolume, VOLUME_SLACK_M};
    use crate::test_edges::edge_on;
    use nalgebra::{Point3, Vector3};
    use omnitrack_core::geometry::{EdgePlane, Pose};

    #[test]
    fn the_disputed_edges_are_those_exactly_one_pose_explains_by_length_and_short_ones_do_not_count() {
        // Edges 0.1, 0.2, 0.3, 0.4 and 0.01 rad long.
        let edges: Vec<_> = [0.1f64, 0.2, 0.3, 0.4, 0.01]
            .iter()
            .map(|&len| {
                let b = Vector3::new(len.cos(), len.sin(), 0.0);
                edge_on(
                    0,
                    EdgePlane::from_rays(Point3::origin(), &Vector3::x(), &b).unwrap(),
                    50,
                )
            })
            .collect();
        let a = [true, true, false, false, true];
        let b = [true, false, true, true, false];
        let (only_a, only_b, total) = disputed_lengths(&edges, &a, &b, 0.05);
        assert!((only_a - 0.2).abs() < 1e-12, "{only_a}");
        assert!((only_b - 0.7).abs() < 1e-12, "{only_b}");
        assert!((total - 1.0).abs() < 1e-12, "{total}");
        let (only_a, only_b, total) = disputed_lengths(&edges, &a, &a, 0.0);
        assert_eq!((only_a, only_b), (0.0, 0.0));
        assert!((total - 1.01).abs() < 1e-12);
    }

    #[test]
    fn a_pose_is_within_a_volume_up_to_the_slack_and_always_within_the_whole_model() {
        let volume = SearchVolume {
            centre: Point3::new(1.0, 2.0, 1.5),
            diameter_m: Some(3.0),
        };
        let at = |x: f64| Pose::from_parts(nalgebra::Translation3::new(1.0 + x, 2.0, 1.5), Default::default());
        assert!(within(&volume, &at(1.5 + 0.5 * VOLUME_SLACK_M)));
        assert!(!within(&volume, &at(1.5 + 2.0 * VOLUME_SLACK_M)));
        let whole = SearchVolume {
            diameter_m: None,
            ..volume
        };
        assert!(within(&whole, &at(1e3)));
    }
}
