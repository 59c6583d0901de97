//! USB3 Vision camera control: the rig's `[control]` as GenICam features over GenCP.
//!
//! In: a [`CameraControl`] and a camera's [`GenCp`] client. Out: a [`ControlReport`]
//! ([`apply`]), after the camera's GenICam file was found through its bootstrap registers
//! ([`Bootstrap::read`], [`load_node_map`]).
//!
//! Bootstrap (USB3 Vision 1.0, the technology-agnostic bootstrap register map, ABRM, at 0):
//! `Maximum Device Response Time` u32 ms at 0x1CC, `Manifest Table Address` u64 at 0x1D0,
//! `SBRM Address` u64 at 0x1D8; in the SBRM, `Maximum Command Transfer Length` u32 at +0x14 and
//! `Maximum Acknowledge Transfer Length` u32 at +0x18. The manifest table is an entry count
//! (u64) followed by 64-byte entries: file version u32, schema u32 (bits 10–15: 0 an XML file,
//! 1 a ZIP archive), address u64, size u64. The first entry's file is read (as aravis does).
//!
//! Features (SFNC names), per key, written in this order and each read back after all writes (a
//! later write, such as the frame rate, may move an earlier value):
//!
//! | key | features |
//! | --- | --- |
//! | `trigger` | `TriggerSelector` = `FrameStart` (where it exists), `TriggerMode` = `Off`/`On`, `TriggerSource` = the line |
//! | `exposure_us` | `ExposureMode` = `Timed`, `ExposureAuto` = `Off` (each if the camera has it) and `ExposureTime` (µs; `ExposureTimeAbs` on pre-SFNC-2 cameras), or `ExposureAuto` = `Continuous` |
//! | `gain` | `GainAuto` = `Off` (if it exists) and `Gain` (dB; `GainAbs`), or `GainAuto` = `Continuous` |
//! | `white_balance` | `BalanceWhiteAuto` = `Off` / `Continuous` |
//! | `frame_rate_hz` | `AcquisitionFrameRateEnable` = true (if it exists; `AcquisitionFrameRateEnabled` on some) and `AcquisitionFrameRate` (`AcquisitionFrameRateAbs`) |
//!
//! A number outside the feature's `Min`/`Max` is not written; an integer feature's value is
//! rounded to its `Inc`.

use super::gencp::{ControlEndpoint, GenCp};
use super::genicam::{self, NodeError, NodeErrorKind, NodeMap, Port};
use super::{compare, CameraControl, ControlReport, Outcome, Setting, Trigger};

pub const ABRM_MAX_RESPONSE_MS: u64 = 0x1CC;
pub const ABRM_MANIFEST_TABLE: u64 = 0x1D0;
pub const ABRM_SBRM_ADDRESS: u64 = 0x1D8;
pub const SBRM_MAX_COMMAND: u64 = 0x14;
pub const SBRM_MAX_ACK: u64 = 0x18;
/// Bytes of a manifest entry.
pub const MANIFEST_ENTRY: usize = 64;
/// Largest GenICam file read (bytes).
pub const MAX_FILE: u64 = 64 << 20;

impl<E: ControlEndpoint> Port for GenCp<E> {
    fn read(&mut self, address: u64, len: usize) -> Result<Vec<u8>, String> {
        self.read_mem(address, len).map_err(|e| e.to_string())
    }

    fn write(&mut self, address: u64, data: &[u8]) -> Result<(), String> {
        self.write_mem(address, data).map_err(|e| e.to_string())
    }
}

fn u32_le(b: &[u8]) -> u32 {
    u32::from_le_bytes([b[0], b[1], b[2], b[3]])
}

fn u64_le(b: &[u8]) -> u64 {
    let mut a = [0; 8];
    a.copy_from_slice(&b[..8]);
    u64::from_le_bytes(a)
}

/// What the bootstrap registers say about the camera's control channel and GenICam file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Bootstrap {
    pub max_response_ms: u32,
    pub max_command: u32,
    pub max_ack: u32,
    /// The first manifest entry: where the GenICam file is, how long, and whether zipped.
    pub file_address: u64,
    pub file_size: u64,
    pub zipped: bool,
}

