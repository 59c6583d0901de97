//! `pnl_bench`: the Rust half of `tools/bench_pnl.py` (the PnL benchmark against PoseLib).
//!
//! Reads trials as JSON lines (one object per trial, written by `bench_pnl.py`):
//!
//! ```text
//! {"id": 17, "seed": 123, "K": [fx, fy, cx, cy],
//!  "lines": [[u1, v1, u2, v2, X1, Y1, Z1, X2, Y2, Z2], ...]}
//! ```
//!
//! (pixel end points of each observed 2D segment, then the world end points of its 3D segment),
//! turns every 2D segment into an [`EdgePlane`] through the camera centre (rig frame = camera
//! frame) and runs our solver on them, timing only the solver call. Writes one JSON line per
//! trial:
//!
//! ```text
//! {"id": 17, "ok": true, "us": 812.4, "inliers": 9,
//!  "t_world_camera": {"t": [x, y, z], "R": [r00, r01, r02, r10, ..., r22]}}
//! {"id": 18, "ok": false, "us": 97.0, "error": "no subset gave a usable pose"}
//! ```
//!
//! `t_world_camera` is T_world_camera (= the solver's T_world_rig): `p_world = R p_camera + t`,
//! so `t` is the camera centre in the world; `R` is row-major.

use clap::{Parser, ValueEnum};
use nalgebra::{Point2, Point3};
use omnitrack::geometry::{Correspondence, EdgePlane, Lens, Pinhole};
use omnitrack::solver::{med_r_and_t, r_and_t, LineError, SolverOptions};
use serde_json::{json, Value};
use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Write};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

#[derive(Clone, Copy, ValueEnum)]
enum MethodArg {
    /// Kumar–Hanson Med_R_and_T (least median of squares, then R_and_T on the inliers).
    Lms,
    /// Kumar–Hanson R_and_T on all correspondences, no guess.
    #[value(name = "r_and_t")]
    RAndT,
}

#[derive(Parser)]
#[command(
    name = "pnl_bench",
    about = "Run omnitrack's line pose solver on bench_pnl.py trials"
)]
struct Cli {
    /// Trials, JSON lines (see the module docs).
    #[arg(long)]
    input: PathBuf,
    /// Results, JSON lines.
    #[arg(long)]
    output: PathBuf,
    #[arg(long, value_enum, default_value = "lms")]
    method: MethodArg,
    /// Med_R_and_T's expected outlier fraction ε (subset count and the order statistic
    /// minimised). The benchmark runs every cell with one setting, sized for its worst cell.
    #[arg(long, default_value_t = 0.5)]
    epsilon: f64,
    /// Med_R_and_T's probability that some random subset is outlier-free. 0.99999 (87 subsets
    /// at ε = 0.5) is what zero failures at 50 % outliers takes; at 0.999 (52 subsets) about
    /// 0.2 % of those trials draw no good subset.
    #[arg(long, default_value_t = 0.99999)]
    success: f64,
    /// Line error minimised (Kumar–Hanson eqs. 10–12). E2 measures angles, closest to the pixel
    /// error PoseLib minimises; the benchmark found it the more accurate of E1/E2.
    #[arg(long, default_value = "e2")]
    error: String,
    /// Med_R_and_T's inlier gate, σ per end point (tracker.toml's `lms_outlier_threshold`).
    #[arg(long, default_value_t = 2.5)]
    threshold: f64,
    /// Leave the solver without the camera's pixel size (σ̂ of the inlier gate unfloored).
    #[arg(long)]
    no_pixel_floor: bool,
}

fn f(v: &Value) -> Result<f64, String> {
    v.as_f64().ok_or_else(|| format!("expected a number, got {v}"))
}

