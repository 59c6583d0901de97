//! The longer jobs behind two subcommands: `render` (a synthetic recording of a rig moving
//! through a model) and `eval --json` (an evaluation as JSON); and the manual of `completions`
//! and `manpage`.
//!
//! In: the subcommands' parsed arguments. Out: files written, or JSON; errors as one line.

use omnitrack::desk::eval::{ErrorSeries, Evaluation, Stats};
use omnitrack::desk::recording::{write_recording, RecordingOptions};
use omnitrack::desk::render::Appearance;
use omnitrack::Rig;

/// Every statistic of an evaluation as JSON (translation in metres, rotation in degrees), for
/// scripts such as tools/check_evo.py.
pub(crate) fn eval_json(e: &Evaluation) -> serde_json::Value {
    let stats = |s: &Stats| {
        serde_json::json!({
            "rmse": s.rmse, "mean": s.mean, "median": s.median, "std": s.std,
            "min": s.min, "max": s.max, "count": s.count,
        })
    };
    let series = |s: Option<&ErrorSeries>| {
        s.map(|s| serde_json::json!({"translation_m": stats(&s.translation_m), "rotation_deg": stats(&s.rotation_deg)}))
    };
    serde_json::json!({
        "matched": e.pairs.len(),
        "ate": series(Some(&e.ate)),
        "rpe": series(e.rpe.as_ref()),
    })
}

/// Renders and writes a recording, with progress on stderr.
pub(crate) fn render(
    rig: &Rig,
    obj: &str,
    trajectory: &omnitrack::trajectory::Trajectory,
    out: &std::path::Path,
    appearance: Appearance,
) -> Result<(), String> {
    let options = RecordingOptions {
        appearance,
        ..RecordingOptions::default()
    };
    let summary = write_recording(out, rig, obj, trajectory, &options, |done, total| {
        eprint!("\rrendering frame {done}/{total}");
    })
    .map_err(|e| e.to_string())?;
    eprintln!(
        "\r{}: {} frames, {} images in {:.1} s ({:.2} frames/s rendering)",
        out.display(),
        summary.frames,
        summary.images,
        summary.render_seconds + summary.write_seconds,
        summary.frames as f64 / summary.render_seconds.max(1e-9)
    );
    Ok(())
}

/// `completions` and `manpage`: the manual of the command line (crates/manual).
pub fn manual() -> omnitrack_manual::Manual {
    omnitrack_manual::Manual::new(<crate::Cli as clap::CommandFactory>::command())
}

/// A manual written, or why not: a reader gone is no failure.
pub fn manual_result(result: std::io::Result<()>) -> Result<(), crate::Failure> {
    match result {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Err(crate::Failure::ReaderGone),
        Err(e) => Err(crate::Failure::Message(e.to_string())),
    }
}
