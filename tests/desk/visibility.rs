//! The prior visibility table (Koch–Teller §4.3): closed room, two rooms joined by a door, a
//! pillar occluding a wall, nodes inside walls and outside the building excluded, the file
//! round trip, the model-hash mismatch error and the query JSON; and models as other tools draw
//! them (issue 20): winding flipped at random, single-face walls, duplicated faces, two
//! storeys.
#![cfg(feature = "desk")]

use nalgebra::{Point3, Vector3};
use omnitrack::visibility::build::{build_raw, build_table, BuildOptions, CubeMap, Merge, Occluders};
use omnitrack::visibility::{query_json, VisibilityError, VisibilityTable};
use omnitrack::Model;

/// OBJ text from polygons given with the side they are seen from.
#[derive(Default)]
struct Obj {
    text: String,
    vertices: usize,
    /// When set, each polygon is wound one way or the other by this generator's next bit
    /// instead of about its visible side (xorshift; winding carries no meaning).
    flips: Option<u64>,
}

impl Obj {
    /// A planar polygon, oriented counter-clockwise about `visible` (the side it is seen from).
    fn poly(&mut self, corners: &[[f64; 3]], visible: [f64; 3]) {
        let mut n = Vector3::zeros();
        for i in 0..corners.len() {
            let (a, b) = (corners[i], corners[(i + 1) % corners.len()]);
            n += Vector3::new(
                (a[1] - b[1]) * (a[2] + b[2]),
                (a[2] - b[2]) * (a[0] + b[0]),
                (a[0] - b[0]) * (a[1] + b[1]),
            );
        }
        let mut order: Vec<usize> = (0..corners.len()).collect();
        let reverse = match &mut self.flips {
            Some(x) => {
                *x ^= *x << 13;
                *x ^= *x >> 7;
                *x ^= *x << 17;
                *x & 1 == 1
            }
            None => n.dot(&Vector3::from(visible)) < 0.0,
        };
        if reverse {
            order.reverse();
        }
        let mut f = String::from("f");
        for &i in &order {
            let c = corners[i];
            self.text.push_str(&format!("v {} {} {}\n", c[0], c[1], c[2]));
            self.vertices += 1;
            let _ = i;
            f.push_str(&format!(" {}", self.vertices));
        }
        // Vertices are written in `order`, so the face lists them 1..n in that order.
        self.text.push_str(&f);
        self.text.push('\n');
    }

    /// An axis-aligned rectangle in the plane `axis = at`, spanning [lo, hi] on the other two
    /// axes (in cyclic order axis+1, axis+2), seen from direction `sign` along `axis`.
    fn rect(&mut self, axis: usize, at: f64, lo: [f64; 2], hi: [f64; 2], sign: f64) {
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        let p = |a: f64, b: f64| {
            let mut c = [0.0; 3];
            c[axis] = at;
            c[u] = a;
            c[v] = b;
            c
        };
        let mut n = [0.0; 3];
        n[axis] = sign;
        self.poly(&[p(lo[0], lo[1]), p(hi[0], lo[1]), p(hi[0], hi[1]), p(lo[0], hi[1])], n);
    }

    /// A closed box room seen from inside: floor, ceiling and four walls.
    fn room(&mut self, lo: [f64; 3], hi: [f64; 3]) {
        self.rect(2, lo[2], [lo[0], lo[1]], [hi[0], hi[1]], 1.0);
        self.rect(2, hi[2], [lo[0], lo[1]], [hi[0], hi[1]], -1.0);
        self.rect(0, lo[0], [lo[1], lo[2]], [hi[1], hi[2]], 1.0);
        self.rect(0, hi[0], [lo[1], lo[2]], [hi[1], hi[2]], -1.0);
        self.rect(1, lo[1], [lo[2], lo[0]], [hi[2], hi[0]], 1.0);
        self.rect(1, hi[1], [lo[2], lo[0]], [hi[2], hi[0]], -1.0);
    }

    fn line(&mut self, a: [f64; 3], b: [f64; 3]) {
        self.text
            .push_str(&format!("v {} {} {}\nv {} {} {}\n", a[0], a[1], a[2], b[0], b[1], b[2]));
        self.vertices += 2;
        self.text
            .push_str(&format!("l {} {}\n", self.vertices - 1, self.vertices));
    }

    fn model(&self) -> Model {
        Model::from_obj_str(&self.text, "test.obj").expect("test model loads")
    }
}

fn options() -> BuildOptions {
    BuildOptions {
        spacing_m: 1.0,
        heights_m: vec![1.0, 1.5],
        cube_map_resolution: 64,
        merge: Merge::None,
        ..BuildOptions::default()
    }
}

const H: f64 = 2.7;

/// Index of the segment with these end points (either order).
fn segment(model: &Model, a: [f64; 3], b: [f64; 3]) -> u32 {
    let (a, b) = (Point3::from(a), Point3::from(b));
    model
        .segments
        .iter()
        .position(|s| {
            ((s.a - a).norm() < 1e-9 && (s.b - b).norm() < 1e-9) || ((s.a - b).norm() < 1e-9 && (s.b - a).norm() < 1e-9)
        })
        .unwrap_or_else(|| panic!("no segment {a:?} – {b:?}")) as u32
}

