//! The `--model` mode (issue 47): the first pose in a detailed building model (an architect's
//! IFC through `omnitrack-desk model from-ifc`, or any OBJ), from start poses sampled over the
//! model, each searched from a 1.5 m hint, a 3 m hint and no hint, with any rig.
//!
//! In: the model, the rig, the shipped (or given) configuration, the appearance. Out: one table
//! row per search volume (pose within 10 cm / 2°, within 30 cm / 5°, wrong commits, no pose,
//! cells looked at, time to the first pose) and one line per start with `--verbose`.
//!
//! **Starts.** Valid nodes of the visibility table's middle layer, drawn by a seeded generator
//! (`--seed`), each moved by up to 0.35 m in plan and turned to a random heading, tilted by up
//! to 5°. A start whose true pose shows fewer than three model segments on the rig's images is
//! not counted (no search can place it). Each start is rendered once (one frame, the
//! `--appearance` of the bench) and replayed still, a frame interval apart, as a rig standing
//! there would see it: the measure is the search, not the maintenance of a moving view.
//!
//! **Walks** (`--walk M`): each start is instead the first pose of a walk of M metres at
//! [`WALK_SPEED_M_S`], straight on where the model leaves the way free, the head turning by up to
//! [`WALK_TURN_DEG`]; its frames are rendered and replayed in turn, then the last stands still.
//! A pose is judged against where the rig was at its frame's time. With `--verbose`, a wrong
//! walk's first pose and the truth are each polished on every frame of the walk from there on,
//! one line a frame: whether the frames after a commit would have told them apart.
//!
//! **Hints** as `zind_bench` makes them: a ball of radius 1.5 m or 3 m whose centre is 0.72 m
//! from the truth in a seeded direction, and the whole model. A trial gives up after
//! [`WINDOW_S`] seconds of frames without a pose (`--window`; `--rows` picks the volumes); a commit is judged [`AFTER`] frames later.
//! A wrong commit is any pose more than 1 m or 10° off on any frame of the trial.

use nalgebra::{Point3, Translation3, UnitQuaternion, Vector3};
use omnitrack::capture::{FrameSource, Pacing, ReplaySource};
use omnitrack::config::TrackerConfig;
use omnitrack::desk::recording::{write_recording, RecordingOptions};
use omnitrack::edges::EdgeDetector;
use omnitrack::frame::FrameSet;
use omnitrack::geometry::Pose;
use omnitrack::model::bvh::{Ray, TriangleBvh};
use omnitrack::runtime::load_or_build_table;
use omnitrack::tracker::{SearchVolume, Tracker};
use omnitrack::trajectory::Stamped;
use omnitrack::{Model, Rig};
use std::path::Path;
use std::time::Instant;

use crate::{cache_root, Args};
use omnitrack::desk::results::percentile;

/// Frames a trial waits for a pose by default (30 s: three whole-model search budgets;
/// `--window SECONDS` sets another), and frames after the commit it is judged at.
const WINDOW_S: f64 = 30.0;
const AFTER: usize = 10;
/// The hints' centres lie this far from the truth (m), as `zind_bench`'s.
const HINT_OFFSET_M: f64 = 0.72;
/// A start is moved this far from its node at most (m), and tilted this far at most (°).
const JITTER_M: f64 = 0.35;
const TILT_DEG: f64 = 5.0;

/// A `--walk` start walks this fast (m/s), its head turning by up to this much over the walk
/// (°, either way), and keeps this far from the model's surfaces ahead (m).
const WALK_SPEED_M_S: f64 = 0.5;
const WALK_TURN_DEG: f64 = 20.0;
const WALK_CLEARANCE_M: f64 = 0.4;

