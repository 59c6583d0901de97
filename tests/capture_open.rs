//! Choosing a frame source (`--source replay:DIR|v4l|usb`), its one-line errors, the live
//! sources' handling of a sensor that disappears and comes back, and the rig's optional USB keys.

use image::{Rgb, RgbImage};
use omnitrack::capture::device::CaptureDevice;
use omnitrack::capture::live::{FailureDetail, LiveCamera, ReadFailure, READ_SLICE, STOPPED};
use omnitrack::capture::open::{USB_DISABLED, V4L_DISABLED};
use omnitrack::capture::{
    open_source, open_source_with, FrameSource, LiveSource, Pacing, SourceError, SourceOptions, SourceSpec,
    SourceSpecError,
};
use omnitrack::frame::{FrameSet, ImageFault, SensorImage};
use omnitrack::rig::{Rig, UsbRig};
use std::fmt::Write as _;
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// A pinhole rig of these sizes; `extra(id)` adds keys to a sensor, `head` goes before them.
fn rig_toml(sizes: &[(u32, u32)], head: &str, extra: &dyn Fn(usize) -> String) -> String {
    let mut s = format!("name = \"test-rig\"\n{head}\n");
    for (id, (w, h)) in sizes.iter().enumerate() {
        let _ = write!(
            s,
            "\n[[sensors]]\nid = {id}\nresolution = [{w}, {h}]\nmodel = \"pinhole\"\n\
             intrinsics = [100.0, 100.0, {}, {}]\nrotation_wxyz = [1.0, 0.0, 0.0, 0.0]\n\
             translation_m = [{}, 0.0, 0.0]\n{}\n",
            (*w as f64 - 1.0) / 2.0,
            (*h as f64 - 1.0) / 2.0,
            0.01 * id as f64,
            extra(id)
        );
    }
    s
}

fn rig(sizes: &[(u32, u32)], head: &str, extra: &dyn Fn(usize) -> String) -> Rig {
    Rig::from_toml_str(&rig_toml(sizes, head, extra), "rig.toml").unwrap()
}

/// The spec `text`, which must parse.
fn spec(text: &str) -> SourceSpec {
    text.parse().unwrap_or_else(|e| panic!("{text}: {e}"))
}

fn open_err(text: &str, rig: Option<&Rig>) -> String {
    let spec = spec(text);
    match open_source(&spec, rig) {
        Ok(_) => panic!("{spec} opened"),
        Err(e) => {
            let s = e.to_string();
            assert!(!s.contains('\n'), "one line: {s}");
            s
        }
    }
}

/// A recording of two frames for a rig of these sizes.
fn recording(sizes: &[(u32, u32)]) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    std::fs::write(root.join("rig.toml"), rig_toml(sizes, "", &|_| String::new())).unwrap();
    let mut index = String::from("frame,sensor,timestamp_ns,path\n");
    for (k, &(w, h)) in sizes.iter().enumerate() {
        std::fs::create_dir_all(root.join(format!("sensor{k}"))).unwrap();
        for f in 0..2u64 {
            let path = format!("sensor{k}/{f:06}.png");
            RgbImage::from_pixel(w, h, Rgb([f as u8, k as u8, 9]))
                .save(root.join(&path))
                .unwrap();
            let _ = writeln!(index, "{f},{k},{},{path}", 1_000 + f * 33_000_000);
        }
    }
    std::fs::write(root.join("frames.csv"), index).unwrap();
    dir
}

#[test]
fn replay_needs_no_rig_and_checks_a_given_one() {
    let sizes = [(8, 6), (10, 4)];
    let dir = recording(&sizes);
    let spec = spec(&format!("replay:{}", dir.path().display()));
    let options = SourceOptions {
        pacing: Pacing::AsFastAsPossible,
        ..SourceOptions::default()
    };
    let mut source = open_source_with(&spec, None, &options).unwrap();
    let mut frame = FrameSet::for_rig(source.rig());
    assert!(source.next_frame(&mut frame).unwrap());
    assert_eq!(frame.valid_count(), 2);
    assert!(source.next_frame(&mut frame).unwrap());
    assert!(!source.next_frame(&mut frame).unwrap());

    // The same sensors given with --rig: fine; other sizes: one line naming the recording's rig.
    assert!(open_source_with(&spec, Some(&rig(&sizes, "", &|_| String::new())), &options).is_ok());
    let other = rig(&[(8, 6)], "", &|_| String::new());
    let e = open_source_with(&spec, Some(&other), &options)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("rig.toml") && e.contains("does not match --rig"), "{e}");
}