impl Bootstrap {
    /// Reads the ABRM, the SBRM and the manifest table, and sets the client's transfer lengths
    /// and timeout from them.
    pub fn read<E: ControlEndpoint>(cp: &mut GenCp<E>) -> Result<Bootstrap, String> {
        let abrm = cp
            .read_mem(ABRM_MAX_RESPONSE_MS, 20)
            .map_err(|e| format!("bootstrap registers: {e}"))?;
        let max_response_ms = u32_le(&abrm[0..4]);
        let manifest = u64_le(&abrm[4..12]);
        let sbrm = u64_le(&abrm[12..20]);
        let lengths = cp
            .read_mem(sbrm.wrapping_add(SBRM_MAX_COMMAND), 8)
            .map_err(|e| format!("SBRM: {e}"))?;
        let (max_command, max_ack) = (u32_le(&lengths[0..4]), u32_le(&lengths[4..8]));
        cp.set_max_lengths(max_command as usize, max_ack as usize);
        if max_response_ms > 0 {
            // The device's own promise, with room for the host's scheduling.
            cp.set_timeout(std::time::Duration::from_millis(
                u64::from(max_response_ms.min(10_000)) + 200,
            ));
        }
        let table = cp
            .read_mem(manifest, 8 + MANIFEST_ENTRY)
            .map_err(|e| format!("manifest table: {e}"))?;
        if u64_le(&table[0..8]) == 0 {
            return Err("the camera's manifest table lists no GenICam file".into());
        }
        let entry = &table[8..];
        let schema = u32_le(&entry[4..8]);
        let file_size = u64_le(&entry[16..24]);
        if file_size == 0 || file_size > MAX_FILE {
            return Err(format!(
                "the manifest's GenICam file has {file_size} bytes (at most {MAX_FILE} are read)"
            ));
        }
        let kind = (schema >> 10) & 0x3F;
        if kind > 1 {
            return Err(format!(
                "the manifest's GenICam file is of type {kind} (0 XML and 1 ZIP are read)"
            ));
        }
        Ok(Bootstrap {
            max_response_ms,
            max_command,
            max_ack,
            file_address: u64_le(&entry[8..16]),
            file_size,
            zipped: kind == 1,
        })
    }
}

/// The camera's node map, read from its manifest.
pub fn load_node_map<E: ControlEndpoint>(cp: &mut GenCp<E>) -> Result<NodeMap, String> {
    let boot = Bootstrap::read(cp)?;
    let bytes = cp
        .read_mem(boot.file_address, boot.file_size as usize)
        .map_err(|e| format!("GenICam file: {e}"))?;
    genicam::load(&bytes, boot.zipped)
}

