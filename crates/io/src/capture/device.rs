//! Capture devices: which camera delivers which sensors' images.
//!
//! In: the rig ([`Rig`]): each sensor's `device` (V4L2) or `usb_serial` (USB3 Vision), and its
//! optional `crop = [x, y, width, height]`. Out: the rig's [`CaptureDevice`]s, one per camera to
//! open, each with the [`Window`]s of its frame that are its sensors' images; and the window
//! copies that turn one device frame into those images ([`copy_window`], [`crop_into`]).
//!
//! Sensors share a device when they name the same `device` or the same `usb_serial`; a consumer
//! dual-fisheye camera is one V4L2 device whose frame holds both circles, so its two kb4 sensors
//! are two windows of one frame. Every sensor of a shared device needs a `crop` (which part of
//! the frame is its image). A sensor without `crop` that shares nothing is its own device whose
//! whole frame is its image, read straight into the sensor's buffer, as before crops existed.
//!
//! Devices are numbered in the order of their first sensor: the order in which cameras found by
//! USB port order are taken. Without shared devices, device k is sensor k.
//!
//! Frame size: a device with crops is asked for the smallest frame that holds all its windows;
//! a driver that offers only a larger one is accepted (the windows still lie inside it), a smaller
//! one is refused in one line naming the window that does not fit ([`CaptureDevice::check_fits`]).

use super::SourceError;
use omnitrack_core::frame::SensorImage;
use omnitrack_core::rig::{CameraControl, Rig};
use std::fmt::Write as _;

/// Most sensors one device's frame may be split into (a fixed bound, so that a capture thread
/// can hold its sensors' buffers in a fixed-size list).
pub const MAX_WINDOWS_PER_DEVICE: usize = 8;

/// One sensor's image as a window of its device's frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Window {
    /// Sensor id.
    pub sensor: usize,
    pub x: u32,
    pub y: u32,
    /// The sensor's resolution (the rig checks that a crop's size is the sensor's).
    pub width: u32,
    pub height: u32,
}

/// One camera to open: a V4L2 device or a USB3 Vision camera, and the sensors it delivers.
#[derive(Debug, Clone, PartialEq)]
pub struct CaptureDevice {
    /// Device number, in the order of each device's first sensor (see the module doc).
    pub index: usize,
    /// The sensors, for messages: `sensor 3`, or `sensors 0 and 1` for a shared device.
    pub label: String,
    /// The frame size to ask of the device: the sensor's resolution for a device of one
    /// uncropped sensor, else the smallest frame holding every window.
    pub width: u32,
    pub height: u32,
    /// Whether the device must deliver exactly `width × height` (one uncropped sensor) or may
    /// deliver a larger frame (crops).
    pub exact: bool,
    /// The rig's `device` key of these sensors (V4L2).
    pub device: Option<String>,
    /// The rig's `usb_serial` of these sensors (USB3 Vision).
    pub usb_serial: Option<String>,
    /// Each sensor's window, in sensor order; one whole-frame window when `direct`.
    pub windows: Vec<Window>,
    /// The frame is the one sensor's image: read straight into its buffer, no copy.
    pub direct: bool,
    /// What the rig asks of the camera (its sensors' `[control]`, which must agree); empty
    /// leaves it as it is.
    pub control: CameraControl,
}

impl CaptureDevice {
    /// Sensor ids delivered by this device, in order.
    pub fn sensors(&self) -> impl Iterator<Item = usize> + '_ {
        self.windows.iter().map(|w| w.sensor)
    }

    /// Whether a device frame of `width × height` holds every window; else the one-line error
    /// naming the device, the sensor and its window.
    pub fn check_fits(&self, name: &str, width: u32, height: u32) -> Result<(), SourceError> {
        let exact_wrong = self.exact && (width, height) != (self.width, self.height);
        let outside = self.windows.iter().find(|w| {
            u64::from(w.x) + u64::from(w.width) > u64::from(width)
                || u64::from(w.y) + u64::from(w.height) > u64::from(height)
        });
        if exact_wrong {
            return Err(SourceError::Device {
                device: name.to_string(),
                message: format!(
                    "{}: the device delivers {width}x{height} frames, the sensor is {}x{}",
                    self.label, self.width, self.height
                ),
            });
        }
        match outside {
            None => Ok(()),
            Some(w) => Err(SourceError::Device {
                device: name.to_string(),
                message: format!(
                    "{}: crop [{}, {}, {}, {}] of sensor {} lies outside the device's {width}x{height} frame",
                    self.label, w.x, w.y, w.width, w.height, w.sensor
                ),
            }),
        }
    }
}

