//! USB3 Vision camera control end to end against the fake camera: bootstrap, manifest, zipped
//! GenICam file, the node kinds of `camera.xml`, and every way the camera can differ from the
//! rig file as one line.

use super::fake_u3v::*;
use omnitrack_io::capture::control::gencp::GenCp;
use omnitrack_io::capture::control::genicam::{self, zip};
use omnitrack_io::capture::control::u3v::{apply, load_node_map, Bootstrap};
use omnitrack_io::capture::control::{CameraControl, ControlReport, Setting, Trigger};
use std::time::Duration;

fn control(cam: FakeCamera, c: &CameraControl) -> (Vec<String>, bool, FakeCamera) {
    let mut cp = GenCp::new(cam, Duration::from_millis(50));
    let map = load_node_map(&mut cp).unwrap();
    let mut report = ControlReport::new("usb 1e10:3300 bus 2 ports [1]", "sensor 4");
    apply(&map, &mut cp, c, &mut report);
    let lines = report
        .lines()
        .map(|l| l.replace("usb 1e10:3300 bus 2 ports [1]: sensor 4, ", ""))
        .collect();
    let errors = report.has_errors();
    let cam = std::mem::replace(cp.endpoint_mut(), FakeCamera::new(b"<x/>", false));
    (lines, errors, cam)
}

#[test]
fn the_manifest_file_is_found_plain_or_zipped() {
    for (cam, zipped) in [
        (FakeCamera::new(CAMERA_XML.as_bytes(), false), false),
        (FakeCamera::standard(), true),
        (
            FakeCamera::new(&zip("FakeCam.xml", CAMERA_XML.as_bytes(), 0), true),
            true,
        ),
    ] {
        let mut cp = GenCp::new(cam, Duration::from_millis(50));
        let boot = Bootstrap::read(&mut cp).unwrap();
        assert_eq!((boot.file_address, boot.zipped, boot.max_ack), (FILE, zipped, 256));
        let map = load_node_map(&mut cp).unwrap();
        assert_eq!(map.kind("ExposureTime"), Some("Float"));
        assert_eq!(map.kind("FrameRateEnableBit"), Some("MaskedIntReg"), "a StructEntry");
        assert_eq!(map.get(&mut cp, "ExposureTime").unwrap(), 10_000.0);
        assert_eq!(map.get(&mut cp, "AcquisitionFrameRate").unwrap(), 30.0);
        assert_eq!(map.get_entry(&mut cp, "ExposureAuto").unwrap(), "Continuous");
    }
    // A damaged archive is one line, not a panic.
    let mut z = zip("FakeCam.xml", CAMERA_XML.as_bytes(), 8);
    let mid = z.len() / 2;
    z[mid] ^= 0xFF;
    let mut cp = GenCp::new(FakeCamera::new(&z, true), Duration::from_millis(50));
    let e = load_node_map(&mut cp).err().unwrap();
    assert!(e.starts_with("zipped GenICam file: "), "{e}");
    assert_eq!(zip::crc32(b"123456789"), 0xCBF4_3926, "the IEEE check value");
    for bad in ["", "<RegisterDescription>", "<Other/>", "<a><b></a>"] {
        assert!(genicam::load(bad.as_bytes(), false).is_err(), "{bad}");
    }
}

#[test]
fn every_key_is_written_through_its_features_and_read_back() {
    let c = CameraControl {
        exposure_us: Some(Setting::Fixed(8000.0)),
        gain: Some(Setting::Fixed(6.5)),
        frame_rate_hz: Some(100.0),
        white_balance_auto: Some(false),
        trigger: Some(Trigger::Off),
    };
    let (lines, errors, cam) = control(FakeCamera::standard(), &c);
    assert!(!errors, "{lines:?}");
    assert_eq!(
        lines,
        vec![
            "control.trigger: set to TriggerMode = Off",
            "control.exposure_us: set to 8000 µs",
            "control.gain: set to 6.5 dB",
            "control.white_balance: set to BalanceWhiteAuto = Off",
            "control.frame_rate_hz: set to 100 Hz",
        ]
    );
    assert_eq!(cam.u32_at(EXPOSURE_AUTO), 0);
    assert_eq!(cam.f32_at(EXPOSURE), 8000.0);
    assert_eq!(cam.u32_at(GAIN_AUTO), 0);
    assert_eq!(cam.u32_at(GAIN_RAW), 65, "through the converter, TO × 10");
    assert_eq!(cam.u32_at(WHITE_AUTO), 0);
    assert_eq!(cam.u32_at(FLAGS) & 1, 1, "AcquisitionFrameRateEnable");
    assert_eq!(cam.f64_at(FRAME_RATE), 100.0);
    assert_eq!(cam.u32_at(TRIGGER_SELECTOR), 0, "FrameStart");
    assert_eq!(cam.u32_at(TRIGGER) & 1, 0);
}