/// The correspondences of one trial. A 2D segment whose end rays are parallel gives no plane and
/// is left out (it cannot happen for the benchmark's segments of ≥ 1 px).
fn correspondences(trial: &Value) -> Result<(Vec<Correspondence>, f64), String> {
    let k = trial["K"].as_array().ok_or("trial without K")?;
    if k.len() != 4 {
        return Err("K must be [fx, fy, cx, cy]".into());
    }
    let pixel_rad = 1.0 / f(&k[0])?.min(f(&k[1])?);
    let lens = Lens::Pinhole(Pinhole::new(f(&k[0])?, f(&k[1])?, f(&k[2])?, f(&k[3])?).map_err(|e| e.to_string())?);
    let lines = trial["lines"].as_array().ok_or("trial without lines")?;
    let mut out = Vec::with_capacity(lines.len());
    for l in lines {
        let v: Vec<f64> = l
            .as_array()
            .ok_or("a line must be an array")?
            .iter()
            .map(f)
            .collect::<Result<_, _>>()?;
        if v.len() != 10 {
            return Err(format!("a line needs 10 numbers, got {}", v.len()));
        }
        let r1 = lens.unproject(&Point2::new(v[0], v[1])).ok_or("pixel without a ray")?;
        let r2 = lens.unproject(&Point2::new(v[2], v[3])).ok_or("pixel without a ray")?;
        if let Some(edge) = EdgePlane::from_rays(Point3::origin(), &r1, &r2) {
            out.push(Correspondence {
                edge,
                segment: [Point3::new(v[4], v[5], v[6]), Point3::new(v[7], v[8], v[9])],
            });
        }
    }
    Ok((out, pixel_rad))
}

fn run(cli: &Cli) -> Result<(), String> {
    let input = File::open(&cli.input).map_err(|e| format!("{}: {e}", cli.input.display()))?;
    let output = File::create(&cli.output).map_err(|e| format!("{}: {e}", cli.output.display()))?;
    let mut out = BufWriter::new(output);
    let options = SolverOptions {
        lms_outlier_fraction: cli.epsilon,
        lms_success_probability: cli.success,
        lms_outlier_threshold: cli.threshold,
        error: match cli.error.as_str() {
            "e1" => LineError::E1,
            "e2" => LineError::E2,
            "e3" => LineError::E3,
            other => return Err(format!("--error {other}: expected e1, e2 or e3")),
        },
        ..SolverOptions::default()
    };
    for (n, line) in BufReader::new(input).lines().enumerate() {
        let line = line.map_err(|e| e.to_string())?;
        if line.trim().is_empty() {
            continue;
        }
        let trial: Value = serde_json::from_str(&line).map_err(|e| format!("line {}: {e}", n + 1))?;
        let id = trial["id"].as_u64().ok_or_else(|| format!("line {}: no id", n + 1))?;
        let seed = trial["seed"].as_u64().unwrap_or(id);
        let (c, pixel_rad) = correspondences(&trial).map_err(|e| format!("line {}: {e}", n + 1))?;
        let options = SolverOptions {
            pixel_rad: if cli.no_pixel_floor { 0.0 } else { pixel_rad },
            ..options.clone()
        };

        let start = Instant::now();
        let result = match cli.method {
            MethodArg::Lms => med_r_and_t(&c, None, &options, seed),
            MethodArg::RAndT => r_and_t(&c, None, &options),
        };
        let us = start.elapsed().as_secs_f64() * 1e6;

        let record = match result {
            Ok(s) => {
                let r = s.pose.rotation.to_rotation_matrix();
                let m = r.matrix();
                let t = s.pose.translation.vector;
                let cov: Vec<f64> = s.covariance.iter().copied().collect();
                json!({
                    "id": id, "ok": true, "us": us, "inliers": s.inliers.len(), "lines": c.len(),
                    "covariance": cov,
                    "t_world_camera": {
                        "t": [t.x, t.y, t.z],
                        "R": [m[(0, 0)], m[(0, 1)], m[(0, 2)],
                              m[(1, 0)], m[(1, 1)], m[(1, 2)],
                              m[(2, 0)], m[(2, 1)], m[(2, 2)]],
                    },
                })
            }
            Err(e) => json!({"id": id, "ok": false, "us": us, "error": e.to_string()}),
        };
        writeln!(out, "{record}").map_err(|e| e.to_string())?;
    }
    out.flush().map_err(|e| e.to_string())
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(&cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("pnl_bench: {e}");
            ExitCode::from(2)
        }
    }
}
