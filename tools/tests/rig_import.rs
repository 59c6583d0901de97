//! `omnitrack-desk rig from-*` as a user runs them (issue 49): `--out -` writes the rig to
//! standard output (it wrote a file named `-`), a plain five-coefficient OpenCV file needs no
//! `--model` (it was read as a fisheye and refused), Basalt's calibration is read, and the
//! summary on stderr names each sensor's lens model and, for OpenCV, where the model came from.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn calibration(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../tests/desk/calibrations")
        .join(name)
}

/// `omnitrack-desk ARGS` run in `dir`.
fn desk(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_omnitrack-desk"))
        .args(args)
        .current_dir(dir)
        .output()
        .unwrap()
}

#[test]
fn out_dash_writes_the_rig_to_standard_output() {
    let dir = tempfile::tempdir().unwrap();
    let ros = calibration("ros-camera-info-plumb-bob.yaml");
    let out = desk(dir.path(), &["rig", "from-opencv", ros.to_str().unwrap(), "--out", "-"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(!dir.path().join("-").exists(), "a file named '-'");
    let toml = String::from_utf8(out.stdout).unwrap();
    let rig = omnitrack::Rig::from_toml_str(&toml, "stdout").unwrap();
    assert_eq!(rig.name, "rig");
    assert_eq!(rig.sensors[0].lens.model_name(), "radtan");
    assert!(
        toml.starts_with("# Converted by `omnitrack-desk rig from-opencv`"),
        "{toml}"
    );
    assert_eq!(
        stderr.trim(),
        "standard output: rig 'rig', 1 sensors (radtan); lens model from distortion_model: plumb_bob"
    );
}

#[test]
fn a_plain_opencv_file_and_a_basalt_calibration_convert_without_options() {
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        (
            vec!["rig", "from-opencv", "opencv-tutorial-default.yml"],
            "cam.toml: rig 'cam', 1 sensors (radtan); lens model from 5 coefficients: the default model's",
        ),
        (
            vec!["rig", "from-basalt", "basalt-euroc-ds-calibration.json"],
            "cam.toml: rig 'cam', 2 sensors (ds, ds)",
        ),
        (
            vec![
                "rig",
                "from-kalibr",
                "kalibr-omni-eucm-camchain.yaml",
                "--rig-frame",
                "cam1",
            ],
            "cam.toml: rig 'cam', 2 sensors (omni, eucm)",
        ),
    ];
    for (mut args, said) in cases {
        let input = calibration(args[2]);
        args[2] = input.to_str().unwrap();
        args.extend(["--out", "cam.toml"]);
        let out = desk(dir.path(), &args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{args:?}: {stderr}");
        assert_eq!(stderr.trim(), said);
        omnitrack::Rig::load(&dir.path().join("cam.toml")).unwrap();
    }
    // A model Basalt writes that omnitrack does not read: one line, exit 2.
    let fov = dir.path().join("fov.json");
    let text = std::fs::read_to_string(calibration("basalt-euroc-ds-calibration.json"))
        .unwrap()
        .replace("\"camera_type\": \"ds\"", "\"camera_type\": \"fov\"");
    std::fs::write(&fov, text).unwrap();
    let out = desk(dir.path(), &["rig", "from-basalt", "fov.json", "--out", "-"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2));
    assert_eq!(stderr.trim().lines().count(), 1, "{stderr}");
    assert!(
        stderr.contains("fov.json: cam0: camera_type 'fov' is not supported"),
        "{stderr}"
    );
    assert!(out.stdout.is_empty());
}
