//! Calibration in, issue 49: the files as Kalibr, Basalt, OpenCV and ROS write them
//! (`tests/desk/calibrations/`) become rigs with the lens models that make them exact: Kalibr's
//! `ds`, `eucm` and `omni`, Basalt's `ds`, `eucm`, `ucm` and `kb4`, OpenCV's plain and fisheye
//! models by what the file says, ROS's `plumb_bob` and `equidistant`. The same two cameras
//! through Kalibr and through Basalt are the same rig; what cannot be read is named in one line.

#![cfg(feature = "desk")]

use omnitrack::desk::basalt::rig_from_basalt;
use omnitrack::desk::kalibr::rig_from_kalibr;
use omnitrack::desk::opencv_calib::{rig_from_opencv, OpenCvModel};
use omnitrack::geometry::Lens;
use omnitrack::Rig;

fn fixture(name: &str) -> String {
    let path = format!("{}/tests/desk/calibrations/{name}", env!("CARGO_MANIFEST_DIR"));
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"))
}

/// Written and read back, a rig is the same to the last bit.
fn round_trips(rig: &Rig) {
    assert_eq!(&Rig::from_toml_str(&rig.to_toml_string(), "again.toml").unwrap(), rig);
}

#[test]
fn kalibr_and_basalt_double_sphere_calibrations_of_one_stereo_pair_are_one_rig() {
    let kalibr = rig_from_kalibr(
        &fixture("kalibr-euroc-ds-camchain.yaml"),
        "camchain.yaml",
        "euroc",
        "cam0",
    )
    .unwrap();
    let basalt = rig_from_basalt(
        &fixture("basalt-euroc-ds-calibration.json"),
        "calibration.json",
        "euroc",
        "cam0",
    )
    .unwrap();
    let Lens::DoubleSphere(ds) = kalibr.sensors[0].lens else {
        panic!("{:?}", kalibr.sensors[0].lens)
    };
    // Kalibr's [ξ, α, fu, fv, pu, pv], parameter for parameter.
    assert_eq!(
        [ds.xi, ds.alpha, ds.fx, ds.fy, ds.cx, ds.cy],
        [
            -0.2409573942178872,
            0.566996899163044,
            349.7560023050409,
            348.72454229977035,
            365.89440762590147,
            249.32995565708703
        ]
    );
    for (a, b) in kalibr.sensors.iter().zip(&basalt.sensors) {
        assert_eq!(a.lens, b.lens);
        assert_eq!((a.width, a.height), (b.width, b.height));
        let gap = a.t_rig_sensor.inverse() * b.t_rig_sensor;
        assert!(
            gap.translation.vector.norm() < 1e-9 && gap.rotation.angle() < 1e-9,
            "sensor {}: {gap}",
            a.id
        );
    }
    // cam1 sits 11 cm to cam0's right: rig y is left.
    let c1 = basalt.sensors[1].centre();
    assert!((c1.y + 0.110).abs() < 1e-3 && c1.x.abs() < 2e-3, "{c1}");
    round_trips(&kalibr);
    round_trips(&basalt);
    // The other camera as the rig frame.
    let from1 = rig_from_basalt(&fixture("basalt-euroc-ds-calibration.json"), "c.json", "e", "cam1").unwrap();
    assert!(from1.sensors[1].t_rig_sensor.translation.vector.norm() < 1e-12);
}

#[test]
fn kalibr_omni_and_eucm_cameras_are_read_by_name() {
    let rig = rig_from_kalibr(&fixture("kalibr-omni-eucm-camchain.yaml"), "camchain.yaml", "r", "cam0").unwrap();
    let Lens::Omni(omni) = rig.sensors[0].lens else {
        panic!("{:?}", rig.sensors[0].lens)
    };
    assert_eq!(
        [omni.xi, omni.fx, omni.fy, omni.cx, omni.cy],
        [0.9217, 764.13, 763.41, 367.22, 248.38]
    );
    assert_eq!(omni.radtan.d, [-0.2587, 0.0717, 0.000192, 1.76e-05, 0.0]);
    let Lens::Eucm(eucm) = rig.sensors[1].lens else {
        panic!("{:?}", rig.sensors[1].lens)
    };
    assert_eq!(
        [eucm.alpha, eucm.beta, eucm.fx, eucm.fy, eucm.cx, eucm.cy],
        [0.6312, 1.0378, 370.12, 369.55, 371.22, 254.51]
    );
    round_trips(&rig);
    // `omni` without distortion is the plain unified model.
    let plain = fixture("kalibr-omni-eucm-camchain.yaml")
        .replace(
            "distortion_coeffs: [-0.2587, 0.0717, 0.000192, 1.76e-05]",
            "distortion_coeffs: []",
        )
        .replacen("distortion_model: radtan", "distortion_model: none", 1);
    let rig = rig_from_kalibr(&plain, "camchain.yaml", "r", "cam0").unwrap();
    assert!(matches!(rig.sensors[0].lens, Lens::Omni(o) if o.radtan.d == [0.0; 5]));
}

