//! Shared by the allocation tests: a global allocator that counts the allocations (and
//! reallocations) made on threads that asked for it, so that one test can assert that a code
//! path allocates nothing while other threads (the test harness, worker pools) go on freely.
//!
//! A test binary that uses it declares the allocator itself (a global allocator is per binary):
//! `#[global_allocator] static ALLOCATOR: common::Counting = common::Counting;`.
#![allow(dead_code)] // each test binary uses a different part

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::process::Command;
use std::sync::atomic::{AtomicBool, AtomicI64, Ordering};

/// The shipped rig's file (`firmware_config/ladybug2.toml`), the rig most tests look through.
pub const SHIPPED_RIG: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/firmware_config/ladybug2.toml");

/// The shipped rig, loaded from [`SHIPPED_RIG`].
pub fn shipped_rig() -> omnitrack::Rig {
    omnitrack::Rig::load(std::path::Path::new(SHIPPED_RIG)).expect("the shipped rig loads")
}

/// Runs the `omnitrack` binary: (exit code, stdout, stderr).
pub fn omnitrack(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_omnitrack"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8(out.stdout).unwrap(),
        String::from_utf8(out.stderr).unwrap(),
    )
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

/// A rendered `lab` recording (default appearance, seed 11) in a temporary directory, with its
/// model, visibility table and ground truth: the fixture of the end-to-end tests.
#[cfg(feature = "desk")]
pub struct LabRecording {
    pub dir: tempfile::TempDir,
    pub rec: std::path::PathBuf,
    pub model: omnitrack::Model,
    pub table: omnitrack::visibility::VisibilityTable,
    pub truth: Vec<omnitrack::trajectory::Stamped>,
}

#[cfg(feature = "desk")]
pub fn lab_recording(frames: usize) -> LabRecording {
    lab_recording_with_rig(frames, "firmware_config/ladybug2.toml")
}

/// [`lab_recording`] rendered through another rig (`rig`: a path in the crate).
#[cfg(feature = "desk")]
pub fn lab_recording_with_rig(frames: usize, rig: &str) -> LabRecording {
    lab_recording_with(
        frames,
        rig,
        "default",
        &omnitrack::desk::recording::RecordingOptions::default(),
    )
}

/// [`lab_recording`] rendered through `rig` with other recording options (`label` names them).
#[cfg(feature = "desk")]
pub fn lab_recording_with(
    frames: usize,
    rig: &str,
    label: &str,
    options: &omnitrack::desk::recording::RecordingOptions,
) -> LabRecording {
    use omnitrack::capture::{Pacing, ReplaySource};
    use omnitrack::desk::recording::cached_scenario;
    use omnitrack::desk::scenario::{Scenario, ScenarioName};
    use omnitrack::visibility::build::{build_table, BuildOptions};
    let dir = tempfile::tempdir().unwrap();
    let rig_path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(rig);
    let rig_name = rig_path.file_stem().unwrap().to_string_lossy().into_owned();
    let rig = omnitrack::Rig::load(&rig_path).unwrap();
    let shared = shared_render(&format!("lab-{frames}f-{label}-{rig_name}"), |root| {
        cached_scenario(
            root,
            &Scenario::get(ScenarioName::Lab),
            frames,
            11,
            label,
            &rig,
            options,
            |_, _| {},
        )
        .unwrap()
        .0
    });
    // The test's own copy (images hard-linked): whatever a test writes stays in its folder.
    let rec = dir.path().join(shared.file_name().unwrap());
    copy_tree(&shared, &rec);
    let model = omnitrack::Model::load(&rec.join("model.obj")).unwrap();
    let table = build_table(&model, "model.obj", &BuildOptions::default());
    let truth = ReplaySource::open(&rec, Pacing::AsFastAsPossible)
        .unwrap()
        .ground_truth()
        .unwrap()
        .to_vec();
    LabRecording {
        dir,
        rec,
        model,
        table,
        truth,
    }
}

/// A rendered recording shared by every test binary and both test runs of CI (default and all
/// features): `target/tmp/renders/<fingerprint>/<key>`, made once by `render` (which renders into
/// the folder it is given and returns the recording's path). The fingerprint hashes the sources
/// that make a render (the desk, core, io and config crates) and `Cargo.lock`, so a changed
/// renderer never reuses an old render. Renders go to a private folder first and are moved into
/// place whole: two tests rendering the same one at once both see a complete recording.
#[cfg(feature = "desk")]
pub fn shared_render(key: &str, render: impl FnOnce(&std::path::Path) -> std::path::PathBuf) -> std::path::PathBuf {
    use std::hash::{Hash, Hasher};
    use std::path::Path;
    fn hash_tree(dir: &Path, h: &mut impl Hasher) {
        let mut entries: Vec<_> = std::fs::read_dir(dir).unwrap().flatten().map(|e| e.path()).collect();
        entries.sort();
        for p in entries {
            if p.is_dir() {
                hash_tree(&p, h);
            } else {
                p.file_name().hash(h);
                std::fs::read(&p).unwrap().hash(h);
            }
        }
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    // SipHash with fixed keys: the same sources give the same fingerprint in every process.
    #[allow(deprecated)]
    let mut h = std::hash::SipHasher::new();
    for krate in ["desk", "core", "io", "config"] {
        hash_tree(&root.join("crates").join(krate).join("src"), &mut h);
    }
    std::fs::read(root.join("Cargo.lock")).unwrap().hash(&mut h);
    let fingerprint = format!("{:016x}", h.finish());
    let cache = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("renders")
        .join(&fingerprint);
    let done = cache.join(key);
    if done.join("complete").exists() {
        return done;
    }
    if !cache.exists() {
        // Renders of older sources are never used again.
        for old in std::fs::read_dir(cache.parent().unwrap())
            .into_iter()
            .flatten()
            .flatten()
        {
            if old.file_name().to_str() != Some(fingerprint.as_str()) {
                let _ = std::fs::remove_dir_all(old.path());
            }
        }
    }
    std::fs::create_dir_all(&cache).unwrap();
    let scratch = tempfile::tempdir_in(&cache).unwrap();
    let made = render(scratch.path());
    // Fails when another test put it there first: that one is whole too.
    let _ = std::fs::rename(&made, &done);
    assert!(done.join("complete").exists(), "render {key} not in place");
    done
}

/// Copies the folder `from` to `to`, hard-linking its files where it can.
pub fn copy_tree(from: &std::path::Path, to: &std::path::Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap().flatten() {
        let (src, dst) = (e.path(), to.join(e.file_name()));
        if src.is_dir() {
            copy_tree(&src, &dst);
        } else if std::fs::hard_link(&src, &dst).is_err() {
            std::fs::copy(&src, &dst).unwrap();
        }
    }
}

/// Frames without a pose on time at the start of a replay at `period_ms` a frame, with a first
/// search of `budget_ms`: its result is taken up once its budget has passed on the recording's
/// clock, the frames kept meanwhile are then tracked `CATCH_UP_FRAMES` a frame (module
/// `tracker::background`), and the confirmation may take three frames more.
pub fn start_frames(budget_ms: f64, period_ms: f64) -> usize {
    use omnitrack::tracker::CATCH_UP_FRAMES;
    let due = (budget_ms / period_ms).ceil() as usize;
    let (mut kept, mut frame) = (due, due);
    while kept > CATCH_UP_FRAMES {
        kept = kept - CATCH_UP_FRAMES + 1;
        frame += 1;
    }
    frame + 3
}
