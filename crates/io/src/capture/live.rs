//! What the live sources share: [`LiveSource`], the frame source of both live drivers.
//!
//! In: the rig, split into capture devices ([`capture_devices`]), and one [`LiveCamera`]
//! implementation (V4L2 in `v4l2`, USB3 Vision in `usb`), with [`SourceOptions`]. Out: frames
//! through [`FrameSource::next_frame`], [`SourceStats`], and the per-read failure vocabulary
//! ([`ReadFailure`], [`FailureDetail`]) the drivers report in.
//!
//! [`LiveSource`] holds one camera per capture device (per sensor, or shared by the sensors
//! cropped from its frame, see [`super::device`]): each [`FrameSource::next_frame`] reads one
//! frame from every connected device in turn, straight into the sensor's image or, for a shared
//! device, into a frame buffer sized at opening whose windows are copied into the sensors'
//! images. A device whose read fails marks its sensors invalid for that frame (the
//! [`ImageFault`] counted and warned, rate-limited); when the failure means the device is gone
//! (unplugged, I/O error, or [`LOST_AFTER_TIMEOUTS`] timeouts in a row) it is closed, reported on
//! standard error, and reopened every [`SourceOptions::reopen_interval`] until it comes back
//! (reported again); the other devices go on meanwhile. With no device connected, `next_frame`
//! waits for the next reopening attempt instead of spinning (`next_frame_or_stop`: until a stop).
//!
//! Clock: image timestamps are nanoseconds of the host's monotonic clock: the drivers' own
//! (V4L2 buffers stamped `CLOCK_MONOTONIC`) or, where a driver has none, [`host_time_ns`], the
//! time since the first call in this process (also monotonic, but another origin).
//!
//! Imports run one way: the drivers use this file, and `open` (which picks a source) uses the
//! drivers; nothing here knows which drivers exist.

use super::device::{capture_devices, copy_window, CaptureDevice};
use super::spec::SourceOptions;
use super::{sleep_until_or_stop, FrameSource, SourceError, SourceStats, WarningKind, WarningLimiter};
use omnitrack_core::frame::{FrameSet, ImageFault, SensorImage};
use omnitrack_core::rig::Rig;
use std::fmt;
use std::sync::OnceLock;
use std::time::{Duration, Instant};

/// Timeouts in a row after which a live sensor counts as lost and is reopened.
pub const LOST_AFTER_TIMEOUTS: u32 = 3;

/// Warnings of one kind printed before the rest are only counted.
const WARN_LIMIT: u32 = 5;

/// Nanoseconds since the first call in this process, monotonic.
pub fn host_time_ns() -> u64 {
    static EPOCH: OnceLock<Instant> = OnceLock::new();
    EPOCH.get_or_init(Instant::now).elapsed().as_nanos() as u64
}

/// Why one read of a live sensor gave no image. Small and `Copy`: nothing is built per frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FailureDetail {
    /// No image within [`SourceOptions::frame_timeout`].
    TimedOut,
    /// An operating-system error number.
    Os(i32),
    /// The image arrived but could not be converted.
    Convert(super::convert::ConvertError),
    /// A USB3 Vision block was rejected.
    U3v(super::u3v::RejectReason),
    /// Anything else, in a few words.
    Text(&'static str),
    /// The read was given up because the run is stopping ([`LiveCamera::read_or_stop`]): not a
    /// fault of the camera, never counted.
    Stopped,
}

impl fmt::Display for FailureDetail {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FailureDetail::TimedOut => f.write_str("no image in time"),
            FailureDetail::Os(code) => write!(f, "{}", std::io::Error::from_raw_os_error(*code)),
            FailureDetail::Convert(e) => write!(f, "{e}"),
            FailureDetail::U3v(r) => write!(f, "USB3 Vision block rejected: {r}"),
            FailureDetail::Text(t) => f.write_str(t),
            FailureDetail::Stopped => f.write_str("stopped"),
        }
    }
}

/// One failed read of a live sensor.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReadFailure {
    /// What the sensor's image is marked with for this frame.
    pub fault: ImageFault,
    /// Whether the device is gone (closed and reopened later) rather than one image lost.
    pub lost: bool,
    pub detail: FailureDetail,
}

/// A live camera: a V4L2 device or a USB3 Vision camera, delivering the images of one or more
/// sensors of the rig ([`CaptureDevice`]).
pub trait LiveCamera: Sized + Send {
    /// What every (re)opening shares (e.g. the USB context); `()` when nothing.
    type Env: Send;

    /// Opens the camera of `device`, asking for its `width × height` frames (exactly, when
    /// `device.exact`; else at least that). Errors are one line naming the device and its
    /// sensors (`device.label`).
    fn open(env: &mut Self::Env, device: &CaptureDevice, options: &SourceOptions) -> Result<Self, SourceError>;

    /// The device, for messages (e.g. `/dev/video0`).
    fn name(&self) -> &str;

    /// The size of the frames it delivers, as negotiated when it was opened.
    fn frame_size(&self) -> (u32, u32);

