//! How hard a rendered world is for the tracker, in the two numbers measured on the real 360°
//! photos of a furnished house (issue 19): at the true pose, (a) the share of the model segments
//! in sight that the frame's edges explain within the tracker's gates
//! (`Initialiser::explained`: the initialisation's acceptance measure; real photos: median
//! 0.61), and (b) how many of the frame's 40 strongest edges lie on a model segment in sight
//! (plane within the tracker's inlier angle of the segment's, overlapping half the edge or more;
//! real photos: about 22 of 40). A synthetic world that predicts the real one should come close
//! to both; the default render is far easier.
//!
//! Run: `cargo bench --bench realism` (needs the `desk` feature, on by default). Options after
//! `--`: `--scenario lab|corridor|handheld` (default lab), `--poses N` (default 24, spread over
//! the 300-frame tour the tracker bench renders, seed 11), `--appearance default|realistic|plain`
//! with optional `+field=value` overrides, e.g. `realistic+paint=1` (repeatable; default
//! `default` and `realistic`), `--png DIR` (write the six sensors of the
//! first two poses per appearance, to look at), `--rig RIG.toml`.
//!
//! In: the scenario's model, tour and the shipped tracker config. Out: one table row per
//! appearance (median and quartiles over the poses) and, with `--png`, the images.

#[cfg(feature = "desk")]
mod bench {
    use nalgebra::{Point3, Vector3};
    use omnitrack::config::TrackerConfig;
    use omnitrack::desk::render::{Appearance, FrameSpec, Renderer};
    use omnitrack::desk::scenario::{Scenario, ScenarioName};
    use omnitrack::edges::{Edge, EdgeDetector};
    use omnitrack::frame::FrameSet;
    use omnitrack::geometry::Pose;
    use omnitrack::runtime::load_or_build_table;
    use omnitrack::tracker::{InitOptions, Initialiser};
    use omnitrack::visibility::at_pose::PoseVisibility;
    use omnitrack::visibility::VisibilityTable;
    use omnitrack::{Model, Rig};
    use std::path::{Path, PathBuf};

    /// The strongest edges the initialisation's triplet search considers.
    const STRONGEST: usize = 40;

    fn fail(msg: &str) -> ! {
        eprintln!("realism bench: {msg}");
        std::process::exit(2);
    }

    use omnitrack::desk::results::percentile;

    fn appearance(spec: &str) -> Appearance {
        Appearance::from_spec(spec).unwrap_or_else(|e| fail(&format!("--appearance {e}")))
    }

    /// Angle of `r` along the plane with unit normal `n`, from `e1` (in the plane).
    fn along(n: &Vector3<f64>, e1: &Vector3<f64>, r: &Vector3<f64>) -> f64 {
        r.dot(&n.cross(e1)).atan2(r.dot(e1))
    }

    /// How many of the `STRONGEST` strongest edges (at least the tracker's shortest long) lie on
    /// a segment in sight from `pose`: plane within `gate_rad`, overlapping ≥ half the edge.
    fn strongest_on_model(
        edges: &[Edge],
        model: &Model,
        rig: &Rig,
        pose: &Pose,
        seen: &[u32],
        min_length_rad: f64,
        gate_rad: f64,
    ) -> (usize, usize) {
        let mut order: Vec<&Edge> = edges.iter().filter(|e| e.length_rad >= min_length_rad).collect();
        order.sort_by(|a, b| b.strength.total_cmp(&a.strength));
        order.truncate(STRONGEST);
        let inv = pose.inverse();
        let on = order
            .iter()
            .filter(|e| {
                let c = rig.sensors[e.sensor as usize].centre();
                let n = e.plane.normal.into_inner();
                let e1 = e.plane.ends[0].into_inner();
                let (lo, hi) = {
                    let x = along(&n, &e1, &e.plane.ends[1]);
                    (x.min(0.0), x.max(0.0))
                };
                seen.iter().any(|&s| {
                    let seg = &model.segments[s as usize];
                    let (a, b) = ((inv * seg.a - c).normalize(), (inv * seg.b - c).normalize());
                    let Some(m) = a.cross(&b).try_normalize(1e-12) else {
                        return false;
                    };
                    if m.dot(&n).abs() < gate_rad.cos() {
                        return false;
                    }
                    let (x, y) = (along(&n, &e1, &a), along(&n, &e1, &b));
                    let (slo, shi) = (x.min(y), x.max(y));
                    // A segment spanning more than half a turn along the plane wraps; skip it.
                    if shi - slo > std::f64::consts::PI {
                        return false;
                    }
                    (hi.min(shi) - lo.max(slo)).max(0.0) >= 0.5 * (hi - lo)
                })
            })
            .count();
        (on, order.len())
    }

