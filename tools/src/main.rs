//! `omnitrack-desk`: offline tools that prepare the tracker's inputs on a workstation.
//!
//! `omnitrack-desk extrude PLAN.geojson --out MODEL.obj` extrudes a GeoJSON floor plan
//! (docs/models.md) into the OBJ building model the tracker loads, and reports how many
//! faces, vertices and model segments the tracker will see in it.
//!
//! `omnitrack-desk render --rig R --model M.obj --trajectory T.tum --out DIR` renders a synthetic
//! recording (the layout of docs/interfaces.md, "Recording") of the rig moving along the
//! trajectory through the model.
//!
//! `omnitrack-desk model from-ifc FILE.ifc --out MODEL.obj [--storey NAME]` converts an IFC
//! building (what architects deliver) into the coarse OBJ model through IfcOpenShell
//! (`tools/ifc_to_obj.py`, carried in the binary; IfcOpenShell in a venv of the user's cache).
//!
//! `omnitrack-desk eval GT.tum EST.tum [--align] [--rpe-delta N] [--max-diff S]` compares an
//! estimated trajectory with the ground truth (ATE and RPE, evo's definitions) and prints a table.
//!
//! Every error is one line on stderr and exit code 2, so scripts can tell a bad input from a
//! crash. A reader of standard output that goes away (`omnitrack-desk eval … | head`) ends the
//! tool quietly with success, as it ends `omnitrack`; standard output that cannot be written (a
//! full disk) is an error like any other.

mod calib;
mod ifc;
mod jobs;
mod look;

use ifc::from_ifc;
use jobs::{eval_json, manual, manual_result, render};

use clap::{Parser, Subcommand};
use omnitrack::desk::eval::{evaluate_files, EvalOptions};
use omnitrack::desk::floorplan;
use omnitrack::desk::render::Appearance;
use omnitrack::desk::scenario::{Scenario, ScenarioName, UnknownScenario};
use omnitrack::trajectory::load_tum;
use omnitrack::{Model, Rig};
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
        /// The floor plan (GeoJSON FeatureCollection in metres; see docs/models.md).
        plan: PathBuf,
        /// Where to write the OBJ model.
        #[arg(long, value_name = "MODEL.obj")]
        out: PathBuf,
    },
    /// Render a recording of one of the paper's scenarios (lab, corridor, handheld): its model,
    /// a seeded trajectory through it, and the images.
    Scenario {
        /// lab, corridor or handheld.
        name: String,
        /// Frames to render (at the scenario's frame rate).
        #[arg(long, default_value_t = 50)]
        frames: usize,
        /// The recording directory to create.
        #[arg(long, value_name = "DIR")]
        out: PathBuf,
        /// The rig (default: firmware_config/ladybug2.toml).
        #[arg(long, value_name = "RIG.toml")]
        rig: Option<PathBuf>,
        #[command(flatten)]
        look: Look,
    },
    /// Render a synthetic recording of a rig moving through a model along a trajectory.
    Render {
        /// The rig to render: each sensor's lens, size and mounting.
        #[arg(long, value_name = "RIG.toml")]
        rig: PathBuf,
        /// The building model to render (OBJ, metres, z up).
        #[arg(long, value_name = "MODEL.obj")]
        model: PathBuf,
        /// T_world_rig per frame, TUM format; one recorded frame per line.
        #[arg(long, value_name = "T.tum")]
        trajectory: PathBuf,
        /// The recording directory to create.
        #[arg(long, value_name = "DIR")]
        out: PathBuf,
        #[command(flatten)]
        look: Look,
    },
    /// Building models from other tools.
    Model {
        #[command(subcommand)]
        command: ModelCommand,
    },
    /// One frame of a recording with the model re-projected over its sensor images at the
    /// trajectory's pose (PNG): a wrong calibration, convention or model shows at a glance.
    Overlay {
        /// The recording (rig.toml, frames.csv, sensorK/*.png), e.g. made by `omnitrack record`.
        #[arg(long, value_name = "DIR")]
        recording: PathBuf,
        /// The building model.
        #[arg(long, value_name = "MODEL.obj")]
        model: PathBuf,
        /// The poses (TUM, e.g. `omnitrack run --trajectory`).
        #[arg(long, value_name = "T.tum")]
        trajectory: PathBuf,
        /// The frame (its number in frames.csv; default: the first with a pose).
        #[arg(long)]
        frame: Option<u64>,
        /// Where to write the picture.
        #[arg(long, value_name = "OUT.png")]
        out: PathBuf,
    },
    /// Pictures of a run: the trajectory over the floor plan (coloured by its error when the
    /// ground truth is given) and the error over time.
    Plot {
        /// The building model (its plan is drawn from its segments).
        #[arg(long, value_name = "MODEL.obj")]
        model: PathBuf,
        /// The estimate (TUM).
        #[arg(long, value_name = "T.tum")]
        trajectory: PathBuf,
        /// The ground truth (TUM), if there is one.
        #[arg(long, value_name = "GT.tum")]
        truth: Option<PathBuf>,
        /// The directory to write plan.png (and errors.png) into.
        #[arg(long, value_name = "DIR")]
        out: PathBuf,
    },
    /// Rig files from other tools' calibrations.
    Rig {
        #[command(subcommand)]
        command: calib::RigCommand,
    },
    /// Compare an estimated trajectory with the ground truth: ATE and RPE (as evo_ape/evo_rpe).
    Eval {
        /// Ground truth, TUM format (T_world_rig).
        gt: PathBuf,
        /// The estimate, TUM format (T_world_rig).
        est: PathBuf,
        /// Rigidly align the estimate onto the ground truth first (Umeyama, no scale).
        #[arg(long)]
        align: bool,
        /// RPE distance in associated frames.
        #[arg(long, value_name = "N", default_value_t = 1)]
        rpe_delta: usize,
        /// Largest timestamp difference (seconds) to associate two poses.
        #[arg(long, value_name = "S", default_value_t = 0.01)]
        max_diff: f64,
        /// Print every statistic as JSON (metres and degrees) instead of the table.
        #[arg(long)]
        json: bool,
    },
    /// Prints a shell completion script for omnitrack-desk (bash, zsh, fish, elvish or powershell).
    Completions {
        /// The shell.
        shell: omnitrack_manual::Shell,
    },
    /// Prints omnitrack-desk's manual page (roff), or writes it and a page per command into a
    /// directory.
    Manpage(omnitrack_manual::ManpageArgs),
}

