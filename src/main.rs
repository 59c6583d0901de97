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
    long_version = long_version(),
    about = "6-DOF tracking of an omnidirectional rig in a known building model",
    after_help = commands::EXIT_STATUS_HELP
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
    #[command(after_help = commands::EXIT_STATUS_HELP)]
    Run(commands::run::Args),
    /// Records what a source delivers (v4l, usb or a replay) in the recording layout `run`
    /// replays: PNG per sensor image, frames.csv with the capture timestamps.
    Record(commands::record::Args),
    /// Validates a rig, and optionally a model and a tracker config, and summarises them.
    #[command(after_help = commands::EXIT_STATUS_HELP)]
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
    /// Subscribes to the pose service (or the status service) and prints one line per sample.
    Listen(commands::listen::Args),
    /// Prints a shell completion script for omnitrack (bash, zsh, fish, elvish or powershell).
    Completions {
        /// The shell.
        shell: omnitrack_manual::Shell,
    },
    /// Prints omnitrack's manual page (roff; `omnitrack manpage | man -l -`), or writes it and a
    /// page per command (omnitrack-run.1, …) into a directory.
    Manpage(omnitrack_manual::ManpageArgs),
    /// Prints the model segments of an OBJ as CSV: x1,y1,z1,x2,y2,z2,faces (OBJ face numbers,
    /// space-separated; empty for a free `l` segment).
    Segments(commands::segments::Args),
}

/// `omnitrack --version`: the version and the sources this build reads (`v4l` and `usb` are
/// cargo features: the Debian package's binary has both).
fn long_version() -> &'static str {
    let mut sources = vec!["replay"];
    if cfg!(feature = "v4l") {
        sources.push("v4l");
    }
    if cfg!(feature = "usb") {
        sources.push("usb");
    }
    let text = format!("{} (sources: {})", env!("CARGO_PKG_VERSION"), sources.join(", "));
    // Once per process: clap's derive takes a `&'static str`.
    Box::leak(text.into_boxed_str())
}

fn main() -> ExitCode {
    let cli: Cli = omnitrack::runtime::cli::parse_or_exit("omnitrack", "omnitrack demo");
    match run(cli.command) {
        Ok(()) => ExitCode::from(commands::exit::SUCCESS),
        // The reader went away (`… | head`): nothing is left to say, and no one to say it to.
        Err(e) if commands::is_broken_pipe(&*e) => ExitCode::from(commands::exit::SUCCESS),
        Err(e) => match e.downcast_ref::<commands::Exit>() {
            // Said already; the code says the rest (a run without a pose, a check that failed).
            Some(commands::Exit(code)) => ExitCode::from(*code),
            None => {
                eprintln!("omnitrack: {e}");
                ExitCode::from(commands::exit::FAILURE)
            }
        },
    }
}

fn run(command: Command) -> CommandResult {
    match command {
        #[cfg(feature = "desk")]
        Command::Demo => {
            let report = omnitrack::desk::demo::run_demo(&omnitrack::desk::demo::DemoOptions::default())?;
            commands::print_line(&report.to_string())?;
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
        Command::Listen(args) => commands::listen::run(args),
        Command::Segments(args) => commands::segments::run(args),
        Command::Completions { shell } => {
            omnitrack_manual::run_completions(&manual(), shell).map_err(commands::stdout_error)?;
            Ok(())
        }
        Command::Manpage(args) => {
            let result = omnitrack_manual::run_manpage(&manual(), &args);
            match args.dir {
                None => result.map_err(commands::stdout_error)?,
                Some(_) => result?,
            }
            Ok(())
        }
    }
}

/// The manual pages and completions: the command line's, with the exit codes as an EXIT STATUS
/// section of the pages that list them.
fn manual() -> omnitrack_manual::Manual {
    omnitrack_manual::Manual::new(<Cli as clap::CommandFactory>::command()).exit_status(commands::EXIT_STATUS_HELP)
}

#[cfg(test)]
mod tests {
    /// docs/interfaces.md, "Command line", is the contract: every command and long option of
    /// `omnitrack` is in its table, and everything the table names exists.
    #[test]
    fn the_command_line_is_the_one_the_contract_documents() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/docs/interfaces.md");
        let doc = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{path}: {e}"));
        let command = <super::Cli as clap::CommandFactory>::command();
        let problems = omnitrack::runtime::cli::undocumented(&command, "omnitrack", &doc);
        assert!(
            problems.is_empty(),
            "{path} and the command line differ:\n{}",
            problems.join("\n")
        );
    }

    /// Every `omnitrack` command the README gives is one the command line takes as written.
    #[test]
    fn the_readme_commands_are_ones_the_command_line_takes() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/README.md");
        let readme = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{path}: {e}"));
        let command = <super::Cli as clap::CommandFactory>::command();
        let problems = omnitrack::runtime::cli::readme_mismatches(&command, "omnitrack", &readme);
        assert!(problems.is_empty(), "README.md:\n{}", problems.join("\n"));
    }
}
