//! Results files: where a benchmark writes the table it printed, so that the figures the docs
//! cite are generated, not typed.
//!
//! In: a benchmark's name and its table (Markdown). Out: `benches/results/DATE-MACHINE/NAME.md`
//! under the repository, headed by the date and time, the commit (with `-dirty` when the work
//! tree had changes) and the machine (processor and cores), so that a figure can be traced to
//! the code and the machine that made it. A file of the same name that day is replaced: the
//! latest run is the one the docs cite, and git keeps the earlier ones. [`percentile`] is the
//! one definition of the quantiles those tables (and the demo) print.

use std::path::{Path, PathBuf};
use std::process::Command;

/// The output of `cmd args…` in `dir`, trimmed (empty when it cannot run).
fn output(dir: &Path, cmd: &str, args: &[&str]) -> String {
    Command::new(cmd)
        .args(args)
        .current_dir(dir)
        .output()
        .ok()
        .filter(|o| o.status.success())
        .and_then(|o| String::from_utf8(o.stdout).ok())
        .map(|s| s.trim().to_string())
        .unwrap_or_default()
}

/// The processor's model name and the cores this process may use.
pub fn machine() -> String {
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|t| {
            t.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split_once(':'))
                .map(|(_, v)| v.trim().to_string())
        })
        .unwrap_or_else(|| std::env::consts::ARCH.to_string());
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    format!("{cpu}, {cores} cores")
}

/// The commit of the repository at `root` (short hash, `-dirty` with uncommitted changes).
pub fn commit(root: &Path) -> String {
    let hash = output(root, "git", &["rev-parse", "--short", "HEAD"]);
    if hash.is_empty() {
        return "unknown".into();
    }
    let dirty = !output(root, "git", &["status", "--porcelain", "--untracked-files=no"]).is_empty();
    if dirty {
        format!("{hash}-dirty")
    } else {
        hash
    }
}

/// Writes `table` to `root/benches/results/DATE-MACHINE/NAME.md` with its header (module doc)
/// and returns the path. `title` heads the file; `command` is how to make it again.
pub fn write(root: &Path, name: &str, title: &str, command: &str, table: &str) -> Result<PathBuf, String> {
    let date = output(root, "date", &["+%F"]);
    let time = output(root, "date", &["-u", "+%H:%M UTC"]);
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let dir = root
        .join("benches/results")
        .join(format!("{date}-{}-{cores}c", std::env::consts::ARCH));
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let path = dir.join(format!("{name}.md"));
    let text = format!(
        "# {title}\n\n- date: {date} {time}\n- commit: {}\n- machine: {}\n- command: `{command}`\n\n{table}\n",
        commit(root),
        machine()
    );
    std::fs::write(&path, text).map_err(|e| format!("{}: {e}", path.display()))?;
    Ok(path)
}

/// The nearest-rank `q` quantile (0..=1) of ascending `sorted` values; NaN when there are none.
pub fn percentile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}
