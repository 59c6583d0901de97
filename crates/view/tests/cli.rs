//! `omnitrack-view` as a user runs it: bad input is one line and a non-zero exit, never a
//! panic; what it received before a stop, a `--count` or a SIGKILL is in the MCAP file (with
//! `--ready`, what came before its input closed, stop signals notwithstanding); the
//! documents name every option and give commands it takes; its manual and completions.

use omnitrack_io::publish::{PosePublisher, PoseSample, TrackerState};
use omnitrack_testkit::docs::{check_documented_runs, interface_row, long_options};
use std::io::{BufRead, BufReader};
use std::net::TcpListener;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_omnitrack-view");

fn unique(tag: &str) -> String {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos();
    format!("omnitrack-test/view-{tag}/{}/{nanos}", std::process::id())
}

fn view(args: &[&str]) -> (i32, String) {
    let out = Command::new(BIN).args(args).output().unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn bad_input_is_one_line_naming_it_and_never_a_panic() {
    let dir = tempfile::tempdir().unwrap();
    let taken = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = taken.local_addr().unwrap().port().to_string();
    let nowhere = dir.path().join("no such folder").join("run.mcap");
    let missing = dir.path().join("missing.obj");
    let services = unique("bad");
    for (args, code, expected) in [
        (
            vec!["--port", &port],
            1,
            "cannot listen for the live view: Address already in use",
        ),
        (vec!["--port", &port], 1, "choose another with --port"),
        (
            vec!["--no-server", "--mcap", nowhere.to_str().unwrap()],
            1,
            "cannot create the MCAP file",
        ),
        (vec!["--model", missing.to_str().unwrap()], 1, "missing.obj"),
        (
            vec!["--recording", dir.path().to_str().unwrap(), "--port", "0"],
            1,
            "rig.toml: cannot read",
        ),
        (vec!["--no-server"], 2, "--mcap"),
        (vec!["--jpeg-quality", "0"], 2, "not a JPEG quality"),
        (vec!["--images-every-s", "4000"], 2, "not a number of seconds"),
        (vec!["--services", "omni track"], 2, "not a service prefix"),
    ] {
        let mut all = vec!["serve"];
        if !args.contains(&"--services") {
            all.extend(["--services", &services]);
        }
        all.extend(&args);
        let (got, stderr) = view(&all);
        assert_eq!(got, code, "{args:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
        let line = stderr
            .trim_end()
            .lines()
            .find(|l| l.contains("error") || l.starts_with("omnitrack-view:"));
        let line = line.unwrap_or_else(|| panic!("{args:?}: no error line in {stderr}"));
        assert!(line.contains(expected), "{args:?}: {line:?} should say {expected:?}");
        assert_eq!(stderr.trim_end().lines().count(), 1, "{args:?}: {stderr}");
    }
    drop(taken);
}

fn tracking(sequence: u64) -> PoseSample {
    let mut s = PoseSample {
        timestamp_ns: 1_000_000_000 + sequence * 33_000_000,
        sequence,
        status: TrackerState::Tracking as u8,
        position_m: [1.0 + sequence as f64 * 0.1, 2.0, 1.5],
        rotation_wxyz: [1.0, 0.0, 0.0, 0.0],
        inliers: 30,
        xi_rad2: 1e-5,
        ..PoseSample::default()
    };
    for i in 0..6 {
        s.covariance[i * 6 + i] = 1e-4;
    }
    s
}

/// Starts `serve` and waits for its start line (its subscribers exist by then).
fn start(args: &[&str]) -> Child {
    let mut child = Command::new(BIN)
        .arg("serve")
        .args(args)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stderr.as_mut().unwrap())
        .read_line(&mut line)
        .unwrap();
    assert!(line.starts_with("omnitrack-view: ") && line.contains("/pose"), "{line}");
    child
}

fn wait(child: &mut Child, within: Duration) -> std::process::ExitStatus {
    let deadline = Instant::now() + within;
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            return status;
        }
        assert!(Instant::now() < deadline, "omnitrack-view did not end");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The `/omnitrack/sample` sequences a streaming reader gets from the file (up to where a
/// killed writer left it), and whether the file has its summary.
fn samples_in(path: &Path) -> (Vec<u64>, bool) {
    let bytes = std::fs::read(path).unwrap();
    let mut sequences = Vec::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let Ok(m) = m else { break };
        if m.channel.topic == "/omnitrack/sample" {
            let v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
            sequences.push(v["sequence"].as_u64().unwrap());
        }
    }
    let summary = mcap::Summary::read(&bytes).ok().flatten().is_some();
    (sequences, summary)
}

#[test]
fn count_and_sigint_end_with_a_whole_file_and_a_kill_loses_at_most_a_second() {
    let dir = tempfile::tempdir().unwrap();
    for how in ["count", "sigint", "sigkill"] {
        let services = unique(how);
        let file = dir.path().join(format!("{how}.mcap"));
        let mut args = vec!["--services", &services, "--no-server", "--mcap", file.to_str().unwrap()];
        if how == "count" {
            args.extend(["--count", "4"]);
        }
        let mut child = start(&args);
        let publisher = PosePublisher::create(&format!("{services}/pose")).unwrap();
        for seq in 0..4 {
            publisher.publish(&tracking(seq)).unwrap();
            std::thread::sleep(Duration::from_millis(30));
        }
        let status = match how {
            "count" => wait(&mut child, Duration::from_secs(10)),
            "sigint" => {
                std::thread::sleep(Duration::from_millis(200));
                unsafe { libc::kill(child.id() as i32, libc::SIGINT) };
                wait(&mut child, Duration::from_secs(10))
            }
            _ => {
                // A quiet tracker: the view flushes within a second of its last message.
                std::thread::sleep(Duration::from_millis(1600));
                child.kill().unwrap();
                child.wait().unwrap()
            }
        };
        let mut stderr = String::new();
        let _ = std::io::Read::read_to_string(child.stderr.as_mut().unwrap(), &mut stderr);
        let (sequences, summary) = samples_in(&file);
        assert_eq!(sequences, [0, 1, 2, 3], "{how}: {stderr}");
        if how == "sigkill" {
            assert!(!status.success());
        } else {
            assert!(status.success(), "{how}: {stderr}");
            assert!(summary, "{how}: the file is finished");
            assert!(stderr.contains("4 poses (4 tracking, 0 missed)"), "{how}: {stderr}");
            assert!(!stderr.contains("panicked"));
        }
    }
}

/// `serve --ready`, as `omnitrack run --mcap` starts it: a SIGTERM or SIGINT that reaches it
/// (systemd stops a service with SIGTERM to each of its processes, the run's child too) does
/// not stop it, so samples its parent publishes after one are in the file; its standard input
/// closing does, with a whole file. A stop used to end it at once.
#[test]
fn ready_ignores_stop_signals_and_stops_when_its_input_closes() {
    let dir = tempfile::tempdir().unwrap();
    let services = unique("ready");
    let file = dir.path().join("ready.mcap");
    let mut child = Command::new(BIN)
        .args(["serve", "--services", &services, "--no-server", "--ready", "--mcap"])
        .arg(&file)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.as_mut().unwrap())
        .read_line(&mut line)
        .unwrap();
    assert_eq!(line.trim(), "ready");
    let publisher = PosePublisher::create(&format!("{services}/pose")).unwrap();
    publisher.publish(&tracking(0)).unwrap();
    publisher.publish(&tracking(1)).unwrap();
    for signal in [libc::SIGTERM, libc::SIGINT] {
        // SAFETY: a signal to our own child, not yet waited for.
        unsafe { libc::kill(child.id() as i32, signal) };
    }
    std::thread::sleep(Duration::from_millis(300));
    assert!(child.try_wait().unwrap().is_none(), "a stop signal ended --ready");
    publisher.publish(&tracking(2)).unwrap();
    publisher.publish(&tracking(3)).unwrap();
    drop(child.stdin.take());
    let status = wait(&mut child, Duration::from_secs(10));
    let mut stderr = String::new();
    let _ = std::io::Read::read_to_string(child.stderr.as_mut().unwrap(), &mut stderr);
    assert!(status.success(), "{stderr}");
    let (sequences, summary) = samples_in(&file);
    assert_eq!(sequences, [0, 1, 2, 3], "{stderr}");
    assert!(summary, "the file is finished");
}

