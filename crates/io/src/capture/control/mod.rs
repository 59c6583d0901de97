//! Camera control: the rig's `[control]` asked of a live camera, and what the camera reports.
//!
//! In: a sensor's [`CameraControl`] (exposure, gain, frame rate, white balance, trigger; from the
//! rig file) and a camera's control channel, behind a narrow trait per protocol: the V4L2
//! control ioctls ([`v4l2::V4l2ControlIo`]), or a USB3 Vision camera's GenCP control endpoint
//! ([`gencp::ControlEndpoint`]) read through the subset of its GenICam description this module
//! understands ([`genicam`], [`u3v`]). Out: a [`ControlReport`], one [`ControlFinding`] per key
//! asked, each saying what the device took, what it changed and what it refused, as one line.
//!
//! Policy (docs/rig-guide.md, "Camera control"): a key the device does not have, refuses, or
//! sets to something else than asked (beyond rounding to its own step) is an *error*: `run`
//! and `record` do not start on it and `check --source` exits 2, since a rig file that fixes the
//! exposure promises images without motion blur, and one that asks for a trigger promises
//! synchronised sensors; a tracker quietly running without them is what a demanding user least
//! wants. A value rounded to the device's step (within one step, or 1 % of the value) is a
//! *warning*. A key not in the rig file is never touched.
//!
//! The protocol layers are always compiled and tested against fake devices that speak the
//! protocols' bytes (crates/io/tests/camctl/); only the thin adapters onto the real
//! ioctls (`capture::v4l2`) and USB endpoints (`capture::usb`) sit behind the cargo features.

pub mod gencp;
pub mod genicam;
pub mod u3v;
pub mod v4l2;

pub use omnitrack_core::rig::{CameraControl, Setting, Trigger};
use std::fmt;

/// What became of one key asked of a device.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// Set, and read back as asked (`got` in the key's unit, for the record).
    Set { got: String },
    /// Set to the device's nearest step: within one step or 1 % of what was asked.
    Rounded { asked: f64, got: f64, unit: &'static str },
    /// The device holds another value than asked after the write (it clamped or ignored it).
    Changed { asked: String, got: String },
    /// The value lies outside the range the device reports; nothing written.
    OutOfRange {
        asked: f64,
        min: f64,
        max: f64,
        unit: &'static str,
    },
    /// The device refused the write or the read (an ioctl's or GenCP's error, a read-only
    /// control, a missing enumeration entry).
    Refused { why: String },
    /// The device (or this protocol, or the subset of GenICam read here) has no such control.
    NotSupported { why: String },
}

impl Outcome {
    /// The outcome's name in `check --json`: `set`, `rounded`, `changed`, `out_of_range`,
    /// `refused` or `not_supported`.
    pub fn kind(&self) -> &'static str {
        match self {
            Outcome::Set { .. } => "set",
            Outcome::Rounded { .. } => "rounded",
            Outcome::Changed { .. } => "changed",
            Outcome::OutOfRange { .. } => "out_of_range",
            Outcome::Refused { .. } => "refused",
            Outcome::NotSupported { .. } => "not_supported",
        }
    }

    /// Whether this outcome stops a run (see the module doc).
    pub fn is_error(&self) -> bool {
        !matches!(self, Outcome::Set { .. } | Outcome::Rounded { .. })
    }
}

/// One key of the rig's `[control]` and what the device made of it.
#[derive(Debug, Clone, PartialEq)]
pub struct ControlFinding {
    /// The rig file's key, e.g. `exposure_us`.
    pub key: &'static str,
    pub outcome: Outcome,
}

/// What one device made of a sensor's `[control]`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ControlReport {
    /// The device, e.g. `/dev/video0` or `usb 1e10:3300 bus 2 ports [1]`.
    pub device: String,
    /// The sensors it delivers, e.g. `sensor 3`.
    pub sensors: String,
    pub findings: Vec<ControlFinding>,
}

impl ControlReport {
    pub fn new(device: &str, sensors: &str) -> ControlReport {
        ControlReport {
            device: device.to_string(),
            sensors: sensors.to_string(),
            findings: Vec::new(),
        }
    }

