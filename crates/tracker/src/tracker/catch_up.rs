//! Frames that arrive while a search runs off the frame path (module
//! [`background`](crate::background)): kept in the backlog, the search taken up when its
//! budget has passed on the recording's clock, then the kept frames tracked, a few per arriving
//! frame, oldest first, their results handed out as late ([`Tracker::late`]); and at the end of
//! the frames, everything still kept worked off ([`Tracker::finish`]).
//!
//! In: each frame's edges and capture time while the tracker is behind. Out: the frame's own
//! result (a pose once the backlog has been worked off up to it) and the late results.

use super::{Tracker, CATCH_UP_FRAMES};
use crate::report::{FrameResult, TrackerState};
use omnitrack_edges::Edge;
use std::time::Instant;

impl Tracker<'_> {
    /// A frame that arrives while a search is under way, or while frames kept during one wait:
    /// it joins the backlog; a search that is due is taken up on its own frame; then up to
    /// [`CATCH_UP_FRAMES`] kept frames are tracked, oldest first. The frame gets a pose once
    /// the backlog has been worked off up to it.
    pub(super) fn behind(&mut self, edges: &[Edge], timestamp_ns: u64) -> FrameResult {
        let started = Instant::now();
        self.backlog.push(edges, timestamp_ns);
        if let Some(pending) = self.pending {
            // Not due yet; or due, but the worker is not done (a machine slower than the
            // reference, or loaded) and the frames do not wait for it. Taking a search up later
            // changes no pose (the same search, judged on its own frame, then the same kept
            // frames), only which of them are answered late; unless the backlog fills and is
            // thinned meanwhile (counted in `backlog_dropped`): the last backstop under load.
            let deferred = self.defer && timestamp_ns >= pending.due_ns && !self.search_done();
            if timestamp_ns < pending.due_ns || deferred {
                self.stats.search_deferrals += u64::from(deferred);
                let mut result = FrameResult::empty(self.state);
                result.match_time = started.elapsed();
                return result;
            }
            self.pending = None;
            let r = self.take_up(pending);
            self.note_late(pending.started_ns, r);
        }
        let mut result = None;
        for _ in 0..CATCH_UP_FRAMES {
            if self.pending.is_some() || self.backlog.is_empty() {
                break;
            }
            match self.catch_up_one() {
                Some((_, r)) if self.backlog.is_empty() => result = Some(r),
                Some((t, r)) => self.note_late(t, r),
                None => break,
            }
        }
        let mut result = result.unwrap_or_else(|| FrameResult::empty(self.state));
        result.match_time = started.elapsed();
        result
    }

    /// Tracks the oldest kept frame; a fresh search starts from it too. Not from the newest: a
    /// search that failed is followed by one on the next frame, as inline, so that the searches
    /// after a start stay near the hint's time (searching from the newest, the corridor's
    /// searches fell 1 s apart, the rig walked out of the hint's reach between them, and the
    /// sixth search committed the next doorway, 4 m off).
    pub(super) fn catch_up_one(&mut self) -> Option<(u64, FrameResult)> {
        // ... unless the kept frames span more than two search budgets (a worker slower than the
        // frames, searching again and again): then from the newest, so the lag stays bounded.
        if self.state != TrackerState::Tracking && self.confirm_count == 0 {
            let budget_ns = u64::try_from(self.search_budget().as_nanos()).unwrap_or(u64::MAX);
            if self.backlog.span_ns() > budget_ns.saturating_mul(2) {
                let before = self.backlog.dropped;
                self.backlog.keep_newest();
                self.stats.backlog_dropped += self.backlog.dropped - before;
            }
        }
        let mut buf = std::mem::take(&mut self.scratch);
        let t = self.backlog.pop_into(&mut buf);
        let r = t.map(|t| (t, self.step(&buf, t)));
        self.scratch = buf;
        self.stats.caught_up += u64::from(r.is_some());
        r
    }

    /// Keeps an earlier frame's result for [`Tracker::late`] when it has a pose or an event.
    pub(super) fn note_late(&mut self, timestamp_ns: u64, r: FrameResult) {
        if (r.pose.is_some() || r.event.is_some()) && self.late.len() < self.late.capacity() {
            self.stats.late_poses += u64::from(r.pose.is_some());
            self.late.push((timestamp_ns, r));
        }
    }

    /// The results of earlier frames worked out on the last call of [`Tracker::process`] or
    /// [`Tracker::finish`], oldest first, with their timestamps: the search frame's once its search
    /// is taken up, and the kept frames' as they are caught up on (only those with a pose or an
    /// event). They are older than the frames already answered, so a live subscriber does not
    /// want them; a trajectory does.
    pub fn late(&self) -> &[(u64, FrameResult)] {
        &self.late
    }

    /// The frames have ended: a search under way is taken up now (waiting for it) and every kept
    /// frame is tracked, their results in [`Tracker::late`], so that a recording's last second
    /// is not lost. Kept frames that would need a fresh search are dropped (counted).
    pub fn finish(&mut self) {
        self.late.clear();
        if let Some(pending) = self.pending.take() {
            let r = self.take_up(pending);
            self.note_late(pending.started_ns, r);
        }
        while !self.backlog.is_empty() {
            if self.state != TrackerState::Tracking && self.confirm_count == 0 {
                break;
            }
            match self.catch_up_one() {
                Some((t, r)) => self.note_late(t, r),
                None => break,
            }
        }
        // Relocalised poses (or a re-initialisation) no later frame held are not published.
        self.withdraw_probation();
        let before = self.backlog.dropped;
        while self.backlog.pop_into(&mut self.scratch).is_some() {
            self.backlog.dropped += 1;
        }
        self.stats.backlog_dropped += self.backlog.dropped - before;
    }
}
