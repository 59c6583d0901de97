//! The deployment files (tools/deploy/) and the Debian packages they go into (Cargo.toml's
//! `[package.metadata.deb]`, and crates/view's, crates/link's and crates/ros2's), read as files:
//! the udev rule takes cameras, not every composite device; the systemd unit runs the binary the
//! package installs, built with the sources the unit may ask for; the packages' files exist, no
//! file in two of them; the unit, the sysusers and the tmpfiles name one user.
//! `tools/deploy/check-deb.sh` checks the built packages (CI).

use std::path::PathBuf;

fn read(path: &str) -> String {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(path);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The lines that are not comments or blank.
fn rules(text: &str) -> Vec<&str> {
    text.lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .collect()
}

/// The programs with a Debian package each, and the manifests that describe them.
const PACKAGES: [(&str, &str); 4] = [
    ("omnitrack", "Cargo.toml"),
    ("omnitrack-view", "crates/view/Cargo.toml"),
    ("omnitrack-link", "crates/link/Cargo.toml"),
    ("omnitrack-ros2", "crates/ros2/Cargo.toml"),
];

fn deb_of(manifest: &str) -> toml::Table {
    let manifest_text: toml::Table = toml::from_str(&read(manifest)).unwrap();
    manifest_text["package"]["metadata"]["deb"]
        .as_table()
        .unwrap_or_else(|| panic!("{manifest} has no [package.metadata.deb]"))
        .clone()
}

fn deb() -> toml::Table {
    deb_of("Cargo.toml")
}

/// (source, destination) of each file of the tracker's package.
fn assets() -> Vec<(String, String)> {
    assets_of(&deb())
}

fn assets_of(deb: &toml::Table) -> Vec<(String, String)> {
    deb["assets"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| {
            let a = a.as_array().unwrap();
            (a[0].as_str().unwrap().to_string(), a[1].as_str().unwrap().to_string())
        })
        .collect()
}

/// USB3 Vision declares device class 0xEF, as every composite device does (webcams, headsets):
/// the rule matched them all. Cameras are matched by vendor id (product id optional), V4L2
/// devices by their subsystem, and the comment lists every vendor a rule takes.
#[test]
fn the_udev_rule_takes_cameras_by_vendor_never_by_class() {
    let text = read("tools/deploy/99-omnitrack.rules");
    let lines = rules(&text);
    assert!(
        lines.iter().any(|l| l.starts_with(r#"SUBSYSTEM=="video4linux""#)),
        "no V4L2 rule"
    );
    let mut vendors = Vec::new();
    for line in &lines {
        assert!(!line.contains("Class}"), "a class match: {line}");
        if line.contains(r#"SUBSYSTEM=="usb""#) {
            let vendor = line
                .split(r#"ATTR{idVendor}==""#)
                .nth(1)
                .and_then(|rest| rest.get(..4))
                .unwrap_or_else(|| panic!("a USB rule without a vendor id: {line}"));
            assert!(vendor.chars().all(|c| c.is_ascii_hexdigit()), "{line}");
            assert!(line.contains(r#"GROUP="omnitrack""#), "{line}");
            vendors.push(vendor);
        }
    }
    assert!(vendors.len() >= 5, "{vendors:?}");
    for vendor in vendors {
        assert!(
            text.contains(&format!("#   {vendor}  ")),
            "vendor {vendor} is not named in the comment"
        );
    }
    assert!(text.contains("To add a camera"), "no word on adding a camera");
}

/// The unit ran `/usr/local/bin/omnitrack … --source v4l`, which nothing installed, and a default
/// build cannot read v4l: the service failed at start. Now it runs the package's binary, which
/// is built with every source the unit and its defaults file may name.
#[test]
fn the_unit_runs_the_binary_the_package_installs_with_the_sources_it_asks_for() {
    let unit = read("tools/deploy/omnitrack.service");
    let exec = rules(&unit)
        .into_iter()
        .find_map(|l| l.strip_prefix("ExecStart="))
        .expect("ExecStart");
    let program = exec.split_whitespace().next().unwrap();
    let installed: Vec<String> = assets()
        .into_iter()
        .filter(|(source, _)| source == "target/release/omnitrack")
        .map(|(_, dest)| format!("/{}", dest.trim_end_matches('/')))
        .collect();
    assert!(
        installed
            .iter()
            .any(|d| d == program || format!("{d}/omnitrack") == program),
        "the unit runs {program}; the package installs the binary at {installed:?}"
    );
    let deb = deb();
    assert_eq!(
        deb["default-features"].as_bool(),
        Some(false),
        "the device build has no desk code"
    );
    let features: Vec<&str> = deb["features"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|f| f.as_str())
        .collect();
    assert!(exec.contains("--source ${OMNITRACK_SOURCE}"), "{exec}");
    let mut sources = vec![];
    for text in [&unit, &read("tools/deploy/omnitrack.default")] {
        for line in rules(text) {
            let line = line.trim_start_matches("Environment=");
            if let Some(source) = line.strip_prefix("OMNITRACK_SOURCE=") {
                sources.push(source.to_string());
            }
        }
    }
    assert!(sources.len() >= 2, "{sources:?}");
    for source in sources.iter().map(String::as_str).chain(["v4l", "usb"]) {
        assert!(
            features.contains(&source),
            "the package's binary lacks the {source} feature: {features:?}"
        );
    }
    assert!(unit.contains("EnvironmentFile=-/etc/default/omnitrack"), "{unit}");
}

/// Every file the packages take from the repository exists; the generated ones (the program,
/// its completions and manual pages) are those `tools/deploy/build-deb.sh` builds and writes,
/// each program's into its own package, and every program has its completions for three shells
/// and its manual pages; no two packages install one file; /etc gets the shipped rig and
/// tracker config, the defaults file, and nothing else.
#[test]
fn every_file_of_the_packages_exists_or_is_made_by_their_build() {
    let script = read("tools/deploy/build-deb.sh");
    assert!(
        script.contains("share=\"$target/$profile/share/$program\"")
            && script.contains("completions/$program.$shell")
            && script.contains("manpage --dir \"$share/man1\""),
        "build-deb.sh no longer writes share/PROGRAM/{{completions,man1}}"
    );
    let mut installed = std::collections::BTreeSet::new();
    let mut etc = Vec::new();
    for (program, manifest) in PACKAGES {
        let known = script
            .lines()
            .find_map(|l| l.strip_prefix("known="))
            .unwrap_or_default();
        assert!(
            known.split(['"', ' ']).any(|w| w == program),
            "build-deb.sh does not know the package {program}: {known}"
        );
        let deb = deb_of(manifest);
        assert_eq!(deb["name"].as_str(), Some(program), "{manifest}");
        let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(manifest);
        let dir = dir.parent().unwrap();
        let mut made = Vec::new();
        for (source, dest) in assets_of(&deb) {
            if let Some(built) = source.strip_prefix("target/release/") {
                made.push(built.to_string());
                let ok = built == program
                    || built
                        .strip_prefix(&format!("share/{program}/completions/{program}."))
                        .is_some()
                    || built == format!("share/{program}/man1/*.1.gz");
                assert!(ok, "{manifest}: {source}: not made by build-deb.sh for {program}");
            } else {
                assert!(dir.join(&source).is_file(), "{manifest}: {source} does not exist");
            }
            if dest.starts_with("etc/") {
                etc.push(dest.clone());
            }
            // The manual pages, a glob, are named by their program; check-deb.sh compares the
            // packages' actual files.
            if source.contains('*') {
                continue;
            }
            let file = if dest.ends_with('/') {
                format!("{dest}{}", source.rsplit('/').next().unwrap())
            } else {
                dest.clone()
            };
            assert!(installed.insert(file.clone()), "{manifest}: {file} is in two packages");
        }
        for shell in ["bash", "zsh", "fish"] {
            let completion = format!("share/{program}/completions/{program}.{shell}");
            assert!(made.contains(&completion), "{manifest}: no {completion}");
        }
        assert!(made.iter().any(|m| m.contains("/man1/")), "{manifest}: no manual pages");
    }
    etc.sort();
    assert_eq!(
        etc,
        [
            "etc/default/omnitrack",
            "etc/omnitrack/rig.toml",
            "etc/omnitrack/tracker.toml"
        ]
    );
    let scripts = deb()["maintainer-scripts"].as_str().unwrap().to_string();
    for script in ["postinst", "prerm", "postrm"] {
        let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(&scripts).join(script);
        assert!(path.is_file(), "{}", path.display());
    }
}

/// The unit's user and group, the sysusers file's and the tmpfiles' owner are one: `omnitrack`.
#[test]
fn the_unit_the_sysusers_and_the_tmpfiles_name_one_user() {
    let unit = read("tools/deploy/omnitrack.service");
    assert!(unit.contains("\nUser=omnitrack\n") && unit.contains("\nGroup=omnitrack\n"));
    let sysusers = read("tools/deploy/omnitrack.sysusers");
    let users: Vec<&str> = rules(&sysusers)
        .into_iter()
        .filter_map(|l| l.strip_prefix('u').map(str::split_whitespace))
        .filter_map(|mut words| words.next())
        .collect();
    assert_eq!(users, ["omnitrack"]);
    for line in rules(&read("tools/deploy/omnitrack.tmpfiles")) {
        let words: Vec<&str> = line.split_whitespace().collect();
        if words.len() >= 5 {
            assert_eq!(&words[3..5], ["omnitrack", "omnitrack"], "{line}");
        }
    }
}
