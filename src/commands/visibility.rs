//! `omnitrack visibility build | query`: the prior visibility table of Koch–Teller §4.3. The
//! build is desk work (feature `desk`); the query runs on the device.

use super::CommandResult;
use std::path::PathBuf;

/// `visibility`'s subcommands.
#[derive(clap::Subcommand)]
pub enum Command {
    /// Builds the table of visible faces, segments and vertices per node (progress on stderr).
    Build {
        /// The building model.
        #[arg(long, value_name = "MODEL.obj")]
        model: PathBuf,
        /// Where to write the table.
        #[arg(long, value_name = "TABLE.vis")]
        out: PathBuf,
        /// Node spacing in metres (default: [visibility] node_spacing_m of tracker.toml, 1 m).
        #[arg(long, value_name = "METRES", allow_hyphen_values = true)]
        spacing_m: Option<f64>,
    },
    /// Prints the visibility set serving a position as one line of JSON.
    Query {
        /// The table, as `visibility build` wrote it.
        #[arg(long, value_name = "TABLE.vis")]
        visibility: PathBuf,
        /// The position in world coordinates, metres.
        #[arg(long, value_name = "x,y,z", allow_hyphen_values = true)]
        at: String,
    },
}

pub fn run(command: Command) -> CommandResult {
    match command {
        #[cfg(feature = "desk")]
        Command::Build { model, out, spacing_m } => {
            let config = omnitrack::config::TrackerConfig::default().visibility;
            let summary = omnitrack::visibility::build::run_build(&model, &out, spacing_m, &config)?;
            eprintln!("{summary}");
            Ok(())
        }
        #[cfg(not(feature = "desk"))]
        Command::Build { .. } => Err(
            "visibility build is desk work: this binary was built without the `desk` \
                                      feature (build with default features)"
                .into(),
        ),
        Command::Query { visibility, at } => {
            let at = omnitrack::visibility::parse_point(&at)?;
            let json = omnitrack::visibility::run_query(&visibility, &at)?;
            super::print_line(&json)?;
            Ok(())
        }
    }
}
