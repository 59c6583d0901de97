//! Floor-plan extrusion (GeoJSON → OBJ) checked through the model loader: the segments the
//! tracker will match are exactly the wall corners, floor and ceiling lines and opening frames.
#![cfg(feature = "desk")]

use nalgebra::Point3;
use omnitrack::desk::floorplan::{extrude, parse};
use omnitrack::Model;

mod errors;

const EXAMPLE: &str = include_str!("../../../tools/plans/example_office.geojson");

fn load(geojson: &str) -> Model {
    let obj = extrude(geojson, "plan.geojson").unwrap_or_else(|e| panic!("extrude failed: {e}"));
    Model::from_obj_str(&obj, "plan.obj").unwrap_or_else(|e| panic!("OBJ does not load: {e}\n{obj}"))
}

fn p(x: f64, y: f64, z: f64) -> Point3<f64> {
    Point3::new(x, y, z)
}

/// Whether the model has a segment with these end points, in either order, within 1e-9.
fn has_segment(model: &Model, a: Point3<f64>, b: Point3<f64>) -> bool {
    let close = |u: &Point3<f64>, v: &Point3<f64>| (u - v).abs().max() <= 1e-9;
    model
        .segments
        .iter()
        .any(|s| (close(&s.a, &a) && close(&s.b, &b)) || (close(&s.a, &b) && close(&s.b, &a)))
}

#[track_caller]
fn assert_segment(model: &Model, a: Point3<f64>, b: Point3<f64>) {
    assert!(
        has_segment(model, a, b),
        "no segment {a} – {b}; segments:\n{}",
        list(model)
    );
}

fn list(model: &Model) -> String {
    let mut v: Vec<String> = model
        .segments
        .iter()
        .map(|s| format!("({}, {}, {}) – ({}, {}, {})", s.a.x, s.a.y, s.a.z, s.b.x, s.b.y, s.b.z))
        .collect();
    v.sort();
    v.join("\n")
}

/// Every segment of an axis-aligned plan runs along x, y or z; a triangulation diagonal or any
/// other stray line would not.
#[track_caller]
fn assert_axis_parallel(model: &Model) {
    for s in &model.segments {
        let d = s.b - s.a;
        let off_axis = d.iter().filter(|c| c.abs() > 1e-9).count();
        assert_eq!(off_axis, 1, "segment {} – {} is not parallel to an axis", s.a, s.b);
    }
}

#[track_caller]
fn assert_clean(model: &Model) {
    assert_eq!(model.stats.degenerate_faces, 0);
    assert_eq!(model.stats.nonplanar_faces, 0);
}

fn faces_with_material(model: &Model, material: &str) -> usize {
    model
        .faces
        .iter()
        .filter(|f| model.label(f.material) == material)
        .count()
}

