//! Edge + hue extraction: accuracy on rendered frames of the synthetic scenarios and speed of a
//! whole six-sensor frame, beside OpenCV's LSD and FastLineDetector on the same images.
//!
//! Run: `cargo bench --bench edges` (needs the `desk` feature, on by default). Options after
//! `--`: `--quick` (fewer frames), `--no-opencv` (skip tools/bench_edges.py), `--seed S`
//! (another draw of every appearance's colours, clutter, people and lights, and of the
//! trajectory the frames are taken from: the defaults are appearance seed 1, trajectory seed 7),
//! `--pixel-samples N` (rays per pixel side, default 3), `--half-resolution` (detect on 2×2-binned
//! images through the rig with its intrinsics halved: what the 5× target against
//! FastLineDetector would cost in accuracy), `--rig RIG.toml` (another rig: `tools/rigs/` has
//! examples; the speed section then times that rig's whole frame).
//!
//! Images. Each pixel averages 3×3 rays over its area (`Appearance::pixel_samples`), as a
//! camera's pixel integrates the light falling on it: an edge crossing a pixel gives it a value
//! in between, which is what sub-pixel location reads. One ray through the pixel centre (the
//! tracker's recordings, which are cheaper to render) gives aliased staircase edges that carry
//! no sub-pixel information; one row measures that too.
//!
//! Accuracy. Ground truth per sensor image: the model segments, sampled every centimetre, each
//! sample kept when it projects onto the image (3 px from the border) and the first hit of the
//! ray from the sensor's centre is the sample itself (± 2 cm: the renderer's scene includes
//! clutter, so clutter occludes; so do the people at the frame time); contiguous runs longer than 30 px are the visible segments.
//! A visible segment is recalled when one detected edge of that sensor has a plane normal within
//! 1° of the segment's plane (through the same sensor centre) and covers ≥ 50 % of the run's
//! angular extent along that plane. Normal error: angle between the planes of the best match.
//! "edges on model" is the fraction of detected edges that lie (≤ 1°, any overlap) on a visible
//! model segment; the rest are clutter, people, texture or noise.
//!
//! Speed: `EdgeDetector::detect` on whole six-sensor frames (2 threads, the calling one
//! included; also 1 thread), p50/p99/max over repeated passes; the first frames are written as
//! PNGs and tools/bench_edges.py times OpenCV on them in the same invocation.

#[cfg(feature = "desk")]
#[path = "edges/truth.rs"]
mod truth;

#[cfg(feature = "desk")]
mod bench {
    use super::truth::{ground_truth, score, Score};
    use nalgebra::{Point3, Vector3};
    use omnitrack::config::EdgeConfig;
    use omnitrack::desk::render::{Appearance, FrameSpec, Renderer};
    use omnitrack::desk::scenario::{Scenario, ScenarioName};
    use omnitrack::edges::{EdgeDetector, EdgeParams, Smoothing};
    use omnitrack::frame::FrameSet;
    use omnitrack::{Model, Rig};
    use std::path::{Path, PathBuf};
    use std::time::Instant;

    use omnitrack::desk::results::percentile;

    /// The rig as its cameras would be with 2×2 binning: half the resolution, the focal lengths
    /// halved and the principal point moved with the pixel centres (pixel u's centre is at
    /// u + 0.5 in pixel-edge coordinates, so c ↦ (c + 0.5) / 2 − 0.5).
    fn binned_rig(rig: &Rig) -> Rig {
        let mut r = rig.clone();
        for s in &mut r.sensors {
            s.width /= 2;
            s.height /= 2;
            s.lens = s.lens.resampled(0.5);
        }
        r
    }