#[test]
fn bad_specs_are_one_line_each() {
    // Refused where the text is parsed (clap names the option and the value before the line).
    let parse_err = |text: &str| {
        let e = text.parse::<SourceSpec>().expect_err(text);
        assert_eq!(e.text(), text);
        let s = e.to_string();
        assert!(!s.contains('\n'), "one line: {s}");
        (e, s)
    };
    let (e, s) = parse_err("webcam");
    assert!(matches!(e, SourceSpecError::Unknown(_)), "{e:?}");
    assert!(s.contains("expected replay:DIR, v4l or usb"), "{s}");
    for text in ["replay", "replay:", " replay: "] {
        let (e, s) = parse_err(text);
        assert!(matches!(e, SourceSpecError::ReplayWithoutDir(_)), "{e:?}");
        assert!(s.contains("replay:DIR"), "{s}");
    }
    // What parses, and back: the command line's own spelling.
    for (text, parsed) in [
        ("v4l", SourceSpec::V4l),
        (" usb ", SourceSpec::Usb),
        ("replay:rec/lab", SourceSpec::Replay("rec/lab".into())),
        ("replay:/a b", SourceSpec::Replay("/a b".into())),
    ] {
        assert_eq!(spec(text), parsed, "{text}");
        assert_eq!(spec(&parsed.to_string()), parsed);
    }
    // Refused when opened: a recording that is not there, a live source without its rig.
    let e = open_err("replay:/no/such/recording_xyz", None);
    assert!(
        e.contains("/no/such/recording_xyz") && e.contains("does not exist"),
        "{e}"
    );
    let e = open_err("v4l", None);
    assert!(e.starts_with("v4l: needs the rig (--rig"), "{e}");
    let e = open_err("usb", None);
    assert!(e.starts_with("usb: needs the rig (--rig"), "{e}");
}

#[test]
fn v4l_missing_device_is_a_clear_error() {
    let rig = rig(&[(8, 6), (8, 6)], "", &|id| {
        format!("device = \"/dev/video_missing_xyz{}\"", if id == 0 { "" } else { "_b" })
    });
    let e = open_err("v4l", Some(&rig));
    if cfg!(feature = "v4l") {
        assert_eq!(e, "/dev/video_missing_xyz: sensor 0: no such device");
    } else {
        assert_eq!(e, format!("v4l: {V4L_DISABLED}"));
        assert!(
            e.contains("cargo build --release --features v4l") && e.contains("libclang"),
            "{e}"
        );
    }
}

#[test]
fn v4l_sensor_without_device_key_is_named() {
    let rig = rig(&[(8, 6)], "", &|_| String::new());
    let e = open_err("v4l", Some(&rig));
    if cfg!(feature = "v4l") {
        assert!(e.contains("sensor 0 has no 'device' key"), "{e}");
    } else {
        assert!(e.contains("--features v4l"), "{e}");
    }
}

#[test]
fn usb_without_cameras_or_bus_is_a_clear_error_not_a_panic() {
    let no_table = rig(&[(8, 6)], "", &|_| String::new());
    let with_table = rig(&[(8, 6)], "[usb]\nvendor_id = 0x1e10\nproduct_id = 0x4000", &|_| {
        String::new()
    });
    let serials = rig(
        &[(8, 6), (8, 6)],
        "[usb]\nvendor_id = 0x1e10\nproduct_id = 0x4000",
        &|id| format!("usb_serial = \"CAM{id}\""),
    );
    if cfg!(feature = "usb") {
        let e = open_err("usb", Some(&no_table));
        assert!(e.starts_with("usb: rig 'test-rig' has no [usb] table"), "{e}");
        // Either libusb cannot start here (no bus) or it finds no such camera.
        for r in [&with_table, &serials] {
            let e = open_err("usb", Some(r));
            eprintln!("{e}");
            assert!(
                e.starts_with("usb: cannot start libusb") || e.starts_with("usb 1e10:4000: sensor 0: no camera"),
                "{e}"
            );
        }
    } else {
        for r in [&no_table, &with_table] {
            assert_eq!(open_err("usb", Some(r)), format!("usb: {USB_DISABLED}"));
        }
    }
}

