//! The rig's `[control]` through a live source's opening: each capture device gets its sensors'
//! table, a camera that does not take it fails the opening in one line under the default policy,
//! and under `ControlPolicy::Report` opens and hands its report to `check`. The camera here runs
//! the V4L2 control step of `V4l2Camera::open` against the fake device.

use super::fake_v4l2::FakeV4l2;
use omnitrack_core::frame::SensorImage;
use omnitrack_core::rig::Rig;
use omnitrack_io::capture::control::v4l2::{CID_EXPOSURE_ABSOLUTE, CID_GAIN};
use omnitrack_io::capture::control::{self, ControlReport};
use omnitrack_io::capture::device::CaptureDevice;
use omnitrack_io::capture::live::{LiveCamera, ReadFailure};
use omnitrack_io::capture::{ControlPolicy, FrameSource, LiveSource, SourceError, SourceOptions};
use std::sync::{Arc, Mutex};

/// The fake devices by path.
type Devices = Arc<Mutex<Vec<(String, FakeV4l2)>>>;

struct Camera {
    path: String,
    size: (u32, u32),
    control: Option<ControlReport>,
}

impl LiveCamera for Camera {
    type Env = Devices;

    fn open(env: &mut Devices, target: &CaptureDevice, options: &SourceOptions) -> Result<Camera, SourceError> {
        let path = target.device.clone().unwrap_or_default();
        let mut devices = env.lock().unwrap();
        let Some((_, dev)) = devices.iter_mut().find(|(p, _)| *p == path) else {
            return Err(SourceError::Device {
                device: path,
                message: "no such device".into(),
            });
        };
        let mut control = None;
        if !target.control.is_empty() {
            let mut report = ControlReport::new(&path, &target.label);
            control::v4l2::apply(dev, &target.control, &mut report);
            control::settle(&report, options.control)?;
            control = Some(report);
        }
        Ok(Camera {
            path,
            size: (target.width, target.height),
            control,
        })
    }

    fn name(&self) -> &str {
        &self.path
    }

    fn frame_size(&self) -> (u32, u32) {
        self.size
    }

    fn read(&mut self, _img: &mut SensorImage) -> Result<u64, ReadFailure> {
        Ok(0)
    }

    fn control_report(&self) -> Option<&ControlReport> {
        self.control.as_ref()
    }
}

fn rig() -> Rig {
    let sensor = |id: usize, extra: &str| {
        format!(
            "[[sensors]]\nid = {id}\nresolution = [8, 6]\nmodel = \"pinhole\"\nintrinsics = [5.0, 5.0, 3.5, 2.5]\n\
             rotation_wxyz = [1.0, 0.0, 0.0, 0.0]\ntranslation_m = [0.0, 0.0, 0.0]\ndevice = \"/dev/video{id}\"\n{extra}\n"
        )
    };
    let text = format!(
        "name = \"c\"\n[control]\nexposure_us = 5000\ngain = 40\n{}{}{}",
        sensor(0, ""),
        sensor(1, "[sensors.control]\ngain = 300"),
        sensor(2, "[sensors.control]\nexposure_us = 2000")
    );
    Rig::from_toml_str(&text, "c.toml").unwrap()
}

fn devices() -> Devices {
    Arc::new(Mutex::new(
        (0..3).map(|k| (format!("/dev/video{k}"), FakeV4l2::uvc())).collect(),
    ))
}

#[test]
fn a_camera_that_refuses_its_control_stops_the_opening_unless_only_reported() {
    let env = devices();
    let e = LiveSource::<Camera>::open_with_env(rig(), env.clone(), SourceOptions::default()).unwrap_err();
    assert_eq!(
        e.to_string(),
        "/dev/video1: sensor 1, control.gain: 300 is outside the device's range [0, 255]; not set"
    );
    // Sensor 0 was set before sensor 1 refused.
    assert_eq!(env.lock().unwrap()[0].1.control(CID_GAIN).value, 40);
    let options = SourceOptions {
        control: ControlPolicy::Report,
        ..SourceOptions::default()
    };
    let source = LiveSource::<Camera>::open_with_env(rig(), env.clone(), options).unwrap();
    let reports = source.control_reports();
    assert_eq!(reports.len(), 3);
    assert!(!reports[0].has_errors() && reports[1].has_errors() && !reports[2].has_errors());
    let devices = env.lock().unwrap();
    // Each device got its sensor's table: the rig's, with the sensor's keys over it.
    assert_eq!(devices[2].1.control(CID_EXPOSURE_ABSOLUTE).value, 20);
    assert_eq!(devices[2].1.control(CID_GAIN).value, 40);
    assert_eq!(devices[1].1.control(CID_EXPOSURE_ABSOLUTE).value, 50);
}
