//! `omnitrack check`: validates a rig, a model and a tracker config, and summarises each on
//! standard error, or, with `--json`, as one JSON object per file on standard output
//! (docs/interfaces.md, "JSON output").
//!
//! Each file given is checked, also after another failed: a script (or a person) hears of every
//! file that is wrong at once (without `--json`, one line each, after the summaries of the valid
//! ones). The model is checked against the config as `run` would use it
//! (the config given, or the shipped values when none is given or it is not valid).
//!
//! With `--source v4l|usb` the rig's cameras are opened as `run` opens them, their `[control]`
//! set and read back, and what each device made of each key is one line (docs/rig-guide.md,
//! "Camera control"); a key refused, missing or changed makes the rig not valid (exit 2), one
//! rounded to the device's step is a warning.

use super::CommandResult;
use omnitrack::capture::control::ControlReport;
use omnitrack::capture::{open_source_with, ControlPolicy, SourceOptions, SourceSpec};
use omnitrack::config::TrackerConfig;
use omnitrack::{Model, Rig};
use serde::Serialize;
use std::path::{Path, PathBuf};

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
    /// Open the rig's cameras (v4l or usb), set each sensor's [control] as `run` would and say
    /// what every device made of every key (needs --rig).
    #[arg(long, value_name = "v4l|usb", requires = "rig")]
    source: Option<SourceSpec>,
    /// One JSON object per file checked on standard output instead of the summary on standard
    /// error (fields in docs/interfaces.md); the exit code is the same.
    #[arg(long)]
    json: bool,
}

/// What `check` found in one file: one line of `--json`.
#[derive(Serialize)]
struct Finding<'a> {
    file: &'a Path,
    /// `rig`, `model` or `config`.
    kind: &'static str,
    ok: bool,
    /// Why the file is refused (one line, as without `--json`); `null` when it is valid.
    error: Option<String>,
    /// What would not stop `run` but deserves a look.
    warnings: Vec<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    rig: Option<RigFinding>,
    #[serde(skip_serializing_if = "Option::is_none")]
    model: Option<ModelFinding>,
    /// With `--source`: one entry per key asked of a camera.
    #[serde(skip_serializing_if = "Option::is_none")]
    controls: Option<Vec<ControlFinding>>,
}

#[derive(Serialize)]
struct ControlFinding {
    device: String,
    sensors: String,
    key: &'static str,
    /// `set`, `rounded`, `changed`, `out_of_range`, `refused` or `not_supported`.
    outcome: &'static str,
    /// Whether it stops `run`.
    error: bool,
    /// The line `check` prints for it.
    line: String,
}

#[derive(Serialize)]
struct RigFinding {
    name: String,
    sensors: Vec<SensorFinding>,
    /// Devices whose frame several sensors share (each sensor a window of it).
    shared_devices: Vec<SharedDevice>,
}

#[derive(Serialize)]
struct SensorFinding {
    id: usize,
    width: u32,
    height: u32,
    lens: &'static str,
    max_off_axis_deg: f64,
    centre_m: [f64; 3],
    /// The sensor's `[control]` (the rig's table with its own keys over it), as `key = value`
    /// lines; empty: its camera is left as it is.
    control: Vec<String>,
}

#[derive(Serialize)]
struct SharedDevice {
    /// `sensors 0 and 1`, for the text.
    #[serde(skip)]
    label: String,
    sensors: Vec<usize>,
    /// The V4L2 device or the USB3 Vision serial.
    device: Option<String>,
    min_width: u32,
    min_height: u32,
}

#[derive(Serialize)]
struct ModelFinding {
    vertices: usize,
    faces: usize,
    segments: usize,
    free_segments: usize,
    degenerate_faces: usize,
    nonplanar_faces: usize,
    welded_vertices: usize,
    ignored_records: usize,
    degenerate_lines: usize,
}

impl<'a> Finding<'a> {
    fn new(file: &'a Path, kind: &'static str) -> Finding<'a> {
        Finding {
            file,
            kind,
            ok: true,
            error: None,
            warnings: Vec::new(),
            rig: None,
            model: None,
            controls: None,
        }
    }

    fn failed(mut self, error: impl std::fmt::Display) -> Finding<'a> {
        self.ok = false;
        self.error = Some(error.to_string());
        self
    }
}

