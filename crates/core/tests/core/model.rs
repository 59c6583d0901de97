//! Model loading and segment extraction on small scenes with known answers, and bad input.

use nalgebra::Point3;
use omnitrack_core::model::{Model, Segment};

fn load(obj: &str) -> Model {
    Model::from_obj_str(obj, "test.obj").unwrap_or_else(|e| panic!("{e}"))
}

fn has_segment(m: &Model, a: [f64; 3], b: [f64; 3]) -> bool {
    let (a, b) = (Point3::from(a), Point3::from(b));
    m.segments.iter().any(|s| {
        ((s.a - a).norm() < 1e-9 && (s.b - b).norm() < 1e-9) || ((s.a - b).norm() < 1e-9 && (s.b - a).norm() < 1e-9)
    })
}

fn axis_aligned(s: &Segment) -> bool {
    let d = s.b - s.a;
    [d.x, d.y, d.z].iter().filter(|c| c.abs() > 1e-12).count() == 1
}

/// A 2 × 1 × 0.5 box as 12 triangles (every face split by a diagonal).
const BOX: &str = "
o box
v 0 0 0
v 2 0 0
v 2 1 0
v 0 1 0
v 0 0 0.5
v 2 0 0.5
v 2 1 0.5
v 0 1 0.5
f 1 3 2
f 1 4 3
f 5 6 7
f 5 7 8
f 1 2 6
f 1 6 5
f 2 3 7
f 2 7 6
f 3 4 8
f 3 8 7
f 4 1 5
f 4 5 8
";

#[test]
fn triangulated_box_has_exactly_its_12_edges() {
    let m = load(BOX);
    assert_eq!(m.faces.len(), 12);
    assert_eq!(m.segments.len(), 12, "{:#?}", m.segments);
    assert!(m.segments.iter().all(axis_aligned), "a diagonal survived");
    for s in &m.segments {
        assert_eq!(
            s.faces.len(),
            2,
            "each box edge bounds one triangle of each of its two sides"
        );
    }
    let mut lengths: Vec<f64> = m.segments.iter().map(Segment::length).collect();
    lengths.sort_by(f64::total_cmp);
    assert_eq!(lengths, [0.5, 0.5, 0.5, 0.5, 1.0, 1.0, 1.0, 1.0, 2.0, 2.0, 2.0, 2.0]);
    assert!(has_segment(&m, [0.0, 0.0, 0.0], [2.0, 0.0, 0.0]));
    assert!(has_segment(&m, [2.0, 1.0, 0.0], [2.0, 1.0, 0.5]));
}

#[test]
fn unwelded_box_with_negative_indices_and_texture_slots_gives_the_same_segments() {
    // Every triangle has its own three vertices (as many exporters write), referenced relatively.
    let welded = load(BOX);
    let mut obj = String::new();
    for line in BOX.lines().filter(|l| l.starts_with("f ")) {
        for i in line[2..].split_whitespace() {
            let v = BOX
                .lines()
                .filter(|l| l.starts_with("v "))
                .nth(i.parse::<usize>().unwrap() - 1)
                .unwrap();
            obj.push_str(v);
            obj.push('\n');
        }
        obj.push_str("vt 0 0\nvn 0 0 1\nf -3/1/1 -2/1/1 -1//1\n");
    }
    let m = load(&obj);
    assert_eq!(m.stats.welded_vertices, 36 - 8);
    assert_eq!(m.stats.ignored_records, 24, "vt and vn records are counted, not used");
    assert_eq!(m.segments.len(), 12);
    for s in &welded.segments {
        assert!(has_segment(&m, s.a.into(), s.b.into()));
    }
}

/// A 4 × 3 × 2.5 room with a 1 m × 2.1 m door in its y = 0 wall, every face triangulated; the
/// door wall is a notched polygon cut into 6 triangles.
const ROOM_WITH_DOOR: &str = "
v 0 0 0
v 4 0 0
v 4 3 0
v 0 3 0
v 0 0 2.5
v 4 0 2.5
v 4 3 2.5
v 0 3 2.5
v 1.5 0 0
v 2.5 0 0
v 1.5 0 2.1
v 2.5 0 2.1
g floor
usemtl floor
f 1 2 3
f 1 3 4
g ceiling
usemtl ceiling
f 5 7 6
f 5 8 7
g walls
usemtl wall
f 2 3 7
f 2 7 6
f 3 4 8
f 3 8 7
f 4 1 5
f 4 5 8
# the door wall: left of the door, over it, right of it
f 1 9 11
f 1 11 5
f 5 11 12
f 5 12 6
f 12 10 2
f 12 2 6
";