/// Brute force: some sample of the segment is in clear line of sight from `eye`.
fn seen(scene: &Occluders, model: &Model, eye: &Point3<f64>, s: u32) -> bool {
    let s = &model.segments[s as usize];
    (0..=200).any(|k| {
        let p = s.a + (s.b - s.a) * (k as f64 / 200.0);
        let d = p - eye;
        scene.clear_line(eye, &(eye + d * (1.0 - 1e-3 / d.norm())))
    })
}

#[test]
fn closed_room_everything_visible() {
    let mut obj = Obj::default();
    obj.room([0.0, 0.0, 0.0], [4.0, 3.0, H]);
    let model = obj.model();
    assert_eq!(model.segments.len(), 12);
    let table = build_table(&model, "room.obj", &options());
    assert_eq!(table.node_count(), 4 * 3 * 2, "every node of the room is valid");
    for n in 0..table.node_count() as u32 {
        let set = table.node_set(n);
        assert_eq!(set.faces, (0..6).collect::<Vec<u32>>().as_slice(), "node {n}");
        assert_eq!(set.segments, (0..12).collect::<Vec<u32>>().as_slice(), "node {n}");
        assert_eq!(set.vertices.len(), 8, "node {n}");
    }
    // Any position, even outside the grid, is served.
    let set = table.query(&Point3::new(-5.0, 40.0, 9.0)).expect("served");
    assert_eq!(set.segments.len(), 12);
}

/// Room A [0,4]×[0,4] and room B [4.3,8.3]×[0,3], joined through a 0.3 m thick wall by a door
/// y ∈ [0.9, 2.1], z ∈ [0, 2.1].
fn two_rooms() -> Obj {
    two_rooms_wound(None)
}

/// [`two_rooms`], its faces wound at random by `flips` (see [`Obj::flips`]) when given.
fn two_rooms_wound(flips: Option<u64>) -> Obj {
    let (x0, x1) = (4.0, 4.3);
    let (d0, d1, dh) = (0.9, 2.1, 2.1);
    let mut obj = Obj {
        flips,
        ..Obj::default()
    };
    // Room A without its x = 4 wall.
    obj.rect(2, 0.0, [0.0, 0.0], [x0, 4.0], 1.0);
    obj.rect(2, H, [0.0, 0.0], [x0, 4.0], -1.0);
    obj.rect(0, 0.0, [0.0, 0.0], [4.0, H], 1.0);
    obj.rect(1, 0.0, [0.0, 0.0], [H, x0], 1.0);
    obj.rect(1, 4.0, [0.0, 0.0], [H, x0], -1.0);
    // Room B without its x = 4.6 wall.
    obj.rect(2, 0.0, [x1, 0.0], [8.3, 3.0], 1.0);
    obj.rect(2, H, [x1, 0.0], [8.3, 3.0], -1.0);
    obj.rect(0, 8.3, [0.0, 0.0], [3.0, H], -1.0);
    obj.rect(1, 0.0, [0.0, x1], [H, 8.3], 1.0);
    obj.rect(1, 3.0, [0.0, x1], [H, 8.3], -1.0);
    // The thick wall: its two sides with the door cut from the bottom, the door's reveals, and
    // the wall's ends and top closing the solid where it meets the rooms' outlines.
    for (x, sign, y_end) in [(x0, -1.0, 4.0), (x1, 1.0, 3.0)] {
        obj.poly(
            &[
                [x, 0.0, 0.0],
                [x, d0, 0.0],
                [x, d0, dh],
                [x, d1, dh],
                [x, d1, 0.0],
                [x, y_end, 0.0],
                [x, y_end, H],
                [x, 0.0, H],
            ],
            [sign, 0.0, 0.0],
        );
    }
    obj.rect(1, d0, [0.0, x0], [dh, x1], 1.0);
    obj.rect(1, d1, [0.0, x0], [dh, x1], -1.0);
    obj.rect(2, dh, [x0, d0], [x1, d1], -1.0);
    // Room B is narrower: the wall's side facing +y beyond y = 3 belongs to the outside.
    obj
}