    pub fn main() {
        let args: Vec<String> = std::env::args().collect();
        let value = |flag: &str| {
            args.iter()
                .position(|a| a == flag)
                .and_then(|k| args.get(k + 1))
                .cloned()
        };
        let scenario_name: ScenarioName = value("--scenario").map_or(ScenarioName::Lab, |s| {
            s.parse().unwrap_or_else(|_| fail(&format!("--scenario {s}")))
        });
        let poses: usize = value("--poses").map_or(24, |s| s.parse().unwrap_or_else(|_| fail("--poses N")));
        let mut names: Vec<String> = args
            .iter()
            .enumerate()
            .filter(|(_, a)| *a == "--appearance")
            .filter_map(|(k, _)| args.get(k + 1).cloned())
            .collect();
        if names.is_empty() {
            names = vec!["default".into(), "realistic".into()];
        }
        let png = value("--png").map(PathBuf::from);
        let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("firmware_config/ladybug2.toml");
        let rig = Rig::load(&value("--rig").map_or(shipped, PathBuf::from)).unwrap_or_else(|e| fail(&e.to_string()));

        let scenario = Scenario::get(scenario_name);
        let obj = scenario.model_obj().unwrap_or_else(|e| fail(&e.to_string()));
        let cache = omnitrack::desk::recording::cache_root(Path::new(env!("CARGO_MANIFEST_DIR")));
        std::fs::create_dir_all(&cache).unwrap_or_else(|e| fail(&e.to_string()));
        let model_path = cache.join(format!("realism-{}.obj", scenario.name));
        std::fs::write(&model_path, &obj).unwrap_or_else(|e| fail(&e.to_string()));
        let model = Model::load(&model_path).unwrap_or_else(|e| fail(&e.to_string()));
        let cfg = TrackerConfig::default();
        let (table, origin): (VisibilityTable, String) =
            load_or_build_table(&model_path, &model, None, &cfg).unwrap_or_else(|e| fail(&e.to_string()));
        eprintln!("{}: {origin}", scenario.name);
        // The tour the tracker bench renders (300 frames, seed 11), so that clutter and people
        // are placed as in its recordings.
        let tour = scenario.trajectory(300, 11);
        let keep: Vec<Point3<f64>> = tour.iter().map(|s| Point3::from(s.pose.translation.vector)).collect();
        let picks: Vec<usize> = (0..poses).map(|k| (k * tour.len() + tour.len() / 2) / poses).collect();
        let max_edges = rig.sensors.len() * cfg.edges.max_edges_per_sensor as usize;
        let opts = InitOptions::from_config(&cfg);
        let (min_len, gate) = (opts.min_length_rad, opts.inlier_alpha_rad);

        println!();
        println!(
            "Edges at the true pose, {} ({} poses of the 300-frame tour, seed 11), shipped rig and tracker config:",
            scenario.name, poses
        );
        println!();
        println!("| appearance | in-sight segments explained: median (quartiles) | of the {STRONGEST} strongest edges on the model: median (quartiles) | edges per frame |");
        println!("| --- | --- | --- | --- |");
        for name in &names {
            let a = appearance(name);
            let renderer = Renderer::new(&model, &rig, a, &keep);
            let counts = renderer.scene().fixture_counts;
            eprintln!(
                "{name}: clutter {:?}, people {}, fixtures {counts:?}",
                renderer.scene().clutter_counts,
                renderer.scene().people.len()
            );
            let mut detector = EdgeDetector::new(&rig, &cfg.edges);
            let mut init = Initialiser::new(&rig, &model, &table, opts.clone(), cfg.solver_options(), max_edges);
            let mut at_pose = PoseVisibility::new(&model);
            let mut frame = FrameSet::for_rig(&rig);
            let (mut explained, mut on_model, mut n_edges) = (Vec::new(), Vec::new(), 0usize);
            for (k, &i) in picks.iter().enumerate() {
                let stamped = tour[i];
                let images = renderer.render_frame(&FrameSpec {
                    index: i as u64,
                    timestamp_ns: stamped.timestamp_ns,
                    pose: stamped.pose,
                    previous: i.checked_sub(1).map(|p| tour[p]),
                });
                if let (Some(dir), true) = (&png, k < 2) {
                    std::fs::create_dir_all(dir).unwrap_or_else(|e| fail(&e.to_string()));
                    for (s, img) in images.iter().enumerate() {
                        let path = dir.join(format!("{}-{name}-pose{k}-sensor{s}.png", scenario.name));
                        img.save(&path)
                            .unwrap_or_else(|e| fail(&format!("{}: {e}", path.display())));
                    }
                }
                for (s, img) in images.iter().enumerate() {
                    let si = frame.sensor_mut(s);
                    si.pixels_mut().copy_from_slice(img.as_raw());
                    si.set_valid(i as u64);
                }
                let edges = detector.detect(&frame).to_vec();
                n_edges += edges.len();
                explained.push(init.explained(&stamped.pose, &edges));
                let seen: Vec<u32> = at_pose
                    .at(&model, &table, &Point3::from(stamped.pose.translation.vector))
                    .iter()
                    .map(|s| s.segment)
                    .collect();
                let (on, of) = strongest_on_model(&edges, &model, &rig, &stamped.pose, &seen, min_len, gate);
                on_model.push(on as f64 * STRONGEST as f64 / of.max(1) as f64);
            }
            explained.sort_by(f64::total_cmp);
            on_model.sort_by(f64::total_cmp);
            println!(
                "| {name} | {:.2} ({:.2}–{:.2}) | {:.0} ({:.0}–{:.0}) | {:.0} |",
                percentile(&explained, 0.5),
                percentile(&explained, 0.25),
                percentile(&explained, 0.75),
                percentile(&on_model, 0.5),
                percentile(&on_model, 0.25),
                percentile(&on_model, 0.75),
                n_edges as f64 / picks.len().max(1) as f64
            );
        }
        println!("| real 360° photos (furnished house, issue 19) | 0.61 | about 22 | |");
    }
}

fn main() {
    #[cfg(feature = "desk")]
    bench::main();
    #[cfg(not(feature = "desk"))]
    eprintln!("the realism benchmark needs the `desk` feature");
}