pub fn run(a: Args) -> CommandResult {
    if a.rig.is_none() && a.model.is_none() && a.config.is_none() {
        return Err("check needs at least one of --rig, --model, --config".into());
    }
    if a.source.as_ref().is_some_and(SourceSpec::is_replay) {
        return Err("check --source takes a live source, v4l or usb: a recording has no camera to set".into());
    }
    let mut findings = Vec::new();
    if let Some(path) = &a.rig {
        let mut f = check_rig(path);
        if let (Some(spec), true) = (&a.source, f.ok) {
            f = check_controls(f, spec);
        }
        findings.push(f);
    }
    // The config before the model: the model is checked against it as `run` will use it.
    let mut cfg = TrackerConfig::default();
    let mut config_finding = None;
    if let Some(path) = &a.config {
        let mut f = Finding::new(path, "config");
        match TrackerConfig::load(path) {
            Ok(c) => cfg = c,
            Err(e) => f = f.failed(e),
        }
        config_finding = Some(f);
    }
    if let Some(path) = &a.model {
        findings.push(check_model(path, &cfg));
    }
    findings.extend(config_finding);
    let failed = findings.iter().filter(|f| !f.ok).count();
    if a.json {
        for f in &findings {
            super::print_json(f)?;
        }
    } else {
        // What is wrong last, one line per file: the last line of the output says it.
        let (bad, good): (Vec<&Finding>, Vec<&Finding>) = findings.iter().partition(|f| !f.ok);
        for f in good.into_iter().chain(bad) {
            say(f);
        }
    }
    if failed > 0 {
        return Err(Box::new(super::Exit(super::exit::FAILURE)));
    }
    Ok(())
}

fn check_rig(path: &Path) -> Finding<'_> {
    let f = Finding::new(path, "rig");
    let rig = match Rig::load(path) {
        Ok(r) => r,
        Err(e) => return f.failed(e),
    };
    // How live capture will open the rig's cameras: a shared device without crops is an error
    // here rather than at the first `run`.
    let devices = match omnitrack::capture::device::capture_devices(&rig) {
        Ok(d) => d,
        Err(e) => return f.failed(format!("{}: {e}", path.display())),
    };
    Finding {
        rig: Some(RigFinding {
            name: rig.name.clone(),
            sensors: rig
                .sensors
                .iter()
                .map(|s| {
                    let c = s.centre();
                    SensorFinding {
                        id: s.id,
                        width: s.width,
                        height: s.height,
                        lens: s.lens.model_name(),
                        max_off_axis_deg: s.max_off_axis().to_degrees(),
                        centre_m: [c.x, c.y, c.z],
                        control: s
                            .control
                            .toml_lines(&Default::default())
                            .lines()
                            .map(str::to_string)
                            .collect(),
                    }
                })
                .collect(),
            shared_devices: devices
                .iter()
                .filter(|d| !d.direct)
                .map(|d| SharedDevice {
                    label: d.label.clone(),
                    sensors: d.sensors().collect(),
                    device: d.device.clone().or_else(|| d.usb_serial.clone()),
                    min_width: d.width,
                    min_height: d.height,
                })
                .collect(),
        }),
        ..f
    }
}

/// Opens the rig's cameras through `spec` as `run` would, keeping what each made of its
/// `[control]` (see the module doc).
fn check_controls<'a>(f: Finding<'a>, spec: &SourceSpec) -> Finding<'a> {
    let rig = match Rig::load(f.file) {
        Ok(r) => r,
        Err(e) => return f.failed(e),
    };
    let options = SourceOptions {
        control: ControlPolicy::Report,
        ..SourceOptions::default()
    };
    match open_source_with(spec, Some(&rig), &options) {
        Ok(source) => with_reports(f, &source.control_reports()),
        Err(e) => f.failed(e),
    }
}

/// The finding with what the cameras made of their `[control]`: every key a line, the first
/// error the finding's error, rounded values its warnings.
fn with_reports<'a>(mut f: Finding<'a>, reports: &[ControlReport]) -> Finding<'a> {
    let mut controls = Vec::new();
    let mut first_error = None;
    for r in reports {
        for c in &r.findings {
            let line = r.line(c);
            if c.outcome.is_error() {
                first_error.get_or_insert_with(|| line.clone());
            } else if c.outcome.kind() == "rounded" {
                f.warnings.push(line.clone());
            }
            controls.push(ControlFinding {
                device: r.device.clone(),
                sensors: r.sensors.clone(),
                key: c.key,
                outcome: c.outcome.kind(),
                error: c.outcome.is_error(),
                line,
            });
        }
    }
    f.controls = Some(controls);
    if let Some(e) = first_error {
        f.ok = false;
        f.error = Some(e);
    }
    f
}

fn check_model<'a>(path: &'a Path, cfg: &TrackerConfig) -> Finding<'a> {
    let mut f = Finding::new(path, "model");
    let m = match Model::load(path) {
        Ok(m) => m,
        Err(e) => return f.failed(e),
    };
    if m.segments.is_empty() {
        return f.failed(format!(
            "{}: the model has no segments: nothing for the edges to match",
            path.display()
        ));
    }
    let v = &cfg.visibility;
    if let Err(e) = omnitrack::visibility::check_grid(&m, v.node_spacing_m, v.node_heights_m.len()) {
        return f.failed(format!("{}: {e}", path.display()));
    }
    // A table is often built on a desk machine and copied to the rig's: a build this machine
    // could not hold is said, not refused (`run` without --visibility, or `visibility build`
    // here, refuses it before allocating). The device build cannot build tables at all.
    #[cfg(feature = "desk")]
    {
        let opts = omnitrack::visibility::build::BuildOptions::from_config(v);
        let available = omnitrack::visibility::build::available_memory();
        if let Err(e) = omnitrack::visibility::build::check_memory(&m, &opts, available) {
            f.warnings
                .push(format!("{e}; a table built elsewhere (--visibility) needs none of it"));
        }
    }
    f.model = Some(ModelFinding {
        vertices: m.vertices.len(),
        faces: m.faces.len(),
        segments: m.segments.len(),
        free_segments: m.segments.iter().filter(|s| s.is_free()).count(),
        degenerate_faces: m.stats.degenerate_faces,
        nonplanar_faces: m.stats.nonplanar_faces,
        welded_vertices: m.stats.welded_vertices,
        ignored_records: m.stats.ignored_records,
        degenerate_lines: m.stats.degenerate_lines,
    });
    f
}

