//! Other local users against the tracker's shared memory (issue 50, items 1 and 2): who can
//! subscribe, who can disturb, and what a start says when another user is in the way.
//!
//! In: processes run as other users, the way a rig's computer has them: the tracker as one
//! system user (`daemon` here, standing for `omnitrack`), a consumer in the tracker's group
//! (`bin`, given the tracker's group), an outsider (`nobody`), and root. Each test has an iceoryx2
//! domain of its own (root folder and file prefix, in `config/iceoryx2.toml` of a fresh working
//! directory, which every iceoryx2 process reads first), so a tracker or test running beside it
//! is not disturbed; its files are removed at the end. The tracker and the raw consumer are this
//! test binary run again ([`helper`]); the listeners are `omnitrack listen`. Out: pass or fail;
//! where this process cannot run processes as other users (not root) each test says so and
//! passes.

use std::fs;
use std::io::{BufRead, BufReader, Write};
use std::os::unix::fs::{MetadataExt, PermissionsExt};
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use omnitrack::publish::{PosePublisher, PoseSample};

/// Where iceoryx2's shared-memory files are (`omnitrack::publish::SHM_DIR`; spelled here so that
/// this file builds against the landed main too, where it fails).
const SHM_DIR: &str = "/dev/shm";
/// omnitrack's own node counter file's suffix (`omnitrack::publish::COUNTER_SUFFIX`).
const COUNTER_SUFFIX: &str = ".omnitrack_mgmt";

/// A user to run a process as.
#[derive(Clone, Copy, Debug)]
struct User {
    uid: u32,
    gid: u32,
    /// Supplementary groups.
    groups: &'static [u32],
}

/// The tracker's user and group (`daemon`, 1:1), as `omnitrack` is in tools/deploy.
const TRACKER: User = User {
    uid: 1,
    gid: 1,
    groups: &[],
};
/// A consumer of another user in the tracker's group (`bin`, 2:2, member of group 1).
const MEMBER: User = User {
    uid: 2,
    gid: 2,
    groups: &[1],
};
/// Another local user (`nobody`).
const OUTSIDER: User = User {
    uid: 65534,
    gid: 65534,
    groups: &[],
};

/// How the error lines name a user: `name (uid N)` from /etc/passwd, or `uid N`.
fn user_named(uid: u32) -> String {
    match id_name("/etc/passwd", uid) {
        Some(name) => format!("{name} (uid {uid})"),
        None => format!("uid {uid}"),
    }
}

/// How the error lines name a group: its name from /etc/group, or its number.
fn group_named(gid: u32) -> String {
    id_name("/etc/group", gid).unwrap_or_else(|| gid.to_string())
}

fn id_name(file: &str, id: u32) -> Option<String> {
    fs::read_to_string(file).ok()?.lines().find_map(|l| {
        let f: Vec<&str> = l.split(':').collect();
        (f.get(2)?.parse::<u32>().ok()? == id).then(|| f[0].to_string())
    })
}

/// Whether processes can be run as other users here; says why not when they cannot.
fn can_switch_users(test: &str) -> bool {
    // SAFETY: reads this process's effective user id.
    let root = unsafe { libc::geteuid() } == 0;
    if !root {
        eprintln!(
            "{test}: skipped: running processes as other users needs root, and this runs as uid {}",
            unsafe { libc::geteuid() }
        );
        return false;
    }
    // A checkout in a private folder (a home of mode 0700) keeps the binaries from other users:
    // then no test here can run, which is the machine's doing, not the tracker's.
    for program in [
        std::env::current_exe().unwrap(),
        PathBuf::from(env!("CARGO_BIN_EXE_omnitrack")),
    ] {
        let mut probe = Command::new(&program);
        probe.arg("--help").stdout(Stdio::null()).stderr(Stdio::null());
        // SAFETY: between fork and exec the closure makes only async-signal-safe system calls.
        unsafe {
            probe.pre_exec(|| {
                if libc::setgroups(0, std::ptr::null()) != 0
                    || libc::setgid(OUTSIDER.gid) != 0
                    || libc::setuid(OUTSIDER.uid) != 0
                {
                    return Err(std::io::Error::last_os_error());
                }
                Ok(())
            });
        }
        if let Err(e) = probe.status() {
            eprintln!(
                "{test}: skipped: other users cannot run {} ({e}): the checkout is in a folder they cannot enter",
                program.display()
            );
            return false;
        }
    }
    true
}

