//! Live capture from USB3 Vision cameras over libusb (cargo feature `usb`): one camera per capture
//! device of the rig (per sensor, or shared by the sensors cropped from its frame,
//! [`super::device`]).
//!
//! In: the rig with its `[usb]` table (`vendor_id`, `product_id`) and, optionally, each sensor's
//! `usb_serial` ([`UsbRig`]). Out: [`UsbSource`], a [`FrameSource`](super::FrameSource)
//! ([`LiveSource`] over [`UsbCamera`]) delivering one image per sensor per frame in the frame
//! set's RGB8 buffers.
//!
//! Finding the cameras: an explicit `rusb::Context` is created (never libusb's global context,
//! which panics in `rusb` where there is no USB bus); every device with the rig's vendor and
//! product id is a candidate. A sensor with `usb_serial` takes the camera with that serial number
//! (sensors naming the same serial share its frame through crops); without serials, capture device
//! *k* (sensor *k* when no sensors share a camera) takes the *k*-th camera in USB port order (bus,
//! then port path) and keeps that port: when it is lost it is reopened at the same port, so that the mapping follows
//! the cabling. On the camera, the USB3 Vision streaming interface (class `0xEF`, subclass `0x05`,
//! protocol `0x02`) is claimed (detaching a kernel driver if one is bound) and its bulk-IN
//! endpoint is read in transfers of [`TRANSFER_SIZE`] bytes into the [`u3v`](super::u3v) parser,
//! which assembles and checks the blocks; a complete image is converted into the sensor's buffer.
//! Errors (no USB bus, no such camera, permission denied, busy, not a USB3 Vision device) are one
//! line naming the camera and the sensor.
//!
//! Timestamps are [`host_time_ns`] when a frame's trailer arrives: the cameras' own tick
//! counters are not on one clock.
//!
//! Camera control: a capture device whose sensors have a `[control]` table gets it through the
//! camera's control interface when it is opened (and reopened), before frames are read
//! ([`super::usb_control`]: exposure, gain, frame rate, white balance, trigger, each read back);
//! a key the camera refuses, lacks or changes stops the opening with one line. Not done here: the
//! image format and acquisition start (GenICam's `PixelFormat`, `Width`, `Height`,
//! `AcquisitionStart`), so the cameras must already be set to the sensor's size and a supported
//! pixel format and be acquiring (e.g. with the vendor's tool and saved user settings that start
//! acquisition at power-up). Frames of another size or format are rejected and counted, never
//! shown.
//!
//! Allocation: opening allocates (device lists, the transfer buffer and the parser's payload
//! buffer); reading allocates nothing in Rust. libusb's synchronous bulk transfer allocates its
//! transfer structure with C `malloc` on each call, outside Rust's allocator.

use super::device::CaptureDevice;
use super::live::{host_time_ns, FailureDetail, LiveCamera, LiveSource, ReadFailure, READ_SLICE, STOPPED};
use super::spec::SourceOptions;
use super::u3v::{U3vEvent, U3vStream};
use super::SourceError;
use omnitrack_core::frame::{ImageFault, SensorImage};
use omnitrack_core::rig::{Rig, UsbRig};
use rusb::{Context, Device, DeviceHandle, Direction, TransferType, UsbContext};
use std::time::{Duration, Instant};

/// Bytes asked of each bulk read (a multiple of every USB packet size).
pub const TRANSFER_SIZE: usize = 512 * 1024;

/// USB3 Vision interface class, subclass and streaming protocol.
const U3V_CLASS: u8 = 0xEF;
const U3V_SUBCLASS: u8 = 0x05;
const U3V_PROTOCOL_STREAM: u8 = 0x02;

/// What every (re)opening shares: the libusb context, the ids, and each sensor's USB port.
pub struct UsbEnv {
    context: Context,
    usb: UsbRig,
    /// (bus, port path) of each sensor's camera once found.
    ports: Vec<Option<(u8, Vec<u8>)>>,
}

impl UsbEnv {
    /// A libusb context for the rig's cameras; fails (one line) where libusb cannot start, e.g.
    /// on a machine without a USB bus.
    pub fn new(rig: &Rig) -> Result<UsbEnv, SourceError> {
        let Some(usb) = rig.usb else {
            return Err(SourceError::Device {
                device: "usb".into(),
                message: format!(
                    "rig '{}' has no [usb] table: add [usb] with vendor_id and product_id of its cameras",
                    rig.name
                ),
            });
        };
        let context = Context::new().map_err(|e| SourceError::Device {
            device: "usb".into(),
            message: format!("cannot start libusb: {e} (is there a USB bus on this machine?)"),
        })?;
        Ok(UsbEnv {
            context,
            usb,
            // At most one camera per sensor.
            ports: vec![None; rig.sensors.len()],
        })
    }

    fn ids(&self) -> String {
        format!("usb {:04x}:{:04x}", self.usb.vendor_id, self.usb.product_id)
    }
}

/// The USB3 Vision frame source: one [`UsbCamera`] per sensor.
pub type UsbSource = LiveSource<UsbCamera>;

