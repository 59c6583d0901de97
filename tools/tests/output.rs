//! `omnitrack-desk`'s standard output as scripts use it (issue 50, item 10): a reader that goes
//! away (`omnitrack-desk eval … | head`) ends the tool quietly with success, as it ends
//! `omnitrack`; an output that cannot be written (`> /dev/full`) is one error line and exit 2.

use std::path::Path;
use std::process::{Command, Output, Stdio};

/// A trajectory of 20 poses along x, 0.1 s apart, each `dx` m off.
fn tum(path: &Path, dx: f64) {
    let text: String = (0..20)
        .map(|k| format!("{:.1} {} 0 1.5 0 0 0 1\n", 0.1 * k as f64, 0.1 * k as f64 + dx))
        .collect();
    std::fs::write(path, text).unwrap();
}

fn desk(args: &[&str], stdout: Stdio) -> Output {
    Command::new(env!("CARGO_BIN_EXE_omnitrack-desk"))
        .args(args)
        .stdout(stdout)
        .output()
        .unwrap()
}

#[test]
fn a_closed_standard_output_ends_quietly_and_a_full_one_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let (gt, est) = (dir.path().join("gt.tum"), dir.path().join("est.tum"));
    tum(&gt, 0.0);
    tum(&est, 0.02);
    let (gt, est) = (gt.to_str().unwrap(), est.to_str().unwrap());
    for args in [vec!["eval", gt, est], vec!["eval", gt, est, "--json"]] {
        // The table goes where it is asked to.
        let out = desk(&args, Stdio::piped());
        assert!(
            out.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(!out.stdout.is_empty(), "{args:?}");

        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        let out = desk(&args, writer.into());
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{args:?}: {:?} {stderr}", out.status);
        assert!(stderr.is_empty(), "{args:?}: {stderr}");

        let full = std::fs::OpenOptions::new().write(true).open("/dev/full").unwrap();
        let out = desk(&args, full.into());
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert_eq!(stderr.lines().count(), 1, "{args:?}: {stderr}");
        assert!(
            stderr.starts_with("omnitrack-desk: cannot write to standard output: "),
            "{args:?}: {stderr}"
        );
    }
}

/// `omnitrack-desk` has completions and a manual page per command (it had neither), and every
/// page a page cites is among them.
#[test]
fn completions_and_a_manual_page_for_every_command() {
    for shell in ["bash", "zsh", "fish"] {
        let out = desk(&["completions", shell], Stdio::piped());
        let script = String::from_utf8_lossy(&out.stdout);
        assert!(out.status.success(), "{shell}");
        assert!(
            script.contains("omnitrack-desk") && script.contains("extrude"),
            "{shell}: {script}"
        );
    }
    let dir = tempfile::tempdir().unwrap();
    let out = desk(&["manpage", "--dir", dir.path().to_str().unwrap()], Stdio::piped());
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    for page in [
        "omnitrack-desk.1",
        "omnitrack-desk-rig-from-kalibr.1",
        "omnitrack-desk-eval.1",
    ] {
        assert!(dir.path().join(page).is_file(), "no {page}");
    }
    assert_eq!(
        omnitrack_manual::dangling_citations(dir.path()).unwrap(),
        Vec::<String>::new()
    );
    let out = desk(&["manpage"], Stdio::piped());
    assert!(String::from_utf8_lossy(&out.stdout).contains(".TH omnitrack-desk 1"));
}