/// What one key's writes left to check once every key is written.
enum Check {
    /// A number: the feature, the value asked, its increment (0 for floats), the unit.
    Number(&'static str, f64, f64, &'static str),
    /// An enumeration's entry (or a boolean's `true`/`false` as `"1"`/`"0"`).
    Entry(&'static str, String),
}

/// Applies every key of `control` through the camera's node map and reads each back (see the
/// module doc).
pub fn apply(map: &NodeMap, port: &mut dyn Port, control: &CameraControl, report: &mut ControlReport) {
    let mut written: Vec<(&'static str, Result<Vec<Check>, Outcome>)> = Vec::new();
    if let Some(trigger) = &control.trigger {
        written.push(("trigger", write_trigger(map, port, trigger)));
    }
    if let Some(exposure) = control.exposure_us {
        let r = write_setting(
            map,
            port,
            exposure,
            "ExposureAuto",
            &["ExposureTime", "ExposureTimeAbs"],
            " µs",
        );
        written.push(("exposure_us", r));
    }
    if let Some(gain) = control.gain {
        written.push((
            "gain",
            write_setting(map, port, gain, "GainAuto", &["Gain", "GainAbs"], " dB"),
        ));
    }
    if let Some(auto) = control.white_balance_auto {
        let entry = if auto { "Continuous" } else { "Off" };
        written.push((
            "white_balance",
            write_entry(map, port, "BalanceWhiteAuto", entry).map(|c| vec![c]),
        ));
    }
    if let Some(hz) = control.frame_rate_hz {
        written.push(("frame_rate_hz", write_frame_rate(map, port, hz)));
    }
    for (key, result) in written {
        let outcome = match result {
            Ok(checks) => read_back(map, port, &checks),
            Err(o) => o,
        };
        report.push(key, outcome);
    }
}

/// The outcome of a node error: missing and unsupported nodes are not supported, the rest
/// refused.
fn outcome(e: NodeError) -> Outcome {
    match e.kind {
        NodeErrorKind::Missing | NodeErrorKind::Unsupported(_) => Outcome::NotSupported { why: e.to_string() },
        _ => Outcome::Refused { why: e.to_string() },
    }
}

fn first_present(map: &NodeMap, port: &mut dyn Port, names: &[&'static str]) -> Result<&'static str, Outcome> {
    names
        .iter()
        .copied()
        .find(|n| map.has(port, n))
        .ok_or_else(|| Outcome::NotSupported {
            why: format!("the camera's GenICam file has no feature {}", names.join(" or ")),
        })
}

fn write_entry(map: &NodeMap, port: &mut dyn Port, feature: &'static str, entry: &str) -> Result<Check, Outcome> {
    map.set_entry(port, feature, entry).map_err(outcome)?;
    Ok(Check::Entry(feature, entry.to_string()))
}

fn write_number(
    map: &NodeMap,
    port: &mut dyn Port,
    feature: &'static str,
    asked: f64,
    unit: &'static str,
) -> Result<Check, Outcome> {
    let (min, max, inc) = map.range(port, feature);
    let (lo, hi) = (min.unwrap_or(f64::NEG_INFINITY), max.unwrap_or(f64::INFINITY));
    if asked < lo || asked > hi {
        return Err(Outcome::OutOfRange {
            asked,
            min: lo,
            max: hi,
            unit,
        });
    }
    let integer = matches!(
        map.kind(feature),
        Some("Integer" | "IntReg" | "MaskedIntReg" | "IntConverter")
    );
    let inc = inc.filter(|i| *i > 0.0).unwrap_or(if integer { 1.0 } else { 0.0 });
    // Rounded to the feature's grid, which starts at its minimum.
    let value = if inc > 0.0 {
        let base = if lo.is_finite() { lo } else { 0.0 };
        base + ((asked - base) / inc).round() * inc
    } else {
        asked
    };
    map.set(port, feature, value.clamp(lo, hi)).map_err(outcome)?;
    Ok(Check::Number(feature, asked, inc, unit))
}

fn write_setting(
    map: &NodeMap,
    port: &mut dyn Port,
    setting: Setting,
    auto: &'static str,
    values: &[&'static str],
    unit: &'static str,
) -> Result<Vec<Check>, Outcome> {
    match setting {
        Setting::Auto => {
            if !map.has(port, auto) {
                return Err(Outcome::NotSupported {
                    why: format!("the camera's GenICam file has no feature '{auto}'"),
                });
            }
            Ok(vec![write_entry(map, port, auto, "Continuous")?])
        }
        Setting::Fixed(v) => {
            let mut checks = Vec::new();
            // A time, not the trigger pulse's width: the exposure the rig file states.
            if auto == "ExposureAuto" && map.has(port, "ExposureMode") {
                checks.push(write_entry(map, port, "ExposureMode", "Timed")?);
            }
            if map.has(port, auto) {
                checks.push(write_entry(map, port, auto, "Off")?);
            }
            let feature = first_present(map, port, values)?;
            checks.push(write_number(map, port, feature, v, unit)?);
            Ok(checks)
        }
    }
}

fn write_trigger(map: &NodeMap, port: &mut dyn Port, trigger: &Trigger) -> Result<Vec<Check>, Outcome> {
    let mut checks = Vec::new();
    if map.has(port, "TriggerSelector") {
        checks.push(write_entry(map, port, "TriggerSelector", "FrameStart")?);
    }
    if !map.has(port, "TriggerMode") {
        return Err(Outcome::NotSupported {
            why: "the camera's GenICam file has no feature 'TriggerMode'".into(),
        });
    }
    match trigger {
        Trigger::Off => checks.push(write_entry(map, port, "TriggerMode", "Off")?),
        Trigger::Line(line) => {
            // The source first: some cameras refuse TriggerMode = On without one.
            let source = first_present(map, port, &["TriggerSource"])?;
            checks.push(write_entry(map, port, source, line)?);
            checks.push(write_entry(map, port, "TriggerMode", "On")?);
        }
    }
    Ok(checks)
}

fn write_frame_rate(map: &NodeMap, port: &mut dyn Port, hz: f64) -> Result<Vec<Check>, Outcome> {
    let mut checks = Vec::new();
    for enable in ["AcquisitionFrameRateEnable", "AcquisitionFrameRateEnabled"] {
        if map.has(port, enable) {
            map.set(port, enable, 1.0).map_err(outcome)?;
            checks.push(Check::Entry(enable, "1".into()));
            break;
        }
    }
    let feature = first_present(map, port, &["AcquisitionFrameRate", "AcquisitionFrameRateAbs"])?;
    checks.push(write_number(map, port, feature, hz, " Hz")?);
    Ok(checks)
}

/// Reads back every feature a key wrote: the first that differs is the key's outcome.
fn read_back(map: &NodeMap, port: &mut dyn Port, checks: &[Check]) -> Outcome {
    let mut last = Outcome::Set { got: String::new() };
    for c in checks {
        let o = match c {
            Check::Number(feature, asked, inc, unit) => match map.get(port, feature) {
                Ok(got) => compare(*asked, got, *inc, unit),
                Err(e) => outcome(e),
            },
            Check::Entry(feature, want) => {
                let got = if map.kind(feature) == Some("Boolean") {
                    map.get(port, feature)
                        .map(|v| if v != 0.0 { "1".to_string() } else { "0".to_string() })
                } else {
                    map.get_entry(port, feature)
                };
                match got {
                    Ok(g) if g == *want => Outcome::Set {
                        got: format!("{feature} = {g}"),
                    },
                    Ok(g) => Outcome::Changed {
                        asked: format!("{feature} = {want}"),
                        got: format!("{feature} = {g}"),
                    },
                    Err(e) => outcome(e),
                }
            }
        };
        if o.is_error() {
            return o;
        }
        // The key's own value (the last check) is what the line shows.
        last = match (o, &last) {
            (Outcome::Set { got }, Outcome::Rounded { .. }) if got.contains(" = ") => last.clone(),
            (o, _) => o,
        };
    }
    last
}