impl LiveSource<UsbCamera> {
    /// Finds and opens every sensor's camera (see the module doc).
    pub fn open(rig: Rig, options: SourceOptions) -> Result<UsbSource, SourceError> {
        let env = UsbEnv::new(&rig)?;
        LiveSource::open_with_env(rig, env, options)
    }
}

/// One sensor's USB3 Vision camera, its streaming interface claimed.
pub struct UsbCamera {
    name: String,
    handle: DeviceHandle<Context>,
    endpoint: u8,
    buffer: Box<[u8]>,
    parser: U3vStream,
    /// The frame size the parser accepts: the capture device's (cameras are not configured here,
    /// see the module doc).
    size: (u32, u32),
    timeout: Duration,
    /// What the camera made of the rig's `[control]`, if anything was asked.
    control: Option<super::control::ControlReport>,
}

impl std::fmt::Debug for UsbCamera {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("UsbCamera")
            .field("name", &self.name)
            .field("endpoint", &self.endpoint)
            .finish()
    }
}

impl UsbCamera {
    /// The stream parser's counters (blocks delivered and rejected by reason).
    pub fn stream_stats(&self) -> &super::u3v::U3vStats {
        self.parser.stats()
    }
}

fn usb_error(device: &str, sensors: &str, what: &str, e: rusb::Error) -> SourceError {
    let why = match e {
        rusb::Error::Access => "permission denied (add a udev rule giving the user access to the camera)".to_string(),
        rusb::Error::Busy => "busy (claimed by another program or driver)".to_string(),
        rusb::Error::NoDevice => "device disappeared".to_string(),
        e => format!("{what}: {e}"),
    };
    SourceError::Device {
        device: device.to_string(),
        message: format!("{sensors}: {why}"),
    }
}

/// Bus and port path of a device (its place in the cabling).
fn port_of(device: &Device<Context>) -> (u8, Vec<u8>) {
    (device.bus_number(), device.port_numbers().unwrap_or_default())
}

/// The U3V streaming interface and its bulk-IN endpoint, if the device has one.
fn streaming_endpoint(device: &Device<Context>) -> Option<(u8, u8)> {
    let config = device.active_config_descriptor().ok()?;
    for interface in config.interfaces() {
        for d in interface.descriptors() {
            if (d.class_code(), d.sub_class_code(), d.protocol_code()) != (U3V_CLASS, U3V_SUBCLASS, U3V_PROTOCOL_STREAM)
            {
                continue;
            }
            let endpoint = d
                .endpoint_descriptors()
                .find(|e| e.direction() == Direction::In && e.transfer_type() == TransferType::Bulk)?;
            return Some((d.interface_number(), endpoint.address()));
        }
    }
    None
}

impl LiveCamera for UsbCamera {
    type Env = UsbEnv;

    fn open(env: &mut UsbEnv, target: &CaptureDevice, options: &SourceOptions) -> Result<UsbCamera, SourceError> {
        let label = target.label.as_str();
        let id = target.index;
        let ids = env.ids();
        let list = env
            .context
            .devices()
            .map_err(|e| usb_error(&ids, label, "cannot list USB devices", e))?;
        let mut cameras: Vec<(u8, Vec<u8>, Device<Context>)> = list
            .iter()
            .filter(|d| {
                d.device_descriptor()
                    .is_ok_and(|desc| desc.vendor_id() == env.usb.vendor_id && desc.product_id() == env.usb.product_id)
            })
            .map(|d| {
                let (bus, ports) = port_of(&d);
                (bus, ports, d)
            })
            .collect();
        cameras.sort_by(|a, b| (a.0, &a.1).cmp(&(b.0, &b.1)));
        let found = cameras.len();
        let mut chosen = None;
        if let Some(serial) = target.usb_serial.as_deref() {
            for (_, _, device) in &cameras {
                let Ok(desc) = device.device_descriptor() else { continue };
                let Ok(handle) = device.open() else { continue };
                let read = handle.read_serial_number_string_ascii(&desc);
                if read.as_deref() == Ok(serial) {
                    chosen = Some((device.clone(), handle));
                    break;
                }
            }
            if chosen.is_none() {
                return Err(SourceError::Device {
                    device: ids,
                    message: format!(
                        "{label}: no camera with serial '{serial}' ({found} camera(s) with these ids on the bus)"
                    ),
                });
            }
        } else {
            let device = match &env.ports[id] {
                Some((bus, ports)) => cameras
                    .iter()
                    .find(|c| c.0 == *bus && &c.1 == ports)
                    .map(|c| c.2.clone()),
                None => cameras.get(id).map(|c| c.2.clone()),
            };
            let Some(device) = device else {
                let place = match &env.ports[id] {
                    Some((bus, ports)) => format!("at its port (bus {bus}, ports {ports:?})"),
                    None => format!("({label} takes camera {} in port order; {found} found)", id + 1),
                };
                return Err(SourceError::Device {
                    device: ids,
                    message: format!("{label}: no camera {place}"),
                });
            };
            let handle = device.open().map_err(|e| usb_error(&ids, label, "cannot open", e))?;
            chosen = Some((device, handle));
        }
        let Some((device, handle)) = chosen else {
            return Err(SourceError::Device {
                device: ids,
                message: format!("{label}: no camera"),
            });
        };
        let (bus, ports) = port_of(&device);
        let name = format!("{ids} bus {bus} ports {ports:?}");
        let Some((interface, endpoint)) = streaming_endpoint(&device) else {
            return Err(SourceError::Device {
                device: name,
                message: format!("{label}: not a USB3 Vision camera (no streaming interface with a bulk-IN endpoint)"),
            });
        };
        // Not every platform can detach kernel drivers; claiming reports what matters.
        let _ = handle.set_auto_detach_kernel_driver(true);
        handle
            .claim_interface(interface)
            .map_err(|e| usb_error(&name, label, "cannot claim the streaming interface", e))?;
        let mut control = None;
        if !target.control.is_empty() {
            let report = super::usb_control::apply(&device, &handle, &target.control, &name, label)?;
            super::control::settle(&report, options.control)?;
            control = Some(report);
        }
        env.ports[id] = Some((bus, ports));
        Ok(UsbCamera {
            name,
            handle,
            endpoint,
            buffer: vec![0u8; TRANSFER_SIZE].into_boxed_slice(),
            parser: U3vStream::new(target.width, target.height),
            size: (target.width, target.height),
            timeout: options.frame_timeout,
            control,
        })
    }

