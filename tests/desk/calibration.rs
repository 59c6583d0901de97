//! Calibration in: Kalibr camera chains and OpenCV calibration files to rig files. The shipped
//! rig written out as Kalibr would write it converts back to itself (up to the rig frame, which
//! becomes the reference camera's); a stereo radtan chain gives radtan lenses and its baseline;
//! an OpenCV fisheye file gives the shipped rig's first sensor; what cannot be converted says
//! which file, camera and key, in one line.

#![cfg(feature = "desk")]

use nalgebra::{Matrix4, Vector3};
use omnitrack::desk::kalibr::{rig_from_kalibr, KalibrError};
use omnitrack::geometry::{Lens, Pose};
use omnitrack::Rig;
use std::fmt::Write as _;

fn shipped() -> Rig {
    crate::common::shipped_rig()
}

fn rows(m: &Matrix4<f64>) -> String {
    let mut s = String::new();
    for r in 0..4 {
        let _ = writeln!(
            s,
            "  - [{:?}, {:?}, {:?}, {:?}]",
            m[(r, 0)],
            m[(r, 1)],
            m[(r, 2)],
            m[(r, 3)]
        );
    }
    s
}

/// The camera chain Kalibr would write for `rig`: per camera its lens and, from cam1 on,
/// T_cn_cnm1 = T_cn_rig · T_rig_cnm1.
fn camchain(rig: &Rig) -> String {
    let mut y = String::new();
    for (n, s) in rig.sensors.iter().enumerate() {
        let _ = writeln!(y, "cam{n}:");
        if n > 0 {
            let link = (s.t_rig_sensor.inverse() * rig.sensors[n - 1].t_rig_sensor).to_homogeneous();
            let _ = write!(y, "  T_cn_cnm1:\n{}", rows(&link));
        }
        let (distortion, coeffs): (&str, Vec<f64>) = match s.lens {
            Lens::Kb4(l) => ("equidistant", l.k.to_vec()),
            Lens::Radtan(l) => ("radtan", l.d[..4].to_vec()),
            Lens::Pinhole(_) => ("none", vec![]),
            _ => unreachable!("not a pinhole Kalibr model"),
        };
        let c = s.lens.principal_point();
        let _ = writeln!(y, "  camera_model: pinhole");
        let _ = writeln!(
            y,
            "  intrinsics: [{:?}, {:?}, {:?}, {:?}]",
            s.lens.fx(),
            s.lens.fy(),
            c.x,
            c.y
        );
        let _ = writeln!(y, "  distortion_model: {distortion}");
        let _ = writeln!(y, "  distortion_coeffs: {coeffs:?}");
        let _ = writeln!(y, "  resolution: [{}, {}]", s.width, s.height);
        let _ = writeln!(y, "  rostopic: /cam{n}/image_raw");
    }
    y
}

fn pose_gap(a: &Pose, b: &Pose) -> (f64, f64) {
    (
        (a.translation.vector - b.translation.vector).norm(),
        a.rotation.angle_to(&b.rotation),
    )
}

#[test]
fn the_shipped_rig_through_kalibr_is_the_same_rig() {
    let rig = shipped();
    for reference in ["cam0", "cam3", "cam5"] {
        let back = rig_from_kalibr(&camchain(&rig), "camchain.yaml", "back", reference).unwrap();
        assert_eq!(back.sensors.len(), rig.sensors.len());
        let k = reference[3..].parse::<usize>().unwrap();
        // The rig frame is the reference camera's, turned: x along its axis, z its image up.
        let t_ref = back.sensors[k].t_rig_sensor;
        assert!(t_ref.translation.vector.norm() < 1e-12);
        let axis = t_ref.rotation * Vector3::z();
        let up = t_ref.rotation * -Vector3::y();
        assert!((axis - Vector3::x()).norm() < 1e-12 && (up - Vector3::z()).norm() < 1e-12);
        // Every sensor sits where it sat relative to the reference, with the same lens.
        for (a, b) in rig.sensors.iter().zip(&back.sensors) {
            let before = rig.sensors[k].t_rig_sensor.inverse() * a.t_rig_sensor;
            let after = back.sensors[k].t_rig_sensor.inverse() * b.t_rig_sensor;
            let (dt, dr) = pose_gap(&before, &after);
            assert!(dt < 1e-12 && dr < 1e-12, "sensor {}: {dt} m, {dr} rad", a.id);
            assert_eq!((a.width, a.height), (b.width, b.height));
            assert_eq!(a.lens, b.lens);
        }
    }
}