/// A fake camera: sensor k's image is filled with k; `plugged[k]` says whether it is there.
struct FakeCamera {
    sensor: usize,
    size: (u32, u32),
    name: String,
    plugged: Arc<Mutex<Vec<bool>>>,
    reads: u64,
}

impl LiveCamera for FakeCamera {
    type Env = Arc<Mutex<Vec<bool>>>;

    fn open(env: &mut Self::Env, device: &CaptureDevice, _: &SourceOptions) -> Result<FakeCamera, SourceError> {
        if !env.lock().unwrap()[device.index] {
            return Err(SourceError::Device {
                device: format!("fake{}", device.index),
                message: format!("{}: no such device", device.label),
            });
        }
        Ok(FakeCamera {
            sensor: device.index,
            size: (device.width, device.height),
            name: format!("fake{}", device.index),
            plugged: env.clone(),
            reads: 0,
        })
    }

    fn name(&self) -> &str {
        &self.name
    }

    fn frame_size(&self) -> (u32, u32) {
        self.size
    }

    fn read(&mut self, img: &mut SensorImage) -> Result<u64, ReadFailure> {
        if !self.plugged.lock().unwrap()[self.sensor] {
            return Err(ReadFailure {
                fault: ImageFault::Missing,
                lost: true,
                detail: FailureDetail::Os(19),
            });
        }
        self.reads += 1;
        img.pixels_mut().fill(self.sensor as u8 + 1);
        Ok(self.reads * 1000 + self.sensor as u64)
    }
}

#[test]
fn a_lost_sensor_is_reported_reopened_and_the_others_go_on() {
    let rig = rig(&[(4, 3), (4, 3), (4, 3)], "", &|_| String::new());
    let plugged = Arc::new(Mutex::new(vec![true; 3]));
    let options = SourceOptions {
        reopen_interval: Duration::from_millis(30),
        ..SourceOptions::default()
    };
    // A sensor missing at start is an error naming it.
    plugged.lock().unwrap()[2] = false;
    let e = LiveSource::<FakeCamera>::open_with_env(rig.clone(), plugged.clone(), options).unwrap_err();
    assert_eq!(e.to_string(), "fake2: sensor 2: no such device");
    plugged.lock().unwrap()[2] = true;

    let mut source = LiveSource::<FakeCamera>::open_with_env(rig, plugged.clone(), options).unwrap();
    let mut frame = FrameSet::for_rig(source.rig());
    assert!(source.next_frame(&mut frame).unwrap());
    assert_eq!(frame.valid_count(), 3);
    assert!(frame.sensor(1).pixels().iter().all(|&p| p == 2));

    // Sensor 1 is unplugged: it is marked missing, the others deliver.
    plugged.lock().unwrap()[1] = false;
    for _ in 0..3 {
        assert!(source.next_frame(&mut frame).unwrap());
        assert_eq!(frame.valid_count(), 2);
        assert!(!frame.sensor(1).valid);
        assert_eq!(frame.sensor(1).fault, Some(ImageFault::Missing));
        assert!(frame.sensor(0).valid && frame.sensor(2).valid);
    }
    assert!(!source.is_connected(1));
    assert_eq!(source.connected(), 2);
    assert_eq!(source.stats().sensors[1].missing, 3);

    // Plugged back: reopened at the next attempt.
    plugged.lock().unwrap()[1] = true;
    std::thread::sleep(Duration::from_millis(40));
    assert!(source.next_frame(&mut frame).unwrap());
    assert_eq!(frame.valid_count(), 3);
    assert!(source.is_connected(1));
    assert_eq!(source.stats().frames_delivered, 5);
    assert_eq!(source.stats().sensors[0].delivered, 5);
    assert_eq!(source.stats().sensors[1].delivered, 2);

    // All gone: next_frame waits for the reopening attempt instead of spinning, never errs.
    *plugged.lock().unwrap() = vec![false; 3];
    for _ in 0..3 {
        assert!(source.next_frame(&mut frame).unwrap());
        assert_eq!(frame.valid_count(), 0);
    }
    // A frame set of another rig is refused.
    let mut wrong = FrameSet::for_rig(&Rig::from_toml_str(&rig_toml(&[(4, 3)], "", &|_| String::new()), "x").unwrap());
    assert!(matches!(
        source.next_frame(&mut wrong),
        Err(SourceError::FrameSetMismatch { .. })
    ));
}