    /// Reads the next frame into `img`'s pixels (an image of [`LiveCamera::frame_size`], not
    /// marked); returns its timestamp (ns).
    fn read(&mut self, img: &mut SensorImage) -> Result<u64, ReadFailure>;

    /// [`read`](Self::read), given up as soon as `stop` says so: a driver that waits for its
    /// device waits in slices of at most [`READ_SLICE`] and returns [`FailureDetail::Stopped`]
    /// when `stop` is true between them, so that a stop is honoured within a tenth of a second
    /// rather than a frame timeout (a second) later. The default reads without looking at `stop`
    /// (a camera whose reads do not wait).
    fn read_or_stop(&mut self, img: &mut SensorImage, stop: &dyn Fn() -> bool) -> Result<u64, ReadFailure> {
        let _ = stop;
        self.read(img)
    }

    /// What the camera made of the rig's `[control]` when it was opened (`None`: nothing was
    /// asked, or the driver has no control channel).
    fn control_report(&self) -> Option<&super::control::ControlReport> {
        None
    }
}

/// The longest a live read waits before it looks at the run's stop flag again.
pub const READ_SLICE: Duration = Duration::from_millis(20);

/// The failure of a read given up for a stop.
pub const STOPPED: ReadFailure = ReadFailure {
    fault: ImageFault::Dropped,
    lost: false,
    detail: FailureDetail::Stopped,
};

/// Opens `device`'s camera and checks that its frames hold every window; sizes `scratch` (the
/// frame buffer of a device split into windows) to the negotiated frame.
pub fn open_device<C: LiveCamera>(
    env: &mut C::Env,
    device: &CaptureDevice,
    options: &SourceOptions,
    scratch: &mut Option<SensorImage>,
) -> Result<C, SourceError> {
    let camera = C::open(env, device, options)?;
    let (w, h) = camera.frame_size();
    device.check_fits(camera.name(), w, h)?;
    if !device.direct && scratch.as_ref().is_none_or(|s| (s.width(), s.height()) != (w, h)) {
        // Only at (re)opening, never per frame.
        *scratch = Some(SensorImage::new(device.windows[0].sensor, w, h));
    }
    Ok(camera)
}

/// One device's camera slot: connected or waiting to be reopened.
struct Slot<C> {
    device: CaptureDevice,
    camera: Option<C>,
    /// The whole frame of a device split into windows; `None` for a direct device.
    scratch: Option<SensorImage>,
    /// The device name of the last connection, for messages while disconnected.
    name: String,
    retry_at: Instant,
    timeouts: u32,
}

/// The [`FrameSource`] of a live driver: one [`LiveCamera`] per capture device. See the module
/// doc.
pub struct LiveSource<C: LiveCamera> {
    rig: Rig,
    env: C::Env,
    options: SourceOptions,
    slots: Vec<Slot<C>>,
    /// Device slot of each sensor.
    slot_of: Vec<usize>,
    stats: SourceStats,
    warnings: WarningLimiter,
    sequence: u64,
}

impl<C: LiveCamera> fmt::Debug for LiveSource<C> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("LiveSource")
            .field("rig", &self.rig.name)
            .field("connected", &self.connected())
            .field("sequence", &self.sequence)
            .finish()
    }
}

impl<C: LiveCamera> LiveSource<C> {
    /// Opens every capture device's camera ([`capture_devices`]); the first that fails is the
    /// error (one line naming device and sensors). The frame buffers are the caller's
    /// ([`FrameSet::for_rig`]); each device sizes its own scratch space here.
    pub fn open_with_env(rig: Rig, mut env: C::Env, options: SourceOptions) -> Result<LiveSource<C>, SourceError> {
        let now = Instant::now();
        let devices = capture_devices(&rig)?;
        let mut slot_of = vec![0; rig.sensors.len()];
        let mut slots = Vec::with_capacity(devices.len());
        for (d, device) in devices.into_iter().enumerate() {
            let mut scratch = None;
            let camera = open_device::<C>(&mut env, &device, &options, &mut scratch)?;
            for k in device.sensors() {
                slot_of[k] = d;
            }
            slots.push(Slot {
                name: camera.name().to_string(),
                device,
                camera: Some(camera),
                scratch,
                retry_at: now,
                timeouts: 0,
            });
        }
        Ok(LiveSource {
            stats: SourceStats::new(rig.sensors.len()),
            rig,
            env,
            options,
            slots,
            slot_of,
            warnings: WarningLimiter::new(WARN_LIMIT),
            sequence: 0,
        })
    }

    /// Whether a sensor's camera is connected now, by sensor id.
    pub fn is_connected(&self, sensor: usize) -> bool {
        self.slot_of
            .get(sensor)
            .is_some_and(|&d| self.slots[d].camera.is_some())
    }

    /// Devices connected now.
    pub fn connected(&self) -> usize {
        self.slots.iter().filter(|s| s.camera.is_some()).count()
    }

