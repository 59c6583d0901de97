//! Desk renderer speed: six-sensor frames (the shipped ladybug2 rig, 384×512 per sensor) of a
//! generated ~5,200-face building, with the default appearance, with every effect off, and with
//! each effect alone on top of "off". Prints figures; asserts nothing.
//!
//! Run: `cargo bench --bench render` (needs the `desk` feature, on by default).

#[cfg(feature = "desk")]
mod bench {
    use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};
    use omnitrack::desk::render::{Appearance, FrameSpec, Renderer};
    use omnitrack::trajectory::Stamped;
    use omnitrack::{Model, Rig};
    use std::fmt::Write;
    use std::path::Path;
    use std::time::Instant;

    /// `n × n` rooms of 4 × 3 × 2.7 m on a grid, each a closed box with a door cut in one wall,
    /// every polygon triangulated, faces under usemtl floor / ceiling / wall / door_reveal.
    fn building(n: usize) -> (String, usize) {
        let mut obj = String::from("# generated\n");
        let mut faces = 0;
        let mut nv = 0;
        for i in 0..n {
            for j in 0..n {
                let (x, y) = (i as f64 * 4.2, j as f64 * 3.2);
                let p = |dx: f64, dy: f64, z: f64| [x + dx, y + dy, z];
                let (w, d, h) = (4.0, 3.0, 2.7);
                let quads = [
                    ("floor", [p(0., 0., 0.), p(w, 0., 0.), p(w, d, 0.), p(0., d, 0.)]),
                    ("ceiling", [p(0., 0., h), p(0., d, h), p(w, d, h), p(w, 0., h)]),
                    ("wall", [p(w, 0., 0.), p(w, d, 0.), p(w, d, h), p(w, 0., h)]),
                    ("wall", [p(w, d, 0.), p(0., d, 0.), p(0., d, h), p(w, d, h)]),
                    ("wall", [p(0., d, 0.), p(0., 0., 0.), p(0., 0., h), p(0., d, h)]),
                    // The y = 0 wall around a 1 m × 2.1 m door at x ∈ [1.5, 2.5].
                    ("wall", [p(0., 0., 0.), p(1.5, 0., 0.), p(1.5, 0., h), p(0., 0., h)]),
                    ("wall", [p(2.5, 0., 0.), p(w, 0., 0.), p(w, 0., h), p(2.5, 0., h)]),
                    (
                        "door_reveal",
                        [p(1.5, 0., 2.1), p(2.5, 0., 2.1), p(2.5, 0., h), p(1.5, 0., h)],
                    ),
                ];
                for (mat, q) in quads {
                    let _ = writeln!(obj, "usemtl {mat}");
                    for v in q {
                        let _ = writeln!(obj, "v {} {} {}", v[0], v[1], v[2]);
                    }
                    let _ = writeln!(
                        obj,
                        "f {} {} {}\nf {} {} {}",
                        nv + 1,
                        nv + 2,
                        nv + 3,
                        nv + 1,
                        nv + 3,
                        nv + 4
                    );
                    nv += 4;
                    faces += 2;
                }
            }
        }
        (obj, faces)
    }

    use omnitrack::desk::results::percentile;

    /// Renders `frames` frames walking through a room row; returns per-frame ms.
    fn run(renderer: &Renderer, traj: &[Stamped], frames: usize) -> Vec<f64> {
        let mut ms = Vec::with_capacity(frames);
        for k in 0..frames {
            let s = traj[k % traj.len()];
            let frame = FrameSpec {
                index: k as u64,
                timestamp_ns: s.timestamp_ns,
                pose: s.pose,
                previous: k.checked_sub(1).map(|p| traj[p % traj.len()]),
            };
            let t = Instant::now();
            let images = renderer.render_frame(&frame);
            ms.push(t.elapsed().as_secs_f64() * 1e3);
            std::hint::black_box(images);
        }
        ms
    }

    fn report(name: &str, ms: &mut [f64], peer_p50: Option<f64>) -> f64 {
        ms.sort_by(f64::total_cmp);
        let mean = ms.iter().sum::<f64>() / ms.len() as f64;
        let p50 = percentile(ms, 0.5);
        let ratio = peer_p50
            .map(|p| format!("  ({:.2}× plain)", p50 / p))
            .unwrap_or_default();
        println!(
            "render {name:<22} {:6.1} frames/s  p50 {p50:7.1} ms  max {:7.1} ms  ({} frames){ratio}",
            1e3 / mean,
            ms[ms.len() - 1],
            ms.len()
        );
        p50
    }

    pub fn main() {
        let rig = Rig::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("firmware_config/ladybug2.toml")).unwrap();
        let (obj, faces) = building(18);
        let model = Model::from_obj_str(&obj, "building.obj").unwrap();
        println!(
            "render: {faces} faces, {} sensors of {}×{}, {} threads",
            rig.sensors.len(),
            rig.sensors[0].width,
            rig.sensors[0].height,
            rayon::current_num_threads()
        );
        // Walk along the middle of a row of rooms (through walls: it is a benchmark), turning.
        let traj: Vec<Stamped> = (0..30)
            .map(|k| Stamped {
                timestamp_ns: 1_000_000_000 + k as u64 * 33_333_333,
                pose: Isometry3::from_parts(
                    Translation3::new(2.0 + 4.2 * 8.0 + 0.05 * k as f64, 1.5 + 3.2 * 8.0, 1.5),
                    UnitQuaternion::from_euler_angles(0.0, 0.0, 0.05 * k as f64),
                ),
            })
            .collect();
        let keep: Vec<Point3<f64>> = traj.iter().map(|s| Point3::from(s.pose.translation.vector)).collect();
        let frames = 12;

        let t = Instant::now();
        let plain = Renderer::new(&model, &rig, Appearance::plain(), &keep);
        println!(
            "render: scene + ray tables built in {:.0} ms (every effect off)",
            t.elapsed().as_secs_f64() * 1e3
        );
        let t = Instant::now();
        let default = Renderer::new(&model, &rig, Appearance::default(), &keep);
        let s = default.scene();
        println!(
            "render: scene + ray tables built in {:.0} ms (default: {} furniture, {} shelves, {} posters, {} people)",
            t.elapsed().as_secs_f64() * 1e3,
            s.clutter_counts.furniture,
            s.clutter_counts.shelves,
            s.clutter_counts.posters,
            s.people.len()
        );
        let _ = run(&plain, &traj, 2); // warm-up
        let p_plain = report("every effect off", &mut run(&plain, &traj, frames), None);
        report("default appearance", &mut run(&default, &traj, frames), Some(p_plain));

        let off = Appearance::plain();
        let one_on: Vec<(&str, Appearance)> = vec![
            (
                "texture 0.06",
                Appearance {
                    texture: 0.06,
                    ..off.clone()
                },
            ),
            (
                "shading + 4 lights",
                Appearance {
                    shading: 1.0,
                    lights: 4,
                    ..off.clone()
                },
            ),
            (
                "noise 2.0",
                Appearance {
                    noise: 2.0,
                    ..off.clone()
                },
            ),
            (
                "vignetting 0.3",
                Appearance {
                    vignetting: 0.3,
                    ..off.clone()
                },
            ),
            (
                "drift 0.1",
                Appearance {
                    lighting_drift: 0.1,
                    ..off.clone()
                },
            ),
            (
                "clutter 1.0",
                Appearance {
                    clutter: 1.0,
                    ..off.clone()
                },
            ),
            (
                "people 1.0",
                Appearance {
                    people: 1.0,
                    ..off.clone()
                },
            ),
            (
                "motion blur 0.5 ×4",
                Appearance {
                    motion_blur: 0.5,
                    motion_blur_samples: 4,
                    ..off.clone()
                },
            ),
        ];
        for (name, a) in one_on {
            let r = Renderer::new(&model, &rig, a, &keep);
            report(name, &mut run(&r, &traj, frames / 2), Some(p_plain));
        }
    }
}

fn main() {
    #[cfg(feature = "desk")]
    bench::main();
    #[cfg(not(feature = "desk"))]
    eprintln!("the render bench needs the `desk` feature");
}
