//! `omnitrack run --mcap FILE` (issue 49 item 4): the run starts `omnitrack-view serve
//! --no-server --mcap FILE` beside itself, subscribed before the first frame, and stops it after
//! the last, so the file holds every tracked pose, even when a stop signal reaches the view too
//! (systemd's SIGTERM to the whole service); a missing view and a path that cannot be
//! written are one line before anything is tracked; a view that ends during the run leaves the
//! run going and its summary saying the file is incomplete (docs/interfaces.md, `run`).
//!
//! The view is another package's binary, which `env!("CARGO_BIN_EXE_…")` cannot name: the
//! workspace's `cargo test` builds it beside `omnitrack` (it has tests of its own), where `run`
//! looks for it first. A cargo run from inside a test would wait forever on the build directory's
//! lock that the running `cargo test` holds, so a missing or stale view is a failure that says
//! what to build.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const OMNITRACK: &str = env!("CARGO_BIN_EXE_omnitrack");

/// `omnitrack-view` beside `omnitrack`, checked to be newer than its sources.
#[cfg(feature = "desk")]
fn view_binary() -> PathBuf {
    let view = Path::new(OMNITRACK).with_file_name("omnitrack-view");
    let built = std::fs::metadata(&view).and_then(|m| m.modified());
    let build = "build it first: `cargo build -p omnitrack-view` (the workspace's `cargo test` does)";
    let built = built.unwrap_or_else(|e| panic!("{}: {e}; {build}", view.display()));
    let sources = Path::new(env!("CARGO_MANIFEST_DIR")).join("crates/view");
    let newest = newest_file(&sources);
    assert!(built >= newest, "{} is older than its sources; {build}", view.display());
    view
}

#[cfg(feature = "desk")]
fn newest_file(dir: &Path) -> std::time::SystemTime {
    let mut newest = std::time::SystemTime::UNIX_EPOCH;
    for entry in std::fs::read_dir(dir).unwrap().flatten() {
        let path = entry.path();
        let t = if path.is_dir() {
            newest_file(&path)
        } else {
            entry.metadata().and_then(|m| m.modified()).unwrap()
        };
        newest = newest.max(t);
    }
    newest
}

/// A copy of `omnitrack` alone in a directory of its own (a hard link where the file system
/// allows), so that nothing is beside it.
fn lone_omnitrack(dir: &Path) -> PathBuf {
    let bin = dir.join("omnitrack");
    if std::fs::hard_link(OMNITRACK, &bin).is_err() {
        std::fs::copy(OMNITRACK, &bin).unwrap();
    }
    bin
}

fn text(out: &Output) -> (i32, String, String) {
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn without_the_view_program_run_mcap_is_one_line_before_anything_is_loaded() {
    let dir = tempfile::tempdir().unwrap();
    let bin = lone_omnitrack(dir.path());
    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    let file = dir.path().join("run.mcap");
    // Neither the model nor the recording exists: the view is looked for before either is read.
    let out = Command::new(&bin)
        .args(["run", "--model", "nowhere.obj", "--source", "replay:nowhere"])
        .arg("--mcap")
        .arg(&file)
        .env("PATH", &empty)
        .output()
        .unwrap();
    let (code, stdout, stderr) = text(&out);
    assert_eq!(code, 2, "{stderr}");
    assert_eq!(stdout, "");
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(
        stderr.contains("omnitrack-view program, which is neither beside this omnitrack nor on PATH")
            && stderr.contains("cargo build --release -p omnitrack-view"),
        "{stderr}"
    );
    assert!(!file.exists(), "nothing written");
}

#[test]
fn an_mcap_path_that_cannot_be_written_is_one_line_before_anything_is_loaded() {
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("room.obj");
    std::fs::write(&model, "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\n").unwrap();
    let no_dir = dir.path().join("no such dir/run.mcap");
    for (file, expected) in [
        (no_dir.as_path(), "No such file or directory"),
        (dir.path(), "Is a directory"),
        (model.as_path(), "that is the input"),
    ] {
        let out = Command::new(OMNITRACK)
            .args(["run", "--source", "replay:nowhere", "--model"])
            .arg(&model)
            .arg("--mcap")
            .arg(file)
            .output()
            .unwrap();
        let (code, _, stderr) = text(&out);
        assert_eq!(code, 2, "{stderr}");
        assert_eq!(stderr.lines().count(), 1, "{stderr}");
        assert!(
            stderr.starts_with(&format!("omnitrack: --mcap {}: ", file.display())) && stderr.contains(expected),
            "{stderr}"
        );
    }
    assert_eq!(
        std::fs::read_to_string(&model).unwrap().lines().count(),
        4,
        "the model untouched"
    );
    // With --no-publish there is nothing to subscribe to: a usage error.
    let out = Command::new(OMNITRACK)
        .args([
            "run",
            "--source",
            "replay:nowhere",
            "--no-publish",
            "--mcap",
            "x.mcap",
            "--model",
        ])
        .arg(&model)
        .output()
        .unwrap();
    let (code, _, stderr) = text(&out);
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("--no-publish"), "{stderr}");
}

