//! GenCP over a USB3 Vision control endpoint: register reads and writes of a camera.
//!
//! In: a [`ControlEndpoint`] (the camera's control interface: class `0xEF`, subclass `0x05`,
//! protocol `0x00`, a bulk-OUT and a bulk-IN endpoint; or a fake in the tests). Out: [`GenCp`],
//! which reads and writes device memory ([`GenCp::read_mem`], [`GenCp::write_mem`]) in
//! commands and acknowledgements of the U3V flavour of GenCP, or a [`GenCpError`] of one line.
//!
//! Packets, little-endian (USB3 Vision 1.0, §5.5; GenCP 1.x):
//!
//! | packet | bytes |
//! | --- | --- |
//! | command prefix | `magic` u32 = `U3VC` (0x43563355), `flags` u16 (0x4000: ack wanted), `command_id` u16, `length` u16 (of what follows), `request_id` u16 |
//! | ack prefix | `magic` u32, `status` u16, `command_id` u16, `length` u16, `request_id` u16 |
//! | READMEM_CMD 0x0800 | address u64, reserved u16, read length u16 |
//! | READMEM_ACK 0x0801 | the bytes read |
//! | WRITEMEM_CMD 0x0802 | address u64, the bytes to write |
//! | WRITEMEM_ACK 0x0803 | reserved u16, bytes written u16 (may be absent: length 0) |
//! | PENDING_ACK 0x0805 | reserved u16, time to wait more in ms u16 |
//!
//! Every command carries the next request id (wrapping, never 0); an ack with another id (late,
//! from a command given up earlier) is read and dropped. A PENDING_ACK extends the wait by the
//! time it names. A non-zero status is an error named by [`status_text`]. Reads and writes
//! longer than the device's transfer lengths (from its SBRM, [`GenCp::set_max_lengths`]) are
//! split. Nothing panics on any bytes the device sends.

use std::fmt;
use std::time::{Duration, Instant};

/// `U3VC`, read little-endian.
pub const MAGIC: u32 = 0x4356_3355;
/// Flag of a command that wants its acknowledgement.
pub const FLAG_REQUEST_ACK: u16 = 0x4000;
pub const READMEM_CMD: u16 = 0x0800;
pub const READMEM_ACK: u16 = 0x0801;
pub const WRITEMEM_CMD: u16 = 0x0802;
pub const WRITEMEM_ACK: u16 = 0x0803;
pub const PENDING_ACK: u16 = 0x0805;
/// Bytes of a command's or an ack's prefix.
pub const PREFIX_LEN: usize = 12;

/// GenCP status codes (GenCP 1.x, Table "Status codes"; the 0xA… ones are USB3 Vision's).
pub const STATUS_SUCCESS: u16 = 0x0000;
pub const STATUS_NOT_IMPLEMENTED: u16 = 0x8001;
pub const STATUS_INVALID_PARAMETER: u16 = 0x8002;
pub const STATUS_INVALID_ADDRESS: u16 = 0x8003;
pub const STATUS_WRITE_PROTECT: u16 = 0x8004;
pub const STATUS_BAD_ALIGNMENT: u16 = 0x8005;
pub const STATUS_ACCESS_DENIED: u16 = 0x8006;
pub const STATUS_BUSY: u16 = 0x8007;
pub const STATUS_MSG_TIMEOUT: u16 = 0x800B;
pub const STATUS_INVALID_HEADER: u16 = 0x800E;
pub const STATUS_WRONG_CONFIG: u16 = 0x800F;
pub const STATUS_ERROR: u16 = 0x8FFF;

/// The name of a status code.
pub fn status_text(status: u16) -> &'static str {
    match status {
        STATUS_SUCCESS => "success",
        STATUS_NOT_IMPLEMENTED => "not implemented",
        STATUS_INVALID_PARAMETER => "invalid parameter",
        STATUS_INVALID_ADDRESS => "invalid address",
        STATUS_WRITE_PROTECT => "write protected",
        STATUS_BAD_ALIGNMENT => "bad alignment",
        STATUS_ACCESS_DENIED => "access denied",
        STATUS_BUSY => "busy",
        STATUS_MSG_TIMEOUT => "message timeout",
        STATUS_INVALID_HEADER => "invalid header",
        STATUS_WRONG_CONFIG => "wrong configuration",
        STATUS_ERROR => "generic error",
        0xA001 => "resend not supported",
        0xA002 => "stream endpoint halted",
        0xA003 => "payload size not aligned",
        0xA004 => "stream registers inconsistent",
        0xA100 => "data discarded",
        0xA101 => "data overrun",
        _ => "unknown status",
    }
}

