//! One module per command of `omnitrack` (docs/interfaces.md, "Command line"): each holds its
//! arguments (clap) and its `run`, which returns the command's error, whatever its layer's type,
//! for `main` to print as one line.

pub mod check;
pub mod edges;
pub mod listen;
pub mod pose;
pub mod record;
pub mod run;
pub mod segments;
pub mod visibility;

/// A command's outcome: its output is written; an error is reported by `main` in one line.
pub type CommandResult = Result<(), Box<dyn std::error::Error>>;

/// The exit codes of `omnitrack` (docs/interfaces.md, "Exit codes"; the man page's EXIT STATUS).
/// Code 1 is `run`'s second SIGINT/SIGTERM, which exits at once from the pipeline's signal
/// handling (`omnitrack::runtime::pipeline::stop_on_signals`).
pub mod exit {
    /// Done: for `run`, at least one pose was found (published or written).
    pub const SUCCESS: u8 = 0;
    /// Bad input, a usage error, or a failure (one line on standard error); for `check`, a file
    /// that is not valid.
    pub const FAILURE: u8 = 2;
    /// `run` ended without a single pose (its last line on standard error says why).
    pub const NO_POSE: u8 = 3;
}

/// The exit codes as the help and the man page list them.
pub const EXIT_STATUS_HELP: &str = "Exit status:
  0  success (run: at least one pose was found, on time or late)
  1  run: stopped at once by a second SIGINT/SIGTERM
  2  bad input, a usage error or a failure (one line on standard error); check: a file not valid
  3  run: ended without any pose (its last line on standard error says why)";

/// A command that has said all it had to (on standard error, and its JSON on standard output)
/// and ends with this exit code: `main` adds no line.
#[derive(Debug)]
pub struct Exit(pub u8);

impl std::fmt::Display for Exit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "exit code {}", self.0)
    }
}

impl std::error::Error for Exit {}

/// Writes `value` as one line of JSON on standard output (`--json`): a closed pipe comes back
/// as an error, as with [`print_line`].
pub fn print_json(value: &impl serde::Serialize) -> std::io::Result<()> {
    let text = serde_json::to_string(value).map_err(std::io::Error::other)?;
    print_line(&text).map_err(stdout_error)
}

/// Writes `text` and a newline to standard output. Unlike `println!`, a closed pipe
/// (`omnitrack pose … | head -c1`) comes back as an error, which `main` ends quietly on.
pub fn print_line(text: &str) -> std::io::Result<()> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    writeln!(out, "{text}").and_then(|_| out.flush())
}

/// A failed write to standard output, said so, its kind kept (a closed pipe stays one).
pub fn stdout_error(e: std::io::Error) -> std::io::Error {
    std::io::Error::new(e.kind(), format!("cannot write to standard output: {e}"))
}

/// Whether `e`, or an error it was caused by, is a write to a closed pipe.
pub fn is_broken_pipe(e: &(dyn std::error::Error + 'static)) -> bool {
    let mut cause = Some(e);
    while let Some(c) = cause {
        if c.downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
        {
            return true;
        }
        cause = c.source();
    }
    false
}

/// `PREFIX/leaf` for `--services PREFIX`: `omnitrack/pose` by default. A prefix iceoryx2 could
/// not name a service with is refused here, in one line, before anything starts.
pub fn service_name(prefix: &str, leaf: &str) -> Result<String, String> {
    let ok = !prefix.is_empty()
        && prefix.len() <= 200
        && !prefix.starts_with('/')
        && !prefix.ends_with('/')
        && prefix
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '/' | '-' | '_' | '.'));
    if ok {
        Ok(format!("{prefix}/{leaf}"))
    } else {
        Err(format!(
            "--services {prefix:?}: a prefix is letters, digits, '-', '_', '.' and inner '/' (at most 200), e.g. omnitrack/rig2"
        ))
    }
}
