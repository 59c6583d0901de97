//! `model from-ifc`: the IFC converter (`tools/ifc_to_obj.py`, carried inside the binary) run
//! through IfcOpenShell in a venv of the per-user cache.
//!
//! In: the IFC file, the OBJ to write, an optional storey. Out: the OBJ (loaded back as the
//! tracker will load it before it replaces `out`), progress and a summary on stderr; errors as
//! one line.
//!
//! **Where things are.** The converter is compiled into the binary (`include_str!`), so an
//! installed `omnitrack-desk` needs no data file beside it and no source tree: each run writes it
//! to `CACHE/ifc_to_obj.py` (when it differs) and runs that with `python3`. CACHE is the desk
//! tools' and the demo's per-user cache: `$OMNITRACK_CACHE`, else `$XDG_CACHE_HOME/omnitrack`,
//! else `~/.cache/omnitrack` (docs/models.md). IfcOpenShell goes into the venv `CACHE/ifc-venv`
//! on first use (about 20 s), which the script announces on stderr as it starts; the lines the
//! script marks as progress (`from-ifc: …`) are passed on while it runs, not after.

use omnitrack::Model;
use std::io::BufRead;
use std::path::{Path, PathBuf};

/// The converter, as the binary carries it.
const IFC_TO_OBJ: &str = include_str!("../ifc_to_obj.py");

/// The prefix of the script's progress lines.
const PROGRESS: &str = "from-ifc: ";

/// Writes the converter into `cache` unless the same text is there; its path.
fn converter_in(cache: &Path) -> Result<PathBuf, String> {
    let script = cache.join("ifc_to_obj.py");
    if std::fs::read_to_string(&script).ok().as_deref() == Some(IFC_TO_OBJ) {
        return Ok(script);
    }
    // Written aside and renamed: a conversion running beside this one never reads half a file.
    let partial = cache.join(format!("ifc_to_obj.py.{}", std::process::id()));
    std::fs::write(&partial, IFC_TO_OBJ)
        .and_then(|()| std::fs::rename(&partial, &script))
        .map_err(|e| {
            let _ = std::fs::remove_file(&partial);
            format!("{}: cannot write the IFC converter: {e}", script.display())
        })?;
    Ok(script)
}

/// `omnitrack-desk model from-ifc FILE --out OUT [--storey NAME]`.
pub(crate) fn from_ifc(file: &Path, out: &Path, storey: Option<&str>) -> Result<(), String> {
    let (cache, _) = omnitrack::desk::demo::user_cache_dir().map_err(|e| e.to_string())?;
    let script = converter_in(&cache)?;
    let out_name = out.display().to_string();
    let partial = out.with_extension("obj.partial");
    let mut cmd = std::process::Command::new("python3");
    cmd.arg(&script)
        .arg(file)
        .arg("--out")
        .arg(&partial)
        .env("OMNITRACK_IFC_VENV", cache.join("ifc-venv"))
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped());
    if let Some(name) = storey {
        cmd.arg("--storey").arg(name);
    }
    let mut child = cmd
        .spawn()
        .map_err(|e| format!("cannot run python3 (IfcOpenShell needs it): {e}"))?;
    // Progress now; the rest (the per-storey report, or the error as its last line) at the end.
    let mut report = Vec::new();
    if let Some(stderr) = child.stderr.take() {
        for line in std::io::BufReader::new(stderr).lines().map_while(Result::ok) {
            if line.starts_with(PROGRESS) {
                eprintln!("{line}");
            } else {
                report.push(line);
            }
        }
    }
    let status = child.wait().map_err(|e| format!("python3 (the IFC converter): {e}"))?;
    if !status.success() {
        let _ = std::fs::remove_file(&partial);
        // The script's error is its last line; anything above it is pip's or Python's noise.
        let last = report
            .iter()
            .rev()
            .find(|l| !l.trim().is_empty())
            .map_or("no message", |l| l.as_str());
        return Err(last.trim().to_string());
    }
    for line in &report {
        eprintln!("{line}");
    }
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