#[test]
fn room_with_a_door_has_its_frame_and_no_diagonals() {
    let m = load(ROOM_WITH_DOOR);
    assert!(
        m.segments.iter().all(axis_aligned),
        "a diagonal survived: {:#?}",
        m.segments
    );
    // The door frame: two jambs and the head.
    assert!(has_segment(&m, [1.5, 0.0, 0.0], [1.5, 0.0, 2.1]));
    assert!(has_segment(&m, [2.5, 0.0, 0.0], [2.5, 0.0, 2.1]));
    assert!(has_segment(&m, [1.5, 0.0, 2.1], [2.5, 0.0, 2.1]));
    // The floor's edge under the door continues the wall–floor line: one segment, end to end.
    assert!(has_segment(&m, [0.0, 0.0, 0.0], [4.0, 0.0, 0.0]));
    // 12 room edges + 3 door frame segments.
    assert_eq!(m.segments.len(), 15, "{:#?}", m.segments);
    let head = m
        .segments
        .iter()
        .find(|s| (s.a.z - 2.1).abs() < 1e-12 && (s.b.z - 2.1).abs() < 1e-12)
        .unwrap();
    assert!(head
        .faces
        .iter()
        .all(|&f| m.label(m.faces[f as usize].material) == "wall"));
    assert_eq!(m.label(m.faces[0].group), "floor");
    assert_eq!(m.faces.last().unwrap().obj_number, 16);
}

#[test]
fn t_junctions_and_coplanar_seams() {
    // A 2 × 1 floor and a wall on its y = 0 edge made of two panels meeting at x = 1: the floor's
    // single edge meets two wall edges (a T-junction at x = 1), and the panel seam is flat.
    let m = load(
        "v 0 0 0\nv 2 0 0\nv 2 1 0\nv 0 1 0\nv 1 0 0\nv 0 0 2\nv 1 0 2\nv 2 0 2\n\
         f 1 2 3 4\nf 1 5 7 6\nf 5 2 8 7\n",
    );
    assert!(has_segment(&m, [0.0, 0.0, 0.0], [2.0, 0.0, 0.0]));
    assert!(
        has_segment(&m, [0.0, 0.0, 2.0], [2.0, 0.0, 2.0]),
        "collinear top edges merge"
    );
    assert!(
        !m.segments
            .iter()
            .any(|s| (s.a.x - 1.0).abs() < 1e-12 && (s.b.x - 1.0).abs() < 1e-12),
        "seam kept"
    );
    assert_eq!(m.segments.len(), 7, "{:#?}", m.segments);
    let junction = m
        .segments
        .iter()
        .find(|s| s.a.z == 0.0 && s.b.z == 0.0 && s.a.y == 0.0 && s.b.y == 0.0)
        .unwrap();
    assert_eq!(junction.faces, [0, 1, 2]);
}

#[test]
fn two_sided_wall_has_only_its_border() {
    // One wall written twice with opposite windings, each side triangulated.
    let m = load("v 0 0 0\nv 3 0 0\nv 3 0 2\nv 0 0 2\nf 1 2 3\nf 1 3 4\nf 1 3 2\nf 1 4 3\n");
    assert_eq!(m.segments.len(), 4, "{:#?}", m.segments);
    assert!(m.segments.iter().all(axis_aligned));
}

#[test]
fn free_line_segments_merge_and_occlude_nothing() {
    let m = load("v 0 0 1\nv 1 0 1\nv 3 0 1\nv 3 2 1\nl 1 2 3 4\n");
    assert_eq!(m.faces.len(), 0);
    assert_eq!(m.segments.len(), 2);
    assert!(has_segment(&m, [0.0, 0.0, 1.0], [3.0, 0.0, 1.0]));
    assert!(m.segments.iter().all(Segment::is_free));
}

#[test]
fn degenerate_faces_are_skipped_and_counted_and_numbers_kept() {
    let m = load(
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 2 0 0\n\
         f 1 1 2\nf 1 2 4\nf 1 2\nf 1 2 3\n",
    );
    assert_eq!(m.stats.degenerate_faces, 3);
    assert_eq!(m.faces.len(), 1);
    assert_eq!(m.faces[0].obj_number, 4);
    assert_eq!(m.segments.len(), 3);
}

#[test]
fn non_planar_face_is_split_and_its_crease_kept() {
    let m = load("v 0 0 0\nv 1 0 0\nv 1 1 0.5\nv 0 1 0\nf 1 2 3 4\n");
    assert_eq!(m.stats.nonplanar_faces, 1);
    assert_eq!(m.faces.len(), 2);
    assert_eq!(m.segments.len(), 5, "four borders and the fold");
    assert!(has_segment(&m, [0.0, 0.0, 0.0], [1.0, 1.0, 0.5]));
}

