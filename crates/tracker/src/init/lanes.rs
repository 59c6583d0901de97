//! The search's helper threads: the lanes of a search's grid scan and of its triplets run on
//! the search's own thread and on helpers started with the [`Initialiser`](super::Initialiser),
//! which wait for work between searches. Threads started per search (as the whole model's were,
//! scoped) would allocate on the search thread, which allocates nothing after start-up; with
//! these, a bounded volume runs lanes too ([`VOLUME_LANES`](super::VOLUME_LANES)).
//!
//! In: a slice of lanes (each a lane's own buffers) and a job run once per lane. Out: the lanes
//! as the job left them. Lane k is handed to whichever thread takes k first off a shared
//! counter, so no lane's work depends on the threads: the answer is the same on one core or
//! four, only the wall time differs.

use crossbeam::channel::{bounded, Receiver, Sender};
use omnitrack_edges::{thread_cpu_time, warm_up_blocking};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;

/// One call of [`LanePool::run`], as the helpers see it: a function that takes lanes off the
/// caller's counter until none is left, and the closure it runs on.
#[derive(Clone, Copy)]
struct Task {
    call: unsafe fn(*const ()),
    data: *const (),
}

// SAFETY: `data` points at a `Sync` closure on the stack of a [`LanePool::run`] that does not
// return (nor unwind) before every helper it sent the task to has said it is done with it.
unsafe impl Send for Task {}

/// Runs the closure `data` points at.
///
/// # Safety
/// `data` must point at a live `W`.
unsafe fn call<W: Fn() + Sync>(data: *const ()) {
    // SAFETY: the caller's contract.
    unsafe { (*data.cast::<W>())() }
}

struct Helper {
    tasks: Option<Sender<Task>>,
    handle: Option<JoinHandle<()>>,
}

/// Helper threads that run a search's lanes beside the search's own thread.
pub(super) struct LanePool {
    helpers: Vec<Helper>,
    done: Receiver<()>,
    /// A helper's lane panicked during the last run.
    panicked: Arc<AtomicBool>,
}

/// A pointer to the lanes that the threads may share: each lane index is taken once, off the
/// counter, so no two threads touch one lane.
struct Lanes<S>(*mut S);
// SAFETY: see the type's doc; the lanes themselves are `Send`.
unsafe impl<S: Send> Sync for Lanes<S> {}

/// Waits, even while unwinding, for the helpers still holding a task: they read the caller's
/// stack until then.
struct Outstanding<'p> {
    done: &'p Receiver<()>,
    sent: usize,
}

impl Drop for Outstanding<'_> {
    fn drop(&mut self) {
        for _ in 0..self.sent {
            // A helper that died dropped its sender only after it stopped touching the task.
            if self.done.recv().is_err() {
                break;
            }
        }
    }
}

impl LanePool {
    /// `threads` threads in all: the caller's and `threads - 1` helpers, each blocked on its
    /// channel once already, so that crossbeam's first-wait allocations happen here. The helpers
    /// add the CPU time they spend on lanes to `cpu_ns`.
    pub(super) fn new(threads: usize, cpu_ns: &Arc<AtomicU64>) -> LanePool {
        let helpers_wanted = threads.max(1) - 1;
        let (done_tx, done) = bounded::<()>(helpers_wanted.max(1));
        let panicked = Arc::new(AtomicBool::new(false));
        let mut helpers = Vec::with_capacity(helpers_wanted);
        for k in 0..helpers_wanted {
            let (tx, rx) = bounded::<Task>(1);
            let done_tx = done_tx.clone();
            let panicked = Arc::clone(&panicked);
            let cpu_ns = Arc::clone(cpu_ns);
            let spawned = std::thread::Builder::new()
                .name(format!("omnitrack-lane{}", k + 1))
                .spawn(move || {
                    warm_up_blocking(&rx);
                    let _ = done_tx.send(());
                    while let Ok(task) = rx.recv() {
                        let started = thread_cpu_time();
                        // SAFETY: `Task`'s contract: the closure lives until this helper's
                        // `done` is received.
                        let ran = std::panic::catch_unwind(|| unsafe { (task.call)(task.data) });
                        if ran.is_err() {
                            panicked.store(true, Ordering::Relaxed);
                        }
                        let spent = thread_cpu_time().saturating_sub(started);
                        cpu_ns.fetch_add(u64::try_from(spent.as_nanos()).unwrap_or(u64::MAX), Ordering::Relaxed);
                        if done_tx.send(()).is_err() {
                            break;
                        }
                    }
                });
            // Without a helper the lanes run on fewer threads, with the same answer
            // ([`LanePool::threads`] says how many).
            match spawned {
                Ok(handle) => helpers.push(Helper {
                    tasks: Some(tx),
                    handle: Some(handle),
                }),
                Err(_) => break,
            }
        }
        for _ in 0..helpers.len() {
            let _ = done.recv();
        }
        warm_up_blocking(&done);
        LanePool {
            helpers,
            done,
            panicked,
        }
    }

