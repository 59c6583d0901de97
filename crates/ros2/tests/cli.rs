//! `omnitrack-ros2` without a network: its manual and completions, and bad input refused in one
//! line naming what is wrong, before any service or DDS participant is opened.

use omnitrack_testkit::docs::{check_documented_runs, interface_row, long_options};
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_omnitrack-ros2");

/// `completions SHELL` prints a script naming the commands; `manpage --dir` writes a page for
/// every command, each one a page cites among them.
#[test]
fn completions_and_a_manual_page_for_every_command() {
    for shell in ["bash", "zsh", "fish"] {
        let out = Command::new(BIN).args(["completions", shell]).output().unwrap();
        let script = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success(),
            "{shell}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(
            script.contains("omnitrack-ros2") && script.contains("publish") && script.contains("map-odom"),
            "{shell}: {script}"
        );
    }
    let out = Command::new(BIN).arg("manpage").output().unwrap();
    assert!(out.status.success());
    assert!(String::from_utf8_lossy(&out.stdout).contains(".TH omnitrack-ros2 1"));
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(BIN)
        .args(["manpage", "--dir"])
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let mut names: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(
        names,
        [
            "omnitrack-ros2-completions.1",
            "omnitrack-ros2-manpage.1",
            "omnitrack-ros2-publish.1",
            "omnitrack-ros2.1"
        ]
    );
    assert_eq!(
        omnitrack_manual::dangling_citations(dir.path()).unwrap(),
        Vec::<String>::new()
    );
}

/// Each bad argument: the exit code, and the one line on standard error that names it.
#[test]
fn bad_input_is_one_line_naming_what_is_wrong() {
    let cases: &[(&[&str], i32, &str)] = &[
        (&["--domain-id", "300"], 2, "'300' is not a ROS domain id (0 to 232)"),
        (&["--depth", "0"], 2, "'0' is not a history depth (1 to 10000)"),
        (&["--rig-in-base", "0.3,0,1.2"], 2, "7 numbers x,y,z,qx,qy,qz,qw are needed, found 3"),
        (&["--rig-in-base", "0,0,0,0,0,0,2"], 2, "the quaternion (0, 0, 0, 2) has norm 2, not 1"),
        (&["--odom-tolerance-s", "-1"], 2, "'-1' is not a number of seconds ≥ 0"),
        (&["--tf", "map-base-link"], 2, "invalid value 'map-base-link' for '--tf <TF>'"),
        (&["--reliability", "sometimes"], 2, "invalid value 'sometimes' for '--reliability"),
        (&["--interface", "eth0"], 2, "invalid value 'eth0' for '--interface <ADDR>'"),
        (
            &["--topic", "omnitrack//pose"],
            1,
            "omnitrack-ros2: --topic 'omnitrack//pose' is not a ROS topic name: it has an empty part ('//' or a trailing '/')",
        ),
        (&["--topic", "omni-track/pose"], 1, "'-' is not allowed"),
        (
            &["--map-frame", "/map"],
            1,
            "omnitrack-ros2: --map-frame '/map' is not a frame id: ROS 2 frame ids have no leading '/'",
        ),
        (
            &["--tf", "map-odom", "--odom-frame", "map"],
            1,
            "omnitrack-ros2: --odom-frame 'map' must differ from --map-frame and --base-frame",
        ),
        (&["--node-name", "2d"], 1, "omnitrack-ros2: --node-name '2d' is not a ROS node name"),
    ];
    for (args, code, message) in cases {
        let out = Command::new(BIN)
            .arg("publish")
            .args(*args)
            .env_remove("ROS_DOMAIN_ID")
            .env_remove("ROS_AUTOMATIC_DISCOVERY_RANGE")
            .env_remove("ROS_LOCALHOST_ONLY")
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(*code), "{args:?}: {err}");
        assert!(err.contains(message), "{args:?}: {err}");
        if *code == 1 {
            assert_eq!(err.lines().count(), 1, "{args:?}: {err}");
        }
    }
    // ROS_DOMAIN_ID is read as ROS reads it, and refused the same way.
    let out = Command::new(BIN)
        .arg("publish")
        .env("ROS_DOMAIN_ID", "abc")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("'abc' is not a ROS domain id"));
    // ROS 2's discovery range: OFF (static peers only) cannot be honoured, and is said so.
    let out = Command::new(BIN)
        .arg("publish")
        .env("ROS_AUTOMATIC_DISCOVERY_RANGE", "OFF")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(
        String::from_utf8_lossy(&out.stderr),
        "omnitrack-ros2: ROS_AUTOMATIC_DISCOVERY_RANGE=OFF (static peers only) is not supported: unset it, or \
         set LOCALHOST or SUBNET\n"
    );
    // An empty ROS_DOMAIN_ID is domain 0 to ROS: accepted, so the bad topic is what is named.
    let out = Command::new(BIN)
        .args(["publish", "--topic", "a//b"])
        .env("ROS_DOMAIN_ID", "")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).starts_with("omnitrack-ros2: --topic 'a//b'"));
}

/// docs/interfaces.md's row of `omnitrack-ros2 publish` names every option the command has, and
/// no other.
#[test]
fn the_interface_document_names_every_option_of_publish() {
    let help = Command::new(BIN).args(["publish", "--help"]).output().unwrap();
    let help = String::from_utf8_lossy(&help.stdout);
    let options_lines: String = help.lines().filter(|l| l.trim_start().starts_with('-')).collect();
    let command = interface_row("omnitrack-ros2 publish ");
    assert_eq!(long_options(&command), long_options(&options_lines), "{command}");
    assert!(long_options(&options_lines).contains("rig-in-base"));
}

/// Every `cargo run … -p omnitrack-ros2 -- ARGS` line of the README and the rig guide is one the
/// command line takes as written (run with `--help` appended: the arguments are parsed, nothing
/// is opened). The front door's README test leaves these lines to this one.
#[test]
fn the_documented_commands_are_ones_the_command_line_takes() {
    let checked = check_documented_runs(BIN, "omnitrack-ros2");
    assert!(
        checked >= 1,
        "no `cargo run -p omnitrack-ros2 -- …` line found in the docs"
    );
}
