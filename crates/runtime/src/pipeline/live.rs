//! Per-device capture: a [`SensorCapture`] per capture device of the rig (one sensor, or the
//! sensors cropped from one device's frame), each read on its own thread, and [`LiveDevice`], the
//! one for any [`LiveCamera`] driver (V4L2, USB3 Vision).
//!
//! [`LiveDevice`] keeps the behaviour of the capture module's whole-rig `LiveSource`, per device:
//! a failed read marks its sensors' images invalid with its fault; a device that is gone
//! (unplugged, I/O error, [`LOST_AFTER_TIMEOUTS`] timeouts in a row) is closed, logged, and
//! reopened every `reopen_interval` while the other devices go on (the wait for it ends at a
//! stop); coming back is logged too.
//! What every (re)opening shares (e.g. the USB context) sits behind a mutex, taken only to open.
//! A device split into windows reads into a frame buffer sized at (re)opening and copies each
//! window into its sensor's image.
//!
//! Imports run one way: the [`SensorCapture`] trait and the [`PipelineSource`] that holds its
//! implementations are `options`'s; this file implements and builds them.

use super::options::{PipelineSource, SensorCapture};
use omnitrack_core::frame::{ImageFault, SensorImage};
use omnitrack_core::rig::Rig;
use omnitrack_io::capture::device::{capture_devices, copy_window, CaptureDevice};
use omnitrack_io::capture::live::{open_device, FailureDetail, LiveCamera, LOST_AFTER_TIMEOUTS};
use omnitrack_io::capture::{
    open_source_with, sleep_until_or_stop, FrameSource, SourceError, SourceOptions, SourceSpec,
};
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// Warnings of one fault kind per device logged at `warn` before the rest go to `debug`.
const WARN_LIMIT: u32 = 5;

/// The [`SensorCapture`] of one [`LiveCamera`]. See the module doc.
pub struct LiveDevice<C: LiveCamera> {
    device: CaptureDevice,
    sensors: Vec<usize>,
    env: Arc<Mutex<C::Env>>,
    options: SourceOptions,
    camera: Option<C>,
    /// The whole frame of a device split into windows; `None` for a direct device.
    scratch: Option<SensorImage>,
    /// The device name of the last connection, for messages while disconnected.
    name: String,
    retry_at: Instant,
    timeouts: u32,
    warned: [u32; ImageFault::ALL.len()],
}

impl<C: LiveCamera> std::fmt::Debug for LiveDevice<C> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LiveDevice")
            .field("sensors", &self.device.label)
            .field("device", &self.name)
            .field("connected", &self.camera.is_some())
            .finish()
    }
}

impl<C: LiveCamera> LiveDevice<C> {
    /// Whether the camera is connected now.
    pub fn is_connected(&self) -> bool {
        self.camera.is_some()
    }

    fn warn(&mut self, fault: ImageFault, detail: &FailureDetail) {
        let n = &mut self.warned[fault.index()];
        *n = n.saturating_add(1);
        let sensors = &self.device.label;
        if *n <= WARN_LIMIT {
            tracing::warn!(%sensors, device = %self.name, %fault, "{detail}");
        } else {
            tracing::debug!(%sensors, device = %self.name, %fault, "{detail}");
        }
    }

    fn reopen(&mut self, now: Instant) {
        let opened = {
            let mut env = self.env.lock().unwrap_or_else(|e| e.into_inner());
            open_device::<C>(&mut env, &self.device, &self.options, &mut self.scratch)
        };
        let sensors = &self.device.label;
        match opened {
            Ok(camera) => {
                tracing::warn!(%sensors, device = camera.name(), "connected again, capturing");
                self.name.clear();
                self.name.push_str(camera.name());
                self.camera = Some(camera);
                self.timeouts = 0;
            }
            Err(e) => {
                self.retry_at = now + self.options.reopen_interval;
                let n = &mut self.warned[ImageFault::Missing.index()];
                *n = n.saturating_add(1);
                if *n <= WARN_LIMIT {
                    tracing::warn!(%sensors, interval = ?self.options.reopen_interval, "{e} (still unavailable, retrying)");
                }
            }
        }
    }
}

impl<C: LiveCamera> SensorCapture for LiveDevice<C> {
    fn sensors(&self) -> &[usize] {
        &self.sensors
    }

