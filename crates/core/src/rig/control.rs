//! Camera control asked of a live sensor's camera: the optional `[control]` tables of the rig
//! file.
//!
//! In: the rig-wide `[control]` table (every sensor's default) and a sensor's own
//! `[sensors.control]` table, each key optional. Out: a [`CameraControl`] per sensor, the
//! sensor's keys over the rig's, or one line naming the sensor and the key. No table and no key
//! means "leave the camera as it is": the drivers then touch no control, as before these tables
//! existed, so older rig files keep their meaning.
//!
//! What a key means on the wire (which register, which ioctl) is the drivers' business
//! (`omnitrack-io`, `capture::control`); this file only says what a rig asks for.

use std::fmt::Write as _;
use toml::{Table, Value};

/// The keys of a `[control]` table.
pub const CONTROL_KEYS: [&str; 5] = ["exposure_us", "gain", "frame_rate_hz", "white_balance", "trigger"];

/// Longest exposure accepted (µs): 10 s, beyond any tracking use and any camera's exposure
/// register we know, so a typo (`5e9`) is refused here rather than by the camera.
pub const MAX_EXPOSURE_US: f64 = 10_000_000.0;

/// Highest frame rate accepted (Hz).
pub const MAX_FRAME_RATE_HZ: f64 = 10_000.0;

/// A value the camera may choose itself (`"auto"`) or a fixed one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Setting {
    /// The camera's automatic control decides.
    Auto,
    /// A fixed value, in the key's unit.
    Fixed(f64),
}

/// How frames are started.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Trigger {
    /// Free running at the frame rate: `trigger = "off"`.
    Off,
    /// A frame starts at an edge on this hardware input (the USB3 Vision `TriggerSource` entry,
    /// e.g. `"Line0"`), so that sensors wired to one line expose together.
    Line(String),
}

/// What a rig asks of one sensor's camera; `None` leaves that setting as the camera has it.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct CameraControl {
    /// Exposure time in microseconds, or automatic exposure.
    pub exposure_us: Option<Setting>,
    /// Analogue gain in the device's own unit (dB on USB3 Vision cameras, as SFNC's `Gain`; the
    /// driver's raw value on V4L2, whose `V4L2_CID_GAIN` has no unit), or automatic gain.
    pub gain: Option<Setting>,
    /// Frames per second (free running).
    pub frame_rate_hz: Option<f64>,
    /// `Some(false)`: automatic white balance off (the colours, and so the hues the tracker
    /// matches, stay put); `Some(true)`: on.
    pub white_balance_auto: Option<bool>,
    pub trigger: Option<Trigger>,
}

impl CameraControl {
    /// Whether nothing is asked: the camera is left as it is.
    pub fn is_empty(&self) -> bool {
        *self == CameraControl::default()
    }

    /// `self`'s keys, each replaced by `over`'s where `over` has it.
    pub fn overridden_by(&self, over: &CameraControl) -> CameraControl {
        CameraControl {
            exposure_us: over.exposure_us.or(self.exposure_us),
            gain: over.gain.or(self.gain),
            frame_rate_hz: over.frame_rate_hz.or(self.frame_rate_hz),
            white_balance_auto: over.white_balance_auto.or(self.white_balance_auto),
            trigger: over.trigger.clone().or_else(|| self.trigger.clone()),
        }
    }

    /// Keys that contradict each other (checked on a sensor's merged control, as one key may
    /// come from the rig's table and the other from the sensor's): `(key, message)`.
    pub fn contradiction(&self) -> Option<(String, String)> {
        if matches!(self.trigger, Some(Trigger::Line(_))) && self.frame_rate_hz.is_some() {
            // A triggered camera takes a frame per pulse: a frame rate as well would be two
            // masters, and SFNC cameras ignore or refuse one of them depending on the model.
            return Some((
                "control.frame_rate_hz".into(),
                "cannot be set with a hardware trigger (the trigger's pulses set the rate)".into(),
            ));
        }
        None
    }

