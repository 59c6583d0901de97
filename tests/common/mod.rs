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

/// The frames of the shipped rig's walk through the `lab` (5 Hz, default appearance) that is
/// rendered: a [`lab_recording`] of fewer frames is its first frames (rendering is most of what
/// the end-to-end tests cost: each walk of another length, a tour of its own, was rendered
/// anew, 54 frames more for the 6-, 8- and 40-frame recordings of the CLI and pipeline tests).
#[cfg(feature = "desk")]
pub const LAB_WALK_FRAMES: usize = 100;

/// The shipped rig's default `lab` walk of `frames` frames ([`LAB_WALK_FRAMES`] or fewer: its
/// first frames) in a temporary directory, with its model, visibility table and ground truth.
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
    let dir = tempfile::tempdir().unwrap();
    let rig_path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(rig);
    let rig_name = rig_path.file_stem().unwrap().to_string_lossy().into_owned();
    let rig = omnitrack::Rig::load(&rig_path).unwrap();
    let render = |frames: usize| {
        shared_render(&format!("lab-{frames}f-{label}-{rig_name}"), |root| {
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
        })
    };
    // The shipped rig's default lab is the first frames of one walk, rendered once.
    let shared = if label == "default" && rig_name == "ladybug2" && frames < LAB_WALK_FRAMES {
        let walk = render(LAB_WALK_FRAMES);
        shared_render(
            &format!("lab-{frames}of{LAB_WALK_FRAMES}f-{label}-{rig_name}"),
            |root| first_frames(&walk, frames, &root.join(format!("lab-{frames}f"))),
        )
    } else {
        render(frames)
    };
    // The test's own copy (images hard-linked): whatever a test writes stays in its folder.
    let rec = dir.path().join(shared.file_name().unwrap());
    copy_tree(&shared, &rec);
    let model = omnitrack::Model::load(&rec.join("model.obj")).unwrap();
    let table = shared_table(&model);
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

/// The visibility table of `model` as `build_table` makes it with the default options (what
/// `omnitrack run` builds), built once and shared like the renders ([`shared_made`], keyed by the
/// model's hash; the fingerprint covers the tracker crate, which builds it). Every lab recording
/// has the same model, and a build took 5 s of CPU: the end-to-end tests built it some fifteen
/// times. The tests of the build itself are in tests/desk/visibility.rs and the tracker crate.
#[cfg(feature = "desk")]
pub fn shared_table(model: &omnitrack::Model) -> omnitrack::visibility::VisibilityTable {
    use omnitrack::visibility::build::{build_table, BuildOptions};
    use omnitrack::visibility::{model_hash, VisibilityTable};
    let key = format!("table-{:016x}", model_hash(model));
    let dir = shared_made("tables", &["core", "config", "tracker"], &key, |root| {
        let dir = root.join("table");
        std::fs::create_dir_all(&dir).unwrap();
        build_table(model, "model.obj", &BuildOptions::default())
            .save(&dir.join("model.vis"))
            .unwrap();
        std::fs::write(dir.join("complete"), b"").unwrap();
        dir
    });
    VisibilityTable::load(&dir.join("model.vis"), model).unwrap()
}

/// A rendered recording shared by every test binary and both test runs of CI (default and all
/// features): `target/tmp/renders/<fingerprint>/<key>`, made once by `render` (which renders into
/// the folder it is given and returns the recording's path). The fingerprint hashes the sources
/// that make a render (the desk, core, io and config crates) and `Cargo.lock`, so a changed
/// renderer never reuses an old render.
#[cfg(feature = "desk")]
pub fn shared_render(key: &str, render: impl FnOnce(&std::path::Path) -> std::path::PathBuf) -> std::path::PathBuf {
    shared_made("renders", &["desk", "core", "io", "config"], key, render)
}

