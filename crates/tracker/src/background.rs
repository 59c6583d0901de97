//! Searches off the frame path (issue 24): the initialisation, re-initialisation and
//! relocalisation searches of KT §4.1–4.2 run on a worker thread while the frames go on; their
//! result is taken up at a frame fixed by the recording's own clock, and the frames that came
//! meanwhile are caught up on.
//!
//! In: a [`SearchJob`] filled by the tracker on the frame that starts a search (that frame's
//! edges, the volume, the breadth and the priors, and for a relocalisation the poses to polish).
//! Out: the same job with the search's candidates, the polished starts and the report, handed
//! back through [`SearchLink`] (or run on the calling thread when no worker is attached).
//!
//! **When the result is taken up.** A search started on a frame stamped t is taken up on the
//! first frame stamped at or after t + its budget (`time_budget_ms`, `relocalise_time_budget_ms`:
//! the work it may do, in reference time), or, when the worker is not done by then (a machine
//! slower than the reference, or loaded): a lossless replay waits for it (counted in
//! [`TrackerStats::search_waits`](crate::TrackerStats)); a live source
//! ([`Tracker::defer_late_searches`](crate::Tracker::defer_late_searches)) takes it up on the first
//! later frame that finds it done (counted in `search_deferrals`). A search stops on its work,
//! never the clock (module `init`), it is judged on its own frame, the kept frames are the same,
//! and a fresh search starts from the oldest kept frame: so a recording gives the
//! same poses whether the search ran on a worker or inline, on an idle or a loaded machine; only
//! which of them come late can differ (a test in `tests/tracker.rs` checks it). The exception, a
//! backstop: a live source whose backlog fills while it does not wait thins it (counted in
//! `backlog_dropped`), and the kept frames then depend on the load.
//!
//! **The frames in between.** They are kept in a `Backlog` (answered meanwhile with no pose).
//! The search is judged on its own frame's edges, which the job holds, exactly as if it had run
//! inline; then the kept frames are tracked oldest first, [`CATCH_UP_FRAMES`](crate::CATCH_UP_FRAMES)
//! per arriving frame, so that no frame's work grows by more than a few maintenance steps. A frame
//! is answered with its pose once the backlog has been worked off up to it; the earlier frames'
//! poses come out late ([`Tracker::late`](crate::Tracker::late)), for a trajectory, never for a
//! live subscriber that has had later frames. At the end of a recording
//! [`Tracker::finish`](crate::Tracker::finish) takes up a search under way and works off the rest.
//! A search that fails is followed by one on the oldest kept frame (the next after its own), as
//! inline: the searches after a start stay near the hint's time; unless the kept frames span
//! more than two search budgets (a worker slower than the frames), when it starts from the newest
//! and the older kept frames are dropped (counted): the lag stays bounded.
//!
//! Memory: the job (its own [`Initialiser`], an edge buffer for the largest frame) and the
//! backlog's slots are made once in [`Tracker::new`](crate::Tracker::new), and written through
//! then (`omnitrack_core::memory::resident`); the job travels by `Box` through bounded channels:
//! nothing is allocated, and no memory first written, per search or per kept frame.

use crate::init::{Candidate, InitReport, Initialiser, SearchVolume};
use crossbeam::channel::{Receiver, Sender};
use nalgebra::UnitQuaternion;
use omnitrack_core::geometry::Pose;
use omnitrack_core::memory::resident;
use omnitrack_edges::Edge;
use rand::rngs::SmallRng;
use std::time::Duration;

/// One search, with everything it needs and, once run, what it found.
pub struct SearchJob<'m> {
    init: Initialiser<'m>,
    edges: Vec<Edge>,
    volume: SearchVolume,
    rng: Option<SmallRng>,
    found: Vec<Candidate>,
    report: InitReport,
    /// Poses polished after the search (a relocalisation's prediction, last pose, …), and what
    /// each became.
    starts: [Option<Pose>; STARTS],
    polished: [Option<Candidate>; STARTS],
}

/// Most starts a job polishes after its search.
pub const STARTS: usize = 6;

impl<'m> SearchJob<'m> {
    /// A job with its own initialiser and room for `max_edges` edges.
    pub fn new(init: Initialiser<'m>, max_edges: usize) -> SearchJob<'m> {
        SearchJob {
            init,
            edges: resident(Vec::with_capacity(max_edges)),
            volume: SearchVolume {
                centre: nalgebra::Point3::origin(),
                diameter_m: None,
            },
            rng: None,
            found: resident(Vec::with_capacity(crate::init::MAX_CANDIDATES)),
            report: InitReport::default(),
            starts: [None; STARTS],
            polished: [None; STARTS],
        }
    }

    /// Fills the job for a search of `volume` on `edges` (copied, up to the buffer's capacity).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn prepare(
        &mut self,
        edges: &[Edge],
        volume: SearchVolume,
        budget: Duration,
        breadth: (usize, usize, usize),
        yaw_twins: bool,
        rotation_prior: Option<(UnitQuaternion<f64>, f64)>,
        rng: SmallRng,
    ) {
        self.edges.clear();
        let n = edges.len().min(self.edges.capacity());
        self.edges.extend_from_slice(&edges[..n]);
        self.volume = volume;
        self.init.set_time_budget(budget);
        self.init.set_breadth(breadth.0, breadth.1, breadth.2);
        self.init.set_yaw_twins(yaw_twins);
        self.init.set_rotation_prior(rotation_prior);
        self.init.set_sweep_from(0.0);
        self.rng = Some(rng);
        self.found.clear();
        self.report = InitReport::default();
        self.starts = [None; STARTS];
        self.polished = [None; STARTS];
    }