#[test]
fn a_radtan_stereo_chain_gives_radtan_lenses_and_its_baseline() {
    // EuRoC's two cameras as Kalibr's sample output gives them (rounded).
    let yaml = "cam0:
  camera_model: pinhole
  intrinsics: [458.654, 457.296, 367.215, 248.375]
  distortion_model: radtan
  distortion_coeffs: [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]
  resolution: [752, 480]
cam1:
  T_cn_cnm1:
  - [0.9999972564779, 0.0023120725, 0.0003413143, -0.1100738323]
  - [-0.0023117532, 0.9999971445, -0.0009321052, 0.0003991804]
  - [-0.0003434688, 0.0009313133, 0.9999995073, -0.0008536743]
  - [0.0, 0.0, 0.0, 1.0]
  camera_model: pinhole
  intrinsics: [457.587, 456.134, 379.999, 255.238]
  distortion_model: radtan
  distortion_coeffs: [-0.28368365, 0.07451284, -0.00010473, -3.55590700e-05]
  resolution: [752, 480]
";
    let rig = rig_from_kalibr(yaml, "euroc.yaml", "euroc", "cam0").unwrap();
    assert!(rig.sensors.iter().all(|s| matches!(s.lens, Lens::Radtan(_))));
    // cam1 sits 11 cm to cam0's right: rig y is left, so at y ≈ −0.11.
    let c1 = rig.sensors[1].centre();
    assert!(
        (c1.y + 0.11).abs() < 1e-3 && c1.x.abs() < 2e-3 && c1.z.abs() < 2e-3,
        "{c1}"
    );
    // Written and read back, the rig is the same to the last bit.
    let again = Rig::from_toml_str(&rig.to_toml_string(), "again.toml").unwrap();
    assert_eq!(again, rig);
}

#[test]
fn what_cannot_be_converted_is_named_in_one_line() {
    let good = camchain(&shipped());
    let cases: Vec<(String, &str, &str)> = vec![
        ("cam0: [unclosed".into(), "cam0", "not YAML"),
        ("other: 1\n".into(), "cam0", "no cameras"),
        (
            good.clone(),
            "cam9",
            "--rig-frame cam9: no such camera (the chain has cam0, cam1, cam2, cam3, cam4, cam5)",
        ),
        (
            good.replacen("camera_model: pinhole", "camera_model: omni", 1),
            "cam0",
            "cam0: camera model 'omni' with distortion 'equidistant' is not supported",
        ),
        (
            good.replace("distortion_model: equidistant", "distortion_model: fov"),
            "cam0",
            "camera model 'pinhole' with distortion 'fov' is not supported",
        ),
        (
            good.replacen(
                "intrinsics: [285.0, 285.0, 191.5, 255.5]",
                "intrinsics: [285.0, 191.5, 255.5]",
                1,
            ),
            "cam0",
            "cam0, key 'intrinsics': must have 4 numbers, found 3",
        ),
        (
            good.replacen("  - [0.0, 0.0, 0.0, 1.0]", "  - [0.0, 0.0, 0.0, 2.0]", 1),
            "cam0",
            "cam1, key 'T_cn_cnm1': not a rigid transform",
        ),
        (
            good.replacen("resolution: [384, 512]", "resolution: [384.5, 512]", 1),
            "cam0",
            "cam0, key 'resolution': must be two pixel counts",
        ),
    ];
    for (yaml, reference, expected) in cases {
        let e: KalibrError = rig_from_kalibr(&yaml, "camchain.yaml", "r", reference).unwrap_err();
        let line = e.to_string();
        assert!(line.starts_with("camchain.yaml: "), "{line}");
        assert!(line.contains(expected), "{line:?} should say {expected:?}");
        assert!(!line.contains('\n'), "{line:?}");
    }
}