/// An iceoryx2 domain of one test: a working directory whose `config/iceoryx2.toml` names a root
/// folder inside it and a prefix of its own.
struct TestDomain {
    dir: tempfile::TempDir,
    prefix: String,
}

impl TestDomain {
    fn new(tag: &str) -> Self {
        let dir = tempfile::Builder::new().prefix("omnitrack-shm-").tempdir().unwrap();
        // Like /tmp: anyone may make the root folder first.
        fs::set_permissions(dir.path(), fs::Permissions::from_mode(0o1777)).unwrap();
        let prefix = format!("ot{}{tag}_", std::process::id());
        let config = dir.path().join("config");
        fs::create_dir(&config).unwrap();
        fs::set_permissions(&config, fs::Permissions::from_mode(0o755)).unwrap();
        let root = dir.path().join("iceoryx2");
        fs::write(
            config.join("iceoryx2.toml"),
            format!("[global]\nroot-path = \"{}/\"\nprefix = \"{prefix}\"\n", root.display()),
        )
        .unwrap();
        fs::set_permissions(config.join("iceoryx2.toml"), fs::Permissions::from_mode(0o644)).unwrap();
        TestDomain { dir, prefix }
    }

    fn root(&self) -> PathBuf {
        self.dir.path().join("iceoryx2")
    }

    /// The domain's files in /dev/shm.
    fn shm_files(&self) -> Vec<PathBuf> {
        let mut files: Vec<PathBuf> = fs::read_dir(SHM_DIR)
            .unwrap()
            .flatten()
            .filter(|e| e.file_name().to_string_lossy().starts_with(&self.prefix))
            .map(|e| e.path())
            .collect();
        files.sort();
        files
    }

    /// Every node counter file of the domain: iceoryx2's (`.global_mgmt`) and omnitrack's.
    fn counter_files(&self) -> Vec<PathBuf> {
        self.shm_files()
            .into_iter()
            .filter(|p| p.to_string_lossy().ends_with("_mgmt"))
            .collect()
    }

    /// Every file and folder of the domain, with its owner, group and mode.
    fn all_files(&self) -> Vec<(PathBuf, u32, u32, u32)> {
        fn walk(dir: &Path, out: &mut Vec<(PathBuf, u32, u32, u32)>) {
            let Ok(entries) = fs::read_dir(dir) else { return };
            for e in entries.flatten() {
                let Ok(m) = fs::symlink_metadata(e.path()) else {
                    continue;
                };
                out.push((e.path(), m.uid(), m.gid(), m.mode() & 0o7777));
                if m.is_dir() {
                    walk(&e.path(), out);
                }
            }
        }
        let mut out = Vec::new();
        if let Ok(m) = fs::symlink_metadata(self.root()) {
            out.push((self.root(), m.uid(), m.gid(), m.mode() & 0o7777));
        }
        walk(&self.root(), &mut out);
        for p in self.shm_files() {
            if let Ok(m) = fs::symlink_metadata(&p) {
                out.push((p, m.uid(), m.gid(), m.mode() & 0o7777));
            }
        }
        out
    }

    /// A command run in the domain as `user` (`None`: as this process, root).
    fn command(&self, program: &Path, user: Option<User>) -> Command {
        let mut cmd = Command::new(program);
        cmd.current_dir(self.dir.path())
            .env_remove("IOX2_LOG_LEVEL")
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        if let Some(u) = user {
            // SAFETY: between fork and exec the closure makes only async-signal-safe system calls
            // on memory it owns.
            unsafe {
                cmd.pre_exec(move || {
                    let groups: Vec<libc::gid_t> = u.groups.to_vec();
                    if libc::setgroups(groups.len(), groups.as_ptr()) != 0
                        || libc::setgid(u.gid) != 0
                        || libc::setuid(u.uid) != 0
                    {
                        return Err(std::io::Error::last_os_error());
                    }
                    Ok(())
                });
            }
        }
        cmd
    }

