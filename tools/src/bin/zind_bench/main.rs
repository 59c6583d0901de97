//! `zind_bench`: the tracker's initialisation on real 360° photographs of a real house.
//!
//! ```text
//! cargo run --release -p omnitrack-tools --bin zind_bench -- --tour PATH/sample_tour/000 \
//!     [--rig firmware_config/ladybug2.toml --rig tools/rigs/pinhole4.toml ...] [--out DIR]
//! ```
//!
//! In: a local copy of one Zillow Indoor Dataset tour (its `zind_data.json` and `panos/`; the
//! docs/real-photos.md says how to get the public sample tour; its terms are academic and non-commercial, so
//! none of it is ever committed). Out (under `--out`, default `target/zind`): the coarse model
//! built from the room layouts (`plan.geojson`, `model.obj`), one recording per rig and
//! panorama (the layout of docs/interfaces.md, "Recording": every frame is the same instant,
//! replayable by
//! `omnitrack run`), overlays of the model at the annotated pose, `results.csv`, and on stdout
//! one table per rig:
//!
//! - rows: the search volume: the `--init` hint of radius 1.5 m and 3 m, its centre 0.72 m from
//!   the truth in a seeded random direction, and no hint (the whole house);
//! - columns: within 10 cm / 2° and within 30 cm / 5° on the last frame; wrong commits (any
//!   frame's pose more than 1 m or 10° off); no pose on any frame; the median and worst time
//!   to the first pose (edges + tracking, image decoding excluded).
//!
//! Each panorama becomes a rig's images by casting every pixel's ray (through the rig's lens,
//! 2 × 2 rays per pixel) into the equirectangular photo, bilinearly. A panorama has one centre,
//! so the rig's sensor centres are moved onto it (their directions are kept): parallax of a few
//! centimetres cannot be made from one photo. The tracker runs in-process with the shipped
//! `firmware_config/tracker.toml` (or `--config`), exactly as `omnitrack run` would.

mod diagnose;
mod resample;
mod tour;

use diagnose::diagnose;

use clap::Parser;
use nalgebra::{Point3, Unit, Vector3};
use omnitrack::capture::replay::{Pacing, ReplaySource};
use omnitrack::config::TrackerConfig;
use omnitrack::desk::floorplan;
use omnitrack::desk::pictures::{omni_view, OmniOptions};
use omnitrack::desk::recording::{image_path, write_png};
use omnitrack::geometry::Pose;
use omnitrack::runtime::{load_or_build_table, track, RunOptions};
use omnitrack::tracker::SearchVolume;
use omnitrack::trajectory::{to_tum_string, Stamped};
use omnitrack::visibility::at_pose::PoseVisibility;
use omnitrack::visibility::VisibilityTable;
use omnitrack::{Model, Rig};
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Duration;