#[derive(Subcommand)]
enum ModelCommand {
    /// The coarse OBJ model of an IFC building: walls, slabs, roofs, doors, windows, stairs,
    /// columns, beams and curtain walls, in metres, z up, in the IFC project's coordinates;
    /// furniture and services left out. Runs IfcOpenShell (PyPI `ifcopenshell`), which it
    /// installs on first use into the user's cache (~/.cache/omnitrack/ifc-venv, or under
    /// $OMNITRACK_CACHE or $XDG_CACHE_HOME), saying so.
    FromIfc {
        /// The IFC file (STEP, IFC2X3 or IFC4).
        file: PathBuf,
        /// Where to write the OBJ model.
        #[arg(long, value_name = "MODEL.obj")]
        out: PathBuf,
        /// Keep only the elements of this building storey (its IFC name).
        #[arg(long, value_name = "NAME")]
        storey: Option<String>,
    },
    /// A random building nobody here drew (the generator of the buildings benchmark): L, U,
    /// courtyard or rectangular outline, thin or thick walls, random winding, triangulated or
    /// not, one or two storeys; the same seed gives the same building.
    Random {
        /// The building's seed.
        seed: u64,
        /// Where to write the OBJ model.
        #[arg(long, value_name = "MODEL.obj")]
        out: PathBuf,
        /// Also write the walked ground storey as a GeoJSON floor plan.
        #[arg(long, value_name = "PLAN.geojson")]
        plan: Option<PathBuf>,
        /// Also write a walk through the ground storey (TUM, T_world_rig) for `render`.
        #[arg(long, value_name = "T.tum")]
        walk: Option<PathBuf>,
        /// Poses of the walk (at the building's frame rate).
        #[arg(long, default_value_t = 150)]
        frames: usize,
    },
}