/// What the tests make once and share across test binaries and CI's two test runs:
/// `target/tmp/<kind>/<fingerprint>/<key>`, made by `make` (which writes into the folder it is
/// given, ending with a `complete` file, and returns the path of what it made). The fingerprint
/// hashes the sources of `crates` (those that decide what is made) and `Cargo.lock`. What is made
/// goes to a private folder first and is moved into place whole: two processes making the same at
/// once both see a complete one. Within a test binary the tests asking for the same thing wait for
/// the one making it: two of the CLI tests, running side by side on a fresh clone, both rendered
/// the 100-frame lab walk.
#[cfg(feature = "desk")]
pub fn shared_made(
    kind: &str,
    crates: &[&str],
    key: &str,
    make: impl FnOnce(&std::path::Path) -> std::path::PathBuf,
) -> std::path::PathBuf {
    use std::collections::HashMap;
    use std::hash::{Hash, Hasher};
    use std::path::Path;
    use std::sync::{Arc, Mutex, PoisonError};
    static MAKING: Mutex<Option<HashMap<String, Arc<Mutex<()>>>>> = Mutex::new(None);
    let this = Arc::clone(
        MAKING
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .get_or_insert_with(HashMap::new)
            .entry(format!("{kind}/{key}"))
            .or_default(),
    );
    // A test that panicked while making leaves nothing in place: the next one makes it again.
    let _making = this.lock().unwrap_or_else(PoisonError::into_inner);
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
    for krate in crates {
        hash_tree(&root.join("crates").join(krate).join("src"), &mut h);
    }
    std::fs::read(root.join("Cargo.lock")).unwrap().hash(&mut h);
    let fingerprint = format!("{:016x}", h.finish());
    let cache = Path::new(env!("CARGO_TARGET_TMPDIR")).join(kind).join(&fingerprint);
    let done = cache.join(key);
    if done.join("complete").exists() {
        return done;
    }
    if !cache.exists() {
        // What older sources made is never used again.
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
    let made = make(scratch.path());
    // Fails when another test put it there first: that one is whole too.
    let _ = std::fs::rename(&made, &done);
    assert!(done.join("complete").exists(), "{kind} {key} not in place");
    done
}

/// The recording `src` cut to its first `frames` frames at `out` (its images hard-linked; the
/// index and the ground truth cut to those frames), marked `complete`. Returns `out`.
#[cfg(feature = "desk")]
pub fn first_frames(src: &std::path::Path, frames: usize, out: &std::path::Path) -> std::path::PathBuf {
    use omnitrack::capture::replay::FRAMES_HEADER;
    std::fs::create_dir_all(out).unwrap();
    for file in ["rig.toml", "model.obj"] {
        std::fs::copy(src.join(file), out.join(file)).unwrap();
    }
    let index = std::fs::read_to_string(src.join("frames.csv")).unwrap();
    let mut csv = format!("{FRAMES_HEADER}\n");
    let mut kept = std::collections::BTreeSet::new();
    for row in index.lines().skip(1) {
        let p: Vec<&str> = row.split(',').collect();
        let frame: usize = p[0].parse().unwrap();
        if frame < frames {
            let image = out.join(p[3]);
            std::fs::create_dir_all(image.parent().unwrap()).unwrap();
            if std::fs::hard_link(src.join(p[3]), &image).is_err() {
                std::fs::copy(src.join(p[3]), &image).unwrap();
            }
            csv.push_str(row);
            csv.push('\n');
            kept.insert(frame);
        }
    }
    assert_eq!(kept.len(), frames, "{} has fewer than {frames} frames", src.display());
    std::fs::write(out.join("frames.csv"), csv).unwrap();
    // The ground truth: its comment lines, then one pose per frame in frame order.
    let truth = std::fs::read_to_string(src.join("groundtruth.tum")).unwrap();
    let comments = truth.lines().take_while(|l| l.starts_with('#'));
    let poses = truth.lines().filter(|l| !l.starts_with('#')).take(frames);
    let cut: String = comments.chain(poses).map(|l| format!("{l}\n")).collect();
    std::fs::write(out.join("groundtruth.tum"), cut).unwrap();
    std::fs::write(out.join("complete"), b"").unwrap();
    out.to_path_buf()
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
