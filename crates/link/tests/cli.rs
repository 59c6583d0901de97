//! `omnitrack-link` on one host, no namespaces needed: its manual and completions, and what
//! `listen --latency` says when the poses' stamps cannot be compared with this host's clock.

use omnitrack_io::publish::{PoseSample, SamplePublisher, TrackerState};
use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_omnitrack-link");

/// `completions SHELL` prints a script naming the commands; `manpage` prints the page and
/// `manpage --dir` writes a page for every command, each one a page cites among them.
#[test]
fn completions_and_a_manual_page_for_every_command() {
    for shell in ["bash", "zsh", "fish"] {
        let out = Command::new(BIN).args(["completions", shell]).output().unwrap();
        let script = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success(),
            "{shell}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(
            script.contains("omnitrack-link") && script.contains("listen"),
            "{shell}: {script}"
        );
    }
    let out = Command::new(BIN).arg("manpage").output().unwrap();
    assert!(out.status.success());
    assert!(String::from_utf8_lossy(&out.stdout).contains(".TH omnitrack-link 1"));
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(BIN)
        .args(["manpage", "--dir"])
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let mut names: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(
        names,
        [
            "omnitrack-link-completions.1",
            "omnitrack-link-listen.1",
            "omnitrack-link-manpage.1",
            "omnitrack-link-send.1",
            "omnitrack-link.1"
        ]
    );
    assert_eq!(
        omnitrack_manual::dangling_citations(dir.path()).unwrap(),
        Vec::<String>::new()
    );
}

/// A free TCP port of the loopback interface.
fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// Runs `send` and `listen --latency` on this host, publishes poses stamped by `stamp` until the
/// far side prints some, and returns `listen`'s standard error.
fn latency_report(tag: &str, stamp: impl Fn() -> u64) -> String {
    let service = format!("omnitrack-link-cli-test/{}/{tag}/pose", std::process::id());
    let publisher = SamplePublisher::<PoseSample>::create(&service).unwrap();
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let mut sender = Command::new(BIN)
        .args(["send", "--service", &service, "--listen", &endpoint])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut listener = Command::new(BIN)
        .args(["listen", "--connect", &endpoint, "--latency", "--count", "20"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let (tx, rx) = mpsc::channel::<String>();
    let out = listener.stdout.take().unwrap();
    let reader = std::thread::spawn(move || {
        for line in BufReader::new(out).lines().map_while(Result::ok) {
            let _ = tx.send(line);
        }
    });
    let start = Instant::now();
    let mut received = 0;
    let mut sequence = 0;
    while received < 20 {
        publisher
            .publish(&PoseSample {
                timestamp_ns: stamp(),
                sequence,
                status: TrackerState::Tracking as u8,
                ..PoseSample::default()
            })
            .unwrap();
        sequence += 1;
        while rx.recv_timeout(Duration::from_millis(20)).is_ok() {
            received += 1;
        }
        assert!(start.elapsed() < Duration::from_secs(60), "{received} poses in 60 s");
    }
    let listened = listener.wait_with_output().unwrap();
    reader.join().unwrap();
    let _ = sender.kill();
    let _ = sender.wait();
    assert!(listened.status.success());
    String::from_utf8_lossy(&listened.stderr).into_owned()
}

/// SIGTERM (systemd's stop) ends `send` with its summary and exit 0: the signal interrupting
/// the wait on the local service was reported as an error, exit 1, on every try.
#[test]
fn send_stops_cleanly_on_sigterm() {
    let service = format!("omnitrack-link-cli-test/{}/sigterm/pose", std::process::id());
    let _publisher = SamplePublisher::<PoseSample>::create(&service).unwrap();
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let sender = Command::new(BIN)
        .args(["send", "--service", &service, "--listen", &endpoint])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Long enough to be waiting on the service, where the signal lands.
    std::thread::sleep(Duration::from_millis(1500));
    let killed = Command::new("kill")
        .args(["-TERM", &sender.id().to_string()])
        .status()
        .unwrap();
    assert!(killed.success());
    let out = sender.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{:?}: {}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
}

/// A replay stamps its recording's time: `listen --latency` printed 1,340 s as its latency. It
/// says the clocks are not comparable instead; poses of a live source on this host get an age.
#[test]
fn latency_is_a_number_only_where_the_clocks_are_comparable() {
    let replay = latency_report("replay", || {
        omnitrack_link::monotonic_ns().saturating_sub(1_340_000_000_000)
    });
    let line = replay.lines().find(|l| l.starts_with("latency:")).unwrap_or_default();
    assert!(line.starts_with("latency: not comparable: "), "{replay}");
    assert!(line.contains("a replay's are its recording's time"), "{line}");
    assert!(!line.contains("p50"), "{line}");

    let live = latency_report("live", omnitrack_link::monotonic_ns);
    let line = live.lines().find(|l| l.starts_with("latency:")).unwrap_or_default();
    assert!(line.starts_with("latency: p50 "), "{live}");
    assert!(line.ends_with("(20 poses)"), "{line}");
}
