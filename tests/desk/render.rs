//! The desk renderer against geometry: corners of a room land on colour boundaries where the
//! lens model says they project, the BVH agrees with brute force, ear clipping covers non-convex
//! faces, recordings have the layout of docs/interfaces.md, renders are deterministic, and
//! several rays per pixel blend colours across boundaries only.
#![cfg(feature = "desk")]

use nalgebra::{Isometry3, Point2, Point3, Translation3, UnitQuaternion, Vector3};
use omnitrack::desk::recording::{write_recording, RecordingOptions};
use omnitrack::desk::render::{
    brute_force_closest, ear_clip, model_triangles, triangulate_polygon, Appearance, FrameSpec, Ray, Renderer,
    Triangle, TriangleBvh,
};
use omnitrack::trajectory::{load_tum, Stamped};
use omnitrack::{Model, Rig};
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use std::path::Path;

const ROOM: (f64, f64, f64) = (5.0, 4.0, 2.7);

/// A closed box room, every face under its own usemtl kind (walls one material, four planes).
fn room_obj() -> String {
    let (w, d, h) = ROOM;
    let mut s = String::from("o room\n");
    for z in [0.0, h] {
        for (x, y) in [(0.0, 0.0), (w, 0.0), (w, d), (0.0, d)] {
            s += &format!("v {x} {y} {z}\n");
        }
    }
    s += "usemtl floor\nf 1 4 3 2\nusemtl ceiling\nf 5 6 7 8\n";
    s += "usemtl wall\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n";
    s
}

fn rig() -> Rig {
    crate::common::shipped_rig()
}

fn pose() -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(2.1, 1.7, 1.45),
        UnitQuaternion::from_euler_angles(0.04, -0.03, 0.35),
    )
}

fn frame(index: u64, pose: Isometry3<f64>) -> FrameSpec {
    FrameSpec {
        index,
        timestamp_ns: 1_000_000_000 + index * 33_333_333,
        pose,
        previous: None,
    }
}

fn no_clutter() -> Appearance {
    Appearance {
        clutter: 0.0,
        people: 0.0,
        ..Appearance::default()
    }
}

/// 5×5 neighbourhood of a pixel, or None near the border.
fn patch(img: &image::RgbImage, px: &Point2<f64>) -> Option<Vec<[i32; 3]>> {
    let (u, v) = (px.x.round() as i64, px.y.round() as i64);
    if u < 2 || v < 2 || u + 2 >= img.width() as i64 || v + 2 >= img.height() as i64 {
        return None;
    }
    let mut out = Vec::new();
    for dv in -2..=2 {
        for du in -2..=2 {
            let p = img.get_pixel((u + du) as u32, (v + dv) as u32).0;
            out.push([p[0] as i32, p[1] as i32, p[2] as i32]);
        }
    }
    Some(out)
}

fn spread(p: &[[i32; 3]]) -> i32 {
    let mut m = 0;
    for a in p {
        for b in p {
            m = m.max((0..3).map(|k| (a[k] - b[k]).abs()).sum::<i32>());
        }
    }
    m
}

