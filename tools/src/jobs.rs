//! The longer jobs behind three subcommands: `render` (a synthetic recording of a rig moving
//! through a model), `model from-ifc` (IfcOpenShell in its own venv) and `eval --json` (an
//! evaluation as JSON); and the manual of `completions` and `manpage`.
//!
//! In: the subcommands' parsed arguments. Out: files written, or JSON; errors as one line.

use omnitrack::desk::eval::{ErrorSeries, Evaluation, Stats};
use omnitrack::desk::recording::{write_recording, RecordingOptions};
use omnitrack::desk::render::Appearance;
use omnitrack::{Model, Rig};

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

/// `model from-ifc`: `tools/ifc_to_obj.py` writes the OBJ through IfcOpenShell; the result is
/// loaded back as the tracker will load it before it replaces `out`.
pub(crate) fn from_ifc(file: &std::path::Path, out: &std::path::Path, storey: Option<&str>) -> Result<(), String> {
    let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("ifc_to_obj.py");
    let out_name = out.display().to_string();
    let partial = out.with_extension("obj.partial");
    let mut cmd = std::process::Command::new("python3");
    cmd.arg(&script).arg(file).arg("--out").arg(&partial);
    if let Some(name) = storey {
        cmd.arg("--storey").arg(name);
    }
    let run = cmd
        .output()
        .map_err(|e| format!("cannot run python3 (IfcOpenShell needs it): {e}"))?;
    let report = String::from_utf8_lossy(&run.stderr);
    if !run.status.success() {
        let _ = std::fs::remove_file(&partial);
        // The script's error is its last line; anything above it is pip's progress.
        let last = report
            .lines()
            .rev()
            .find(|l| !l.trim().is_empty())
            .unwrap_or("no message");
        return Err(last.trim().to_string());
    }
    eprint!("{report}");
    let model = Model::load(&partial).map_err(|e| {
        let _ = std::fs::remove_file(&partial);
        format!("{}: the converted model does not load: {e}", file.display())
    })?;
    std::fs::rename(&partial, out).map_err(|e| format!("{out_name}: cannot write: {e}"))?;
    // The segments the tracker will use (the shipped `[visibility] min_segment_length_m`).
    let min = omnitrack::config::MIN_SEGMENT_LENGTH_M;
    let long = model.segments.iter().filter(|s| s.length() >= min).count();
    let s = &model.stats;
    eprintln!(
        "{out_name}: {} faces, {} vertices, {} segments ({long} at least {min} m long, which the tracker uses); loader: {} degenerate faces, {} welded vertices",
        model.faces.len(),
        model.vertices.len(),
        model.segments.len(),
        s.degenerate_faces,
        s.welded_vertices
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
