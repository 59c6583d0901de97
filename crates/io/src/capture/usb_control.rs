//! A USB3 Vision camera's control interface over rusb (cargo feature `usb`): the rig's
//! `[control]` applied when the camera is opened.
//!
//! In: an open camera ([`DeviceHandle`]) and the capture device's [`CameraControl`]. Out: the
//! camera set as asked, or the one-line error of [`super::control::enforce`]. The control
//! interface (class `0xEF`, subclass `0x05`, protocol `0x00`) is claimed for the time it takes
//! and released after, so that a vendor's tool may connect to it later; its bulk-OUT endpoint
//! carries GenCP commands and its bulk-IN endpoint their acknowledgements
//! ([`super::control::gencp`]).

use super::control::gencp::{ControlEndpoint, EndpointError, GenCp};
use super::control::{self, CameraControl, ControlReport};
use super::SourceError;
use rusb::{Context, Device, DeviceHandle, Direction, TransferType};
use std::time::Duration;

const U3V_CLASS: u8 = 0xEF;
const U3V_SUBCLASS: u8 = 0x05;
const U3V_PROTOCOL_CONTROL: u8 = 0x00;

/// How long a GenCP answer is waited for until the camera's bootstrap registers say.
const FIRST_TIMEOUT: Duration = Duration::from_millis(1000);

/// The control interface's bulk endpoints on an open camera.
struct UsbEndpoint<'h> {
    handle: &'h DeviceHandle<Context>,
    out: u8,
    into: u8,
}

fn failed(e: rusb::Error) -> EndpointError {
    match e {
        rusb::Error::Timeout => EndpointError::Timeout,
        e => EndpointError::Failed(format!("USB: {e}")),
    }
}

impl ControlEndpoint for UsbEndpoint<'_> {
    fn send(&mut self, packet: &[u8], timeout: Duration) -> Result<(), EndpointError> {
        let n = self.handle.write_bulk(self.out, packet, timeout).map_err(failed)?;
        if n != packet.len() {
            return Err(EndpointError::Failed(format!(
                "USB: {n} of {} bytes sent",
                packet.len()
            )));
        }
        Ok(())
    }

    fn receive(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize, EndpointError> {
        self.handle.read_bulk(self.into, buf, timeout).map_err(failed)
    }
}

/// The control interface and its bulk-OUT and bulk-IN endpoints, if the device has them.
fn control_interface(device: &Device<Context>) -> Option<(u8, u8, u8)> {
    let config = device.active_config_descriptor().ok()?;
    for interface in config.interfaces() {
        for d in interface.descriptors() {
            if (d.class_code(), d.sub_class_code(), d.protocol_code())
                != (U3V_CLASS, U3V_SUBCLASS, U3V_PROTOCOL_CONTROL)
            {
                continue;
            }
            let bulk = |dir| {
                d.endpoint_descriptors()
                    .find(|e| e.direction() == dir && e.transfer_type() == TransferType::Bulk)
                    .map(|e| e.address())
            };
            return Some((d.interface_number(), bulk(Direction::Out)?, bulk(Direction::In)?));
        }
    }
    None
}

/// Applies `wanted` to the camera (see the module doc); `name` and `label` for messages.
pub fn apply(
    device: &Device<Context>,
    handle: &DeviceHandle<Context>,
    wanted: &CameraControl,
    name: &str,
    label: &str,
) -> Result<ControlReport, SourceError> {
    let fail = |message: String| SourceError::Device {
        device: name.to_string(),
        message: format!("{label}: camera control: {message}"),
    };
    let Some((interface, out, into)) = control_interface(device) else {
        return Err(fail("no USB3 Vision control interface with bulk endpoints".into()));
    };
    handle
        .claim_interface(interface)
        .map_err(|e| fail(format!("cannot claim the control interface: {e}")))?;
    let mut cp = GenCp::new(UsbEndpoint { handle, out, into }, FIRST_TIMEOUT);
    let result = control::u3v::load_node_map(&mut cp).map(|map| {
        let mut report = ControlReport::new(name, label);
        control::u3v::apply(&map, &mut cp, wanted, &mut report);
        report
    });
    // Released whatever happened: the camera stays usable by other tools.
    let _ = handle.release_interface(interface);
    result.map_err(fail)
}
