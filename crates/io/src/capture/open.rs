//! Choosing the frame source from the command line.
//!
//! In: a `--source` spec (docs/interfaces.md, "Command line": `replay:DIR`, `v4l` or `usb`) and
//! the rig given with `--rig`, if any. Out: a boxed [`FrameSource`] ([`open_source`]), or one
//! line saying what is wrong: an unknown spec, a live source without a rig, a live source this
//! binary was built without (with the cargo command that enables it), or the device error of
//! the source itself.
//!
//! A recording carries its own rig, so `replay:DIR` needs none; when `--rig` is given as well its
//! sensors must have the recording's sizes. `v4l` and `usb` need the rig: it names each sensor's
//! device (`device`, `usb_serial`, `[usb]`).
//!
//! Imports run one way: this file uses the sources (`replay`, `v4l2`, `usb`, and through them
//! [`super::live`]); none of them uses it.

use super::replay::ReplaySource;
use super::spec::SourceOptions;
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
pub fn open_source(spec: &str, rig: Option<&Rig>) -> Result<Box<dyn FrameSource + Send>, SourceError> {
    open_source_with(spec, rig, &SourceOptions::default())
}

/// [`open_source`] with explicit options.
pub fn open_source_with(
    spec: &str,
    rig: Option<&Rig>,
    options: &SourceOptions,
) -> Result<Box<dyn FrameSource + Send>, SourceError> {
    let spec_error = |message: String| SourceError::Device {
        device: spec.to_string(),
        message,
    };
    let spec = spec.trim();
    if let Some(dir) = spec.strip_prefix("replay:") {
        if dir.is_empty() {
            return Err(spec_error(
                "replay needs a recording directory: --source replay:DIR".into(),
            ));
        }
        let source = ReplaySource::open(Path::new(dir), options.pacing)?;
        if let Some(rig) = rig {
            check_same_sensors(source.rig(), rig, dir)?;
        }
        return Ok(Box::new(source));
    }
    let need_rig = |what: &str| {
        rig.ok_or_else(|| spec_error(format!("needs the rig (--rig RIG.toml) to know each sensor's {what}")))
    };
    match spec {
        "v4l" => {
            let rig = need_rig("V4L2 device")?;
            open_v4l(rig, options)
        }
        "usb" => {
            let rig = need_rig("USB3 Vision camera")?;
            open_usb(rig, options)
        }
        "replay" => Err(spec_error(
            "replay needs a recording directory: --source replay:DIR".into(),
        )),
        _ => Err(spec_error("unknown source (expected replay:DIR, v4l or usb)".into())),
    }
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
fn check_same_sensors(recorded: &Rig, given: &Rig, dir: &str) -> Result<(), SourceError> {
    let sizes = |r: &Rig| r.sensors.iter().map(|s| (s.width, s.height)).collect::<Vec<_>>();
    if sizes(recorded) == sizes(given) {
        return Ok(());
    }
    Err(SourceError::Format {
        path: Path::new(dir).join("rig.toml"),
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