    fn capture(&mut self, imgs: &mut [&mut SensorImage], stop: &dyn Fn() -> bool) -> Result<bool, SourceError> {
        let now = Instant::now();
        if self.camera.is_none() {
            // Nothing to read: wait for the reopening attempt rather than spin (a stop does
            // not wait for it).
            let at = self.retry_at.min(now + self.options.reopen_interval);
            if !sleep_until_or_stop(Some(at), stop) {
                return Ok(false);
            }
            self.reopen(Instant::now());
        }
        let Some(camera) = self.camera.as_mut() else {
            for img in imgs.iter_mut() {
                img.set_invalid(ImageFault::Missing, 0);
            }
            return Ok(true);
        };
        let read = match self.scratch.as_mut() {
            None => camera.read_or_stop(imgs[0], stop),
            Some(frame) => camera.read_or_stop(frame, stop),
        };
        match read {
            // Given up for the stop: nothing captured, nothing counted.
            Err(failure) if failure.detail == FailureDetail::Stopped => return Ok(false),
            Ok(ts) => {
                for (img, w) in imgs.iter_mut().zip(&self.device.windows) {
                    if let Some(frame) = self.scratch.as_ref() {
                        copy_window(frame, w, img);
                    }
                    img.set_valid(ts);
                }
                self.timeouts = 0;
            }
            Err(failure) => {
                for img in imgs.iter_mut() {
                    img.set_invalid(failure.fault, 0);
                }
                let timed_out = failure.detail == FailureDetail::TimedOut;
                self.timeouts = if timed_out { self.timeouts + 1 } else { 0 };
                if failure.lost || self.timeouts >= LOST_AFTER_TIMEOUTS {
                    // Dropping the camera closes the device.
                    self.camera = None;
                    self.retry_at = now + self.options.reopen_interval;
                    self.timeouts = 0;
                    tracing::warn!(
                        sensors = %self.device.label,
                        device = %self.name,
                        interval = ?self.options.reopen_interval,
                        "lost ({}); going on without it, reopening",
                        failure.detail
                    );
                } else {
                    self.warn(failure.fault, &failure.detail);
                }
            }
        }
        Ok(true)
    }
}

/// Opens the camera of every capture device of `rig` ([`capture_devices`]) with driver `C` (one
/// [`LiveDevice`] each, read on its own thread by the pipeline). The first camera that fails is
/// the error: one line naming device and sensors.
pub fn live_sensors<C: LiveCamera + 'static>(
    rig: &Rig,
    env: C::Env,
    options: &SourceOptions,
) -> Result<PipelineSource, SourceError>
where
    C::Env: 'static,
{
    let env = Arc::new(Mutex::new(env));
    let now = Instant::now();
    let devices = capture_devices(rig)?;
    let mut sensors: Vec<Box<dyn SensorCapture>> = Vec::with_capacity(devices.len());
    for device in devices {
        let mut scratch = None;
        let camera = {
            let mut e = env.lock().unwrap_or_else(|e| e.into_inner());
            open_device::<C>(&mut e, &device, options, &mut scratch)?
        };
        sensors.push(Box::new(LiveDevice::<C> {
            sensors: device.sensors().collect(),
            device,
            env: Arc::clone(&env),
            options: *options,
            name: camera.name().to_string(),
            camera: Some(camera),
            scratch,
            retry_at: now,
            timeouts: 0,
            warned: [0; ImageFault::ALL.len()],
        }));
    }
    Ok(PipelineSource::Sensors {
        rig: rig.clone(),
        sensors,
    })
}

/// Opens the source `spec` names (`replay:DIR`, `v4l`, `usb`) for the pipeline: live drivers
/// built into this binary as one [`SensorCapture`] per capture device (one capture thread each), anything
/// else as the whole-rig source of [`open_source_with`] (one capture thread), whose errors —
/// including a live source left out of the build, with the cargo command that enables it — are
/// one line each.
pub fn open_pipeline_source(
    spec: &SourceSpec,
    rig: Option<&Rig>,
    options: &SourceOptions,
) -> Result<PipelineSource, SourceError> {
    match (spec, rig) {
        #[cfg(feature = "v4l")]
        (SourceSpec::V4l, Some(rig)) => live_sensors::<omnitrack_io::capture::v4l2::V4l2Camera>(rig, (), options),
        #[cfg(feature = "usb")]
        (SourceSpec::Usb, Some(rig)) => {
            let env = omnitrack_io::capture::usb::UsbEnv::new(rig)?;
            live_sensors::<omnitrack_io::capture::usb::UsbCamera>(rig, env, options)
        }
        _ => open_source_with(spec, rig, options).map(PipelineSource::from),
    }
}

impl From<Box<dyn FrameSource + Send>> for PipelineSource {
    fn from(source: Box<dyn FrameSource + Send>) -> Self {
        PipelineSource::Rig(source)
    }
}