    /// A flag that stops the job's search too ([`Initialiser::add_cancel`]).
    pub(crate) fn add_cancel(&mut self, flag: &std::sync::Arc<std::sync::atomic::AtomicBool>) {
        self.init.add_cancel(flag);
    }

    /// The search continues a sweep of its volume: the cells nearer its centre than `m` (in
    /// plan) were looked at by earlier searches and are left ([`Initialiser::set_sweep_from`]).
    /// Call after [`Self::prepare`], which starts every search at the centre.
    pub(crate) fn set_sweep_from(&mut self, m: f64) {
        self.init.set_sweep_from(m);
    }

    /// Poses to polish on the job's edges once the search is done.
    pub(crate) fn set_starts(&mut self, starts: [Option<Pose>; STARTS]) {
        self.starts = starts;
    }

    /// What each start given to the job became, in order (None: not given, or its polish failed).
    pub fn polished(&self) -> &[Option<Candidate>; STARTS] {
        &self.polished
    }

    /// Runs the search (on whichever thread holds the job).
    pub fn run(&mut self) {
        let Some(rng) = self.rng.as_mut() else {
            return;
        };
        let (found, report) = self.init.run(&self.edges, &self.volume, rng);
        self.found.clear();
        let n = found.len().min(self.found.capacity());
        self.found.extend_from_slice(&found[..n]);
        self.report = report;
        self.rng = None;
        for (start, slot) in self.starts.iter().zip(self.polished.iter_mut()) {
            *slot = start.and_then(|p| self.init.polish(&p, &self.edges));
        }
    }

    /// The edges of the frame the search ran on.
    pub fn edges(&self) -> &[Edge] {
        &self.edges
    }

    /// The candidates found, best first, and the report.
    pub fn result(&self) -> (&[Candidate], &InitReport) {
        (&self.found, &self.report)
    }
}

/// A link between a tracker ([`Tracker::attach_search_worker`](crate::Tracker::attach_search_worker))
/// and the worker that runs its searches ([`SearchWorker::run`] on a thread of the caller's):
/// one job in flight at a time.
pub fn search_link<'m>() -> (SearchLink<'m>, SearchWorker<'m>) {
    let (jobs_tx, jobs_rx) = crossbeam::channel::bounded(1);
    let (done_tx, done_rx) = crossbeam::channel::bounded(1);
    // Crossbeam allocates a channel side's list of waiting threads the first time a thread waits
    // there, and the tracker may first wait for a search late in a run (the first search not
    // done when due): a waiter registered on each receiving side now, and taken off at once
    // (`try_select` registers without waiting), leaves the list its room. The sending sides never
    // wait: one job is in flight at a time, and each channel holds one.
    for rx in [&jobs_rx, &done_rx] {
        omnitrack_edges::warm_up_blocking(rx);
    }
    (
        SearchLink {
            jobs: jobs_tx,
            done: done_rx,
        },
        SearchWorker {
            jobs: jobs_rx,
            done: done_tx,
        },
    )
}

/// The worker's side of a [`search_link`].
pub struct SearchWorker<'m> {
    jobs: Receiver<Box<SearchJob<'m>>>,
    done: Sender<Box<SearchJob<'m>>>,
}

impl SearchWorker<'_> {
    /// Runs the jobs until the tracker's side is dropped.
    pub fn run(self) {
        search_worker(self.jobs, self.done);
    }
}

/// The tracker's side of a search worker: jobs out, finished jobs back.
pub struct SearchLink<'m> {
    pub jobs: Sender<Box<SearchJob<'m>>>,
    pub done: Receiver<Box<SearchJob<'m>>>,
}

/// The worker's loop: runs each job it receives and hands it back, until the tracker's side is
/// dropped.
/// A search that panics hands its job back with nothing found: the tracker searches afresh.
fn search_worker<'m>(jobs: Receiver<Box<SearchJob<'m>>>, done: Sender<Box<SearchJob<'m>>>) {
    while let Ok(mut job) = jobs.recv() {
        let ran = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| job.run()));
        if ran.is_err() {
            job.found.clear();
            job.rng = None;
        }
        if done.send(job).is_err() {
            break;
        }
    }
}

