//! The scenario floor plans, generated as GeoJSON text for [`crate::floorplan`].
//!
//! Both plans use thick exterior walls (0.3 m) with rooms drawn to their inner face, and thinner
//! interior walls (0.15 m, partitions 0.12 m) with rooms drawn to their axes, as the floor-plan
//! reference asks. Every number here is a constant: the text is the same on every call.

use serde_json::{json, Value};

/// Thickness of exterior walls and of the fire wall between the two CORRIDOR buildings.
const EXTERIOR_T: f64 = 0.3;
/// Thickness of corridor walls and office partitions.
const INTERIOR_T: f64 = 0.15;
/// Thickness of the LAB's free-standing and partial partitions.
const PARTITION_T: f64 = 0.12;

struct PlanBuilder {
    features: Vec<Value>,
}

impl PlanBuilder {
    fn new() -> Self {
        Self { features: Vec::new() }
    }

    fn wall(&mut self, name: &str, thickness: f64, points: &[[f64; 2]]) {
        self.features.push(json!({
            "type": "Feature",
            "properties": { "kind": "wall", "name": name, "thickness_m": thickness },
            "geometry": { "type": "LineString", "coordinates": points },
        }));
    }

    fn opening(&mut self, kind: &str, name: &str, a: [f64; 2], b: [f64; 2]) {
        self.features.push(json!({
            "type": "Feature",
            "properties": { "kind": kind, "name": name },
            "geometry": { "type": "LineString", "coordinates": [a, b] },
        }));
    }

    fn door(&mut self, name: &str, a: [f64; 2], b: [f64; 2]) {
        self.opening("door", name, a, b);
    }

    fn window(&mut self, name: &str, a: [f64; 2], b: [f64; 2]) {
        self.opening("window", name, a, b);
    }

    /// An axis-aligned rectangular room.
    fn room(&mut self, name: &str, x0: f64, y0: f64, x1: f64, y1: f64) {
        let ring = [[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]];
        self.features.push(json!({
            "type": "Feature",
            "properties": { "kind": "room", "name": name },
            "geometry": { "type": "Polygon", "coordinates": [ring] },
        }));
    }

    fn finish(self, name: &str) -> String {
        let doc = json!({
            "type": "FeatureCollection",
            "name": name,
            "properties": {
                "storey_height_m": 2.7,
                "door_head_height_m": 2.1,
                "window_sill_height_m": 0.9,
                "window_head_height_m": 2.1,
                "wall_thickness_m": INTERIOR_T,
            },
            "features": self.features,
        });
        serde_json::to_string_pretty(&doc).expect("a JSON value always serialises")
    }
}

/// LAB: one 25 m × 18 m room (437 m² inside the exterior walls' inner faces) with two bays off the
/// north wall, a partial wall off the south wall, an L-shaped partition off the east wall, a
/// free-standing partition and a thin pillar; three doors to the outside (not walked through) and
/// eight windows.
pub fn lab() -> String {
    let mut p = PlanBuilder::new();
    let h = EXTERIOR_T / 2.0;
    p.wall(
        "lab exterior",
        EXTERIOR_T,
        &[[0.0, 0.0], [25.0, 0.0], [25.0, 18.0], [0.0, 18.0], [0.0, 0.0]],
    );
    p.wall("bay wall west", PARTITION_T, &[[7.0, 18.0], [7.0, 13.0]]);
    p.wall("bay wall east", PARTITION_T, &[[14.0, 18.0], [14.0, 13.5]]);
    p.wall("south partial wall", PARTITION_T, &[[18.0, 0.0], [18.0, 4.5]]);
    p.wall(
        "east L partition",
        PARTITION_T,
        &[[25.0, 10.0], [21.5, 10.0], [21.5, 7.0]],
    );
    p.wall("free-standing partition", PARTITION_T, &[[9.0, 7.5], [14.0, 7.5]]);
    p.wall(
        "pillar",
        0.0,
        &[[4.0, 8.0], [4.6, 8.0], [4.6, 8.6], [4.0, 8.6], [4.0, 8.0]],
    );
    p.door("south door", [2.0, 0.0], [3.0, 0.0]);
    p.door("north double door", [20.0, 18.0], [21.5, 18.0]);
    p.door("west door", [0.0, 14.0], [0.0, 15.0]);
    for (i, (a, b)) in [
        ([6.0, 0.0], [9.0, 0.0]),
        ([11.0, 0.0], [14.0, 0.0]),
        ([20.0, 0.0], [23.0, 0.0]),
        ([25.0, 2.0], [25.0, 4.0]),
        ([25.0, 13.0], [25.0, 15.5]),
        ([2.0, 18.0], [5.0, 18.0]),
        ([9.0, 18.0], [12.0, 18.0]),
        ([0.0, 4.0], [0.0, 7.0]),
    ]
    .into_iter()
    .enumerate()
    {
        p.window(&format!("lab window {i}"), a, b);
    }
    p.room("lab", h, h, 25.0 - h, 18.0 - h);
    p.finish("LAB (Koch-Teller 2007, Table 2)")
}

