//! `omnitrack edges`: the detected edges of one sensor image as CSV (docs/interfaces.md).

use super::CommandResult;
use omnitrack::config::TrackerConfig;
use omnitrack::Rig;
use std::io::Write;
use std::path::PathBuf;

/// `edges`' arguments.
#[derive(clap::Args)]
pub struct Args {
    /// The rig the image comes from (its sensor's lens and size).
    #[arg(long, value_name = "RIG.toml")]
    rig: PathBuf,
    /// The sensor's id in the rig.
    #[arg(long)]
    sensor: usize,
    /// Tracker config whose [edges] section to use (default: the papers' values).
    #[arg(long, value_name = "tracker.toml")]
    config: Option<PathBuf>,
    /// The sensor image (PNG or JPEG).
    #[arg(value_name = "IMAGE.png")]
    image: PathBuf,
}

pub fn run(
    Args {
        rig,
        sensor,
        config,
        image,
    }: Args,
) -> CommandResult {
    let rig = Rig::load(&rig)?;
    let edges = match config {
        Some(p) => TrackerConfig::load(&p)?.edges,
        None => omnitrack::config::EdgeConfig::default(),
    };
    let csv = omnitrack::edges::edges_csv_for_image(&rig, &edges, sensor, &image)?;
    let mut out = std::io::stdout().lock();
    out.write_all(csv.as_bytes()).map_err(super::stdout_error)?;
    Ok(())
}