/// What went wrong on the endpoint itself.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum EndpointError {
    /// Nothing came within the time given.
    Timeout,
    /// The transfer failed (a USB error, the camera gone), in a few words.
    Failed(String),
}

/// A camera's control channel: one bulk-OUT and one bulk-IN endpoint.
pub trait ControlEndpoint {
    /// Sends one command packet whole.
    fn send(&mut self, packet: &[u8], timeout: Duration) -> Result<(), EndpointError>;
    /// Receives one acknowledgement packet into `buf`; its length.
    fn receive(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize, EndpointError>;
}

/// A register access that failed: one line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum GenCpError {
    Endpoint {
        address: u64,
        error: EndpointError,
    },
    /// The device answered with a non-zero status.
    Status {
        address: u64,
        status: u16,
    },
    /// The device's answer does not parse as the ack expected.
    Malformed {
        address: u64,
        what: &'static str,
    },
}

impl fmt::Display for GenCpError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            GenCpError::Endpoint {
                address,
                error: EndpointError::Timeout,
            } => write!(f, "no answer from the camera for register 0x{address:x}"),
            GenCpError::Endpoint {
                address,
                error: EndpointError::Failed(why),
            } => write!(f, "register 0x{address:x}: {why}"),
            GenCpError::Status { address, status } => {
                write!(
                    f,
                    "register 0x{address:x}: status 0x{status:04x} ({})",
                    status_text(*status)
                )
            }
            GenCpError::Malformed { address, what } => write!(f, "register 0x{address:x}: {what}"),
        }
    }
}

impl std::error::Error for GenCpError {}

/// The GenCP client of one camera. See the module doc.
pub struct GenCp<E> {
    endpoint: E,
    request_id: u16,
    /// Bytes a command and an ack may have, prefix included.
    max_command: usize,
    max_ack: usize,
    timeout: Duration,
    packet: Vec<u8>,
    ack: Vec<u8>,
    /// Acks of other requests read and dropped.
    stale_acks: u64,
}

/// Transfer lengths every U3V device takes (the SBRM's minimum) until it says more.
const DEFAULT_MAX_LEN: usize = 1024;
/// Longest PENDING_ACK chain followed before giving up (each may ask up to 65 s).
const MAX_PENDING: usize = 16;

impl<E: ControlEndpoint> GenCp<E> {
    /// A client over `endpoint`, each ack waited for up to `timeout` (the ABRM's maximum
    /// device response time is a good value).
    pub fn new(endpoint: E, timeout: Duration) -> GenCp<E> {
        GenCp {
            endpoint,
            request_id: 0,
            max_command: DEFAULT_MAX_LEN,
            max_ack: DEFAULT_MAX_LEN,
            timeout,
            packet: Vec::with_capacity(DEFAULT_MAX_LEN),
            ack: vec![0; DEFAULT_MAX_LEN],
            stale_acks: 0,
        }
    }

    /// The largest command and ack the device takes (SBRM `Maximum Command Transfer Length`
    /// and `Maximum Acknowledge Transfer Length`); values too small for a prefix and a word are
    /// ignored.
    pub fn set_max_lengths(&mut self, command: usize, ack: usize) {
        if command >= PREFIX_LEN + 16 {
            self.max_command = command.min(PREFIX_LEN + u16::MAX as usize);
        }
        if ack >= PREFIX_LEN + 16 {
            self.max_ack = ack.min(PREFIX_LEN + u16::MAX as usize);
            self.ack.resize(self.max_ack, 0);
        }
    }

    pub fn set_timeout(&mut self, timeout: Duration) {
        self.timeout = timeout;
    }

    /// Acks of other requests dropped so far.
    pub fn stale_acks(&self) -> u64 {
        self.stale_acks
    }

    pub fn endpoint_mut(&mut self) -> &mut E {
        &mut self.endpoint
    }

    fn next_id(&mut self) -> u16 {
        self.request_id = self.request_id.wrapping_add(1).max(1);
        self.request_id
    }

