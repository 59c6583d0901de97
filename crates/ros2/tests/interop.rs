//! ROS 2 interoperability, with nothing of omnitrack-ros2's code on the receiving side:
//!
//! - a ROS 2 node: rclpy of ROS 2 Jazzy over its default middleware, rmw_fastrtps_cpp (Fast DDS),
//!   from PyPI's `ros-jazzy-*` wheels (`tests/rclpy_peer.py`);
//! - an independent DDS implementation: Eclipse Cyclone DDS (the default middleware of several
//!   ROS 2 releases) through its Python binding from PyPI (`cyclonedds`), with the ROS 2
//!   messages' IDL types declared by their DDS names (`tests/cyclonedds_peer.py`).
//!
//! The tests publish poses and status samples on the tracker's iceoryx2 services (the real
//! services, as `omnitrack run` publishes them), run `omnitrack-ros2 publish`, and check every
//! field of what the peers receive on `rt/omnitrack/pose`, `rt/tf` and `rt/diagnostics`: stamps
//! in ROS time (the capture instant on the system clock), frame ids, pose, covariance in ROS's
//! order, `map → odom` against the odometry the Cyclone peer published, diagnostic levels and
//! values, and the ROS graph the rclpy node sees.
//!
//! The DDS participants run in a network namespace the test makes, with only its own loopback
//! interface (multicast on): DDS discovery multicasts, and here it reaches nothing but the test's
//! processes. Namespaces need root (CI runs as root); the peers' packages are installed once into
//! venvs in the per-user cache (`$OMNITRACK_CACHE`, else `$XDG_CACHE_HOME/omnitrack`, else
//! `~/.cache/omnitrack`: `ros2-peers-venv-…`, `ros2-jazzy-venv-…`). Where either is not possible
//! the test says why it did not run, and fails if `CI` is set, so CI can never pass it by skipping.
//!
//! The IDL types of the Cyclone peer and the serde structs of `omnitrack_ros2::msg` are both
//! transcribed from ROS's `.msg` files, so a field out of order in both would pass that wire test:
//! the bytes the publisher writes are also decoded by rosbags with ROS 2 Jazzy's own definitions
//! (and rclpy decodes them with ROS's generated type support).

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use omnitrack_io::publish::{PoseSample, SamplePublisher, StatusSample, TrackerState};
use serde_json::Value;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_omnitrack-ros2");
/// The Cyclone DDS Python binding, pinned: its wheel bundles the C library, no system package.
const CYCLONEDDS: &str = "11.0.1";
/// rosbags, pinned: pure Python, with ROS 2's own message definitions (its Jazzy type store).
const ROSBAGS: &str = "0.11.9";
const PEER: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/cyclonedds_peer.py");

fn skip_or_fail(why: &str) {
    assert!(std::env::var_os("CI").is_none(), "CI must run the interop test: {why}");
    eprintln!("ROS 2 interop test not run: {why}");
}