#[test]
fn room_corners_land_on_colour_boundaries_and_faces_are_uniform() {
    let model = Model::from_obj_str(&room_obj(), "room.obj").unwrap();
    let rig = rig();
    let pose = pose();
    let renderer = Renderer::new(&model, &rig, no_clutter(), &[]);
    let images = renderer.render_frame(&frame(0, pose));
    if let Ok(dir) = std::env::var("OMNITRACK_RENDER_DUMP") {
        for (k, img) in images.iter().enumerate() {
            img.save(Path::new(&dir).join(format!("room_sensor{k}.png"))).unwrap();
        }
    }
    let mut corners_checked = 0;
    for v in &model.vertices {
        for (sensor, img) in rig.sensors.iter().zip(&images) {
            let p_rig = pose.inverse() * v;
            let Some(px) = sensor.project_from_rig(&p_rig) else {
                continue;
            };
            // Visible: nothing between the sensor centre and the corner.
            let origin = pose * sensor.centre();
            let to = v - origin;
            let hit = renderer.cast(&origin, &to).expect("a closed room is hit everywhere");
            if hit.t < to.norm() - 1e-3 {
                continue;
            }
            let Some(p) = patch(img, &px) else { continue };
            let s = spread(&p);
            assert!(
                s >= 60,
                "corner {v:?} in sensor {} at {px:?}: 5x5 spread {s}: {p:?}",
                sensor.id
            );
            corners_checked += 1;
        }
    }
    assert!(corners_checked >= 8, "only {corners_checked} corner views");

    // Centres of faces: uniform-ish.
    let mut centres_checked = 0;
    for face in &model.faces {
        let centre = face
            .vertices
            .iter()
            .map(|&i| model.vertices[i as usize].coords)
            .sum::<Vector3<f64>>()
            / face.vertices.len() as f64;
        // The centre and points halfway from it to each corner: all well inside the face.
        let inner = face
            .vertices
            .iter()
            .map(|&i| (centre + model.vertices[i as usize].coords) / 2.0);
        for (c, (sensor, img)) in std::iter::once(centre)
            .chain(inner)
            .flat_map(|c| rig.sensors.iter().zip(&images).map(move |s| (c, s)))
        {
            let Some(px) = sensor.project_from_rig(&(pose.inverse() * Point3::from(c))) else {
                continue;
            };
            let Some(p) = patch(img, &px) else { continue };
            let s = spread(&p);
            assert!(
                s <= 40,
                "face centre {c:?} in sensor {} at {px:?}: spread {s}",
                sensor.id
            );
            centres_checked += 1;
        }
    }
    assert!(centres_checked >= 12, "only {centres_checked} face-centre views");
}

fn random_boxes(rng: &mut SmallRng, n: usize) -> Vec<Triangle> {
    let mut tris = Vec::new();
    for _ in 0..n {
        let c: [f32; 3] = [
            rng.random_range(-10.0..10.0),
            rng.random_range(-10.0..10.0),
            rng.random_range(-3.0..3.0),
        ];
        let h: [f32; 3] = [
            rng.random_range(0.05..1.5),
            rng.random_range(0.05..1.5),
            rng.random_range(0.05..1.5),
        ];
        let p = |sx: f32, sy: f32, sz: f32| [c[0] + sx * h[0], c[1] + sy * h[1], c[2] + sz * h[2]];
        let quads = [
            [p(-1., -1., -1.), p(1., -1., -1.), p(1., 1., -1.), p(-1., 1., -1.)],
            [p(-1., -1., 1.), p(1., -1., 1.), p(1., 1., 1.), p(-1., 1., 1.)],
            [p(-1., -1., -1.), p(1., -1., -1.), p(1., -1., 1.), p(-1., -1., 1.)],
            [p(-1., 1., -1.), p(1., 1., -1.), p(1., 1., 1.), p(-1., 1., 1.)],
            [p(-1., -1., -1.), p(-1., 1., -1.), p(-1., 1., 1.), p(-1., -1., 1.)],
            [p(1., -1., -1.), p(1., 1., -1.), p(1., 1., 1.), p(1., -1., 1.)],
        ];
        for q in quads {
            tris.push(Triangle::new(q[0], q[1], q[2]));
            tris.push(Triangle::new(q[0], q[2], q[3]));
        }
    }
    tris
}

#[test]
fn bvh_matches_brute_force() {
    let mut rng = SmallRng::seed_from_u64(7);
    let tris = random_boxes(&mut rng, 300);
    let ids: Vec<u32> = (0..tris.len() as u32).collect();
    let bvh = TriangleBvh::build(&tris, &ids);
    let mut hits = 0;
    for i in 0..4000 {
        let o = [
            rng.random_range(-12.0..12.0),
            rng.random_range(-12.0..12.0),
            rng.random_range(-4.0..4.0),
        ];
        let mut d: [f32; 3] = [
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        ];
        if i % 10 == 0 {
            // Axis-parallel rays exercise the slab test's infinities.
            d = [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]][i / 10 % 3];
        }
        let ray = Ray::new(o, d);
        let t_max = if i % 7 == 0 { 3.0 } else { f32::INFINITY };
        let a = bvh.closest(&ray, 1e-4, t_max);
        let b = brute_force_closest(&tris, &ray, 1e-4, t_max);
        assert_eq!(
            bvh.occluded(&ray, 1e-4, t_max),
            b.is_some(),
            "ray {i}: the occlusion query"
        );
        match (a, b) {
            (None, None) => {}
            (Some((ia, ta)), Some((ib, tb))) => {
                assert_eq!(ta, tb, "ray {i}: t differs");
                // Equal t through a shared edge may pick either triangle.
                if ia != ib {
                    assert_eq!(tris[ia as usize].intersect(&ray, 1e-4, t_max), Some(ta), "ray {i}");
                }
                hits += 1;
            }
            _ => panic!("ray {i}: bvh {a:?} vs brute force {b:?}"),
        }
    }
    assert!(hits > 1000, "only {hits} rays hit anything");
}