/// The poses of a walk of `metres` from `start` at [`WALK_SPEED_M_S`], a frame every
/// `interval_ns`: straight on along the first of eight headings (from a drawn one) whose way is
/// free of the model's surfaces at the rig's height and 0.5 m below it, the head turning
/// steadily by up to [`WALK_TURN_DEG`]. A start with no free way stands still (one pose).
fn walk(start: &Pose, metres: f64, interval_ns: u64, bvh: &TriangleBvh, draw: &mut Draw) -> Vec<Pose> {
    let p = start.translation.vector;
    let first = draw.next() * std::f64::consts::TAU;
    let turn = (2.0 * draw.next() - 1.0) * WALK_TURN_DEG.to_radians();
    let free = |h: f64| {
        let d = [h.cos() as f32, h.sin() as f32, 0.0];
        [0.0, -0.5].iter().all(|dz| {
            let o = [p.x as f32, p.y as f32, (p.z + dz) as f32];
            !bvh.occluded(&Ray::new(o, d), 0.0, (metres + WALK_CLEARANCE_M) as f32)
        })
    };
    let Some(h) = (0..8)
        .map(|j| first + j as f64 * std::f64::consts::FRAC_PI_4)
        .find(|&h| free(h))
    else {
        return vec![*start];
    };
    let steps = (metres / (WALK_SPEED_M_S * interval_ns as f64 * 1e-9)).round().max(1.0) as usize;
    (0..=steps)
        .map(|i| {
            let f = i as f64 / steps as f64;
            let at = p + Vector3::new(h.cos(), h.sin(), 0.0) * (metres * f);
            let r = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), turn * f) * start.rotation;
            Pose::from_parts(Translation3::from(at), r)
        })
        .collect()
}

/// xorshift64*: the bench's own seeded draws.
struct Draw(u64);

