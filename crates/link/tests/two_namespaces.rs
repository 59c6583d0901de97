//! Poses to another host, end to end: two network namespaces joined by a veth pair stand for the
//! rig's computer and a far host. In the first, `omnitrack-link send` subscribes to the local pose
//! service and listens on the veth address; in the second, `omnitrack-link listen` connects to
//! it. The far side must receive every pose; the latency is printed. An unreachable peer is one
//! line and exit code 1.
//!
//! Namespaces need root (CI runs as root). Elsewhere the test says why it did not run, and fails
//! if `CI` is set, so that CI can never pass it by skipping.

use omnitrack_io::publish::{PoseSample, PoseSubscriber, SamplePublisher, TrackerState};
use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_omnitrack-link");

/// Poses sent at 200 Hz (the tracker publishes at ~30).
const POSES: u64 = 1000;
const PERIOD: Duration = Duration::from_millis(5);
/// Sequence numbers of the measured poses start here; those before are warm-up.
const FIRST: u64 = 1_000_000;

fn ip(args: &[&str]) -> Result<(), String> {
    let out = Command::new("ip").args(args).output().map_err(|e| format!("ip: {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!(
            "ip {}: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr).trim()
        ))
    }
}

/// Two namespaces joined by a veth pair, `10.231.N.1` ↔ `10.231.N.2`; removed on drop.
struct Hosts {
    a: String,
    b: String,
    addr_a: String,
}

impl Hosts {
    fn new() -> Result<Hosts, String> {
        let id = std::process::id() % 10_000;
        let (a, b) = (format!("omt-a-{id}"), format!("omt-b-{id}"));
        let (va, vb) = (format!("omta{id}"), format!("omtb{id}"));
        let net = id % 250;
        let hosts = Hosts {
            a: a.clone(),
            b: b.clone(),
            addr_a: format!("10.231.{net}.1"),
        };
        ip(&["netns", "add", &a])?;
        ip(&["netns", "add", &b])?;
        ip(&["link", "add", &va, "type", "veth", "peer", "name", &vb])?;
        ip(&["link", "set", &va, "netns", &a])?;
        ip(&["link", "set", &vb, "netns", &b])?;
        ip(&["-n", &a, "addr", "add", &format!("10.231.{net}.1/30"), "dev", &va])?;
        ip(&["-n", &b, "addr", "add", &format!("10.231.{net}.2/30"), "dev", &vb])?;
        for (ns, dev) in [(&a, &va), (&b, &vb)] {
            ip(&["-n", ns, "link", "set", dev, "up"])?;
            ip(&["-n", ns, "link", "set", "lo", "up"])?;
        }
        Ok(hosts)
    }

    fn spawn(&self, ns: &str, args: &[&str]) -> Child {
        Command::new("ip")
            .args(["netns", "exec", ns, BIN])
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start omnitrack-link")
    }
}

impl Drop for Hosts {
    fn drop(&mut self) {
        // Deleting a namespace deletes its end of the veth pair, and with it the other end.
        let _ = ip(&["netns", "del", &self.a]);
        let _ = ip(&["netns", "del", &self.b]);
    }
}

/// Whether namespaces can be made here; `Err` says why not.
fn namespaces_available() -> Result<(), String> {
    if unsafe { libc::geteuid() } != 0 {
        return Err("network namespaces need root".into());
    }
    Command::new("ip")
        .arg("-V")
        .output()
        .map(|_| ())
        .map_err(|e| format!("no `ip` command (iproute2): {e}"))
}

fn skip_or_fail(why: &str) {
    assert!(
        std::env::var_os("CI").is_none(),
        "CI must run the two-namespace test: {why}"
    );
    eprintln!("two-namespace test not run: {why}");
}

fn pose(sequence: u64) -> PoseSample {
    PoseSample {
        timestamp_ns: omnitrack_link::monotonic_ns(),
        sequence,
        status: TrackerState::Tracking as u8,
        position_m: [sequence as f64 * 1e-3, 2.0, 1.6],
        inliers: 40,
        ..PoseSample::default()
    }
}