    /// `omnitrack ARGS` as `user`, killed after `timeout`: (exit code or `None` if it had to be
    /// killed, stdout, stderr).
    fn omnitrack(&self, user: Option<User>, args: &[&str], timeout: Duration) -> (Option<i32>, String, String) {
        let child = self
            .command(Path::new(env!("CARGO_BIN_EXE_omnitrack")), user)
            .args(args)
            .spawn()
            .unwrap();
        finish(child, timeout)
    }

    /// This test binary's [`helper`] as `user`, doing `role`.
    fn helper(&self, user: Option<User>, role: &str) -> Running {
        let child = self
            .command(&std::env::current_exe().unwrap(), user)
            .args([
                "helper",
                "--exact",
                "--ignored",
                "--nocapture",
                "--test-threads=1",
                "-q",
            ])
            .env("OMNITRACK_SHM_ROLE", role)
            .spawn()
            .unwrap();
        Running::new(child)
    }
}

impl Drop for TestDomain {
    fn drop(&mut self) {
        for p in self.shm_files() {
            let _ = fs::remove_file(p);
        }
        // The TempDir removes the root folder with the rest.
    }
}

/// Waits for `child` at most `timeout`, then kills it.
fn finish(mut child: Child, timeout: Duration) -> (Option<i32>, String, String) {
    let start = Instant::now();
    let code = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status.code();
        }
        if start.elapsed() > timeout {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let mut out = String::new();
    let mut err = String::new();
    let _ = std::io::Read::read_to_string(child.stdout.as_mut().unwrap(), &mut out);
    let _ = std::io::Read::read_to_string(child.stderr.as_mut().unwrap(), &mut err);
    (code, out, err)
}

/// A helper process whose standard output is read line by line.
struct Running {
    child: Child,
    lines: mpsc::Receiver<String>,
}

impl Running {
    fn new(mut child: Child) -> Self {
        let (tx, lines) = mpsc::channel();
        let stdout = child.stdout.take().unwrap();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        Running { child, lines }
    }

    /// The helper's first line that says how it went (`ready`, `got …`, `error: …`, …), or
    /// `None` when it said nothing in `timeout`.
    fn said(&self, timeout: Duration) -> Option<String> {
        let deadline = Instant::now() + timeout;
        loop {
            let left = deadline.checked_duration_since(Instant::now())?;
            match self.lines.recv_timeout(left) {
                Ok(l)
                    if ["ready", "got ", "error: ", "none", "done", "refused: "]
                        .iter()
                        .any(|p| l.starts_with(p)) =>
                {
                    return Some(l)
                }
                Ok(_) => continue,
                Err(_) => return None,
            }
        }
    }
}