impl Draw {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// One search volume's counts.
#[derive(Default)]
struct Row {
    counted: usize,
    within_10: usize,
    within_30: usize,
    wrong: usize,
    none: usize,
    first_pose_ms: Vec<f64>,
    cells: Vec<(usize, usize)>,
}

/// The `--model` mode (module doc).
pub(crate) fn detailed(a: &Args, rig: &Rig, label: &str, options: &RecordingOptions, model_path: &Path) {
    if a.stand && a.walk_m <= 0.0 {
        eprintln!("--stand replays the first frames of walks: give --walk METRES (more than 0) too");
        std::process::exit(2);
    }
    let model = Model::load(model_path).unwrap_or_else(|e| {
        eprintln!("--model {}: {}", model_path.display(), e.message);
        std::process::exit(2);
    });
    let cfg = match &a.config {
        Some(p) => TrackerConfig::load(p).unwrap(),
        None => TrackerConfig::default(),
    };
    let (table, origin) = load_or_build_table(model_path, &model, None, &cfg).unwrap();
    let name = model_path
        .file_stem()
        .map_or("model".into(), |s| s.to_string_lossy().to_string());
    let long = model
        .segments
        .iter()
        .filter(|s| (s.b - s.a).norm() >= cfg.visibility.min_segment_length_m)
        .count();
    eprintln!(
        "{name}: {} faces, {} segments ({long} at least {} m); {origin}",
        model.faces.len(),
        model.segments.len(),
        cfg.visibility.min_segment_length_m
    );
    // The starts: nodes of the middle layer, moved and turned.
    let layers = table.header.heights_m.len().max(1);
    let middle = layers / 2;
    let nodes: Vec<Point3<f64>> = (0..table.node_count() as u32)
        .map(|n| table.node_position(n))
        .filter(|p| {
            let k = ((p.z - table.header.origin[2] - table.header.heights_m[0]) / 0.25).round();
            let want = ((table.header.heights_m[middle] - table.header.heights_m[0]) / 0.25).round();
            (k - want).abs() < 0.5
        })
        .collect();
    if nodes.is_empty() {
        eprintln!("{name}: the visibility table has no node to start from");
        std::process::exit(2);
    }
    let mut draw = Draw(0x9E37_79B9_7F4A_7C15 ^ a.seed.wrapping_mul(0xD1B5_4A32_D192_ED03));
    let interval_ns = 100_000_000u64;
    let mut truth = Vec::new();
    for k in 0..a.starts {
        let node = nodes[(draw.next() * nodes.len() as f64) as usize % nodes.len()];
        let p = node
            + Vector3::new(
                (2.0 * draw.next() - 1.0) * JITTER_M,
                (2.0 * draw.next() - 1.0) * JITTER_M,
                0.0,
            );
        let yaw = draw.next() * std::f64::consts::TAU;
        let tilt_axis = draw.next() * std::f64::consts::TAU;
        let tilt = draw.next() * TILT_DEG.to_radians();
        let r = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw)
            * UnitQuaternion::from_scaled_axis(Vector3::new(tilt_axis.cos(), tilt_axis.sin(), 0.0) * tilt);
        truth.push(Stamped {
            timestamp_ns: k as u64 * interval_ns,
            pose: Pose::from_parts(Translation3::from(p.coords), r),
        });
    }
    // With `--walk`, each start is the first pose of a walk (drawn apart, so that the starts
    // are the still mode's).
    let walks: Vec<Vec<Pose>> = if a.walk_m > 0.0 {
        let mut draw = Draw(0x2545_F491_4F6C_DD1D ^ a.seed.wrapping_mul(0x9E37_79B9_7F4A_7C15));
        let (t, payload): (Vec<_>, Vec<_>) = omnitrack::model::bvh::model_triangles(&model).into_iter().unzip();
        let bvh = TriangleBvh::build(&t, &payload);
        truth
            .iter()
            .map(|t| walk(&t.pose, a.walk_m, interval_ns, &bvh, &mut draw))
            .collect()
    } else {
        truth.iter().map(|t| vec![t.pose]).collect()
    };
    // One recording holds every start, a frame each, or its walk's frames (no motion blur: a
    // slow walk, and the still frames are not a walk).
    let mut opts = options.clone();
    opts.appearance.motion_blur = 0.0;
    let walk_label = if a.walk_m > 0.0 {
        format!("-walk{}m", a.walk_m)
    } else {
        String::new()
    };
    let result_label = if a.stand {
        format!("{walk_label}-stand")
    } else {
        walk_label.clone()
    };
    let key = format!(
        "{name}-{:016x}-starts{}-seed{}{walk_label}-{label}",
        omnitrack::visibility::model_hash(&model),
        a.starts,
        a.seed
    );
    let frames: Vec<Stamped> = walks
        .iter()
        .flatten()
        .enumerate()
        .map(|(k, &pose)| Stamped {
            timestamp_ns: k as u64 * interval_ns,
            pose,
        })
        .collect();
    let dir = cache_root().join(key);
    if !dir.join("complete").exists() {
        let _ = std::fs::remove_dir_all(&dir);
        let text = std::fs::read_to_string(model_path).unwrap();
        write_recording(&dir, rig, &text, &frames, &opts, |d, t| {
            eprint!("\rrendering {name}: {d}/{t}")
        })
        .unwrap();
        std::fs::write(dir.join("complete"), b"").unwrap();
        eprintln!();
    }
    let mut source = ReplaySource::open(&dir, Pacing::AsFastAsPossible).unwrap();
    let mut frame = FrameSet::for_rig(rig);
    let mut detector = EdgeDetector::new(rig, &cfg.edges);
    let volumes: [(&str, Option<f64>); 3] = [
        ("hint, radius 1.5 m", Some(1.5)),
        ("hint, radius 3 m", Some(3.0)),
        ("no hint", None),
    ];
    let wanted = |r: Option<f64>| {
        a.rows.as_deref().is_none_or(|spec| {
            spec.split(',').any(|w| match (w.trim(), r) {
                ("none", None) => true,
                (w, Some(r)) => w.parse::<f64>().is_ok_and(|w| (w - r).abs() < 1e-9),
                _ => false,
            })
        })
    };
    let window = (a.window_s * 1e9 / interval_ns as f64).round().max(1.0) as usize;
    let mut rows: Vec<Row> = volumes.iter().map(|_| Row::default()).collect();
    let mut blind = 0;
    for (k, (t, path)) in truth.iter().zip(&walks).enumerate() {
        // The start's frames: their edges, and where the rig was (the last frame stands still).
        // The first frame's detection counts towards the time to the first pose (the first
        // search runs on it).
        let mut seen = Vec::with_capacity(path.len());
        let mut detect_ms = 0.0;
        for _ in path {
            if !source.next_frame(&mut frame).unwrap() {
                break;
            }
            let detect_started = Instant::now();
            seen.push(detector.detect(&frame).to_vec());
            if seen.len() == 1 {
                detect_ms = detect_started.elapsed().as_secs_f64() * 1e3;
            }
        }
        if seen.len() < path.len() {
            break;
        }
        // With `--stand`, the walk's first frame stands still.
        let last_frame = if a.stand { 0 } else { path.len() - 1 };
        let at = |f: usize| (&seen[f.min(last_frame)], path[f.min(last_frame)]);
        let (edges, truth_pose) = (&seen[0], t.pose);
        for (v, &(row_name, radius)) in volumes.iter().enumerate() {
            let angle = draw.next() * std::f64::consts::TAU;
            if !wanted(radius) || a.only.as_ref().is_some_and(|o| !o.contains(&k)) {
                continue;
            }
            let hint = radius.map(|r| SearchVolume {
                centre: Point3::from(
                    truth_pose.translation.vector + Vector3::new(angle.cos(), angle.sin(), 0.0) * HINT_OFFSET_M,
                ),
                diameter_m: Some(2.0 * r),
            });
            let mut tracker = Tracker::new(rig, &model, &table, &cfg, hint, 1 + k as u64);
            if tracker.segments_in_view(&truth_pose) < 3 {
                if volumes[..v].iter().all(|w| !wanted(w.1)) {
                    blind += 1;
                }
                continue;
            }
            let row = &mut rows[v];
            row.counted += 1;
            let started = Instant::now();
            let (mut first, mut committed_at, mut last, mut wrong) = (None, None, None, false);
            let mut first_pose: Option<(u64, Pose)> = None;
            // How far a pose is from where the rig was at its frame's time.
            let t0 = t.timestamp_ns;
            let off_at = |p: &Pose, ts: u64| {
                let truth = at(((ts.saturating_sub(t0)) / interval_ns) as usize).1;
                (
                    (p.translation.vector - truth.translation.vector).norm(),
                    p.rotation.angle_to(&truth.rotation).to_degrees(),
                )
            };
            let mut last_ts = t0;
            for f in 0..window + AFTER {
                if committed_at.is_none() && f >= window {
                    break;
                }
                let ts = t0 + f as u64 * interval_ns;
                let r = tracker.process(at(f).0, ts);
                let mut poses: Vec<(u64, Pose)> = tracker
                    .late()
                    .iter()
                    .filter_map(|(lt, l)| l.pose.map(|p| (*lt, p)))
                    .collect();
                poses.extend(r.pose.map(|p| (ts, p)));
                for (pt, p) in poses {
                    let (dp, dr) = off_at(&p, pt);
                    wrong |= dp > 1.0 || dr > 10.0;
                    if first.is_none() {
                        first_pose = Some((pt, p));
                        first = Some(started.elapsed().as_secs_f64() * 1e3 + detect_ms);
                        committed_at = Some(f);
                    }
                    last = Some(p);
                    last_ts = pt;
                }
                if committed_at.is_some_and(|c| f >= c + AFTER) {
                    break;
                }
            }
            tracker.finish();
            for (lt, l) in tracker.late() {
                if let Some(p) = l.pose {
                    let (dp, dr) = off_at(&p, *lt);
                    wrong |= dp > 1.0 || dr > 10.0;
                    last = Some(p);
                    last_ts = *lt;
                }
            }
            let off = |p: &Pose| off_at(p, last_ts);
            let stats = tracker.stats();
            let cells = (stats.plan_cells_scanned as usize, stats.plan_cells_in_volume as usize);
            row.cells.push(cells);
            let verdict = match last {
                None => {
                    row.none += 1;
                    "no pose".to_string()
                }
                Some(p) => {
                    let (dp, dr) = off(&p);
                    row.within_10 += usize::from(dp <= 0.10 && dr <= 2.0);
                    row.within_30 += usize::from(dp <= 0.30 && dr <= 5.0);
                    row.wrong += usize::from(wrong);
                    format!("{:.1} cm {:.2}°{}", dp * 100.0, dr, if wrong { " WRONG" } else { "" })
                }
            };
            if let Some(ms) = first {
                row.first_pose_ms.push(ms);
            }
            if a.verbose {
                eprintln!(
                    "  start {k} {row_name}: {verdict}; first pose {}; looked at {} of {} cells",
                    first.map_or("none".into(), |ms| format!("{ms:.0} ms")),
                    cells.0,
                    cells.1
                );
                let off_truth = last.is_none_or(|p| off(&p).0 > 0.1 || off(&p).1 > 2.0);
                if off_truth {
                    eprintln!(
                        "{}",
                        diagnose(rig, &model, &table, &cfg, edges, hint, &truth_pose, 1 + k as u64)
                    );
                }
                if let (true, Some((ft, fp))) = (a.walk_m > 0.0 && wrong, first_pose) {
                    // A wrong walk's first pose against the truth, frame by frame: each polished
                    // on every frame of the walk from the first pose's on (the first pose from
                    // where it was polished on the frame before; the truth from the truth).
                    let f0 = ((ft - t0) / interval_ns) as usize;
                    let mut init = omnitrack::tracker::Initialiser::new(
                        rig,
                        &model,
                        &table,
                        omnitrack::tracker::InitOptions::from_config(&cfg),
                        cfg.solver_options(),
                        rig.sensors.len() * cfg.edges.max_edges_per_sensor as usize,
                    );
                    let mut cp = fp;
                    for f in f0..path.len() {
                        let (e, tp) = at(f);
                        let tc = init.polish(&tp, e);
                        let cc = init.polish(&cp, e);
                        if let Some(c) = cc {
                            cp = c.pose;
                        }
                        let fmt = |c: Option<omnitrack::tracker::Candidate>| {
                            c.map_or("none".to_string(), |c| {
                                format!(
                                    "merit {:.3} (explained {:.2} support {:.2} blank {:.2}, {} inliers)",
                                    c.merit(),
                                    c.explained,
                                    c.support,
                                    c.blank,
                                    c.inliers
                                )
                            })
                        };
                        eprintln!("    walk frame {f}: truth {}; first pose {}", fmt(tc), fmt(cc));
                    }
                }
            }
        }
    }
    let appearance = a.appearance.as_deref().unwrap_or("default");
    let title = format!(
        "{name} ({} segments, {long} used), rig {}, {} starts ({blind} more that see fewer than 3 model segments not counted){}, appearance {appearance}",
        model.segments.len(),
        rig.name,
        rows.iter().map(|r| r.counted).max().unwrap_or(0),
        if a.walk_m > 0.0 {
            if a.stand {
                format!(", each the first frame of a {} m walk, standing still", a.walk_m)
            } else {
                format!(", each walking {} m at {WALK_SPEED_M_S} m/s before it stands still", a.walk_m)
            }
        } else {
            String::new()
        },
    );
    let mut table = String::from(
        "| search | within 10 cm / 2° | within 30 cm / 5° | wrong commits | no pose | cells looked at (all searches) | first pose p50 / max (ms) |\n| --- | --- | --- | --- | --- | --- | --- |",
    );
    for (row, (row_name, radius)) in rows.iter_mut().zip(volumes) {
        if !wanted(radius) {
            continue;
        }
        row.first_pose_ms.sort_by(f64::total_cmp);
        let (looked, of) = row.cells.iter().fold((0, 0), |s, c| (s.0 + c.0, s.1 + c.1));
        table.push_str(&format!(
            "\n| {row_name} | {} of {n} | {} | {} | {} | {looked} of {of} | {} |",
            row.within_10,
            row.within_30,
            row.wrong,
            row.none,
            match row.first_pose_ms.last() {
                Some(max) => format!("{:.0} / {max:.0}", percentile(&row.first_pose_ms, 0.5)),
                None => "no first pose".into(),
            },
            n = row.counted,
        ));
    }
    println!("\n{title}:\n\n{table}");
    let note = format!(
        "{table}\n\nStarts drawn with seed {}; {}. Wrong: a pose more than 1 m or 10° off on any frame. \
         First-pose times are wall time (edges and search) on this machine, with whatever else ran on it. \
         A trial waits {} s of frames for a pose{}.",
        a.seed,
        match &a.config {
            Some(c) => format!("config {} (NOT the shipped one)", c.display()),
            None => "the shipped configuration".into(),
        },
        a.window_s,
        if a.window_s == WINDOW_S {
            " (the default)"
        } else {
            " (NOT the default 30 s)"
        }
    );
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    // The command as given (the recording's cache label is not an option: it also names the rig).
    let mut command = format!("cargo bench --bench tracker -- --model {}", model_path.display());
    if let Some(r) = &a.rig {
        command.push_str(&format!(" --rig {}", r.display()));
    }
    command.push_str(&format!(" --starts {}", a.starts));
    if let Some(spec) = &a.appearance {
        command.push_str(&format!(" --appearance {spec}"));
    }
    if a.window_s != WINDOW_S {
        command.push_str(&format!(" --window {}", a.window_s));
    }
    if let Some(r) = &a.rows {
        command.push_str(&format!(" --rows {r}"));
    }
    // A file of some starts only says so: its rows are not the whole set's.
    if let Some(only) = &a.only {
        let list: Vec<String> = only.iter().map(|k| k.to_string()).collect();
        command.push_str(&format!(" --only {}", list.join(",")));
    }
    if a.walk_m > 0.0 {
        command.push_str(&format!(" --walk {}", a.walk_m));
    }
    if a.stand {
        command.push_str(" --stand");
    }
    if let Some(c) = &a.config {
        command.push_str(&format!(" --config {}", c.display()));
    }
    match omnitrack::desk::results::write(
        root,
        &format!("detailed-{name}-{}-{appearance}{result_label}", rig.name),
        &title,
        &command,
        &note,
    ) {
        Ok(path) => eprintln!("{name}: results in {}", path.display()),
        Err(e) => eprintln!("{name}: results file not written: {e}"),
    }
}