/// The rig's capture devices (see the module doc), or one line saying why the rig's sensors
/// cannot be split among devices.
pub fn capture_devices(rig: &Rig) -> Result<Vec<CaptureDevice>, SourceError> {
    let key = |k: usize| {
        let s = &rig.sensors[k];
        s.device.as_deref().or(s.usb_serial.as_deref())
    };
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for k in 0..rig.sensors.len() {
        match key(k).and_then(|name| groups.iter_mut().find(|g| key(g[0]) == Some(name))) {
            Some(group) => group.push(k),
            None => groups.push(vec![k]),
        }
    }
    let rig_error = |message: String| SourceError::Device {
        device: rig.name.clone(),
        message,
    };
    let mut devices = Vec::with_capacity(groups.len());
    for (index, group) in groups.into_iter().enumerate() {
        let label = label(&group);
        let first = &rig.sensors[group[0]];
        let shared_name = key(group[0]).unwrap_or_default();
        if group.len() > MAX_WINDOWS_PER_DEVICE {
            return Err(rig_error(format!(
                "{label} share '{shared_name}': one device can deliver at most {MAX_WINDOWS_PER_DEVICE} sensors"
            )));
        }
        if group.len() > 1 {
            if let Some(&k) = group.iter().find(|&&k| rig.sensors[k].crop.is_none()) {
                return Err(rig_error(format!(
                    "{label} share '{shared_name}', but sensor {k} has no crop: each sensor of a shared device \
                     needs crop = [x, y, width, height], its window of the device's frame"
                )));
            }
        }
        // One camera has one exposure: sensors cut from its frame must ask the same of it.
        if let Some(&k) = group.iter().find(|&&k| rig.sensors[k].control != first.control) {
            let keys = first.control.differing_keys(&rig.sensors[k].control);
            return Err(rig_error(format!(
                "{label} share '{shared_name}', but sensor {k}'s control.{} differs from sensor {}'s: \
                 one camera takes one setting",
                keys.first().copied().unwrap_or("exposure_us"),
                group[0]
            )));
        }
        let direct = group.len() == 1 && first.crop.is_none();
        let windows: Vec<Window> = group
            .iter()
            .map(|&k| {
                let s = &rig.sensors[k];
                let [x, y, _, _] = s.crop.unwrap_or([0, 0, s.width, s.height]);
                Window {
                    sensor: k,
                    x,
                    y,
                    width: s.width,
                    height: s.height,
                }
            })
            .collect();
        let width = windows.iter().map(|w| w.x + w.width).max().unwrap_or(0);
        let height = windows.iter().map(|w| w.y + w.height).max().unwrap_or(0);
        devices.push(CaptureDevice {
            index,
            label,
            width,
            height,
            exact: direct,
            device: first.device.clone(),
            usb_serial: first.usb_serial.clone(),
            windows,
            direct,
            control: first.control.clone(),
        });
    }
    Ok(devices)
}

/// `sensor 3`, `sensors 0 and 1`, `sensors 0, 1 and 2`.
fn label(group: &[usize]) -> String {
    match group {
        [k] => format!("sensor {k}"),
        _ => {
            let mut s = String::from("sensors ");
            for (i, k) in group.iter().enumerate() {
                let sep = match i {
                    0 => "",
                    i if i + 1 == group.len() => " and ",
                    _ => ", ",
                };
                let _ = write!(s, "{sep}{k}");
            }
            s
        }
    }
}

/// Copies `window` of a device frame (RGB8, in `frame`) into `out`, the window's sensor image.
/// The caller has checked that the window lies inside the frame ([`CaptureDevice::check_fits`]).
pub fn copy_window(frame: &SensorImage, window: &Window, out: &mut SensorImage) {
    crop_into(frame.pixels(), frame.width(), 3, window, out);
}