fn area2d(p: &[Point2<f64>], t: &[usize; 3]) -> f64 {
    let (a, b, c) = (p[t[0]], p[t[1]], p[t[2]]);
    ((b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x)) / 2.0
}

#[test]
fn ear_clipping_covers_non_convex_polygons() {
    let l = [(0.0, 0.0), (3.0, 0.0), (3.0, 1.0), (1.0, 1.0), (1.0, 3.0), (0.0, 3.0)];
    let u = [
        (0.0, 0.0),
        (3.0, 0.0),
        (3.0, 3.0),
        (2.0, 3.0),
        (2.0, 1.0),
        (1.0, 1.0),
        (1.0, 3.0),
        (0.0, 3.0),
    ];
    for (shape, area) in [(&l[..], 5.0), (&u[..], 7.0)] {
        let pts: Vec<Point2<f64>> = shape.iter().map(|&(x, y)| Point2::new(x, y)).collect();
        let tris = ear_clip(&pts);
        assert_eq!(tris.len(), pts.len() - 2);
        // Every triangle counter-clockwise (no overlap), and together exactly the area.
        assert!(tris.iter().all(|t| area2d(&pts, t) > 0.0), "{tris:?}");
        let sum: f64 = tris.iter().map(|t| area2d(&pts, t)).sum();
        assert!((sum - area).abs() < 1e-12, "{sum} vs {area}");

        // The same polygon on a tilted plane in 3D, and clockwise input.
        let r = UnitQuaternion::from_euler_angles(0.3, -1.1, 2.0);
        let n = r * Vector3::z();
        let pts3: Vec<Point3<f64>> = pts
            .iter()
            .map(|p| r * Point3::new(p.x, p.y, 0.0) + Vector3::new(4.0, -2.0, 7.0))
            .collect();
        let tris = triangulate_polygon(&pts3, &n);
        assert_eq!(tris.len(), pts.len() - 2);
        let mut sum = 0.0;
        for t in &tris {
            let c = (pts3[t[1]] - pts3[t[0]]).cross(&(pts3[t[2]] - pts3[t[0]])) / 2.0;
            assert!(c.dot(&n) > 0.0, "triangle {t:?} not counter-clockwise about the normal");
            sum += c.norm();
        }
        assert!((sum - area).abs() < 1e-9);
        let rev: Vec<Point2<f64>> = pts.iter().rev().copied().collect();
        let tris = ear_clip(&rev);
        let sum: f64 = tris.iter().map(|t| -area2d(&rev, t)).sum();
        assert!(tris.iter().all(|t| area2d(&rev, t) < 0.0));
        assert!((sum - area).abs() < 1e-12);
    }
    // Through the model: a U-shaped OBJ face becomes 6 triangles of total area 7.
    let obj = "v 0 0 0\nv 3 0 0\nv 3 0 3\nv 2 0 3\nv 2 0 1\nv 1 0 1\nv 1 0 3\nv 0 0 3\nf 1 2 3 4 5 6 7 8\n";
    let model = Model::from_obj_str(obj, "u.obj").unwrap();
    let tris = model_triangles(&model);
    assert_eq!(tris.len(), 6);
    let sum: f32 = tris.iter().map(|(t, _)| t.area2() / 2.0).sum();
    assert!((sum - 7.0).abs() < 1e-5);
}