/// One building of CORRIDOR: offices `office_w` wide on both sides of a corridor between
/// `y_south` and `y_north`, from x0 to x1 (x0 the exterior wall's axis or the fire wall's).
struct Wing {
    tag: &'static str,
    x0: f64,
    x1: f64,
    office_w: f64,
    y_south: f64,
    y_north: f64,
    /// Door offset from the office's west partition, and width.
    door_at: f64,
    door_w: f64,
    window_at: f64,
    window_w: f64,
}

/// Depth of the whole CORRIDOR building (exterior axes at y = 0 and y = 22).
const DEPTH: f64 = 22.0;

fn wing(p: &mut PlanBuilder, w: &Wing, west_inner: f64, east_inner: f64) {
    let h = EXTERIOR_T / 2.0;
    let n = ((w.x1 - w.x0) / w.office_w).round() as usize;
    p.wall(
        &format!("{} corridor south wall", w.tag),
        INTERIOR_T,
        &[[w.x0, w.y_south], [w.x1, w.y_south]],
    );
    p.wall(
        &format!("{} corridor north wall", w.tag),
        INTERIOR_T,
        &[[w.x0, w.y_north], [w.x1, w.y_north]],
    );
    for k in 1..n {
        let x = w.x0 + k as f64 * w.office_w;
        p.wall(
            &format!("{} partition {k} south", w.tag),
            INTERIOR_T,
            &[[x, 0.0], [x, w.y_south]],
        );
        p.wall(
            &format!("{} partition {k} north", w.tag),
            INTERIOR_T,
            &[[x, w.y_north], [x, DEPTH]],
        );
    }
    for k in 0..n {
        let xa = w.x0 + k as f64 * w.office_w;
        let xb = xa + w.office_w;
        let (ra, rb) = (
            if k == 0 { west_inner } else { xa },
            if k + 1 == n { east_inner } else { xb },
        );
        p.room(&format!("{} office {k}S", w.tag), ra, h, rb, w.y_south);
        p.room(&format!("{} office {k}N", w.tag), ra, w.y_north, rb, DEPTH - h);
        let d = [xa + w.door_at, xa + w.door_at + w.door_w];
        p.door(&format!("{} door {k}S", w.tag), [d[0], w.y_south], [d[1], w.y_south]);
        p.door(&format!("{} door {k}N", w.tag), [d[0], w.y_north], [d[1], w.y_north]);
        let g = [xa + w.window_at, xa + w.window_at + w.window_w];
        p.window(&format!("{} window {k}S", w.tag), [g[0], 0.0], [g[1], 0.0]);
        p.window(&format!("{} window {k}N", w.tag), [g[0], DEPTH], [g[1], DEPTH]);
    }
    p.room(
        &format!("{} corridor", w.tag),
        west_inner,
        w.y_south,
        east_inner,
        w.y_north,
    );
}

/// CORRIDOR: two adjoining office buildings, each 160 m × 22 m, under one exterior shell and
/// separated by a fire wall with a 1.6 m double door. Building A has 80 offices 4 m wide along a
/// 3 m corridor, building B 64 offices 5 m wide along a corridor offset 0.5 m north; every office
/// has the same 1 m door to the corridor (the repeated doorways of the paper's failure case) and
/// one window. Rooms total about 6,940 m².
pub fn corridor() -> String {
    let mut p = PlanBuilder::new();
    let h = EXTERIOR_T / 2.0;
    p.wall(
        "exterior",
        EXTERIOR_T,
        &[[0.0, 0.0], [320.0, 0.0], [320.0, DEPTH], [0.0, DEPTH], [0.0, 0.0]],
    );
    p.wall("fire wall", EXTERIOR_T, &[[160.0, 0.0], [160.0, DEPTH]]);
    p.door("fire door", [160.0, 10.45], [160.0, 12.05]);
    let a = Wing {
        tag: "A",
        x0: 0.0,
        x1: 160.0,
        office_w: 4.0,
        y_south: 9.5,
        y_north: 12.5,
        door_at: 0.8,
        door_w: 1.0,
        window_at: 1.0,
        window_w: 2.0,
    };
    // The fire wall is thick: rooms next to it are drawn to its axis all the same (it is interior).
    wing(&mut p, &a, h, 160.0);
    let b = Wing {
        tag: "B",
        x0: 160.0,
        x1: 320.0,
        office_w: 5.0,
        y_south: 10.0,
        y_north: 13.0,
        door_at: 1.0,
        door_w: 1.0,
        window_at: 1.0,
        window_w: 3.0,
    };
    wing(&mut p, &b, 160.0, 320.0 - h);
    p.finish("CORRIDOR (Koch-Teller 2007, Table 2)")
}