/// What OpenCV 5.0's `cv::FileStorage` wrote for `cv::fisheye` K and D (the shipped rig's first
/// sensor), with the `%YAML:1.0` header OpenCV 3 wrote instead of `%YAML 1.2`.
const OPENCV_FISHEYE: &str = "%YAML:1.0
---
K: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 285., 0., 191.5, 0., 285., 255.5, 0., 0., 1. ]
D: !!opencv-matrix
   rows: 4
   cols: 1
   dt: d
   data: [ -0.014999999999999999, 0.002, -0.00029999999999999997, 0. ]
image_width: 384
image_height: 512
";

#[test]
fn an_opencv_fisheye_calibration_is_the_shipped_rigs_first_sensor() {
    use omnitrack::desk::opencv_calib::{rig_from_opencv, OpenCvModel};
    let rig = rig_from_opencv(OPENCV_FISHEYE, "cam.yaml", "one", Some(OpenCvModel::Fisheye), None)
        .unwrap()
        .0;
    let shipped = shipped();
    assert_eq!(rig.sensors.len(), 1);
    let (a, b) = (&rig.sensors[0], &shipped.sensors[0]);
    assert_eq!(a.lens, b.lens);
    assert_eq!((a.width, a.height), (b.width, b.height));
    // Sensor 0 of the shipped rig looks forward as the turned camera frame does.
    assert!(a.t_rig_sensor.rotation.angle_to(&b.t_rig_sensor.rotation) < 1e-12);

    // The default model from OpenCV's calibration sample's key names, five coefficients.
    let default = "%YAML 1.2
---
camera_matrix: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 458.654, 0., 367.21499999999997, 0., 457.29599999999999,
       248.375, 0., 0., 1. ]
distortion_coefficients: !!opencv-matrix
   rows: 1
   cols: 5
   dt: d
   data: [ -0.28340810999999999, 0.073959070000000002,
       0.00019358999999999999, 1.7618711400000001e-05,
       0.0011999999999999999 ]
";
    let rig = rig_from_opencv(default, "cam.yaml", "one", Some(OpenCvModel::Default), Some((752, 480)))
        .unwrap()
        .0;
    assert!(matches!(rig.sensors[0].lens, Lens::Radtan(r) if r.d[4] == 0.0012));
    assert_eq!((rig.sensors[0].width, rig.sensors[0].height), (752, 480));
}

#[test]
fn what_an_opencv_file_lacks_is_named_in_one_line() {
    use omnitrack::desk::opencv_calib::{rig_from_opencv, OpenCvModel};
    let cases = [
        (
            OPENCV_FISHEYE.replace("K: ", "Kx: "),
            OpenCvModel::Fisheye,
            "key 'K' or 'camera_matrix': missing",
        ),
        (
            OPENCV_FISHEYE.replace("rows: 4", "rows: 5"),
            OpenCvModel::Fisheye,
            "key 'D': rows × cols = 5 but data has 4 numbers",
        ),
        (
            OPENCV_FISHEYE.replace("image_width: 384\n", ""),
            OpenCvModel::Fisheye,
            "no image size",
        ),
        (
            OPENCV_FISHEYE.replace("0., 285., 255.5", "2., 285., 255.5"),
            OpenCvModel::Fisheye,
            "no skew",
        ),
        (
            OPENCV_FISHEYE.replace("rows: 4", "rows: 8").replace(
                "0.002, -0.00029999999999999997, 0. ]",
                "0.002, -0.0003, 0., 0., 0.1, 0., 0. ]",
            ),
            OpenCvModel::Default,
            "8 coefficients with k4, k5, k6 = [0.1, 0.0, 0.0]",
        ),
    ];
    for (yaml, model, expected) in cases {
        let line = rig_from_opencv(&yaml, "cam.yaml", "one", Some(model), None)
            .unwrap_err()
            .to_string();
        assert!(line.starts_with("cam.yaml"), "{line}");
        assert!(line.contains(expected), "{line:?} should say {expected:?}");
        assert!(!line.contains('\n'));
    }
}
