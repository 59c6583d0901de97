//! How far the search under way has got, readable from any thread while it runs: what a
//! person waiting seconds for a whole-model search is told (`omnitrack run`'s progress lines).
//!
//! In: the search's own charges ([`Initialiser::spend`](super::Initialiser), the grid's lanes
//! and the triplets' lanes as they go), its start and end, and the kind the tracker launched.
//! Out: a [`SearchSnapshot`] on demand; and a stop flag raised at a given amount of work
//! ([`SearchProgress::raise_at_work`]). Atomics only: a search adds to a counter per step (a
//! step is tens of microseconds or more); nothing is allocated, a lock is taken only once a
//! flag's work is reached, and the frame path never reads it.

use omnitrack_core::status::SearchKind;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicU8, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// The progress of one searcher's runs, shared (`Arc`) between the search and whoever watches.
#[derive(Debug)]
pub struct SearchProgress {
    /// When the watch began: `started_ns` counts from it.
    epoch: Instant,
    running: AtomicBool,
    /// [`SearchKind::wire`] of the search under way (set by the tracker as it launches it).
    kind: AtomicU8,
    started_ns: AtomicU64,
    /// Work units spent (module [`work`](super::work)) and the run's budget of them.
    work: AtomicU64,
    budget: AtomicU64,
    /// The volume's diameter in mm, or `u64::MAX` for the whole model.
    diameter_mm: AtomicU64,
    /// A flag to raise once a run's work reaches `raise_at` (`u64::MAX`: none).
    raise_at: AtomicU64,
    raise: Mutex<Option<Arc<AtomicBool>>>,
}

/// What a search under way has done so far.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SearchSnapshot {
    /// `None` only if the tracker did not say (a searcher run on its own).
    pub kind: Option<SearchKind>,
    /// Wall time since the search started.
    pub elapsed: Duration,
    /// Work spent and the budget, in work units (about a microsecond of the reference machine,
    /// module [`work`](super::work)): the share done is `work_done / work_budget`.
    pub work_done: u64,
    pub work_budget: u64,
    /// The volume searched: its diameter in metres, `None` for the whole model.
    pub diameter_m: Option<f64>,
}

impl SearchSnapshot {
    /// The share of the budget spent, 0 … 1.
    pub fn fraction_done(&self) -> f64 {
        if self.work_budget == 0 {
            return 1.0;
        }
        (self.work_done as f64 / self.work_budget as f64).clamp(0.0, 1.0)
    }
}

impl Default for SearchProgress {
    fn default() -> Self {
        SearchProgress {
            epoch: Instant::now(),
            running: AtomicBool::new(false),
            kind: AtomicU8::new(0),
            started_ns: AtomicU64::new(0),
            work: AtomicU64::new(0),
            budget: AtomicU64::new(0),
            diameter_mm: AtomicU64::new(u64::MAX),
            raise_at: AtomicU64::new(u64::MAX),
            raise: Mutex::new(None),
        }
    }
}

/// Marks the run finished when dropped, also when the search unwinds (a panic the worker
/// catches): a watcher never reports a search that has ended.
pub(crate) struct Running(Arc<SearchProgress>);

impl Drop for Running {
    fn drop(&mut self) {
        self.0.running.store(false, Ordering::Release);
    }
}

impl SearchProgress {
    /// The search under way, or `None` between searches.
    pub fn snapshot(&self) -> Option<SearchSnapshot> {
        if !self.running.load(Ordering::Acquire) {
            return None;
        }
        let started = Duration::from_nanos(self.started_ns.load(Ordering::Relaxed));
        let diameter_mm = self.diameter_mm.load(Ordering::Relaxed);
        Some(SearchSnapshot {
            kind: SearchKind::from_wire(self.kind.load(Ordering::Relaxed)).ok().flatten(),
            elapsed: self.epoch.elapsed().saturating_sub(started),
            work_done: self.work.load(Ordering::Relaxed),
            work_budget: self.budget.load(Ordering::Relaxed),
            diameter_m: (diameter_mm != u64::MAX).then(|| diameter_mm as f64 / 1e3),
        })
    }

