//! The tracker end to end on rendered recordings of the paper's scenarios: accuracy against the
//! ground truth (absolute trajectory error, no alignment: both are in the model frame), the
//! fraction of frames tracked, re-initialisations, initialisation time, per-frame latency and
//! frames per second (edge extraction + tracking; PNG decoding of the replay excluded).
//!
//! Run: `cargo bench --bench tracker` (needs the `desk` feature, on by default). Options after
//! `--`: `--scenario lab|corridor|handheld` (repeatable; default all three), `--frames N`
//! (default 300 per scenario; `--full` for the paper's lengths, Table 2: 1500, 7800 and 1900
//! frames — an hour of rendering on 2 cores, cached afterwards), `--seed S` (the rendering's:
//! a new seed renders a new recording), `--tracker-seed S` (the tracker's random sampling, default
//! 1: the same recording tracked by another draw), `--tracker-seeds A-B` (each of those seeds in
//! turn, one row each, then the median, best and worst ATE over them: the searches work to a
//! clock, so a scenario that relocalises often gives different runs; quote several seeds),
//! `--verbose` (one line
//! per frame), `--upright` (KT §5.4 mode for the rolling scenarios), `--no-hint` (search the
//! whole model instead of a 3 m volume around the first ground-truth pose), `--config tracker.toml`,
//! `--rig RIG.toml` (render and track with another rig: `tools/rigs/` has examples),
//! `--one-frame` (track the rendered images joined into one device frame per instant, each
//! sensor `crop`ped from it on replay, as a dual-fisheye 360° camera delivers them),
//! `--appearance realistic` (render with `Appearance::realistic()`: floorboards, trims, built-ins,
//! closed doors, walls a few cm off the model, blur and JPEG — the world of the real photos,
//! issue 19; cached apart from the default renders; any `Appearance::from_spec` spec works, e.g.
//! `realistic+blur_px=0` to see what one effect does).
//!
//! It first reproduces Koch–Teller Figure 15 as a table (`--no-figure15` skips it).
//!
//! `--init-trials N` measures initialisation alone instead (the paper's admitted weakness:
//! repeated structure such as doorways along a corridor): from N start frames spread over the
//! recording, a fresh tracker searches a 3 m volume whose centre is 1 m from the true position
//! (in a different direction each trial) until it commits, and the commit is judged right
//! (within 10 cm and 1°) or wrong, with the time and frames it took. A trial whose start frame
//! sees fewer than three model segments (in sight and on a sensor's image at the true pose) is
//! not counted: no search can place such a frame. With `--from-truth` each trial starts tracking
//! at the true pose instead of searching: what maintenance makes of a right commit, the ceiling
//! of the trials' "right". With `--still` each trial replays its start frame alone, again and
//! again a frame interval apart (a rig standing still; issue 19's protocol for the one-pinhole
//! case, "every 10th frame replayed alone"), so the trial measures the search and not the
//! maintenance of a moving narrow view.
//!
//! `--hold N` measures maintenance alone instead (issue 47, item 4; module `hold`): N stretches
//! of 90 frames spread over each recording, each started at the true pose, every frame judged:
//! the share within 10 cm and 1° of the truth, more than 30 cm or 3° off, and without a pose.
//!
//! `--buildings A-B` tracks walks through random buildings nobody here drew instead
//! (`desk::scenario::random`, seeds A to B: L, U, courtyard and rectangular outlines, single-face
//! or thick walls, random winding, triangulated faces, two storeys with a stair hall; furniture
//! and people in the images only). Per building: a walk of `--seconds S` (default 40) at the
//! building's frame rate, rendered once; the recall of its visibility table's VIS(T) along the
//! walk against brute-force ray casting (`desk::vis_truth`, every 10th pose); one tracking run
//! from a 3 m volume round the first pose; and `--starts N` (default 10) initialisation trials
//! as `--init-trials` runs them, spread over the walk (overlapping where the walk is short).
//! `--pin L,thin,cart` pins draws of every building (`Choices::parse`: outline, walls, storeys,
//! triangles, motion) and caches its recordings apart.
//! Then one table row per building and a summary line: median ATE, fewest frames tracked, and the
//! share of commits off the truth.
//!
//! `--model MODEL.obj` measures the first pose in a detailed model instead (issue 47; module
//! `detailed`): `--starts N` start poses sampled over the model (`--seed`), each rendered once
//! and searched from a 1.5 m hint, a 3 m hint and no hint; the rows count poses within 10 cm,
//! wrong commits, starts without a pose, the grid cells the searches looked at and the time to
//! the first pose. For an IFC building, convert it first (`omnitrack-desk model from-ifc`).
//! `--walk M` makes each start a walk of M metres (0.5 m/s, the head turning) before it stands
//! still, as a rig carried into view would be, rather than a still frame; `--stand` replays
//! each walk's first frame still instead (the walk's own images: the renders' noise follows the
//! frame).
//!
//! Recordings are cached in `target/omnitrack-cache/` (or `$OMNITRACK_CACHE`).