/// Whether the pattern device is plugged in, and the frame size it forces (else the one asked).
type PatternEnv = Arc<Mutex<(bool, Option<(u32, u32)>)>>;

/// A device delivering frames whose pixel (u, v) is (u, v, n) for its n-th read, of the size
/// asked for, or of `forced` when set; `plugged` says whether it is there.
struct PatternCamera {
    size: (u32, u32),
    plugged: PatternEnv,
    reads: u8,
}

impl LiveCamera for PatternCamera {
    type Env = PatternEnv;

    fn open(env: &mut Self::Env, device: &CaptureDevice, _: &SourceOptions) -> Result<PatternCamera, SourceError> {
        let (plugged, forced) = *env.lock().unwrap();
        if !plugged {
            return Err(SourceError::Device {
                device: "pattern".into(),
                message: format!("{}: no such device", device.label),
            });
        }
        Ok(PatternCamera {
            size: forced.unwrap_or((device.width, device.height)),
            plugged: env.clone(),
            reads: 0,
        })
    }

    fn name(&self) -> &str {
        "pattern"
    }

    fn frame_size(&self) -> (u32, u32) {
        self.size
    }

    fn read(&mut self, img: &mut SensorImage) -> Result<u64, ReadFailure> {
        if !self.plugged.lock().unwrap().0 {
            return Err(ReadFailure {
                fault: ImageFault::Missing,
                lost: true,
                detail: FailureDetail::Os(19),
            });
        }
        self.reads += 1;
        assert_eq!((img.width(), img.height()), self.size);
        let w = self.size.0 as usize;
        for (i, p) in img.pixels_mut().chunks_exact_mut(3).enumerate() {
            p.copy_from_slice(&[(i % w) as u8, (i / w) as u8, self.reads]);
        }
        Ok(u64::from(self.reads) * 1000)
    }
}

/// Two sensors cropped from one device's frame (a dual-fisheye camera): one device opened, each
/// sensor's image is its window, a device that vanishes takes both, and a frame too small for a
/// window is one line naming it.
#[test]
fn sensors_cropped_from_one_device_get_their_windows_of_each_frame() {
    let r = rig(&[(4, 3), (4, 3), (2, 2)], "", &|id| match id {
        0 => "device = \"/dev/video0\"\ncrop = [0, 0, 4, 3]".into(),
        1 => "device = \"/dev/video0\"\ncrop = [5, 1, 4, 3]".into(),
        _ => "device = \"/dev/video1\"".into(),
    });
    let env = Arc::new(Mutex::new((true, None)));
    let options = SourceOptions {
        reopen_interval: Duration::from_millis(20),
        ..SourceOptions::default()
    };
    let mut source = LiveSource::<PatternCamera>::open_with_env(r.clone(), env.clone(), options).unwrap();
    assert_eq!(source.connected(), 2, "two devices for three sensors");
    let mut frame = FrameSet::for_rig(source.rig());
    assert!(source.next_frame(&mut frame).unwrap());
    assert_eq!(frame.valid_count(), 3);
    // Sensor 1's pixel (u, v) is the device's (5 + u, 1 + v); both carry the device's time.
    assert_eq!(frame.sensor(0).rgb(3, 2), [3, 2, 1]);
    assert_eq!(frame.sensor(1).rgb(0, 0), [5, 1, 1]);
    assert_eq!(frame.sensor(1).rgb(3, 2), [8, 3, 1]);
    assert_eq!(frame.sensor(2).rgb(1, 1), [1, 1, 1]);
    assert_eq!(frame.sensor(0).timestamp_ns, frame.sensor(1).timestamp_ns);

    env.lock().unwrap().0 = false;
    assert!(source.next_frame(&mut frame).unwrap());
    assert_eq!(frame.valid_count(), 0);
    assert_eq!(source.stats().sensors[1].missing, 1);
    assert!(!source.is_connected(0) && !source.is_connected(1));
    env.lock().unwrap().0 = true;
    std::thread::sleep(Duration::from_millis(30));
    assert!(source.next_frame(&mut frame).unwrap());
    assert_eq!(frame.valid_count(), 3);
    assert_eq!(frame.sensor(1).rgb(0, 0)[..2], [5, 1]);

    // A larger frame than the windows need is taken; a smaller one is refused, naming the window.
    *env.lock().unwrap() = (true, Some((12, 5)));
    let r0 = rig(&[(4, 3), (4, 3)], "", &|id| {
        format!("device = \"/dev/video0\"\ncrop = [{}, 1, 4, 3]", 5 * id)
    });
    let mut wide = LiveSource::<PatternCamera>::open_with_env(r0.clone(), env.clone(), options).unwrap();
    let mut frame = FrameSet::for_rig(wide.rig());
    assert!(wide.next_frame(&mut frame).unwrap());
    assert_eq!(frame.sensor(1).rgb(3, 2), [8, 3, 1]);
    *env.lock().unwrap() = (true, Some((8, 5)));
    let e = LiveSource::<PatternCamera>::open_with_env(r0, env.clone(), options).unwrap_err();
    assert_eq!(
        e.to_string(),
        "pattern: sensors 0 and 1: crop [5, 1, 4, 3] of sensor 1 lies outside the device's 8x5 frame"
    );
    // Two sensors on one device without crops cannot be told apart: one line.
    let r1 = rig(&[(4, 3), (4, 3)], "", &|_| "device = \"/dev/video0\"".into());
    let e = LiveSource::<PatternCamera>::open_with_env(r1, env, options).unwrap_err();
    assert!(
        e.to_string()
            .starts_with("test-rig: sensors 0 and 1 share '/dev/video0', but sensor 0 has no crop"),
        "{e}"
    );
}