#[test]
fn two_rooms_far_room_seen_only_through_the_door() {
    let obj = two_rooms();
    let model = obj.model();
    let scene = Occluders::new(&model);
    let table = build_table(&model, "two_rooms.obj", &options());

    // Nodes inside the wall (x = 4.15) and outside the building (room B's side beyond y = 3)
    // are excluded; the rest of both rooms is in.
    for n in 0..table.node_count() as u32 {
        let p = table.node_position(n);
        assert!(!(p.x > 4.0 && p.x < 4.3), "node {p} lies in the wall");
        assert!(!(p.x > 4.3 && p.y > 3.0), "node {p} lies outside the building");
    }
    let nodes: Vec<_> = (0..table.node_count() as u32).map(|n| table.node_position(n)).collect();
    assert_eq!(table.node_count(), (3 * 4 + 3 * 3) * 2, "{nodes:?}");
    let p = Point3::new(2.15, 1.5, 1.5);
    let set = table.query(&p).expect("served");
    let eye = set.node_position;
    assert!(
        eye.x < 4.0,
        "room A's position is served by a node of room A, not {eye}"
    );

    // Room B's far corners (8.3, 0) and (8.3, 3) are seen through the door; its corners behind
    // the wall, (4.3, 0) and (4.3, 3), are not.
    let far = segment(&model, [8.3, 0.0, 0.0], [8.3, 0.0, H]);
    let far2 = segment(&model, [8.3, 3.0, 0.0], [8.3, 3.0, H]);
    let hidden = [
        segment(&model, [4.3, 0.0, 0.0], [4.3, 0.0, H]),
        segment(&model, [4.3, 3.0, 0.0], [4.3, 3.0, H]),
    ];
    let b_only: Vec<u32> = (0..model.segments.len() as u32)
        .filter(|&s| {
            let g = &model.segments[s as usize];
            g.a.x >= 4.3 - 1e-9 && g.b.x >= 4.3 - 1e-9
        })
        .collect();
    assert!(
        set.segments.contains(&far),
        "far corner of room B seen through the door"
    );
    assert!(
        set.segments.contains(&far2),
        "far corner of room B seen through the door"
    );
    for h in hidden {
        assert!(!set.segments.contains(&h), "segment {h} is behind the wall");
    }
    // Everything of room B in the set is seen through the door, by brute force.
    let mut through = 0;
    for &s in set.segments.iter().filter(|s| b_only.contains(s)) {
        assert!(
            seen(&scene, &model, &eye, s),
            "segment {s} of room B is not visible from {eye}"
        );
        through += 1;
    }
    assert!(through >= 3, "only {through} segments of room B seen through the door");

    // A node in room A off the door's axis, near the shared wall: whatever of room B it has is
    // visible (through the door).
    let side = table.query(&Point3::new(3.5, 0.5, 1.0)).expect("served");
    for &s in side.segments {
        if b_only.contains(&s) {
            assert!(seen(&scene, &model, &side.node_position, s), "segment {s}");
        }
    }
}

#[test]
fn pillar_occludes_wall() {
    let mut obj = Obj::default();
    obj.room([0.0, 0.0, 0.0], [10.0, 5.0, H]);
    // A pillar [4.1,4.9]×[2.1,2.9], floor to ceiling, seen from outside; node (4.5, 2.5) lies
    // in it, 0.4 m from its faces (excluded: a space closed all round, 1.13 m across at most).
    obj.rect(0, 4.1, [2.1, 0.0], [2.9, H], -1.0);
    obj.rect(0, 4.9, [2.1, 0.0], [2.9, H], 1.0);
    obj.rect(1, 2.1, [0.0, 4.1], [H, 4.9], -1.0);
    obj.rect(1, 2.9, [0.0, 4.1], [H, 4.9], 1.0);
    // A free segment painted on the far wall behind the pillar.
    obj.line([10.0, 2.5, 0.5], [10.0, 2.5, 2.2]);
    let model = obj.model();
    let table = build_table(&model, "pillar.obj", &options());
    let painted = segment(&model, [10.0, 2.5, 0.5], [10.0, 2.5, 2.2]);
    let front = segment(&model, [4.1, 2.1, 0.0], [4.1, 2.1, H]);
    let back = segment(&model, [4.9, 2.1, 0.0], [4.9, 2.1, H]);

    let behind = table.query(&Point3::new(1.5, 2.5, 1.5)).expect("served");
    assert_eq!(behind.node_position, Point3::new(1.5, 2.5, 1.5));
    assert!(!behind.segments.contains(&painted), "the pillar hides the painted line");
    assert!(behind.segments.contains(&front));
    assert!(!behind.segments.contains(&back), "the pillar hides its own back edge");
    // The pillar's faces are opaque: nodes inside it are excluded.
    for n in 0..table.node_count() as u32 {
        let p = table.node_position(n);
        assert!(
            !(p.x > 4.1 && p.x < 4.9 && p.y > 2.1 && p.y < 2.9),
            "node {p} inside the pillar"
        );
    }

    let aside = table.query(&Point3::new(1.5, 0.5, 1.5)).expect("served");
    assert!(aside.segments.contains(&painted), "seen past the pillar");
    assert!(aside.segments.contains(&back), "back edge seen from the side");
}

#[test]
fn file_round_trip_and_model_mismatch() {
    let obj = two_rooms();
    let model = obj.model();
    let table = build_table(&model, "two_rooms.obj", &options());
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("two_rooms.vis");
    table.save(&path).expect("saved");
    let back = VisibilityTable::load(&path, &model).expect("loads against its model");
    assert_eq!(back, table);

    let mut other = Obj::default();
    other.room([0.0, 0.0, 0.0], [4.0, 3.0, H]);
    let err = VisibilityTable::load(&path, &other.model()).expect_err("other model");
    assert!(matches!(err, VisibilityError::ModelMismatch { .. }), "{err:?}");
    let msg = err.to_string();
    assert!(
        msg.contains("two_rooms.vis") && msg.contains("different model"),
        "{msg}"
    );
    assert!(!msg.contains('\n'));

    // Garbage and truncation are errors too, never panics.
    let bytes = table.to_bytes();
    assert!(VisibilityTable::from_bytes(b"not a table", "x.vis").is_err());
    for cut in [8, 20, bytes.len() / 2, bytes.len() - 1] {
        assert!(
            VisibilityTable::from_bytes(&bytes[..cut], "x.vis").is_err(),
            "cut {cut}"
        );
    }
}

