//! V4L2 camera control against the fake device: each key through its ioctls, each way a device
//! can differ from the rig file as one line.

use super::fake_v4l2::{ctrl, FakeV4l2};
use omnitrack_io::capture::control::v4l2::*;
use omnitrack_io::capture::control::{CameraControl, ControlReport, Outcome, Setting, Trigger};

fn run(dev: &mut FakeV4l2, control: CameraControl) -> ControlReport {
    let mut report = ControlReport::new("/dev/video0", "sensor 0");
    apply(dev, &control, &mut report);
    report
}

fn lines(r: &ControlReport) -> Vec<String> {
    r.lines().collect()
}

#[test]
fn every_key_is_set_and_read_back() {
    let mut dev = FakeV4l2::uvc();
    let r = run(
        &mut dev,
        CameraControl {
            exposure_us: Some(Setting::Fixed(5000.0)),
            gain: Some(Setting::Fixed(32.0)),
            frame_rate_hz: Some(60.0),
            white_balance_auto: Some(false),
            trigger: Some(Trigger::Off),
        },
    );
    assert!(!r.has_errors(), "{:?}", lines(&r));
    assert_eq!(
        lines(&r),
        vec![
            "/dev/video0: sensor 0, control.exposure_us: set to 5000 µs",
            "/dev/video0: sensor 0, control.gain: set to 32",
            "/dev/video0: sensor 0, control.white_balance: set to off",
            "/dev/video0: sensor 0, control.frame_rate_hz: set to 60 Hz",
            "/dev/video0: sensor 0, control.trigger: set to off (V4L2 cameras run free)",
        ]
    );
    // What the device holds: manual exposure of 50 × 100 µs, auto gain off before the gain.
    assert_eq!(dev.control(CID_EXPOSURE_AUTO).value, EXPOSURE_MANUAL);
    assert_eq!(dev.control(CID_EXPOSURE_ABSOLUTE).value, 50);
    assert_eq!(dev.control(CID_EXPOSURE_ABSOLUTE).query.flags & FLAG_INACTIVE, 0);
    assert_eq!(dev.control(CID_AUTOGAIN).value, 0);
    assert_eq!(dev.control(CID_GAIN).value, 32);
    assert_eq!(dev.control(CID_AUTO_WHITE_BALANCE).value, 0);
    assert_eq!(dev.interval, (1, 60));
    let autogain_off = dev.log.iter().position(|l| l == &format!("S_CTRL {CID_AUTOGAIN:#x} 0"));
    let gain = dev.log.iter().position(|l| l == &format!("S_CTRL {CID_GAIN:#x} 32"));
    assert!(autogain_off < gain, "{:?}", dev.log);
}

#[test]
fn auto_settings_pick_the_modes_the_device_offers() {
    let mut dev = FakeV4l2::uvc();
    dev.control_mut(CID_EXPOSURE_AUTO).value = EXPOSURE_MANUAL;
    let r = run(
        &mut dev,
        CameraControl {
            exposure_us: Some(Setting::Auto),
            gain: Some(Setting::Auto),
            white_balance_auto: Some(true),
            ..CameraControl::default()
        },
    );
    assert!(!r.has_errors(), "{:?}", lines(&r));
    // UVC's menu has no 0 (auto): aperture priority is its automatic exposure.
    assert_eq!(dev.control(CID_EXPOSURE_AUTO).value, EXPOSURE_APERTURE_PRIORITY);
    assert_eq!(dev.control(CID_AUTOGAIN).value, 1);
    // A device whose menu starts at 0 gets the full auto mode.
    let mut dev = FakeV4l2::uvc();
    dev.control_mut(CID_EXPOSURE_AUTO).query.minimum = 0;
    let r = run(
        &mut dev,
        CameraControl {
            exposure_us: Some(Setting::Auto),
            ..CameraControl::default()
        },
    );
    assert!(!r.has_errors());
    assert_eq!(dev.control(CID_EXPOSURE_AUTO).value, EXPOSURE_AUTO);
}

#[test]
fn a_value_between_steps_is_rounded_and_warned_not_refused() {
    let mut dev = FakeV4l2::uvc();
    let r = run(
        &mut dev,
        CameraControl {
            exposure_us: Some(Setting::Fixed(5040.0)),
            frame_rate_hz: Some(29.97),
            ..CameraControl::default()
        },
    );
    assert!(!r.has_errors(), "{:?}", lines(&r));
    assert_eq!(
        lines(&r),
        vec![
            "/dev/video0: sensor 0, control.exposure_us: set to 5000 µs (asked 5040 µs; the device's nearest step)",
            "/dev/video0: sensor 0, control.frame_rate_hz: set to 30 Hz (asked 29.97 Hz; the device's nearest step)",
        ]
    );
    assert!(matches!(r.findings[0].outcome, Outcome::Rounded { .. }));
}