/// 6 s at the recording's 5 Hz, as the live view's own test: the first search ends well within
/// it, even on a loaded machine.
#[cfg(feature = "desk")]
const FRAMES: usize = 30;

#[cfg(feature = "desk")]
fn lab_run(bin: &Path, lab: &crate::common::LabRecording, prefix: &str, file: &Path) -> Output {
    let t0 = lab.truth[0].pose.translation.vector;
    let init = format!("{},{},{},1.5", t0.x + 0.5, t0.y, t0.z);
    Command::new(bin)
        .args(["run", "--model", lab.rec.join("model.obj").to_str().unwrap()])
        .args(["--source", &format!("replay:{}", lab.rec.display())])
        .args(["--init", &init, "--services", prefix, "--realtime", "--json"])
        .arg("--mcap")
        .arg(file)
        .output()
        .unwrap()
}

#[cfg(feature = "desk")]
#[test]
fn a_replayed_run_with_mcap_writes_every_tracked_pose_to_the_file() {
    view_binary();
    let lab = crate::common::lab_recording(FRAMES);
    lab.table.save(&lab.rec.join("model.vis")).unwrap();
    let file = lab.dir.path().join("run.mcap");
    let prefix = format!("omnitrack-test/mcap-{}", std::process::id());
    let out = lab_run(Path::new(OMNITRACK), &lab, &prefix, &file);
    let (code, stdout, stderr) = text(&out);
    assert_eq!(code, 0, "{stderr}");
    // --json's output is the run's alone: the view's lines are on standard error.
    let run: serde_json::Value = serde_json::from_str(&stdout).unwrap_or_else(|e| panic!("{e}: {stdout}"));
    let tracked = run["poses"]["on_time"].as_u64().unwrap();
    let published = run["samples_published"]["pose"].as_u64().unwrap();
    assert_eq!(published as usize, FRAMES, "{run}");
    assert!(tracked >= 5, "the run tracked: {run}");
    assert!(stderr.contains("omnitrack-view: "), "the view's lines: {stderr}");
    assert!(
        stderr.contains(&format!("omnitrack: MCAP file {} written", file.display())),
        "{stderr}"
    );

    let bytes = std::fs::read(&file).unwrap();
    let summary = mcap::Summary::read(&bytes)
        .unwrap()
        .expect("a finished file has a summary");
    let mut count = std::collections::BTreeMap::<String, u64>::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        *count.entry(m.unwrap().channel.topic.clone()).or_default() += 1;
    }
    assert_eq!(count.get("/omnitrack/pose").copied(), Some(tracked), "{count:?}");
    assert_eq!(count.get("/omnitrack/sample").copied(), Some(published), "{count:?}");
    assert_eq!(count.get("/omnitrack/model").copied(), Some(1), "{count:?}");
    assert!(
        count.get("/omnitrack/sensor0/image").is_some_and(|&n| n >= 1),
        "{count:?}"
    );
    assert_eq!(summary.stats.unwrap().message_count, count.values().sum::<u64>());
}

/// A view that ends during the run (here a stand-in that says it is ready and exits): the run
/// goes on to its end, its exit code its own, and its summary says the file is incomplete.
#[cfg(feature = "desk")]
#[test]
fn a_view_that_ends_during_the_run_leaves_the_run_going_and_the_file_called_incomplete() {
    let dir = tempfile::tempdir().unwrap();
    let bin = lone_omnitrack(dir.path());
    let stand_in = dir.path().join("omnitrack-view");
    std::fs::write(&stand_in, "#!/bin/sh\necho ready\nexit 7\n").unwrap();
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&stand_in, std::fs::Permissions::from_mode(0o755)).unwrap();
    let lab = crate::common::lab_recording(FRAMES);
    lab.table.save(&lab.rec.join("model.vis")).unwrap();
    let file = dir.path().join("run.mcap");
    let prefix = format!("omnitrack-test/mcap-gone-{}", std::process::id());
    let out = lab_run(&bin, &lab, &prefix, &file);
    let (code, stdout, stderr) = text(&out);
    assert_eq!(code, 0, "{stderr}");
    let run: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(run["samples_published"]["pose"].as_u64(), Some(FRAMES as u64), "{run}");
    assert!(
        stderr.contains(&format!(
            "omnitrack: MCAP file {} is incomplete: omnitrack-view exited with code 7 during the run",
            file.display()
        )),
        "{stderr}"
    );
}