#[test]
fn a_flipped_bit_anywhere_is_refused_in_one_line() {
    let model = two_rooms().model();
    let bytes = build_table(&model, "two_rooms.obj", &options()).to_bytes();
    // Every byte after the version (which is reported as a version), one bit each.
    for at in (12..bytes.len()).step_by(7) {
        let mut bad = bytes.clone();
        bad[at] ^= 0x10;
        let err = VisibilityTable::from_bytes(&bad, "x.vis").expect_err("damaged");
        let msg = err.to_string();
        assert!(msg.starts_with("x.vis: ") && !msg.contains('\n'), "{msg}");
    }
    let mut bad = bytes.clone();
    let mid = bytes.len() / 2;
    bad[mid] ^= 1;
    let msg = VisibilityTable::from_bytes(&bad, "x.vis").unwrap_err().to_string();
    assert!(msg.contains("checksum"), "{msg}");
}

#[test]
fn a_cached_table_built_with_other_settings_is_rebuilt() {
    use omnitrack::config::TrackerConfig;
    use omnitrack::runtime::load_or_build_table;
    let dir = tempfile::tempdir().expect("temp dir");
    let model_path = dir.path().join("two_rooms.obj");
    std::fs::write(&model_path, &two_rooms().text).unwrap();
    let model = Model::load(&model_path).unwrap();
    let mut cfg = TrackerConfig::default();
    let (first, origin) = load_or_build_table(&model_path, &model, None, &cfg).unwrap();
    assert!(origin.contains("built"), "{origin}");
    let (again, origin) = load_or_build_table(&model_path, &model, None, &cfg).unwrap();
    assert!(origin.contains("cached"), "{origin}");
    assert_eq!(again, first);
    cfg.visibility.min_segment_length_m = 5.0;
    let (rebuilt, origin) = load_or_build_table(&model_path, &model, None, &cfg).unwrap();
    assert!(
        origin.contains("other settings") && origin.contains("min_segment_length_m"),
        "{origin}"
    );
    assert_eq!(rebuilt.header.min_segment_length_m, 5.0);
    assert_ne!(rebuilt, first);
    cfg.visibility.node_spacing_m *= 2.0;
    let (_, origin) = load_or_build_table(&model_path, &model, None, &cfg).unwrap();
    assert!(origin.contains("node_spacing_m"), "{origin}");
}

#[test]
fn query_json_lists_obj_faces_segments_and_vertices() {
    let mut obj = Obj::default();
    obj.room([0.0, 0.0, 0.0], [4.0, 3.0, H]);
    let model = obj.model();
    let table = build_table(&model, "room.obj", &options());
    let json = query_json(&table, &model, &Point3::new(-1.5, 2.0, 1.6));
    let v: serde_json::Value = serde_json::from_str(&json).expect("valid JSON");
    assert_eq!(v["node_m"], serde_json::json!([0.5, 2.5, 1.5]));
    assert_eq!(v["faces"], serde_json::json!([1, 2, 3, 4, 5, 6]));
    assert_eq!(v["segments"].as_array().unwrap().len(), 12);
    assert!(v["segments"]
        .as_array()
        .unwrap()
        .iter()
        .all(|s| s.as_array().unwrap().len() == 6));
    assert_eq!(v["vertices"].as_array().unwrap().len(), 8);
    assert!(!json.contains('\n'));
}

#[test]
fn neighbour_merging_is_a_superset() {
    let obj = two_rooms();
    let model = obj.model();
    let plain = build_table(&model, "m.obj", &options());
    let merged = build_table(
        &model,
        "m.obj",
        &BuildOptions {
            merge: Merge::Neighbours,
            ..options()
        },
    );
    assert_eq!(plain.node_count(), merged.node_count());
    for n in 0..plain.node_count() as u32 {
        let (a, b) = (plain.node_set(n), merged.node_set(n));
        assert!(a.segments.iter().all(|s| b.segments.contains(s)), "node {n}");
    }
}

#[test]
fn cli_build_and_query_entry_points() {
    use omnitrack::config::VisibilityConfig;
    use omnitrack::visibility::build::run_build;
    use omnitrack::visibility::{parse_point, run_query};
    let dir = tempfile::tempdir().expect("temp dir");
    let model_path = dir.path().join("room.obj");
    let table_path = dir.path().join("room.vis");
    let mut obj = Obj::default();
    obj.room([0.0, 0.0, 0.0], [4.0, 3.0, H]);
    std::fs::write(&model_path, &obj.text).unwrap();
    let config = VisibilityConfig {
        cube_map_resolution: 32,
        ..VisibilityConfig::default()
    };
    let summary = run_build(&model_path, &table_path, Some(1.0), &config).expect("builds");
    assert!(summary.contains("valid nodes"), "{summary}");
    let json = run_query(&table_path, &parse_point("-1.5,2,1.6").unwrap()).expect("queries");
    let v: serde_json::Value = serde_json::from_str(&json).expect("valid JSON");
    assert_eq!(v["faces"], serde_json::json!([1, 2, 3, 4, 5, 6]));

    // The model changed on disk since the build: one line naming the table and the cause.
    let mut other = Obj::default();
    other.room([0.0, 0.0, 0.0], [5.0, 3.0, H]);
    std::fs::write(&model_path, &other.text).unwrap();
    let err = run_query(&table_path, &parse_point("1,1,1.5").unwrap()).expect_err("mismatch");
    let msg = err.to_string();
    assert!(
        msg.contains("room.vis") && msg.contains("different model") && !msg.contains('\n'),
        "{msg}"
    );

    // Bad inputs are one-line errors.
    std::fs::write(&model_path, "# nothing\n").unwrap();
    let err = run_build(&model_path, &table_path, None, &config).expect_err("no faces");
    assert!(err.to_string().contains("room.obj"), "{err}");
    assert!(run_build(&model_path, &table_path, Some(-1.0), &config).is_err());
    let err = run_query(&dir.path().join("missing.vis"), &parse_point("0,0,0").unwrap()).expect_err("missing");
    assert!(err.to_string().contains("missing.vis"), "{err}");
}