#[derive(Parser)]
#[command(name = "zind_bench", about = "Initialisation on the real panoramas of a ZInD tour")]
struct Cli {
    /// The tour directory (holding zind_data.json and panos/).
    #[arg(long, value_name = "DIR")]
    tour: PathBuf,
    /// The floor to use (default: the first).
    #[arg(long)]
    floor: Option<String>,
    /// Rigs to turn the panoramas into (repeatable; default: the shipped ladybug2 and the two
    /// example rigs of tools/rigs).
    #[arg(long = "rig", value_name = "RIG.toml")]
    rigs: Vec<PathBuf>,
    /// The tracker configuration (default: the shipped firmware_config/tracker.toml).
    #[arg(long, value_name = "tracker.toml")]
    config: Option<PathBuf>,
    /// Where the model, recordings, overlays and results go.
    #[arg(long, value_name = "DIR", default_value = "target/zind")]
    out: PathBuf,
    /// Frames per recording (all of the same instant): the search, the confirmation frames and
    /// some tracking.
    #[arg(long, default_value_t = 6)]
    frames: usize,
    /// Distance of the hint's centre from the truth (m).
    #[arg(long, default_value_t = 0.72)]
    hint_offset_m: f64,
    /// Search volumes: hint radii in metres and/or `none` (the whole house).
    #[arg(long, value_delimiter = ',', default_value = "1.5,3,none")]
    rows: Vec<String>,
    /// Only these panoramas (ZInD ids such as pano_14); default: all.
    #[arg(long, value_delimiter = ',')]
    panos: Vec<String>,
    /// Seed of the hints and of the tracker's sampling.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Print one line per panorama and row.
    #[arg(long)]
    verbose: bool,
    /// Print every frame's state, error against the truth and tracker event (stderr).
    #[arg(long)]
    events: bool,
    /// Instead of the table: per panorama, what the initialisation sees at the true pose (the
    /// share of VIS(T) explained, the polished truth's score against the acceptance limit) and
    /// the search's candidates from the first hint radius (the whole house when no row has a
    /// hint), each with the grid's coarse merit (the truth's too) and the soft share explained
    /// (1 − truncated ξ / cap²); the best wrong candidate drawn over the images in
    /// RIG/PANO/rival.jpg.
    #[arg(long)]
    diagnose: bool,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(&cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("zind_bench: {e}");
            ExitCode::from(2)
        }
    }
}

/// One row of the table: a search volume.
#[derive(Clone, Copy)]
enum Row {
    Hint(f64),
    WholeHouse,
}

impl Row {
    fn parse(text: &str) -> Result<Row, String> {
        if text == "none" {
            return Ok(Row::WholeHouse);
        }
        match text.parse::<f64>() {
            Ok(r) if r.is_finite() && r > 0.0 => Ok(Row::Hint(r)),
            _ => Err(format!(
                "--rows: {text:?} is neither a positive radius in metres nor `none`"
            )),
        }
    }

    fn name(&self) -> String {
        match self {
            Row::Hint(r) => format!("hint, radius {r} m"),
            Row::WholeHouse => "no hint (whole house)".into(),
        }
    }
}

/// What became of one panorama in one row.
#[derive(Debug, Clone, Default)]
struct Outcome {
    /// Last frame's pose error (m, deg), if it had a pose.
    last: Option<(f64, f64)>,
    /// Last frame's position error along the world axes (x, y, z), m: a coarse model's walls
    /// and a nominal camera height show as a bias in one direction.
    last_offset: Option<Vector3<f64>>,
    /// Some frame's pose was more than 1 m or 10° off.
    wrong: bool,
    first_pose_frame: Option<usize>,
    time_to_first_pose: Option<Duration>,
    /// Edges + tracking over all frames.
    total_time: Duration,
}

