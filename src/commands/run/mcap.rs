//! `run --mcap FILE`: the run's services written to an MCAP file by `omnitrack-view serve
//! --no-server --mcap FILE`, a child process that subscribes like any other consumer. The
//! tracker itself carries no MCAP code and its frame path only gains a subscriber
//! (docs/decisions.md, the live view); this module starts the view before the first frame and
//! stops it after the last one, by closing its standard input: the view (`--ready`) ignores
//! SIGINT and SIGTERM, so a stop meant for the run that reaches the view too (systemd's, to
//! every process of the service) cannot end it before the run's last sample.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// The view's program name.
pub const VIEW: &str = "omnitrack-view";
/// The line `omnitrack-view serve --ready` prints once subscribed.
const READY: &str = "ready";
/// How long the view may take to load the model and the recording and subscribe.
const READY_TIMEOUT: Duration = Duration::from_secs(120);
/// How long the view may take after its standard input closed to finish the file (its last
/// samples, summary and indexes) before it is killed.
const STOP_TIMEOUT: Duration = Duration::from_secs(5);

/// `omnitrack-view` beside the running `omnitrack` (a build's target directory, an install's
/// bin directory), else on PATH; one line saying how to get it when it is in neither.
pub fn find_view() -> Result<PathBuf, String> {
    let beside = std::env::current_exe()
        .ok()
        .and_then(|exe| exe.parent().map(|d| d.join(VIEW)));
    let on_path = std::env::var_os("PATH")
        .map(|p| std::env::split_paths(&p).map(|d| d.join(VIEW)).collect::<Vec<_>>())
        .unwrap_or_default();
    beside
        .into_iter()
        .chain(on_path)
        .find(|p| is_executable(p))
        .ok_or_else(|| {
            format!(
                "--mcap needs the {VIEW} program, which is neither beside this omnitrack nor on PATH: \
                 install the Debian package {VIEW}, or build it with `cargo build --release -p {VIEW}` \
                 (it lands beside target/release/omnitrack)"
            )
        })
}

fn is_executable(path: &Path) -> bool {
    use std::os::unix::fs::PermissionsExt;
    std::fs::metadata(path).is_ok_and(|m| m.is_file() && m.permissions().mode() & 0o111 != 0)
}

/// Whether `path` can be written, found out before any tracking: a file made only to find out
/// is removed again (the view replaces the file when it starts).
pub fn check_writable(path: &Path) -> Result<(), String> {
    let existed = path.exists();
    let opened = std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(false)
        .open(path);
    match opened {
        Ok(_) => {
            if !existed {
                let _ = std::fs::remove_file(path);
            }
            Ok(())
        }
        Err(e) => Err(format!("--mcap {}: cannot write there: {e}", path.display())),
    }
}

/// What the view is given: the run's own services, model and (for a replay) recording.
pub struct ViewArgs<'a> {
    pub program: &'a Path,
    pub file: &'a Path,
    pub services: &'a str,
    pub model: &'a Path,
    pub recording: Option<&'a Path>,
}

/// The running view; dropped without [`McapRecorder::finish`] (a run that failed), it is
/// stopped all the same, so the file is finished.
pub struct McapRecorder {
    child: Option<Child>,
    file: PathBuf,
}

impl McapRecorder {
    /// Starts the view and waits until it has subscribed, so that the run's first sample
    /// reaches it.
    pub fn start(a: &ViewArgs) -> Result<McapRecorder, String> {
        let mut command = Command::new(a.program);
        command
            .args(["serve", "--no-server", "--ready", "--mcap"])
            .arg(a.file)
            .args(["--services", a.services, "--model"])
            .arg(a.model);
        if let Some(dir) = a.recording {
            command.arg("--recording").arg(dir);
        }
        // Its start line and summary join the run's on standard error; standard output carries
        // only the handshake, so `run --json`'s output stays the run's.
        command.stdout(Stdio::piped()).stderr(Stdio::inherit());
        detach(&mut command);
        let mut child = command
            .spawn()
            .map_err(|e| format!("--mcap: cannot start {}: {e}", a.program.display()))?;
        let (tx, rx) = mpsc::channel();
        if let Some(stdout) = child.stdout.take() {
            std::thread::spawn(move || {
                let mut lines = BufReader::new(stdout).lines();
                if lines.any(|l| l.is_ok_and(|l| l.trim() == READY)) {
                    let _ = tx.send(());
                }
                // Read on until the view ends, so that it never blocks on a full pipe.
                lines.for_each(drop);
            });
        }
        let mut recorder = McapRecorder {
            child: Some(child),
            file: a.file.to_path_buf(),
        };
        match rx.recv_timeout(READY_TIMEOUT) {
            Ok(()) => Ok(recorder),
            Err(mpsc::RecvTimeoutError::Disconnected) => {
                let status = recorder.child.take().map(|mut c| c.wait());
                let how = match status {
                    Some(Ok(s)) => describe(s),
                    _ => "ended".to_string(),
                };
                Err(format!(
                    "--mcap {}: {VIEW} {how} before it subscribed (its line above says why)",
                    a.file.display()
                ))
            }
            Err(mpsc::RecvTimeoutError::Timeout) => {
                recorder.stop();
                Err(format!(
                    "--mcap {}: {VIEW} did not subscribe within {} s; stopped",
                    a.file.display(),
                    READY_TIMEOUT.as_secs()
                ))
            }
        }
    }