#[test]
fn rig_usb_keys_parse_validate_and_round_trip() {
    let head = "[usb]\nvendor_id = 0x1E10\nproduct_id = 16384";
    let r = rig(&[(8, 6), (8, 6)], head, &|id| format!("usb_serial = \"SN{id}\""));
    assert_eq!(
        r.usb,
        Some(UsbRig {
            vendor_id: 0x1e10,
            product_id: 0x4000
        })
    );
    assert_eq!(r.sensors[1].usb_serial.as_deref(), Some("SN1"));
    let again = Rig::from_toml_str(&r.to_toml_string(), "again.toml").unwrap();
    assert_eq!(again, r);
    // Without the keys nothing changes.
    let plain = rig(&[(8, 6)], "", &|_| String::new());
    assert_eq!(plain.usb, None);
    assert_eq!(plain.sensors[0].usb_serial, None);
    assert_eq!(Rig::from_toml_str(&plain.to_toml_string(), "p").unwrap(), plain);

    let err = |head: &str, extra: &dyn Fn(usize) -> String| {
        Rig::from_toml_str(&rig_toml(&[(8, 6), (8, 6)], head, extra), "rig.toml")
            .unwrap_err()
            .to_string()
    };
    let none = |_: usize| String::new();
    assert_eq!(
        err("[usb]\nvendor_id = 70000\nproduct_id = 1", &none),
        "rig.toml: [usb], key 'vendor_id': must be a USB id 0..=0xFFFF, found 70000"
    );
    assert_eq!(
        err("[usb]\nvendor_id = 1", &none),
        "rig.toml: [usb], key 'product_id': missing"
    );
    assert!(err("[usb]\nvendor_id = 1\nproduct_id = 2\nserial = 3", &none)
        .starts_with("rig.toml: [usb], key 'serial': unknown key"));
    assert!(err("usb = 5", &none).starts_with("rig.toml: key 'usb': must be a table"));
    assert!(err("", &|id| if id == 0 {
        "usb_serial = \"A\"".into()
    } else {
        String::new()
    })
    .starts_with("rig.toml: sensor 1, key 'usb_serial': missing, while 1 other sensor(s) have one"));
    assert_eq!(
        err("", &|_| "usb_serial = \"A\"".into()),
        "rig.toml: sensor 1, key 'usb_serial': duplicate serial 'A' (also sensor 0); sensors sharing one camera each need a crop"
    );
    assert!(err("", &|_| "usb_serial = \"\"".into()).starts_with("rig.toml: sensor 0, key 'usb_serial': must be"));
}

