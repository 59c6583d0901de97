//! Live capture from V4L2 devices (cargo feature `v4l`): one device per capture device of the rig
//! (per sensor, or shared by the sensors cropped from its frame, [`super::device`]).
//!
//! In: the rig, whose sensors each name a `device` (e.g. `/dev/video0`). Out: [`V4l2Source`], a
//! [`FrameSource`](super::FrameSource) ([`LiveSource`] over [`V4l2Camera`]) delivering every
//! sensor's latest image per frame, converted into the frame set's RGB8 buffers.
//!
//! Opening a device: the device is opened (errors: no `device` key, no such device, permission
//! denied, busy, not a streaming capture device — one line each naming the device and its
//! sensors), and the first format of [`PREFERENCE`] the device offers is set at the capture
//! device's size (the sensor's resolution; for a device split into crops, the smallest frame
//! holding them, where a larger frame the driver settles on is accepted):
//! `RGB3`, then `YUYV`, `MJPG`, `GREY`, then the 8-bit Bayer mosaics `RGGB`, `GRBG`, `GBRG`,
//! `BA81` (BGGR). A device whose offered formats all fail at that size is an error listing what it
//! offers. Then [`BUFFERS`] driver buffers are memory-mapped and streaming starts on the first read.
//!
//! Camera control: when the sensors ask for it (`[control]` of the rig file), the exposure,
//! gain, white balance and frame interval are set once the format is, before the buffers are
//! requested, and each is read back ([`super::control::v4l2`] over [`super::v4l2_ioctl`]); under
//! the default [`ControlPolicy::Enforce`](super::ControlPolicy) a control the device refuses,
//! lacks or changes fails the opening in one line.
//!
//! Reading: each read waits (up to the frame timeout; after the first, which starts the stream,
//! in polls of [`READ_SLICE`] with the run's stop looked at between them) for the next filled
//! buffer, converts its
//! bytes (`bytesused`, the driver's row stride) with [`convert`] into the sensor's
//! image and takes the driver's timestamp (`CLOCK_MONOTONIC` for almost every driver; when a
//! driver gives none, [`host_time_ns`]). A buffer flagged as erroneous or too short is a corrupt
//! image; a timeout is a dropped one; `ENODEV`, `EIO` and other errors mean the device is lost,
//! and [`LiveSource`] reopens it every second until it is back. YUYV is taken as BT.601 video
//! range.
//!
//! Latency: sensors are read in turn, each its oldest filled buffer; a consumer slower than the
//! cameras sees images up to [`BUFFERS`] frames old (the driver drops new frames while every
//! buffer is full). A pipeline that wants the latest image of each sensor runs one reader per
//! sensor ([`V4l2Camera`] through [`LiveCamera`]).
//!
//! Allocation: opening allocates (format lists, mappings); reading allocates nothing, except
//! MJPEG decoding inside the `image` crate (a copy of the compressed frame and decoder state per
//! frame; see [`convert`]). Failure messages may allocate when printed.
//!
//! Teardown: the `v4l` crate panics in its stream destructor if stopping the stream fails with
//! anything but `ENODEV`; this module stops the stream itself first and, should that fail, leaks
//! the stream (its mappings and file descriptor) rather than panic.

use super::convert::{self, BayerPattern, ConvertError, YuvOrder, YuvRange};
use super::device::CaptureDevice;
use super::live::{host_time_ns, FailureDetail, LiveCamera, LiveSource, ReadFailure, READ_SLICE, STOPPED};
use super::spec::SourceOptions;
use super::SourceError;
use omnitrack_core::frame::{ImageFault, SensorImage};
use omnitrack_core::rig::Rig;
use std::io;
use v4l::buffer::{Flags, Type};
use v4l::capability::Flags as CapFlags;
use v4l::io::mmap::Stream;
use v4l::io::traits::{CaptureStream, Stream as _};
use v4l::video::Capture;
use v4l::{Device, Format, FourCC};

/// poll(2)'s "data to read" event (the same on every Linux architecture).
const POLLIN: i16 = 0x001;

/// A read that found no frame within the frame timeout: a dropped image.
const TIMED_OUT: ReadFailure = ReadFailure {
    fault: ImageFault::Dropped,
    lost: false,
    detail: FailureDetail::TimedOut,
};

/// A device error while reading: the device is lost (unplugged, I/O error) and reopened later.
fn device_lost(e: &io::Error, what: &'static str) -> ReadFailure {
    ReadFailure {
        fault: ImageFault::Missing,
        lost: true,
        detail: match e.raw_os_error() {
            Some(code) => FailureDetail::Os(code),
            None => FailureDetail::Text(what),
        },
    }
}

/// Driver buffers memory-mapped per device.
pub const BUFFERS: u32 = 4;