    /// The keys whose values differ between `self` and `other`, in [`CONTROL_KEYS`] order.
    pub fn differing_keys(&self, other: &CameraControl) -> Vec<&'static str> {
        let same = [
            self.exposure_us == other.exposure_us,
            self.gain == other.gain,
            self.frame_rate_hz == other.frame_rate_hz,
            self.white_balance_auto == other.white_balance_auto,
            self.trigger == other.trigger,
        ];
        CONTROL_KEYS
            .iter()
            .zip(same)
            .filter(|(_, same)| !same)
            .map(|(k, _)| *k)
            .collect()
    }

    /// The table's lines (`key = value`), each key of `self` that `base` does not have with the
    /// same value, so that a sensor's table written after the rig's reads back to the same
    /// merged control.
    pub fn toml_lines(&self, base: &CameraControl) -> String {
        let mut out = String::new();
        let setting = |s: Setting| match s {
            Setting::Auto => "\"auto\"".to_string(),
            Setting::Fixed(v) => format!("{v:?}"),
        };
        if self.exposure_us != base.exposure_us {
            if let Some(s) = self.exposure_us {
                let _ = writeln!(out, "exposure_us = {}", setting(s));
            }
        }
        if self.gain != base.gain {
            if let Some(s) = self.gain {
                let _ = writeln!(out, "gain = {}", setting(s));
            }
        }
        if self.frame_rate_hz != base.frame_rate_hz {
            if let Some(f) = self.frame_rate_hz {
                let _ = writeln!(out, "frame_rate_hz = {f:?}");
            }
        }
        if self.white_balance_auto != base.white_balance_auto {
            if let Some(a) = self.white_balance_auto {
                let _ = writeln!(out, "white_balance = \"{}\"", if a { "auto" } else { "off" });
            }
        }
        if self.trigger != base.trigger {
            match &self.trigger {
                Some(Trigger::Off) => out.push_str("trigger = \"off\"\n"),
                Some(Trigger::Line(l)) => {
                    let _ = writeln!(out, "trigger = {}", Value::String(l.clone()));
                }
                None => {}
            }
        }
        out
    }
}

/// Reads one `[control]` table; errors are `(key, message)`.
pub fn parse_control(value: &Value) -> Result<CameraControl, (String, String)> {
    let Value::Table(t) = value else {
        return Err((
            "control".into(),
            "must be a table ([control] or [sensors.control])".into(),
        ));
    };
    if let Some(key) = t.keys().find(|k| !CONTROL_KEYS.contains(&k.as_str())) {
        return Err((
            format!("control.{key}"),
            format!("unknown key (allowed: {})", CONTROL_KEYS.join(", ")),
        ));
    }
    let fail = |key: &str, m: String| (format!("control.{key}"), m);
    let number = |key: &str, v: &Value| -> Result<f64, (String, String)> {
        match v {
            Value::Integer(i) => Ok(*i as f64),
            Value::Float(f) if f.is_finite() => Ok(*f),
            Value::Float(f) => Err(fail(key, format!("non-finite number {f}"))),
            other => Err(fail(key, format!("expected a number, found {}", other.type_str()))),
        }
    };
    let setting = |key: &str, what: &str, check: &dyn Fn(f64) -> Result<(), String>| match t.get(key) {
        None => Ok(None),
        Some(Value::String(s)) if s == "auto" => Ok(Some(Setting::Auto)),
        Some(Value::String(s)) => Err(fail(key, format!("must be {what} or \"auto\", found \"{s}\""))),
        Some(v) => {
            let x = number(key, v)?;
            check(x).map_err(|m| fail(key, m))?;
            Ok(Some(Setting::Fixed(x)))
        }
    };
    let exposure_us = setting("exposure_us", "a time in microseconds", &|x| {
        if x > 0.0 && x <= MAX_EXPOSURE_US {
            Ok(())
        } else {
            Err(format!("must lie in (0, {MAX_EXPOSURE_US}] µs, found {x}"))
        }
    })?;
    let gain = setting("gain", "a number in the device's unit", &|x| {
        if (-1000.0..=1000.0).contains(&x) {
            Ok(())
        } else {
            Err(format!("must lie in [-1000, 1000], found {x}"))
        }
    })?;
    let frame_rate_hz = match t.get("frame_rate_hz") {
        None => None,
        Some(v) => {
            let f = number("frame_rate_hz", v)?;
            if !(f > 0.0 && f <= MAX_FRAME_RATE_HZ) {
                return Err(fail(
                    "frame_rate_hz",
                    format!("must lie in (0, {MAX_FRAME_RATE_HZ}] Hz, found {f}"),
                ));
            }
            Some(f)
        }
    };
    let white_balance_auto = match t.get("white_balance") {
        None => None,
        Some(Value::String(s)) if s == "off" => Some(false),
        Some(Value::String(s)) if s == "auto" => Some(true),
        Some(_) => return Err(fail("white_balance", "must be \"off\" or \"auto\"".into())),
    };
    let trigger = match t.get("trigger") {
        None => None,
        Some(Value::String(s)) if s == "off" => Some(Trigger::Off),
        Some(Value::String(s)) if is_line_name(s) => Some(Trigger::Line(s.clone())),
        Some(_) => {
            return Err(fail(
                "trigger",
                "must be \"off\" or the trigger input's name, e.g. \"Line0\" (letters, digits, '_')".into(),
            ))
        }
    };
    Ok(CameraControl {
        exposure_us,
        gain,
        frame_rate_hz,
        white_balance_auto,
        trigger,
    })
}

/// A GenICam enumeration entry's name: what a `TriggerSource` entry can be called.
fn is_line_name(s: &str) -> bool {
    !s.is_empty() && s.len() <= 64 && s.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_')
}

/// The rig-wide `[control]` of a rig file's top-level table (empty when absent).
pub fn rig_control(table: &Table) -> Result<CameraControl, (String, String)> {
    match table.get("control") {
        None => Ok(CameraControl::default()),
        Some(v) => parse_control(v),
    }
}