    pub fn push(&mut self, key: &'static str, outcome: Outcome) {
        self.findings.push(ControlFinding { key, outcome });
    }

    /// Whether any key stops a run.
    pub fn has_errors(&self) -> bool {
        self.findings.iter().any(|f| f.outcome.is_error())
    }

    /// One line per finding: `/dev/video0: sensor 3, control.exposure_us: …`.
    pub fn lines(&self) -> impl Iterator<Item = String> + '_ {
        self.findings.iter().map(|f| self.line(f))
    }

    /// The line of one finding.
    pub fn line(&self, f: &ControlFinding) -> String {
        format!("{}: {}, control.{}: {}", self.device, self.sensors, f.key, f.outcome)
    }

    /// The findings that stop a run, as a [`super::SourceError`]: the first, and how many
    /// more (`omnitrack check --source` lists them all; printing them here would repeat them at
    /// every reopening attempt of a camera that came back different).
    pub fn error(&self) -> Option<super::SourceError> {
        let mut errors = self.findings.iter().filter(|f| f.outcome.is_error());
        let first = errors.next()?;
        let more = errors.count();
        let tail = if more > 0 {
            format!(" (and {more} more control error(s): `omnitrack check --source` lists them)")
        } else {
            String::new()
        };
        Some(super::SourceError::Device {
            device: self.device.clone(),
            message: format!("{}, control.{}: {}{tail}", self.sensors, first.key, first.outcome),
        })
    }
}

/// [`enforce`] under [`ControlPolicy::Enforce`](super::ControlPolicy::Enforce); nothing under
/// [`ControlPolicy::Report`](super::ControlPolicy::Report) (the report is read back from the
/// source).
pub fn settle(report: &ControlReport, policy: super::ControlPolicy) -> Result<(), super::SourceError> {
    match policy {
        super::ControlPolicy::Enforce => enforce(report),
        super::ControlPolicy::Report => Ok(()),
    }
}

/// Says a report's rounded values on standard error (`warning: ` and the line) and turns its
/// errors into the device's opening error ([`ControlReport::error`]).
pub fn enforce(report: &ControlReport) -> Result<(), super::SourceError> {
    for f in &report.findings {
        if matches!(f.outcome, Outcome::Rounded { .. }) {
            eprintln!("warning: {}", report.line(f));
        }
    }
    report.error().map_or(Ok(()), Err)
}

impl fmt::Display for Outcome {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Outcome::Set { got } => write!(f, "set to {got}"),
            Outcome::Rounded { asked, got, unit } => {
                write!(
                    f,
                    "set to {}{unit} (asked {}{unit}; the device's nearest step)",
                    trim(*got),
                    trim(*asked)
                )
            }
            Outcome::Changed { asked, got } => write!(f, "asked {asked}, the device reports {got}"),
            Outcome::OutOfRange { asked, min, max, unit } => {
                write!(
                    f,
                    "{}{unit} is outside the device's range [{}, {}]{unit}; not set",
                    trim(*asked),
                    trim(*min),
                    trim(*max)
                )
            }
            Outcome::Refused { why } => write!(f, "refused by the device: {why}"),
            Outcome::NotSupported { why } => write!(f, "not supported: {why}"),
        }
    }
}

/// How a number read back compares with the one asked: the same (to the last bits of a float
/// register), rounded to the device's step (`step`, or 1 % of the value), or changed.
pub fn compare(asked: f64, got: f64, step: f64, unit: &'static str) -> Outcome {
    let diff = (got - asked).abs();
    if diff <= 1e-6 * asked.abs().max(1.0) {
        Outcome::Set {
            got: format!("{}{unit}", trim(got)),
        }
    } else if diff <= step.abs().max(0.01 * asked.abs()) {
        Outcome::Rounded { asked, got, unit }
    } else {
        Outcome::Changed {
            asked: format!("{}{unit}", trim(asked)),
            got: format!("{}{unit}", trim(got)),
        }
    }
}

/// A number as people write it: no trailing zeros, at most six decimals.
pub fn trim(x: f64) -> String {
    let s = format!("{x:.6}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" {
        "0".into()
    } else {
        s.to_string()
    }
}
