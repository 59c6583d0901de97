//! Opening the frame source the command line chose.
//!
//! In: a [`SourceSpec`] (parsed from `--source`, see [`super::spec`]) and the rig given with
//! `--rig`, if any. Out: a boxed [`FrameSource`] ([`open_source`]), or one line saying what is
//! wrong: a live source without a rig, a live source this binary was built without (with the
//! cargo command that enables it), or the error of the source itself.
//!
//! A recording carries its own rig, so `replay:DIR` needs none; when `--rig` is given as well its
//! sensors must have the recording's sizes. `v4l` and `usb` need the rig: it names each sensor's
//! device (`device`, `usb_serial`, `[usb]`).
//!
//! Imports run one way: this file uses the sources (`replay`, `v4l2`, `usb`, and through them
//! [`super::live`]); none of them uses it.

use super::replay::ReplaySource;
use super::spec::{SourceOptions, SourceSpec};
use super::{FrameSource, SourceError};
use omnitrack_core::rig::Rig;
use std::path::Path;

/// The hint printed when a live source is asked of a binary built without it.
pub const V4L_DISABLED: &str = "live V4L2 capture is not in this build: rebuild with \
     `cargo build --release --features v4l` (needs libclang, e.g. `apt-get install libclang-dev`)";

/// The hint printed when `--source usb` is asked of a binary built without it.
pub const USB_DISABLED: &str = "live USB3 Vision capture is not in this build: rebuild with \
     `cargo build --release --features usb`";

/// Opens the source named by `spec` with [`SourceOptions::default`]. See the module doc.
pub fn open_source(spec: &SourceSpec, rig: Option<&Rig>) -> Result<Box<dyn FrameSource + Send>, SourceError> {
    open_source_with(spec, rig, &SourceOptions::default())
}

/// [`open_source`] with explicit options.
pub fn open_source_with(
    spec: &SourceSpec,
    rig: Option<&Rig>,
    options: &SourceOptions,
) -> Result<Box<dyn FrameSource + Send>, SourceError> {
    match spec {
        SourceSpec::Replay(dir) => {
            let source = ReplaySource::open(dir, options.pacing)?;
            if let Some(rig) = rig {
                check_same_sensors(source.rig(), rig, dir)?;
            }
            Ok(Box::new(source))
        }
        SourceSpec::V4l => open_v4l(need_rig(spec, rig, "V4L2 device")?, options),
        SourceSpec::Usb => open_usb(need_rig(spec, rig, "USB3 Vision camera")?, options),
    }
}

/// The rig a live source needs to know its devices, or one line saying so.
fn need_rig<'r>(spec: &SourceSpec, rig: Option<&'r Rig>, what: &str) -> Result<&'r Rig, SourceError> {
    rig.ok_or_else(|| SourceError::Device {
        device: spec.to_string(),
        message: format!("needs the rig (--rig RIG.toml) to know each sensor's {what}"),
    })
}

#[cfg(feature = "v4l")]
fn open_v4l(rig: &Rig, options: &SourceOptions) -> Result<Box<dyn FrameSource + Send>, SourceError> {
    Ok(Box::new(super::v4l2::V4l2Source::open(rig.clone(), *options)?))
}

#[cfg(not(feature = "v4l"))]
fn open_v4l(_rig: &Rig, _options: &SourceOptions) -> Result<Box<dyn FrameSource + Send>, SourceError> {
    Err(SourceError::Device {
        device: "v4l".into(),
        message: V4L_DISABLED.into(),
    })
}

#[cfg(feature = "usb")]
fn open_usb(rig: &Rig, options: &SourceOptions) -> Result<Box<dyn FrameSource + Send>, SourceError> {
    Ok(Box::new(super::usb::UsbSource::open(rig.clone(), *options)?))
}

#[cfg(not(feature = "usb"))]
fn open_usb(_rig: &Rig, _options: &SourceOptions) -> Result<Box<dyn FrameSource + Send>, SourceError> {
    Err(SourceError::Device {
        device: "usb".into(),
        message: USB_DISABLED.into(),
    })
}

/// A `--rig` given with a recording must have the recording's sensors (count and sizes).
fn check_same_sensors(recorded: &Rig, given: &Rig, dir: &Path) -> Result<(), SourceError> {
    let sizes = |r: &Rig| r.sensors.iter().map(|s| (s.width, s.height)).collect::<Vec<_>>();
    if sizes(recorded) == sizes(given) {
        return Ok(());
    }
    Err(SourceError::Format {
        path: dir.join("rig.toml"),
        line: None,
        message: format!(
            "the recording's rig '{}' ({} sensors) does not match --rig '{}' ({} sensors) in sensor count or sizes",
            recorded.name,
            recorded.sensors.len(),
            given.name,
            given.sensors.len()
        ),
    })
}