    fn name(&self) -> &str {
        &self.name
    }

    fn frame_size(&self) -> (u32, u32) {
        self.size
    }

    fn control_report(&self) -> Option<&super::control::ControlReport> {
        self.control.as_ref()
    }

    fn read(&mut self, img: &mut SensorImage) -> Result<u64, ReadFailure> {
        self.read_or_stop(img, &|| false)
    }

    fn read_or_stop(&mut self, img: &mut SensorImage, stop: &dyn Fn() -> bool) -> Result<u64, ReadFailure> {
        let deadline = Instant::now() + self.timeout;
        loop {
            // Transfers of at most READ_SLICE, the stop looked at between them: a block cut by
            // a slice's end goes on in the next transfer (the parser keeps its state).
            if stop() {
                return Err(STOPPED);
            }
            let left = deadline.saturating_duration_since(Instant::now()).min(READ_SLICE);
            if left.is_zero() {
                return Err(ReadFailure {
                    fault: ImageFault::Dropped,
                    lost: false,
                    detail: FailureDetail::TimedOut,
                });
            }
            let n = match self.handle.read_bulk(self.endpoint, &mut self.buffer, left) {
                Ok(n) => n,
                Err(rusb::Error::Timeout) => continue,
                Err(rusb::Error::Overflow) => {
                    self.parser.reset();
                    return Err(ReadFailure {
                        fault: ImageFault::Corrupt,
                        lost: false,
                        detail: FailureDetail::Text("USB transfer overflow"),
                    });
                }
                Err(e) => {
                    self.parser.reset();
                    return Err(ReadFailure {
                        fault: ImageFault::Missing,
                        lost: true,
                        detail: FailureDetail::Text(usb_error_text(e)),
                    });
                }
            };
            let mut outcome: Option<Result<(), ReadFailure>> = None;
            let pixels = img.pixels_mut();
            self.parser.push(&self.buffer[..n], |event| match event {
                U3vEvent::Frame(frame) => {
                    outcome = Some(frame.to_rgb(pixels).map_err(|e| ReadFailure {
                        fault: e.fault(),
                        lost: false,
                        detail: FailureDetail::Convert(e),
                    }));
                }
                // A whole block rejected; a run of garbage (no block id) is only counted.
                U3vEvent::Rejected {
                    reason,
                    block_id: Some(_),
                } => {
                    if matches!(outcome, Some(Ok(()))) {
                        return;
                    }
                    outcome = Some(Err(ReadFailure {
                        fault: reason.fault(),
                        lost: false,
                        detail: FailureDetail::U3v(reason),
                    }));
                }
                U3vEvent::Rejected { block_id: None, .. } => {}
            });
            match outcome {
                Some(Ok(())) => return Ok(host_time_ns()),
                Some(Err(failure)) => return Err(failure),
                None => {}
            }
        }
    }
}

/// A few words for a libusb error.
fn usb_error_text(e: rusb::Error) -> &'static str {
    match e {
        rusb::Error::Io => "USB I/O error",
        rusb::Error::InvalidParam => "invalid USB parameter",
        rusb::Error::Access => "USB access denied",
        rusb::Error::NoDevice => "camera disconnected",
        rusb::Error::NotFound => "USB entity not found",
        rusb::Error::Busy => "USB resource busy",
        rusb::Error::Timeout => "USB timeout",
        rusb::Error::Overflow => "USB transfer overflow",
        rusb::Error::Pipe => "USB endpoint stalled",
        rusb::Error::Interrupted => "USB transfer interrupted",
        rusb::Error::NoMem => "libusb out of memory",
        rusb::Error::NotSupported => "not supported by libusb here",
        rusb::Error::BadDescriptor => "malformed USB descriptor",
        rusb::Error::Other => "other USB error",
    }
}