/// Every node and every set of a table, for comparing two builds.
/// A node's position, faces and segments (each by its end points, to the micrometre).
type NodeContents = (Point3<f64>, Vec<u32>, Vec<[[i64; 3]; 2]>);

/// Segments are named by their end points (a face wound the other way lists its edges in the
/// other order, so segment indices differ between the two models).
fn contents(table: &VisibilityTable, model: &Model) -> Vec<NodeContents> {
    let key = |p: &Point3<f64>| [p.x, p.y, p.z].map(|c| (c * 1e6).round() as i64);
    (0..table.node_count() as u32)
        .map(|n| {
            let set = table.node_set(n);
            let mut segments: Vec<[[i64; 3]; 2]> = set
                .segments
                .iter()
                .map(|&s| {
                    let seg = &model.segments[s as usize];
                    let mut ends = [key(&seg.a), key(&seg.b)];
                    ends.sort();
                    ends
                })
                .collect();
            segments.sort();
            (table.node_position(n), set.faces.to_vec(), segments)
        })
        .collect()
}

/// Winding carries no meaning (docs/interfaces.md, "Building model"): the same building with its faces wound at
/// random, three draws, gives the same nodes and the same sets.
#[test]
fn winding_flipped_at_random_leaves_the_table_unchanged() {
    let model = two_rooms().model();
    let wound = contents(&build_table(&model, "two_rooms.obj", &options()), &model);
    assert_eq!(wound.len(), (3 * 4 + 3 * 3) * 2);
    for seed in [1u64, 0x9e37_79b9_7f4a_7c15, 12345] {
        let model = two_rooms_wound(Some(seed)).model();
        let flipped = contents(&build_table(&model, "two_rooms.obj", &options()), &model);
        assert_eq!(flipped, wound, "seed {seed}");
    }
}

/// A building drawn as another tool draws it: every wall one face, wound either way, an inner
/// wall with a doorway, floor and ceiling one face each. Both rooms keep every node, and each
/// sees the other only through the doorway.
#[test]
fn single_face_walls_wound_either_way_keep_their_rooms() {
    let mut obj = Obj {
        flips: Some(7),
        ..Obj::default()
    };
    obj.rect(2, 0.0, [0.0, 0.0], [6.0, 3.0], 1.0);
    obj.rect(2, H, [0.0, 0.0], [6.0, 3.0], -1.0);
    obj.rect(0, 0.0, [0.0, 0.0], [3.0, H], 1.0);
    obj.rect(0, 6.0, [0.0, 0.0], [3.0, H], -1.0);
    obj.rect(1, 0.0, [0.0, 0.0], [H, 6.0], 1.0);
    obj.rect(1, 3.0, [0.0, 0.0], [H, 6.0], -1.0);
    // The inner wall at x = 3, a doorway y ∈ [1, 2] up to 2.1 m.
    obj.poly(
        &[
            [3.0, 0.0, 0.0],
            [3.0, 1.0, 0.0],
            [3.0, 1.0, 2.1],
            [3.0, 2.0, 2.1],
            [3.0, 2.0, 0.0],
            [3.0, 3.0, 0.0],
            [3.0, 3.0, H],
            [3.0, 0.0, H],
        ],
        [1.0, 0.0, 0.0],
    );
    let model = obj.model();
    let table = build_table(&model, "single.obj", &options());
    assert_eq!(table.node_count(), 6 * 3 * 2, "every node of both rooms is valid");
    // From beside the inner wall, the far corner of the other room is hidden by it (the line
    // of sight meets x = 3 at y = 0.86, short of the doorway), the doorway's jamb seen.
    let set = table.query(&Point3::new(2.5, 0.5, 1.5)).expect("served");
    assert_eq!(set.node_position, Point3::new(2.5, 0.5, 1.5));
    let far_corner = segment(&model, [6.0, 3.0, 0.0], [6.0, 3.0, H]);
    let jamb = segment(&model, [3.0, 1.0, 0.0], [3.0, 1.0, 2.1]);
    assert!(!set.segments.contains(&far_corner));
    assert!(set.segments.contains(&jamb));
}

