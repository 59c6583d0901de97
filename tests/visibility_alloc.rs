//! VIS(T) is queried every frame on the device: it must not allocate.
#![cfg(feature = "desk")]

use nalgebra::Point3;
use omnitrack::visibility::build::{build_table, BuildOptions};
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

struct Counting;

thread_local! {
    static COUNTING: Cell<bool> = const { Cell::new(false) };
    static COUNT: Cell<usize> = const { Cell::new(0) };
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if COUNTING.with(Cell::get) {
            COUNT.with(|c| c.set(c.get() + 1));
        }
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

#[test]
fn query_allocates_nothing() {
    let obj =
        omnitrack::desk::floorplan::extrude(include_str!("../tools/plans/example_office.geojson"), "plan").unwrap();
    let model = omnitrack::Model::from_obj_str(&obj, "office.obj").unwrap();
    let opts = BuildOptions {
        cube_map_resolution: 64,
        ..BuildOptions::default()
    };
    let table = build_table(&model, "office.obj", &opts);
    // The counter itself must work.
    COUNTING.with(|c| c.set(true));
    let v = vec![1u8];
    COUNTING.with(|c| c.set(false));
    assert_eq!(COUNT.with(Cell::get), 1);
    drop(v);
    COUNT.with(|c| c.set(0));

    let mut seen = 0usize;
    COUNTING.with(|c| c.set(true));
    for i in 0..1000 {
        let at = Point3::new(-1.0 + 0.014 * i as f64, -0.5 + 0.007 * i as f64, 1.0 + 0.001 * i as f64);
        if let Some(set) = table.query(&at) {
            seen += set.segments.len() + set.faces.len() + set.vertices.len();
        }
    }
    COUNTING.with(|c| c.set(false));
    assert!(seen > 0);
    assert_eq!(COUNT.with(Cell::get), 0, "queries allocated");
}