fn error_of(obj: &str) -> String {
    Model::from_obj_str(obj, "bad.obj").unwrap_err().to_string()
}

#[test]
fn malformed_files_name_the_line_and_the_problem() {
    let cases: [(&str, &str); 8] = [
        ("v 0 0 0\nv 1 2\n", "bad.obj:2: vertex needs 3 coordinates, found 2"),
        (
            "v 0 0 0\nv 1 x 0\n",
            "bad.obj:2: vertex coordinate 'x' is not a finite number",
        ),
        (
            "v 0 0 0\nv inf 0 0\n",
            "bad.obj:2: vertex coordinate 'inf' is not a finite number",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 q\n",
            "bad.obj:4: 'q' is not a vertex index",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n",
            "bad.obj:4: vertex index 0 is invalid",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\n\nf 1 2 9\n",
            "bad.obj:5: vertex index 9 is beyond the 3 vertices",
        ),
        (
            "v 0 0 0\nf -1 -2 -3\n",
            "bad.obj:2: relative index -2 reaches before the first vertex",
        ),
        ("v 0 0 0\nl 1\n", "bad.obj:2: line record needs at least 2 vertices"),
    ];
    for (obj, expected) in cases {
        let e = error_of(obj);
        assert!(e.starts_with(expected), "{e:?} should start with {expected:?}");
        assert!(!e.contains('\n'));
    }
    let missing = Model::load(std::path::Path::new("/no/such/model.obj"))
        .unwrap_err()
        .to_string();
    assert!(
        missing.starts_with("/no/such/model.obj: cannot read model"),
        "{missing}"
    );
}

#[test]
fn forward_references_and_continuation_lines_are_accepted() {
    let m = load("f 1 2 \\\n 3\nv 0 0 0\nv 1 0 0\nv 0 1 0\n");
    assert_eq!(m.faces.len(), 1);
    assert_eq!(m.segments.len(), 3);
}

#[test]
fn seams_on_45_degree_lines_vanish_even_without_shared_vertices() {
    // Face B's edge lies inside face A's edge (a T-junction on both ends) on a 45° line, where
    // rounding decides which direction component is "largest".
    let m = load("v 0.1 0.5 0\nv 0.4 0.2 0\nv 0.4 0.5 0\nv 0.2 0.4 0\nv 0.3 0.3 0\nv 0.1 0.2 0\nf 1 2 3\nf 5 4 6\n");
    assert!(has_segment(&m, [0.1, 0.5, 0.0], [0.2, 0.4, 0.0]), "{:#?}", m.segments);
    assert!(has_segment(&m, [0.3, 0.3, 0.0], [0.4, 0.2, 0.0]), "{:#?}", m.segments);
    assert!(!has_segment(&m, [0.2, 0.4, 0.0], [0.3, 0.3, 0.0]), "the seam survived");
    assert_eq!(m.segments.len(), 2 + 2 + 2, "{:#?}", m.segments);
}

#[test]
fn lines_a_tenth_of_a_micron_apart_are_one_line_across_rounding_boundaries() {
    for y in [0.00005, 0.00015, 0.000051234] {
        let y2 = y - 1e-7;
        let obj = format!("v 0 {y} 0\nv 4 {y} 0\nv 4 1 0\nv 1 {y2} 0\nv 2 {y2} 0\nv 1.5 -1 0\nf 1 2 3\nf 5 4 6\n");
        let m = load(&obj);
        // The seam between x = 1 and x = 2 is flat; only the outer pieces of A's edge remain.
        let on_seam = m
            .segments
            .iter()
            .filter(|s| s.a.y.abs() < 1e-3 && s.b.y.abs() < 1e-3)
            .count();
        assert_eq!(on_seam, 2, "y = {y}: {:#?}", m.segments);
    }
}

/// Coordinates past ±1e9 m are refused with the line; 1e155 used to overflow the stack (the face
/// geometry's squares became infinite and a triangle was split for ever). A georeferenced model
/// (UTM northings of millions of metres) loads.
#[test]
fn coordinates_beyond_any_building_are_refused_and_georeferenced_ones_load() {
    let far = "v 0 0 0\nv 1e155 0 0\nv 0 1e155 0\nf 1 2 3\n";
    let e = Model::from_obj_str(far, "far.obj").unwrap_err().to_string();
    assert!(e.starts_with("far.obj:2: vertex coordinate '1e155' is beyond"), "{e}");
    let utm = "v 500000 5400000 300\nv 500010 5400000 300\nv 500010 5400010 300\nv 500000 5400010 300\nf 1 2 3 4\n";
    let m = Model::from_obj_str(utm, "utm.obj").unwrap();
    assert_eq!((m.faces.len(), m.segments.len()), (1, 4));
}