    /// Stops the view after the run's last sample and says, in one line for the run's summary,
    /// whether the file is whole.
    pub fn finish(mut self) -> String {
        let file = self.file.display().to_string();
        match self.stop() {
            Stopped::Finished => format!("MCAP file {file} written"),
            Stopped::EndedEarly(s) => format!(
                "MCAP file {file} is incomplete: {VIEW} {} during the run (the poses were published all the same)",
                describe(s)
            ),
            Stopped::Failed(s) => format!(
                "MCAP file {file} may be incomplete: {VIEW} {} when stopped",
                describe(s)
            ),
            Stopped::Killed => format!(
                "MCAP file {file} is incomplete: {VIEW} did not finish it within {} s of its stop and was killed",
                STOP_TIMEOUT.as_secs()
            ),
            Stopped::Lost(e) => format!("MCAP file {file} may be incomplete: {VIEW}: {e}"),
        }
    }

    /// Closes the view's standard input, which stops it (`--ready`), then gives it at most
    /// [`STOP_TIMEOUT`] to finish the file; a view that ended on its own before is reported as
    /// such.
    fn stop(&mut self) -> Stopped {
        let Some(mut child) = self.child.take() else {
            return Stopped::Lost("already stopped".to_string());
        };
        match child.try_wait() {
            Ok(Some(s)) => return Stopped::EndedEarly(s),
            Ok(None) => {}
            Err(e) => return Stopped::Lost(e.to_string()),
        }
        drop(child.stdin.take());
        let deadline = Instant::now() + STOP_TIMEOUT;
        loop {
            match child.try_wait() {
                Ok(Some(s)) if s.success() => return Stopped::Finished,
                Ok(Some(s)) => return Stopped::Failed(s),
                Ok(None) if Instant::now() < deadline => std::thread::sleep(Duration::from_millis(20)),
                Ok(None) => {
                    let _ = child.kill();
                    let _ = child.wait();
                    return Stopped::Killed;
                }
                Err(e) => return Stopped::Lost(e.to_string()),
            }
        }
    }
}

impl Drop for McapRecorder {
    fn drop(&mut self) {
        self.stop();
    }
}

enum Stopped {
    Finished,
    EndedEarly(ExitStatus),
    Failed(ExitStatus),
    Killed,
    Lost(String),
}

fn describe(s: ExitStatus) -> String {
    use std::os::unix::process::ExitStatusExt;
    match (s.code(), s.signal()) {
        (Some(code), _) => format!("exited with code {code}"),
        (None, Some(sig)) => format!("was ended by signal {sig}"),
        (None, None) => "ended".to_string(),
    }
}

/// The view's standard input is a pipe whose other end only the run holds: it closes when the
/// run stops the view after its last sample, and also when the run ends without doing so (a
/// second Ctrl-C, SIGKILL); `--ready` makes the view stop on that alone and finish the file. A
/// stop signal does not: a terminal's Ctrl-C goes to the whole foreground process group and
/// systemd's SIGTERM to every process of the service, and a view stopped by either could miss
/// the samples the run publishes after it. The view's own process group keeps the terminal's
/// signals from it all the same.
fn detach(command: &mut Command) {
    use std::os::unix::process::CommandExt;
    command.process_group(0).stdin(Stdio::piped());
}