    /// The camera of a sensor, if connected.
    pub fn camera(&self, sensor: usize) -> Option<&C> {
        self.slot_of.get(sensor).and_then(|&d| self.slots[d].camera.as_ref())
    }

    /// Marks every sensor of device `d` invalid with `fault` and counts it.
    fn fail_device(&mut self, d: usize, fault: ImageFault, out: &mut FrameSet) {
        for w in &self.slots[d].device.windows {
            out.sensor_mut(w.sensor).set_invalid(fault, 0);
            self.stats.sensors[w.sensor].count(fault);
        }
    }

    /// Reads device `d` into `out`; false when the read was given up for `stop` (nothing
    /// counted).
    fn capture(&mut self, d: usize, out: &mut FrameSet, stop: &dyn Fn() -> bool) -> bool {
        let now = Instant::now();
        let slot = &mut self.slots[d];
        if slot.camera.is_none() && now >= slot.retry_at {
            match open_device::<C>(&mut self.env, &slot.device, &self.options, &mut slot.scratch) {
                Ok(camera) => {
                    eprintln!("{} ({}): connected again, capturing", slot.device.label, camera.name());
                    self.stats.warnings_printed += 1;
                    slot.name.clear();
                    slot.name.push_str(camera.name());
                    slot.camera = Some(camera);
                    slot.timeouts = 0;
                }
                Err(e) => {
                    slot.retry_at = now + self.options.reopen_interval;
                    self.warnings.warn(
                        &mut self.stats,
                        WarningKind::Image(ImageFault::Missing),
                        format_args!(
                            "{e} (still unavailable, retrying every {:?})",
                            self.options.reopen_interval
                        ),
                    );
                }
            }
        }
        let Some(camera) = slot.camera.as_mut() else {
            self.fail_device(d, ImageFault::Missing, out);
            return true;
        };
        let read = match slot.scratch.as_mut() {
            None => camera.read_or_stop(out.sensor_mut(slot.device.windows[0].sensor), stop),
            Some(frame) => camera.read_or_stop(frame, stop),
        };
        match read {
            Err(failure) if failure.detail == FailureDetail::Stopped => return false,
            Ok(ts) => {
                for w in &slot.device.windows {
                    let img = out.sensor_mut(w.sensor);
                    if let Some(frame) = slot.scratch.as_ref() {
                        copy_window(frame, w, img);
                    }
                    img.set_valid(ts);
                    self.stats.sensors[w.sensor].delivered += 1;
                }
                slot.timeouts = 0;
            }
            Err(failure) => {
                let timed_out = failure.detail == FailureDetail::TimedOut;
                slot.timeouts = if timed_out { slot.timeouts + 1 } else { 0 };
                let lost = failure.lost || slot.timeouts >= LOST_AFTER_TIMEOUTS;
                if lost {
                    // Dropping the camera closes the device.
                    slot.camera = None;
                    slot.retry_at = now + self.options.reopen_interval;
                    slot.timeouts = 0;
                    eprintln!(
                        "{} ({}): lost ({}); going on without it, reopening every {:?}",
                        slot.device.label, slot.name, failure.detail, self.options.reopen_interval
                    );
                    self.stats.warnings_printed += 1;
                } else {
                    self.warnings.warn(
                        &mut self.stats,
                        WarningKind::Image(failure.fault),
                        format_args!("{} ({}): {}", slot.device.label, slot.name, failure.detail),
                    );
                }
                self.fail_device(d, failure.fault, out);
            }
        }
        true
    }
}

impl<C: LiveCamera> FrameSource for LiveSource<C> {
    fn rig(&self) -> &Rig {
        &self.rig
    }

    fn next_frame(&mut self, out: &mut FrameSet) -> Result<bool, SourceError> {
        self.next_frame_or_stop(out, &|| false)
    }

    fn next_frame_or_stop(&mut self, out: &mut FrameSet, stop: &dyn Fn() -> bool) -> Result<bool, SourceError> {
        if !out.fits(&self.rig) {
            return Err(SourceError::FrameSetMismatch {
                rig: self.rig.name.clone(),
            });
        }
        if self.connected() == 0 {
            // Nothing to read: wait for the next reopening attempt rather than spin (a stop
            // does not wait for it).
            let now = Instant::now();
            if let Some(at) = self.slots.iter().map(|s| s.retry_at).min() {
                let at = at.min(now + self.options.reopen_interval);
                if !sleep_until_or_stop(Some(at), stop) {
                    return Ok(false);
                }
            }
        }
        for d in 0..self.slots.len() {
            // A read given up for the stop: the frame is not delivered, half read.
            if !self.capture(d, out, stop) {
                return Ok(false);
            }
        }
        out.sequence = self.sequence;
        self.sequence += 1;
        self.stats.frames_delivered += 1;
        Ok(true)
    }

    fn stats(&self) -> &SourceStats {
        &self.stats
    }

    fn control_reports(&self) -> Vec<super::control::ControlReport> {
        self.slots
            .iter()
            .filter_map(|s| s.camera.as_ref()?.control_report().cloned())
            .collect()
    }
}
