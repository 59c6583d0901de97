//! Building-model load time: parse + weld + segment extraction of a generated 50,000-face OBJ
//! (unwelded triangles, as many exporters write them). Prints figures; asserts nothing.
//!
//! Run: `cargo bench --bench model_load`

use omnitrack::Model;
use std::fmt::Write;
use std::time::Instant;

/// `n × n` rooms of 4 × 3 × 2.7 m on a grid, each a closed box with a door cut in one wall,
/// every polygon triangulated and every triangle given its own vertices.
fn building(n: usize) -> (String, usize) {
    let mut obj = String::from("# generated\n");
    let mut faces = 0;
    let mut tri = |obj: &mut String, a: [f64; 3], b: [f64; 3], c: [f64; 3]| {
        for p in [a, b, c] {
            let _ = writeln!(obj, "v {} {} {}", p[0], p[1], p[2]);
        }
        obj.push_str("f -3 -2 -1\n");
        faces += 1;
    };
    for i in 0..n {
        for j in 0..n {
            let (x, y) = (i as f64 * 4.2, j as f64 * 3.2);
            let p = |dx: f64, dy: f64, z: f64| [x + dx, y + dy, z];
            let (w, d, h) = (4.0, 3.0, 2.7);
            let quads = [
                [p(0., 0., 0.), p(w, 0., 0.), p(w, d, 0.), p(0., d, 0.)],
                [p(0., 0., h), p(0., d, h), p(w, d, h), p(w, 0., h)],
                [p(w, 0., 0.), p(w, d, 0.), p(w, d, h), p(w, 0., h)],
                [p(w, d, 0.), p(0., d, 0.), p(0., d, h), p(w, d, h)],
                [p(0., d, 0.), p(0., 0., 0.), p(0., 0., h), p(0., d, h)],
                // The y = 0 wall around a 1 m × 2.1 m door at x ∈ [1.5, 2.5].
                [p(0., 0., 0.), p(1.5, 0., 0.), p(1.5, 0., h), p(0., 0., h)],
                [p(2.5, 0., 0.), p(w, 0., 0.), p(w, 0., h), p(2.5, 0., h)],
                [p(1.5, 0., 2.1), p(2.5, 0., 2.1), p(2.5, 0., h), p(1.5, 0., h)],
            ];
            for q in quads {
                tri(&mut obj, q[0], q[1], q[2]);
                tri(&mut obj, q[0], q[2], q[3]);
            }
        }
    }
    (obj, faces)
}

fn main() {
    let (obj, faces) = building(56);
    println!(
        "model_load: {faces} faces, {:.1} MB of OBJ text",
        obj.len() as f64 / 1e6
    );
    let mut times = Vec::new();
    let mut model = None;
    for _ in 0..7 {
        let t = Instant::now();
        let m = Model::from_obj_str(&obj, "generated.obj").expect("generated model loads");
        times.push(t.elapsed().as_secs_f64() * 1e3);
        model = Some(m);
    }
    let m = model.unwrap();
    times.sort_by(f64::total_cmp);
    println!(
        "model_load: {} vertices after welding, {} faces, {} segments",
        m.vertices.len(),
        m.faces.len(),
        m.segments.len()
    );
    println!(
        "model_load: parse + weld + segments: median {:.1} ms, min {:.1} ms, max {:.1} ms (7 runs)",
        times[3], times[0], times[6]
    );
}