/// Appearance switches: each a level, 0 = off (defaults are moderate and realistic).
#[derive(clap::Args)]
struct Look {
    /// Seed of every random choice (colours, clutter, people, noise).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Clutter not in the model (furniture, shelves, posters); 1 = default density.
    #[arg(long)]
    clutter: Option<f64>,
    /// People walking through the view; 1 = default density.
    #[arg(long)]
    people: Option<f64>,
    /// Sensor noise σ in grey levels.
    #[arg(long)]
    noise: Option<f64>,
    /// Motion blur: fraction of the frame interval the shutter is open.
    #[arg(long)]
    motion_blur: Option<f64>,
    /// Global lighting drift amplitude.
    #[arg(long)]
    lighting_drift: Option<f64>,
    /// Start from every effect off (flat surface colours) instead of the defaults.
    #[arg(long)]
    plain: bool,
}

impl Look {
    fn appearance(&self) -> Result<Appearance, String> {
        let mut a = if self.plain {
            Appearance::plain()
        } else {
            Appearance::default()
        };
        a.seed = self.seed;
        for (name, value, slot) in [
            ("--clutter", self.clutter, &mut a.clutter),
            ("--people", self.people, &mut a.people),
            ("--noise", self.noise, &mut a.noise),
            ("--motion-blur", self.motion_blur, &mut a.motion_blur),
            ("--lighting-drift", self.lighting_drift, &mut a.lighting_drift),
        ] {
            if let Some(v) = value {
                if !(v.is_finite() && v >= 0.0) {
                    return Err(format!("{name} must be a finite level ≥ 0, found {v}"));
                }
                *slot = v;
            }
        }
        Ok(a)
    }
}

fn main() -> ExitCode {
    let cli: Cli =
        omnitrack::runtime::cli::parse_or_exit("omnitrack-desk", "omnitrack-desk extrude PLAN.geojson --out MODEL.obj");
    match run(cli.command) {
        // Nothing is left to say, and no one to say it to.
        Ok(()) | Err(Failure::ReaderGone) => ExitCode::SUCCESS,
        Err(Failure::Message(message)) => {
            eprintln!("omnitrack-desk: {message}");
            ExitCode::from(2)
        }
    }
}

/// Why a command did not complete.
#[derive(Debug)]
pub(crate) enum Failure {
    /// One line for standard error.
    Message(String),
    /// Standard output's reader went away.
    ReaderGone,
}

impl From<String> for Failure {
    fn from(message: String) -> Failure {
        Failure::Message(message)
    }
}

impl From<&str> for Failure {
    fn from(message: &str) -> Failure {
        Failure::Message(message.to_string())
    }
}

/// Writes `text` to standard output, whole. `print!` would panic on a closed pipe (exit 101).
pub(crate) fn print_out(text: &str) -> Result<(), Failure> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Err(Failure::ReaderGone),
        Err(e) => Err(Failure::Message(format!("cannot write to standard output: {e}"))),
    }
}