impl Running {
    /// Waits at most `timeout` for the process to end (killed after): its exit code (`None`
    /// when killed), its standard output's lines and its standard error.
    fn end(mut self, timeout: Duration) -> (Option<i32>, Vec<String>, String) {
        let start = Instant::now();
        let code = loop {
            if let Some(status) = self.child.try_wait().unwrap() {
                break status.code();
            }
            if start.elapsed() > timeout {
                let _ = self.child.kill();
                let _ = self.child.wait();
                break None;
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        let lines: Vec<String> =
            std::iter::from_fn(|| self.lines.recv_timeout(Duration::from_millis(200)).ok()).collect();
        let mut err = String::new();
        let _ = std::io::Read::read_to_string(self.child.stderr.as_mut().unwrap(), &mut err);
        (code, lines, err)
    }
}

impl Drop for Running {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn sample(seq: u64) -> PoseSample {
    PoseSample {
        sequence: seq,
        timestamp_ns: 1_000 + seq,
        status: 1,
        rotation_wxyz: [1.0, 0.0, 0.0, 0.0],
        ..PoseSample::default()
    }
}

/// Not a test: what the tests run as another user (`OMNITRACK_SHM_ROLE`):
/// - `publish SERVICE`: a tracker: says `ready` (or `error: …`), then publishes a pose every
///   10 ms for 30 s;
/// - `rawsub SERVICE`: a consumer that knows nothing of omnitrack's library, iceoryx2 with the
///   config every iceoryx2 process finds: says `got seq=N` for its first sample, or `none`;
/// - `damage FILE ff|truncate`: writes 16 bytes of 0xff into FILE, or cuts it to nothing: `done`
///   or `refused: …`.
#[test]
#[ignore = "run by the other tests as another user"]
fn helper() {
    let Ok(role) = std::env::var("OMNITRACK_SHM_ROLE") else {
        return;
    };
    let words: Vec<&str> = role.split(' ').collect();
    let say = |line: String| {
        let mut out = std::io::stdout().lock();
        let _ = writeln!(out, "{line}");
        let _ = out.flush();
    };
    match words.as_slice() {
        ["publish", service] => match PosePublisher::create(service) {
            Err(e) => {
                say(format!("error: {e}"));
                std::process::exit(2)
            }
            Ok(p) => {
                say("ready".into());
                let start = Instant::now();
                let mut seq = 0;
                while start.elapsed() < Duration::from_secs(30) {
                    let _ = p.publish(&sample(seq));
                    seq += 1;
                    std::thread::sleep(Duration::from_millis(10));
                }
                std::process::exit(0)
            }
        },
        ["rawsub", service] => {
            let code = match raw_subscriber(service) {
                Ok(Some(seq)) => {
                    say(format!("got seq={seq}"));
                    0
                }
                Ok(None) => {
                    say("none".into());
                    1
                }
                Err(e) => {
                    say(format!("error: {e}"));
                    2
                }
            };
            std::process::exit(code)
        }
        ["damage", file, how] => {
            let r = fs::OpenOptions::new().write(true).open(file).and_then(|f| match *how {
                "ff" => std::os::unix::fs::FileExt::write_all_at(&f, &[0xff; 16], 0),
                _ => f.set_len(0),
            });
            say(match r {
                Ok(()) => "done".into(),
                Err(e) => format!("refused: {e}"),
            });
            std::process::exit(0)
        }
        _ => panic!("unknown role {role:?}"),
    }
}

/// A subscriber made with iceoryx2 alone, as a consumer in another language would be: the
/// config iceoryx2 finds by itself, the service's settings from docs/interfaces.md.
fn raw_subscriber(service: &str) -> Result<Option<u64>, String> {
    use iceoryx2::prelude::*;
    set_log_level(LogLevel::Error);
    let node = NodeBuilder::new()
        .create::<ipc::Service>()
        .map_err(|e| format!("node: {e:?}"))?;
    let name = ServiceName::new(service).map_err(|e| format!("{e:?}"))?;
    let pubsub = node
        .service_builder(&name)
        .publish_subscribe::<PoseSample>()
        .history_size(1)
        .subscriber_max_buffer_size(8)
        .enable_safe_overflow(true)
        .max_subscribers(16)
        .max_publishers(2)
        .open_or_create()
        .map_err(|e| format!("service: {e:?}"))?;
    let subscriber = pubsub
        .subscriber_builder()
        .create()
        .map_err(|e| format!("subscriber: {e:?}"))?;
    let start = Instant::now();
    while start.elapsed() < Duration::from_secs(10) {
        if let Some(s) = subscriber.receive().map_err(|e| format!("receive: {e:?}"))? {
            return Ok(Some(s.payload().sequence));
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    Ok(None)
}

/// Item 1: another user damaging iceoryx2's node counter file (mode 0666 in iceoryx2 0.10) made
/// every later `run` fail ("UnableToGenerateUniqueNodeId") or hang, and every `listen` hang.
/// Now omnitrack's nodes count in a file of their own, made group-only, so the outsider's writes
/// are refused and every new tracker and listener starts.
#[test]
fn another_user_cannot_stop_new_trackers_or_listeners_through_the_node_counter() {
    if !can_switch_users("another_user_cannot_stop_new_trackers_or_listeners_through_the_node_counter") {
        return;
    }
    let d = TestDomain::new("n");
    let tracker = d.helper(Some(TRACKER), "publish omnitrack/pose");
    assert_eq!(tracker.said(Duration::from_secs(10)).as_deref(), Some("ready"));
    for (round, attack) in ["ff", "truncate"].into_iter().enumerate() {
        let counters = d.counter_files();
        assert!(!counters.is_empty(), "no node counter file in {:?}", d.shm_files());
        for f in &counters {
            let what = d.helper(Some(OUTSIDER), &format!("damage {} {attack}", f.display()));
            eprintln!(
                "nobody, {attack} {}: {:?}",
                f.display(),
                what.said(Duration::from_secs(5))
            );
        }
        let next = d.helper(Some(TRACKER), &format!("publish omnitrack/next{round}"));
        let said = next.said(Duration::from_secs(10));
        assert_eq!(
            said.as_deref(),
            Some("ready"),
            "a new tracker after nobody's {attack} (None: it hung)"
        );
        let (code, out, err) = d.omnitrack(Some(TRACKER), &["listen", "--count", "1"], Duration::from_secs(10));
        assert_eq!(code, Some(0), "listen after nobody's {attack} (None: it hung): {err}");
        assert!(out.starts_with("seq="), "{out}");
    }
}

/// Item 1, the file damaged by someone allowed to write it (a member of the group, a crash
/// mid-write): a truncated counter file made iceoryx2 wait for ever, a wrong version made it
/// refuse. Every new process repairs it (it only counts) and starts.
#[test]
fn a_damaged_node_counter_is_repaired_not_waited_on() {
    if !can_switch_users("a_damaged_node_counter_is_repaired_not_waited_on") {
        return;
    }
    let d = TestDomain::new("r");
    let tracker = d.helper(Some(TRACKER), "publish omnitrack/pose");
    assert_eq!(tracker.said(Duration::from_secs(10)).as_deref(), Some("ready"));
    for attack in ["truncate", "ff"] {
        for f in d.counter_files() {
            let what = d.helper(Some(TRACKER), &format!("damage {} {attack}", f.display()));
            assert_eq!(what.said(Duration::from_secs(5)).as_deref(), Some("done"));
        }
        let (code, out, err) = d.omnitrack(Some(TRACKER), &["listen", "--count", "1"], Duration::from_secs(10));
        assert_eq!(code, Some(0), "listen after a {attack} (None: it hung): {err}");
        assert!(out.starts_with("seq="), "{out}");
        for f in d.counter_files() {
            assert_eq!(fs::metadata(&f).unwrap().len(), 16, "{} not repaired", f.display());
        }
    }
}

/// Item 2: whoever made the domain first owned it: a consumer of another user starting before
/// the tracker left `/tmp/iceoryx2` as its own 0750 folder and the tracker failed with "create
/// node: InternalError". Now the tracker refuses in one line that names the folder, its owner and
/// what to do.
#[test]
fn a_user_who_makes_the_domain_first_is_named_and_refused() {
    if !can_switch_users("a_user_who_makes_the_domain_first_is_named_and_refused") {
        return;
    }
    let d = TestDomain::new("f");
    let outsider = d
        .command(Path::new(env!("CARGO_BIN_EXE_omnitrack")), Some(OUTSIDER))
        .args(["listen"])
        .spawn()
        .unwrap();
    let outsider = Running::new(outsider);
    let start = Instant::now();
    while !d.root().join("services").exists() && start.elapsed() < Duration::from_secs(10) {
        std::thread::sleep(Duration::from_millis(20));
    }
    assert_eq!(fs::metadata(d.root()).unwrap().uid(), OUTSIDER.uid);
    let tracker = d.helper(Some(TRACKER), "publish omnitrack/pose");
    let said = tracker.said(Duration::from_secs(10)).unwrap_or_default();
    let root = d.root();
    assert!(
        said.starts_with("error: ")
            && said.contains(&format!("{} is owned by {}", root.display(), user_named(OUTSIDER.uid)))
            && said.contains(&format!("sudo rm -r {}", root.display()))
            && said.contains("tools/deploy/omnitrack.tmpfiles"),
        "{said}"
    );
    // A consumer in the group does not take the outsider's poses for the tracker's either.
    let (code, _, err) = d.omnitrack(Some(MEMBER), &["listen", "--count", "1"], Duration::from_secs(10));
    assert_eq!(code, Some(2), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.contains(&format!("is owned by {}", user_named(OUTSIDER.uid))),
        "{err}"
    );
    drop(outsider);
}

/// The lines of tools/deploy/omnitrack.tmpfiles applied to a test domain: its paths moved into
/// the domain, its user and group the tracker's. Returns how many lines were applied.
fn apply_tmpfiles(d: &TestDomain) -> usize {
    let text = fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/tools/deploy/omnitrack.tmpfiles")).unwrap();
    let root = d.root();
    let mut applied = 0;
    for line in text
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
    {
        let f: Vec<&str> = line.split_whitespace().collect();
        if f[0] == "x" {
            continue;
        }
        assert!(f.len() >= 5, "{line}");
        let path = f[1]
            .replace("/tmp/iceoryx2", &root.display().to_string())
            .replace("/dev/shm/iox2_", &format!("{SHM_DIR}/{}", d.prefix));
        let mode = u32::from_str_radix(f[2], 8).unwrap_or(0);
        assert!(f[3] == "omnitrack" || f[3] == "-", "{line}");
        match f[0] {
            "d" => fs::create_dir(&path).unwrap(),
            "f" => drop(fs::File::create(&path).unwrap()),
            other => panic!("tmpfiles type {other} in {line}"),
        }
        std::os::unix::fs::chown(&path, Some(TRACKER.uid), Some(TRACKER.gid)).unwrap();
        fs::set_permissions(&path, fs::Permissions::from_mode(mode)).unwrap();
        assert_eq!(mode & 0o007, 0, "{line} lets every user in");
        applied += 1;
    }
    applied
}

/// Item 2, deployed as tools/deploy says: the domain made at boot for the tracker's user and
/// group. The tracker's group (a consumer of another user, refused before, since iceoryx2 makes
/// every file owner-only), root and a plain iceoryx2 consumer of the tracker's user receive its
/// poses, before or after it starts; an outsider can neither subscribe nor take the service nor
/// damage the node counter, and nothing in the domain is open to other users.
#[test]
fn only_the_trackers_group_and_root_reach_its_files() {
    if !can_switch_users("only_the_trackers_group_and_root_reach_its_files") {
        return;
    }
    let d = TestDomain::new("g");
    assert!(
        apply_tmpfiles(&d) >= 4,
        "tools/deploy/omnitrack.tmpfiles makes the folders and counters"
    );
    // A consumer of the group that starts before the tracker.
    let early = Running::new(
        d.command(Path::new(env!("CARGO_BIN_EXE_omnitrack")), Some(MEMBER))
            .args(["listen", "--count", "2"])
            .spawn()
            .unwrap(),
    );
    std::thread::sleep(Duration::from_millis(300));
    // An outsider cannot take the service before the tracker.
    let squatter = d.helper(Some(OUTSIDER), "publish omnitrack/pose");
    let said = squatter.said(Duration::from_secs(10)).unwrap_or_default();
    assert!(
        said.starts_with("error: ")
            && said.contains(&format!("is owned by {}", user_named(TRACKER.uid)))
            && said.contains(&format!("nor in group {}", group_named(TRACKER.gid))),
        "{said}"
    );
    let tracker = d.helper(Some(TRACKER), "publish omnitrack/pose");
    assert_eq!(tracker.said(Duration::from_secs(10)).as_deref(), Some("ready"));
    let (code, lines, err) = early.end(Duration::from_secs(10));
    assert_eq!(code, Some(0), "the consumer that started first: {err}");
    assert_eq!(lines.len(), 2, "{lines:?}");
    for (who, user) in [("a member of the group", Some(MEMBER)), ("root", None)] {
        let (code, out, err) = d.omnitrack(user, &["listen", "--count", "3"], Duration::from_secs(10));
        assert_eq!(code, Some(0), "{who}: {err}");
        assert_eq!(out.lines().count(), 3, "{who}: {out}");
    }
    let raw = d.helper(Some(TRACKER), "rawsub omnitrack/pose");
    let got = raw.said(Duration::from_secs(15)).unwrap_or_default();
    assert!(
        got.starts_with("got seq="),
        "a plain iceoryx2 consumer of the tracker's user: {got}"
    );
    // The outsider: refused in one line that says who may subscribe.
    let (code, _, err) = d.omnitrack(Some(OUTSIDER), &["listen", "--count", "1"], Duration::from_secs(10));
    assert_eq!(code, Some(2), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.contains(&format!("sudo usermod -aG {} USER", group_named(TRACKER.gid))),
        "{err}"
    );
    for f in d.counter_files() {
        let what = d.helper(Some(OUTSIDER), &format!("damage {} truncate", f.display()));
        let said = what.said(Duration::from_secs(5)).unwrap_or_default();
        assert!(said.starts_with("refused: "), "nobody on {}: {said}", f.display());
    }
    for (path, uid, gid, mode) in d.all_files() {
        assert_eq!(
            mode & 0o007,
            0,
            "{} ({uid}:{gid} {mode:o}) is open to other users",
            path.display()
        );
        assert!(
            [TRACKER.uid, MEMBER.uid, 0].contains(&uid),
            "{} belongs to uid {uid}",
            path.display()
        );
    }
    // The counter files in use are the two tmpfiles made (iceoryx2 names them so), filled.
    let counters = d.counter_files();
    assert_eq!(counters.len(), 2, "{counters:?}");
    assert!(
        counters.iter().any(|p| p.to_string_lossy().ends_with(COUNTER_SUFFIX)),
        "{counters:?}"
    );
    for p in &counters {
        assert_eq!(fs::metadata(p).unwrap().len(), 16, "{} not filled", p.display());
    }
}

/// The tracker killed (SIGKILL, the OOM killer) and started again, as systemd does, with a
/// consumer of another user in its group listening throughout: the new tracker cleans up what
/// the dead one left (its own files; the consumer cannot see whether another user's node is
/// dead, so it leaves them alone) and the consumer receives from it without reconnecting.
#[test]
fn a_consumer_of_the_group_outlives_a_tracker_crash() {
    if !can_switch_users("a_consumer_of_the_group_outlives_a_tracker_crash") {
        return;
    }
    let d = TestDomain::new("k");
    apply_tmpfiles(&d);
    let first = d.helper(Some(TRACKER), "publish omnitrack/pose");
    assert_eq!(first.said(Duration::from_secs(10)).as_deref(), Some("ready"));
    let consumer = Running::new(
        d.command(Path::new(env!("CARGO_BIN_EXE_omnitrack")), Some(MEMBER))
            .args(["listen"])
            .spawn()
            .unwrap(),
    );
    let seq = |line: &str| -> u64 {
        line.strip_prefix("seq=")
            .and_then(|r| r.split(' ').next())
            .unwrap()
            .parse()
            .unwrap()
    };
    let line = consumer
        .lines
        .recv_timeout(Duration::from_secs(10))
        .expect("a pose from the first tracker");
    let before = seq(&line);
    // Well into the first tracker's sequence, so that the second one's (from 0) tells them apart.
    std::thread::sleep(Duration::from_millis(500));
    drop(first);
    let second = d.helper(Some(TRACKER), "publish omnitrack/pose");
    assert_eq!(second.said(Duration::from_secs(10)).as_deref(), Some("ready"));
    let deadline = Instant::now() + Duration::from_secs(10);
    let mut from_second = None;
    while let Some(left) = deadline.checked_duration_since(Instant::now()) {
        match consumer.lines.recv_timeout(left) {
            Ok(l) if seq(&l) < 20 => {
                from_second = Some(l);
                break;
            }
            Ok(_) => continue,
            Err(_) => break,
        }
    }
    assert!(
        from_second.is_some(),
        "the consumer got nothing from the restarted tracker (first: seq {before})"
    );
    // Nothing of the dead tracker is left in /dev/shm: one data segment per live publisher.
    let data = d
        .shm_files()
        .into_iter()
        .filter(|p| p.to_string_lossy().ends_with(".data"))
        .count();
    assert_eq!(data, 1, "{:?}", d.shm_files());
}
