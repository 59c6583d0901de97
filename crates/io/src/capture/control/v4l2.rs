//! V4L2 camera control: the rig's `[control]` through the control ioctls.
//!
//! In: a [`CameraControl`] and a device behind [`V4l2ControlIo`], the ioctls this needs with the
//! kernel's structures' fields (`VIDIOC_QUERYCTRL`, `VIDIOC_G_CTRL`, `VIDIOC_S_CTRL`,
//! `VIDIOC_G_PARM`, `VIDIOC_S_PARM`) and errno for errors, so that the real device
//! (`capture::v4l2`, feature `v4l`) and a fake one in the tests answer alike. Out: a
//! [`ControlReport`] ([`apply`]).
//!
//! The mapping, per key (the user-class and camera-class controls of the V4L2 specification):
//!
//! | key | controls |
//! | --- | --- |
//! | `exposure_us` | `V4L2_CID_EXPOSURE_AUTO` (menu: 1 manual for a number, where the device has the control; 0 auto, else 3 aperture priority, UVC's auto, for `"auto"`, which needs it), then `V4L2_CID_EXPOSURE_ABSOLUTE` in units of 100 µs (sensor drivers whose only exposure is `V4L2_CID_EXPOSURE`, in lines of unknown length, are not supported) |
//! | `gain` | `V4L2_CID_AUTOGAIN` (off for a number, where the device has it; on for `"auto"`, which needs it), then `V4L2_CID_GAIN` in the driver's unit |
//! | `white_balance` | `V4L2_CID_AUTO_WHITE_BALANCE` |
//! | `frame_rate_hz` | `VIDIOC_S_PARM`'s `timeperframe` (the driver picks its nearest interval), where `V4L2_CAP_TIMEPERFRAME` says it has one |
//! | `trigger` | V4L2 has no standard trigger control: `"off"` (free running) is what every V4L2 camera does; a line is not supported |
//!
//! Each control is queried first: a control the device lacks (`EINVAL`) or has disabled is not
//! supported, a read-only one is refused, a number outside its range is not written, and a number
//! between its steps is rounded to the nearest (a warning). After writing, every control is read
//! back; a device that holds another value is reported as such.

use super::{compare, trim, CameraControl, ControlReport, Outcome, Setting, Trigger};

/// `V4L2_CID_BASE`: the user class.
pub const CID_BASE: u32 = 0x0098_0900;
pub const CID_AUTO_WHITE_BALANCE: u32 = CID_BASE + 12;
pub const CID_AUTOGAIN: u32 = CID_BASE + 18;
pub const CID_GAIN: u32 = CID_BASE + 19;
/// `V4L2_CID_CAMERA_CLASS_BASE`.
pub const CID_CAMERA_CLASS_BASE: u32 = 0x009A_0900;
pub const CID_EXPOSURE_AUTO: u32 = CID_CAMERA_CLASS_BASE + 1;
pub const CID_EXPOSURE_ABSOLUTE: u32 = CID_CAMERA_CLASS_BASE + 2;

/// `enum v4l2_exposure_auto_type`.
pub const EXPOSURE_AUTO: i32 = 0;
pub const EXPOSURE_MANUAL: i32 = 1;
pub const EXPOSURE_APERTURE_PRIORITY: i32 = 3;

/// `V4L2_CTRL_FLAG_*`.
pub const FLAG_DISABLED: u32 = 0x0001;
pub const FLAG_GRABBED: u32 = 0x0002;
pub const FLAG_READ_ONLY: u32 = 0x0004;
pub const FLAG_INACTIVE: u32 = 0x0010;
pub const FLAG_WRITE_ONLY: u32 = 0x0040;

/// `V4L2_CAP_TIMEPERFRAME` of `v4l2_captureparm.capability`.
pub const CAP_TIMEPERFRAME: u32 = 0x1000;

/// `V4L2_CTRL_TYPE_*` this module writes.
pub const TYPE_INTEGER: u32 = 1;
pub const TYPE_BOOLEAN: u32 = 2;
pub const TYPE_MENU: u32 = 3;

/// errno values the control ioctls answer with.
pub const EACCES: i32 = 13;
pub const EBUSY: i32 = 16;
pub const EINVAL: i32 = 22;
pub const ERANGE: i32 = 34;

/// `struct v4l2_queryctrl`'s fields.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct QueryCtrl {
    pub id: u32,
    /// `V4L2_CTRL_TYPE_*`.
    pub kind: u32,
    pub name: String,
    pub minimum: i32,
    pub maximum: i32,
    pub step: i32,
    pub default_value: i32,
    pub flags: u32,
}

/// `struct v4l2_captureparm`'s fields this needs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CaptureParm {
    pub capability: u32,
    /// `timeperframe`: seconds per frame as numerator / denominator.
    pub numerator: u32,
    pub denominator: u32,
}