fn run(command: Command) -> Result<(), Failure> {
    match command {
        Command::Overlay {
            recording,
            model,
            trajectory,
            frame,
            out,
        } => {
            eprintln!("{}", look::overlay(&recording, &model, &trajectory, frame, &out)?);
            Ok(())
        }
        Command::Plot {
            model,
            trajectory,
            truth,
            out,
        } => {
            eprintln!("{}", look::plot(&model, &trajectory, truth.as_deref(), &out)?);
            Ok(())
        }
        Command::Rig { command } => calib::run(command),
        Command::Model {
            command: ModelCommand::FromIfc { file, out, storey },
        } => Ok(from_ifc(&file, &out, storey.as_deref())?),
        Command::Model {
            command:
                ModelCommand::Random {
                    seed,
                    out,
                    plan,
                    walk,
                    frames,
                },
        } => {
            let b = omnitrack::desk::scenario::random::RandomBuilding::new(seed);
            let out_name = out.display().to_string();
            let model = Model::from_obj_str(&b.obj, &out_name).map_err(|e| e.to_string())?;
            std::fs::write(&out, &b.obj).map_err(|e| format!("{out_name}: cannot write: {e}"))?;
            if let Some(p) = plan {
                std::fs::write(&p, &b.plan_geojson).map_err(|e| format!("{}: cannot write: {e}", p.display()))?;
            }
            if let Some(p) = walk {
                let t = b.trajectory(frames, seed);
                std::fs::write(&p, omnitrack::trajectory::to_tum_string(&t))
                    .map_err(|e| format!("{}: cannot write: {e}", p.display()))?;
            }
            print_out(&format!("{out_name}: {b}; {} segments\n", model.segments.len()))
        }
        Command::Extrude { plan, out } => {
            let plan_name = plan.display().to_string();
            let text = omnitrack::text_file::read_text(&plan, omnitrack::text_file::LARGE_FILE_LIMIT)
                .map_err(|e| format!("{plan_name}: cannot read: {e}"))?;
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
        Command::Scenario {
            name,
            frames,
            out,
            rig,
            look,
        } => {
            let name: ScenarioName = name.parse().map_err(|e: UnknownScenario| e.to_string())?;
            if frames == 0 {
                return Err("--frames must be at least 1".into());
            }
            let rig = match rig {
                Some(path) => Rig::load(&path).map_err(|e| e.to_string())?,
                None => Rig::from_toml_str(include_str!("../../firmware_config/ladybug2.toml"), "ladybug2.toml")
                    .map_err(|e| e.to_string())?,
            };
            let scenario = Scenario::get(name);
            let obj = scenario.model_obj().map_err(|e| e.to_string())?;
            let trajectory = scenario.trajectory(frames, look.seed);
            Ok(render(&rig, &obj, &trajectory, &out, look.appearance()?)?)
        }
        Command::Render {
            rig,
            model,
            trajectory,
            out,
            look,
        } => {
            let rig = Rig::load(&rig).map_err(|e| e.to_string())?;
            let model_name = model.display().to_string();
            let obj = omnitrack::text_file::read_text(&model, omnitrack::text_file::LARGE_FILE_LIMIT)
                .map_err(|e| format!("{model_name}: cannot read: {e}"))?;
            let trajectory = load_tum(&trajectory).map_err(|e| e.to_string())?;
            if trajectory.is_empty() {
                return Err("the trajectory has no poses".into());
            }
            Ok(render(&rig, &obj, &trajectory, &out, look.appearance()?)?)
        }
        Command::Eval {
            gt,
            est,
            align,
            rpe_delta,
            max_diff,
            json,
        } => {
            let options = EvalOptions {
                max_diff_s: max_diff,
                align,
                rpe_delta,
            };
            let evaluation = evaluate_files(&gt, &est, &options).map_err(|e| e.to_string())?;
            for cut in &evaluation.cut_lines {
                eprintln!("omnitrack-desk: {cut}");
            }
            if json {
                print_out(&format!("{}\n", eval_json(&evaluation)))
            } else {
                print_out(&evaluation.table())
            }
        }
        Command::Completions { shell } => manual_result(omnitrack_manual::run_completions(&manual(), shell)),
        Command::Manpage(args) => manual_result(omnitrack_manual::run_manpage(&manual(), &args)),
    }
}
#[cfg(test)]
mod tests {
    /// docs/interfaces.md, "`omnitrack-desk`", is the contract: every command and long option of
    /// `omnitrack-desk` is in its table, and everything the table names exists.
    #[test]
    fn the_command_line_is_the_one_the_contract_documents() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/interfaces.md");
        let doc = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{path}: {e}"));
        let command = <super::Cli as clap::CommandFactory>::command();
        let problems = omnitrack::runtime::cli::undocumented(&command, "omnitrack-desk", &doc);
        assert!(
            problems.is_empty(),
            "{path} and the command line differ:\n{}",
            problems.join("\n")
        );
    }

    /// Every `omnitrack-desk` command the README gives is one the command line takes as written.
    #[test]
    fn the_readme_commands_are_ones_the_command_line_takes() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../README.md");
        let readme = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{path}: {e}"));
        let command = <super::Cli as clap::CommandFactory>::command();
        let problems = omnitrack::runtime::cli::readme_mismatches(&command, "omnitrack-desk", &readme);
        assert!(problems.is_empty(), "README.md:\n{}", problems.join("\n"));
    }
}