#[test]
fn recording_has_the_interfaces_layout() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("rec");
    let rig = rig();
    let obj = room_obj();
    let traj: Vec<Stamped> = (0..3u64)
        .map(|k| Stamped {
            timestamp_ns: 1_700_000_000_000_000_000 + k * 33_333_333,
            pose: Isometry3::from_parts(
                Translation3::new(1.5 + 0.1 * k as f64, 1.8, 1.5),
                UnitQuaternion::from_euler_angles(0.0, 0.0, 0.2 * k as f64),
            ),
        })
        .collect();
    let mut calls = Vec::new();
    let opts = RecordingOptions {
        appearance: Appearance {
            motion_blur: 0.5,
            motion_blur_samples: 2,
            ..Appearance::default()
        },
        ..Default::default()
    };
    let summary = write_recording(&rec, &rig, &obj, &traj, &opts, |d, t| calls.push((d, t))).unwrap();
    assert_eq!(calls, vec![(1, 3), (2, 3), (3, 3)]);
    assert_eq!((summary.frames, summary.images), (3, 18));

    assert_eq!(Rig::load(&rec.join("rig.toml")).unwrap().sensors.len(), 6);
    assert_eq!(std::fs::read_to_string(rec.join("model.obj")).unwrap(), obj);
    let csv = std::fs::read_to_string(rec.join("frames.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some("frame,sensor,timestamp_ns,path"));
    let rows: Vec<Vec<String>> = lines.map(|l| l.split(',').map(str::to_string).collect()).collect();
    assert_eq!(rows.len(), 3 * 6);
    for row in &rows {
        let (f, s, ts): (u64, usize, u64) = (
            row[0].parse().unwrap(),
            row[1].parse().unwrap(),
            row[2].parse().unwrap(),
        );
        let offset = ts - traj[f as usize].timestamp_ns;
        assert!(offset < 5_000_000, "sensor offset {offset} ns");
        assert_eq!(row[3], format!("sensor{s}/{f:06}.png"));
        let img = image::open(rec.join(&row[3])).unwrap();
        assert_eq!(
            (img.width(), img.height()),
            (rig.sensors[s].width, rig.sensors[s].height)
        );
        assert!(matches!(img, image::DynamicImage::ImageRgb8(_)));
    }
    let back = load_tum(&rec.join("groundtruth.tum")).unwrap();
    assert_eq!(back.len(), traj.len());
    for (a, b) in traj.iter().zip(&back) {
        assert_eq!(a.timestamp_ns, b.timestamp_ns);
        assert!((a.pose.translation.vector - b.pose.translation.vector).norm() < 1e-9);
        assert!(a.pose.rotation.angle_to(&b.pose.rotation) < 1e-9);
    }

    // A bad model names the model path and writes nothing else.
    let bad = dir.path().join("bad");
    let e = write_recording(&bad, &rig, "f 1 2 3\n", &traj, &opts, |_, _| {})
        .unwrap_err()
        .to_string();
    assert!(e.starts_with(&bad.join("model.obj").display().to_string()), "{e}");
    assert_eq!(e.lines().count(), 1);
}

#[test]
fn renders_are_deterministic() {
    let model = Model::from_obj_str(&room_obj(), "room.obj").unwrap();
    let rig = rig();
    let appearance = Appearance {
        seed: 42,
        ..Appearance::default()
    };
    let keep = [Point3::new(2.1, 1.7, 1.45)];
    let f = frame(5, pose());
    let a = Renderer::new(&model, &rig, appearance.clone(), &keep).render_sensor(1, &f);
    if let Ok(dir) = std::env::var("OMNITRACK_RENDER_DUMP") {
        let r = Renderer::new(&model, &rig, appearance.clone(), &keep);
        let all = r.render_frame(&f);
        for (k, img) in all.iter().enumerate() {
            img.save(Path::new(&dir).join(format!("cluttered_sensor{k}.png")))
                .unwrap();
        }
    }
    let b = Renderer::new(&model, &rig, appearance.clone(), &keep).render_sensor(1, &f);
    assert!(a.as_raw() == b.as_raw(), "two renders of one frame differ");
    let c = Renderer::new(&model, &rig, Appearance { seed: 43, ..appearance }, &keep).render_sensor(1, &f);
    assert!(a.as_raw() != c.as_raw(), "the seed changes nothing");
}

/// Several rays per pixel average the light over the pixel's area: where a colour boundary
/// crosses a pixel it gets a blend, elsewhere the value of the one-ray render.
#[test]
fn pixel_samples_blend_colours_across_boundaries_only() {
    let model = Model::from_obj_str(&room_obj(), "room.obj").unwrap();
    let rig = rig();
    let keep = [Point3::new(2.1, 1.7, 1.45)];
    let f = frame(5, pose());
    let render = |n: u32| {
        let appearance = Appearance {
            pixel_samples: n,
            ..Appearance::plain()
        };
        Renderer::new(&model, &rig, appearance, &keep).render_sensor(1, &f)
    };
    let (one, area) = (render(1), render(3));
    let colours = |img: &image::RgbImage| {
        img.pixels()
            .map(|p| p.0)
            .collect::<std::collections::HashSet<_>>()
            .len()
    };
    // Flat surface colours only: one ray per pixel gives one colour per surface seen (and
    // black past the lens's field).
    assert!(colours(&one) <= 8, "{} colours", colours(&one));
    assert!(colours(&area) > 5 * colours(&one), "{} colours", colours(&area));
    let same = one.pixels().zip(area.pixels()).filter(|(a, b)| a == b).count();
    let n = (one.width() * one.height()) as usize;
    assert!(same > n * 95 / 100, "{same} of {n} pixels unchanged");
    assert!(same < n, "nothing blended");
}

#[test]
fn clutter_and_people_are_in_the_images_only() {
    let model = Model::from_obj_str(&room_obj(), "room.obj").unwrap();
    let before = model.clone();
    let rig = rig();
    let keep = [Point3::new(2.1, 1.7, 1.45)];
    let r = Renderer::new(&model, &rig, Appearance::default(), &keep);
    let scene = r.scene();
    assert_eq!(model, before);
    assert_eq!(scene.model_triangles, 12);
    assert!(scene.geometry.triangles.len() > 12);
    let c = scene.clutter_counts;
    assert!(
        [c.furniture, c.shelves, c.posters].iter().all(|&n| n >= 1),
        "{:?}",
        scene.clutter_counts
    );
    assert!(!scene.people.is_empty());
    // People keep clear of the trajectory and walk inside the room.
    for p in &scene.people {
        for t in [0.0, 1.7, 3.1, 10.0] {
            let q = p.position(t);
            assert!(q[0] > 0.0 && q[0] < ROOM.0 && q[1] > 0.0 && q[1] < ROOM.1, "{q:?}");
            assert!(((q[0] - 2.1f64).powi(2) + (q[1] - 1.7f64).powi(2)).sqrt() > 0.6);
        }
    }
    // Nothing of the clutter within 0.6 m of the keep-out point: the view from there is clear.
    for d in [
        Vector3::x(),
        -Vector3::x(),
        Vector3::y(),
        -Vector3::y(),
        Vector3::z(),
        -Vector3::z(),
    ] {
        assert!(r.cast(&keep[0], &d).unwrap().t > 0.6);
    }
}

/// A small two-pinhole rig, cheap to render in a test: up at the ceiling and 45° off it or,
/// with `level`, level and 45° down at the floor.
fn small_rig(level: bool) -> Rig {
    let (first, tilt) = if level {
        (
            "0.7071067811865476, 0.7071067811865476",
            "0.38268343236508984, 0.9238795325112867",
        )
    } else {
        ("1.0, 0.0", "0.9238795325112867, 0.3826834323650898")
    };
    let text = "name = \"small\"\n\n[[sensors]]\nid = 0\nresolution = [160, 120]\nmodel = \"pinhole\"\n\
intrinsics = [90.0, 90.0, 79.5, 59.5]\nrotation_wxyz = [FIRST, 0.0, 0.0]\ntranslation_m = [0.0, 0.0, 0.0]\n\n\
[[sensors]]\nid = 1\nresolution = [160, 120]\nmodel = \"pinhole\"\nintrinsics = [90.0, 90.0, 79.5, 59.5]\n\
rotation_wxyz = [TILT, 0.0, 0.0]\ntranslation_m = [0.0, 0.0, 0.0]\n"
        .replace("FIRST", first)
        .replace("TILT", tilt);
    Rig::from_toml_str(&text, "small rig").unwrap()
}

/// FNV-1a over the bytes: a fingerprint of an image.
fn fingerprint(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xCBF2_9CE4_8422_2325u64, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01B3)
    })
}