    /// 2×2 binning: each output pixel the rounded mean of four.
    fn bin2x2(img: &image::RgbImage) -> image::RgbImage {
        image::RgbImage::from_fn(img.width() / 2, img.height() / 2, |x, y| {
            let mut sum = [2u32; 3];
            for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let p = img.get_pixel(2 * x + dx, 2 * y + dy);
                for (s, &v) in sum.iter_mut().zip(&p.0) {
                    *s += v as u32;
                }
            }
            image::Rgb(sum.map(|v| (v / 4) as u8))
        })
    }

    fn to_frameset(rig: &Rig, images: &[image::RgbImage], frame: &mut FrameSet) {
        for (k, img) in images.iter().enumerate().take(rig.sensors.len()) {
            let si = frame.sensor_mut(k);
            si.pixels_mut().copy_from_slice(img.as_raw());
            si.set_valid(k as u64);
        }
    }

    struct Setup {
        name: String,
        scenario: ScenarioName,
        appearance: Appearance,
        /// Rendered with one ray per pixel whatever `--pixel-samples` says.
        point_sampled: bool,
    }

    fn setups() -> Vec<Setup> {
        let d = Appearance::default;
        let mk = |name: &str, scenario, appearance| Setup {
            name: name.to_string(),
            scenario,
            appearance,
            point_sampled: false,
        };
        vec![
            mk("lab default", ScenarioName::Lab, d()),
            Setup {
                point_sampled: true,
                ..mk("lab default, one ray per pixel (aliased)", ScenarioName::Lab, d())
            },
            mk("lab plain (all effects off)", ScenarioName::Lab, Appearance::plain()),
            mk(
                "lab clutter 0",
                ScenarioName::Lab,
                Appearance {
                    clutter: 0.0,
                    people: 0.0,
                    ..d()
                },
            ),
            mk(
                "lab clutter 2, people 2",
                ScenarioName::Lab,
                Appearance {
                    clutter: 2.0,
                    people: 2.0,
                    ..d()
                },
            ),
            mk(
                "lab clutter 4, people 4",
                ScenarioName::Lab,
                Appearance {
                    clutter: 4.0,
                    people: 4.0,
                    ..d()
                },
            ),
            mk("lab noise 0", ScenarioName::Lab, Appearance { noise: 0.0, ..d() }),
            mk("lab noise 5", ScenarioName::Lab, Appearance { noise: 5.0, ..d() }),
            mk("lab noise 10", ScenarioName::Lab, Appearance { noise: 10.0, ..d() }),
            mk(
                "lab dim: drift 0.3, vignetting 0.7",
                ScenarioName::Lab,
                Appearance {
                    lighting_drift: 0.3,
                    vignetting: 0.7,
                    ..d()
                },
            ),
            mk(
                "lab flat light (shading 0)",
                ScenarioName::Lab,
                Appearance { shading: 0.0, ..d() },
            ),
            mk(
                "lab grey (colour 0)",
                ScenarioName::Lab,
                Appearance { colour: 0.0, ..d() },
            ),
            mk(
                "lab motion blur 0.5",
                ScenarioName::Lab,
                Appearance {
                    motion_blur: 0.5,
                    ..d()
                },
            ),
            mk("corridor default", ScenarioName::Corridor, d()),
            mk("handheld default", ScenarioName::Handheld, d()),
        ]
    }

    /// `EdgeParams::default()`, with overrides from EDGES_THRESHOLD, EDGES_SPLIT_DEG,
    /// EDGES_MERGE_DEG, EDGES_GAP_DEG, EDGES_SMOOTH (0 none, 1 binomial², 2 along the edge),
    /// EDGES_MIN_CHAIN, EDGES_TWO_LINE (`two_line_excess`), EDGES_GAP_EVIDENCE
    /// (`merge_gap_evidence`), EDGES_MIN_SUPPORT (`merge_min_support`; for tuning sweeps). EDGES_MISSES=1
    /// prints every missed segment to stderr (frame, pixel ends, the nearest edge; with
    /// `--half-resolution` the edge's pixel ends are binned pixels, the truth's full ones).
    fn params() -> EdgeParams {
        let get = |k: &str| std::env::var(k).ok().and_then(|v| v.parse::<f64>().ok());
        let mut p = EdgeParams::default();
        if let Some(v) = get("EDGES_THRESHOLD") {
            p.gradient_threshold = v as u16;
        }
        if let Some(v) = get("EDGES_SPLIT_DEG") {
            p.split_tolerance_rad = v.to_radians();
        }
        if let Some(v) = get("EDGES_MERGE_DEG") {
            p.merge_angle_rad = v.to_radians();
        }
        if let Some(v) = get("EDGES_GAP_DEG") {
            p.merge_gap_rad = v.to_radians();
        }
        if let Some(v) = get("EDGES_SMOOTH") {
            // 0: none, 1: binomial [1 2 1]², 2: along the edge only.
            p.smoothing = match v as i64 {
                0 => Smoothing::None,
                1 => Smoothing::Full,
                _ => Smoothing::Along,
            };
        }
        if let Some(v) = get("EDGES_MIN_CHAIN") {
            p.min_chain_edgels = v as usize;
        }
        if let Some(v) = get("EDGES_TWO_LINE") {
            p.two_line_excess = v;
        }
        if let Some(v) = get("EDGES_GAP_EVIDENCE") {
            p.merge_gap_evidence = v;
        }
        if let Some(v) = get("EDGES_MIN_SUPPORT") {
            p.merge_min_support = v;
        }
        p
    }

    fn root() -> PathBuf {
        PathBuf::from(env!("CARGO_MANIFEST_DIR"))
    }

    pub fn main() {
        let args: Vec<String> = std::env::args().collect();
        let quick = args.iter().any(|a| a == "--quick");
        let opencv = !args.iter().any(|a| a == "--no-opencv");
        // `--rig RIG.toml`: another rig's images (tools/rigs/ has examples); one-line errors.
        let rig_path = match args.iter().position(|a| a == "--rig") {
            None => root().join("firmware_config/ladybug2.toml"),
            Some(k) => match args.get(k + 1) {
                Some(p) => PathBuf::from(p),
                None => {
                    eprintln!("edges bench: --rig needs a rig TOML path");
                    std::process::exit(2);
                }
            },
        };
        let rig = match Rig::load(&rig_path) {
            Ok(rig) => rig,
            Err(e) => {
                eprintln!("edges bench: {e}");
                std::process::exit(2);
            }
        };
        let config = EdgeConfig::default();
        let frames_per_setup = if quick { 3 } else { 8 };
        // A flag's value, or a one-line error naming the flag.
        let value = |flag: &str| -> Option<u64> {
            let k = args.iter().position(|a| a == flag)?;
            match args.get(k + 1).and_then(|v| v.parse::<u64>().ok()) {
                Some(v) => Some(v),
                None => {
                    eprintln!("edges bench: {flag} needs a whole number");
                    std::process::exit(2);
                }
            }
        };
        let seed = value("--seed");
        // Detection at half resolution (the trade the 5× target against FastLineDetector would
        // need): every rendered image 2×2-binned, through the rig with its intrinsics halved, and
        // chains of half as many edgels. Ground truth, recall and normal error stay those of the
        // full-resolution rig (planes are resolution-free); OpenCV still gets the full images.
        let half = args.iter().any(|a| a == "--half-resolution");
        let det_rig = if half { binned_rig(&rig) } else { rig.clone() };
        let det_params = || {
            let p = params();
            let min_chain_edgels = if half {
                (p.min_chain_edgels / 2).max(3)
            } else {
                p.min_chain_edgels
            };
            EdgeParams { min_chain_edgels, ..p }
        };
        let for_detector = |images: &[image::RgbImage]| -> Vec<image::RgbImage> {
            if half {
                images.iter().map(bin2x2).collect()
            } else {
                images.to_vec()
            }
        };
        let pixel_samples = match value("--pixel-samples").unwrap_or(3) {
            n @ 1..=16 => n as u32,
            n => {
                eprintln!("edges bench: --pixel-samples must be 1 to 16, found {n}");
                std::process::exit(2);
            }
        };
        let traj_len = 400;

        println!(
            "# omnitrack edges benchmark (rig {}, {} sensors)",
            rig.name,
            rig.sensors.len()
        );
        println!("config: {config:?}");
        println!("params: {:?}", det_params());
        if half {
            println!("detection at half resolution: 2×2-binned images, intrinsics halved (OpenCV: full images)");
        }
        if let Some(seed) = seed {
            println!("seed: appearance {seed}, trajectory {}", seed + 6);
        }
        println!("pixels: {pixel_samples}×{pixel_samples} rays each, averaged (but where the row says one ray)");
        println!();
        println!("## Accuracy ({frames_per_setup} frames per row, visible model segments > 30 px)");
        println!();
        println!(
            "| setup | visible segs | recall | median normal err (°) | p90 err (°) | edges/sensor | edges on model | missed: no plane / fragmented |"
        );
        println!("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |");
        let mut detector = EdgeDetector::with_params(&det_rig, &config, det_params());
        let mut frame = FrameSet::for_rig(&det_rig);
        let mut truths = Vec::new();
        let mut speed_frames: Vec<Vec<image::RgbImage>> = Vec::new();
        let only = std::env::var("EDGES_BENCH_ONLY").ok();
        for mut setup in setups() {
            if let Some(seed) = seed {
                setup.appearance.seed = seed;
            }
            setup.appearance.pixel_samples = if setup.point_sampled { 1 } else { pixel_samples };
            if only.as_ref().is_some_and(|o| !setup.name.contains(o.as_str())) && setup.name != "lab default" {
                continue;
            }
            let scenario = Scenario::get(setup.scenario);
            let model = Model::from_obj_str(&scenario.model_obj().expect("model"), "scenario").expect("model");
            let traj = scenario.trajectory(traj_len, seed.map_or(7, |s| s + 6));
            let keep: Vec<Point3<f64>> = traj.iter().map(|s| Point3::from(s.pose.translation.vector)).collect();
            let renderer = Renderer::new(&model, &rig, setup.appearance.clone(), &keep);
            let mut sc = Score::default();
            for f in 0..frames_per_setup {
                let k = 5 + f * (traj_len - 10) / frames_per_setup;
                let spec = FrameSpec {
                    index: k as u64,
                    timestamp_ns: traj[k].timestamp_ns,
                    pose: traj[k].pose,
                    previous: Some(traj[k - 1]),
                };
                let images = renderer.render_frame(&spec);
                to_frameset(&det_rig, &for_detector(&images), &mut frame);
                let edges = detector.detect(&frame);
                ground_truth(
                    &model,
                    &rig,
                    &renderer,
                    &traj[k].pose,
                    traj[k].timestamp_ns as f64 * 1e-9,
                    &mut truths,
                );
                score(&truths, edges, &mut sc, &rig, f);
                if std::env::var("EDGES_DEBUG").is_ok() {
                    for (k, image) in images.iter().enumerate() {
                        let _ = image.save(format!("/tmp/edges_raw_{}_f{f}_s{k}.png", setup.name.replace(' ', "_")));
                        let mut img = image.clone();
                        let s = &rig.sensors[k];
                        let mut arc = |r1: &Vector3<f64>, r2: &Vector3<f64>, col: [u8; 3]| {
                            for i in 0..=200 {
                                let t = i as f64 / 200.0;
                                let r = (r1 * (1.0 - t) + r2 * t).normalize();
                                if let Some(px) = s.project_from_rig(&(s.centre() + r)) {
                                    let (u, v) = (px.x.round() as u32, px.y.round() as u32);
                                    if u < img.width() && v < img.height() {
                                        img.put_pixel(u, v, image::Rgb(col));
                                    }
                                }
                            }
                        };
                        for t in truths.iter().filter(|t| t.sensor == k) {
                            arc(&t.r1, &t.r2, [255, 0, 0]);
                        }
                        for e in edges.iter().filter(|e| e.sensor as usize == k) {
                            arc(&e.plane.ends[0], &e.plane.ends[1], [0, 255, 0]);
                        }
                        let _ = img.save(format!(
                            "/tmp/edges_debug_{}_f{f}_s{k}.png",
                            setup.name.replace(' ', "_")
                        ));
                    }
                }
                sc.sensor_frames += rig.sensors.len();
                if setup.name == "lab default" {
                    speed_frames.push(images);
                }
            }
            sc.errors_deg.sort_by(f64::total_cmp);
            println!(
                "| {} | {} | {:.1} % | {:.4} | {:.4} | {:.1} | {:.1} % | {} / {} |",
                setup.name,
                sc.truths,
                100.0 * sc.recalled as f64 / sc.truths.max(1) as f64,
                percentile(&sc.errors_deg, 0.5),
                percentile(&sc.errors_deg, 0.9),
                sc.edges as f64 / sc.sensor_frames.max(1) as f64,
                100.0 * sc.edges_on_model as f64 / sc.edges.max(1) as f64,
                sc.missed_no_plane,
                sc.missed_fragmented
            );
        }

        // Speed.
        let dir = root().join("target/bench-edges/frames");
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("create the PNG directory");
        for (f, images) in speed_frames.iter().enumerate() {
            for (k, img) in images.iter().enumerate() {
                img.save(dir.join(format!("frame{f:03}_s{k}.png")))
                    .expect("write a PNG");
            }
        }
        let frames: Vec<FrameSet> = speed_frames
            .iter()
            .map(|images| {
                let mut fs = FrameSet::for_rig(&det_rig);
                to_frameset(&det_rig, &for_detector(images), &mut fs);
                fs
            })
            .collect();
        let passes = if quick { 60 } else { 300 };
        println!();
        println!(
            "## Speed: whole {}-sensor frame, lab default appearance, {} distinct frames, {passes} passes",
            rig.sensors.len(),
            frames.len()
        );
        println!();
        println!("| detector | threads | p50 ms | p99 ms | max ms | edges/frame |");
        println!("| --- | ---: | ---: | ---: | ---: | ---: |");
        let mut ours_p50 = f64::NAN;
        let mut phases = Vec::new();
        for threads in [2usize, 1] {
            let params = EdgeParams {
                threads,
                ..det_params()
            };
            let mut det = EdgeDetector::with_params(&det_rig, &config, params);
            for fs in &frames {
                det.detect(fs); // warm-up
            }
            let mut ms = Vec::with_capacity(passes);
            let mut count = 0usize;
            let mut phase_ns = [0u64; 3];
            for p in 0..passes {
                let fs = &frames[p % frames.len()];
                let t = Instant::now();
                let n = det.detect(fs).len();
                ms.push(t.elapsed().as_secs_f64() * 1e3);
                count += n;
                for k in 0..rig.sensors.len() {
                    let st = det.sensor_stats(k);
                    phase_ns[0] += st.pixel_ns as u64;
                    phase_ns[1] += st.chain_ns as u64;
                    phase_ns[2] += (st.merge_ns + st.select_ns) as u64;
                }
            }
            let per_image = |ns: u64| ns as f64 / (passes * rig.sensors.len()) as f64 / 1e3;
            phases.push(format!(
                "{} thread(s), mean µs of CPU per sensor image: pixel pass {:.0}, chains (link, fit, hue) {:.0}, merge and select {:.0}",
                det.threads(),
                per_image(phase_ns[0]),
                per_image(phase_ns[1]),
                per_image(phase_ns[2])
            ));
            ms.sort_by(f64::total_cmp);
            if threads == 2 {
                ours_p50 = percentile(&ms, 0.5);
            }
            println!(
                "| omnitrack EdgeDetector (edges + hue) | {} | {:.3} | {:.3} | {:.3} | {:.1} |",
                det.threads(),
                percentile(&ms, 0.5),
                percentile(&ms, 0.99),
                ms[ms.len() - 1],
                count as f64 / passes as f64
            );
        }
        if opencv {
            run_opencv(&dir, ours_p50);
        }
        println!();
        for line in &phases {
            println!("{line}");
        }
        println!();
        println!("PNG frames: {}", dir.display());
    }

    fn run_opencv(dir: &Path, ours_p50: f64) {
        let script = root().join("tools/bench_edges.py");
        let out = std::process::Command::new("python3")
            .arg(&script)
            .arg(dir)
            .arg("--repeats")
            .arg("5")
            .output();
        let out = match out {
            Ok(o) if o.status.success() => o,
            Ok(o) => {
                println!("(OpenCV run failed: {})", String::from_utf8_lossy(&o.stderr).trim());
                return;
            }
            Err(e) => {
                println!("(OpenCV run failed: {e})");
                return;
            }
        };
        for line in String::from_utf8_lossy(&out.stdout).lines() {
            let Ok(v) = serde_json::from_str::<serde_json::Value>(line) else {
                continue;
            };
            let name = v["detector"].as_str().unwrap_or("?");
            let p50 = v["p50_ms"].as_f64().unwrap_or(f64::NAN);
            println!(
                "| OpenCV {} (grey, cv2.setNumThreads(2)) | 2 | {:.3} | {:.3} | {:.3} | {:.1} |",
                if name == "lsd" { "LSD" } else { "FastLineDetector" },
                p50,
                v["p99_ms"].as_f64().unwrap_or(f64::NAN),
                v["max_ms"].as_f64().unwrap_or(f64::NAN),
                v["lines_per_frame"].as_f64().unwrap_or(f64::NAN),
            );
            println!("|   ratio {name} p50 / ours p50 | | {:.1}× | | | |", p50 / ours_p50);
        }
    }
}

fn main() {
    #[cfg(feature = "desk")]
    bench::main();
    #[cfg(not(feature = "desk"))]
    eprintln!("the edges benchmark needs the `desk` feature");
}