fn run(cmd: &mut Command) -> Result<(), String> {
    let out = cmd.output().map_err(|e| format!("{cmd:?}: {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!("{cmd:?}: {}", String::from_utf8_lossy(&out.stderr).trim()))
    }
}

/// The per-user cache of omnitrack's tools.
fn cache_dir() -> Result<PathBuf, String> {
    let var = |k: &str| std::env::var_os(k).map(PathBuf::from).filter(|p| p.is_absolute());
    var("OMNITRACK_CACHE")
        .or_else(|| var("XDG_CACHE_HOME").map(|p| p.join("omnitrack")))
        .or_else(|| var("HOME").map(|p| p.join(".cache/omnitrack")))
        .ok_or_else(|| "no per-user cache: neither OMNITRACK_CACHE, XDG_CACHE_HOME nor HOME is set".into())
}

/// The venv's python with `cyclonedds` and `rosbags` importable, made on first use.
fn cyclonedds_python() -> Result<PathBuf, String> {
    let venv = cache_dir()?.join(format!("ros2-peers-venv-cyclonedds-{CYCLONEDDS}-rosbags-{ROSBAGS}"));
    let python = venv.join("bin/python");
    let importable = |p: &Path| {
        Command::new(p)
            .args(["-c", "import cyclonedds.domain, rosbags.typesys"])
            .output()
            .is_ok_and(|o| o.status.success())
    };
    if importable(&python) {
        return Ok(python);
    }
    eprintln!(
        "installing cyclonedds=={CYCLONEDDS} and rosbags=={ROSBAGS} into {} (once)",
        venv.display()
    );
    let started = Instant::now();
    run(Command::new("python3").arg("-m").arg("venv").arg(&venv))?;
    run(Command::new(&python).args([
        "-m",
        "pip",
        "install",
        "--quiet",
        "--disable-pip-version-check",
        &format!("cyclonedds=={CYCLONEDDS}"),
        &format!("rosbags=={ROSBAGS}"),
    ]))?;
    eprintln!("installed in {:.1} s", started.elapsed().as_secs_f64());
    if importable(&python) {
        Ok(python)
    } else {
        Err(format!(
            "{}: cyclonedds and rosbags installed but not importable",
            python.display()
        ))
    }
}

/// ROS 2 Jazzy's rclpy from PyPI, pinned (manylinux wheels of ROS's own build), with its
/// default middleware rmw_fastrtps_cpp (eProsima Fast DDS) and the message packages.
const RCLPY: &[&str] = &[
    "ros-jazzy-rclpy[fastrtps]==7.1.6",
    "ros-jazzy-geometry-msgs==5.3.6",
    "ros-jazzy-diagnostic-msgs==5.3.6",
];

/// The venv's python with ROS 2 Jazzy's rclpy importable, made on first use.
fn rclpy_python() -> Result<PathBuf, String> {
    let venv = cache_dir()?.join("ros2-jazzy-venv-rclpy-7.1.6");
    let python = venv.join("bin/python");
    let importable = |p: &Path| {
        Command::new(p)
            .args(["-c", "import rclpy, geometry_msgs.msg, diagnostic_msgs.msg"])
            .output()
            .is_ok_and(|o| o.status.success())
    };
    if importable(&python) {
        return Ok(python);
    }
    eprintln!("installing {} into {} (once)", RCLPY.join(" "), venv.display());
    let started = Instant::now();
    run(Command::new("python3").arg("-m").arg("venv").arg(&venv))?;
    run(Command::new(&python)
        .args(["-m", "pip", "install", "--quiet", "--disable-pip-version-check"])
        .args(RCLPY))?;
    eprintln!("installed in {:.1} s", started.elapsed().as_secs_f64());
    if importable(&python) {
        Ok(python)
    } else {
        Err(format!("{}: rclpy installed but not importable", python.display()))
    }
}

/// A network namespace with only a loopback interface that multicasts; removed on drop.
struct Netns(String);

impl Netns {
    fn new(tag: &str) -> Result<Netns, String> {
        Netns::with_multicast(tag, true)
    }

    /// Without multicast, the loopback is as Linux leaves it: discovery must go by unicast.
    fn with_multicast(tag: &str, multicast: bool) -> Result<Netns, String> {
        if unsafe { libc::geteuid() } != 0 {
            return Err("network namespaces need root".into());
        }
        let name = format!("omt-ros2-{tag}-{}", std::process::id());
        run(Command::new("ip").args(["netns", "add", &name]))?;
        let ns = Netns(name);
        run(Command::new("ip").args(["-n", &ns.0, "link", "set", "lo", "up"]))?;
        if multicast {
            run(Command::new("ip").args(["-n", &ns.0, "link", "set", "lo", "multicast", "on"]))?;
            run(Command::new("ip").args(["-n", &ns.0, "route", "add", "224.0.0.0/4", "dev", "lo"]))?;
        }
        Ok(ns)
    }

    fn spawn(&self, program: &Path, args: &[&str]) -> Proc {
        Proc(
            Command::new("ip")
                .args(["netns", "exec", &self.0])
                .arg(program)
                .args(args)
                .stdout(Stdio::piped())
                .stderr(Stdio::piped())
                .spawn()
                .expect("start a process in the namespace"),
        )
    }
}

impl Drop for Netns {
    fn drop(&mut self) {
        let _ = Command::new("ip").args(["netns", "del", &self.0]).output();
    }
}

/// A child process, ended when dropped: a failed assertion leaves nothing running.
struct Proc(Child);

impl std::ops::Deref for Proc {
    type Target = Child;
    fn deref(&self) -> &Child {
        &self.0
    }
}

impl std::ops::DerefMut for Proc {
    fn deref_mut(&mut self) -> &mut Child {
        &mut self.0
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Lines of a child's standard output, as they come.
fn lines(child: &mut Child) -> mpsc::Receiver<String> {
    let (tx, rx) = mpsc::channel();
    let out = child.stdout.take().unwrap();
    std::thread::spawn(move || {
        for line in BufReader::new(out).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    rx
}

/// Ends a child and returns what it wrote on standard error.
fn stderr_of(child: &mut Child) -> String {
    let _ = child.kill();
    let mut text = String::new();
    if let Some(mut err) = child.stderr.take() {
        let _ = std::io::Read::read_to_string(&mut err, &mut text);
    }
    let _ = child.wait();
    text
}

fn monotonic_ns() -> i64 {
    omnitrack_ros2::clock::monotonic_ns()
}

/// system − monotonic read by the test itself (std's clock for the system time).
fn offset_ns() -> i64 {
    let m0 = monotonic_ns();
    let s = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos() as i64;
    let m1 = monotonic_ns();
    s - (m0 + m1) / 2
}

/// The pose the test publishes as frame `n`: every field distinct, exact in binary.
fn pose(n: u64, stamp_ns: u64) -> PoseSample {
    let yaw = 0.01 * n as f64;
    let r = UnitQuaternion::from_euler_angles(0.1, -0.2, yaw);
    let q = r.quaternion();
    let s = if q.w < 0.0 { -1.0 } else { 1.0 };
    let mut p = PoseSample {
        timestamp_ns: stamp_ns,
        sequence: n,
        status: if n % 5 == 4 {
            TrackerState::Lost
        } else {
            TrackerState::Tracking
        } as u8,
        position_m: [n as f64 * 0.125, -2.5 + n as f64 / 1024.0, 1.625],
        rotation_wxyz: [s * q.w, s * q.i, s * q.j, s * q.k],
        inliers: 40,
        xi_rad2: 1e-5,
        ..PoseSample::default()
    };
    for (i, c) in p.covariance.iter_mut().enumerate() {
        *c = n as f64 + i as f64 / 64.0;
    }
    p
}

fn f64s(v: &Value) -> Vec<f64> {
    v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
}

fn stamp_ns(v: &Value) -> i64 {
    v[0].as_i64().unwrap() * 1_000_000_000 + v[1].as_i64().unwrap()
}

/// The peer's odometry (`odom()` in cyclonedds_peer.py).
fn odom(t_ns: i64, t0_ns: i64) -> Isometry3<f64> {
    let s = (t_ns - t0_ns) as f64 / 1e9;
    Isometry3::from_parts(
        Translation3::new(0.4 * s, 0.1 * s, 0.0),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.05 * s),
    )
}

/// Checks every field of a pose line (from either peer) against the pose sent with that
/// position; returns its ROS stamp and the pose. `offsets` are system − monotonic as the test read
/// them before and after.
fn check_pose<'a>(
    m: &Value,
    sent: &'a std::collections::HashMap<u64, PoseSample>,
    offsets: (i64, i64),
) -> (i64, &'a PoseSample) {
    let position = f64s(&m["position"]);
    // Frame n is at x = n / 8.
    let k = (position[0] * 8.0).round() as u64;
    let p = sent.get(&k).unwrap_or_else(|| panic!("a pose never sent: {m}"));
    assert_eq!(
        p.pose_status(),
        Ok(TrackerState::Tracking),
        "a lost pose was published: {m}"
    );
    assert_eq!(position, p.position_m.to_vec(), "{m}");
    assert_eq!(m["frame_id"], "map");
    let [w, x, y, z] = p.rotation_wxyz;
    let o = f64s(&m["orientation"]);
    for (got, want) in o.iter().zip([x, y, z, w]) {
        assert!(
            (got - want).abs() < 1e-15,
            "orientation x y z w {o:?}, sent w x y z {:?}",
            p.rotation_wxyz
        );
    }
    // Row-major over x, y, z, rx, ry, rz: ROS's order is omnitrack's, copied exactly.
    assert_eq!(f64s(&m["covariance"]), p.covariance.to_vec(), "{m}");
    // ROS time: the capture instant on the system clock.
    let stamp = stamp_ns(&m["stamp"]);
    let capture = p.timestamp_ns as i64;
    let (lo, hi) = (offsets.0.min(offsets.1), offsets.0.max(offsets.1));
    assert!(
        stamp >= capture + lo - 1_000_000 && stamp <= capture + hi + 1_000_000,
        "stamp {stamp} for capture {capture}: offset {} (test: {lo}..{hi})",
        stamp - capture
    );
    let age = m["received_ns"].as_i64().unwrap() - stamp;
    assert!((0..1_000_000_000).contains(&age), "received {age} ns after its stamp");
    (stamp, p)
}

/// Checks a diagnostics line against the status the tests publish (tracking, rig
/// `interop-rig`, sensor 5 at 30 Hz with 3 drops).
fn check_diagnostics(d: &Value) {
    let s = &d["status"][0];
    assert_eq!(d["status"].as_array().unwrap().len(), 1);
    assert_eq!(
        (s["level"].as_u64(), s["name"].as_str()),
        (Some(0), Some("omnitrack: tracker")),
        "{d}"
    );
    assert_eq!(
        (s["message"].as_str(), s["hardware_id"].as_str()),
        (Some("tracking"), Some("interop-rig"))
    );
    assert_eq!(s["values"]["sensor 5 rate (Hz)"], "30.0");
    assert_eq!(s["values"]["sensor 5 frames dropped"], "3");
    assert_eq!(s["values"]["state"], "tracking");
    let age = d["received_ns"].as_i64().unwrap() - stamp_ns(&d["stamp"]);
    assert!(
        (0..1_000_000_000).contains(&age),
        "diagnostics received {age} ns after its stamp"
    );
}

/// One tick of the tracker as the tests play it: pose `n`, captured 5 ms before it is published
/// (as a live camera's frame would be), kept in `sent`; and every fifth tick a status.
fn publish_tick(
    n: u64,
    poses: &SamplePublisher<PoseSample>,
    statuses: &SamplePublisher<StatusSample>,
    status: &mut StatusSample,
    sent: &mut std::collections::HashMap<u64, PoseSample>,
) {
    let p = pose(n, (monotonic_ns() - 5_000_000) as u64);
    poses.publish(&p).unwrap();
    sent.insert(n, p);
    if n.is_multiple_of(5) {
        status.sequence = n / 5;
        status.timestamp_ns = monotonic_ns() as u64;
        statuses.publish(status).unwrap();
    }
}

/// The status the tests publish, every fifth frame.
fn interop_status() -> StatusSample {
    let mut status = StatusSample {
        tracker_state: TrackerState::Tracking as u8,
        sensor_count: 6,
        ..StatusSample::default()
    };
    status.set_source("interop-rig");
    status.frame_rate_hz[5] = 30.0;
    status.frames_dropped[5] = 3;
    status
}

/// Poses at 50 Hz (every fifth lost) and a status every 100 ms through the real iceoryx2
/// services, into `omnitrack-ros2 publish --tf map-odom`, out to Cyclone DDS; every field read
/// back.
#[test]
fn cyclone_dds_receives_every_field_in_ros_time_and_rep_105_frames() {
    const POSES: usize = 40;
    const DIAGNOSTICS: usize = 5;
    const TRANSFORMS: usize = 30;
    let ns = match Netns::new("a") {
        Ok(ns) => ns,
        Err(why) => return skip_or_fail(&why),
    };
    let python = match cyclonedds_python() {
        Ok(p) => p,
        Err(why) => return skip_or_fail(&why),
    };
    let domain = (std::process::id() % 200 + 10).to_string();
    let service = format!("omnitrack-ros2-test/{}/pose", std::process::id());
    let status_service = format!("omnitrack-ros2-test/{}/status", std::process::id());
    let poses = SamplePublisher::<PoseSample>::create(&service).unwrap();
    let statuses = SamplePublisher::<StatusSample>::create(&status_service).unwrap();
    let t0 = (monotonic_ns() + offset_ns()).to_string();

    let mut peer = ns.spawn(
        &python,
        &[
            PEER,
            "--domain",
            &domain,
            "--poses",
            &POSES.to_string(),
            "--diagnostics",
            &DIAGNOSTICS.to_string(),
            "--transforms",
            &TRANSFORMS.to_string(),
            "--odom",
            &t0,
            "--timeout-s",
            "30",
        ],
    );
    let from_peer = lines(&mut peer);
    let ready = from_peer.recv_timeout(Duration::from_secs(30));
    assert_eq!(ready.as_deref(), Ok("ready"), "peer: {}", stderr_of(&mut peer));
    let mut bridge = ns.spawn(
        Path::new(BIN),
        &[
            "publish",
            "--service",
            &service,
            "--status-service",
            &status_service,
            "--domain-id",
            &domain,
            "--interface",
            "127.0.0.1",
            "--tf",
            "map-odom",
            "--transform-tolerance-s",
            "0.25",
        ],
    );

    let offset_before = offset_ns();
    let mut sent = std::collections::HashMap::new();
    let mut got = Vec::new();
    let start = Instant::now();
    let mut n = 0u64;
    let mut status = interop_status();
    loop {
        publish_tick(n, &poses, &statuses, &mut status, &mut sent);
        n += 1;
        std::thread::sleep(Duration::from_millis(20));
        while let Ok(line) = from_peer.try_recv() {
            got.push(line);
        }
        match peer.try_wait().unwrap() {
            Some(code) if code.success() => break,
            Some(code) => panic!(
                "peer exited {code}: {}\nbridge: {}",
                stderr_of(&mut peer),
                stderr_of(&mut bridge)
            ),
            None if start.elapsed() > Duration::from_secs(90) => {
                panic!("peer: {}\nbridge: {}", stderr_of(&mut peer), stderr_of(&mut bridge))
            }
            None => {}
        }
    }
    while let Ok(line) = from_peer.recv_timeout(Duration::from_millis(200)) {
        got.push(line);
    }
    let offset_after = offset_ns();
    let bridge_log = stderr_of(&mut bridge);
    assert!(bridge_log.contains("clock: system − monotonic = "), "{bridge_log}");

    let parsed: Vec<Value> = got.iter().map(|l| serde_json::from_str(l).unwrap()).collect();
    let of = |topic: &'static str| parsed.iter().filter(move |v| v["topic"] == topic);
    let mut pose_stamps = std::collections::HashMap::new();
    let mut ages = Vec::new();
    let mut checked = 0;
    for m in of("pose") {
        let (stamp, p) = check_pose(m, &sent, (offset_before, offset_after));
        let age = m["received_ns"].as_i64().unwrap() - stamp;
        // From the pose's publication on iceoryx2 (5 ms after its capture) to Cyclone's take.
        ages.push(age - 5_000_000);
        let k = p.sequence;
        pose_stamps.insert(stamp, (k, p));
        checked += 1;
    }
    assert!(checked >= POSES, "{checked} poses");
    ages.sort();
    eprintln!(
        "{checked} poses, iceoryx2 → omnitrack-ros2 → Cyclone DDS: p50 {:.2} ms, max {:.2} ms",
        ages[ages.len() / 2] as f64 / 1e6,
        ages[ages.len() - 1] as f64 / 1e6
    );

    // map → odom at each pose's stamp: T_map_base · T_odom_base(stamp)⁻¹.
    let t0: i64 = t0.parse().unwrap();
    let mut transforms = 0;
    for t in of("tf") {
        assert_eq!(
            (t["parent"].as_str(), t["child"].as_str()),
            (Some("map"), Some("odom")),
            "{t}"
        );
        // Stamped 0.25 s after its pose (--transform-tolerance-s), the transform at the pose's stamp.
        let stamp = stamp_ns(&t["stamp"]) - 250_000_000;
        let Some((_, p)) = pose_stamps.get(&stamp) else {
            continue; // a transform of a pose sent before the peer's reader matched
        };
        let map_base = p.pose().unwrap();
        let want = map_base * odom(stamp, t0).inverse();
        let tr = f64s(&t["translation"]);
        let r = f64s(&t["rotation"]);
        let got = Isometry3::from_parts(
            Translation3::new(tr[0], tr[1], tr[2]),
            UnitQuaternion::from_quaternion(Quaternion::new(r[3], r[0], r[1], r[2])),
        );
        assert!(
            (got.translation.vector - want.translation.vector).norm() < 1e-6
                && got.rotation.angle_to(&want.rotation) < 1e-6,
            "map → odom {got} at {stamp}, expected {want}"
        );
        transforms += 1;
    }
    // /tf is read best effort, and the first poses come before the peer's odometry does: most of
    // the transforms received, not all, are of a pose it received.
    assert!(
        transforms >= TRANSFORMS / 2,
        "{transforms} map → odom transforms matched a pose"
    );
    eprintln!("{transforms} map → odom transforms checked against the peer's odometry");

    let mut diagnostics = 0;
    for d in of("diagnostics") {
        check_diagnostics(d);
        diagnostics += 1;
    }
    assert!(diagnostics >= DIAGNOSTICS, "{diagnostics} diagnostics");
}

/// Standard error of a child, line by line as it comes.
fn error_lines(child: &mut Child) -> mpsc::Receiver<String> {
    let (tx, rx) = mpsc::channel();
    let err = child.stderr.take().unwrap();
    std::thread::spawn(move || {
        for line in BufReader::new(err).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    rx
}

/// What the other tests need: a namespace, Cyclone's python, a domain and the two services.
struct Bench {
    ns: Netns,
    python: PathBuf,
    domain: String,
    service: String,
    status_service: String,
}

impl Bench {
    fn new(tag: &str) -> Result<Bench, String> {
        let ns = Netns::new(tag)?;
        let python = cyclonedds_python()?;
        let id = std::process::id();
        Ok(Bench {
            ns,
            python,
            // Another domain than the first test's, which may run at the same time.
            domain: ((id + tag.len() as u32 * 7) % 200 + 10).to_string(),
            service: format!("omnitrack-ros2-test/{id}/{tag}/pose"),
            status_service: format!("omnitrack-ros2-test/{id}/{tag}/status"),
        })
    }

    /// `omnitrack-ros2 publish` on the bench's services and domain, with `args`; returns it and
    /// its standard error once it has said it started (or ended).
    fn bridge(&self, args: &[&str]) -> (Proc, mpsc::Receiver<String>) {
        let mut all = vec![
            "publish",
            "--service",
            &self.service,
            "--status-service",
            &self.status_service,
            "--domain-id",
            &self.domain,
            "--interface",
            "127.0.0.1",
        ];
        all.extend_from_slice(args);
        let mut child = self.ns.spawn(Path::new(BIN), &all);
        let err = error_lines(&mut child);
        (child, err)
    }

    fn peer(&self, args: &[&str]) -> (Proc, mpsc::Receiver<String>) {
        let mut all = vec![PEER, "--domain", &self.domain];
        all.extend_from_slice(args);
        let mut child = self.ns.spawn(&self.python, &all);
        let out = lines(&mut child);
        assert_eq!(out.recv_timeout(Duration::from_secs(30)).as_deref(), Ok("ready"));
        (child, out)
    }
}

fn wait_exit(child: &mut Child, within: Duration) -> Option<std::process::ExitStatus> {
    let start = Instant::now();
    while start.elapsed() < within {
        if let Some(status) = child.try_wait().unwrap() {
            return Some(status);
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let _ = child.kill();
    None
}

/// A replay's stamps (its recording's time, here the system clock's of the day it was made) on the default
/// `--capture-clock monotonic` end the run with one line naming the option; with
/// `--capture-clock receipt` they are stamped on arrival. And `--durability transient-local
/// --depth 3`: a subscriber that joins after the poses went out gets the last three.
#[test]
fn replay_stamps_are_refused_or_stamped_on_arrival_and_a_late_subscriber_gets_the_last_poses() {
    let bench = match Bench::new("replay") {
        Ok(b) => b,
        Err(why) => return skip_or_fail(&why),
    };
    let poses = SamplePublisher::<PoseSample>::create(&bench.service).unwrap();
    // A recording stamped on the system clock, replayed: far ahead of the monotonic clock.
    let replay_stamp = || (monotonic_ns() + offset_ns()) as u64;
    let tracking = |n: u64| PoseSample {
        status: TrackerState::Tracking as u8,
        ..pose(n, replay_stamp())
    };

    let (mut bridge, err) = bench.bridge(&[]);
    assert!(err.recv_timeout(Duration::from_secs(30)).unwrap().contains("clock: "));
    poses.publish(&tracking(0)).unwrap();
    let code = wait_exit(&mut bridge, Duration::from_secs(10));
    let said: Vec<String> = err.try_iter().collect();
    assert_eq!(code.and_then(|c| c.code()), Some(1), "{said:?}");
    assert_eq!(said.len(), 1, "{said:?}");
    assert!(
        said[0].starts_with("omnitrack-ros2: pose 0: its stamp is 17"),
        "{said:?}"
    );
    assert!(
        said[0].ends_with(
            " s ahead of this host's monotonic clock, not a live capture's: run with --capture-clock receipt"
        ),
        "{said:?}"
    );

    let (mut bridge, err) = bench.bridge(&[
        "--capture-clock",
        "receipt",
        "--durability",
        "transient-local",
        "--depth",
        "3",
    ]);
    assert!(err.recv_timeout(Duration::from_secs(30)).unwrap().contains("clock: "));
    let before = monotonic_ns() + offset_ns();
    for n in 0..10 {
        poses.publish(&tracking(n)).unwrap();
        std::thread::sleep(Duration::from_millis(30));
    }
    std::thread::sleep(Duration::from_millis(500));
    let after = monotonic_ns() + offset_ns();
    // A subscriber of depth 3 keeps the last three. RustDDS 0.15 trims a writer's history to
    // its depth only every 6 s (and keeps up to 8,192 samples while no reader matched), so the
    // late joiner is sent more than three: its own depth keeps the last, as ROS's would.
    let peer_args = ["--poses", "3", "--transient-local", "--depth", "3", "--settle-s", "1"];
    let (mut peer, out) = bench.peer(&[&peer_args[..], &["--timeout-s", "30"]].concat());
    let code = wait_exit(&mut peer, Duration::from_secs(40));
    let _ = bridge.kill();
    let _ = bridge.wait();
    assert_eq!(code.and_then(|c| c.code()), Some(0));
    let got: Vec<Value> = out.try_iter().map(|l| serde_json::from_str(&l).unwrap()).collect();
    let xs: Vec<f64> = got.iter().map(|m| f64s(&m["position"])[0]).collect();
    assert_eq!(
        xs,
        [7.0 * 0.125, 8.0 * 0.125, 9.0 * 0.125],
        "the last three, oldest first"
    );
    for m in &got {
        let stamp = stamp_ns(&m["stamp"]);
        assert!(
            before <= stamp && stamp <= after,
            "stamped {stamp}, published in {before}..{after}"
        );
    }
}

/// SIGTERM (systemd's stop) ends the run with its closing line and exit code 0, within a second.
#[test]
fn sigterm_ends_the_run_with_its_summary() {
    let bench = match Bench::new("term") {
        Ok(b) => b,
        Err(why) => return skip_or_fail(&why),
    };
    let (mut bridge, err) = bench.bridge(&[]);
    assert!(err.recv_timeout(Duration::from_secs(30)).unwrap().contains("clock: "));
    // `ip netns exec` runs the program in its own process: the child is the publisher.
    assert_eq!(unsafe { libc::kill(bridge.id() as i32, libc::SIGTERM) }, 0);
    let code = wait_exit(&mut bridge, Duration::from_secs(1));
    let said: Vec<String> = err.try_iter().collect();
    assert_eq!(code.and_then(|c| c.code()), Some(0), "{said:?}");
    assert_eq!(
        said,
        [
            "omnitrack-ros2: 0 poses received, 0 published, 0 not tracking; 0 transforms, 0 poses without \
          odometry; 0 messages a full reliable window refused"
        ]
    );
}

/// `--tf map-base` is for a rig without odometry: as soon as /tf shows `odom → base_link`, it
/// stops with one line rather than give base_link a second parent.
#[test]
fn map_base_is_refused_when_the_robot_publishes_odometry() {
    let bench = match Bench::new("parent") {
        Ok(b) => b,
        Err(why) => return skip_or_fail(&why),
    };
    let t0 = (monotonic_ns() + offset_ns()).to_string();
    let (mut peer, _out) = bench.peer(&["--poses", "1", "--odom", &t0, "--timeout-s", "30"]);
    let (mut bridge, err) = bench.bridge(&["--tf", "map-base"]);
    let code = wait_exit(&mut bridge, Duration::from_secs(30));
    let _ = peer.kill();
    let _ = peer.wait();
    let said: Vec<String> = err.try_iter().collect();
    assert_eq!(code.and_then(|c| c.code()), Some(1), "{said:?}");
    assert_eq!(
        said.last().map(String::as_str),
        Some(
            "omnitrack-ros2: /tf: base_link already has the parent odom; --tf map-base would give it a second \
             one (REP-105): use --tf map-odom with --odom-frame odom"
        ),
        "{said:?}"
    );
}

/// Decodes `TYPE HEX` lines (CDR with its encapsulation header) with ROS 2 Jazzy's own message
/// definitions (rosbags' type store) and prints each message as JSON, field names as ROS's.
const ROSBAGS_DECODE: &str = r#"
import dataclasses, json, sys
import numpy as np
from rosbags.typesys import Stores, get_typestore
store = get_typestore(Stores.ROS2_JAZZY)
def plain(v):
    if dataclasses.is_dataclass(v):
        # The message's fields, as its definition lists them (its constants are not fields).
        return {name: plain(getattr(v, name)) for name, _ in store.fielddefs[v.__msgtype__][1]}
    if isinstance(v, (list, tuple, np.ndarray)):
        return [plain(x) for x in v]
    if isinstance(v, np.generic):
        return v.item()
    return v
for line in sys.stdin:
    kind, data = line.split()
    print(json.dumps(plain(store.deserialize_cdr(bytes.fromhex(data), kind))), flush=True)
status = store.types["diagnostic_msgs/msg/DiagnosticStatus"]
print(json.dumps({k: getattr(status, k) for k in ("OK", "WARN", "ERROR", "STALE")}))
"#;

/// The CDR bytes the publisher writes for `m`: RustDDS's serializer, as its writer uses it, after
/// the 4-byte encapsulation header (CDR little-endian).
fn cdr<M: serde::Serialize>(m: &M) -> String {
    use ros2_client::dds::rustdds::no_key::SerializerAdapter;
    let body = <ros2_client::dds::rustdds::CDRSerializerAdapter<M> as SerializerAdapter<M>>::to_bytes(m).unwrap();
    let mut hex = String::from("00010000");
    for b in body.iter() {
        hex.push_str(&format!("{b:02x}"));
    }
    hex
}

/// Every message type the publisher writes, serialized as it writes it, decoded by rosbags
/// with ROS 2's definitions: the same fields with the same values, name for name.
#[test]
fn the_bytes_written_decode_with_ros_2s_own_message_definitions() {
    use omnitrack_ros2::msg::*;
    let python = match cyclonedds_python() {
        Ok(p) => p,
        Err(why) => return skip_or_fail(&why),
    };
    let header = |frame: &str| Header {
        stamp: Time {
            sec: 1_795_966_335,
            nanosec: 891_423_007,
        },
        frame_id: frame.into(),
    };
    let mut covariance = [0.0; 36];
    for (i, c) in covariance.iter_mut().enumerate() {
        *c = i as f64 / 64.0 - 0.25;
    }
    let pose = PoseWithCovarianceStamped {
        header: header("map"),
        pose: PoseWithCovariance {
            pose: Pose {
                position: Point {
                    x: 1.5,
                    y: -2.25,
                    z: 0.125,
                },
                orientation: Quaternion {
                    x: 0.1,
                    y: -0.2,
                    z: 0.3,
                    w: 0.9,
                },
            },
            covariance: Covariance(covariance),
        },
    };
    let transform = |child: &str, x: f64| TransformStamped {
        header: header("map"),
        child_frame_id: child.into(),
        transform: Transform {
            translation: Vector3 { x, y: 2.0, z: -3.0 },
            rotation: Quaternion {
                x: 0.0,
                y: 0.0,
                z: 0.6,
                w: 0.8,
            },
        },
    };
    let tf = TfMessage {
        transforms: vec![transform("odom", 1.0), transform("base_link", -7.5)],
    };
    let diagnostics = DiagnosticArray {
        header: header(""),
        status: vec![
            DiagnosticStatus {
                level: ERROR,
                name: "omnitrack: tracker".into(),
                message: "lost, relocalising".into(),
                hardware_id: "ladybug2".into(),
                values: vec![
                    KeyValue {
                        key: "state".into(),
                        value: "lost".into(),
                    },
                    KeyValue {
                        key: "sensor 5 rate (Hz)".into(),
                        value: "29.9".into(),
                    },
                ],
            },
            DiagnosticStatus {
                level: STALE,
                name: "b".into(),
                ..DiagnosticStatus::default()
            },
        ],
    };
    let input = format!(
        "geometry_msgs/msg/PoseWithCovarianceStamped {}\ntf2_msgs/msg/TFMessage {}\ndiagnostic_msgs/msg/DiagnosticArray {}\n",
        cdr(&pose),
        cdr(&tf),
        cdr(&diagnostics)
    );
    let mut child = Command::new(&python)
        .args(["-c", ROSBAGS_DECODE])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::io::Write::write_all(&mut child.stdin.take().unwrap(), input.as_bytes()).unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let decoded: Vec<Value> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let ours = [
        serde_json::to_value(&pose).unwrap(),
        serde_json::to_value(&tf).unwrap(),
        serde_json::to_value(&diagnostics).unwrap(),
    ];
    assert_eq!(decoded.len(), 4);
    for (theirs, ours) in decoded.iter().zip(&ours) {
        assert_eq!(theirs, ours);
    }
    // The levels' values, as ROS defines them.
    assert_eq!(
        decoded[3],
        serde_json::json!({"OK": OK, "WARN": WARN, "ERROR": ERROR, "STALE": STALE})
    );
}

/// `--rig-in-base` (the rig's pose in base_link, x,y,z,qx,qy,qz,qw): the pose published is
/// base_link's, `T_map_rig · T_base_rig⁻¹`, and its covariance moves by the lever arm,
/// `J Σ Jᵀ` with `J = [[I, −[a]×], [0, I]]`, `a = R_map_rig · t_rig_base` (docs/interfaces.md).
#[test]
fn the_rigs_mounting_moves_the_pose_and_its_covariance_to_base_link() {
    use nalgebra::{Matrix3, Matrix6};
    let bench = match Bench::new("mount") {
        Ok(b) => b,
        Err(why) => return skip_or_fail(&why),
    };
    let poses = SamplePublisher::<PoseSample>::create(&bench.service).unwrap();
    // 0.3 m ahead, 1.2 m above the base, pitched 10° down.
    let half = 5f64.to_radians();
    let mount = format!("0.3,0,1.2,0,{},0,{}", half.sin(), half.cos());
    let base_rig = Isometry3::from_parts(
        Translation3::new(0.3, 0.0, 1.2),
        UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 2.0 * half),
    );
    let (mut peer, out) = bench.peer(&["--topic", "mounted/pose", "--poses", "5", "--timeout-s", "30"]);
    let (_bridge, err) = bench.bridge(&["--topic", "mounted/pose", "--rig-in-base", &mount]);
    assert!(err.recv_timeout(Duration::from_secs(30)).unwrap().contains("clock: "));
    let mut sent = Vec::new();
    let start = Instant::now();
    while peer.try_wait().unwrap().is_none() {
        let mut p = pose(sent.len() as u64, (monotonic_ns() - 5_000_000) as u64);
        p.status = TrackerState::Tracking as u8;
        // Uncertain in yaw and in x only.
        p.covariance = [0.0; 36];
        p.covariance[0] = 1e-4;
        p.covariance[35] = 1e-2;
        poses.publish(&p).unwrap();
        sent.push(p);
        std::thread::sleep(Duration::from_millis(20));
        assert!(start.elapsed() < Duration::from_secs(40), "{}", stderr_of(&mut peer));
    }
    assert!(peer.wait().unwrap().success());
    let got: Vec<Value> = out.try_iter().map(|l| serde_json::from_str(&l).unwrap()).collect();
    assert!(got.len() >= 5, "{got:?}");
    for m in &got {
        // Which pose: the one whose base pose this is.
        let position = Vector3::from_vec(f64s(&m["position"]));
        let p = sent
            .iter()
            .find(|p| ((p.pose().unwrap() * base_rig.inverse()).translation.vector - position).norm() < 1e-9)
            .unwrap_or_else(|| panic!("no pose sent has this base position: {m}"));
        let map_rig = p.pose().unwrap();
        let want = map_rig * base_rig.inverse();
        let o = f64s(&m["orientation"]);
        let got_rotation = UnitQuaternion::from_quaternion(Quaternion::new(o[3], o[0], o[1], o[2]));
        assert!(got_rotation.angle_to(&want.rotation) < 1e-12, "{m}");
        let a = map_rig.rotation * base_rig.inverse().translation.vector;
        let skew = Matrix3::new(0.0, -a.z, a.y, a.z, 0.0, -a.x, -a.y, a.x, 0.0);
        let mut j = Matrix6::<f64>::identity();
        j.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-skew));
        let want_cov = j * Matrix6::from_row_slice(&p.covariance) * j.transpose();
        let cov = f64s(&m["covariance"]);
        for (i, c) in cov.iter().enumerate() {
            assert!(
                (c - want_cov[(i / 6, i % 6)]).abs() < 1e-15,
                "covariance[{i}] {c}, expected {want_cov}"
            );
        }
        // The base, away from the rig, moves sideways when the yaw is off: x-y terms appear.
        assert!(cov[1].abs() > 1e-6 && cov[5].abs() > 1e-6, "{cov:?}");
    }
}

/// A real ROS 2 node: rclpy of ROS 2 Jazzy over Fast DDS (its default middleware) subscribes with
/// ROS's default QoS and receives every field as the Cyclone peer does; its graph shows the node
/// `/omnitrack` publishing the pose topic with the QoS asked for (`ros2 node list`, `ros2 topic
/// info -v`).
#[test]
fn a_ros_2_jazzy_node_over_fast_dds_receives_every_field_and_sees_the_publisher() {
    const POSES: usize = 20;
    let bench = match Bench::new("rclpy") {
        Ok(b) => b,
        Err(why) => return skip_or_fail(&why),
    };
    let python = match rclpy_python() {
        Ok(p) => p,
        Err(why) => return skip_or_fail(&why),
    };
    let poses = SamplePublisher::<PoseSample>::create(&bench.service).unwrap();
    let statuses = SamplePublisher::<StatusSample>::create(&bench.status_service).unwrap();
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/rclpy_peer.py");
    let domain = format!("ROS_DOMAIN_ID={}", bench.domain);
    let python = python.to_string_lossy().into_owned();
    let args = [
        &domain,
        &python,
        script,
        "--poses",
        "20",
        "--diagnostics",
        "2",
        "--timeout-s",
        "60",
    ];
    let mut peer = bench.ns.spawn(Path::new("env"), &args);
    let from_peer = lines(&mut peer);
    let ready = from_peer.recv_timeout(Duration::from_secs(60));
    assert_eq!(ready.as_deref(), Ok("ready"), "peer: {}", stderr_of(&mut peer));
    let (mut bridge, err) = bench.bridge(&["--durability", "transient-local", "--depth", "5"]);
    assert!(err.recv_timeout(Duration::from_secs(30)).unwrap().contains("clock: "));

    let offset_before = offset_ns();
    let mut sent = std::collections::HashMap::new();
    let mut status = interop_status();
    let start = Instant::now();
    let mut n = 0u64;
    loop {
        publish_tick(n, &poses, &statuses, &mut status, &mut sent);
        n += 1;
        std::thread::sleep(Duration::from_millis(20));
        match peer.try_wait().unwrap() {
            Some(code) if code.success() => break,
            Some(code) => panic!(
                "peer exited {code}: {}\nbridge: {}",
                stderr_of(&mut peer),
                stderr_of(&mut bridge)
            ),
            None if start.elapsed() > Duration::from_secs(90) => {
                panic!("peer: {}\nbridge: {}", stderr_of(&mut peer), stderr_of(&mut bridge))
            }
            None => {}
        }
    }
    let offset_after = offset_ns();
    let got: Vec<Value> = from_peer
        .try_iter()
        .map(|l| serde_json::from_str(&l).unwrap())
        .collect();
    let of = |topic: &'static str| got.iter().filter(move |v| v["topic"] == topic);
    let mut checked = 0;
    for m in of("pose") {
        check_pose(m, &sent, (offset_before, offset_after));
        checked += 1;
    }
    assert!(checked >= POSES, "{checked} poses");
    let mut diagnostics = 0;
    for d in of("diagnostics") {
        check_diagnostics(d);
        diagnostics += 1;
    }
    assert!(diagnostics >= 2, "{diagnostics} diagnostics");
    let graph = of("graph").next().expect("the peer's graph line");
    assert!(
        graph["nodes"].as_array().unwrap().iter().any(|n| n == "/omnitrack"),
        "{graph}"
    );
    assert_eq!(
        graph["publishers"],
        serde_json::json!([{
            "node": "omnitrack",
            "namespace": "/",
            "type": "geometry_msgs/msg/PoseWithCovarianceStamped",
            "reliability": "RELIABLE",
            "durability": "TRANSIENT_LOCAL",
        }])
    );
}

/// `ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST` (ROS 2 Jazzy's way of keeping a node on its host),
/// with no `--interface`: on a loopback without multicast, as Linux leaves it, the rclpy node
/// and the publisher find each other by unicast and the poses arrive.
#[test]
fn localhost_discovery_as_ros_2_sets_it_reaches_a_ros_2_node() {
    let ns = match Netns::with_multicast("localhost", false) {
        Ok(ns) => ns,
        Err(why) => return skip_or_fail(&why),
    };
    let python = match rclpy_python() {
        Ok(p) => p,
        Err(why) => return skip_or_fail(&why),
    };
    let id = std::process::id();
    let service = format!("omnitrack-ros2-test/{id}/localhost/pose");
    let status_service = format!("omnitrack-ros2-test/{id}/localhost/status");
    let poses = SamplePublisher::<PoseSample>::create(&service).unwrap();
    let domain = format!("ROS_DOMAIN_ID={}", id % 200 + 20);
    let range = "ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST";
    let python = python.to_string_lossy().into_owned();
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/rclpy_peer.py");
    let peer_args = [
        &domain,
        range,
        &python,
        script,
        "--poses",
        "5",
        "--diagnostics",
        "0",
        "--timeout-s",
        "60",
    ];
    let mut peer = ns.spawn(Path::new("env"), &peer_args);
    let from_peer = lines(&mut peer);
    let ready = from_peer.recv_timeout(Duration::from_secs(60));
    assert_eq!(ready.as_deref(), Ok("ready"), "peer: {}", stderr_of(&mut peer));
    let bridge_args = [
        &domain,
        range,
        BIN,
        "publish",
        "--service",
        &service,
        "--status-service",
        &status_service,
    ];
    let mut bridge = ns.spawn(Path::new("env"), &bridge_args);
    let start = Instant::now();
    let mut n = 0;
    while peer.try_wait().unwrap().is_none() {
        let mut p = pose(n, (monotonic_ns() - 5_000_000) as u64);
        p.status = TrackerState::Tracking as u8;
        poses.publish(&p).unwrap();
        n += 1;
        std::thread::sleep(Duration::from_millis(20));
        if start.elapsed() > Duration::from_secs(70) {
            panic!("peer: {}\nbridge: {}", stderr_of(&mut peer), stderr_of(&mut bridge));
        }
    }
    assert!(peer.wait().unwrap().success(), "peer: {}", stderr_of(&mut peer));
    let got: Vec<Value> = from_peer
        .try_iter()
        .map(|l| serde_json::from_str(&l).unwrap())
        .collect();
    assert!(got.iter().filter(|m| m["topic"] == "pose").count() >= 5, "{got:?}");
    let graph = got.iter().find(|m| m["topic"] == "graph").expect("the graph line");
    assert!(
        graph["nodes"].as_array().unwrap().iter().any(|n| n == "/omnitrack"),
        "{graph}"
    );
}