/// The lab, a pose of its tour, and the keep-out points of that tour.
fn lab_at(frame_index: usize) -> (Model, Isometry3<f64>, Vec<Point3<f64>>) {
    use omnitrack::desk::scenario::{Scenario, ScenarioName};
    let scenario = Scenario::get(ScenarioName::Lab);
    let model = Model::from_obj_str(&scenario.model_obj().unwrap(), "lab.obj").unwrap();
    let tour = scenario.trajectory(40, 11);
    let keep = tour.iter().map(|s| Point3::from(s.pose.translation.vector)).collect();
    (model, tour[frame_index].pose, keep)
}

/// `Appearance::default()` renders byte for byte what it rendered before the realism levels of
/// issue 19 existed (fingerprints taken from that code): every level is off at 0, so the
/// recordings and figures made with it stay valid.
#[test]
fn default_appearance_renders_as_before_the_realism_levels() {
    let (model, pose, keep) = lab_at(25);
    let r = Renderer::new(&model, &small_rig(false), Appearance::default(), &keep);
    let images = r.render_frame(&frame(25, pose));
    let prints: Vec<u64> = images.iter().map(|i| fingerprint(i.as_raw())).collect();
    eprintln!("fingerprints {prints:x?}");
    assert_eq!(prints, GOLDEN_DEFAULT);
}