/// A pixel format this module converts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum V4l2Format {
    /// `RGB3`: packed RGB8.
    Rgb3,
    /// `YUYV`: packed YUV 4:2:2.
    Yuyv,
    /// `MJPG`: one JPEG per frame.
    Mjpeg,
    /// `GREY`: 8-bit luminance.
    Grey,
    /// `RGGB`, `GRBG`, `GBRG`, `BA81`: 8-bit Bayer mosaics.
    Bayer(BayerPattern),
}

/// Formats in order of preference (cheapest conversion and best quality first).
pub const PREFERENCE: [V4l2Format; 8] = [
    V4l2Format::Rgb3,
    V4l2Format::Yuyv,
    V4l2Format::Mjpeg,
    V4l2Format::Grey,
    V4l2Format::Bayer(BayerPattern::Rggb),
    V4l2Format::Bayer(BayerPattern::Grbg),
    V4l2Format::Bayer(BayerPattern::Gbrg),
    V4l2Format::Bayer(BayerPattern::Bggr),
];

impl V4l2Format {
    /// The V4L2 four-character code.
    pub fn fourcc(self) -> [u8; 4] {
        match self {
            V4l2Format::Rgb3 => *b"RGB3",
            V4l2Format::Yuyv => *b"YUYV",
            V4l2Format::Mjpeg => *b"MJPG",
            V4l2Format::Grey => *b"GREY",
            V4l2Format::Bayer(BayerPattern::Rggb) => *b"RGGB",
            V4l2Format::Bayer(BayerPattern::Grbg) => *b"GRBG",
            V4l2Format::Bayer(BayerPattern::Gbrg) => *b"GBRG",
            V4l2Format::Bayer(BayerPattern::Bggr) => *b"BA81",
        }
    }

    /// Bytes per pixel of the raw formats (0 for MJPEG).
    fn bytes_per_pixel(self) -> usize {
        match self {
            V4l2Format::Rgb3 => 3,
            V4l2Format::Yuyv => 2,
            V4l2Format::Mjpeg => 0,
            V4l2Format::Grey | V4l2Format::Bayer(_) => 1,
        }
    }

    /// The code as text.
    pub fn name(self) -> &'static str {
        match self {
            V4l2Format::Rgb3 => "RGB3",
            V4l2Format::Yuyv => "YUYV",
            V4l2Format::Mjpeg => "MJPG",
            V4l2Format::Grey => "GREY",
            V4l2Format::Bayer(BayerPattern::Rggb) => "RGGB",
            V4l2Format::Bayer(BayerPattern::Grbg) => "GRBG",
            V4l2Format::Bayer(BayerPattern::Gbrg) => "GBRG",
            V4l2Format::Bayer(BayerPattern::Bggr) => "BA81",
        }
    }

    /// Converts one raw image into RGB8 `out`.
    pub fn to_rgb(
        self,
        src: &[u8],
        width: u32,
        height: u32,
        stride: usize,
        out: &mut [u8],
    ) -> Result<(), ConvertError> {
        match self {
            V4l2Format::Rgb3 => convert::rgb_to_rgb(src, width, height, stride, out),
            V4l2Format::Yuyv => {
                convert::yuv422_to_rgb(src, width, height, stride, YuvOrder::Yuyv, YuvRange::Limited, out)
            }
            V4l2Format::Mjpeg => convert::jpeg_to_rgb(src, width, height, out),
            V4l2Format::Grey => convert::grey_to_rgb(src, width, height, stride, out),
            V4l2Format::Bayer(p) => convert::bayer_to_rgb(src, width, height, stride, p, out),
        }
    }
}

/// The formats to try, in [`PREFERENCE`] order, among the four-character codes a device offers.
pub fn candidates(offered: &[[u8; 4]]) -> impl Iterator<Item = V4l2Format> + '_ {
    PREFERENCE.into_iter().filter(move |f| offered.contains(&f.fourcc()))
}

/// The V4L2 frame source: one [`V4l2Camera`] per sensor.
pub type V4l2Source = LiveSource<V4l2Camera>;

impl LiveSource<V4l2Camera> {
    /// Opens every sensor's device (see the module doc); errors name the device and the sensor.
    pub fn open(rig: Rig, options: SourceOptions) -> Result<V4l2Source, SourceError> {
        LiveSource::open_with_env(rig, (), options)
    }
}

/// One sensor's V4L2 device, streaming.
pub struct V4l2Camera {
    path: String,
    /// Its sensors, for messages.
    label: String,
    width: u32,
    height: u32,
    format: V4l2Format,
    stride: usize,
    /// How long a read waits for a frame.
    frame_timeout: std::time::Duration,
    /// The device's handle, polled for a filled buffer a slice at a time.
    handle: std::sync::Arc<v4l::device::Handle>,
    /// Whether the stream has been started (by the first read).
    streaming: bool,
    /// `Some` until dropped; taken by [`Drop`] to stop it without panicking.
    stream: Option<Stream<'static>>,
    /// What the device made of the rig's `[control]`, if anything was asked.
    control: Option<super::control::ControlReport>,
    /// Kept open for the stream's lifetime.
    _device: Device,
}

