//! The walked ground storey as a GeoJSON floor plan for [`crate::floorplan`]: a [`Layout`] in,
//! the plan's text out. Its walls are the model's wall runs with their thicknesses and ground
//! doors; the stair is a wall as wide as the stair, so that walks keep clear of it.

use super::layout::Layout;
use super::STAIR_WIDTH_M;
use serde_json::{json, Value};

pub(super) fn plan_geojson(layout: &Layout, seed: u64) -> String {
    let Layout { height, stair_axis, .. } = *layout;
    let (runs, rects) = (&layout.runs, &layout.rects);
    let mut features: Vec<Value> = Vec::new();
    for (k, r) in runs.iter().enumerate() {
        features.push(json!({
            "type": "Feature",
            "properties": { "kind": "wall", "name": format!("wall {k}"), "thickness_m": r.thickness },
            "geometry": { "type": "LineString", "coordinates": [[r.a.x, r.a.y], [r.b.x, r.b.y]] },
        }));
        let u = (r.b - r.a) / (r.b - r.a).norm();
        for (d, &(s0, s1)) in r.doors.iter().enumerate() {
            let (p, q) = (r.a + u * s0, r.a + u * s1);
            features.push(json!({
                "type": "Feature",
                "properties": { "kind": "door", "name": format!("wall {k} door {d}") },
                "geometry": { "type": "LineString", "coordinates": [[p.x, p.y], [q.x, q.y]] },
            }));
        }
    }
    if let Some((a, b)) = stair_axis {
        features.push(json!({
            "type": "Feature",
            "properties": { "kind": "wall", "name": "stair", "thickness_m": STAIR_WIDTH_M },
            "geometry": { "type": "LineString", "coordinates": [[a.x, a.y], [b.x, b.y]] },
        }));
    }
    for (k, (lo, hi)) in rects.iter().enumerate() {
        features.push(json!({
            "type": "Feature",
            "properties": { "kind": "room", "name": format!("room {k}") },
            "geometry": { "type": "Polygon", "coordinates": [[
                [lo.x, lo.y], [hi.x, lo.y], [hi.x, hi.y], [lo.x, hi.y], [lo.x, lo.y]
            ]] },
        }));
    }
    let plan = json!({
        "type": "FeatureCollection",
        "name": format!("random building {seed}"),
        "properties": { "storey_height_m": height },
        "features": features,
    });
    serde_json::to_string_pretty(&plan).expect("a JSON value always serialises")
}
