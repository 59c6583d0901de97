//! Edge + hue extraction: exact planes of known great circles, one edge for a strongly curved
//! fisheye line, two edges for two lines end to end a pixel and a half apart (two-line test),
//! a gap bridged only where the image shows the line (`merge_gap_evidence`),
//! hue strips (wrap-around at red, unsaturated pixels left out), blank images, the CSV, and zero
//! heap allocations per frame after warm-up (counting allocator).

use nalgebra::{Point2, Vector3};
use omnitrack_config::EdgeConfig;
use omnitrack_core::frame::{FrameSet, SensorImage};
use omnitrack_core::Rig;
use omnitrack_edges::{edges_csv, Edge, EdgeDetector, EdgeParams, EDGES_CSV_HEADER};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Mutex, MutexGuard};

/// Counts allocations while `COUNTING` is on, on every thread but the test harness's.
struct Counting;
static COUNTING: AtomicBool = AtomicBool::new(false);
static ALLOCS: AtomicUsize = AtomicUsize::new(0);
/// Allocations while counting by threads other than the one that counts (the edge workers).
static OTHER_THREAD: AtomicUsize = AtomicUsize::new(0);
static LAST_SIZE: AtomicUsize = AtomicUsize::new(0);
thread_local! {
    static COUNTER_THREAD: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if COUNTING.load(Ordering::Relaxed) && !omnitrack_testkit::on_harness_thread() {
            ALLOCS.fetch_add(1, Ordering::Relaxed);
            LAST_SIZE.store(layout.size(), Ordering::Relaxed);
            if !COUNTER_THREAD.with(|c| c.get()) {
                OTHER_THREAD.fetch_add(1, Ordering::Relaxed);
            }
        }
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if COUNTING.load(Ordering::Relaxed) && !omnitrack_testkit::on_harness_thread() {
            ALLOCS.fetch_add(1, Ordering::Relaxed);
        }
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// The tests of this file run one at a time, so that the allocation count sees one test only.
static SERIAL: Mutex<()> = Mutex::new(());

fn serial() -> MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|e| e.into_inner())
}

fn rig() -> Rig {
    omnitrack_testkit::shipped_rig()
}

/// Renders sensor `k` of the rig: `colour(ray)` for the sensor-frame unit ray of each pixel,
/// supersampled 4×4 where the ray is within ~3 px of one of the `boundaries` great circles
/// (given by their sensor-frame normals), so that those edges are anti-aliased.
fn render(rig: &Rig, k: usize, boundaries: &[Vector3<f64>], colour: impl Fn(&Vector3<f64>) -> [f64; 3]) -> SensorImage {
    let s = &rig.sensors[k];
    let mut img = SensorImage::new(k, s.width, s.height);
    let w = s.width as usize;
    let px = img.pixels_mut();
    for v in 0..s.height as usize {
        for u in 0..w {
            let centre = s.lens.unproject(&Point2::new(u as f64, v as f64)).expect("ray");
            let near = boundaries.iter().any(|n| n.dot(&centre).abs() < 0.012);
            let mut acc = [0.0; 3];
            let ss = if near { 4 } else { 1 };
            for i in 0..ss {
                for j in 0..ss {
                    let (du, dv) = if near {
                        ((i as f64 + 0.5) / 4.0 - 0.5, (j as f64 + 0.5) / 4.0 - 0.5)
                    } else {
                        (0.0, 0.0)
                    };
                    let r = s
                        .lens
                        .unproject(&Point2::new(u as f64 + du, v as f64 + dv))
                        .expect("ray");
                    let c = colour(&r);
                    for q in 0..3 {
                        acc[q] += c[q];
                    }
                }
            }
            for q in 0..3 {
                px[(v * w + u) * 3 + q] = (acc[q] / (ss * ss) as f64).round().clamp(0.0, 255.0) as u8;
            }
        }
    }
    img.set_valid(1);
    img
}

fn angle_deg(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    a.dot(b).abs().min(1.0).acos().to_degrees()
}

