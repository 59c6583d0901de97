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

pub struct Counting;

thread_local! {
    static ON: Cell<bool> = const { Cell::new(false) };
    static COUNT: Cell<u64> = const { Cell::new(0) };
}

fn note() {
    // `try_with`: the allocator also runs while thread-locals are being torn down.
    let _ = ON.try_with(|on| {
        if on.get() {
            let _ = COUNT.try_with(|n| n.set(n.get() + 1));
        }
    });
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note();
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note();
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note();
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
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
    let rig = omnitrack::Rig::load(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(rig)).unwrap();
    let (rec, _) = cached_scenario(
        dir.path(),
        &Scenario::get(ScenarioName::Lab),
        frames,
        11,
        label,
        &rig,
        options,
        |_, _| {},
    )
    .unwrap();
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