/// A point inside a wall or a slab thicker than twice the clearance is not free space, whichever
/// way the solid's faces are wound.
#[test]
fn the_inside_of_a_thick_solid_is_not_free() {
    for flips in [None, Some(3u64)] {
        let mut obj = Obj {
            flips,
            ..Obj::default()
        };
        // Two rooms either side of a 0.45 m wall (a closed solid), under one ceiling.
        obj.room([0.0, 0.0, 0.0], [3.0, 3.0, H]);
        obj.room([3.45, 0.0, 0.0], [6.45, 3.0, H]);
        let model = obj.model();
        let scene = Occluders::new(&model);
        assert!(scene.is_free(&Point3::new(1.5, 1.5, 1.5), 0.2));
        assert!(!scene.is_free(&Point3::new(3.225, 1.5, 1.5), 0.2), "inside the wall");
        assert!(!scene.is_free(&Point3::new(1.5, 1.5, -0.3), 0.2), "under the floor");
        assert!(!scene.is_free(&Point3::new(1.5, 1.5, H + 0.4), 0.2), "on the roof");
        assert!(!scene.is_free(&Point3::new(1.5, 8.0, 1.5), 0.2), "outside");
    }
}

/// `once` with each `f` line written again after all of them, its vertices in the other order
/// when `reversed`.
fn written_twice(once: &Obj, reversed: bool) -> Obj {
    let mut twice = Obj {
        text: once.text.clone(),
        vertices: once.vertices,
        flips: None,
    };
    for line in once.text.lines().filter(|l| l.starts_with("f ")) {
        let mut ids: Vec<&str> = line[2..].split_whitespace().collect();
        if reversed {
            ids.reverse();
        }
        twice.text.push_str(&format!("f {}\n", ids.join(" ")));
    }
    twice
}

/// Every face written twice, the copy wound the other way (as exporters of two-sided walls
/// write them): the same nodes and sets as the building drawn once.
#[test]
fn duplicated_faces_leave_the_table_unchanged() {
    let once = two_rooms();
    let twice = written_twice(&once, true);
    let (a, b) = (once.model(), twice.model());
    assert_eq!(b.faces.len(), 2 * a.faces.len());
    let (ta, tb) = (
        build_table(&a, "once.obj", &options()),
        build_table(&b, "twice.obj", &options()),
    );
    let strip = |c: Vec<NodeContents>| c.into_iter().map(|(p, _, s)| (p, s)).collect::<Vec<_>>();
    assert_eq!(strip(contents(&tb, &b)), strip(contents(&ta, &a)));
}

/// Every face written twice the same way: at each pixel the two copies are at exactly the same
/// depth, and the render shows the first (smaller id) everywhere, as drawing in file order would,
/// although the build draws nearest first.
#[test]
fn coincident_faces_show_the_smaller_face_id() {
    let once = two_rooms();
    let twice = written_twice(&once, false);
    let (a, b) = (once.model(), twice.model());
    let n = a.faces.len() as u32;
    assert_eq!(b.faces.len() as u32, 2 * n);
    let scene = Occluders::new(&b);
    let mut cube = CubeMap::new(64, b.faces.len());
    for eye in [[1.0, 1.0, 1.5], [2.5, 3.0, 1.0], [6.0, 1.5, 1.5]] {
        let (faces, _) = cube.visibility(&scene, &Point3::from(eye), &options());
        assert!(!faces.is_empty());
        assert!(faces.iter().all(|&f| f < n), "a copy shows from {eye:?}: {faces:?}");
        let shown = (0..6).flat_map(|f| (0..64).flat_map(move |y| (0..64).map(move |x| (f, x, y))));
        for (f, x, y) in shown {
            let id = cube.id_at(f, x, y);
            assert!(
                id == u32::MAX || id < n,
                "pixel {f} {x} {y} from {eye:?} shows copy {id}"
            );
        }
    }
}

/// Lookup cells beyond two node cells of any node (here the 30 m between two rooms) map to a
/// node at the smallest distance, found by a search over every node.
#[test]
fn far_lookup_cells_take_a_nearest_node() {
    let mut obj = Obj::default();
    obj.room([0.0, 0.0, 0.0], [3.0, 3.0, H]);
    obj.room([33.0, 8.0, 0.0], [36.0, 11.0, H]);
    let model = obj.model();
    let (raw, _) = build_raw(&model, "two.obj", &options());
    let h = &raw.header;
    let m = h.lookup_subdivisions as usize;
    let (nx, ny) = (h.dims[0] as usize, h.dims[1] as usize);
    let (lx, ly) = (nx * m, ny * m);
    let node_pos = |n: u32| {
        let c = raw.node_cell[n as usize] as usize;
        let (i, j, k) = (c % nx, (c / nx) % ny, c / (nx * ny));
        Point3::new(
            h.origin[0] + i as f64 * h.spacing_m,
            h.origin[1] + j as f64 * h.spacing_m,
            h.origin[2] + h.heights_m[k],
        )
    };
    assert!(raw.node_cell.len() > 4);
    let mut far = 0;
    for (lc, &chosen) in raw.cell_node.iter().enumerate() {
        let (li, lj, k) = (lc % lx, (lc / lx) % ly, lc / (lx * ly));
        let p = Point3::new(
            h.origin[0] - 0.5 * h.spacing_m + (li as f64 + 0.5) * h.spacing_m / m as f64,
            h.origin[1] - 0.5 * h.spacing_m + (lj as f64 + 0.5) * h.spacing_m / m as f64,
            h.origin[2] + h.heights_m[k],
        );
        let best = (0..raw.node_cell.len() as u32)
            .map(|n| (node_pos(n) - p).norm())
            .fold(f64::INFINITY, f64::min);
        if best > 3.0 * h.spacing_m {
            far += 1;
            assert!(
                ((node_pos(chosen) - p).norm() - best).abs() < 1e-9,
                "lookup cell {lc} at {p:?}: node {chosen} at {:.3} m, nearest {best:.3} m",
                (node_pos(chosen) - p).norm()
            );
        }
    }
    assert!(far > 1000, "{far} far lookup cells");
}