#[test]
fn a_hardware_trigger_sets_source_and_mode_in_one_register() {
    let mut cam = FakeCamera::standard();
    cam.put(TRIGGER, &0xA00u32.to_le_bytes());
    let c = CameraControl {
        trigger: Some(Trigger::Line("Line1".into())),
        exposure_us: Some(Setting::Auto),
        ..CameraControl::default()
    };
    let (lines, errors, cam) = control(cam, &c);
    assert!(!errors, "{lines:?}");
    assert_eq!(lines[0], "control.trigger: set to TriggerMode = On");
    // Mode in bit 0, source in bits 4–7, and the register's other bits kept.
    assert_eq!(cam.u32_at(TRIGGER), 0xA00 | 0x10 | 1);
    assert_eq!(cam.u32_at(EXPOSURE_AUTO), 2);
    let c = CameraControl {
        trigger: Some(Trigger::Line("Line5".into())),
        ..CameraControl::default()
    };
    let (lines, errors, _) = control(FakeCamera::standard(), &c);
    assert!(errors);
    assert_eq!(
        lines,
        vec!["control.trigger: refused by the device: 'TriggerSource': has no entry 'Line5' (it has: Line0, Line1, Software)"]
    );
}

#[test]
fn out_of_range_clamped_and_refused_values_are_one_line_each() {
    let mut cam = FakeCamera::standard();
    // The white balance register is write protected on this camera.
    cam.protected.push(WHITE_AUTO..WHITE_AUTO + 4);
    let c = CameraControl {
        exposure_us: Some(Setting::Fixed(20_000.0)),
        gain: Some(Setting::Fixed(30.0)),
        frame_rate_hz: Some(60.0),
        white_balance_auto: Some(false),
        trigger: None,
    };
    let (lines, errors, cam) = control(cam, &c);
    assert!(errors);
    assert_eq!(
        lines,
        vec![
            "control.exposure_us: set to 20000 µs",
            "control.gain: 30 dB is outside the device's range [0, 24] dB; not set",
            "control.white_balance: refused by the device: 'BalanceWhiteAutoReg': register 0x20010: status 0x8004 (write protected)",
            // 20 ms of exposure leave at most 50 frames a second: the camera clamps.
            "control.frame_rate_hz: asked 60 Hz, the device reports 50 Hz",
        ]
    );
    assert_eq!(cam.u32_at(GAIN_RAW), 0, "nothing written out of range");
}

#[test]
fn features_the_file_lacks_or_this_reader_cannot_follow_are_named() {
    // A mono camera: no white balance; its gain register indexed by a selector.
    let xml = CAMERA_XML
        .replace(
            "<Enumeration Name=\"BalanceWhiteAuto\">",
            "<Enumeration Name=\"Unused\">",
        )
        .replace("<Enumeration Name=\"GainAuto\">", "<Command Name=\"GainAuto\">")
        .replace(
            "<pValue>GainAutoReg</pValue>\n    </Enumeration>",
            "<pValue>GainAutoReg</pValue>\n    </Command>",
        );
    let cam = FakeCamera::new(xml.as_bytes(), false);
    let c = CameraControl {
        gain: Some(Setting::Fixed(3.0)),
        white_balance_auto: Some(false),
        ..CameraControl::default()
    };
    let (lines, errors, _) = control(cam, &c);
    assert!(errors);
    assert_eq!(
        lines,
        vec![
            "control.gain: not supported: 'GainAuto': node kind 'Command' is not supported by omnitrack's GenICam reader",
            "control.white_balance: not supported: the camera's GenICam file has no feature 'BalanceWhiteAuto'",
        ]
    );
    let xml = CAMERA_XML.replace("<IntReg Name=\"GainRaw\">", "<Register Name=\"GainRaw\">").replace(
        "<Sign>Unsigned</Sign><Endianess>LittleEndian</Endianess>\n    </IntReg>\n    <Enumeration Name=\"BalanceWhiteAuto\">",
        "<Sign>Unsigned</Sign><Endianess>LittleEndian</Endianess>\n    </Register>\n    <Enumeration Name=\"BalanceWhiteAuto\">",
    );
    let (lines, _, _) = control(FakeCamera::new(xml.as_bytes(), false), &c);
    assert_eq!(
        lines[0],
        "control.gain: not supported: 'GainRaw': node kind 'Register' is not supported by omnitrack's GenICam reader"
    );
}