#[test]
fn every_pose_crosses_from_one_namespace_to_another() {
    if let Err(why) = namespaces_available() {
        return skip_or_fail(&why);
    }
    let hosts = match Hosts::new() {
        Ok(h) => h,
        Err(why) => return skip_or_fail(&why),
    };
    let service = format!("omnitrack-link-test/{}/pose", std::process::id());
    let publisher = SamplePublisher::<PoseSample>::create(&service).unwrap();
    let endpoint = format!("tcp/{}:7447", hosts.addr_a);
    let mut sender = hosts.spawn(&hosts.a, &["send", "--service", &service, "--listen", &endpoint]);
    // The far host also republishes on a local service of its own; /dev/shm is not namespaced,
    // so this process can subscribe to it as a program on the far host would.
    let far_service = format!("omnitrack-link-test/{}/far/pose", std::process::id());
    let far = PoseSubscriber::create(&far_service).unwrap();
    let mut listener = hosts.spawn(
        &hosts.b,
        &[
            "listen",
            "--connect",
            &endpoint,
            "--latency",
            "--idle-s",
            "3",
            "--republish",
            &far_service,
        ],
    );
    let mut far_seqs = Vec::new();

    // Lines of the far side, as they come.
    let (tx, rx) = mpsc::channel::<String>();
    let out = listener.stdout.take().unwrap();
    let reader = std::thread::spawn(move || {
        for line in BufReader::new(out).lines().map_while(Result::ok) {
            let _ = tx.send(line);
        }
    });
    // Warm up until the far side prints a pose: Zenoh keeps nothing for a subscriber that has
    // not joined yet.
    let start = Instant::now();
    let mut warm = 0;
    let mut lines = Vec::new();
    loop {
        publisher.publish(&pose(warm)).unwrap();
        warm += 1;
        if let Ok(l) = rx.recv_timeout(Duration::from_millis(50)) {
            lines.push(l);
            break;
        }
        assert!(start.elapsed() < Duration::from_secs(30), "no pose crossed in 30 s");
    }
    for k in 0..POSES {
        let due = Instant::now() + PERIOD;
        publisher.publish(&pose(FIRST + k)).unwrap();
        while let Some(s) = far.receive().unwrap() {
            far_seqs.push(s.sequence);
        }
        std::thread::sleep(due.saturating_duration_since(Instant::now()));
    }
    let drain_until = Instant::now() + Duration::from_secs(2);
    while Instant::now() < drain_until {
        if let Some(s) = far.wait(Duration::from_millis(50)).unwrap() {
            far_seqs.push(s.sequence);
        }
    }
    let listened = listener.wait_with_output().unwrap();
    reader.join().unwrap();
    lines.extend(rx.try_iter());
    let _ = sender.kill();
    let _ = sender.wait();

    let stderr = String::from_utf8_lossy(&listened.stderr).to_string();
    assert!(listened.status.success(), "{stderr}");
    let seqs: Vec<u64> = lines
        .iter()
        .filter_map(|l| l.strip_prefix("seq=")?.split(' ').next()?.parse().ok())
        .filter(|&s| s >= FIRST)
        .collect();
    let expected: Vec<u64> = (FIRST..FIRST + POSES).collect();
    assert_eq!(seqs, expected, "every pose, in order, once");
    far_seqs.retain(|&s| s >= FIRST);
    assert_eq!(far_seqs, expected, "every pose on the far host's own service too");
    let latency = stderr.lines().find(|l| l.starts_with("latency:")).unwrap_or("");
    println!("{POSES} poses at 200 Hz across two network namespaces over Zenoh (plus {warm} warm-up): {latency}");
    assert!(latency.contains("p99"), "{stderr}");
    drop(hosts);
}

#[test]
fn an_unreachable_peer_is_one_line_and_exit_code_1() {
    // A TEST-NET-1 address (RFC 5737): routed nowhere.
    let start = Instant::now();
    let out = Command::new(BIN)
        .args(["listen", "--connect", "tcp/192.0.2.1:7447", "--count", "1"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert_eq!(stderr.trim_end().lines().count(), 1, "one line: {stderr}");
    assert!(
        stderr.starts_with("omnitrack-link: zenoh: cannot reach tcp/192.0.2.1:7447: "),
        "{stderr}"
    );
    assert!(!stderr.contains(".rs:"), "no source locations: {stderr}");
    assert!(
        start.elapsed() < Duration::from_secs(30),
        "gave up in {:?}",
        start.elapsed()
    );
    // Bad arguments are clap's one-line errors too.
    let out = Command::new(BIN).args(["listen", "--idle-s", "0"]).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--idle-s must be a positive number"));
}
