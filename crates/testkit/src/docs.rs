//! What the command-line tests of the subscriber programs (`omnitrack-ros2`, `omnitrack-view`)
//! check against the documents: the long options a text names, and the `cargo run -p PACKAGE --
//! ARGS` lines of the README and the rig guide.
//!
//! In: the repository's README.md, docs/rig-guide.md and docs/interfaces.md. Out: option names
//! and argument lists for the tests to run their binary with. (The front door's own check is
//! `omnitrack_runtime::cli`, which the binary itself carries.)

use std::collections::BTreeSet;

/// The repository's root.
const ROOT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../..");

/// The long options named in `text`, `--help` and `--version` left out.
pub fn long_options(text: &str) -> BTreeSet<String> {
    let mut found = BTreeSet::new();
    let mut rest = text;
    while let Some(at) = rest.find("--") {
        let name: String = rest[at + 2..]
            .chars()
            .take_while(|c| c.is_ascii_lowercase() || *c == '-')
            .collect();
        if !name.is_empty() && name != "help" && name != "version" && !name.ends_with('-') {
            found.insert(name.clone());
        }
        rest = &rest[at + 2 + name.len()..];
    }
    found
}

/// The command cell of docs/interfaces.md's row that starts with `` | `PREFIX ``, up to its
/// closing code span (its `\|` are not cell borders). Panics, naming the prefix, without one.
pub fn interface_row(prefix: &str) -> String {
    let path = format!("{ROOT}/docs/interfaces.md");
    let docs = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
    let start = format!("| `{prefix}");
    let row = docs
        .lines()
        .find(|l| l.starts_with(&start))
        .unwrap_or_else(|| panic!("docs/interfaces.md has no row for `{prefix}`"));
    row.split("` |").next().unwrap_or(row).to_string()
}

/// Runs the binary `bin` with the arguments of every `cargo run … -p PACKAGE -- ARGS` line of
/// README.md and docs/rig-guide.md, `--help` appended (parsed, nothing opened), and panics,
/// naming the document and the line, where the command line refuses one. Returns how many ran.
pub fn check_documented_runs(bin: &str, package: &str) -> usize {
    let runs = documented_runs(package);
    for (doc, line, mut argv) in runs.clone() {
        argv.push("--help".into());
        let out = std::process::Command::new(bin)
            .args(&argv)
            .output()
            .unwrap_or_else(|e| panic!("{bin}: {e}"));
        assert!(
            out.status.success(),
            "{doc}: `{line}`: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    runs.len()
}

/// Every `cargo run … -p PACKAGE -- ARGS` line of README.md and docs/rig-guide.md (a trailing
/// `# comment` left out): the document, the line, and its arguments.
pub fn documented_runs(package: &str) -> Vec<(&'static str, String, Vec<String>)> {
    let flag = format!("-p {package}");
    let mut runs = Vec::new();
    for doc in ["README.md", "docs/rig-guide.md"] {
        let path = format!("{ROOT}/{doc}");
        let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
        for line in text.lines() {
            let line = line.split(" #").next().unwrap_or(line).trim();
            let Some((cargo, args)) = line.split_once(" -- ") else {
                continue;
            };
            if cargo.starts_with("cargo run") && cargo.contains(&flag) {
                runs.push((
                    doc,
                    line.to_string(),
                    args.split_whitespace().map(String::from).collect(),
                ));
            }
        }
    }
    runs
}
