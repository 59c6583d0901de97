//! `omnitrack run` stopped by SIGTERM wherever it waits (issue 50, item 8): a `--realtime`
//! replay sleeping towards a frame far in the future, and a lossless replay waiting for the whole
//! model's search. Each run is a child process signalled once it waits there; it must end
//! cleanly (status 0, or 3 when it had no pose yet; the trajectory whole, the poses it had
//! written kept) within [`BOUND`] —
//! a bound for a loaded CI machine: the waits it guards against are 36 s, 10 min and forever.

#![cfg(feature = "desk")]

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// How long a signalled run may take to end. The stop itself is honoured within a tick (20 ms);
/// the rest is joining the threads and flushing the trajectory.
const BOUND: Duration = Duration::from_secs(5);

/// A child `omnitrack run` and its standard error, collected as it comes.
struct Run {
    child: Child,
    stderr: Arc<Mutex<String>>,
}

impl Run {
    fn start(args: &[&str]) -> Run {
        let mut child = Command::new(env!("CARGO_BIN_EXE_omnitrack"))
            .args(args)
            // `source ended` tells when the replay has delivered its last frame.
            .env("OMNITRACK_LOG", "info")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let stderr = Arc::new(Mutex::new(String::new()));
        let pipe = child.stderr.take().unwrap();
        let collected = Arc::clone(&stderr);
        std::thread::spawn(move || {
            for line in BufReader::new(pipe).lines().map_while(Result::ok) {
                let mut s = collected.lock().unwrap();
                s.push_str(&line);
                s.push('\n');
            }
        });
        Run { child, stderr }
    }

    fn stderr(&self) -> String {
        self.stderr.lock().unwrap().clone()
    }