/// docs/interfaces.md's row of `omnitrack-view serve` names every option the command has.
#[test]
fn the_interface_document_names_every_option_of_serve() {
    let help = Command::new(BIN).args(["serve", "--help"]).output().unwrap();
    let help = String::from_utf8_lossy(&help.stdout);
    let options: String = help.lines().filter(|l| l.trim_start().starts_with('-')).collect();
    let command = interface_row("omnitrack-view serve ");
    assert_eq!(long_options(&command), long_options(&options), "{command}");
    assert!(long_options(&options).contains("mcap"));
}

/// Every `cargo run … -p omnitrack-view -- ARGS` line of the README and the rig guide is one the
/// command line takes as written (`--help` appended: parsed, nothing opened).
#[test]
fn the_documented_commands_are_ones_the_command_line_takes() {
    let checked = check_documented_runs(BIN, "omnitrack-view");
    assert!(
        checked >= 2,
        "the README and the rig guide give `cargo run -p omnitrack-view -- …` lines"
    );
}

#[test]
fn completions_and_a_manual_page() {
    for shell in ["bash", "zsh", "fish"] {
        let out = Command::new(BIN).args(["completions", shell]).output().unwrap();
        assert!(out.status.success());
        let script = String::from_utf8_lossy(&out.stdout);
        assert!(script.contains("serve") && script.contains("jpeg-quality"), "{shell}");
    }
    let out = Command::new(BIN).arg("manpage").output().unwrap();
    assert!(out.status.success());
    assert!(String::from_utf8_lossy(&out.stdout).contains(".TH omnitrack-view 1"));
}