mod buildings;
mod detailed;
mod figure15;
mod hold;
mod init_trials;
mod run;

use buildings::buildings;
use detailed::detailed;
use figure15::figure15;
use hold::{hold, HoldSummary, HOLD_HEADER};
use init_trials::{init_trials, WINDOW_AND_AFTER};
use run::{hint_at_start, run_once};

use omnitrack::capture::{Pacing, ReplaySource};
use omnitrack::config::TrackerConfig;
use omnitrack::desk::recording::{cached_scenario, RecordingOptions};
use omnitrack::desk::scenario::{Motion, Scenario, ScenarioName};
use omnitrack::runtime::load_or_build_table;
use omnitrack::trajectory::Stamped;
use omnitrack::{Model, Rig};
use std::path::{Path, PathBuf};

use omnitrack::desk::results::percentile;

/// The largest standard deviation of a pose covariance's position (`block` 0, m) or rotation
/// (`block` 3, rad) block.
fn largest_sigma(cov: &nalgebra::Matrix6<f64>, block: usize) -> f64 {
    cov.fixed_view::<3, 3>(block, block)
        .symmetric_eigenvalues()
        .max()
        .max(0.0)
        .sqrt()
}

struct Args {
    scenarios: Vec<ScenarioName>,
    frames: Option<usize>,
    full: bool,
    seed: u64,
    verbose: bool,
    upright: bool,
    hint: bool,
    config: Option<PathBuf>,
    rig: Option<PathBuf>,
    figure15: bool,
    init_trials: usize,
    hold: usize,
    tracker_seeds: Vec<u64>,
    appearance: Option<String>,
    from_truth: bool,
    still: bool,
    buildings: Vec<u64>,
    pins: Option<String>,
    seconds: f64,
    starts: usize,
    one_frame: bool,
    model: Option<PathBuf>,
    /// `--model` mode: seconds of frames a trial waits for a pose, and the rows searched.
    window_s: f64,
    rows: Option<String>,
    only: Option<Vec<usize>>,
    /// `--model` mode: metres each start walks before it stands still (0: a still start); with
    /// `--stand`, the walk's first frame is replayed still (the same images as the walk's start).
    walk_m: f64,
    stand: bool,
}

