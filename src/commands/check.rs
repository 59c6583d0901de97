//! `omnitrack check`: validates a rig, a model and a tracker config, and summarises each on
//! standard error.

use super::CommandResult;
use omnitrack::config::TrackerConfig;
use omnitrack::{Model, Rig};
use std::path::PathBuf;

/// `check`'s arguments: any of the three files.
#[derive(clap::Args)]
pub struct Args {
    /// The rig file to validate.
    #[arg(long, value_name = "RIG.toml")]
    rig: Option<PathBuf>,
    /// A building model (OBJ) to load, with its faces and segments summarised.
    #[arg(long, value_name = "MODEL.obj")]
    model: Option<PathBuf>,
    /// A tracker config to validate (every key's type and range).
    #[arg(long, value_name = "tracker.toml")]
    config: Option<PathBuf>,
}

pub fn run(Args { rig, model, config }: Args) -> CommandResult {
    if rig.is_none() && model.is_none() && config.is_none() {
        return Err("check needs at least one of --rig, --model, --config".into());
    }
    if let Some(path) = rig {
        let rig = Rig::load(&path)?;
        eprintln!("{}: rig '{}', {} sensors", path.display(), rig.name, rig.sensors.len());
        for s in &rig.sensors {
            let c = s.centre();
            eprintln!(
                "  sensor {}: {}×{}, {} lens seeing up to {:.1}° off its axis, centre ({:.3}, {:.3}, {:.3}) m",
                s.id,
                s.width,
                s.height,
                s.lens.model_name(),
                s.max_off_axis().to_degrees(),
                c.x,
                c.y,
                c.z
            );
        }
        // How live capture will open the rig's cameras: a shared device without crops is an error
        // here rather than at the first `run`.
        let devices =
            omnitrack::capture::device::capture_devices(&rig).map_err(|e| format!("{}: {e}", path.display()))?;
        for d in devices.iter().filter(|d| !d.direct) {
            eprintln!(
                "  {}: windows of one device's frame ({}), at least {}×{}",
                d.label,
                d.device
                    .as_deref()
                    .or(d.usb_serial.as_deref())
                    .unwrap_or("its own camera"),
                d.width,
                d.height
            );
        }
    }
    // The config first: the model is checked against it as `run` will use it.
    let cfg = match &config {
        Some(path) => TrackerConfig::load(path)?,
        None => TrackerConfig::default(),
    };
    if let Some(path) = model {
        let m = Model::load(&path)?;
        if m.segments.is_empty() {
            return Err(format!(
                "{}: the model has no segments: nothing for the edges to match",
                path.display()
            )
            .into());
        }
        let v = &cfg.visibility;
        omnitrack::visibility::check_grid(&m, v.node_spacing_m, v.node_heights_m.len())
            .map_err(|e| format!("{}: {e}", path.display()))?;
        // A table is often built on a desk machine and copied to the rig's: a build this machine
        // could not hold is said, not refused (`run` without --visibility, or `visibility build`
        // here, refuses it before allocating). The device build cannot build tables at all.
        #[cfg(feature = "desk")]
        {
            let opts = omnitrack::visibility::build::BuildOptions::from_config(v);
            let available = omnitrack::visibility::build::available_memory();
            if let Err(e) = omnitrack::visibility::build::check_memory(&m, &opts, available) {
                eprintln!(
                    "{}: warning: {e}; a table built elsewhere (--visibility) needs none of it",
                    path.display()
                );
            }
        }
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
        eprintln!("{}: tracker config valid", path.display());
    }
    Ok(())
}
