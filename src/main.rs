//! `omnitrack`: the device binary's command line (docs/interfaces.md, "Command line").
//!
//! Standard output carries only documented output (CSV, JSON, TUM); messages go to standard
//! error; every failure is one line and a non-zero exit, never a panic.

mod commands;

use clap::{Parser, Subcommand};
use commands::CommandResult;
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
    /// Tracks: frames from the source, poses on the iceoryx2 pose service and, if asked, a TUM
    /// trajectory. Without --init the whole model is searched.
    Run(commands::run::Args),
    /// Records what a source delivers (v4l, usb or a replay) in the recording layout `run`
    /// replays: PNG per sensor image, frames.csv with the capture timestamps.
    Record(commands::record::Args),
    /// Validates a rig, and optionally a model and a tracker config, and summarises them.
    Check(commands::check::Args),
    /// Solves one pose T_world_rig from line correspondences and prints it as JSON.
    Pose(commands::pose::Args),
    /// Prints the detected edges of one sensor image as CSV (docs/interfaces.md).
    Edges(commands::edges::Args),
    /// Builds or queries the prior visibility table (Koch–Teller §4.3).
    Visibility {
        #[command(subcommand)]
        command: commands::visibility::Command,
    },
    /// Subscribes to the pose service and prints one line per sample.
    Listen {
        /// Stop after N samples (default: until Ctrl-C).
        #[arg(long)]
        count: Option<u64>,
    },
    /// Prints the model segments of an OBJ as CSV: x1,y1,z1,x2,y2,z2,faces (OBJ face numbers,
    /// space-separated; empty for a free `l` segment).
    Segments(commands::segments::Args),
}

fn main() -> ExitCode {
    let cli: Cli = omnitrack::runtime::cli::parse_or_exit("omnitrack", "omnitrack demo");
    match run(cli.command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(message) => {
            eprintln!("omnitrack: {message}");
            ExitCode::from(2)
        }
    }
}

fn run(command: Command) -> CommandResult {
    match command {
        #[cfg(feature = "desk")]
        Command::Demo => {
            let report = omnitrack::desk::demo::run_demo(&omnitrack::desk::demo::DemoOptions::default())?;
            println!("{report}");
            Ok(())
        }
        #[cfg(not(feature = "desk"))]
        Command::Demo => Err(
            "demo needs the `desk` feature, which this device build leaves out (`cargo run --release -- demo` \
             has it by default)"
                .into(),
        ),
        Command::Run(args) => commands::run::run(args),
        Command::Record(args) => commands::record::run(args),
        Command::Check(args) => commands::check::run(args),
        Command::Pose(args) => commands::pose::run(args),
        Command::Edges(args) => commands::edges::run(args),
        Command::Visibility { command } => commands::visibility::run(command),
        Command::Listen { count } => Ok(omnitrack::publish::listen(
            omnitrack::publish::POSE_SERVICE,
            count,
            &mut std::io::stdout().lock(),
        )?),
        Command::Segments(args) => commands::segments::run(args),
    }
}