fn args() -> Args {
    let mut a = Args {
        scenarios: vec![],
        frames: None,
        full: false,
        seed: 11,
        verbose: false,
        upright: false,
        hint: true,
        config: None,
        rig: None,
        figure15: true,
        init_trials: 0,
        hold: 0,
        tracker_seeds: vec![1],
        appearance: None,
        from_truth: false,
        still: false,
        buildings: vec![],
        pins: None,
        seconds: 40.0,
        starts: 10,
        one_frame: false,
        model: None,
        window_s: 30.0,
        rows: None,
        only: None,
        walk_m: 0.0,
        stand: false,
    };
    let mut it = std::env::args().skip(1);
    while let Some(x) = it.next() {
        match x.as_str() {
            "--scenario" => a
                .scenarios
                .push(it.next().and_then(|s| s.parse().ok()).expect("--scenario NAME")),
            "--frames" => a.frames = it.next().and_then(|s| s.parse().ok()),
            "--seed" => a.seed = it.next().and_then(|s| s.parse().ok()).expect("--seed S"),
            "--full" => a.full = true,
            "--verbose" => a.verbose = true,
            "--upright" => a.upright = true,
            "--no-hint" => a.hint = false,
            "--config" => a.config = it.next().map(PathBuf::from),
            "--rig" => a.rig = Some(it.next().map(PathBuf::from).expect("--rig RIG.toml")),
            "--no-figure15" => a.figure15 = false,
            "--one-frame" => a.one_frame = true,
            "--model" => a.model = Some(it.next().map(PathBuf::from).expect("--model MODEL.obj")),
            "--appearance" => {
                let spec = it.next().expect("--appearance SPEC");
                a.appearance = (spec != "default").then_some(spec);
            }
            "--tracker-seed" => {
                a.tracker_seeds = vec![it.next().and_then(|s| s.parse().ok()).expect("--tracker-seed S")]
            }
            "--tracker-seeds" => {
                let spec = it.next().expect("--tracker-seeds A-B");
                let range = spec
                    .split_once('-')
                    .and_then(|(lo, hi)| Some((lo.parse::<u64>().ok()?, hi.parse::<u64>().ok()?)))
                    .filter(|(lo, hi)| lo <= hi)
                    .expect("--tracker-seeds A-B (A <= B)");
                a.tracker_seeds = (range.0..=range.1).collect();
            }
            "--from-truth" => a.from_truth = true,
            "--still" => a.still = true,
            "--buildings" => {
                let spec = it.next().expect("--buildings A-B");
                let (lo, hi) = spec.split_once('-').unwrap_or((spec.as_str(), spec.as_str()));
                let (lo, hi): (u64, u64) = (
                    lo.parse().expect("--buildings A-B"),
                    hi.parse().expect("--buildings A-B"),
                );
                a.buildings = (lo..=hi).collect();
            }
            "--pin" => a.pins = Some(it.next().expect("--pin L,thin,cart")),
            "--seconds" => a.seconds = it.next().and_then(|s| s.parse().ok()).expect("--seconds S"),
            "--starts" => a.starts = it.next().and_then(|s| s.parse().ok()).expect("--starts N"),
            "--hold" => a.hold = it.next().and_then(|s| s.parse().ok()).expect("--hold N"),
            "--stand" => a.stand = true,
            "--walk" => a.walk_m = it.next().and_then(|s| s.parse().ok()).expect("--walk METRES"),
            "--window" => a.window_s = it.next().and_then(|s| s.parse().ok()).expect("--window SECONDS"),
            "--only" => {
                let spec = it.next().expect("--only K,K,...");
                a.only = Some(
                    spec.split(',')
                        .map(|k| k.trim().parse().expect("--only K,K,..."))
                        .collect(),
                );
            }
            "--rows" => a.rows = Some(it.next().expect("--rows 1.5,3,none")),
            "--init-trials" => a.init_trials = it.next().and_then(|s| s.parse().ok()).expect("--init-trials N"),
            _ => {}
        }
    }
    if a.scenarios.is_empty() {
        a.scenarios = ScenarioName::ALL.to_vec();
    }
    a
}

fn cache_root() -> PathBuf {
    omnitrack::desk::recording::cache_root(Path::new(env!("CARGO_MANIFEST_DIR")))
}