/// The search of one start taken apart (`--verbose`, for starts not placed within 10 cm): the
/// truth as the search's scores see it, and the search's candidates with their distances from
/// it and their scores, each also with its share explained over resolved lines and its chance
/// support (the support of the pose turned ±3° and ±6° about the vertical: what its segments
/// explain by chance; docs/decisions.md, 2026-12-02).
#[allow(clippy::too_many_arguments)]
pub(crate) fn diagnose(
    rig: &Rig,
    model: &Model,
    table: &omnitrack::visibility::VisibilityTable,
    cfg: &TrackerConfig,
    edges: &[omnitrack::edges::Edge],
    hint: Option<SearchVolume>,
    truth: &Pose,
    seed: u64,
) -> String {
    use omnitrack::tracker::{InitOptions, Initialiser};
    use rand::SeedableRng;
    use std::fmt::Write;
    let max_edges = rig.sensors.len() * cfg.edges.max_edges_per_sensor as usize;
    let mut init = Initialiser::new(
        rig,
        model,
        table,
        InitOptions::from_config(cfg),
        cfg.solver_options(),
        max_edges,
    );
    let volume = hint.unwrap_or(SearchVolume {
        centre: Point3::origin(),
        diameter_m: None,
    });
    if volume.diameter_m.is_none() {
        init.set_time_budget(std::time::Duration::from_secs_f64(
            cfg.initialisation.whole_model_time_budget_ms / 1e3,
        ));
    }
    let err = |p: &Pose| {
        (
            (p.translation.vector - truth.translation.vector).norm(),
            p.rotation.angle_to(&truth.rotation).to_degrees(),
        )
    };
    // The support of the pose turned about the vertical by a few degrees (beyond the inlier
    // gate): what its segments explain by chance.
    let chance = |init: &mut Initialiser, p: &Pose| -> f64 {
        let mut sum = 0.0;
        for d in [-6.0f64, -3.0, 3.0, 6.0] {
            let turned = Pose::from_parts(
                p.translation,
                nalgebra::UnitQuaternion::from_axis_angle(&nalgebra::Vector3::z_axis(), d.to_radians()) * p.rotation,
            );
            sum += init.edge_support(&turned, edges);
        }
        sum / 4.0
    };
    let mut line = String::from("    truth:");
    match init.polish(truth, edges) {
        Some(c) => {
            let (dp, dr) = err(&c.pose);
            let _ = write!(
                line,
                " polished {dp:.3} m {dr:.2}°, merit {:.3} (explained {:.2} support {:.2} blank {:.2}, {} inliers; resolved {:.2}, chance support {:.3})",
                c.merit(),
                c.explained,
                c.support,
                c.blank,
                c.inliers,
                init.explained_resolved(&c.pose, edges),
                chance(&mut init, &c.pose)
            );
        }
        None => line.push_str(" polished: none"),
    }
    let mut rng = rand::rngs::SmallRng::seed_from_u64(seed);
    let (candidates, report) = init.run(edges, &volume, &mut rng);
    let candidates = candidates.to_vec();
    let _ = write!(
        line,
        "; grid merit {:.3}\n    search: {} rotations, looked at {} of {} cells, triplets in {} of {}, work {} (scan {} over {} positions, {} climbed), {:.0} ms{}",
        init.grid_merit(truth).unwrap_or(f64::NAN),
        report.rotations,
        report.plan_cells_scanned,
        report.plan_cells_in_volume,
        report.cells_searched,
        report.cells_in_volume,
        report.work,
        report.scan_work,
        report.positions_scored,
        report.climbed,
        report.elapsed.as_secs_f64() * 1e3,
        if report.backstop { " (backstop)" } else { "" }
    );
    // The grid's kept positions under the truth's rotation (within 10°), nearest the truth first.
    let mut kept: Vec<(f64, f64)> = init
        .grid_kept()
        .filter(|(_, p)| err(p).1 <= 10.0)
        .map(|(m, p)| (err(&p).0, m))
        .collect();
    kept.sort_by(|a, b| a.0.total_cmp(&b.0));
    let _ = write!(
        line,
        "\n      grid kept under the truth's rotation (m from the truth, merit):"
    );
    for (d, m) in kept.iter().take(8) {
        let _ = write!(line, " {d:.2}/{m:.3}");
    }
    for c in candidates.iter().take(8) {
        let (dp, dr) = err(&c.pose);
        let _ = write!(
            line,
            "\n      {dp:6.2} m {dr:6.1}°: merit {:.3} (explained {:.2} support {:.2} blank {:.2}, {} inliers; resolved {:.2}, chance support {:.3}), grid {:.3}",
            c.merit(),
            c.explained,
            c.support,
            c.blank,
            c.inliers,
            init.explained_resolved(&c.pose, edges),
            chance(&mut init, &c.pose),
            init.grid_merit(&c.pose).unwrap_or(f64::NAN)
        );
    }
    line
}