/// The detected edge whose plane is closest to the rig-frame normal `n`.
fn closest<'a>(edges: &'a [Edge], n: &Vector3<f64>) -> Option<(&'a Edge, f64)> {
    edges
        .iter()
        .map(|e| (e, angle_deg(&e.plane.normal, n)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
}

/// A spherical quadrilateral (the four planes' intersection) on a two-colour background: its
/// four sides are great-circle arcs with exactly known planes.
#[test]
fn known_great_circles_recovered_to_0_05_deg() {
    let _g = serial();
    let rig = rig();
    let k = 0;
    let s = &rig.sensors[k];
    let normals: Vec<Vector3<f64>> = [
        Vector3::new(1.0, 0.05, 0.35),   // left side, tilted
        Vector3::new(-1.0, 0.08, 0.30),  // right side
        Vector3::new(0.03, 1.0, 0.45),   // top
        Vector3::new(-0.06, -1.0, 0.40), // bottom
    ]
    .iter()
    .map(|n| n.normalize())
    .collect();
    let img = render(&rig, k, &normals, |r| {
        if normals.iter().all(|n| n.dot(r) > 0.0) {
            [200.0, 170.0, 60.0]
        } else {
            [40.0, 60.0, 110.0]
        }
    });
    let mut det = EdgeDetector::new(&rig, &EdgeConfig::default());
    let edges = det.detect_sensor(&img).to_vec();
    assert!(!edges.is_empty());
    for n in &normals {
        let n_rig = s.t_rig_sensor.rotation * n;
        let (e, err) = closest(&edges, &n_rig).expect("an edge");
        assert!(err <= 0.05, "plane {n:?}: closest edge {err:.4}° off ({e:?})");
        assert!(e.length_rad.to_degrees() > 10.0, "the side is one long edge: {e:?}");
        assert_eq!(e.sensor as usize, k);
        assert!((e.plane.centre - s.centre()).norm() < 1e-12);
        // End rays lie in the plane and map to the pixel ends.
        for (r, px) in e.plane.ends.iter().zip(&e.px) {
            assert!(e.plane.normal.dot(r).abs() < 1e-9);
            let p = s
                .project_from_rig(&(s.centre() + r.into_inner()))
                .expect("on the image");
            assert!((p - px).norm() < 1e-6);
        }
    }
    // Nothing else in the image: exactly the four sides.
    assert_eq!(edges.len(), 4, "{edges:#?}");
}

/// A straight 3D line far off the optical axis: strongly curved in the fisheye image, yet one
/// edge on one plane.
#[test]
fn curved_fisheye_line_is_one_edge() {
    let _g = serial();
    let rig = rig();
    let k = 0;
    let s = &rig.sensors[k];
    let a = 40f64.to_radians();
    let n = Vector3::new(0.0, a.cos(), -a.sin());
    let img = render(&rig, k, &[n], |r| {
        if n.dot(r) > 0.0 {
            [70.0, 150.0, 90.0]
        } else {
            [190.0, 120.0, 150.0]
        }
    });
    let mut det = EdgeDetector::new(&rig, &EdgeConfig::default());
    let edges = det.detect_sensor(&img).to_vec();
    assert_eq!(edges.len(), 1, "{edges:#?}");
    let e = &edges[0];
    let n_rig = s.t_rig_sensor.rotation * n;
    let err = angle_deg(&e.plane.normal, &n_rig);
    assert!(err < 0.05, "normal {err:.4}° off");
    // The edge is strongly curved on the image: its middle is far from the chord of its ends.
    let mid = (e.plane.ends[0].into_inner() + e.plane.ends[1].into_inner()).normalize();
    let pm = s.project_from_rig(&(s.centre() + mid)).expect("middle on the image");
    let (p1, p2) = (e.px[0], e.px[1]);
    let chord = p2 - p1;
    let sag = ((pm - p1).x * chord.y - (pm - p1).y * chord.x).abs() / chord.norm();
    assert!(
        sag > 20.0,
        "sagitta {sag:.1} px: the test line should be strongly curved"
    );
    assert!(chord.norm() > 300.0, "the edge spans the image: {e:?}");
}

/// A wall's corner continued, a pixel and a half aside, by the edge of a box standing in front of
/// it (the same colours on both sides, so no edge marks the junction): with the two-line test
/// on (`EdgeParams::two_line_excess`), two lines, each found on its own plane, not one edge
/// tilted between them.
#[test]
fn two_lines_a_pixel_and_a_half_apart_end_to_end_are_two_edges() {
    let _g = serial();
    let rig = rig();
    let k = 0;
    let s = &rig.sensors[k];
    // Near-vertical lines ~28 px left of the centre; the lower one 0.005 / 0.1 of that further
    // left: ≈ 1.4 px at f = 285.
    let upper = Vector3::new(1.0, 0.02, 0.1).normalize();
    let lower = Vector3::new(1.0, 0.02, 0.105).normalize();
    let side = |r: &Vector3<f64>| if r.y < 0.0 { upper.dot(r) } else { lower.dot(r) };
    let img = render(&rig, k, &[upper, lower], |r| {
        if side(r) > 0.0 {
            [190.0, 150.0, 80.0]
        } else {
            [60.0, 80.0, 130.0]
        }
    });
    let params = EdgeParams {
        two_line_excess: 0.3,
        ..EdgeParams::default()
    };
    let mut det = EdgeDetector::with_params(&rig, &EdgeConfig::default(), params);
    let edges = det.detect_sensor(&img).to_vec();
    let worst = |edges: &[Edge]| {
        let mut worst = 0.0f64;
        for (name, n) in [("upper", upper), ("lower", lower)] {
            let (e, err) = closest(edges, &(s.t_rig_sensor.rotation * n)).expect("an edge");
            assert!(e.length_rad.to_degrees() > 20.0, "{name} line: {e:?}");
            worst = worst.max(err);
        }
        worst
    };
    let err = worst(&edges);
    assert!(err <= 0.05, "a line's closest edge is {err:.4}° off ({edges:#?})");
    // The default has it on; with it off, one edge runs between the two.
    assert_eq!(EdgeParams::default().two_line_excess, params.two_line_excess);
    let off = EdgeParams {
        two_line_excess: 0.0,
        ..EdgeParams::default()
    };
    let mut det = EdgeDetector::with_params(&rig, &EdgeConfig::default(), off);
    let edges = det.detect_sensor(&img).to_vec();
    let err = worst(&edges);
    assert!(err > 0.1, "{err:.4}°: the lines should blend without the two-line test");
}

/// One straight line drawn in two stretches with a gap of about 7° between them: across plain
/// wall (both sides one colour) the two pieces stay apart when `merge_gap_evidence` asks the
/// image to show the line across the gap, and merge when it does not; across a faint stretch of
/// the same line (7 grey levels, under the edgel threshold) they merge either way.
#[test]
fn a_gap_merges_only_where_the_image_shows_the_line() {
    let _g = serial();
    let rig = rig();
    let k = 0;
    let s = &rig.sensors[k];
    let n = Vector3::new(1.0, 0.02, 0.1).normalize();
    let in_gap = |r: &Vector3<f64>| (r.y / r.z).abs() < 0.06;
    let draw = |faint: bool| {
        render(&rig, k, &[n], |r| {
            let left = n.dot(r) > 0.0;
            match (in_gap(r), faint, left) {
                (false, _, true) => [190.0, 150.0, 80.0],
                (false, _, false) => [60.0, 80.0, 130.0],
                (true, false, _) => [125.0, 115.0, 105.0],
                (true, true, true) => [128.0, 118.0, 108.0],
                (true, true, false) => [121.0, 111.0, 101.0],
            }
        })
    };
    let n_rig = s.t_rig_sensor.rotation * n;
    let longest = |img: &SensorImage, evidence: f64| {
        let params = EdgeParams {
            merge_gap_evidence: evidence,
            ..EdgeParams::default()
        };
        let mut det = EdgeDetector::with_params(&rig, &EdgeConfig::default(), params);
        let edges = det.detect_sensor(img).to_vec();
        edges
            .iter()
            .filter(|e| angle_deg(&e.plane.normal, &n_rig) < 0.5)
            .map(|e| e.length_rad.to_degrees())
            .fold(0.0f64, f64::max)
    };
    let plain = draw(false);
    let (apart, merged) = (longest(&plain, 0.9), longest(&plain, 0.0));
    assert!(
        merged > apart + 5.0,
        "across plain wall: {apart:.1}° with the check, {merged:.1}° without"
    );
    let faint = draw(true);
    let shown = longest(&faint, 0.9);
    assert!(
        shown > merged - 1.0,
        "across a faint line: {shown:.1}° with the check, {merged:.1}° merged over plain wall"
    );
}

/// Colour of a hue in [0,1) at full saturation and value 200.
fn hsv(h: f64) -> [f64; 3] {
    let h6 = h.rem_euclid(1.0) * 6.0;
    let x = 1.0 - (h6 % 2.0 - 1.0).abs();
    let (r, g, b) = match h6 as u32 {
        0 => (1.0, x, 0.0),
        1 => (x, 1.0, 0.0),
        2 => (0.0, 1.0, x),
        3 => (0.0, x, 1.0),
        4 => (x, 0.0, 1.0),
        _ => (1.0, 0.0, x),
    };
    [r * 200.0, g * 200.0, b * 200.0]
}

fn circ_dist(a: f32, b: f32) -> f32 {
    let d = (a - b).rem_euclid(1.0);
    d.min(1.0 - d)
}

/// The plane x = 0 (sensor frame) is the image column through the principal point. One side
/// alternates hues 0.97 / 0.03 pixel by pixel (mean at red, across the wrap), the other is
/// green (hue 1/3); then one side grey (no hue: left out, kept fraction 0).
#[test]
fn hue_strips_wrap_around_red() {
    let _g = serial();
    let rig = rig();
    let k = 0;
    let s = &rig.sensors[k];
    let n = Vector3::new(1.0, 0.0, 0.0);
    let mut img = render(&rig, k, &[n], |r| if r.x < 0.0 { [0.0; 3] } else { hsv(1.0 / 3.0) });
    // Checkerboard of hues 0.97 / 0.03 on the x < 0 side (columns u ≤ 191).
    let w = s.width as usize;
    for v in 0..s.height as usize {
        for u in 0..w {
            if u < 192 {
                let c = hsv(if (u + v) % 2 == 0 { 0.97 } else { 0.03 });
                for (q, &cq) in c.iter().enumerate() {
                    img.pixels_mut()[(v * w + u) * 3 + q] = cq as u8;
                }
            }
        }
    }
    let mut det = EdgeDetector::new(&rig, &EdgeConfig::default());
    let edges = det.detect_sensor(&img).to_vec();
    let n_rig = s.t_rig_sensor.rotation * n;
    let (e, err) = closest(&edges, &n_rig).expect("the edge");
    assert!(err < 0.1, "{err}");
    // Which side is "left": the side of (v2 − v1, −(u2 − u1)).
    let left_dir_u = e.px[1].y - e.px[0].y;
    let (red, green) = if left_dir_u < 0.0 {
        (
            (e.hue.left_mean, e.hue.left_var, e.hue.left_kept),
            (e.hue.right_mean, e.hue.right_var, e.hue.right_kept),
        )
    } else {
        (
            (e.hue.right_mean, e.hue.right_var, e.hue.right_kept),
            (e.hue.left_mean, e.hue.left_var, e.hue.left_kept),
        )
    };
    assert!(
        circ_dist(red.0, 0.0) < 0.005,
        "red side mean {} (must wrap to ~0, not 0.5)",
        red.0
    );
    assert!(red.0 >= 0.0 && red.0 < 1.0);
    // Hues ±0.03 around red: variance ≈ 0.03² = 9e-4.
    assert!((red.1 - 9e-4).abs() < 3e-4, "red side variance {}", red.1);
    assert!(circ_dist(green.0, 1.0 / 3.0) < 0.005, "green side mean {}", green.0);
    assert!(green.1 < 1e-4, "green side variance {}", green.1);
    assert!(red.2 > 0.99 && green.2 > 0.99);

    // Grey on one side: no hue there, kept fraction 0, mean NaN.
    let img = render(&rig, k, &[n], |r| if r.x < 0.0 { [120.0; 3] } else { hsv(0.6) });
    let edges = det.detect_sensor(&img).to_vec();
    let (e, _) = closest(&edges, &n_rig).expect("the edge");
    let left_dir_u = e.px[1].y - e.px[0].y;
    let (grey_mean, grey_kept, blue_mean) = if left_dir_u < 0.0 {
        (e.hue.left_mean, e.hue.left_kept, e.hue.right_mean)
    } else {
        (e.hue.right_mean, e.hue.right_kept, e.hue.left_mean)
    };
    assert_eq!(grey_kept, 0.0);
    assert!(grey_mean.is_nan());
    assert!(circ_dist(blue_mean, 0.6) < 0.005, "{blue_mean}");
}

#[test]
fn blank_and_invalid_images_give_no_edges() {
    let _g = serial();
    let rig = rig();
    let mut det = EdgeDetector::new(&rig, &EdgeConfig::default());
    let mut frame = FrameSet::for_rig(&rig);
    for value in [0u8, 255] {
        for img in frame.sensors_mut() {
            img.pixels_mut().fill(value);
            img.set_valid(0);
        }
        assert!(det.detect(&frame).is_empty(), "uniform {value}");
    }
    // Noise only, below the gradient threshold.
    for img in frame.sensors_mut() {
        for (i, p) in img.pixels_mut().iter_mut().enumerate() {
            *p = 100 + ((i * 2654435761) >> 13 & 3) as u8;
        }
    }
    assert!(det.detect(&frame).is_empty());
    // An invalid image, and an image of the wrong size, are skipped.
    let img = SensorImage::new(0, 384, 512);
    assert!(det.detect_sensor(&img).is_empty());
    let mut small = SensorImage::new(1, 10, 10);
    small.set_valid(0);
    assert!(det.detect_sensor(&small).is_empty());
}

#[test]
fn csv_header_and_columns() {
    let _g = serial();
    let rig = rig();
    let n = Vector3::new(1.0, 0.0, 0.0);
    let img = render(&rig, 2, &[n], |r| {
        if r.x < 0.0 {
            [30.0, 30.0, 160.0]
        } else {
            [200.0, 200.0, 40.0]
        }
    });
    let mut det = EdgeDetector::new(&rig, &EdgeConfig::default());
    let edges = det.detect_sensor(&img).to_vec();
    let csv = edges_csv(&edges, &rig);
    let mut lines = csv.lines();
    let header = lines.next().unwrap();
    assert_eq!(header, EDGES_CSV_HEADER);
    assert!(header.starts_with("u1,v1,u2,v2,hue_left_mean,hue_left_var,hue_right_mean,hue_right_var"));
    let cols = header.split(',').count();
    let rows: Vec<&str> = lines.collect();
    assert_eq!(rows.len(), edges.len());
    for (row, e) in rows.iter().zip(&edges) {
        let f: Vec<&str> = row.split(',').collect();
        assert_eq!(f.len(), cols);
        assert!((f[0].parse::<f64>().unwrap() - e.px[0].x).abs() < 1e-3);
        assert_eq!(f[8], "2");
    }
}

/// A line broken by an occluder is one edge (its plane fitted to both pieces) that remembers the
/// gap: the occluder lies in it, and the CSV's `pieces` column gives the two pieces on either
/// side.
#[test]
fn a_line_broken_by_an_occluder_is_one_edge_with_its_gap() {
    let _g = serial();
    let rig = rig();
    let n = Vector3::new(1.0, 0.0, 0.0);
    let band = |r: &Vector3<f64>| (r.y - 0.1).abs() < 0.04;
    let img = render(&rig, 2, &[n], |r| {
        if band(r) {
            [110.0, 110.0, 110.0]
        } else if r.x < 0.0 {
            [30.0, 30.0, 160.0]
        } else {
            [200.0, 200.0, 40.0]
        }
    });
    let mut det = EdgeDetector::new(&rig, &EdgeConfig::default());
    let edges = det.detect_sensor(&img).to_vec();
    let to_sensor = rig.sensors[2].t_rig_sensor.rotation.inverse();
    let line = edges
        .iter()
        .find(|e| (to_sensor * e.plane.normal.into_inner()).x.abs() > 0.999)
        .expect("the broken line is one edge");
    assert_eq!(line.gaps().len(), 1, "one gap: {:?}", line.gaps());
    let [t0, t1] = line.gaps()[0].map(f64::from);
    // The occluder spans 0.08 rad; the gap is the occluder, give or take the pixels the
    // edgels next to it lose.
    assert!((t1 - t0 - 0.08).abs() < 0.02, "gap {t0}..{t1}");
    let mid = to_sensor * line.ray_at(0.5 * (t0 + t1));
    assert!(band(&mid), "the middle of the gap {mid:?} is on the occluder");
    for t in [t0 - 0.01, t1 + 0.01] {
        assert!(
            !band(&(to_sensor * line.ray_at(t))),
            "{t} rad is on the line, not the occluder"
        );
    }
    let pieces: Vec<[f64; 2]> = line.pieces().collect();
    assert_eq!(pieces, vec![[0.0, t0], [t1, line.length_rad]]);
    // In the CSV: two pieces, from the edge's own first end to its own last.
    let csv = edges_csv(std::slice::from_ref(line), &rig);
    let row = csv.lines().nth(1).expect("a row");
    let groups: Vec<Vec<f64>> = row
        .rsplit(',')
        .next()
        .expect("pieces column")
        .split(';')
        .map(|g| g.split(' ').map(|x| x.parse().expect("number")).collect())
        .collect();
    assert_eq!(groups.len(), 2, "{row}");
    assert!((groups[0][0] - line.px[0].x).abs() < 1e-3 && (groups[0][1] - line.px[0].y).abs() < 1e-3);
    assert!((groups[1][2] - line.px[1].x).abs() < 1e-3 && (groups[1][3] - line.px[1].y).abs() < 1e-3);
    // The pieces' inner ends lie on the line, either side of the occluder's rows.
    let s = &rig.sensors[2];
    let rows = |v: f64| {
        s.lens
            .unproject(&nalgebra::Point2::new(line.px[0].x, v))
            .expect("ray")
            .y
    };
    let (inner_a, inner_b) = (rows(groups[0][3]), rows(groups[1][1]));
    assert!(
        inner_a.min(inner_b) < 0.07 && inner_a.max(inner_b) > 0.13,
        "{inner_a} {inner_b}"
    );
    // A line the image shows whole has no gaps and an empty pieces column.
    let whole = render(&rig, 2, &[n], |r| {
        if r.x < 0.0 {
            [30.0, 30.0, 160.0]
        } else {
            [200.0, 200.0, 40.0]
        }
    });
    let edges = det.detect_sensor(&whole).to_vec();
    let line = edges
        .iter()
        .find(|e| (to_sensor * e.plane.normal.into_inner()).x.abs() > 0.999)
        .expect("the line");
    assert!(line.gaps().is_empty());
    assert!(edges_csv(std::slice::from_ref(line), &rig)
        .lines()
        .nth(1)
        .expect("row")
        .ends_with(','));
}

/// Two frames of six images with content (polygons in every sensor).
fn polygon_frames(rig: &Rig) -> Vec<FrameSet> {
    (0..2)
        .map(|f| {
            let mut fs = FrameSet::for_rig(rig);
            for k in 0..rig.sensors.len() {
                let t = 0.1 * (k + 3 * f) as f64;
                let normals: Vec<Vector3<f64>> = [
                    Vector3::new(1.0, t, 0.4),
                    Vector3::new(-1.0, 0.1, 0.35 + t),
                    Vector3::new(t, 1.0, 0.5),
                    Vector3::new(0.0, -1.0, 0.3),
                ]
                .iter()
                .map(|n| n.normalize())
                .collect();
                let img = render(rig, k, &normals, |r| {
                    let inside = normals.iter().all(|n| n.dot(r) > 0.0);
                    match (inside, r.y > 0.3) {
                        (true, _) => [210.0, 80.0, 60.0],
                        (false, true) => [60.0, 60.0, 60.0],
                        (false, false) => [90.0, 140.0, 200.0],
                    }
                });
                fs.sensor_mut(k).pixels_mut().copy_from_slice(img.pixels());
                fs.sensor_mut(k).set_valid(0);
            }
            fs
        })
        .collect()
}

/// Six images with content (polygons in every sensor), two different frames alternating: after
/// warm-up, `detect` performs no heap allocation at all (worker threads included).
#[test]
fn zero_allocations_per_frame_after_warm_up() {
    let _g = serial();
    let rig = rig();
    let config = EdgeConfig::default();
    let mut frames = polygon_frames(&rig);
    // One sensor missing from a frame: still no allocation.
    frames[1]
        .sensor_mut(3)
        .set_invalid(omnitrack_core::frame::ImageFault::Dropped, 0);
    // The two-line test's cuts and refused merges take the same pre-sized buffers.
    for (threads, two_line_excess) in [(2, 0.0), (1, 0.0), (2, 0.3)] {
        let params = EdgeParams {
            threads,
            two_line_excess,
            ..EdgeParams::default()
        };
        let mut det = EdgeDetector::with_params(&rig, &config, params);
        for fs in &frames {
            det.detect(fs);
        }
        let mut total = 0;
        for i in 0..20 {
            ALLOCS.store(0, Ordering::SeqCst);
            COUNTING.store(true, Ordering::SeqCst);
            let n = det.detect(&frames[i % 2]).len();
            COUNTING.store(false, Ordering::SeqCst);
            total += ALLOCS.load(Ordering::SeqCst);
            assert!(n > 0);
        }
        assert_eq!(
            total,
            0,
            "{threads} threads: {total} allocations in 20 frames, {} on other threads, last of {} bytes",
            OTHER_THREAD.load(Ordering::SeqCst),
            LAST_SIZE.load(Ordering::SeqCst)
        );
    }
}

/// `last_cpu` charges every thread's work on the frame: at least the CPU time of every sensor's
/// phases (timed on whichever thread ran it), and at least what the calling thread spent.
#[test]
fn detect_reports_the_cpu_time_of_every_thread() {
    let _g = serial();
    let rig = rig();
    let frames = polygon_frames(&rig);
    for threads in [1, 2] {
        let params = EdgeParams {
            threads,
            ..EdgeParams::default()
        };
        let mut det = EdgeDetector::with_params(&rig, &EdgeConfig::default(), params);
        assert_eq!(det.last_cpu(), std::time::Duration::ZERO);
        let (mut charged, mut spent) = (std::time::Duration::ZERO, std::time::Duration::ZERO);
        for fs in frames.iter().cycle().take(6) {
            let before = omnitrack_edges::thread_cpu_time();
            det.detect(fs);
            let caller = omnitrack_edges::thread_cpu_time() - before;
            let phases: u64 = (0..rig.sensors.len())
                .map(|k| {
                    let s = det.sensor_stats(k);
                    [s.pixel_ns, s.chain_ns, s.merge_ns, s.select_ns]
                        .map(u64::from)
                        .iter()
                        .sum::<u64>()
                })
                .sum();
            let cpu = det.last_cpu();
            assert!(phases > 0, "{threads} threads: no phase time");
            assert!(
                cpu.as_nanos() as u64 >= phases,
                "{threads} threads: detect charged {cpu:?}, its sensors' phases took {phases} ns"
            );
            charged += cpu;
            spent += caller;
        }
        // The caller's clock also runs outside `detect`'s own readings (the call, two clock
        // reads), and an interrupt handled there is charged to it: one such frame was 0.1 ms
        // over (CI, 2026-12-02). Over six frames the charge must cover all but 5 % of what the
        // caller spent; a `last_cpu` that left out the caller's share (all of it with one thread)
        // falls far below.
        assert!(
            charged >= spent.mul_f64(0.95),
            "{threads} threads: detect charged {charged:?} over six frames, the caller spent {spent:?}"
        );
    }
}

/// The tracker's detector gives the same edges, field for field, as the line detector's, but
/// for the pieces shown: every piece between the gaps, untested.
#[test]
fn the_trackers_edges_are_the_line_detectors_less_the_tested_pieces() {
    let _g = serial();
    let rig = rig();
    let frames = polygon_frames(&rig);
    let mut full = EdgeDetector::new(&rig, &EdgeConfig::default());
    let mut tracking = EdgeDetector::for_tracking(&rig, &EdgeConfig::default());
    for fs in &frames {
        let a = full.detect(fs).to_vec();
        let b = tracking.detect(fs);
        assert!(!a.is_empty());
        assert_eq!(a.len(), b.len());
        for (x, y) in a.iter().zip(b) {
            let between: Vec<[f32; 2]> = (0..=y.gaps().len())
                .map(|k| {
                    let from = if k == 0 { 0.0 } else { y.gaps()[k - 1][1] };
                    let to = y.gaps().get(k).map_or(y.length_rad as f32, |g| g[0]);
                    [from, to]
                })
                .collect();
            assert_eq!(y.shown(), &between[..], "every piece between the gaps");
            let untested = Edge {
                shown: y.shown,
                n_shown: y.n_shown,
                ..*x
            };
            // Debug text, not ==: a strip without hue has a NaN mean, bit for bit the same.
            assert_eq!(format!("{untested:?}"), format!("{y:?}"));
        }
    }
}

/// A rig whose sensors differ in size: one thread runs them all on one set of scratch buffers
/// (sized for the largest, cleared when the size changes), and every sensor's edges are those
/// a detector of its own gives on fresh buffers.
#[test]
fn sensors_of_several_sizes_share_a_threads_buffers() {
    let _g = serial();
    let sensor = |id: usize, (w, h): (u32, u32), yaw_deg: f64| {
        let (s, c) = (yaw_deg.to_radians() / 2.0).sin_cos();
        format!(
            "[[sensors]]\nid = {id}\nresolution = [{w}, {h}]\nmodel = \"pinhole\"\n\
intrinsics = [{f}, {f}, {cx}, {cy}]\nrotation_wxyz = [{c}, 0.0, {s}, 0.0]\ntranslation_m = [0.0, 0.0, 0.0]\n\n",
            f = 0.6 * w as f64,
            cx = (w as f64 - 1.0) / 2.0,
            cy = (h as f64 - 1.0) / 2.0,
        )
    };
    let text = format!(
        "name = \"sizes\"\n\n{}{}{}",
        sensor(0, (320, 240), 0.0),
        sensor(1, (200, 150), 120.0),
        sensor(2, (320, 240), 240.0)
    );
    let rig = Rig::from_toml_str(&text, "(test rig)").expect("rig");
    // Bands of colour between great circles all round the rig: busy images, edges up to every
    // border.
    let normals: Vec<Vector3<f64>> = (0..7)
        .map(|k| {
            let a = k as f64 * 0.9;
            Vector3::new(a.cos(), 0.35 * (k as f64 - 3.0), a.sin()).normalize()
        })
        .collect();
    let colour = |r: &Vector3<f64>| {
        let code = normals
            .iter()
            .enumerate()
            .fold(0u32, |c, (k, n)| c | (u32::from(n.dot(r) > 0.0) << k));
        [
            (37 * code % 200 + 30) as f64,
            (91 * code % 200 + 30) as f64,
            (53 * code % 200 + 30) as f64,
        ]
    };
    let mut frame = FrameSet::for_rig(&rig);
    for k in 0..3 {
        // The boundaries in sensor k's frame: the sensor's rotation from the rig's.
        let q = rig.sensors[k].t_rig_sensor.rotation;
        let local: Vec<Vector3<f64>> = normals.iter().map(|n| q.inverse() * n).collect();
        let img = render(&rig, k, &local, |r| colour(&(q * r)));
        *frame.sensor_mut(k) = img;
    }
    let params = EdgeParams {
        threads: 1,
        ..EdgeParams::default()
    };
    let config = EdgeConfig::default();
    let mut shared = EdgeDetector::with_params(&rig, &config, params);
    // Twice: the second frame starts on buffers the last (large) sensor left behind.
    for pass in 0..2 {
        shared.detect(&frame);
        for k in 0..3 {
            let mut alone = EdgeDetector::with_params(&rig, &config, params);
            let want = alone.detect_sensor(frame.sensor(k)).to_vec();
            let got = shared.sensor_edges(k);
            assert!(!want.is_empty(), "sensor {k}: no edges to compare");
            assert_eq!(got.len(), want.len(), "pass {pass}, sensor {k}: edge count");
            for (g, w) in got.iter().zip(&want) {
                assert_eq!(
                    g.plane.normal, w.plane.normal,
                    "pass {pass}, sensor {k}: an edge differs"
                );
            }
        }
    }
}