/// Two storeys, one above the other with a 0.3 m slab between them: nodes on both floors, none
/// in the slab.
#[test]
fn two_storeys_keep_both_floors_and_nothing_in_the_slab() {
    let mut obj = Obj::default();
    obj.room([0.0, 0.0, 0.0], [6.0, 4.0, H]);
    obj.room([0.0, 0.0, H + 0.3], [6.0, 4.0, 2.0 * H + 0.3]);
    let model = obj.model();
    let table = build_table(
        &model,
        "storeys.obj",
        &BuildOptions {
            heights_m: vec![1.0, 1.5, H + 0.15, H + 0.3 + 1.0, H + 0.3 + 1.5],
            ..options()
        },
    );
    let on = |z: f64| {
        (0..table.node_count() as u32)
            .filter(|&n| (table.node_position(n).z - z).abs() < 1e-9)
            .count()
    };
    for z in [1.0, 1.5, H + 1.3, H + 1.8] {
        assert_eq!(on(z), 6 * 4, "layer {z}");
    }
    assert_eq!(on(H + 0.15), 0, "nodes in the slab");
    assert_eq!(table.node_count(), 4 * 6 * 4);
}

#[test]
fn segments_shorter_than_the_minimum_enter_no_set() {
    // A handle-sized plate 6 cm × 30 cm, 1 cm off the wall x = 0 of a plain room.
    let mut obj = Obj::default();
    obj.room([0.0, 0.0, 0.0], [4.0, 3.0, H]);
    obj.rect(0, 0.01, [1.5, 1.0], [1.56, 1.3], 1.0);
    let model = obj.model();
    assert_eq!(model.segments.len(), 16);
    let short = |s: &u32| model.segments[*s as usize].length() < 0.1;
    assert_eq!((0..16u32).filter(short).count(), 2);
    // Shipped: the two 6 cm edges are in no set, the 30 cm ones and the room's are.
    let shipped = build_table(&model, "plate.obj", &options());
    assert!((0.09..=0.11).contains(&options().min_segment_length_m));
    let all = BuildOptions {
        min_segment_length_m: 0.0,
        ..options()
    };
    let every = build_table(&model, "plate.obj", &all);
    let (mut kept, mut with_short) = (0, 0);
    for n in 0..shipped.node_count() as u32 {
        let set = shipped.node_set(n).segments;
        assert!(!set.iter().any(short), "node {n} keeps a short segment");
        kept = kept.max(set.len());
        with_short = with_short.max(every.node_set(n).segments.iter().filter(|s| short(s)).count());
    }
    assert_eq!(kept, 14, "the room's 12 and the plate's two long edges");
    assert_eq!(with_short, 2, "with no minimum the short edges are seen");
}

/// An open model: one room's floor and single-face walls, no ceiling and nothing outside it (a
/// plan extruded without a roof, walls traced from a scan). Every node of the room is kept, and
/// the room's corners are seen from its middle.
#[test]
fn an_open_model_without_a_ceiling_keeps_its_room() {
    let mut obj = Obj {
        flips: Some(11),
        ..Obj::default()
    };
    obj.rect(2, 0.0, [0.0, 0.0], [6.0, 3.0], 1.0);
    obj.rect(0, 0.0, [0.0, 0.0], [3.0, H], 1.0);
    obj.rect(0, 6.0, [0.0, 0.0], [3.0, H], -1.0);
    obj.rect(1, 0.0, [0.0, 0.0], [H, 6.0], 1.0);
    obj.rect(1, 3.0, [0.0, 0.0], [H, 6.0], -1.0);
    let model = obj.model();
    let table = build_table(&model, "open.obj", &options());
    assert_eq!(table.node_count(), 6 * 3 * 2, "every node of the room is valid");
    let set = table.query(&Point3::new(3.0, 1.5, 1.5)).expect("served");
    for corner in [[0.0, 0.0], [6.0, 0.0], [0.0, 3.0], [6.0, 3.0]] {
        let s = segment(&model, [corner[0], corner[1], 0.0], [corner[0], corner[1], H]);
        assert!(set.segments.contains(&s), "corner {corner:?}");
    }
    // Outside the walls is not free space, though nothing is there to stand under.
    let scene = Occluders::new(&model);
    assert!(!scene.is_free(&Point3::new(3.0, 5.0, 1.5), 0.2));
}

/// A grid too large to build (a 100 km model at 1 m, or a room at 0.1 mm) is refused in one
/// line before any of it is allocated, saying what to change.
#[test]
fn a_grid_too_large_to_build_is_refused_before_it_is_allocated() {
    use omnitrack::config::VisibilityConfig;
    use omnitrack::visibility::build::run_build;
    let dir = tempfile::tempdir().unwrap();
    for (size, spacing) in [(1e5, None), (10.0, Some(1e-4))] {
        let obj = dir.path().join("m.obj");
        std::fs::write(
            &obj,
            format!("v 0 0 0\nv {size} 0 0\nv {size} {size} 0\nv 0 {size} 0\nf 1 2 3 4\n"),
        )
        .unwrap();
        let out = dir.path().join("m.vis");
        let e = run_build(&obj, &out, spacing, &VisibilityConfig::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("grid cells, more than 30000000"), "{e}");
        assert!(e.contains("use a wider spacing"), "{e}");
        assert!(!out.exists());
    }
}