impl std::fmt::Debug for V4l2Camera {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("V4l2Camera")
            .field("path", &self.path)
            .field("format", &self.format)
            .field("stride", &self.stride)
            .finish()
    }
}

impl V4l2Camera {
    /// The negotiated format.
    pub fn format(&self) -> V4l2Format {
        self.format
    }

    /// The driver's row stride (bytes per line) of raw formats.
    pub fn stride(&self) -> usize {
        self.stride
    }
}

/// One line for an error of opening or configuring a device.
fn device_error(path: &str, sensors: &str, what: &str, e: &io::Error) -> SourceError {
    let why = match (e.kind(), e.raw_os_error()) {
        (io::ErrorKind::NotFound, _) | (_, Some(2)) => "no such device".to_string(),
        (io::ErrorKind::PermissionDenied, _) | (_, Some(13)) => {
            "permission denied (is the user in the 'video' group?)".to_string()
        }
        (_, Some(16)) => "device busy (another program is using it)".to_string(),
        (_, Some(19)) | (_, Some(6)) => "device disappeared".to_string(),
        (_, Some(25)) => "not a V4L2 device".to_string(),
        _ => format!("{what}: {e}"),
    };
    SourceError::Device {
        device: path.to_string(),
        message: format!("{sensors}: {why}"),
    }
}

impl LiveCamera for V4l2Camera {
    type Env = ();

    fn open(_env: &mut (), target: &CaptureDevice, options: &SourceOptions) -> Result<V4l2Camera, SourceError> {
        let id = &target.label;
        let Some(path) = target.device.as_deref() else {
            return Err(SourceError::Device {
                device: "v4l".into(),
                message: format!(
                    "{id} has no 'device' key in the rig file (e.g. device = \"/dev/video{}\")",
                    target.index
                ),
            });
        };
        let fail = |what: &str, e: &io::Error| device_error(path, id, what, e);
        let device = Device::with_path(path).map_err(|e| fail("cannot open", &e))?;
        let caps = device.query_caps().map_err(|e| fail("cannot query capabilities", &e))?;
        if !caps
            .capabilities
            .contains(CapFlags::VIDEO_CAPTURE | CapFlags::STREAMING)
        {
            return Err(SourceError::Device {
                device: path.into(),
                message: format!("{id}: '{}' is not a video capture device with streaming I/O", caps.card),
            });
        }
        let offered: Vec<[u8; 4]> = device
            .enum_formats()
            .map_err(|e| fail("cannot list formats", &e))?
            .iter()
            .map(|d| d.fourcc.repr)
            .collect();
        let (w, h) = (target.width, target.height);
        let size_ok = |sw: u32, sh: u32| {
            if target.exact {
                (sw, sh) == (w, h)
            } else {
                sw >= w && sh >= h
            }
        };
        let mut chosen = None;
        for format in candidates(&offered) {
            let set = device
                .set_format(&Format::new(w, h, FourCC::new(&format.fourcc())))
                .map_err(|e| fail("cannot set format", &e))?;
            if size_ok(set.width, set.height) && set.fourcc.repr == format.fourcc() {
                chosen = Some((format, set));
                break;
            }
        }
        let Some((format, set)) = chosen else {
            let names: Vec<String> = offered
                .iter()
                .map(|c| String::from_utf8_lossy(c).into_owned())
                .collect();
            let supported: Vec<&str> = PREFERENCE.iter().map(|f| f.name()).collect();
            return Err(SourceError::Device {
                device: path.into(),
                message: format!(
                    "{id}: no supported format at {w}x{h} (device offers: {}; supported: {})",
                    if names.is_empty() {
                        "none".into()
                    } else {
                        names.join(", ")
                    },
                    supported.join(", ")
                ),
            });
        };
        // Before the buffers are requested: drivers refuse a new frame interval (EBUSY) once
        // buffers are allocated.
        let mut control = None;
        if !target.control.is_empty() {
            let mut report = super::control::ControlReport::new(path, id);
            let mut io = super::v4l2_ioctl::DeviceControls::new(&device);
            super::control::v4l2::apply(&mut io, &target.control, &mut report);
            super::control::settle(&report, options.control)?;
            control = Some(report);
        }
        // The driver's size: larger than asked for a device split into crops.
        let (w, h) = (set.width, set.height);
        let packed = w as usize * format.bytes_per_pixel();
        let stride = (set.stride as usize).max(packed);
        let mut stream =
            Stream::with_buffers(&device, Type::VideoCapture, BUFFERS).map_err(|e| fail("cannot map buffers", &e))?;
        stream.set_timeout(options.frame_timeout);
        Ok(V4l2Camera {
            path: path.to_string(),
            label: target.label.clone(),
            width: w,
            height: h,
            format,
            stride,
            frame_timeout: options.frame_timeout,
            handle: device.handle(),
            streaming: false,
            stream: Some(stream),
            control,
            _device: device,
        })
    }

