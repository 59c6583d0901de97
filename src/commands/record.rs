//! `omnitrack record`: what a source delivers, in the recording layout `run` replays.

use super::CommandResult;
use omnitrack::capture::{open_source_with, Pacing, SourceOptions, SourceSpec};
use omnitrack::runtime::pipeline::stop_on_signals;
use omnitrack::runtime::record::{record, ImageFormat, RecordOptions};
use omnitrack::Rig;
use std::path::PathBuf;

/// `record`'s arguments (docs/interfaces.md).
#[derive(clap::Args)]
pub struct Args {
    /// The rig (a replay's own rig.toml is used when this is omitted).
    #[arg(long, value_name = "RIG.toml")]
    rig: Option<PathBuf>,
    /// replay:DIR, v4l or usb.
    #[arg(long, value_name = "replay:DIR|v4l|usb")]
    source: SourceSpec,
    /// The recording directory to create (it must not exist, or be empty).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Stop after N frames (default: until the source ends, or Ctrl-C).
    #[arg(long)]
    frames: Option<u64>,
    /// The images' file format, all lossless: ppm (raw, the default: the least CPU to write and to
    /// replay, twice PNG's disk), png (what any tool opens) or qoi.
    #[arg(long, value_name = "ppm|png|qoi", default_value = "ppm", value_parser = parse_format)]
    format: ImageFormat,
}

fn parse_format(s: &str) -> Result<ImageFormat, String> {
    ImageFormat::parse(s).ok_or_else(|| format!("'{s}': ppm, png or qoi"))
}

pub fn run(a: Args) -> CommandResult {
    let rig = a.rig.as_deref().map(Rig::load).transpose()?;
    let replay = a.source.is_replay();
    // A replay is re-recorded whole and as fast as the disk takes it; cameras are never made
    // to wait.
    let options = SourceOptions {
        pacing: if replay {
            Pacing::AsFastAsPossible
        } else {
            Pacing::RealTime
        },
        ..SourceOptions::default()
    };
    let mut source = open_source_with(&a.source, rig.as_ref(), &options)?;
    let opts = RecordOptions {
        max_frames: a.frames,
        lossless: replay,
        format: a.format,
        ..RecordOptions::default()
    };
    let _signals = stop_on_signals(&opts.stop)?;
    let summary = record(source.as_mut(), &a.out, &opts)?;
    eprintln!("omnitrack: {}: {summary}", a.out.display());
    Ok(())
}