#[test]
fn a_damaged_genicam_file_is_an_error_or_a_report_never_a_panic() {
    let c = CameraControl {
        exposure_us: Some(Setting::Fixed(8000.0)),
        gain: Some(Setting::Fixed(6.5)),
        frame_rate_hz: Some(100.0),
        white_balance_auto: Some(false),
        trigger: None,
    };
    let pieces: [&str; 12] = [
        "<", ">", "/", "0x", "9", "-1", "64", "LSB", "Big", "pValue", "Gain", "((",
    ];
    let mut seed = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed
    };
    let mut loaded = 0;
    for _ in 0..300 {
        let mut xml = CAMERA_XML.to_string();
        for _ in 0..1 + next() % 4 {
            let at = (next() as usize) % xml.len();
            let at = (0..=at).rev().find(|&i| xml.is_char_boundary(i)).unwrap_or(0);
            let end = (at + 1 + (next() as usize) % 6).min(xml.len());
            let end = (end..=xml.len())
                .find(|&i| xml.is_char_boundary(i))
                .unwrap_or(xml.len());
            xml.replace_range(at..end, pieces[(next() % 12) as usize]);
        }
        let mut cp = GenCp::new(FakeCamera::new(xml.as_bytes(), false), Duration::from_millis(5));
        if let Ok(map) = load_node_map(&mut cp) {
            loaded += 1;
            let mut report = ControlReport::new("cam", "sensor 0");
            apply(&map, &mut cp, &c, &mut report);
            assert_eq!(report.findings.len(), 4);
            assert!(report.lines().all(|l| !l.contains('\n')));
        }
    }
    assert!(loaded > 0, "some damage leaves a file that still parses");
}

#[test]
fn a_register_indexed_by_its_selector_is_written_where_the_selector_points() {
    // TriggerMode per trigger: FrameStart's mode 8 bytes after AcquisitionStart's; and an
    // ExposureMode that must be Timed for a fixed exposure.
    let xml = CAMERA_XML
        .replace(
            "<EnumEntry Name=\"FrameStart\"><Value>0</Value></EnumEntry>\n      <EnumEntry Name=\"AcquisitionStart\"><Value>1</Value></EnumEntry>",
            "<EnumEntry Name=\"FrameStart\"><Value>1</Value></EnumEntry>\n      <EnumEntry Name=\"AcquisitionStart\"><Value>0</Value></EnumEntry>",
        )
        .replace(
            "<MaskedIntReg Name=\"TriggerModeReg\">",
            "<MaskedIntReg Name=\"TriggerModeReg\">\n      <pIndex Offset=\"8\">TriggerSelectorReg</pIndex>",
        )
        .replace(
            "<Group Comment=\"AcquisitionControl\">",
            "<Group Comment=\"AcquisitionControl\">\n    <Enumeration Name=\"ExposureMode\">\n      \
             <EnumEntry Name=\"Timed\"><Value>1</Value></EnumEntry>\n      \
             <EnumEntry Name=\"TriggerWidth\"><Value>2</Value></EnumEntry>\n      \
             <pValue>ExposureModeReg</pValue>\n    </Enumeration>\n    \
             <IntReg Name=\"ExposureModeReg\"><Address>0x2002C</Address><Length>4</Length>\
             <AccessMode>RW</AccessMode></IntReg>",
        );
    let mut cam = FakeCamera::new(xml.as_bytes(), false);
    cam.put(0x2002C, &2u32.to_le_bytes());
    cam.put(TRIGGER_SELECTOR, &0u32.to_le_bytes());
    let c = CameraControl {
        trigger: Some(Trigger::Line("Line0".into())),
        exposure_us: Some(Setting::Fixed(1000.0)),
        ..CameraControl::default()
    };
    let (lines, errors, cam) = control(cam, &c);
    assert!(!errors, "{lines:?}");
    assert_eq!(cam.u32_at(TRIGGER_SELECTOR), 1, "FrameStart");
    assert_eq!(cam.u32_at(TRIGGER) & 1, 0, "AcquisitionStart's mode untouched");
    assert_eq!(cam.u32_at(TRIGGER + 8) & 1, 1, "FrameStart's mode on");
    assert_eq!(cam.u32_at(0x2002C), 1, "ExposureMode Timed");
    assert_eq!(cam.f32_at(EXPOSURE), 1000.0);
}