/// The control ioctls of one open V4L2 device; errors are errno values.
pub trait V4l2ControlIo {
    fn query_ctrl(&mut self, id: u32) -> Result<QueryCtrl, i32>;
    fn g_ctrl(&mut self, id: u32) -> Result<i32, i32>;
    /// `VIDIOC_S_CTRL`; the value the driver left in the structure.
    fn s_ctrl(&mut self, id: u32, value: i32) -> Result<i32, i32>;
    fn g_parm(&mut self) -> Result<CaptureParm, i32>;
    /// `VIDIOC_S_PARM` with `timeperframe = numerator / denominator`; the parameters the driver
    /// settled on.
    fn s_parm(&mut self, numerator: u32, denominator: u32) -> Result<CaptureParm, i32>;
}

/// An errno as a few words.
pub fn errno_text(e: i32) -> String {
    match e {
        EACCES => "EACCES (read-only or write-only control)".into(),
        EBUSY => "EBUSY (grabbed: the device is streaming or another program holds it)".into(),
        EINVAL => "EINVAL (no such control or value)".into(),
        ERANGE => "ERANGE (value out of range)".into(),
        e => format!("{} (errno {e})", std::io::Error::from_raw_os_error(e)),
    }
}

/// Applies every key of `control` to the device and reads each back (see the module doc).
pub fn apply(io: &mut dyn V4l2ControlIo, control: &CameraControl, report: &mut ControlReport) {
    if let Some(exposure) = control.exposure_us {
        report.push("exposure_us", exposure_outcome(io, exposure));
    }
    if let Some(gain) = control.gain {
        report.push("gain", gain_outcome(io, gain));
    }
    if let Some(auto) = control.white_balance_auto {
        let outcome = match query(io, CID_AUTO_WHITE_BALANCE, "V4L2_CID_AUTO_WHITE_BALANCE") {
            Ok(q) => set_exact(io, &q, i32::from(auto), if auto { "auto" } else { "off" }),
            Err(o) => o,
        };
        report.push("white_balance", outcome);
    }
    if let Some(hz) = control.frame_rate_hz {
        report.push("frame_rate_hz", frame_rate_outcome(io, hz));
    }
    match &control.trigger {
        None => {}
        Some(Trigger::Off) => report.push(
            "trigger",
            Outcome::Set {
                got: "off (V4L2 cameras run free)".into(),
            },
        ),
        Some(Trigger::Line(line)) => report.push(
            "trigger",
            Outcome::NotSupported {
                why: format!("V4L2 has no standard trigger control (asked \"{line}\"); use a USB3 Vision camera"),
            },
        ),
    }
}

/// The control's description, or the outcome that ends the key: missing, disabled, read-only.
fn query(io: &mut dyn V4l2ControlIo, id: u32, name: &str) -> Result<QueryCtrl, Outcome> {
    let q = io.query_ctrl(id).map_err(|e| {
        if e == EINVAL {
            Outcome::NotSupported {
                why: format!("the device has no {name}"),
            }
        } else {
            Outcome::Refused {
                why: format!("VIDIOC_QUERYCTRL {name}: {}", errno_text(e)),
            }
        }
    })?;
    if q.flags & FLAG_DISABLED != 0 {
        return Err(Outcome::NotSupported {
            why: format!("{name} is disabled on this device"),
        });
    }
    if q.flags & FLAG_READ_ONLY != 0 {
        return Err(Outcome::Refused {
            why: format!("{name} is read-only on this device"),
        });
    }
    if q.flags & FLAG_WRITE_ONLY != 0 {
        return Err(Outcome::NotSupported {
            why: format!("{name} is write-only: its value cannot be checked"),
        });
    }
    Ok(q)
}

/// Writes `value` to a menu or boolean control and checks it reads back exactly.
fn set_exact(io: &mut dyn V4l2ControlIo, q: &QueryCtrl, value: i32, words: &str) -> Outcome {
    if value < q.minimum || value > q.maximum {
        return Outcome::Refused {
            why: format!("{} offers {}..={}, not {value} ({words})", q.name, q.minimum, q.maximum),
        };
    }
    if let Err(e) = io.s_ctrl(q.id, value) {
        return Outcome::Refused {
            why: format!("VIDIOC_S_CTRL {} = {value}: {}", q.name, errno_text(e)),
        };
    }
    match io.g_ctrl(q.id) {
        Ok(v) if v == value => Outcome::Set { got: words.to_string() },
        Ok(v) => Outcome::Changed {
            asked: format!("{words} ({value})"),
            got: v.to_string(),
        },
        Err(e) => Outcome::Refused {
            why: format!("VIDIOC_G_CTRL {}: {}", q.name, errno_text(e)),
        },
    }
}