/// A run that ends without stopping the view (SIGKILL; a second Ctrl-C is the same): the view's
/// standard input closes with the run, and the view finishes the file all the same.
#[cfg(feature = "desk")]
#[test]
fn a_run_killed_outright_still_leaves_a_finished_file() {
    view_binary();
    let lab = crate::common::lab_recording(FRAMES);
    lab.table.save(&lab.rec.join("model.vis")).unwrap();
    let file = lab.dir.path().join("killed.mcap");
    let prefix = format!("omnitrack-test/mcap-killed-{}", std::process::id());
    let t0 = lab.truth[0].pose.translation.vector;
    let mut run = Command::new(OMNITRACK)
        .args(["run", "--model", lab.rec.join("model.obj").to_str().unwrap()])
        .args(["--source", &format!("replay:{}", lab.rec.display())])
        .args(["--init", &format!("{},{},{},1.5", t0.x + 0.5, t0.y, t0.z)])
        .args(["--services", &prefix, "--realtime"])
        .arg("--mcap")
        .arg(&file)
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    // The view makes the file as it starts; a second more and the run has published.
    while !file.exists() && std::time::Instant::now() < deadline {
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    std::thread::sleep(std::time::Duration::from_secs(1));
    run.kill().unwrap();
    run.wait().unwrap();
    let finished = |b: &[u8]| b.len() > 16 && b.ends_with(b"\x89MCAP0\r\n");
    let mut bytes = Vec::new();
    while !finished(&bytes) && std::time::Instant::now() < deadline + std::time::Duration::from_secs(10) {
        std::thread::sleep(std::time::Duration::from_millis(100));
        bytes = std::fs::read(&file).unwrap_or_default();
    }
    assert!(
        finished(&bytes),
        "the file has no closing magic: the view did not finish it"
    );
    assert!(
        mcap::Summary::read(&bytes).unwrap().is_some(),
        "a finished file has a summary"
    );
}

/// The parent of `pid` (from /proc/PID/stat: the field after the command's closing parenthesis
/// and the state).
#[cfg(feature = "desk")]
fn parent_of(pid: u32) -> Option<u32> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    stat.rsplit_once(')')?.1.split_whitespace().nth(1)?.parse().ok()
}

/// systemd stops a service with SIGTERM to every process of its control group (the default
/// `KillMode=control-group`): the run and its view at once. The view used to stop at once and
/// miss what the run published after it (the frame in hand, and the status the run publishes as
/// it stops: missing in every try); it now waits for the run, so the file has every sample the
/// run published and the run calls it written.
#[cfg(feature = "desk")]
#[test]
fn a_sigterm_to_the_run_and_its_view_together_leaves_every_published_sample_in_the_file() {
    view_binary();
    let lab = crate::common::lab_recording(FRAMES);
    lab.table.save(&lab.rec.join("model.vis")).unwrap();
    let file = lab.dir.path().join("stopped.mcap");
    let prefix = format!("omnitrack-test/mcap-stopped-{}", std::process::id());
    let t0 = lab.truth[0].pose.translation.vector;
    let run = Command::new(OMNITRACK)
        .args(["run", "--model", lab.rec.join("model.obj").to_str().unwrap()])
        .args(["--source", &format!("replay:{}", lab.rec.display())])
        .args(["--init", &format!("{},{},{},1.5", t0.x + 0.5, t0.y, t0.z)])
        .args(["--services", &prefix, "--realtime", "--json"])
        .arg("--mcap")
        .arg(&file)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    while !file.exists() && std::time::Instant::now() < deadline {
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    // Two seconds of the six: the run has tracked and is mid-recording.
    std::thread::sleep(std::time::Duration::from_secs(2));
    let view = std::fs::read_dir("/proc")
        .unwrap()
        .filter_map(|e| e.ok()?.file_name().to_str()?.parse::<u32>().ok())
        .find(|&pid| parent_of(pid) == Some(run.id()))
        .expect("the run's view process");
    for pid in [view, run.id()] {
        // SAFETY: signals to the run we started and to its child.
        unsafe { libc::kill(pid as i32, libc::SIGTERM) };
    }
    let out = run.wait_with_output().unwrap();
    let (code, stdout, stderr) = text(&out);
    // 3: stopped before its first pose (a loaded machine's search can outlast the two seconds);
    // what is published is recorded all the same.
    assert!(code == 0 || code == 3, "exit {code}: {stderr}");
    let summary: serde_json::Value = serde_json::from_str(&stdout).unwrap_or_else(|e| panic!("{e}: {stdout}"));
    let published = summary["samples_published"]["pose"].as_u64().unwrap();
    assert!(published > 0 && published < FRAMES as u64, "stopped mid-run: {summary}");
    assert!(
        stderr.contains(&format!("omnitrack: MCAP file {} written", file.display())),
        "{stderr}"
    );
    let bytes = std::fs::read(&file).unwrap();
    assert!(mcap::Summary::read(&bytes).unwrap().is_some(), "a finished file");
    let mut count = std::collections::BTreeMap::<String, u64>::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        *count.entry(m.unwrap().channel.topic.clone()).or_default() += 1;
    }
    assert_eq!(count.get("/omnitrack/sample").copied(), Some(published), "{count:?}");
    // The run's last status, published as it stops, is the last sample of all.
    let statuses = summary["samples_published"]["status"].as_u64().unwrap();
    assert_eq!(count.get("/omnitrack/status").copied(), Some(statuses), "{count:?}");
}