    /// Reads `len` bytes of device memory at `address`.
    pub fn read_mem(&mut self, address: u64, len: usize) -> Result<Vec<u8>, GenCpError> {
        let mut out = Vec::with_capacity(len);
        let chunk = (self.max_ack - PREFIX_LEN).min(u16::MAX as usize);
        while out.len() < len {
            let at = address.wrapping_add(out.len() as u64);
            let n = chunk.min(len - out.len());
            let id = self.next_id();
            self.packet.clear();
            push_prefix(&mut self.packet, READMEM_CMD, 12, id);
            self.packet.extend_from_slice(&at.to_le_bytes());
            self.packet.extend_from_slice(&0u16.to_le_bytes());
            self.packet.extend_from_slice(&(n as u16).to_le_bytes());
            let body = self.transact(at, READMEM_ACK, id)?;
            if body.len() != n {
                return Err(GenCpError::Malformed {
                    address: at,
                    what: "READMEM_ACK of another length than asked",
                });
            }
            out.extend_from_slice(&self.ack[PREFIX_LEN..PREFIX_LEN + n]);
        }
        Ok(out)
    }

    /// Writes `data` to device memory at `address`.
    pub fn write_mem(&mut self, address: u64, data: &[u8]) -> Result<(), GenCpError> {
        let chunk = self.max_command - PREFIX_LEN - 8;
        let mut done = 0;
        loop {
            let at = address.wrapping_add(done as u64);
            let n = chunk.min(data.len() - done);
            let id = self.next_id();
            self.packet.clear();
            push_prefix(&mut self.packet, WRITEMEM_CMD, (8 + n) as u16, id);
            self.packet.extend_from_slice(&at.to_le_bytes());
            self.packet.extend_from_slice(&data[done..done + n]);
            let body = self.transact(at, WRITEMEM_ACK, id)?;
            if body.len() >= 4 {
                let written = u16::from_le_bytes([self.ack[PREFIX_LEN + 2], self.ack[PREFIX_LEN + 3]]) as usize;
                if written != n {
                    return Err(GenCpError::Malformed {
                        address: at,
                        what: "WRITEMEM_ACK reports fewer bytes written than sent",
                    });
                }
            }
            done += n;
            if done >= data.len() {
                return Ok(());
            }
        }
    }

    /// Sends `self.packet` and waits for its ack; the range of the ack's body in `self.ack`.
    fn transact(&mut self, address: u64, want: u16, id: u16) -> Result<std::ops::Range<usize>, GenCpError> {
        let endpoint_error = |error| GenCpError::Endpoint { address, error };
        self.endpoint.send(&self.packet, self.timeout).map_err(endpoint_error)?;
        let mut deadline = Instant::now() + self.timeout;
        let mut pending = 0;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(endpoint_error(EndpointError::Timeout));
            }
            let n = self.endpoint.receive(&mut self.ack, left).map_err(endpoint_error)?;
            let malformed = |what| GenCpError::Malformed { address, what };
            if n < PREFIX_LEN {
                return Err(malformed("an ack shorter than its prefix"));
            }
            let a = &self.ack[..n];
            let magic = u32::from_le_bytes([a[0], a[1], a[2], a[3]]);
            let status = u16::from_le_bytes([a[4], a[5]]);
            let command = u16::from_le_bytes([a[6], a[7]]);
            let length = u16::from_le_bytes([a[8], a[9]]) as usize;
            let ack_id = u16::from_le_bytes([a[10], a[11]]);
            if magic != MAGIC {
                return Err(malformed("an ack without the U3VC prefix"));
            }
            if PREFIX_LEN + length > n {
                return Err(malformed("an ack shorter than its length field"));
            }
            if ack_id != id {
                // The late answer to a command given up before: not ours.
                self.stale_acks += 1;
                continue;
            }
            if command == PENDING_ACK && status == STATUS_SUCCESS {
                pending += 1;
                if pending > MAX_PENDING || length < 4 {
                    return Err(malformed("PENDING_ACK without end"));
                }
                let ms = u16::from_le_bytes([a[PREFIX_LEN + 2], a[PREFIX_LEN + 3]]);
                deadline = Instant::now() + Duration::from_millis(u64::from(ms)) + self.timeout;
                continue;
            }
            if status != STATUS_SUCCESS {
                return Err(GenCpError::Status { address, status });
            }
            if command != want {
                return Err(malformed("an ack of another command"));
            }
            return Ok(PREFIX_LEN..PREFIX_LEN + length);
        }
    }
}

fn push_prefix(out: &mut Vec<u8>, command: u16, length: u16, id: u16) {
    out.extend_from_slice(&MAGIC.to_le_bytes());
    out.extend_from_slice(&FLAG_REQUEST_ACK.to_le_bytes());
    out.extend_from_slice(&command.to_le_bytes());
    out.extend_from_slice(&length.to_le_bytes());
    out.extend_from_slice(&id.to_le_bytes());
}