/// Copies `window` of an 8-bit image of `src_width` columns and `channels` bytes per pixel (1
/// grey, 2 grey + alpha, 3 RGB, 4 RGBA) into `out` as RGB8. The window lies inside the image and
/// has `out`'s size; nothing is allocated.
pub fn crop_into(src: &[u8], src_width: u32, channels: usize, window: &Window, out: &mut SensorImage) {
    debug_assert_eq!((window.width, window.height), (out.width(), out.height()));
    let (w, x, y) = (window.width as usize, window.x as usize, window.y as usize);
    let row_bytes = src_width as usize * channels;
    let dst = out.pixels_mut();
    for (r, out_row) in dst.chunks_exact_mut(w * 3).enumerate() {
        let start = (y + r) * row_bytes + x * channels;
        let in_row = &src[start..start + w * channels];
        match channels {
            3 => out_row.copy_from_slice(in_row),
            4 => {
                for (d, s) in out_row.chunks_exact_mut(3).zip(in_row.chunks_exact(4)) {
                    d.copy_from_slice(&s[..3]);
                }
            }
            _ => {
                for (d, s) in out_row.chunks_exact_mut(3).zip(in_row.chunks_exact(channels)) {
                    d.fill(s[0]);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rig(sensors: &[&str]) -> Rig {
        let mut text = String::from("name = \"t\"\n");
        for (k, extra) in sensors.iter().enumerate() {
            let _ = write!(
                text,
                "[[sensors]]\nid = {k}\nresolution = [4, 3]\nmodel = \"pinhole\"\nintrinsics = [2.0, 2.0, 1.5, 1.0]\n\
                 rotation_wxyz = [1.0, 0.0, 0.0, 0.0]\ntranslation_m = [0.0, 0.0, 0.0]\n{extra}\n"
            );
        }
        Rig::from_toml_str(&text, "t.toml").unwrap()
    }

    #[test]
    fn sensors_naming_one_device_share_it_and_the_rest_stand_alone() {
        let r = rig(&[
            "device = \"/dev/video0\"\ncrop = [0, 0, 4, 3]",
            "device = \"/dev/video1\"",
            "device = \"/dev/video0\"\ncrop = [4, 1, 4, 3]",
            "",
        ]);
        let d = capture_devices(&r).unwrap();
        assert_eq!(d.len(), 3);
        assert_eq!(d[0].label, "sensors 0 and 2");
        assert_eq!(d[0].sensors().collect::<Vec<_>>(), vec![0, 2]);
        assert_eq!((d[0].width, d[0].height, d[0].exact, d[0].direct), (8, 4, false, false));
        assert_eq!(d[1].label, "sensor 1");
        assert_eq!((d[1].width, d[1].height, d[1].exact, d[1].direct), (4, 3, true, true));
        assert_eq!(d[2].label, "sensor 3");
        assert_eq!(d[2].index, 2);
        // A larger frame holds the windows; a smaller one names the window that does not fit.
        assert!(d[0].check_fits("/dev/video0", 10, 4).is_ok());
        let e = d[0].check_fits("/dev/video0", 7, 4).unwrap_err().to_string();
        assert_eq!(
            e,
            "/dev/video0: sensors 0 and 2: crop [4, 1, 4, 3] of sensor 2 lies outside the device's 7x4 frame"
        );
        let e = d[1].check_fits("/dev/video1", 5, 3).unwrap_err().to_string();
        assert_eq!(
            e,
            "/dev/video1: sensor 1: the device delivers 5x3 frames, the sensor is 4x3"
        );
    }

    #[test]
    fn a_shared_device_needs_every_sensor_cropped() {
        let r = rig(&[
            "device = \"/dev/video0\"\ncrop = [0, 0, 4, 3]",
            "device = \"/dev/video0\"",
            "device = \"/dev/video0\"\ncrop = [0, 3, 4, 3]",
        ]);
        let e = capture_devices(&r).unwrap_err().to_string();
        assert!(
            e.starts_with("t: sensors 0, 1 and 2 share '/dev/video0', but sensor 1 has no crop"),
            "{e}"
        );
        // USB cameras are shared through their serial number, every sharing sensor cropped.
        let r = rig(&[
            "usb_serial = \"A\"\ncrop = [0, 0, 4, 3]",
            "usb_serial = \"A\"\ncrop = [0, 3, 4, 3]",
        ]);
        let d = capture_devices(&r).unwrap();
        assert_eq!((d.len(), d[0].width, d[0].height), (1, 4, 6));
        assert_eq!(d[0].usb_serial.as_deref(), Some("A"));
        // They take one [control] between them: the same, or the camera could not honour both.
        let r = rig(&[
            "usb_serial = \"A\"\ncrop = [0, 0, 4, 3]\n[sensors.control]\nexposure_us = 100",
            "usb_serial = \"A\"\ncrop = [0, 3, 4, 3]\n[sensors.control]\nexposure_us = 100",
        ]);
        assert_eq!(capture_devices(&r).unwrap()[0].control, r.sensors[0].control);
        let r = rig(&[
            "usb_serial = \"A\"\ncrop = [0, 0, 4, 3]\n[sensors.control]\nexposure_us = 100",
            "usb_serial = \"A\"\ncrop = [0, 3, 4, 3]\n[sensors.control]\nexposure_us = 200\ngain = 2",
        ]);
        assert_eq!(
            capture_devices(&r).unwrap_err().to_string(),
            "t: sensors 0 and 1 share 'A', but sensor 1's control.exposure_us differs from sensor 0's: one camera takes one setting"
        );
    }

    #[test]
    fn windows_are_copied_from_any_pixel_layout() {
        // A 5×2 image whose byte at (u, v, c) is 10v + u + 60c (for c below the channel count).
        let window = Window {
            sensor: 0,
            x: 2,
            y: 1,
            width: 3,
            height: 1,
        };
        for channels in 1..=4usize {
            let src: Vec<u8> = (0..2u8)
                .flat_map(|v| (0..5u8).flat_map(move |u| (0..channels as u8).map(move |c| 10 * v + u + 60 * c)))
                .collect();
            let mut out = SensorImage::new(0, 3, 1);
            crop_into(&src, 5, channels, &window, &mut out);
            let expected: Vec<u8> = (2..5u8)
                .flat_map(|u| {
                    let p = |c: u8| 10 + u + 60 * c;
                    if channels >= 3 {
                        [p(0), p(1), p(2)]
                    } else {
                        [p(0); 3]
                    }
                })
                .collect();
            assert_eq!(out.pixels(), &expected[..], "{channels} channels");
        }
    }
}
