//! `omnitrack`: the device binary's command line (INTERFACES.md, "Command line").
//!
//! Standard output carries only documented output (CSV, JSON, TUM); messages go to standard
//! error; every failure is one line and a non-zero exit, never a panic.

use clap::{Parser, Subcommand};
use omnitrack::config::TrackerConfig;
use omnitrack::{Model, Rig};
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "omnitrack",
    version,
    about = "6-DOF tracking of an omnidirectional rig in a known building model"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// The embedded default: synthetic building, recording, visibility table, tracking, report.
    Demo,
    /// Validates a rig, and optionally a model and a tracker config, and summarises them.
    Check {
        #[arg(long)]
        rig: Option<PathBuf>,
        #[arg(long)]
        model: Option<PathBuf>,
        #[arg(long)]
        config: Option<PathBuf>,
    },
    /// Prints the model segments of an OBJ as CSV: x1,y1,z1,x2,y2,z2,faces (OBJ face numbers,
    /// space-separated; empty for a free `l` segment).
    Segments {
        #[arg(long)]
        model: PathBuf,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli.command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(message) => {
            eprintln!("omnitrack: {message}");
            ExitCode::from(2)
        }
    }
}

fn run(command: Command) -> Result<(), String> {
    match command {
        Command::Demo => Err(
            "demo is not available yet: it waits for the synthetic recordings (issue 3), \
             the pose solvers (4), edge extraction (5), the visibility table (6) and the tracker (7)"
                .into(),
        ),
        Command::Check { rig, model, config } => {
            if rig.is_none() && model.is_none() && config.is_none() {
                return Err("check needs at least one of --rig, --model, --config".into());
            }
            if let Some(path) = rig {
                let rig = Rig::load(&path).map_err(|e| e.to_string())?;
                eprintln!("{}: rig '{}', {} sensors", path.display(), rig.name, rig.sensors.len());
                for s in &rig.sensors {
                    let c = s.centre();
                    eprintln!(
                        "  sensor {}: {}×{}, {} lens seeing {:.1}° off-axis at the corners, centre ({:.3}, {:.3}, {:.3}) m",
                        s.id,
                        s.width,
                        s.height,
                        lens_name(&s.lens),
                        s.max_off_axis().to_degrees(),
                        c.x,
                        c.y,
                        c.z
                    );
                }
            }
            if let Some(path) = model {
                let m = Model::load(&path).map_err(|e| e.to_string())?;
                eprintln!(
                    "{}: {} vertices, {} faces, {} segments ({} free); skipped {} degenerate faces, \
                     split {} non-planar faces, welded {} duplicate vertices, ignored {} records",
                    path.display(),
                    m.vertices.len(),
                    m.faces.len(),
                    m.segments.len(),
                    m.segments.iter().filter(|s| s.is_free()).count(),
                    m.stats.degenerate_faces,
                    m.stats.nonplanar_faces,
                    m.stats.welded_vertices,
                    m.stats.ignored_records
                );
            }
            if let Some(path) = config {
                TrackerConfig::load(&path).map_err(|e| e.to_string())?;
                eprintln!("{}: tracker config valid", path.display());
            }
            Ok(())
        }
        Command::Segments { model } => {
            let m = Model::load(&model).map_err(|e| e.to_string())?;
            let mut out = std::io::BufWriter::new(std::io::stdout().lock());
            let write = |out: &mut std::io::BufWriter<_>| -> std::io::Result<()> {
                writeln!(out, "x1,y1,z1,x2,y2,z2,faces")?;
                for s in &m.segments {
                    let faces: Vec<String> = s
                        .faces
                        .iter()
                        .map(|&f| m.faces[f as usize].obj_number.to_string())
                        .collect();
                    writeln!(
                        out,
                        "{},{},{},{},{},{},{}",
                        s.a.x,
                        s.a.y,
                        s.a.z,
                        s.b.x,
                        s.b.y,
                        s.b.z,
                        faces.join(" ")
                    )?;
                }
                out.flush()
            };
            write(&mut out).map_err(|e| format!("cannot write to standard output: {e}"))
        }
    }
}

fn lens_name(lens: &omnitrack::geometry::Lens) -> &'static str {
    match lens {
        omnitrack::geometry::Lens::Pinhole(_) => "pinhole",
        omnitrack::geometry::Lens::Kb4(_) => "kb4",
    }
}
