//! VIS(T) is queried every frame on the device, and refined at the pose by every search: neither may allocate.
#![cfg(feature = "desk")]

use nalgebra::Point3;
use omnitrack::visibility::build::{build_table, check_memory, estimate, BuildOptions, Merge};

mod common;

#[global_allocator]
static ALLOCATOR: common::Counting = common::Counting;

/// Held by every test here: the memory tests count the heap of every thread of the process.
static SERIAL: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn serial() -> std::sync::MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// The example office plan extruded, and its table at a coarse cube map.
fn office() -> (omnitrack::Model, omnitrack::visibility::VisibilityTable) {
    let obj =
        omnitrack::desk::floorplan::extrude(include_str!("../tools/plans/example_office.geojson"), "plan").unwrap();
    let model = omnitrack::Model::from_obj_str(&obj, "office.obj").unwrap();
    let opts = BuildOptions {
        cube_map_resolution: 64,
        ..BuildOptions::default()
    };
    let table = build_table(&model, "office.obj", &opts);
    (model, table)
}

#[test]
fn query_allocates_nothing() {
    let _serial = serial();
    let (_model, table) = office();
    common::assert_counter_works();
    let mut seen = 0usize;
    let ((), allocated) = common::allocations_in(|| {
        for i in 0..1000 {
            let at = Point3::new(-1.0 + 0.014 * i as f64, -0.5 + 0.007 * i as f64, 1.0 + 0.001 * i as f64);
            if let Some(set) = table.query(&at) {
                seen += set.segments.len() + set.faces.len() + set.vertices.len();
            }
        }
    });
    assert!(seen > 0);
    assert_eq!(allocated, 0, "queries allocated");
}

/// Visibility at the pose (ray cast from the position itself) is asked for by every search and
/// every polish on the device: after construction it must not allocate either.
#[test]
fn visibility_at_the_pose_allocates_nothing() {
    let _serial = serial();
    use omnitrack::visibility::at_pose::PoseVisibility;
    let (model, table) = office();
    let mut at_pose = PoseVisibility::new(&model);
    common::assert_counter_works();
    let mut seen = 0usize;
    let ((), allocated) = common::allocations_in(|| {
        for i in 0..200 {
            let at = Point3::new(-1.0 + 0.07 * i as f64, -0.5 + 0.035 * i as f64, 1.5);
            seen += at_pose.at(&model, &table, &at).len();
        }
    });
    assert!(seen > 0);
    assert_eq!(allocated, 0, "visibility at the pose allocated");
}

/// The memory a build will take is known before it starts, as an upper bound of the right size:
/// between the peak measured over every thread (build, packing, and the file image `save`
/// writes) and 2.5 times it, with and without merging.
#[test]
fn a_builds_memory_is_estimated_before_it_starts() {
    let _serial = serial();
    let obj =
        omnitrack::desk::floorplan::extrude(include_str!("../tools/plans/example_office.geojson"), "plan").unwrap();
    let model = omnitrack::Model::from_obj_str(&obj, "office.obj").unwrap();
    let dir = tempfile::tempdir().unwrap();
    for merge in [Merge::None, Merge::CellCorners] {
        let opts = BuildOptions {
            cube_map_resolution: 64,
            spacing_m: 0.5,
            merge,
            ..BuildOptions::default()
        };
        let e = estimate(&model, &opts);
        let (nodes, peak) = common::peak_heap_of_all_threads_in(|| {
            let table = build_table(&model, "office.obj", &opts);
            table.save(&dir.path().join("office.vis")).unwrap();
            table.node_count()
        });
        eprintln!("{merge:?}: estimated {e:?}; built {nodes} nodes, peak heap {peak} B");
        assert!(
            e.peak_bytes as i64 >= peak,
            "{merge:?}: estimate {} B < peak {peak} B",
            e.peak_bytes
        );
        assert!(
            (e.peak_bytes as f64) <= 2.5 * peak as f64,
            "{merge:?}: estimate {} B > 2.5 × peak {peak} B",
            e.peak_bytes
        );
        let share = e.nodes as f64 / nodes as f64;
        assert!(
            (0.8..1.25).contains(&share),
            "{merge:?}: {} nodes expected, {nodes} built",
            e.nodes
        );
    }
}

/// A 3 km × 3 km site at the shipped 1 m spacing passed every check and its build died out of
/// memory at 1.7 GB after 88 s (issue 50): now it is refused before a byte of its table exists,
/// in one line saying what it would take and a spacing that fits.
#[test]
fn a_build_larger_than_the_memory_is_refused_before_it_starts() {
    let _serial = serial();
    let mut obj = String::new();
    // A floor, a ceiling and a wall round a square, 3 km a side.
    let side = 3000.0;
    for (x, y) in [(0.0, 0.0), (side, 0.0), (side, side), (0.0, side)] {
        obj += &format!("v {x} {y} 0\nv {x} {y} 3\n");
    }
    obj += "f 1 3 5 7\nf 2 4 6 8\nf 1 3 4 2\nf 3 5 6 4\nf 5 7 8 6\nf 7 1 2 8\n";
    let model = omnitrack::Model::from_obj_str(&obj, "site.obj").unwrap();
    let opts = BuildOptions::default();
    let e = estimate(&model, &opts);
    eprintln!("3 km site: {e:?}");
    assert!(e.cells > 20_000_000, "{e:?}");
    assert!(e.peak_bytes > 4_000_000_000, "{e:?}");
    let err = check_memory(&model, &opts, Some(2_000_000_000)).unwrap_err();
    assert!(
        !err.contains('\n') && err.contains("GB") && err.contains("spacing"),
        "{err}"
    );
    assert!(check_memory(&model, &opts, Some(e.peak_bytes)).is_ok());
}
