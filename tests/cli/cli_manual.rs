//! `omnitrack completions` and `omnitrack manpage`: the completions and the manual the Debian
//! package ships. The page of `omnitrack` cited `omnitrack-run(1)` and the like, which nothing
//! made: `manpage --dir` now writes a page per command, and every page cited is among them.

use super::common::omnitrack;

#[test]
fn completions_for_each_shell_name_the_commands() {
    for shell in ["bash", "zsh", "fish"] {
        let (code, script, stderr) = omnitrack(&["completions", shell]);
        assert_eq!(code, 0, "{shell}: {stderr}");
        for word in ["omnitrack", "run", "listen", "visibility"] {
            assert!(script.contains(word), "{shell}: no {word}");
        }
    }
}

#[test]
fn every_manual_page_cited_is_made() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("man1");
    let (code, stdout, stderr) = omnitrack(&["manpage", "--dir", out.to_str().unwrap()]);
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.is_empty(), "{stdout}");
    let mut names: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    for page in [
        "omnitrack.1",
        "omnitrack-run.1",
        "omnitrack-visibility-build.1",
        "omnitrack-listen.1",
    ] {
        assert!(names.iter().any(|n| n == page), "{page} not in {names:?}");
    }
    assert!(!names.iter().any(|n| n.contains("help")), "{names:?}");
    assert_eq!(
        omnitrack_manual::dangling_citations(&out).unwrap(),
        Vec::<String>::new()
    );
    // `manpage` alone prints the binary's page, the same as the file.
    let (code, page, _) = omnitrack(&["manpage"]);
    assert_eq!(code, 0);
    assert_eq!(page, std::fs::read_to_string(out.join("omnitrack.1")).unwrap());
    // The run's page has the exit codes, as the binary's does.
    let run = std::fs::read_to_string(out.join("omnitrack-run.1")).unwrap();
    assert!(run.contains(".SH \"EXIT STATUS\""), "{run}");
}