#[test]
fn basalt_kb4_eucm_and_ucm_cameras_are_read_by_name() {
    let rig = rig_from_basalt(
        &fixture("basalt-tumvi-kb4-eucm-ucm-calibration.json"),
        "c.json",
        "tumvi",
        "cam0",
    )
    .unwrap();
    let names: Vec<&str> = rig.sensors.iter().map(|s| s.lens.model_name()).collect();
    assert_eq!(names, ["kb4", "eucm", "eucm"]);
    assert!(matches!(rig.sensors[0].lens, Lens::Kb4(k) if k.k[3] == 0.00020293673591811182));
    // Basalt's ucm is EUCM with β = 1.
    assert!(matches!(rig.sensors[2].lens, Lens::Eucm(e) if e.alpha == 0.58 && e.beta == 1.0));
    // TUM-VI's fisheyes see past 90° at their image borders.
    assert!(rig.sensors[1].max_off_axis() > 100f64.to_radians());
    round_trips(&rig);
}

#[test]
fn opencv_and_ros_files_say_their_own_lens_model() {
    // OpenCV's calibration tutorial output: five coefficients, no model named (issue 49: it was
    // read as a fisheye and refused).
    let (rig, why) = rig_from_opencv(&fixture("opencv-tutorial-default.yml"), "out.yml", "one", None, None).unwrap();
    assert!(
        matches!(rig.sensors[0].lens, Lens::Radtan(r) if r.d[4] == -0.5784359721448747),
        "{rig:?}"
    );
    assert_eq!((rig.sensors[0].width, rig.sensors[0].height), (640, 480));
    assert!(why.contains("5 coefficients"), "{why}");
    // The tutorial's fisheye_model flag decides when it is there.
    let flagged = fixture("opencv-tutorial-default.yml").replace("flags: 2\n", "flags: 2\nfisheye_model: 0\n");
    let (_, why) = rig_from_opencv(&flagged, "out.yml", "one", None, None).unwrap();
    assert_eq!(why, "fisheye_model: 0");
    // ROS camera_info, plumb_bob.
    let (rig, why) = rig_from_opencv(
        &fixture("ros-camera-info-plumb-bob.yaml"),
        "ost.yaml",
        "one",
        None,
        None,
    )
    .unwrap();
    assert!(matches!(rig.sensors[0].lens, Lens::Radtan(r) if r.fx == 430.21554 && r.d[0] == -0.337586));
    assert_eq!(why, "distortion_model: plumb_bob");
    // ROS camera_info, equidistant: OpenCV's fisheye, our kb4.
    let (rig, why) = rig_from_opencv(
        &fixture("ros-camera-info-equidistant.yaml"),
        "fe.yaml",
        "one",
        None,
        None,
    )
    .unwrap();
    assert!(matches!(rig.sensors[0].lens, Lens::Kb4(k) if k.k == [-0.00536, 0.04116, -0.03818, 0.00627]));
    assert_eq!(why, "distortion_model: equidistant");
    assert_eq!((rig.sensors[0].width, rig.sensors[0].height), (1280, 800));
    // rational_polynomial with k4 = k5 = k6 = 0 is the five-coefficient lens.
    let rational = fixture("ros-camera-info-plumb-bob.yaml")
        .replace("plumb_bob", "rational_polynomial")
        .replace("cols: 5", "cols: 8")
        .replace("0.000126, 0]", "0.000126, 0, 0, 0, 0]");
    let (r8, _) = rig_from_opencv(&rational, "ost.yaml", "one", None, None).unwrap();
    let (r5, _) = rig_from_opencv(
        &fixture("ros-camera-info-plumb-bob.yaml"),
        "ost.yaml",
        "one",
        None,
        None,
    )
    .unwrap();
    assert_eq!(r8.sensors[0].lens, r5.sensors[0].lens);
    // Four coefficients with no model named are cv::fisheye's, and the override reads them as
    // k1, k2, p1, p2.
    let four = fixture("ros-camera-info-equidistant.yaml").replace("distortion_model: equidistant\n", "");
    let (rig, why) = rig_from_opencv(&four, "fe.yaml", "one", None, None).unwrap();
    assert!(
        matches!(rig.sensors[0].lens, Lens::Kb4(_)) && why.contains("--model default"),
        "{why}"
    );
    let (rig, why) = rig_from_opencv(&four, "fe.yaml", "one", Some(OpenCvModel::Default), None).unwrap();
    assert!(
        matches!(rig.sensors[0].lens, Lens::Radtan(_)) && why.contains("--model"),
        "{why}"
    );
}