/// The frames that arrive while a search is under way, oldest first, kept so that the tracker
/// can catch up on them once the search's result is taken up (a few per frame period, module
/// doc of [`Tracker`](crate::Tracker)). The slots are made at start-up; a full backlog is
/// thinned to every other frame, so a long search keeps frames spread over its whole time at a
/// lower rate rather than its first or last stretch at the full rate.
pub(crate) struct Backlog {
    slots: Vec<(u64, Vec<Edge>)>,
    head: usize,
    len: usize,
    /// Frames dropped by thinning or passed over by a fresh search, since start.
    pub(crate) dropped: u64,
}

impl Backlog {
    /// Room for `frames` frames of up to `max_edges` edges each.
    pub(crate) fn new(frames: usize, max_edges: usize) -> Backlog {
        Backlog {
            // Resident from the start (`omnitrack_core::memory`): each search keeps its frames
            // in the slots after the last one's, and a slot written for the first time took
            // new memory, about 90 KB a relocalisation (issue 50).
            slots: (0..frames.max(2))
                .map(|_| (0, resident(Vec::with_capacity(max_edges))))
                .collect(),
            head: 0,
            len: 0,
            dropped: 0,
        }
    }

    pub(crate) fn is_empty(&self) -> bool {
        self.len == 0
    }

    fn is_full(&self) -> bool {
        self.len == self.slots.len()
    }

    fn at(&self, k: usize) -> usize {
        (self.head + k) % self.slots.len()
    }

    /// Keeps a copy of the frame stamped `timestamp_ns` (its edges up to a slot's capacity).
    pub(crate) fn push(&mut self, edges: &[Edge], timestamp_ns: u64) {
        if self.is_full() {
            self.thin();
        }
        let i = self.at(self.len);
        let slot = &mut self.slots[i];
        slot.0 = timestamp_ns;
        slot.1.clear();
        let n = edges.len().min(slot.1.capacity());
        slot.1.extend_from_slice(&edges[..n]);
        self.len += 1;
    }

    /// Keeps every other frame, the oldest among them.
    fn thin(&mut self) {
        let kept = self.len.div_ceil(2);
        for k in 1..kept {
            let (a, b) = (self.at(k), self.at(2 * k));
            self.slots.swap(a, b);
        }
        self.dropped += (self.len - kept) as u64;
        self.len = kept;
    }

    /// How far apart the oldest and the newest kept frames are (ns; 0 with fewer than two).
    pub(crate) fn span_ns(&self) -> u64 {
        if self.len < 2 {
            return 0;
        }
        self.slots[self.at(self.len - 1)]
            .0
            .saturating_sub(self.slots[self.head].0)
    }

    /// Drops all but the newest frame (counted).
    pub(crate) fn keep_newest(&mut self) {
        if self.len > 1 {
            self.dropped += (self.len - 1) as u64;
            self.head = self.at(self.len - 1);
            self.len = 1;
        }
    }

    /// Takes the oldest frame: its edges are swapped into `buf` (whose buffer takes the slot's
    /// place, so nothing is allocated) and its timestamp returned.
    pub(crate) fn pop_into(&mut self, buf: &mut Vec<Edge>) -> Option<u64> {
        if self.len == 0 {
            return None;
        }
        let slot = &mut self.slots[self.head];
        std::mem::swap(&mut slot.1, buf);
        let t = slot.0;
        self.head = (self.head + 1) % self.slots.len();
        self.len -= 1;
        Some(t)
    }
}

#[cfg(test)]
mod tests {
    use super::Backlog;

    fn stamps(b: &mut Backlog) -> Vec<u64> {
        let mut buf = Vec::with_capacity(4);
        std::iter::from_fn(|| b.pop_into(&mut buf)).collect()
    }

    #[test]
    fn a_full_backlog_keeps_every_other_frame_from_the_oldest_and_the_newest() {
        let mut b = Backlog::new(4, 4);
        for t in 1..=5 {
            b.push(&[], t);
        }
        // Full at 1–4: thinned to 1, 3, then 5 joins.
        assert_eq!(stamps(&mut b), [1, 3, 5]);
        assert_eq!(b.dropped, 2);
        // Across the ring's end.
        for t in 10..=16 {
            b.push(&[], t);
        }
        assert_eq!(stamps(&mut b), [10, 14, 16]);
    }

    #[test]
    fn the_span_runs_from_the_oldest_to_the_newest_and_keep_newest_keeps_one() {
        let mut b = Backlog::new(8, 4);
        assert_eq!(b.span_ns(), 0);
        for t in [10, 20, 35] {
            b.push(&[], t);
        }
        assert_eq!(b.span_ns(), 25);
        b.keep_newest();
        assert_eq!((b.span_ns(), b.dropped), (0, 2));
        assert_eq!(stamps(&mut b), [35]);
    }
}