/// Writes a number (in the control's unit × `scale` = the key's unit) to an integer control:
/// refused outside the range, rounded to the step, read back.
fn set_number(io: &mut dyn V4l2ControlIo, q: &QueryCtrl, asked: f64, scale: f64, unit: &'static str) -> Outcome {
    let (min, max) = (f64::from(q.minimum) * scale, f64::from(q.maximum) * scale);
    if asked < min || asked > max {
        return Outcome::OutOfRange { asked, min, max, unit };
    }
    let step = i64::from(q.step.max(1));
    let raw = (asked / scale).round() as i64;
    let raw = i64::from(q.minimum) + ((raw - i64::from(q.minimum)) as f64 / step as f64).round() as i64 * step;
    let raw = raw.clamp(i64::from(q.minimum), i64::from(q.maximum)) as i32;
    if let Err(e) = io.s_ctrl(q.id, raw) {
        return Outcome::Refused {
            why: format!("VIDIOC_S_CTRL {} = {raw}: {}", q.name, errno_text(e)),
        };
    }
    match io.g_ctrl(q.id) {
        Ok(v) => compare(asked, f64::from(v) * scale, step as f64 * scale, unit),
        Err(e) => Outcome::Refused {
            why: format!("VIDIOC_G_CTRL {}: {}", q.name, errno_text(e)),
        },
    }
}

fn exposure_outcome(io: &mut dyn V4l2ControlIo, exposure: Setting) -> Outcome {
    let mode = io.query_ctrl(CID_EXPOSURE_AUTO).ok();
    match exposure {
        Setting::Auto => {
            let mode = match query(io, CID_EXPOSURE_AUTO, "V4L2_CID_EXPOSURE_AUTO") {
                Ok(q) => q,
                Err(o) => return o,
            };
            // UVC cameras offer only manual (1) and aperture priority (3), their "auto".
            let value = if mode.minimum <= EXPOSURE_AUTO {
                EXPOSURE_AUTO
            } else {
                EXPOSURE_APERTURE_PRIORITY
            };
            set_exact(io, &mode, value, "auto")
        }
        Setting::Fixed(us) => {
            // A device without an automatic exposure has nothing to switch off.
            if mode.is_some() {
                let manual = match query(io, CID_EXPOSURE_AUTO, "V4L2_CID_EXPOSURE_AUTO") {
                    Ok(q) => set_exact(io, &q, EXPOSURE_MANUAL, "manual"),
                    Err(o) => o,
                };
                if manual.is_error() {
                    return manual;
                }
            }
            match query(io, CID_EXPOSURE_ABSOLUTE, "V4L2_CID_EXPOSURE_ABSOLUTE") {
                Ok(q) => set_number(io, &q, us, 100.0, " µs"),
                Err(o) => o,
            }
        }
    }
}

fn gain_outcome(io: &mut dyn V4l2ControlIo, gain: Setting) -> Outcome {
    let auto = io.query_ctrl(CID_AUTOGAIN).ok();
    match gain {
        Setting::Auto => match query(io, CID_AUTOGAIN, "V4L2_CID_AUTOGAIN") {
            Ok(q) => set_exact(io, &q, 1, "auto"),
            Err(o) => o,
        },
        Setting::Fixed(g) => {
            if auto.is_some() {
                let off = match query(io, CID_AUTOGAIN, "V4L2_CID_AUTOGAIN") {
                    Ok(q) => set_exact(io, &q, 0, "off"),
                    Err(o) => o,
                };
                if off.is_error() {
                    return off;
                }
            }
            match query(io, CID_GAIN, "V4L2_CID_GAIN") {
                Ok(q) => set_number(io, &q, g, 1.0, ""),
                Err(o) => o,
            }
        }
    }
}

fn frame_rate_outcome(io: &mut dyn V4l2ControlIo, hz: f64) -> Outcome {
    let parm = match io.g_parm() {
        Ok(p) => p,
        Err(e) => {
            return Outcome::NotSupported {
                why: format!("VIDIOC_G_PARM: {}", errno_text(e)),
            }
        }
    };
    if parm.capability & CAP_TIMEPERFRAME == 0 {
        return Outcome::NotSupported {
            why: "the device does not set its frame interval (no V4L2_CAP_TIMEPERFRAME)".into(),
        };
    }
    // Milliseconds of a frame as a fraction: 1000 / (hz × 1000).
    let denominator = (hz * 1000.0).round().clamp(1.0, f64::from(u32::MAX)) as u32;
    let set = match io.s_parm(1000, denominator) {
        Ok(p) => p,
        Err(e) => {
            return Outcome::Refused {
                why: format!("VIDIOC_S_PARM 1000/{denominator} s: {}", errno_text(e)),
            }
        }
    };
    // Read back as a reader of the device would see it, not as S_PARM echoed it.
    let now = io.g_parm().unwrap_or(set);
    if now.numerator == 0 || now.denominator == 0 {
        return Outcome::Changed {
            asked: format!("{} Hz", trim(hz)),
            got: format!("a frame interval of {}/{} s", now.numerator, now.denominator),
        };
    }
    let got = f64::from(now.denominator) / f64::from(now.numerator);
    // Drivers offer a list of intervals: the nearest of them is what "rounded" means here.
    compare(hz, got, 0.0, " Hz")
}