/// Each bad input: (what the importer said, what it must say).
fn says(line: String, expected: &str) {
    assert!(line.contains(expected), "{line:?} should say {expected:?}");
    assert!(!line.contains('\n'), "{line:?}");
}

#[test]
fn what_cannot_be_imported_is_named_in_one_line() {
    let ds = fixture("kalibr-euroc-ds-camchain.yaml");
    let kalibr = |yaml: String| {
        rig_from_kalibr(&yaml, "camchain.yaml", "r", "cam0")
            .unwrap_err()
            .to_string()
    };
    // A ds camera with a pinhole's four intrinsics: the model and its parameters named
    // (issue 49: "intrinsics must have 4 numbers, found 5").
    says(
        kalibr(ds.replacen("[-0.2409573942178872, 0.566996899163044, ", "[", 1)),
        "camchain.yaml: cam0, key 'intrinsics': must have 6 numbers, found 4 (camera model 'ds' has [xi, alpha, fu, fv, pu, pv])",
    );
    says(
        kalibr(ds.replacen("camera_model: ds", "camera_model: fov", 1)),
        "cam0: camera model 'fov' with distortion 'none' is not supported (omnitrack reads pinhole with radtan, equidistant or none; omni with radtan or none; ds and eucm with none)",
    );
    says(
        kalibr(ds.replacen("distortion_model: none", "distortion_model: radtan", 1)),
        "camera model 'ds' with distortion 'radtan' is not supported",
    );
    says(
        kalibr(ds.replacen("0.566996899163044", "1.7", 1)),
        "cam0, key 'intrinsics': ds: α must be in [0, 1], found 1.7",
    );

    let basalt_text = fixture("basalt-euroc-ds-calibration.json");
    let basalt = |json: String| {
        rig_from_basalt(&json, "calibration.json", "r", "cam0")
            .unwrap_err()
            .to_string()
    };
    says(basalt("{ \"value0\": ".into()), "calibration.json: not JSON");
    says(
        basalt("{\"intrinsics\": []}".into()),
        "calibration.json: key 'value0': missing: not a Basalt calibration",
    );
    says(
        basalt(basalt_text.replacen("\"camera_type\": \"ds\"", "\"camera_type\": \"fov\"", 1)),
        "calibration.json: cam0: camera_type 'fov' is not supported (omnitrack reads ds, eucm, ucm, kb4 and pinhole)",
    );
    says(
        basalt(basalt_text.replacen("\"alpha\"", "\"beta\"", 1)),
        "key 'value0.intrinsics[0].intrinsics': unexpected 'beta' for camera_type 'ds' (it has fx, fy, cx, cy, xi, alpha)",
    );
    says(
        basalt(basalt_text.replacen("\"qw\": 0.7123125505904486", "\"qw\": 0.8", 1)),
        "key 'value0.T_imu_cam[0]': quaternion is not unit",
    );
    says(
        basalt(basalt_text.replacen("[\n                752,\n                480\n            ],", "", 1)),
        "key 'value0.resolution': 1 entries for 2 cameras",
    );
    let e = rig_from_basalt(&basalt_text, "calibration.json", "r", "cam2")
        .unwrap_err()
        .to_string();
    says(e, "--rig-frame cam2: no such camera (the calibration has cam0, cam1)");

    let ros = fixture("ros-camera-info-plumb-bob.yaml");
    let opencv = |yaml: String| {
        rig_from_opencv(&yaml, "ost.yaml", "r", None, None)
            .unwrap_err()
            .to_string()
    };
    says(
        opencv(ros.replace("plumb_bob", "kannala_brandt")),
        "ost.yaml, key 'distortion_model': 'kannala_brandt' is not read (plumb_bob, rational_polynomial or equidistant)",
    );
    says(
        opencv(ros.replace("distortion_model: plumb_bob", "distortion_model: equidistant")),
        "key 'distortion_coefficients': a fisheye lens (cv::fisheye, distortion_model: equidistant) has 4 coefficients, found 5",
    );
    says(
        opencv(
            ros.replace("plumb_bob", "rational_polynomial")
                .replace("cols: 5", "cols: 8")
                .replace("0.000126, 0]", "0.000126, 0, 0.1, 0, 0]"),
        ),
        "8 coefficients with k4, k5, k6 = [0.1, 0.0, 0.0]: OpenCV's rational model is not read",
    );
}
