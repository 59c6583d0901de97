//! VIS(T) is queried every frame on the device, and refined at the pose by every search: neither may allocate.
#![cfg(feature = "desk")]

use nalgebra::Point3;
use omnitrack::visibility::build::{build_table, BuildOptions};

mod common;

#[global_allocator]
static ALLOCATOR: common::Counting = common::Counting;

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
