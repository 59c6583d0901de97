//! `omnitrack-desk`: offline tools that prepare the tracker's inputs on a workstation.
//!
//! `omnitrack-desk extrude PLAN.geojson --out MODEL.obj` extrudes a GeoJSON floor plan
//! (docs/floorplan.md) into the OBJ building model the tracker loads, and reports how many
//! faces, vertices and model segments the tracker will see in it. Every error is one line on
//! stderr and exit code 2, so scripts can tell a bad input from a crash.

use clap::error::ErrorKind;
use clap::{Parser, Subcommand};
use omnitrack::desk::floorplan;
use omnitrack::Model;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "omnitrack-desk",
    version,
    about = "Offline tools for omnitrack building models"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Extrude a GeoJSON floor plan into a Wavefront OBJ building model.
    Extrude {
        /// The floor plan (GeoJSON FeatureCollection in metres; see docs/floorplan.md).
        plan: PathBuf,
        /// Where to write the OBJ model.
        #[arg(long, value_name = "MODEL.obj")]
        out: PathBuf,
    },
}

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) if matches!(e.kind(), ErrorKind::DisplayHelp | ErrorKind::DisplayVersion) => e.exit(),
        Err(e) if e.kind() == ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand => {
            eprintln!("omnitrack-desk: no command given (try: omnitrack-desk extrude PLAN.geojson --out MODEL.obj)");
            return ExitCode::from(2);
        }
        Err(e) => {
            // clap's report spans several lines (the problem, a tip, the usage); keep the first two.
            let text = e.render().to_string();
            let mut problem = String::new();
            for line in text.lines().map(str::trim).take_while(|l| !l.starts_with("Usage:")) {
                if !line.is_empty() {
                    if !problem.is_empty() {
                        problem.push_str(if problem.ends_with(':') { " " } else { "; " });
                    }
                    problem.push_str(line);
                }
            }
            eprintln!(
                "omnitrack-desk: {} (see omnitrack-desk --help)",
                problem.trim_start_matches("error: ")
            );
            return ExitCode::from(2);
        }
    };
    match run(cli.command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(message) => {
            eprintln!("omnitrack-desk: {message}");
            ExitCode::from(2)
        }
    }
}

fn run(command: Command) -> Result<(), String> {
    match command {
        Command::Extrude { plan, out } => {
            let plan_name = plan.display().to_string();
            let text = std::fs::read_to_string(&plan).map_err(|e| format!("{plan_name}: cannot read: {e}"))?;
            let obj = floorplan::extrude(&text, &plan_name).map_err(|e| e.to_string())?;
            // Loading the result back is the check that matters: it is what the tracker will do.
            let out_name = out.display().to_string();
            let model = Model::from_obj_str(&obj, &out_name).map_err(|e| e.to_string())?;
            std::fs::write(&out, &obj).map_err(|e| format!("{out_name}: cannot write: {e}"))?;
            let s = &model.stats;
            let mut summary = format!(
                "{out_name}: {} faces, {} vertices, {} segments",
                model.faces.len(),
                model.vertices.len(),
                model.segments.len()
            );
            if s.degenerate_faces + s.nonplanar_faces + s.welded_vertices > 0 {
                summary.push_str(&format!(
                    " (loader: {} degenerate faces, {} non-planar faces, {} welded vertices)",
                    s.degenerate_faces, s.nonplanar_faces, s.welded_vertices
                ));
            }
            eprintln!("{summary}");
            Ok(())
        }
    }
}
