//! `omnitrack-desk model from-ifc` on an IFC house written by IfcOpenShell's own authoring API
//! (`tools/ifc_sample_house.py`: two storeys in millimetres, a door cut into a wall, furniture,
//! a duct and a railing that must be left out). The first run installs IfcOpenShell from PyPI
//! into the per-user cache (`~/.cache/omnitrack/ifc-venv`); the tests of an installed binary
//! below install nothing.

use omnitrack::visibility::build::{build_table, BuildOptions, Merge};
use omnitrack::Model;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

fn tools() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The sample house, written once per test run.
fn house() -> &'static PathBuf {
    static HOUSE: OnceLock<(tempfile::TempDir, PathBuf)> = OnceLock::new();
    &HOUSE
        .get_or_init(|| {
            let dir = tempfile::tempdir().unwrap();
            let path = dir.path().join("house.ifc");
            let out = Command::new("python3")
                .arg(tools().join("ifc_sample_house.py"))
                .arg(&path)
                .output()
                .expect("python3");
            assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
            (dir, path)
        })
        .1
}

/// Runs `omnitrack-desk ARGS`: (exit code, stderr).
fn desk(args: &[&str]) -> (i32, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_omnitrack-desk"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// The lines of `stderr` that are not the converter's progress.
fn errors(stderr: &str) -> usize {
    stderr.lines().filter(|l| !l.starts_with("from-ifc: ")).count()
}

/// `omnitrack-desk` as a package installs it: copied out of the build tree into `DIR/bin`, run
/// from `DIR` with its own cache `DIR/cache` (`$OMNITRACK_CACHE`). (exit code, stderr).
fn installed(dir: &Path, args: &[&str]) -> (i32, String) {
    let bin = dir.join("bin");
    std::fs::create_dir_all(&bin).unwrap();
    let exe = bin.join("omnitrack-desk");
    if !exe.exists() {
        std::fs::copy(env!("CARGO_BIN_EXE_omnitrack-desk"), &exe).unwrap();
    }
    let out = Command::new(&exe)
        .args(args)
        .current_dir(dir)
        .env("OMNITRACK_CACHE", dir.join("cache"))
        .env_remove("OMNITRACK_IFC_VENV")
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Issue 49: an installed binary ran `tools/ifc_to_obj.py` by the path it was built at ("can't
/// open file"). It carries the converter, writes it into the cache and runs it from there: a
/// file that is not IFC gets the converter's own one-line answer, and nothing is installed for
/// it (the input is checked before any venv is made).
#[test]
fn an_installed_binary_runs_the_converter_it_carries_from_the_cache() {
    let dir = tempfile::tempdir().unwrap();
    let notes = dir.path().join("notes.ifc");
    std::fs::write(&notes, "a shopping list\n").unwrap();
    let (code, stderr) = installed(dir.path(), &["model", "from-ifc", "notes.ifc", "--out", "notes.obj"]);
    assert_eq!(code, 2, "{stderr}");
    assert_eq!(stderr.trim().lines().count(), 1, "{stderr}");
    assert!(stderr.contains("notes.ifc: not an IFC file"), "{stderr}");
    let script = dir.path().join("cache/ifc_to_obj.py");
    assert_eq!(
        std::fs::read_to_string(&script).unwrap(),
        std::fs::read_to_string(tools().join("ifc_to_obj.py")).unwrap()
    );
    assert!(!dir.path().join("cache/ifc-venv").exists());
}

/// Issue 49: the first use installed IfcOpenShell into the source tree for ~20 s without a word.
/// It goes into the cache's `ifc-venv`, and a line says so before it starts. Here the venv's
/// Python is a stand-in that has no IfcOpenShell and whose pip fails, so nothing is downloaded:
/// the progress line, then one line naming the venv that could not be set up.
#[test]
fn ifcopenshell_goes_into_the_users_cache_with_a_line_that_says_so() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let venv = dir.path().join("cache/ifc-venv");
    std::fs::create_dir_all(venv.join("bin")).unwrap();
    let python = venv.join("bin/python");
    std::fs::write(&python, "#!/bin/sh\nexit 1\n").unwrap();
    std::fs::set_permissions(&python, std::fs::Permissions::from_mode(0o755)).unwrap();
    std::fs::write(dir.path().join("house.ifc"), "ISO-10303-21;\n").unwrap();
    let (code, stderr) = installed(dir.path(), &["model", "from-ifc", "house.ifc", "--out", "house.obj"]);
    assert_eq!(code, 2, "{stderr}");
    let lines: Vec<&str> = stderr.lines().collect();
    let venv = venv.display().to_string();
    assert_eq!(lines.len(), 2, "{stderr}");
    assert!(
        lines[0].starts_with("from-ifc: installing IfcOpenShell (PyPI ifcopenshell) into ") && lines[0].contains(&venv),
        "{stderr}"
    );
    assert!(
        lines[1].contains(&format!("cannot set up IfcOpenShell in {venv}")),
        "{stderr}"
    );
    assert!(!dir.path().join("house.obj").exists());
}

/// The `o` names of an OBJ file.
fn objects(obj: &Path) -> Vec<String> {
    std::fs::read_to_string(obj)
        .unwrap()
        .lines()
        .filter_map(|l| l.strip_prefix("o ").map(str::to_string))
        .collect()
}

#[test]
fn a_two_storey_house_converts_in_metres_with_furniture_and_services_left_out() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("house.obj");
    let (code, stderr) = desk(&[
        "model",
        "from-ifc",
        house().to_str().unwrap(),
        "--out",
        obj.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{stderr}");
    assert!(
        stderr.contains("storey 'Ground' (elevation 0.00 m): 1 columns, 1 doors, 1 slabs, 4 walls"),
        "{stderr}"
    );
    assert!(
        stderr.contains("storey 'Upper' (elevation 3.00 m): 1 slabs, 4 walls"),
        "{stderr}"
    );
    let names = objects(&obj);
    assert_eq!(names.len(), 12, "{names:?}");
    for kept in names.iter().map(|n| n.split('_').next().unwrap()) {
        assert!(["IfcWall", "IfcSlab", "IfcColumn", "IfcDoor"].contains(&kept), "{kept}");
    }
    let model = Model::load(&obj).unwrap();
    // Millimetres in the file, metres out: the room is 6 × 4 m, two storeys of 2.8 m walls on
    // 0.2 m slabs.
    let (lo, hi) = model
        .vertices
        .iter()
        .fold(([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]), |(mut lo, mut hi), v| {
            for k in 0..3 {
                lo[k] = lo[k].min(v[k]);
                hi[k] = hi[k].max(v[k]);
            }
            (lo, hi)
        });
    let near = |a: [f64; 3], b: [f64; 3]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-6);
    assert!(near(lo, [0.0, 0.0, -0.2]), "{lo:?}");
    assert!(near(hi, [6.0, 4.0, 5.8]), "{hi:?}");
    // The door opening is cut: the door wall's inner face has the opening's jambs and head as
    // model segments (2.1 m jambs at x = 2.0 and 2.9 m).
    let jamb = |x: f64| {
        model.segments.iter().any(|s| {
            (s.a.x - x).abs() < 1e-6
                && (s.b.x - x).abs() < 1e-6
                && (s.length() - 2.1).abs() < 1e-6
                && (s.a.y - 0.2).abs() < 1e-6
        })
    };
    assert!(jamb(2.0) && jamb(2.9), "no door jambs in the wall");
    // The tracker can use it: the visibility table has free nodes on both storeys.
    // Node layers 1.0 and 1.5 m above each floor (heights count from the model's lowest point,
    // the ground slab's underside at -0.2 m).
    let opts = BuildOptions {
        spacing_m: 1.0,
        heights_m: vec![1.2, 1.7, 4.2, 4.7],
        cube_map_resolution: 64,
        merge: Merge::None,
        ..BuildOptions::default()
    };
    let table = build_table(&model, "house.obj", &opts);
    let mut storeys = [0usize; 2];
    for n in 0..table.node_count() as u32 {
        storeys[usize::from(table.node_position(n).z > 2.9)] += 1;
    }
    assert!(storeys[0] > 0 && storeys[1] > 0, "valid nodes per storey {storeys:?}");
}

#[test]
fn a_storey_alone_and_bad_input_in_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("upper.obj");
    let house = house().to_str().unwrap();
    let from_ifc = |storey: &str| {
        desk(&[
            "model",
            "from-ifc",
            house,
            "--out",
            obj.to_str().unwrap(),
            "--storey",
            storey,
        ])
    };
    let (code, stderr) = from_ifc("Upper");
    assert_eq!(code, 0, "{stderr}");
    assert_eq!(objects(&obj).len(), 5);
    assert!(Model::load(&obj).unwrap().vertices.iter().all(|v| v.z >= 2.8 - 1e-6));

    let (code, stderr) = from_ifc("Attic");
    assert_eq!(code, 2);
    // One line of error (after the progress lines of a first install, if this test made it).
    assert_eq!(errors(&stderr), 1, "{stderr}");
    assert!(
        stderr.contains("no storey named 'Attic' (storeys: 'Ground', 'Upper')"),
        "{stderr}"
    );

    let not_ifc = dir.path().join("notes.ifc");
    std::fs::write(&not_ifc, "a shopping list\n").unwrap();
    let out = dir.path().join("never.obj");
    let (code, stderr) = desk(&[
        "model",
        "from-ifc",
        not_ifc.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 2);
    assert_eq!(errors(&stderr), 1, "{stderr}");
    assert!(stderr.contains("not an IFC file"), "{stderr}");
    assert!(!out.exists() && !out.with_extension("obj.partial").exists());

    let (code, stderr) = desk(&["model", "from-ifc", "/no/such.ifc", "--out", out.to_str().unwrap()]);
    assert_eq!(code, 2);
    assert!(stderr.contains("no such file"), "{stderr}");
}