/// A finding as the lines people read on standard error (an error as `omnitrack: …`).
fn say(f: &Finding) {
    let path = f.file.display();
    if let Some(controls) = &f.controls {
        if controls.is_empty() {
            eprintln!("{path}: no [control] asked: the cameras opened and were left as they are");
        }
        // Every key asked and what the device made of it; the first error again last, below.
        for c in controls {
            let mark = if c.error {
                "error"
            } else if c.outcome == "rounded" {
                "warning"
            } else {
                "ok"
            };
            eprintln!("  {mark}: {}", c.line);
        }
    }
    if let Some(e) = &f.error {
        eprintln!("omnitrack: {e}");
        return;
    }
    for w in f
        .warnings
        .iter()
        .filter(|w| f.controls.as_ref().is_none_or(|c| !c.iter().any(|c| c.line == **w)))
    {
        eprintln!("{path}: warning: {w}");
    }
    if let Some(rig) = &f.rig {
        eprintln!("{path}: rig '{}', {} sensors", rig.name, rig.sensors.len());
        for s in &rig.sensors {
            let c = s.centre_m;
            eprintln!(
                "  sensor {}: {}×{}, {} lens seeing up to {:.1}° off its axis, centre ({:.3}, {:.3}, {:.3}) m",
                s.id, s.width, s.height, s.lens, s.max_off_axis_deg, c[0], c[1], c[2]
            );
            if !s.control.is_empty() {
                eprintln!("    asks its camera: {}", s.control.join(", "));
            }
        }
        for d in &rig.shared_devices {
            eprintln!(
                "  {}: windows of one device's frame ({}), at least {}×{}",
                d.label,
                d.device.as_deref().unwrap_or("its own camera"),
                d.min_width,
                d.min_height
            );
        }
    }
    if let Some(m) = &f.model {
        eprintln!(
            "{path}: {} vertices, {} faces, {} segments ({} free); skipped {} degenerate faces, \
             split {} non-planar faces, welded {} duplicate vertices, ignored {} records",
            m.vertices,
            m.faces,
            m.segments,
            m.free_segments,
            m.degenerate_faces,
            m.nonplanar_faces,
            m.welded_vertices,
            m.ignored_records
        );
    }
    if f.kind == "config" {
        eprintln!("{path}: tracker config valid");
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use omnitrack::capture::control::Outcome;

    #[test]
    fn every_control_is_a_line_the_first_error_fails_the_rig_and_rounding_warns() {
        let path = Path::new("rig.toml");
        let mut a = ControlReport::new("/dev/video0", "sensor 0");
        a.push(
            "exposure_us",
            Outcome::Rounded {
                asked: 5040.0,
                got: 5000.0,
                unit: " µs",
            },
        );
        a.push("gain", Outcome::Set { got: "32".into() });
        let mut b = ControlReport::new("/dev/video1", "sensor 1");
        b.push(
            "frame_rate_hz",
            Outcome::Changed {
                asked: "25 Hz".into(),
                got: "30 Hz".into(),
            },
        );
        b.push(
            "trigger",
            Outcome::NotSupported {
                why: "V4L2 has none".into(),
            },
        );
        let f = with_reports(Finding::new(path, "rig"), &[a.clone()]);
        assert!(f.ok && f.error.is_none());
        assert_eq!(
            f.warnings,
            ["/dev/video0: sensor 0, control.exposure_us: set to 5000 µs (asked 5040 µs; the device's nearest step)"]
        );
        let f = with_reports(Finding::new(path, "rig"), &[a, b]);
        assert!(!f.ok);
        assert_eq!(
            f.error.as_deref(),
            Some("/dev/video1: sensor 1, control.frame_rate_hz: asked 25 Hz, the device reports 30 Hz")
        );
        let json = serde_json::to_value(&f).unwrap();
        let controls = json["controls"].as_array().unwrap();
        let kinds: Vec<&str> = controls.iter().map(|c| c["outcome"].as_str().unwrap()).collect();
        assert_eq!(kinds, ["rounded", "set", "changed", "not_supported"]);
        let errors: Vec<bool> = controls.iter().map(|c| c["error"].as_bool().unwrap()).collect();
        assert_eq!(errors, [false, false, true, true]);
        assert_eq!(
            controls[3]["line"],
            "/dev/video1: sensor 1, control.trigger: not supported: V4L2 has none"
        );
        assert_eq!(controls[2]["device"], "/dev/video1");
        assert_eq!(controls[2]["key"], "frame_rate_hz");
    }
}
