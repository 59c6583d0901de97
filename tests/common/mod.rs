//! Shared by the front door's tests: running the `omnitrack` binary, the rendered `lab`
//! recordings of the end-to-end tests (made once, shared by every test binary), and the frames a
//! replay starts without a pose. What every layer's tests share (the counting allocator, the
//! harness thread, page faults, the shipped rig) is `omnitrack-testkit`'s, re-exported here.
//!
//! A test binary that counts declares the allocator itself (a global allocator is per binary):
//! `#[global_allocator] static ALLOCATOR: common::Counting = common::Counting;`.
#![allow(dead_code, unused_imports)] // each test binary uses a different part

pub use omnitrack_testkit::{
    allocations_in, assert_counter_works, heap_in, minor_faults, on_harness_thread, peak_heap_of_all_threads_in,
    shipped_rig, Counting, SHIPPED_RIG,
};
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