fn main() {
    let a = args();
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("firmware_config/ladybug2.toml");
    let rig = match Rig::load(a.rig.as_ref().unwrap_or(&shipped)) {
        Ok(rig) => rig,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(2);
        }
    };
    // Recordings of other rigs are cached apart from the shipped rig's.
    let mut label = match &a.rig {
        None => "default".to_string(),
        Some(_) => format!("rig-{}", rig.name),
    };
    let mut options = RecordingOptions::default();
    if let Some(spec) = &a.appearance {
        options.appearance = omnitrack::desk::render::Appearance::from_spec(spec).unwrap_or_else(|e| {
            eprintln!("--appearance {e}");
            std::process::exit(2);
        });
        // The spec names the recording: `realistic` for the preset docs/real-photos.md quotes.
        label = if a.rig.is_some() {
            format!("{label}-{spec}")
        } else {
            spec.clone()
        };
    }
    if let Some(model) = &a.model {
        detailed(&a, &rig, &label, &options, model);
        return;
    }
    println!(
        "| scenario | frames | tracked on time (with late poses) | re-inits (relocalised) | ATE pos RMSE / max (cm) | ATE rot RMSE / max (°) | init (ms) | frame p50 / p99 / max (ms) | frames/s |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- | --- | --- |");
    if !a.buildings.is_empty() {
        buildings(&a, &rig, &label, &options);
        return;
    }
    if a.figure15 {
        figure15(&rig);
    }
    let mut held = HoldSummary::default();
    let mut held_rows = Vec::new();
    for name in &a.scenarios {
        let scenario = Scenario::get(*name);
        let frames = a.frames.unwrap_or(if a.full { scenario.paper_frames } else { 300 });
        let (dir, made) = cached_scenario(
            &cache_root(),
            &scenario,
            frames,
            a.seed,
            &label,
            &rig,
            &options,
            |d, t| eprint!("\rrendering {name}: {d}/{t}"),
        )
        .unwrap();
        if made {
            eprintln!();
        }
        let dir = if a.one_frame {
            // The same images as one device's frames, each sensor cropped from them on replay.
            let joined = dir.with_file_name(format!("{}-one-frame", dir.file_name().unwrap().to_string_lossy()));
            if omnitrack::desk::recording::join_sensors(&dir, &joined, "/dev/video0").unwrap() {
                eprintln!(
                    "{name}: joined every frame's images into one device frame: {}",
                    joined.display()
                );
            }
            joined
        } else {
            dir
        };
        let model_path = dir.join("model.obj");
        let model = Model::load(&model_path).unwrap();
        let mut cfg = match &a.config {
            Some(p) => TrackerConfig::load(p).unwrap(),
            None => TrackerConfig::default(),
        };
        if a.upright {
            if let Motion::Rolling3Dof { height_m } = scenario.motion {
                cfg.motion.upright = true;
                cfg.motion.upright_height_m = height_m;
            }
        }
        let (table, origin) = load_or_build_table(&model_path, &model, None, &cfg).unwrap();
        eprintln!("{name}: {origin}");
        let mut source = ReplaySource::open(&dir, Pacing::AsFastAsPossible).unwrap();
        let truth: Vec<Stamped> = source.ground_truth().unwrap().to_vec();
        if a.hold > 0 {
            let h = hold(
                name.as_str(),
                &rig,
                &model,
                &table,
                &cfg,
                &mut source,
                &truth,
                a.hold,
                a.verbose,
            );
            held.add(&h);
            held_rows.push(h.row(name.as_str()));
            continue;
        }
        if a.init_trials > 0 {
            init_trials(
                name.as_str(),
                &rig,
                &model,
                &table,
                &cfg,
                &mut source,
                &truth,
                a.init_trials,
                a.verbose,
                a.from_truth,
                a.still,
                // Trials of the scenarios do not overlap (issue 19's protocol).
                WINDOW_AND_AFTER,
            );
            continue;
        }
        // Each tracker seed in turn: one row each (the seed in the row's name when there are
        // several), then the spread of the ATE over them.
        let mut per_seed: Vec<f64> = Vec::new();
        for &tracker_seed in &a.tracker_seeds {
            let row = if a.tracker_seeds.len() > 1 {
                format!("{name} (tracker seed {tracker_seed})")
            } else {
                name.to_string()
            };
            let hint = a.hint.then(|| hint_at_start(&truth, &cfg));
            if let Some(out) = run_once(
                &row,
                name.as_str(),
                &dir,
                &model,
                &table,
                &cfg,
                &truth,
                hint,
                tracker_seed,
                a.verbose,
            ) {
                per_seed.push(out.ate_pos_cm);
            }
        }
        if per_seed.len() > 1 {
            per_seed.sort_by(f64::total_cmp);
            eprintln!(
                "{name}: ATE pos RMSE over tracker seeds {}-{}: median {:.2} cm, best {:.2}, worst {:.2} ({} of {} runs with a pose)",
                a.tracker_seeds[0],
                a.tracker_seeds[a.tracker_seeds.len() - 1],
                percentile(&per_seed, 0.5),
                per_seed[0],
                per_seed[per_seed.len() - 1],
                per_seed.len(),
                a.tracker_seeds.len()
            );
        }
    }
    if a.hold > 0 {
        let pct = |n: usize| 100.0 * n as f64 / held.frames.max(1) as f64;
        println!(
            "all: {:.1} % of {} frames within 10 cm / 1°, {:.1} % more than 30 cm or 3° off, {:.1} % without a pose, {} losses of lock, {} frames of few lines taken by the motion filter",
            pct(held.right),
            held.frames,
            pct(held.wrong),
            pct(held.none),
            held.losses,
            held.filtered_few_lines
        );
        held_rows.push(held.row("all"));
        let table = format!("{HOLD_HEADER}\n{}", held_rows.join("\n"));
        let note = format!(
            "{table}\n\n{} stretches of {} frames per recording ({} frames, seed {}), each started at the true pose; \
             a frame counts by its pose on time or late. {}.",
            a.hold,
            hold::HOLD_FRAMES,
            a.frames.unwrap_or(300),
            a.seed,
            match &a.config {
                Some(c) => format!("Config {} (NOT the shipped one)", c.display()),
                None => "The shipped configuration".into(),
            }
        );
        let title = format!("Maintenance held from the truth (`--hold`), rig {}", rig.name);
        let command = format!(
            "cargo bench --bench tracker -- {}--no-figure15 --hold {}",
            a.rig
                .as_ref()
                .map_or(String::new(), |r| format!("--rig {} ", r.display())),
            a.hold
        );
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        match omnitrack::desk::results::write(root, &format!("hold-{}", rig.name), &title, &command, &note) {
            Ok(path) => eprintln!("results in {}", path.display()),
            Err(e) => eprintln!("results file not written: {e}"),
        }
    }
}