/// A FeatureCollection of 2.5 m storeys around the given features.
fn plan(features: &str) -> String {
    format!(r#"{{"type": "FeatureCollection", "properties": {{"storey_height_m": 2.5}}, "features": [{features}]}}"#)
}

fn feature(kind: &str, extra: &str, geometry: &str, coordinates: &str) -> String {
    format!(
        r#"{{"type": "Feature", "properties": {{"kind": "{kind}"{extra}}}, "geometry": {{"type": "{geometry}", "coordinates": {coordinates}}}}}"#
    )
}

// ---------------------------------------------------------------------------------------------
// The example plan.

/// tools/plans/example_office.geojson, storey 2.7 m, doors 0–2.1 m, windows 0.9–2.1 m except
/// window C (1.2–2.1 m):
/// - a thin outer shell, the closed rectangle x 0..12, y 0..6;
/// - the corridor wall, axis y = 2 from x = 0 to 12, 0.2 m thick (faces y = 1.9 and y = 2.1),
///   its ends abutting the shell's axis, so it has no end caps; a top face at z = 2.7;
/// - two thin partitions x = 4 and x = 8 from the corridor wall's axis (trimmed to its face
///   y = 2.1) to the shell (y = 6);
/// - doors A, B, C in the corridor wall at x 1.5–2.4, 5.5–6.4, 9.5–10.4 (jamb, head and soffit
///   reveals, no sill);
/// - windows A, B, C in the shell's north side y = 6 at x 1–3, 5–7, 9–11 (thin: no reveals);
/// - rooms (floor z = 0, ceiling z = 2.7): the corridor x 0..12, y 0..2 and offices A, B, C
///   x 0..4, 4..8, 8..12, y 2..6, all drawn to wall axes.
///
/// Segments, by direction:
///
/// Vertical (z), 30:
/// -  4 shell corners (0,0) (12,0) (12,6) (0,6), 0–2.7: two panels at 90°;
/// -  4 corridor-wall face ends at (0,1.9) (0,2.1) (12,1.9) (12,2.1), 0–2.7: the thick wall's
///    face meets the shell panel, whose interior has no edge there;
/// -  4 partition ends: (4,2.1) (8,2.1) on the corridor wall's room face, (4,6) (8,6) on the
///    shell, 0–2.7;
/// - 12 door jambs, 0–2.1: 3 doors × 2 sides × 2 faces (y = 1.9 and 2.1), the wall face meeting
///   the jamb reveal; above 2.1 the panel beside the door and the panel over it are coplanar,
///   so that piece of the line vanishes;
/// -  6 window jambs on the thin shell, sill–2.1: 3 windows × 2 sides; below the sill and above
///    the head the panels are coplanar again.
///
/// Along x, 26:
/// -  2 on the shell's south side y = 0: floor line and ceiling line, each 0–12;
/// -  8 on the shell's north side y = 6: floor line 0–12, ceiling line 0–12 (the panels under
///    and over each window continue both), 3 window sills and 3 window heads;
/// -  8 on each corridor-wall face (y = 1.9, y = 2.1): 4 floor lines interrupted by the three
///    doors (0–1.5, 2.4–5.5, 6.4–9.5, 10.4–12; no door sill and the floor runs through), the
///    ceiling line 0–12, 3 door heads (face meets soffit) → 16;
/// -  0 on the axis y = 2: corridor and office floors (and ceilings) meet there from both
///    sides in one plane, hidden under the thick wall.
///
/// Along y, 20:
/// -  2 on the shell's west side x = 0 (floor line and ceiling line, 0–6) and 2 on its east
///    side x = 12;
/// -  2 per partition (x = 4, x = 8): floor and ceiling lines from y = 2.1 to 6; between 2 and
///    2.1 the two offices' floors (ceilings) meet in one plane under the corridor wall → 4;
/// - 12 in the doors: 3 doors × 2 jambs × (threshold line at z = 0, where the jamb reveal
///   stands on the floor's interior; and jamb-meets-soffit at 2.1), each y 1.9–2.1.
///
/// Total 30 + 26 + 20 = 76.
#[test]
fn example_plan_has_exactly_the_visible_lines() {
    let model = load(EXAMPLE);
    assert_clean(&model);
    assert_axis_parallel(&model);
    assert_eq!(model.segments.len(), 76, "segments:\n{}", list(&model));

    // Door A, x 1.5–2.4, in the 0.2 m corridor wall: jambs on both faces, head on both faces,
    // the jamb-soffit corner and the threshold corner.
    for y in [1.9, 2.1] {
        assert_segment(&model, p(1.5, y, 0.0), p(1.5, y, 2.1));
        assert_segment(&model, p(2.4, y, 0.0), p(2.4, y, 2.1));
        assert_segment(&model, p(1.5, y, 2.1), p(2.4, y, 2.1));
    }
    assert_segment(&model, p(1.5, 1.9, 2.1), p(1.5, 2.1, 2.1));
    assert_segment(&model, p(2.4, 1.9, 0.0), p(2.4, 2.1, 0.0));
    // Window A's sill, head and a jamb on the thin shell; window C's higher sill.
    assert_segment(&model, p(1.0, 6.0, 0.9), p(3.0, 6.0, 0.9));
    assert_segment(&model, p(1.0, 6.0, 2.1), p(3.0, 6.0, 2.1));
    assert_segment(&model, p(3.0, 6.0, 0.9), p(3.0, 6.0, 2.1));
    assert_segment(&model, p(9.0, 6.0, 1.2), p(11.0, 6.0, 1.2));
    // Floor corner lines: the corridor's south side, the west side of corridor and office A,
    // and the partition's foot starting at the corridor wall's face.
    assert_segment(&model, p(0.0, 0.0, 0.0), p(12.0, 0.0, 0.0));
    assert_segment(&model, p(0.0, 0.0, 0.0), p(0.0, 6.0, 0.0));
    assert_segment(&model, p(4.0, 2.1, 0.0), p(4.0, 6.0, 0.0));
    assert_segment(&model, p(0.0, 1.9, 0.0), p(1.5, 1.9, 0.0));
    // Ceiling line along the corridor wall's room face, unbroken over the doors.
    assert_segment(&model, p(0.0, 2.1, 2.7), p(12.0, 2.1, 2.7));
    // Vertical wall corners: a shell corner, the corridor wall's end against the shell, the
    // partition's end against the corridor wall.
    assert_segment(&model, p(12.0, 6.0, 0.0), p(12.0, 6.0, 2.7));
    assert_segment(&model, p(0.0, 1.9, 0.0), p(0.0, 1.9, 2.7));
    assert_segment(&model, p(4.0, 2.1, 0.0), p(4.0, 2.1, 2.7));
    // Nothing where floors meet under the thick wall, nothing reaching into it.
    assert!(!model
        .segments
        .iter()
        .any(|s| (s.a.y - 2.0).abs() < 1e-9 && (s.b.y - 2.0).abs() < 1e-9));
    assert!(!model
        .segments
        .iter()
        .any(|s| [s.a, s.b].iter().any(|q| q.y > 1.9 + 1e-9 && q.y < 2.1 - 1e-9)));

    // Groups and materials name every face.
    for f in &model.faces {
        assert!(!model.label(f.group).is_empty(), "face {} has no group", f.obj_number);
        let m = model.label(f.material);
        assert!(
            ["wall", "floor", "ceiling", "door_reveal", "window_reveal"].contains(&m),
            "material {m:?}"
        );
    }
    for name in [
        "wall_0",
        "wall_1",
        "door_4",
        "room_corridor_floor",
        "room_corridor_ceiling",
        "room_office_A_floor",
    ] {
        assert!(
            model.labels.iter().any(|l| l == name),
            "no group {name}: {:?}",
            model.labels
        );
    }
    assert_eq!(faces_with_material(&model, "floor"), 4);
    assert_eq!(faces_with_material(&model, "ceiling"), 4);
    // 3 doors × (2 jambs + soffit); the windows are in a thin wall.
    assert_eq!(faces_with_material(&model, "door_reveal"), 9);
    assert_eq!(faces_with_material(&model, "window_reveal"), 0);
    // Floors face up, ceilings down.
    for f in &model.faces {
        match model.label(f.material) {
            "floor" => assert!(f.normal.z > 0.999),
            "ceiling" => assert!(f.normal.z < -0.999),
            _ => {}
        }
    }
}

#[test]
fn example_plan_parses_as_described() {
    let plan = parse(EXAMPLE, "example").unwrap();
    assert_eq!((plan.walls.len(), plan.openings.len(), plan.rooms.len()), (4, 6, 4));
    assert!(plan.walls[0].closed);
    assert_eq!(plan.walls[0].axis.len(), 4);
    assert_eq!(plan.walls[1].thickness_m, 0.2);
    assert!(plan.walls.iter().filter(|w| w.thickness_m > 0.0).count() == 1);
    assert_eq!(plan.defaults.storey_height_m, 2.7);
    assert_eq!(plan.openings[5].sill_height_m, 1.2);
    assert_eq!(plan.openings[3].sill_height_m, 0.9);
}

#[test]
fn obj_has_a_header_and_is_deterministic() {
    let a = extrude(EXAMPLE, "example_office.geojson").unwrap();
    assert!(a.starts_with("# "), "{}", &a[..80]);
    assert!(a.lines().next().unwrap().contains("example_office.geojson"));
    assert_eq!(a, extrude(EXAMPLE, "example_office.geojson").unwrap());
}

// ---------------------------------------------------------------------------------------------
// Tiny plans.

#[test]
fn thin_wall_with_a_door() {
    // A 4 m thin wall, 2.5 m high, a door x 1–2 with its head at 2 m: panels 0–1 (full),
    // 1–2 (over the door, 2–2.5), 2–4 (full).
    let model = load(&plan(
        &[
            feature("wall", "", "LineString", "[[0, 0], [4, 0]]"),
            feature("door", r#", "head_height_m": 2.0"#, "LineString", "[[1, 0], [2, 0]]"),
        ]
        .join(","),
    ));
    assert_clean(&model);
    assert_eq!(model.faces.len(), 3);
    let expected = [
        (p(0.0, 0.0, 0.0), p(1.0, 0.0, 0.0)), // foot, broken by the door
        (p(2.0, 0.0, 0.0), p(4.0, 0.0, 0.0)),
        (p(0.0, 0.0, 2.5), p(4.0, 0.0, 2.5)), // top, unbroken
        (p(0.0, 0.0, 0.0), p(0.0, 0.0, 2.5)), // free ends
        (p(4.0, 0.0, 0.0), p(4.0, 0.0, 2.5)),
        (p(1.0, 0.0, 0.0), p(1.0, 0.0, 2.0)), // jambs, up to the head only
        (p(2.0, 0.0, 0.0), p(2.0, 0.0, 2.0)),
        (p(1.0, 0.0, 2.0), p(2.0, 0.0, 2.0)), // head
    ];
    assert_eq!(model.segments.len(), expected.len(), "segments:\n{}", list(&model));
    for (a, b) in expected {
        assert_segment(&model, a, b);
    }
}

#[test]
fn thick_wall_with_a_window_has_reveals() {
    // A 4 m wall 0.2 m thick (faces y = ±0.1), 2.5 m high, window x 1–3, sill 1, head 2: a closed
    // box with a hole: faces, caps, top, and the window's two jambs, soffit and sill.
    let model = load(&plan(
        &[
            feature("wall", r#", "thickness_m": 0.2"#, "LineString", "[[0, 0], [4, 0]]"),
            feature(
                "window",
                r#", "sill_height_m": 1.0, "head_height_m": 2.0"#,
                "LineString",
                "[[1, 0], [3, 0]]",
            ),
        ]
        .join(","),
    ));
    assert_clean(&model);
    assert_axis_parallel(&model);
    // Vertical: 4 box corners + 2 jambs × 2 faces = 8. Along x: per face foot, top, sill line,
    // head line = 8. Along y: foot and top of both caps = 4, jamb-sill and jamb-soffit corners of
    // both jambs = 4. No bottom faces, so the feet are single-face edges and still corners.
    assert_eq!(model.segments.len(), 24, "segments:\n{}", list(&model));
    assert_eq!(faces_with_material(&model, "window_reveal"), 4);
    for y in [-0.1, 0.1] {
        assert_segment(&model, p(1.0, y, 1.0), p(3.0, y, 1.0)); // sill meets face
        assert_segment(&model, p(1.0, y, 2.0), p(3.0, y, 2.0)); // soffit meets face
        assert_segment(&model, p(1.0, y, 1.0), p(1.0, y, 2.0)); // jamb meets face
        assert_segment(&model, p(3.0, y, 1.0), p(3.0, y, 2.0));
        assert_segment(&model, p(0.0, y, 0.0), p(0.0, y, 2.5)); // box corner
    }
    assert_segment(&model, p(1.0, -0.1, 1.0), p(1.0, 0.1, 1.0)); // jamb meets sill
    assert_segment(&model, p(3.0, -0.1, 2.0), p(3.0, 0.1, 2.0)); // jamb meets soffit
    assert_segment(&model, p(4.0, -0.1, 2.5), p(4.0, 0.1, 2.5)); // cap meets top
                                                                 // The sill faces up and the soffit down.
    let reveal_normals: Vec<f64> = model
        .faces
        .iter()
        .filter(|f| model.label(f.material) == "window_reveal" && f.normal.z.abs() > 0.5)
        .map(|f| f.normal.z)
        .collect();
    assert_eq!(reveal_normals.len(), 2);
}

#[test]
fn t_junction_is_trimmed_to_the_face_and_has_no_cap() {
    // Thick wall A on y = 0 (faces ±0.1); wall B from A's axis at x = 2 up to y = 3, thin or
    // 0.2 m thick.
    for (thickness, extra_faces) in [(0.0, 1), (0.2, 3)] {
        let model = load(&plan(
            &[
                feature("wall", r#", "thickness_m": 0.2"#, "LineString", "[[0, 0], [4, 0]]"),
                feature(
                    "wall",
                    &format!(r#", "thickness_m": {thickness}"#),
                    "LineString",
                    "[[2, 0], [2, 3]]",
                ),
            ]
            .join(","),
        ));
        assert_clean(&model);
        assert_axis_parallel(&model);
        // A: 2 faces, 2 caps, top. B: one face, or 2 faces and the far cap (no near cap) and top.
        assert_eq!(model.faces.len(), 5 + extra_faces + usize::from(thickness > 0.0));
        let b = model.labels.iter().position(|l| l == "wall_1").unwrap() as u32;
        for f in model.faces.iter().filter(|f| f.group == b) {
            for &v in &f.vertices {
                let q = model.vertices[v as usize];
                assert!(q.y >= 0.1 - 1e-9, "wall B reaches into wall A: {q}");
            }
            assert!(f.normal.y > -0.5, "wall B has a cap facing wall A");
        }
        let h = thickness / 2.0;
        for x in [2.0 - h, 2.0 + h] {
            assert_segment(&model, p(x, 0.1, 0.0), p(x, 0.1, 2.5)); // B's end against A's face
            assert_segment(&model, p(x, 0.1, 0.0), p(x, 3.0, 0.0));
        }
        // A's face y = 0.1 keeps its foot and top lines whole: B's end makes no break in them.
        assert_segment(&model, p(0.0, 0.1, 0.0), p(4.0, 0.1, 0.0));
        assert_segment(&model, p(0.0, 0.1, 2.5), p(4.0, 0.1, 2.5));
        // A's other face y = -0.1 is untouched.
        assert_segment(&model, p(0.0, -0.1, 0.0), p(4.0, -0.1, 0.0));
    }
}

#[test]
fn thick_polyline_is_mitred_and_closed_ring_has_no_caps() {
    // An L: (0,0) → (4,0) → (4,3), 0.2 thick. The outer corner is at (4.1, -0.1), the inner at
    // (3.9, 0.1).
    let model = load(&plan(&feature(
        "wall",
        r#", "thickness_m": 0.2"#,
        "LineString",
        "[[0, 0], [4, 0], [4, 3]]",
    )));
    assert_clean(&model);
    assert_segment(&model, p(4.1, -0.1, 0.0), p(4.1, -0.1, 2.5));
    assert_segment(&model, p(3.9, 0.1, 0.0), p(3.9, 0.1, 2.5));
    assert_segment(&model, p(0.0, -0.1, 0.0), p(4.1, -0.1, 0.0));
    assert_segment(&model, p(4.1, -0.1, 0.0), p(4.1, 3.0, 0.0));
    // Corners 2 + free-end corners 4; feet and tops of 4 faces 8, of 2 caps 4. The mitre seam
    // of the top is coplanar: no segment.
    assert_eq!(model.segments.len(), 18, "segments:\n{}", list(&model));

    // A closed square ring, 0.2 thick: 8 vertical corners, 8 feet, 8 tops; no caps.
    let model = load(&plan(&feature(
        "wall",
        r#", "thickness_m": 0.2"#,
        "LineString",
        "[[0, 0], [4, 0], [4, 4], [0, 4], [0, 0]]",
    )));
    assert_clean(&model);
    assert_eq!(model.segments.len(), 24, "segments:\n{}", list(&model));
    assert_segment(&model, p(-0.1, -0.1, 0.0), p(-0.1, -0.1, 2.5));
    assert_segment(&model, p(0.1, 0.1, 2.5), p(3.9, 0.1, 2.5));
}

#[test]
fn room_floor_and_ceiling() {
    // An L-shaped room, written clockwise, with a name that needs cleaning for OBJ.
    let model = load(&plan(&feature(
        "room",
        r#", "name": "Lab 2", "floor_m": 0.1, "ceiling_m": 3"#,
        "Polygon",
        "[[[0, 0], [0, 3], [2, 3], [2, 1], [4, 1], [4, 0], [0, 0]]]",
    )));
    assert_clean(&model);
    assert_eq!(model.faces.len(), 2);
    assert!(model.labels.iter().any(|l| l == "room_Lab_2_floor"));
    assert!(model.labels.iter().any(|l| l == "room_Lab_2_ceiling"));
    let floor = model.faces.iter().find(|f| model.label(f.material) == "floor").unwrap();
    assert!(floor.normal.z > 0.999 && (floor.offset - 0.1).abs() < 1e-12);
    // 6 edges of each polygon: 12 segments, none a diagonal.
    assert_eq!(model.segments.len(), 12);
    assert_axis_parallel(&model);
    assert_segment(&model, p(2.0, 3.0, 3.0), p(2.0, 1.0, 3.0));
}

// ---------------------------------------------------------------------------------------------
// Random plans: whatever the input, an error or an OBJ the loader takes without repairs.

#[test]
fn random_grid_plans_extrude_cleanly_or_fail_in_one_line() {
    use rand::{rngs::SmallRng, Rng, SeedableRng};
    let mut rng = SmallRng::seed_from_u64(7);
    let mut extruded = 0;
    for _ in 0..1500 {
        // Walls on a 1 m grid, turning by ±90° (some closed), thin or thick; openings on them;
        // maybe a room.
        let mut features = Vec::new();
        let mut axes: Vec<Vec<(f64, f64)>> = Vec::new();
        for _ in 0..rng.random_range(1..5) {
            let mut at = (rng.random_range(0..6) as f64, rng.random_range(0..6) as f64);
            let mut axis = vec![at];
            let mut dir: usize = rng.random_range(0..4);
            for _ in 0..rng.random_range(1..4) {
                let (dx, dy) = [(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0)][dir];
                let l = rng.random_range(1..5) as f64;
                at = (at.0 + l * dx, at.1 + l * dy);
                axis.push(at);
                dir = (dir + [1, 3][rng.random_range(0..2)]) % 4;
            }
            let (first, last) = (axis[0], axis[axis.len() - 1]);
            if axis.len() >= 3 && (first.0 == last.0 || first.1 == last.1) && rng.random_bool(0.2) {
                axis.push(first);
            }
            let t = [0.0, 0.0, 0.2, 0.3][rng.random_range(0..4)];
            let coords: Vec<String> = axis.iter().map(|(x, y)| format!("[{x}, {y}]")).collect();
            features.push(feature(
                "wall",
                &format!(r#", "thickness_m": {t}"#),
                "LineString",
                &format!("[{}]", coords.join(",")),
            ));
            axes.push(axis);
        }
        for _ in 0..rng.random_range(0..4) {
            let axis = &axes[rng.random_range(0..axes.len())];
            let k = rng.random_range(0..axis.len() - 1);
            let (a, b) = (axis[k], axis[k + 1]);
            let t0 = rng.random_range(0.05..0.6);
            let t1 = t0 + rng.random_range(0.05..0.35);
            let at = |t: f64| format!("[{}, {}]", a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1));
            let (kind, heights) = if rng.random_bool(0.5) {
                (
                    "door",
                    format!(r#", "head_height_m": {}"#, [2.1, 2.7, 2.0][rng.random_range(0..3)]),
                )
            } else {
                (
                    "window",
                    format!(r#", "sill_height_m": {}"#, [0.0, 0.9, 0.5][rng.random_range(0..3)]),
                )
            };
            features.push(feature(
                kind,
                &heights,
                "LineString",
                &format!("[{}, {}]", at(t0), at(t1)),
            ));
        }
        if rng.random_bool(0.5) {
            let (x0, y0) = (rng.random_range(0..4), rng.random_range(0..4));
            let (x1, y1) = (x0 + rng.random_range(1..4), y0 + rng.random_range(1..4));
            let ring = format!("[[[{x0}, {y0}], [{x1}, {y0}], [{x1}, {y1}], [{x0}, {y1}], [{x0}, {y0}]]]");
            features.push(feature("room", "", "Polygon", &ring));
        }
        let geojson = plan(&features.join(","));
        match extrude(&geojson, "random.geojson") {
            Err(e) => {
                let message = e.to_string();
                assert!(
                    message.starts_with("random.geojson: features[") && !message.contains('\n'),
                    "{message}"
                );
            }
            Ok(obj) => {
                extruded += 1;
                let model = Model::from_obj_str(&obj, "random.obj").unwrap();
                assert_eq!(
                    model.stats.degenerate_faces + model.stats.nonplanar_faces,
                    0,
                    "{geojson}"
                );
                assert_eq!(model.stats.welded_vertices, 0, "{geojson}");
                assert_axis_parallel(&model);
            }
        }
    }
    // Most plans are fine: the generator is not just exercising error paths.
    assert!(extruded > 500, "only {extruded} random plans extruded");
}