fn run(cli: &Cli) -> Result<(), String> {
    let rows = cli.rows.iter().map(|r| Row::parse(r)).collect::<Result<Vec<_>, _>>()?;
    if !(cli.hint_offset_m.is_finite() && cli.hint_offset_m >= 0.0) {
        return Err(format!(
            "--hint-offset-m: {} is not a distance (finite, 0 or more)",
            cli.hint_offset_m
        ));
    }
    if cli.frames == 0 {
        return Err("--frames: a recording needs at least one frame".into());
    }
    let json_path = cli.tour.join("zind_data.json");
    let json = std::fs::read_to_string(&json_path).map_err(|e| format!("{}: {e}", json_path.display()))?;
    let tour = tour::parse(&json, cli.floor.as_deref()).map_err(|e| format!("{}: {e}", json_path.display()))?;
    let mut panos: Vec<&tour::Pano> = tour.panos.iter().collect();
    // A hint's direction is seeded by the panorama's place in the whole tour, so that a run of
    // a few (`--panos`) gives them the hints, and the results, of the full run.
    let tour_index = |pano: &tour::Pano| tour.panos.iter().position(|p| p.id == pano.id).unwrap_or(0);
    if !cli.panos.is_empty() {
        for wanted in &cli.panos {
            if !tour.panos.iter().any(|p| &p.id == wanted) {
                return Err(format!("--panos: the tour has no {wanted}"));
            }
        }
        panos.retain(|p| cli.panos.contains(&p.id));
    }

    std::fs::create_dir_all(&cli.out).map_err(|e| format!("{}: {e}", cli.out.display()))?;
    let plan = tour.plan_geojson();
    let plan_path = cli.out.join("plan.geojson");
    write(&plan_path, plan.as_bytes())?;
    let obj = floorplan::extrude(&plan, &plan_path.display().to_string()).map_err(|e| e.to_string())?;
    let model_path = cli.out.join("model.obj");
    write(&model_path, obj.as_bytes())?;
    let model = Model::load(&model_path).map_err(|e| e.to_string())?;
    let config_path = cli
        .config
        .clone()
        .unwrap_or_else(|| PathBuf::from("firmware_config/tracker.toml"));
    let cfg = TrackerConfig::load(&config_path).map_err(|e| e.to_string())?;
    let (table, origin) = load_or_build_table(&model_path, &model, None, &cfg).map_err(|e| e.to_string())?;
    eprintln!(
        "zind_bench: {} rooms, {} panoramas; model {} faces, {} segments; {origin}",
        tour.rooms.len(),
        tour.panos.len(),
        model.faces.len(),
        model.segments.len()
    );

    let rig_paths = if cli.rigs.is_empty() {
        vec![
            PathBuf::from("firmware_config/ladybug2.toml"),
            PathBuf::from("tools/rigs/pinhole4.toml"),
            PathBuf::from("tools/rigs/dual_fisheye.toml"),
        ]
    } else {
        cli.rigs.clone()
    };
    let mut csv = String::from("rig,pano,row,pos_err_m,rot_err_deg,wrong,first_pose_frame,time_to_first_pose_ms\n");
    for rig_path in &rig_paths {
        let rig = centred(&Rig::load(rig_path).map_err(|e| e.to_string())?);
        let rig_dir = cli.out.join(&rig.name);
        let mut recordings = Vec::new();
        for pano in &panos {
            let dir = rig_dir.join(&pano.id);
            make_recording(&dir, &cli.tour, pano, &rig, (&model, &table), cli.frames)?;
            recordings.push(dir);
        }
        if cli.diagnose {
            let radius = rows.iter().find_map(|r| match r {
                Row::Hint(r) => Some(*r),
                Row::WholeHouse => None,
            });
            let (mut found, mut first) = (0, 0);
            for (pano, dir) in panos.iter().zip(&recordings) {
                let k = tour_index(pano);
                let truth = pano.t_world_rig();
                // With no hinted row, the whole house is searched, from the centre the tracker
                // gives a search without a hint (the model's origin): the whole model's cells
                // are scanned nearest that centre first, and the budget may end before the last.
                let volume = match radius {
                    Some(r) => SearchVolume {
                        centre: hint_centre(&truth, cli.hint_offset_m, cli.seed, k),
                        diameter_m: Some(2.0 * r),
                    },
                    None => SearchVolume {
                        centre: Point3::origin(),
                        diameter_m: None,
                    },
                };
                let rank = diagnose(dir, &pano.id, &model, &table, &cfg, volume, cli.seed, &truth)?;
                found += rank.is_some() as usize;
                first += (rank == Some(0)) as usize;
            }
            println!(
                "{}: the search's candidates hold the truth (10 cm, 2°) for {found} of {}, first for {first}",
                rig.name,
                panos.len()
            );
            continue;
        }
        println!(
            "\nrig {} ({} sensors), {} panoramas, {}",
            rig.name,
            rig.sensors.len(),
            panos.len(),
            today()
        );
        let header = "| search volume | within 10 cm / 2° | within 30 cm / 5° | wrong commits | no pose | first pose p50 / max (ms) |\n| --- | --- | --- | --- | --- | --- |";
        println!("{header}");
        let mut summary = String::from(header);
        let mut misses = String::new();
        for row in &rows {
            let mut outcomes = Vec::new();
            for (pano, dir) in panos.iter().zip(&recordings) {
                let k = tour_index(pano);
                let truth = pano.t_world_rig();
                let hint = match row {
                    Row::Hint(radius) => Some(SearchVolume {
                        centre: hint_centre(&truth, cli.hint_offset_m, cli.seed, k),
                        diameter_m: Some(2.0 * radius),
                    }),
                    Row::WholeHouse => None,
                };
                let outcome = track_one(dir, &model, &table, &cfg, hint, cli.seed, cli.events, &truth)?;
                let (dp, dr) = outcome.last.unwrap_or((f64::NAN, f64::NAN));
                let _ = writeln!(
                    csv,
                    "{},{},{},{dp:.4},{dr:.3},{},{},{}",
                    rig.name,
                    pano.id,
                    row.name(),
                    outcome.wrong,
                    outcome.first_pose_frame.map(|f| f.to_string()).unwrap_or_default(),
                    outcome
                        .time_to_first_pose
                        .map(|t| format!("{:.1}", ms(t)))
                        .unwrap_or_default()
                );
                if cli.verbose {
                    eprintln!(
                        "  {} {:<8} {:<22} error {:>7.3} m {:>7.2}° (x, y, z {}) wrong {} first pose frame {:?} after {:?} ms",
                        rig.name,
                        pano.id,
                        row.name(),
                        dp,
                        dr,
                        outcome
                            .last_offset
                            .map(|v| format!("{:+.3}, {:+.3}, {:+.3} m", v.x, v.y, v.z))
                            .unwrap_or_else(|| "-".into()),
                        outcome.wrong,
                        outcome.first_pose_frame,
                        outcome.time_to_first_pose.map(ms)
                    );
                }
                if !(dp <= 0.1 && dr <= 2.0) {
                    let _ = writeln!(
                        misses,
                        "- {} from {}: {}",
                        pano.id,
                        row.name(),
                        if dp.is_nan() {
                            "no pose".to_string()
                        } else {
                            format!(
                                "{:.1} cm, {dr:.2}°{}",
                                dp * 100.0,
                                if outcome.wrong { ", wrong" } else { "" }
                            )
                        }
                    );
                }
                outcomes.push(outcome);
            }
            let line = table_row(&row.name(), &outcomes);
            println!("{line}");
            summary.push('\n');
            summary.push_str(&line);
        }
        // The table as a results file, when the whole tour was run with the shipped config.
        if cli.panos.is_empty() {
            let config = match &cli.config {
                Some(c) => format!(", config {} (not the shipped one)", c.display()),
                None => String::new(),
            };
            let text = format!(
                "{summary}\n\nNot within 10 cm / 2°:\n{misses}\nHints of radius R centred {} m from the truth (seed {}){config}; \
                 the first-pose times are wall time on this machine, with whatever else ran on it.",
                cli.hint_offset_m, cli.seed
            );
            let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
            match omnitrack::desk::results::write(
                &root,
                &format!("zind-{}-{}", rig.name, cli.rows.join("_")),
                &format!(
                    "ZInD sample tour, rig {} ({} sensors), {} panoramas",
                    rig.name,
                    rig.sensors.len(),
                    panos.len()
                ),
                "cargo run --release -p omnitrack-tools --bin zind_bench -- --tour DIR [--rig R] [--rows ...]",
                &text,
            ) {
                Ok(path) => eprintln!("zind_bench: results in {}", path.display()),
                Err(e) => eprintln!("zind_bench: results file not written: {e}"),
            }
        }
    }
    write(&cli.out.join("results.csv"), csv.as_bytes())?;
    eprintln!(
        "zind_bench: per-panorama results in {}, overlays in {}/RIG/PANO/overlay.jpg",
        cli.out.join("results.csv").display(),
        cli.out.display()
    );
    Ok(())
}

