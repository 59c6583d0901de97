//! `omnitrack visibility build / query` as a black box on the extruded example plan.
#![cfg(feature = "desk")]

use crate::common::omnitrack;

#[test]
fn build_then_query_prints_the_documented_json() {
    let dir = tempfile::tempdir().unwrap();
    let obj =
        omnitrack::desk::floorplan::extrude(include_str!("../../tools/plans/example_office.geojson"), "plan").unwrap();
    let model_path = dir.path().join("office.obj");
    std::fs::write(&model_path, &obj).unwrap();
    let model = omnitrack::Model::from_obj_str(&obj, "office.obj").unwrap();
    let table = dir.path().join("office.vis");
    let (m, t) = (model_path.to_str().unwrap(), table.to_str().unwrap());

    let (code, stdout, stderr) = omnitrack(&["visibility", "build", "--model", m, "--out", t, "--spacing-m", "1.0"]);
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.is_empty(), "build prints nothing on stdout");

    // In the corridor, and outside the building with negative coordinates as written.
    for at in ["6,1,1.5", "-1.5,2,1.6"] {
        let (code, stdout, stderr) = omnitrack(&["visibility", "query", "--visibility", t, "--at", at]);
        assert_eq!(code, 0, "{stderr}");
        let json: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
        let node: Vec<f64> = json["node_m"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert_eq!(node.len(), 3);
        let faces = json["faces"].as_array().unwrap();
        assert!(!faces.is_empty());
        let numbers: Vec<u64> = faces.iter().map(|f| f.as_u64().unwrap()).collect();
        assert!(
            numbers.iter().all(|&n| n >= 1 && n as usize <= model.faces.len()),
            "1-based OBJ face numbers"
        );
        let segments = json["segments"].as_array().unwrap();
        assert!(!segments.is_empty());
        for s in segments {
            let v: Vec<f64> = s.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
            assert_eq!(v.len(), 6);
            // Whole model segments, not clipped pieces.
            assert!(model.segments.iter().any(|m| {
                let (a, b) = ([m.a.x, m.a.y, m.a.z], [m.b.x, m.b.y, m.b.z]);
                let close = |p: &[f64], q: &[f64; 3]| p.iter().zip(q).all(|(x, y)| (x - y).abs() < 1e-9);
                (close(&v[..3], &a) && close(&v[3..], &b)) || (close(&v[..3], &b) && close(&v[3..], &a))
            }));
        }
        assert!(!json["vertices"].as_array().unwrap().is_empty());
    }
    // From the corridor the corridor's own floor line (y = 0 shell wall foot) is seen.
    let (_, stdout, _) = omnitrack(&["visibility", "query", "--visibility", t, "--at", "6,1,1.5"]);
    assert!(
        stdout.contains("[0,0,0,12,0,0]") || stdout.contains("[12,0,0,0,0,0]"),
        "{stdout}"
    );

    // Bad input: one line each, exit 2.
    let cases = [
        (
            vec!["visibility", "query", "--visibility", t, "--at", "1,2"],
            "expected x,y,z",
        ),
        (
            vec!["visibility", "query", "--visibility", "/no/table.vis", "--at", "1,2,3"],
            "/no/table.vis",
        ),
    ];
    for (args, expected) in cases {
        let (code, stdout, stderr) = omnitrack(&args);
        assert_eq!(code, 2);
        assert!(stdout.is_empty());
        assert_eq!(stderr.lines().count(), 1, "{stderr}");
        assert!(stderr.contains(expected), "{stderr}");
    }
    // The model changed after the table was built: the query refuses the stale table.
    std::fs::write(&model_path, obj.replace("v 0 0 0", "v 0 0 0.001")).unwrap();
    let (code, _, stderr) = omnitrack(&["visibility", "query", "--visibility", t, "--at", "6,1,1.5"]);
    assert_eq!(code, 2);
    assert!(stderr.contains("different model"), "{stderr}");
}