const GOLDEN_DEFAULT: [u64; 2] = [0x84ac_c14d_3d72_f65f, 0xd36f_5782_08c6_82b7];

/// A JPEG round trip keeps the image's size and roughly its values, but changes pixels.
#[test]
fn jpeg_round_trip_degrades_but_keeps_the_image() {
    use omnitrack::desk::render::jpeg_round_trip;
    let img = image::RgbImage::from_fn(70, 45, |x, y| {
        if x * 3 + y > 90 {
            image::Rgb([200, 180, 60])
        } else {
            image::Rgb([30, 60, (x * 3) as u8])
        }
    });
    let out = jpeg_round_trip(&img, 60);
    assert_eq!(out.dimensions(), img.dimensions());
    let diffs: Vec<i32> = img
        .as_raw()
        .iter()
        .zip(out.as_raw())
        .map(|(&a, &b)| (i32::from(a) - i32::from(b)).abs())
        .collect();
    assert!(diffs.iter().any(|&d| d > 0), "no pixel changed");
    let mean = diffs.iter().sum::<i32>() as f64 / diffs.len() as f64;
    assert!(mean < 8.0, "mean change {mean}");
}

/// Each realism level, turned on alone over Default, changes the lab's render (each is wired
/// to something the rig sees), and the realistic preset changes most of it.
#[test]
fn each_realism_level_changes_the_render() {
    let (model, pose, keep) = lab_at(25);
    let rig = small_rig(true);
    let render = |a: Appearance| {
        let r = Renderer::new(&model, &rig, a, &keep);
        r.render_frame(&frame(25, pose))
    };
    let base = render(Appearance::default());
    if let Some(dir) = std::env::var_os("OMNITRACK_TEST_PNG") {
        for (k, img) in base.iter().chain(render(Appearance::realistic()).iter()).enumerate() {
            img.save(Path::new(&dir).join(format!("small{k}.png"))).unwrap();
        }
    }
    let changed = |a: Appearance| {
        let imgs = render(a);
        imgs.iter()
            .zip(&base)
            .map(|(x, y)| x.as_raw().iter().zip(y.as_raw()).filter(|(p, q)| p != q).count())
            .sum::<usize>()
    };
    let d = Appearance::default;
    let levels = [
        (
            "floor_pattern",
            Appearance {
                floor_pattern: 1.0,
                ..d()
            },
        ),
        (
            "clutter_texture",
            Appearance {
                clutter_texture: 1.0,
                ..d()
            },
        ),
        ("trims", Appearance { trims: 1.0, ..d() }),
        (
            "wall_offset_m",
            Appearance {
                wall_offset_m: 0.03,
                ..d()
            },
        ),
        (
            "jpeg_quality",
            Appearance {
                jpeg_quality: 85,
                ..d()
            },
        ),
        (
            "lens_falloff",
            Appearance {
                lens_falloff: 0.5,
                ..d()
            },
        ),
        ("paint", Appearance { paint: 0.8, ..d() }),
        ("blur_px", Appearance { blur_px: 1.5, ..d() }),
    ];
    let mut most = 0;
    for (name, a) in levels {
        let n = changed(a);
        eprintln!("{name}: {n} bytes changed");
        assert!(n > 0, "{name} changed nothing");
        most = most.max(n);
    }
    let all = changed(Appearance::realistic());
    let bytes: usize = base.iter().map(|i| i.as_raw().len()).sum();
    assert!(all > bytes / 2, "realistic changed {all} of {bytes} bytes");
    assert!(most > 0);
}