#[test]
fn what_the_device_cannot_do_is_one_error_line_each() {
    let mut dev = FakeV4l2::uvc();
    dev.control_mut(CID_GAIN).query.flags |= FLAG_READ_ONLY;
    dev.controls.retain(|c| c.query.id != CID_AUTO_WHITE_BALANCE);
    let r = run(
        &mut dev,
        CameraControl {
            exposure_us: Some(Setting::Fixed(500_000.0)),
            gain: Some(Setting::Fixed(10.0)),
            frame_rate_hz: Some(25.0),
            white_balance_auto: Some(false),
            trigger: Some(Trigger::Line("Line0".into())),
        },
    );
    assert!(r.has_errors());
    assert_eq!(
        lines(&r),
        vec![
            "/dev/video0: sensor 0, control.exposure_us: 500000 µs is outside the device's range [300, 204700] µs; not set",
            "/dev/video0: sensor 0, control.gain: refused by the device: V4L2_CID_GAIN is read-only on this device",
            "/dev/video0: sensor 0, control.white_balance: not supported: the device has no V4L2_CID_AUTO_WHITE_BALANCE",
            "/dev/video0: sensor 0, control.frame_rate_hz: asked 25 Hz, the device reports 30 Hz",
            "/dev/video0: sensor 0, control.trigger: not supported: V4L2 has no standard trigger control (asked \"Line0\"); use a USB3 Vision camera",
        ]
    );
    // Nothing was written for the exposure out of range, and never to a read-only control.
    assert_eq!(dev.control(CID_EXPOSURE_ABSOLUTE).value, 250);
    assert!(!dev.log.iter().any(|l| l.starts_with(&format!("S_CTRL {CID_GAIN:#x}"))));
    let e = r.error().unwrap().to_string();
    assert_eq!(
        e,
        "/dev/video0: sensor 0, control.exposure_us: 500000 µs is outside the device's range [300, 204700] µs; not set (and 4 more control error(s): `omnitrack check --source` lists them)"
    );
}

#[test]
fn a_device_that_ignores_or_refuses_a_write_is_reported() {
    let mut dev = FakeV4l2::uvc();
    dev.control_mut(CID_GAIN).stuck = true;
    dev.control_mut(CID_EXPOSURE_ABSOLUTE).accepts_up_to = Some(333);
    dev.capability = 0;
    let r = run(
        &mut dev,
        CameraControl {
            exposure_us: Some(Setting::Fixed(100_000.0)),
            gain: Some(Setting::Fixed(10.0)),
            frame_rate_hz: Some(30.0),
            ..CameraControl::default()
        },
    );
    assert_eq!(
        lines(&r),
        vec![
            "/dev/video0: sensor 0, control.exposure_us: refused by the device: VIDIOC_S_CTRL Exposure Time, Absolute = 1000: ERANGE (value out of range)",
            "/dev/video0: sensor 0, control.gain: asked 10, the device reports 64",
            "/dev/video0: sensor 0, control.frame_rate_hz: not supported: the device does not set its frame interval (no V4L2_CAP_TIMEPERFRAME)",
        ]
    );
    // Auto gain asked of a device without V4L2_CID_AUTOGAIN.
    let mut dev = FakeV4l2::uvc();
    dev.controls.retain(|c| c.query.id != CID_AUTOGAIN);
    dev.controls
        .push(ctrl(0x0098_0999, TYPE_INTEGER, "Other", [0, 1, 1], 0, 0));
    let r = run(
        &mut dev,
        CameraControl {
            gain: Some(Setting::Auto),
            ..CameraControl::default()
        },
    );
    assert_eq!(
        lines(&r),
        vec!["/dev/video0: sensor 0, control.gain: not supported: the device has no V4L2_CID_AUTOGAIN"]
    );
    // A fixed exposure on a device without V4L2_CID_EXPOSURE_AUTO: nothing to switch off.
    dev.controls.retain(|c| c.query.id != CID_EXPOSURE_AUTO);
    let r = run(
        &mut dev,
        CameraControl {
            exposure_us: Some(Setting::Fixed(1000.0)),
            ..CameraControl::default()
        },
    );
    assert!(!r.has_errors(), "{:?}", lines(&r));
    assert_eq!(dev.control(CID_EXPOSURE_ABSOLUTE).value, 10);
    let r = run(
        &mut dev,
        CameraControl {
            exposure_us: Some(Setting::Auto),
            ..CameraControl::default()
        },
    );
    assert_eq!(
        lines(&r),
        vec!["/dev/video0: sensor 0, control.exposure_us: not supported: the device has no V4L2_CID_EXPOSURE_AUTO"]
    );
    // A fixed gain on that device needs no auto gain switched off.
    let r = run(
        &mut dev,
        CameraControl {
            gain: Some(Setting::Fixed(7.0)),
            ..CameraControl::default()
        },
    );
    assert!(!r.has_errors(), "{:?}", lines(&r));
}

#[test]
fn an_empty_control_touches_nothing() {
    let mut dev = FakeV4l2::uvc();
    let r = run(&mut dev, CameraControl::default());
    assert!(r.findings.is_empty());
    assert!(dev.log.is_empty(), "{:?}", dev.log);
}