fn write(path: &Path, bytes: &[u8]) -> Result<(), String> {
    std::fs::write(path, bytes).map_err(|e| format!("{}: {e}", path.display()))
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

fn today() -> String {
    std::process::Command::new("date")
        .arg("+%F")
        .output()
        .ok()
        .and_then(|o| String::from_utf8(o.stdout).ok())
        .map(|s| s.trim().to_string())
        .unwrap_or_default()
}

/// The rig with every sensor's centre moved to the rig centre (a panorama has one centre).
fn centred(rig: &Rig) -> Rig {
    let mut rig = rig.clone();
    for s in &mut rig.sensors {
        s.t_rig_sensor.translation.vector = Vector3::zeros();
        s.device = None;
        s.usb_serial = None;
    }
    rig.usb = None;
    rig
}

/// `truth`'s centre moved `offset_m` in a direction drawn uniformly on the sphere from `seed`
/// and the panorama's index.
fn hint_centre(truth: &Pose, offset_m: f64, seed: u64, index: usize) -> Point3<f64> {
    let mut rng = SmallRng::seed_from_u64(seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ index as u64);
    let z: f64 = rng.random_range(-1.0..1.0);
    let a: f64 = rng.random_range(0.0..std::f64::consts::TAU);
    let r = (1.0 - z * z).sqrt();
    let d = Unit::new_normalize(Vector3::new(r * a.cos(), r * a.sin(), z));
    Point3::from(truth.translation.vector + offset_m * d.into_inner())
}

/// Writes the recording of `pano` through `rig` into `dir` unless it is already complete.
fn make_recording(
    dir: &Path,
    tour_dir: &Path,
    pano: &tour::Pano,
    rig: &Rig,
    (model, table): (&Model, &VisibilityTable),
    frames: usize,
) -> Result<(), String> {
    let marker = dir.join("complete");
    let index = dir.join("frames.csv");
    let recorded_frames =
        std::fs::read_to_string(&index).map(|t| t.lines().count().saturating_sub(1) / rig.sensors.len().max(1));
    if marker.exists() && recorded_frames.as_ref().is_ok_and(|&n| n == frames) {
        return Ok(());
    }
    let image_file = tour_dir.join(&pano.image);
    let photo = image::open(&image_file)
        .map_err(|e| format!("{}: {e}", image_file.display()))?
        .to_rgb8();
    let truth = pano.t_world_rig();
    let images: Vec<_> = rig
        .sensors
        .iter()
        .map(|s| resample::sensor_image(&photo, pano, &truth, s))
        .collect();
    for (s, img) in rig.sensors.iter().zip(&images) {
        let d = dir.join(format!("sensor{}", s.id));
        std::fs::create_dir_all(&d).map_err(|e| format!("{}: {e}", d.display()))?;
        write_png(&dir.join(image_path(s.id, 0)), img).map_err(|e| e.to_string())?;
    }
    write(&dir.join("rig.toml"), rig.to_toml_string().as_bytes())?;
    // Every frame shows the same instant: its rows point at the same images, 1/30 s apart.
    let mut csv = format!("{}\n", omnitrack::capture::replay::FRAMES_HEADER);
    let mut truth_track = Vec::new();
    for f in 0..frames {
        let ts = 1_000_000_000 + f as u64 * 33_333_333;
        for s in &rig.sensors {
            let _ = writeln!(csv, "{f},{},{ts},{}", s.id, image_path(s.id, 0));
        }
        truth_track.push(Stamped {
            timestamp_ns: ts,
            pose: truth,
        });
    }
    write(&index, csv.as_bytes())?;
    write(&dir.join("groundtruth.tum"), to_tum_string(&truth_track).as_bytes())?;
    let overlay = dir.join("overlay.jpg");
    // The segments in sight from the pose, as the initialisation predicts them.
    let options = OmniOptions {
        title: format!(
            "{} {} ({}): the model at the annotated pose",
            rig.name, pano.id, pano.label
        ),
        segments: Some(in_sight(model, table, &truth)),
        ..OmniOptions::default()
    };
    omni_view(&overlay, rig, &images, model, &truth, &options).map_err(|e| e.to_string())?;
    write(&marker, b"")?;
    Ok(())
}

/// The model segments in sight from `pose` (ray cast, `visibility::at_pose`), for overlays.
fn in_sight(model: &Model, table: &VisibilityTable, pose: &Pose) -> Vec<usize> {
    PoseVisibility::new(model)
        .at(model, table, &Point3::from(pose.translation.vector))
        .iter()
        .map(|s| s.segment as usize)
        .collect()
}

/// Tracks one recording from `hint` and measures the outcome against `truth`.
#[allow(clippy::too_many_arguments)]
fn track_one(
    dir: &Path,
    model: &Model,
    table: &VisibilityTable,
    cfg: &TrackerConfig,
    hint: Option<SearchVolume>,
    seed: u64,
    events: bool,
    truth: &Pose,
) -> Result<Outcome, String> {
    let mut source = ReplaySource::open(dir, Pacing::AsFastAsPossible).map_err(|e| e.to_string())?;
    let opts = RunOptions {
        hint,
        seed,
        max_frames: None,
    };
    let mut outcome = Outcome::default();
    let mut elapsed = Duration::ZERO;
    let mut sink = |record: &omnitrack::runtime::FrameRecord, _: &omnitrack::tracker::Tracker| {
        elapsed += record.frame_time;
        outcome.total_time += record.frame_time;
        let error = record.result.pose.map(|p| {
            (
                (p.translation.vector - truth.translation.vector).norm(),
                p.rotation.angle_to(&truth.rotation).to_degrees(),
            )
        });
        if events {
            eprintln!(
                "    frame at {} ns{}: {:?}, error (m, °) {error:?}, {:?}",
                record.timestamp_ns,
                if record.late { " (late)" } else { "" },
                record.result.state,
                record.result.event
            );
        }
        match (record.result.pose, error) {
            (Some(p), Some((dp, dr))) => {
                if dp > 1.0 || dr > 10.0 {
                    outcome.wrong = true;
                }
                if outcome.first_pose_frame.is_none() {
                    outcome.first_pose_frame = Some(record.sequence as usize);
                    outcome.time_to_first_pose = Some(elapsed);
                }
                outcome.last = Some((dp, dr));
                outcome.last_offset = Some(p.translation.vector - truth.translation.vector);
            }
            _ => {
                outcome.last = None;
                outcome.last_offset = None;
            }
        }
        Ok(())
    };
    track(&mut source, model, table, cfg, &opts, &mut sink).map_err(|e| e.to_string())?;
    Ok(outcome)
}

fn table_row(name: &str, outcomes: &[Outcome]) -> String {
    let n = outcomes.len();
    let within = |p: f64, r: f64| {
        outcomes
            .iter()
            .filter(|o| o.last.is_some_and(|(dp, dr)| dp <= p && dr <= r))
            .count()
    };
    let wrong = outcomes.iter().filter(|o| o.wrong).count();
    let none = outcomes.iter().filter(|o| o.first_pose_frame.is_none()).count();
    let mut times: Vec<f64> = outcomes.iter().filter_map(|o| o.time_to_first_pose.map(ms)).collect();
    times.sort_by(f64::total_cmp);
    let time = if times.is_empty() {
        "–".to_string()
    } else {
        format!("{:.0} / {:.0}", times[times.len() / 2], times[times.len() - 1])
    };
    format!(
        "| {name} | {} of {n} | {} of {n} | {wrong} | {none} | {time} |",
        within(0.10, 2.0),
        within(0.30, 5.0)
    )
}