    /// Waits (at most two minutes: a table build on a loaded machine) until standard error holds
    /// `text`.
    fn wait_for(&mut self, text: &str) {
        let started = Instant::now();
        while !self.stderr().contains(text) {
            assert!(
                self.child.try_wait().unwrap().is_none(),
                "ended before `{text}`: {}",
                self.stderr()
            );
            assert!(
                started.elapsed() < Duration::from_secs(120),
                "no `{text}`: {}",
                self.stderr()
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// SIGTERM, then the exit code and how long the run took to end; a run still there after
    /// four times [`BOUND`] is killed (the test fails rather than hangs).
    fn terminate(mut self) -> (Option<i32>, Duration, String) {
        let signalled = Instant::now();
        // SAFETY: kill(2) on the child's own process id.
        assert_eq!(unsafe { libc::kill(self.child.id() as libc::pid_t, libc::SIGTERM) }, 0);
        loop {
            if let Some(status) = self.child.try_wait().unwrap() {
                let took = signalled.elapsed();
                // The collector ends with the pipe; what it has is all there is.
                std::thread::sleep(Duration::from_millis(50));
                return (status.code(), took, self.stderr());
            }
            if signalled.elapsed() > 4 * BOUND {
                self.child.kill().unwrap();
                let _ = self.child.wait();
                panic!("still running {:?} after SIGTERM: {}", 4 * BOUND, self.stderr());
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }
}

/// Writes a recording's index anew: a file of its own, not the shared render's that the test's
/// copy is a hard link to.
fn rewrite(path: &Path, text: &str) {
    std::fs::remove_file(path).unwrap();
    std::fs::write(path, text).unwrap();
}

/// The pose lines of a TUM trajectory written so far, and whether it ends with a whole line.
fn poses(path: &Path) -> (usize, bool) {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let n = text.lines().filter(|l| !l.starts_with('#') && !l.is_empty()).count();
    (n, text.is_empty() || text.ends_with('\n'))
}

/// A `--realtime` replay whose last frame lies 40 s, or `u64::MAX` ns, after the others: the
/// replay sleeps towards it in slices and the stop ends the sleep (it used to end 36 s later, or
/// never). The poses written before are kept.
#[test]
fn sigterm_ends_a_realtime_replay_waiting_for_a_distant_frame() {
    let lab = crate::common::lab_recording(6);
    // The table beside the model, as `run` caches it: the run loads it rather than building it
    // (5 s of CPU; tests/cli/cli_run.rs has a run build and cache one).
    lab.table.save(&lab.rec.join("model.vis")).unwrap();
    let index = lab.rec.join("frames.csv");
    let original = std::fs::read_to_string(&index).unwrap();
    let rows: Vec<&str> = original.lines().skip(1).collect();
    let last: Vec<&str> = rows.iter().copied().filter(|r| r.starts_with("5,")).collect();
    let first_ns: u64 = rows[0].split(',').nth(2).unwrap().parse().unwrap();
    let model = lab.rec.join("model.obj");
    let t0 = lab.truth[0].pose.translation.vector;
    let init = format!("{},{},{},3", t0.x + 0.5, t0.y, t0.z);
    for (label, far_ns) in [("40 s", first_ns + 40_000_000_000), ("u64::MAX ns", u64::MAX)] {
        let mut csv = original.clone();
        for row in &last {
            let p: Vec<&str> = row.split(',').collect();
            csv.push_str(&format!("6,{},{far_ns},{}\n", p[1], p[3]));
        }
        rewrite(&index, &csv);
        let trajectory = lab.dir.path().join(format!("gap-{}.tum", far_ns % 1000));
        let source = format!("replay:{}", lab.rec.display());
        let mut run = Run::start(&[
            "run",
            "--model",
            model.to_str().unwrap(),
            "--source",
            &source,
            "--realtime",
            "--init",
            &init,
            "--no-publish",
            "--trajectory",
            trajectory.to_str().unwrap(),
        ]);
        run.wait_for("omnitrack: visibility table");
        // The six frames span one second: past it, the replay waits for the seventh.
        std::thread::sleep(Duration::from_secs(3));
        assert!(!run.stderr().contains("source ended"), "{label}: {}", run.stderr());
        let (written, _) = poses(&trajectory);
        let (code, took, stderr) = run.terminate();
        eprintln!("{label}: SIGTERM honoured in {took:?}, {written} poses before it");
        assert!(took < BOUND, "{label}: {took:?} after SIGTERM: {stderr}");
        let (kept, whole) = poses(&trajectory);
        assert!(whole && kept >= written, "{label}: {kept} poses kept of {written}");
        // A clean stop: 0 with poses, 3 (docs/interfaces.md, "Exit codes") without.
        assert_eq!(code, Some(if kept > 0 { 0 } else { 3 }), "{label}: {stderr}");
        assert!(
            stderr.contains("frames processed of"),
            "{label}: the run's summary: {stderr}"
        );
        assert!(
            !stderr.contains("source ended"),
            "{label}: the seventh frame came: {stderr}"
        );
    }
}

/// A lossless replay of one frame with no hint searches the whole model (10 s of work, more in a
/// debug build), and the run, at the end of the recording, waits for it. SIGTERM cuts the
/// search short, and half a search commits nothing: no pose, and the run says why.
#[test]
fn sigterm_cuts_a_whole_model_search_short_and_writes_no_pose_from_it() {
    let lab = crate::common::lab_recording(6);
    // The table beside the model, as `run` caches it: the run loads it rather than building it
    // (5 s of CPU; tests/cli/cli_run.rs has a run build and cache one).
    lab.table.save(&lab.rec.join("model.vis")).unwrap();
    let index = lab.rec.join("frames.csv");
    let text = std::fs::read_to_string(&index).unwrap();
    let first: String = text
        .lines()
        .filter(|l| !l.starts_with(|c: char| c.is_ascii_digit()) || l.starts_with("0,"))
        .map(|l| format!("{l}\n"))
        .collect();
    rewrite(&index, &first);
    let model = lab.rec.join("model.obj");
    let trajectory = lab.dir.path().join("whole.tum");
    let source = format!("replay:{}", lab.rec.display());
    let mut run = Run::start(&[
        "run",
        "--model",
        model.to_str().unwrap(),
        "--source",
        &source,
        "--no-publish",
        "--trajectory",
        trajectory.to_str().unwrap(),
    ]);
    run.wait_for("source ended");
    // The frame's edges (a second in a debug build, three on a loaded machine), then its search
    // sent to the worker, which the run waits for: signalled once the search is under way.
    run.wait_for("search started");
    std::thread::sleep(Duration::from_millis(300));
    let (code, took, stderr) = run.terminate();
    eprintln!("SIGTERM honoured in {took:?} during the whole model's search");
    assert!(took < BOUND, "{took:?} after SIGTERM: {stderr}");
    let (kept, whole) = poses(&trajectory);
    assert!(whole, "{stderr}");
    assert_eq!(kept, 0, "a pose from a search cut short: {stderr}");
    assert!(stderr.contains("cut short by the stop"), "{stderr}");
    // Stopped cleanly without a pose: exit 3, the last line saying why.
    assert_eq!(code, Some(3), "{stderr}");
    assert!(
        stderr
            .trim_end()
            .ends_with("omnitrack: no pose: the stop cut the search short before it finished"),
        "{stderr}"
    );
}
