//! omnitrack-testkit: what the tests of every layer share, so that a crate's own `tests/` need
//! not go through the front door for it. A dev-dependency only; nothing of it reaches a build.
//!
//! In: nothing but the shipped rig file (`firmware_config/ladybug2.toml`). Out: a global
//! allocator that counts the allocations (and reallocations) made on threads that asked for it,
//! so that one test can assert that a code path allocates nothing while other threads (the test
//! harness, worker pools) go on freely; the bytes a thread or the whole process held meanwhile;
//! whether a thread is the test harness's own; a thread's page faults; and the shipped rig.
//!
//! A test binary that counts declares the allocator itself (a global allocator is per binary):
//! `#[global_allocator] static ALLOCATOR: omnitrack_testkit::Counting = omnitrack_testkit::Counting;`.

pub mod docs;

use omnitrack_core::Rig;
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicBool, AtomicI64, Ordering};

/// The shipped rig's file (`firmware_config/ladybug2.toml`), the rig most tests look through.
pub const SHIPPED_RIG: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../firmware_config/ladybug2.toml");

/// The shipped rig, loaded from [`SHIPPED_RIG`].
pub fn shipped_rig() -> Rig {
    Rig::load(std::path::Path::new(SHIPPED_RIG)).expect("the shipped rig loads")
}

/// Whether this is the test harness's own thread (on Linux its thread id is the process id). It
/// runs no test, only reports on them: its note that a test "has been running for over 60
/// seconds", which a loaded machine brings on in the middle of a counting window, allocates.
pub fn on_harness_thread() -> bool {
    #[cfg(target_os = "linux")]
    {
        // SAFETY: both calls only read the calling thread's and process's ids.
        unsafe { libc::gettid() == libc::getpid() }
    }
    #[cfg(not(target_os = "linux"))]
    {
        false
    }
}

/// The counting global allocator: the system allocator, noting what the threads that count ask.
pub struct Counting;

thread_local! {
    static ON: Cell<bool> = const { Cell::new(false) };
    static COUNT: Cell<u64> = const { Cell::new(0) };
    /// Bytes this thread allocated minus those it freed while counting, and the most it reached.
    static LIVE: Cell<i64> = const { Cell::new(0) };
    static PEAK: Cell<i64> = const { Cell::new(0) };
}

/// Whether every thread's allocations are summed into [`ALL_LIVE`] and [`ALL_PEAK`].
static ALL_ON: AtomicBool = AtomicBool::new(false);
static ALL_LIVE: AtomicI64 = AtomicI64::new(0);
static ALL_PEAK: AtomicI64 = AtomicI64::new(0);

/// An allocation (`grown` > 0) or a free (< 0) of `grown` bytes; `new` counts it as a call.
fn note_bytes(grown: i64, new: bool) {
    if ALL_ON.load(Ordering::Relaxed) {
        let live = ALL_LIVE.fetch_add(grown, Ordering::Relaxed) + grown;
        ALL_PEAK.fetch_max(live, Ordering::Relaxed);
    }
    // `try_with`: the allocator also runs while thread-locals are being torn down.
    let _ = ON.try_with(|on| {
        if on.get() {
            if new {
                let _ = COUNT.try_with(|n| n.set(n.get() + 1));
            }
            let _ = LIVE.try_with(|live| {
                live.set(live.get() + grown);
                let _ = PEAK.try_with(|peak| peak.set(peak.get().max(live.get())));
            });
        }
    });
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note_bytes(layout.size() as i64, true);
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note_bytes(layout.size() as i64, true);
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note_bytes(new_size as i64 - layout.size() as i64, true);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        note_bytes(-(layout.size() as i64), false);
        unsafe { System.dealloc(ptr, layout) }
    }
}

/// Runs `f` and returns its result with the heap allocations this thread made during it.
pub fn allocations_in<T>(f: impl FnOnce() -> T) -> (T, u64) {
    let before = COUNT.with(Cell::get);
    ON.with(|c| c.set(true));
    let out = f();
    ON.with(|c| c.set(false));
    (out, COUNT.with(Cell::get) - before)
}

/// The heap this thread used while running `f`: the most it held at once beyond what it held
/// before, and what it still held at the end (bytes).
pub fn heap_in<T>(f: impl FnOnce() -> T) -> (T, i64, i64) {
    LIVE.with(|c| c.set(0));
    PEAK.with(|c| c.set(0));
    ON.with(|c| c.set(true));
    let out = f();
    ON.with(|c| c.set(false));
    (out, PEAK.with(Cell::get), LIVE.with(Cell::get))
}

/// The most heap all threads of the process held at once while `f` ran, beyond what they held
/// before (bytes): for work spread over a thread pool. One such measurement at a time.
pub fn peak_heap_of_all_threads_in<T>(f: impl FnOnce() -> T) -> (T, i64) {
    ALL_LIVE.store(0, Ordering::SeqCst);
    ALL_PEAK.store(0, Ordering::SeqCst);
    ALL_ON.store(true, Ordering::SeqCst);
    let out = f();
    ALL_ON.store(false, Ordering::SeqCst);
    (out, ALL_PEAK.load(Ordering::SeqCst))
}

/// Minor page faults this thread has taken so far: each is a page of memory it wrote first, so
/// none over a stretch of work means the work took no memory beyond what it already held
/// (`getrusage(RUSAGE_THREAD)`; Linux only, 0 elsewhere).
pub fn minor_faults() -> u64 {
    #[cfg(target_os = "linux")]
    {
        // SAFETY: `getrusage` only writes the struct it is given.
        let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
        let r = unsafe { libc::getrusage(libc::RUSAGE_THREAD, &mut usage) };
        assert_eq!(r, 0, "getrusage");
        usage.ru_minflt as u64
    }
    #[cfg(not(target_os = "linux"))]
    {
        0
    }
}

/// The counter counts: one boxed value is one allocation (a test that cannot fail is no test).
/// The box itself goes through `black_box`: once inlined, LLVM may drop an allocation whose
/// pointer never escapes (it did without incremental compilation's many codegen units).
pub fn assert_counter_works() {
    let (b, n) = allocations_in(|| std::hint::black_box(Box::new(7u64)));
    drop(b);
    assert_eq!(n, 1, "the allocation counter missed an allocation");
}
