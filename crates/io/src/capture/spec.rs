//! Which frame source to open, and how: the `--source` specification and the options.
//!
//! In: the text of `--source` (docs/interfaces.md, "Command line": `replay:DIR`, `v4l` or `usb`),
//! parsed once, where the command line is read ([`SourceSpec`] implements [`FromStr`], so clap
//! takes it as a typed argument). Out: a [`SourceSpec`], or one line saying what is wrong with
//! the text; and [`SourceOptions`], how the chosen source is paced and how long a live one
//! waits. Opening is [`super::open`]'s; nothing here touches a file or a device.
//!
//! A spec names a source this binary may have been built without (`v4l`, `usb`): that is still a
//! valid spec, answered when it is opened with the cargo command that enables it.

use super::replay::Pacing;
use std::fmt;
use std::path::PathBuf;
use std::str::FromStr;
use std::time::Duration;

/// A frame source as `--source` names it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SourceSpec {
    /// `replay:DIR`: the recording in `DIR` (the mock camera).
    Replay(PathBuf),
    /// `v4l`: the rig's V4L2 devices (its sensors' `device` keys).
    V4l,
    /// `usb`: the rig's USB3 Vision cameras (`usb_serial`, `[usb]`).
    Usb,
}

impl SourceSpec {
    /// Whether this is a recording (which brings its own rig and can be read lossless).
    pub fn is_replay(&self) -> bool {
        matches!(self, SourceSpec::Replay(_))
    }

    /// The word of the spec, for messages: `replay`, `v4l` or `usb`.
    pub fn kind(&self) -> &'static str {
        match self {
            SourceSpec::Replay(_) => "replay",
            SourceSpec::V4l => "v4l",
            SourceSpec::Usb => "usb",
        }
    }
}

/// Why a `--source` text is not a [`SourceSpec`]: one line. Like the standard library's parse
/// errors it does not repeat the text (clap names the value and the option before it); the text
/// is kept for callers that report it themselves ([`SourceSpecError::text`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SourceSpecError {
    /// `replay` or `replay:` without a directory.
    #[error("replay needs a recording directory: replay:DIR")]
    ReplayWithoutDir(String),
    /// Anything else.
    #[error("unknown source (expected replay:DIR, v4l or usb)")]
    Unknown(String),
}

impl SourceSpecError {
    /// The text that was refused.
    pub fn text(&self) -> &str {
        match self {
            SourceSpecError::ReplayWithoutDir(t) | SourceSpecError::Unknown(t) => t,
        }
    }
}

impl FromStr for SourceSpec {
    type Err = SourceSpecError;

    /// `replay:DIR`, `v4l` or `usb`; blanks around the whole text are ignored.
    fn from_str(text: &str) -> Result<SourceSpec, SourceSpecError> {
        let spec = text.trim();
        if let Some(dir) = spec.strip_prefix("replay:") {
            if dir.is_empty() {
                return Err(SourceSpecError::ReplayWithoutDir(text.to_string()));
            }
            return Ok(SourceSpec::Replay(PathBuf::from(dir)));
        }
        match spec {
            "v4l" => Ok(SourceSpec::V4l),
            "usb" => Ok(SourceSpec::Usb),
            "replay" => Err(SourceSpecError::ReplayWithoutDir(text.to_string())),
            _ => Err(SourceSpecError::Unknown(text.to_string())),
        }
    }
}

impl fmt::Display for SourceSpec {
    /// The spec as `--source` takes it (`replay:DIR`, `v4l`, `usb`).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SourceSpec::Replay(dir) => write!(f, "replay:{}", dir.display()),
            SourceSpec::V4l => f.write_str("v4l"),
            SourceSpec::Usb => f.write_str("usb"),
        }
    }
}

/// How sources are opened and run; [`SourceOptions::default`] is what `omnitrack run` uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SourceOptions {
    /// Pacing of `replay:DIR` (default: real time, like a camera).
    pub pacing: Pacing,
    /// Longest wait for one sensor's image before it counts as dropped (live sources; default 1 s).
    pub frame_timeout: Duration,
    /// How often a lost live sensor is reopened (default 1 s).
    pub reopen_interval: Duration,
    /// What a live camera's control errors do when it is opened: stop the opening (`run`,
    /// `record`) or only be reported (`check --source`).
    pub control: ControlPolicy,
}

/// What a live camera that does not take the rig's `[control]` as asked does to its opening.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ControlPolicy {
    /// A control error fails the opening, in one line naming the first and counting the rest.
    #[default]
    Enforce,
    /// The camera opens whatever its controls did; the report is kept for
    /// [`super::FrameSource::control_reports`].
    Report,
}

impl Default for SourceOptions {
    fn default() -> SourceOptions {
        SourceOptions {
            pacing: Pacing::RealTime,
            frame_timeout: Duration::from_secs(1),
            reopen_interval: Duration::from_secs(1),
            control: ControlPolicy::Enforce,
        }
    }
}