/// The front door built as it is (with or without the capture features): `omnitrack record
/// --source v4l|usb` on a machine without the rig's cameras ends in one line naming the problem
/// and a non-zero exit, never a panic. CI runs this file again with every feature on, so the
/// binary that reaches the live drivers is checked too.
#[test]
fn the_binary_refuses_a_missing_camera_in_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let rig = dir.path().join("rig.toml");
    let text = rig_toml(&[(8, 6)], "[usb]\nvendor_id = 0x1e10\nproduct_id = 0x4000", &|_| {
        "device = \"/dev/video_missing_xyz\"".to_string()
    });
    std::fs::write(&rig, text).unwrap();
    for source in ["v4l", "usb"] {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_omnitrack"))
            .args([
                "record",
                "--rig",
                rig.to_str().unwrap(),
                "--source",
                source,
                "--frames",
                "1",
            ])
            .arg("--out")
            .arg(dir.path().join(format!("out-{source}")))
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        let lines: Vec<&str> = stderr.lines().filter(|l| !l.trim().is_empty()).collect();
        eprintln!("{source}: {stderr}");
        assert!(
            !out.status.success() && out.status.code() != Some(101),
            "{source}: {stderr}"
        );
        assert_eq!(lines.len(), 1, "{source}: one line: {stderr}");
        let expected = match (source, cfg!(feature = "v4l"), cfg!(feature = "usb")) {
            ("v4l", true, _) => "/dev/video_missing_xyz: sensor 0: no such device",
            ("v4l", false, _) => "--features v4l",
            (_, _, true) => "usb",
            _ => "--features usb",
        };
        assert!(lines[0].contains(expected), "{source}: {stderr}");
    }
}

/// A camera that never delivers: each read waits the whole frame timeout, as a driver does, in
/// slices of [`READ_SLICE`] with the stop looked at between them (as the V4L2 and USB drivers
/// wait).
struct SilentCamera {
    timeout: Duration,
}

impl LiveCamera for SilentCamera {
    type Env = ();

    fn open(_: &mut (), device: &CaptureDevice, options: &SourceOptions) -> Result<SilentCamera, SourceError> {
        let _ = device;
        Ok(SilentCamera {
            timeout: options.frame_timeout,
        })
    }

    fn name(&self) -> &str {
        "silent"
    }

    fn frame_size(&self) -> (u32, u32) {
        (4, 3)
    }

    fn read(&mut self, img: &mut SensorImage) -> Result<u64, ReadFailure> {
        self.read_or_stop(img, &|| false)
    }

    fn read_or_stop(&mut self, _: &mut SensorImage, stop: &dyn Fn() -> bool) -> Result<u64, ReadFailure> {
        let deadline = std::time::Instant::now() + self.timeout;
        while std::time::Instant::now() < deadline {
            if stop() {
                return Err(STOPPED);
            }
            std::thread::sleep(READ_SLICE);
        }
        Err(ReadFailure {
            fault: ImageFault::Dropped,
            lost: false,
            detail: FailureDetail::TimedOut,
        })
    }
}

/// A stop while a live camera waits for its frame ends the wait within a slice, not a frame
/// timeout later (issue 50, item 8): no frame is delivered, and nothing is counted against the
/// camera. Unstopped, the same read times out and counts a dropped frame.
#[test]
fn a_stop_ends_a_live_read_waiting_for_its_frame() {
    let one = rig(&[(4, 3)], "", &|_| String::new());
    let options = SourceOptions {
        frame_timeout: Duration::from_secs(2),
        ..SourceOptions::default()
    };
    let mut source = LiveSource::<SilentCamera>::open_with_env(one.clone(), (), options).unwrap();
    let mut frame = FrameSet::for_rig(source.rig());
    let started = std::time::Instant::now();
    let stop_at = started + Duration::from_millis(100);
    let delivered = source
        .next_frame_or_stop(&mut frame, &|| std::time::Instant::now() >= stop_at)
        .unwrap();
    let took = started.elapsed();
    assert!(!delivered, "a frame after the stop");
    assert!(took < Duration::from_secs(1), "the stop waited {took:?} for the read");
    assert_eq!(source.stats().frames_delivered, 0);
    assert_eq!(
        source.stats().sensors[0].total_faults(),
        0,
        "a stop is no fault of the camera"
    );

    let mut source = LiveSource::<SilentCamera>::open_with_env(
        one,
        (),
        SourceOptions {
            frame_timeout: Duration::from_millis(60),
            ..SourceOptions::default()
        },
    )
    .unwrap();
    assert!(source.next_frame(&mut frame).unwrap());
    assert_eq!(frame.sensor(0).fault, Some(ImageFault::Dropped));
    assert_eq!(source.stats().sensors[0].dropped, 1);
}