    /// Threads a run may use (the caller's included).
    pub(super) fn threads(&self) -> usize {
        self.helpers.len() + 1
    }

    /// Runs `job(k, &mut lanes[k])` once for every lane, on the calling thread and the helpers;
    /// returns when every lane is done. Allocates nothing. A lane that panicked on a helper
    /// panics here once all are done.
    pub(super) fn run<S: Send>(&self, lanes: &mut [S], job: impl Fn(usize, &mut S) + Sync) {
        let n = lanes.len();
        let next = AtomicUsize::new(0);
        let base = Lanes(lanes.as_mut_ptr());
        let work = || {
            let base = &base;
            loop {
                let k = next.fetch_add(1, Ordering::Relaxed);
                if k >= n {
                    break;
                }
                // SAFETY: k < n, and the counter hands each k out once (`Lanes`).
                let lane = unsafe { &mut *base.0.add(k) };
                job(k, lane);
            }
        };
        self.panicked.store(false, Ordering::Relaxed);
        let task = Task {
            call: call_of(&work),
            data: std::ptr::from_ref(&work).cast(),
        };
        let mut outstanding = Outstanding {
            done: &self.done,
            sent: 0,
        };
        for h in self.helpers.iter().take(n.saturating_sub(1)) {
            if h.tasks.as_ref().is_some_and(|tx| tx.send(task).is_ok()) {
                outstanding.sent += 1;
            }
        }
        work();
        drop(outstanding);
        if self.panicked.load(Ordering::Relaxed) {
            panic!("a search lane panicked on a helper thread");
        }
    }
}

/// The monomorphic caller of `work`, picked by the closure's type.
fn call_of<W: Fn() + Sync>(_: &W) -> unsafe fn(*const ()) {
    call::<W>
}

impl Drop for LanePool {
    fn drop(&mut self) {
        for h in &mut self.helpers {
            h.tasks = None;
        }
        for h in &mut self.helpers {
            if let Some(handle) = h.handle.take() {
                let _ = handle.join();
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_lane_runs_once_whatever_the_threads() {
        let cpu = Arc::default();
        for threads in 1..=4 {
            let pool = LanePool::new(threads, &cpu);
            assert_eq!(pool.threads(), threads);
            for n in [1, 2, 7] {
                let mut lanes = vec![0u64; n];
                pool.run(&mut lanes, |k, lane| *lane += k as u64 + 1);
                assert_eq!(
                    lanes,
                    (1..=n as u64).collect::<Vec<u64>>(),
                    "{threads} threads, {n} lanes"
                );
            }
        }
    }

    #[test]
    fn a_helpers_panic_reaches_the_caller_after_every_lane_is_done() {
        let pool = LanePool::new(2, &Arc::default());
        let finished = AtomicUsize::new(0);
        let mut lanes = vec![0usize; 8];
        let ran = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            pool.run(&mut lanes, |k, _| {
                if k == 3 {
                    panic!("lane 3");
                }
                std::thread::sleep(std::time::Duration::from_millis(2));
                finished.fetch_add(1, Ordering::Relaxed);
            })
        }));
        assert!(ran.is_err());
        // Every lane but the one that panicked ran (on whichever thread took it).
        assert_eq!(finished.load(Ordering::Relaxed), 7);
        // The pool still works.
        let mut lanes = vec![0usize; 3];
        pool.run(&mut lanes, |k, lane| *lane = k);
        assert_eq!(lanes, vec![0, 1, 2]);
    }
}
