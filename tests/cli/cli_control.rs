//! `omnitrack check` and the rig's `[control]` (issue 49, item 2), as a user meets them with no
//! camera attached: the sensors' tables summarised, a bad value one line naming the file, the
//! sensor and the key, and `--source` opening the cameras (the protocol-level tests with fake
//! devices are crates/io/tests/camctl/).

use crate::common::omnitrack;

const RIG: &str = r#"name = "cams"
[control]
exposure_us = 5000
white_balance = "off"

[[sensors]]
id = 0
resolution = [640, 480]
model = "pinhole"
intrinsics = [500.0, 500.0, 319.5, 239.5]
rotation_wxyz = [1.0, 0.0, 0.0, 0.0]
translation_m = [0.0, 0.0, 0.0]
device = "/dev/video-omnitrack-test-absent"
[sensors.control]
gain = "auto"
"#;

#[test]
fn check_summarises_each_sensors_control_and_names_a_bad_key() {
    let dir = tempfile::tempdir().unwrap();
    let rig = dir.path().join("cams.toml");
    std::fs::write(&rig, RIG).unwrap();
    let rig = rig.to_str().unwrap();
    let (code, stdout, stderr) = omnitrack(&["check", "--rig", rig]);
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.is_empty());
    assert!(
        stderr.contains("    asks its camera: exposure_us = 5000.0, gain = \"auto\", white_balance = \"off\"\n"),
        "{stderr}"
    );
    let (_, stdout, _) = omnitrack(&["check", "--rig", rig, "--json"]);
    let json: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
    assert_eq!(
        json["rig"]["sensors"][0]["control"],
        serde_json::json!(["exposure_us = 5000.0", "gain = \"auto\"", "white_balance = \"off\""])
    );
    assert!(json.get("controls").is_none(), "no cameras opened without --source");

    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, RIG.replace("gain = \"auto\"", "gain = \"high\"")).unwrap();
    let bad = bad.to_str().unwrap();
    let (code, _, stderr) = omnitrack(&["check", "--rig", bad]);
    assert_eq!(code, 2);
    assert_eq!(
        stderr,
        format!("omnitrack: {bad}: sensor 0, key 'control.gain': must be a number in the device's unit or \"auto\", found \"high\"\n")
    );
}

#[test]
fn check_source_opens_the_cameras_or_says_why_not() {
    let dir = tempfile::tempdir().unwrap();
    let rig = dir.path().join("cams.toml");
    std::fs::write(&rig, RIG).unwrap();
    let rig = rig.to_str().unwrap();
    let (code, _, stderr) = omnitrack(&["check", "--rig", rig, "--source", "v4l"]);
    assert_eq!(code, 2, "{stderr}");
    let last = stderr.lines().last().unwrap_or_default();
    if cfg!(feature = "v4l") {
        assert_eq!(
            last, "omnitrack: /dev/video-omnitrack-test-absent: sensor 0: no such device",
            "{stderr}"
        );
    } else {
        assert!(
            last.starts_with("omnitrack: v4l: live V4L2 capture is not in this build"),
            "{stderr}"
        );
    }
    let (code, _, stderr) = omnitrack(&["check", "--rig", rig, "--source", "replay:somewhere"]);
    assert_eq!(code, 2);
    assert_eq!(
        stderr,
        "omnitrack: check --source takes a live source, v4l or usb: a recording has no camera to set\n"
    );
    let (code, _, stderr) = omnitrack(&["check", "--source", "v4l"]);
    assert_eq!(code, 2);
    assert!(stderr.contains("--rig"), "{stderr}");
}