    fn name(&self) -> &str {
        &self.path
    }

    fn frame_size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    fn control_report(&self) -> Option<&super::control::ControlReport> {
        self.control.as_ref()
    }

    fn read(&mut self, img: &mut SensorImage) -> Result<u64, ReadFailure> {
        self.read_or_stop(img, &|| false)
    }

    fn read_or_stop(&mut self, img: &mut SensorImage, stop: &dyn Fn() -> bool) -> Result<u64, ReadFailure> {
        let Some(stream) = self.stream.as_mut() else {
            return Err(ReadFailure {
                fault: ImageFault::Missing,
                lost: true,
                detail: FailureDetail::Text("stream closed"),
            });
        };
        // Once streaming, a filled buffer is waited for here, a slice at a time with the stop
        // looked at between slices; the stream's own wait (the whole frame timeout) then finds
        // it ready. Not through the stream: after its wait times out it queues its last buffer
        // again on the next call, which the driver refuses. The first read starts the stream
        // and waits in it.
        if self.streaming {
            let deadline = std::time::Instant::now() + self.frame_timeout;
            loop {
                if stop() {
                    return Err(STOPPED);
                }
                let left = deadline.saturating_duration_since(std::time::Instant::now());
                if left.is_zero() {
                    return Err(TIMED_OUT);
                }
                let ms = left.min(READ_SLICE).as_millis().clamp(1, 1000) as i32;
                match self.handle.poll(POLLIN, ms) {
                    Ok(0) => continue,
                    Ok(_) => break,
                    Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                    Err(e) => return Err(device_lost(&e, "poll failed")),
                }
            }
        }
        self.streaming = true;
        let next = CaptureStream::next(stream);
        let (buf, meta) = match next {
            Ok(x) => x,
            Err(e) if e.kind() == io::ErrorKind::TimedOut => return Err(TIMED_OUT),
            Err(e) => return Err(device_lost(&e, "read failed")),
        };
        if meta.flags.contains(Flags::ERROR) {
            return Err(ReadFailure {
                fault: ImageFault::Corrupt,
                lost: false,
                detail: FailureDetail::Text("driver flagged the buffer as corrupted"),
            });
        }
        let used = match meta.bytesused as usize {
            0 => buf.len(),
            n => n.min(buf.len()),
        };
        self.format
            .to_rgb(&buf[..used], self.width, self.height, self.stride, img.pixels_mut())
            .map_err(|e| ReadFailure {
                fault: e.fault(),
                lost: false,
                detail: FailureDetail::Convert(e),
            })?;
        let (sec, usec) = (meta.timestamp.sec, meta.timestamp.usec);
        let ts = if sec > 0 || usec > 0 {
            (sec.max(0) as u64) * 1_000_000_000 + (usec.max(0) as u64) * 1_000
        } else {
            host_time_ns()
        };
        Ok(ts)
    }
}

impl Drop for V4l2Camera {
    fn drop(&mut self) {
        let Some(mut stream) = self.stream.take() else {
            return;
        };
        match stream.stop() {
            // Stopped (or the device is gone, which v4l's destructor tolerates): its destructor
            // stops again and unmaps; guard against a panic there all the same.
            Ok(()) => drop_guarded(stream),
            Err(e) if e.raw_os_error() == Some(19) => drop_guarded(stream),
            Err(e) => {
                eprintln!(
                    "warning: {} ({}): cannot stop streaming ({e}); leaking its buffers rather than panic",
                    self.path, self.label
                );
                std::mem::forget(stream);
            }
        }
    }
}

fn drop_guarded(stream: Stream<'static>) {
    let _ = std::panic::catch_unwind(std::panic::AssertUnwindSafe(move || drop(stream)));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn preference_order_picks_the_cheapest_offered() {
        let offered = [*b"MJPG", *b"YUYV", *b"GRBG"];
        let order: Vec<V4l2Format> = candidates(&offered).collect();
        assert_eq!(
            order,
            vec![
                V4l2Format::Yuyv,
                V4l2Format::Mjpeg,
                V4l2Format::Bayer(BayerPattern::Grbg)
            ]
        );
        assert_eq!(candidates(&[*b"H264"]).count(), 0);
        assert_eq!(candidates(&[*b"RGB3", *b"GREY"]).next(), Some(V4l2Format::Rgb3));
    }
}
