//! `omnitrack pose` as a black box: rig TOML + lines CSV in, the JSON of docs/interfaces.md out.

use crate::common::omnitrack;
use nalgebra::{Isometry3, Point3, Vector3};
use omnitrack::Rig;
use std::fmt::Write;

/// Lines seen from `truth` by the six-sensor rig: each segment's end points projected into the
/// sensor that sees both.
fn lines_csv(rig: &Rig, truth: &Isometry3<f64>) -> (String, usize) {
    let mut csv = String::from("sensor,u1,v1,u2,v2,x1,y1,z1,x2,y2,z2\n");
    let mut rows = 0;
    // The 12 edges of a 6 × 5 × 2.6 m room around the rig, cut into pieces.
    let c = [
        [0.0, 0.0, 0.0],
        [6.0, 0.0, 0.0],
        [6.0, 5.0, 0.0],
        [0.0, 5.0, 0.0],
        [0.0, 0.0, 2.6],
        [6.0, 0.0, 2.6],
        [6.0, 5.0, 2.6],
        [0.0, 5.0, 2.6],
    ];
    let edges = [
        (0, 1),
        (1, 2),
        (2, 3),
        (3, 0),
        (4, 5),
        (5, 6),
        (6, 7),
        (7, 4),
        (0, 4),
        (1, 5),
        (2, 6),
        (3, 7),
    ];
    for (i, j) in edges {
        for k in 0..4 {
            let a = Point3::from(c[i]) + (Point3::from(c[j]) - Point3::from(c[i])) * (0.05 + 0.22 * k as f64);
            let b = Point3::from(c[i]) + (Point3::from(c[j]) - Point3::from(c[i])) * (0.2 + 0.22 * k as f64);
            for s in &rig.sensors {
                let pa = s.project_from_rig(&truth.inverse_transform_point(&a));
                let pb = s.project_from_rig(&truth.inverse_transform_point(&b));
                if let (Some(pa), Some(pb)) = (pa, pb) {
                    if (pa - pb).norm() > 20.0 {
                        let _ = writeln!(
                            csv,
                            "{},{},{},{},{},{},{},{},{},{},{}",
                            s.id, pa.x, pa.y, pb.x, pb.y, a.x, a.y, a.z, b.x, b.y, b.z
                        );
                        rows += 1;
                        break;
                    }
                }
            }
        }
    }
    (csv, rows)
}

#[test]
fn every_method_recovers_the_pose_and_prints_the_documented_json() {
    let rig_path = crate::common::SHIPPED_RIG;
    let rig = crate::common::shipped_rig();
    let truth = Isometry3::new(Vector3::new(2.2, 1.9, 1.3), Vector3::new(0.02, -0.03, 0.8));
    let (csv, rows) = lines_csv(&rig, &truth);
    assert!(rows >= 15, "{rows} lines");
    let dir = tempfile::tempdir().unwrap();
    let lines = dir.path().join("lines.csv");
    std::fs::write(&lines, csv).unwrap();
    let lines = lines.to_str().unwrap();
    let q = truth.rotation.quaternion();
    let guess = format!("{},{},{},{},{},{},{}", 2.0, 2.1, 1.2, q.w, q.i, q.j, q.k);
    for method in ["r_and_t", "r_then_t", "lms", "xi"] {
        for with_guess in [false, true] {
            let mut args = vec!["pose", "--rig", rig_path, "--lines", lines, "--method", method];
            if with_guess {
                args.extend(["--guess", &guess]);
            }
            let (code, stdout, stderr) = omnitrack(&args);
            assert_eq!(code, 0, "{method}: {stderr}");
            let json: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
            let p: Vec<f64> = json["position"]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_f64().unwrap())
                .collect();
            let r: Vec<f64> = json["rotation_wxyz"]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_f64().unwrap())
                .collect();
            assert_eq!(json["covariance"].as_array().unwrap().len(), 36);
            assert_eq!(
                json["inliers"].as_array().unwrap().len(),
                rows,
                "{method}: all lines are inliers"
            );
            assert!(json["xi_rad2"].as_f64().unwrap() < 1e-12);
            assert!(json["iterations"].as_u64().is_some());
            let pos_err = (Vector3::new(p[0], p[1], p[2]) - truth.translation.vector).norm();
            let rot = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(r[0], r[1], r[2], r[3]));
            let tol = if method == "xi" { 1e-6 } else { 1e-9 };
            assert!(pos_err < tol, "{method} guess={with_guess}: position off by {pos_err}");
            assert!(rot.angle_to(&truth.rotation) < tol, "{method}: rotation off");
        }
    }
}

#[test]
fn bad_input_is_one_line_naming_the_problem() {
    let rig_path = crate::common::SHIPPED_RIG;
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.csv");
    std::fs::write(&bad, "sensor,u1,v1,u2,v2,x1,y1,z1,x2,y2,z2\n0,1,2,3\n").unwrap();
    let bad = bad.to_str().unwrap();
    let cases: Vec<(Vec<&str>, String)> = vec![
        (
            vec!["pose", "--rig", rig_path, "--lines", bad],
            format!("{bad}:2: expected 11 fields, found 4"),
        ),
        (
            vec!["pose", "--rig", rig_path, "--lines", "/no/such.csv"],
            "/no/such.csv: cannot read".into(),
        ),
        (
            vec!["pose", "--rig", "/no/rig.toml", "--lines", bad],
            "/no/rig.toml: cannot read rig file".into(),
        ),
        (
            vec!["pose", "--rig", rig_path, "--lines", bad, "--guess", "-1,2,3,1,0,0"],
            "--guess '-1,2,3,1,0,0': expected 7 numbers".into(),
        ),
    ];
    for (args, expected) in cases {
        let (code, stdout, stderr) = omnitrack(&args);
        assert_eq!(code, 2, "{args:?}");
        assert!(stdout.is_empty());
        assert_eq!(stderr.lines().count(), 1, "{stderr}");
        assert!(stderr.contains(&expected), "{stderr:?} should contain {expected:?}");
    }
    let few = dir.path().join("few.csv");
    std::fs::write(
        &few,
        "sensor,u1,v1,u2,v2,x1,y1,z1,x2,y2,z2\n0,100,100,200,120,4,0,1,4,1,1\n",
    )
    .unwrap();
    let (code, _, stderr) = omnitrack(&["pose", "--rig", rig_path, "--lines", few.to_str().unwrap()]);
    assert_eq!(code, 2);
    assert!(stderr.contains("need at least 3 correspondences, got 1"), "{stderr}");
}