    /// The tracker's word for the search it launches next (or launched last).
    pub(crate) fn set_kind(&self, kind: Option<SearchKind>) {
        self.kind.store(SearchKind::wire(kind), Ordering::Relaxed);
    }

    /// A run starts with `budget` work units over a volume of `diameter_m` (`None`: the whole
    /// model); it is under way until the returned guard is dropped.
    pub(crate) fn begin(self: &Arc<Self>, budget: u64, diameter_m: Option<f64>) -> Running {
        let now = u64::try_from(self.epoch.elapsed().as_nanos()).unwrap_or(u64::MAX);
        self.started_ns.store(now, Ordering::Relaxed);
        self.work.store(0, Ordering::Relaxed);
        self.budget.store(budget, Ordering::Relaxed);
        let mm = diameter_m.map_or(u64::MAX, |d| (d.max(0.0) * 1e3).min(u64::MAX as f64 / 2.0) as u64);
        self.diameter_mm.store(mm, Ordering::Relaxed);
        self.running.store(true, Ordering::Release);
        Running(Arc::clone(self))
    }

    /// The run's work so far, exactly (the searcher's own total).
    pub(crate) fn set_work(&self, work: u64) {
        self.work.store(work, Ordering::Relaxed);
        self.raise_if_reached(work);
    }

    /// Work a lane has done since it last said (lanes run on several threads at once; the
    /// searcher's total overwrites their sum once they are joined).
    pub(crate) fn add_work(&self, units: u64) {
        let work = self.work.fetch_add(units, Ordering::Relaxed).saturating_add(units);
        self.raise_if_reached(work);
    }

    /// Sets `flag` (once) as soon as a run of this searcher has spent `units` of work: a stop
    /// at a known point of a search (a stop flag the searcher was given, set from the search's
    /// own thread, is seen at its next check), where a flag set from another thread lands
    /// wherever the search happens to be. Where a search cut short at a given point stops is
    /// then the same on every run and under any load to within a step of each lane: the lanes
    /// add their work in the threads' order. For tests.
    pub fn raise_at_work(&self, flag: Arc<AtomicBool>, units: u64) {
        *self.raise.lock().unwrap_or_else(|e| e.into_inner()) = Some(flag);
        self.raise_at.store(units, Ordering::Release);
    }

    fn raise_if_reached(&self, work: u64) {
        if work < self.raise_at.load(Ordering::Acquire) {
            return;
        }
        self.raise_at.store(u64::MAX, Ordering::Release);
        if let Some(flag) = self.raise.lock().unwrap_or_else(|e| e.into_inner()).take() {
            flag.store(true, Ordering::Relaxed);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_snapshot_shows_the_run_under_way_and_nothing_after_it() {
        let p = Arc::new(SearchProgress::default());
        assert_eq!(p.snapshot(), None);
        p.set_kind(Some(SearchKind::Initialisation));
        let running = p.begin(1000, None);
        p.add_work(100);
        p.add_work(150);
        let s = p.snapshot().unwrap();
        assert_eq!(s.kind, Some(SearchKind::Initialisation));
        assert_eq!((s.work_done, s.work_budget, s.diameter_m), (250, 1000, None));
        assert!((s.fraction_done() - 0.25).abs() < 1e-12);
        p.set_work(900);
        assert_eq!(p.snapshot().unwrap().work_done, 900);
        drop(running);
        assert_eq!(p.snapshot(), None);
        let _running = p.begin(10, Some(3.0));
        let s = p.snapshot().unwrap();
        assert_eq!((s.work_done, s.diameter_m), (0, Some(3.0)));
    }

    #[test]
    fn a_flag_is_raised_when_the_work_reaches_its_mark_and_only_then() {
        let p = Arc::new(SearchProgress::default());
        let flag = Arc::new(AtomicBool::new(false));
        p.raise_at_work(Arc::clone(&flag), 300);
        let _running = p.begin(1000, None);
        p.add_work(100);
        p.set_work(299);
        assert!(!flag.load(Ordering::Relaxed));
        p.add_work(1);
        assert!(flag.load(Ordering::Relaxed));
        // Once: a flag cleared after it was raised stays clear.
        flag.store(false, Ordering::Relaxed);
        p.set_work(900);
        assert!(!flag.load(Ordering::Relaxed));
    }
}