/// A table is saved by renaming a finished file over the path: a symbolic link there (the
/// cache beside a model) is replaced, and the file it pointed to is left alone; a device is
/// refused as a table to read.
#[test]
fn saving_replaces_a_link_and_never_writes_through_it() {
    let mut obj = Obj::default();
    obj.room([0.0, 0.0, 0.0], [4.0, 3.0, 2.6]);
    let model = obj.model();
    let table = build_table(&model, "room.obj", &options());
    let dir = tempfile::tempdir().unwrap();
    let precious = dir.path().join("precious.txt");
    std::fs::write(&precious, "mine").unwrap();
    let vis = dir.path().join("room.vis");
    std::os::unix::fs::symlink(&precious, &vis).unwrap();
    table.save(&vis).unwrap();
    assert_eq!(std::fs::read_to_string(&precious).unwrap(), "mine");
    assert!(!std::fs::symlink_metadata(&vis).unwrap().file_type().is_symlink());
    assert_eq!(
        VisibilityTable::load(&vis, &model).unwrap().node_count(),
        table.node_count()
    );
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        2,
        "no partial file left"
    );
    let e = VisibilityTable::load_unchecked(std::path::Path::new("/dev/zero")).unwrap_err();
    assert!(e.to_string().contains("not a regular file"), "{e}");
}

/// Issue 47: a grid position of the search asks for the few dozen segments spanning the widest
/// angle in sight. On a detailed model (here the two rooms with 60 small window panes, 240 short
/// segments, standing in for an architect's sashes and trims) ranking the candidates by the
/// angle they span before casting rays gives exactly the brute-force answer (every candidate
/// ray-cast, ranked by the angle in sight) for a fraction of the rays.
#[test]
fn the_widest_segments_in_sight_are_those_of_brute_force_for_a_fraction_of_the_rays() {
    use omnitrack::visibility::at_pose::{spanned_angle, PoseVisibility};
    let mut obj = two_rooms();
    // Panes 0.12 m square, 2 mm proud of the walls y = 0 (room A) and y = 3 (room B), in rows.
    for row in 0..3 {
        for col in 0..10 {
            let z = 1.0 + 0.3 * row as f64;
            let xa = 0.3 + 0.35 * col as f64;
            obj.rect(1, 0.002, [z, xa], [z + 0.12, xa + 0.12], 1.0);
            let xb = 4.6 + 0.35 * col as f64;
            obj.rect(1, 2.998, [z, xb], [z + 0.12, xb + 0.12], -1.0);
        }
    }
    let model = obj.model();
    assert!(model.segments.len() >= 240, "{} segments", model.segments.len());
    let table = build_table(&model, "panes.obj", &options());
    let mut sight = PoseVisibility::new(&model);
    let mut kept = Vec::with_capacity(model.segments.len());
    let (mut rays_ranked, mut rays_all, mut positions) = (0u64, 0u64, 0);
    for ix in 0..16 {
        for iy in 0..7 {
            let at = Point3::new(0.25 + 0.5 * ix as f64, 0.2 + 0.4 * iy as f64, 1.3);
            if table.query(&at).is_none() {
                continue;
            }
            let before = sight.rays_cast();
            let seen = sight.at(&model, &table, &at).to_vec();
            let mut all: Vec<f64> = seen
                .iter()
                .map(|s| {
                    let seg = &model.segments[s.segment as usize];
                    spanned_angle(&at, &seg.a, &seg.b) * f64::from(s.mask.count_ones()) / 8.0
                })
                .collect();
            rays_all += sight.rays_cast() - before;
            all.sort_by(|a, b| b.total_cmp(a));
            for keep in [1, 12, 48] {
                let before = sight.rays_cast();
                sight.widest(&model, &table, &at, keep, &mut kept);
                if keep == 12 {
                    rays_ranked += sight.rays_cast() - before;
                }
                // Each kept segment with the points in sight that `at` gives it.
                for (_, k) in &kept {
                    assert!(seen.contains(k), "at {at:?}: {k:?} is not as `at` sees it");
                }
                let mut got: Vec<f64> = kept.iter().map(|k| k.0).collect();
                got.sort_by(|a, b| b.total_cmp(a));
                let want = &all[..keep.min(all.len())];
                assert_eq!(got.len(), want.len(), "at {at:?}, keep {keep}");
                for (g, a) in got.iter().zip(want) {
                    assert!(
                        (g - a).abs() < 1e-12,
                        "at {at:?}, keep {keep}: {got:?} against {want:?}"
                    );
                }
            }
            positions += 1;
        }
    }
    assert!(positions > 40, "{positions} positions in the rooms");
    assert!(
        rays_ranked * 3 < rays_all,
        "ranked {rays_ranked} rays against {rays_all} for all, over {positions} positions"
    );
}
