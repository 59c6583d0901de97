//! A fake USB3 Vision camera at the control endpoint: it parses GenCP command packets (prefix,
//! flags, command id, length, request id), answers READMEM and WRITEMEM with their acks and the
//! status codes a camera gives (invalid address, write protected, invalid header), and can
//! answer late (PENDING_ACK), answer a stale request id first, or not answer. Its memory holds
//! the bootstrap registers, a manifest, the GenICam file (`camera.xml`, plain or zipped) and the
//! feature registers that file describes, where the frame rate is limited by the exposure as a
//! real sensor's is.

use omnitrack_io::capture::control::gencp::*;
use omnitrack_io::capture::control::genicam::zip::crc32;
use std::collections::VecDeque;
use std::ops::Range;
use std::time::Duration;

pub const CAMERA_XML: &str = include_str!("camera.xml");

pub const SBRM: u64 = 0x1000;
pub const MANIFEST: u64 = 0x2000;
pub const FILE: u64 = 0x10000;
pub const EXPOSURE_AUTO: u64 = 0x20000;
pub const EXPOSURE: u64 = 0x20004;
pub const GAIN_AUTO: u64 = 0x20008;
pub const GAIN_RAW: u64 = 0x2000C;
pub const WHITE_AUTO: u64 = 0x20010;
pub const FLAGS: u64 = 0x20014;
pub const FRAME_RATE: u64 = 0x20018;
pub const TRIGGER_SELECTOR: u64 = 0x20024;
pub const TRIGGER: u64 = 0x20020;
const MEMORY: usize = 0x20040;

pub struct FakeCamera {
    pub memory: Vec<u8>,
    /// Ranges a WRITEMEM answers "write protected" (0x8004) to.
    pub protected: Vec<Range<u64>>,
    /// Ranges backed by memory; anything else is "invalid address" (0x8003).
    mapped: Vec<Range<u64>>,
    acks: VecDeque<Vec<u8>>,
    /// Answer the next commands with a PENDING_ACK first.
    pub pending: u32,
    /// Answer the next command with an ack of the previous request id first.
    pub stale: bool,
    /// Answer nothing at all.
    pub silent: bool,
    pub max_ack: u32,
    /// Every command's (command id, request id), in order.
    pub commands: Vec<(u16, u16)>,
}

/// A ZIP archive of one file, `method` 0 (stored) or 8 (deflated), as a camera's manifest
/// would hold it.
pub fn zip(name: &str, data: &[u8], method: u16) -> Vec<u8> {
    let packed = if method == 8 {
        miniz_oxide::deflate::compress_to_vec(data, 6)
    } else {
        data.to_vec()
    };
    let crc = crc32(data);
    let mut z = Vec::new();
    let header = |z: &mut Vec<u8>, sig: u32, central: bool| {
        z.extend_from_slice(&sig.to_le_bytes());
        if central {
            z.extend_from_slice(&20u16.to_le_bytes());
        }
        z.extend_from_slice(&20u16.to_le_bytes());
        z.extend_from_slice(&0u16.to_le_bytes());
        z.extend_from_slice(&method.to_le_bytes());
        z.extend_from_slice(&[0; 4]);
        z.extend_from_slice(&crc.to_le_bytes());
        z.extend_from_slice(&(packed.len() as u32).to_le_bytes());
        z.extend_from_slice(&(data.len() as u32).to_le_bytes());
        z.extend_from_slice(&(name.len() as u16).to_le_bytes());
        z.extend_from_slice(&0u16.to_le_bytes());
    };
    header(&mut z, 0x0403_4b50, false);
    z.extend_from_slice(name.as_bytes());
    z.extend_from_slice(&packed);
    let central = z.len();
    header(&mut z, 0x0201_4b50, true);
    // Comment length, disk, internal and external attributes, and the local header at 0.
    z.extend_from_slice(&[0; 14]);
    z.extend_from_slice(name.as_bytes());
    let central_len = z.len() - central;
    z.extend_from_slice(&0x0605_4b50u32.to_le_bytes());
    z.extend_from_slice(&[0; 4]);
    z.extend_from_slice(&1u16.to_le_bytes());
    z.extend_from_slice(&1u16.to_le_bytes());
    z.extend_from_slice(&(central_len as u32).to_le_bytes());
    z.extend_from_slice(&(central as u32).to_le_bytes());
    z.extend_from_slice(&0u16.to_le_bytes());
    z
}

impl FakeCamera {
    /// A camera whose manifest holds `file` (zipped when `zipped`), with the feature registers
    /// at their power-up values: auto exposure, 10 ms, auto gain, 30 Hz, the acquisition-start trigger selected, trigger off.
    pub fn new(file: &[u8], zipped: bool) -> FakeCamera {
        let mut c = FakeCamera {
            memory: vec![0; MEMORY],
            protected: vec![
                0..0x300,
                SBRM..SBRM + 0x40,
                MANIFEST..MANIFEST + 0x48,
                FILE..FILE + file.len() as u64,
            ],
            mapped: vec![
                0..0x300,
                SBRM..SBRM + 0x40,
                MANIFEST..MANIFEST + 0x48,
                FILE..FILE + file.len() as u64,
                0x20000..0x20040,
            ],
            acks: VecDeque::new(),
            pending: 0,
            stale: false,
            silent: false,
            max_ack: 256,
            commands: Vec::new(),
        };
        c.put(0x1CC, &500u32.to_le_bytes());
        c.put(0x1D0, &MANIFEST.to_le_bytes());
        c.put(0x1D8, &SBRM.to_le_bytes());
        c.put(SBRM + 0x14, &256u32.to_le_bytes());
        c.put(SBRM + 0x18, &256u32.to_le_bytes());
        c.put(MANIFEST, &1u64.to_le_bytes());
        c.put(MANIFEST + 8, &0x0101_0000u32.to_le_bytes());
        c.put(MANIFEST + 12, &(u32::from(zipped) << 10).to_le_bytes());
        c.put(MANIFEST + 16, &FILE.to_le_bytes());
        c.put(MANIFEST + 24, &(file.len() as u64).to_le_bytes());
        c.memory.resize(MEMORY.max((FILE as usize) + file.len()), 0);
        c.put(FILE, file);
        c.put(EXPOSURE_AUTO, &2u32.to_le_bytes());
        c.put(EXPOSURE, &10_000f32.to_le_bytes());
        c.put(GAIN_AUTO, &2u32.to_le_bytes());
        c.put(WHITE_AUTO, &2u32.to_le_bytes());
        c.put(FRAME_RATE, &30f64.to_le_bytes());
        c.put(TRIGGER_SELECTOR, &1u32.to_le_bytes());
        c
    }

    /// The camera with `camera.xml` as a deflated ZIP, as most cameras ship it.
    pub fn standard() -> FakeCamera {
        FakeCamera::new(&zip("FakeCam.xml", CAMERA_XML.as_bytes(), 8), true)
    }

    pub fn put(&mut self, at: u64, bytes: &[u8]) {
        self.memory[at as usize..at as usize + bytes.len()].copy_from_slice(bytes);
    }

    pub fn u32_at(&self, at: u64) -> u32 {
        u32::from_le_bytes(self.memory[at as usize..at as usize + 4].try_into().unwrap())
    }

    pub fn f32_at(&self, at: u64) -> f32 {
        f32::from_bits(self.u32_at(at))
    }

    pub fn f64_at(&self, at: u64) -> f64 {
        f64::from_le_bytes(self.memory[at as usize..at as usize + 8].try_into().unwrap())
    }

    fn inside(ranges: &[Range<u64>], at: u64, len: u64) -> bool {
        ranges.iter().any(|r| at >= r.start && at.saturating_add(len) <= r.end)
    }

    fn ack(&mut self, status: u16, command: u16, id: u16, body: &[u8]) {
        let mut a = Vec::new();
        a.extend_from_slice(&MAGIC.to_le_bytes());
        a.extend_from_slice(&status.to_le_bytes());
        a.extend_from_slice(&command.to_le_bytes());
        a.extend_from_slice(&(body.len() as u16).to_le_bytes());
        a.extend_from_slice(&id.to_le_bytes());
        a.extend_from_slice(body);
        self.acks.push_back(a);
    }

    /// What the sensor does after a register write: the frame rate cannot exceed what the
    /// exposure leaves (1 / exposure).
    fn settle(&mut self) {
        let exposure = f64::from(self.f32_at(EXPOSURE));
        let fastest = 1e6 / exposure.max(1.0);
        if self.f64_at(FRAME_RATE) > fastest {
            self.put(FRAME_RATE, &fastest.to_le_bytes());
        }
    }

    fn command(&mut self, p: &[u8]) {
        let u16_at = |i: usize| u16::from_le_bytes([p[i], p[i + 1]]);
        if p.len() < PREFIX_LEN || u32::from_le_bytes([p[0], p[1], p[2], p[3]]) != MAGIC {
            // Not a GenCP command at all: a camera answers nothing it can attribute.
            return;
        }
        let (flags, command, length, id) = (u16_at(4), u16_at(6), u16_at(8) as usize, u16_at(10));
        self.commands.push((command, id));
        if flags & FLAG_REQUEST_ACK == 0 || PREFIX_LEN + length != p.len() {
            self.ack(STATUS_INVALID_HEADER, command + 1, id, &[]);
            return;
        }
        if self.stale {
            self.stale = false;
            self.ack(STATUS_SUCCESS, command + 1, id.wrapping_sub(1), &[0; 4]);
        }
        if self.pending > 0 {
            self.pending -= 1;
            let mut body = vec![0, 0];
            body.extend_from_slice(&5u16.to_le_bytes());
            self.ack(STATUS_SUCCESS, PENDING_ACK, id, &body);
        }
        if p.len() < PREFIX_LEN + 8 {
            self.ack(STATUS_INVALID_HEADER, command + 1, id, &[]);
            return;
        }
        let address = u64::from_le_bytes(p[12..20].try_into().unwrap());
        match command {
            READMEM_CMD if length == 12 => {
                let n = u16_at(22) as u64;
                if n as u32 + PREFIX_LEN as u32 > self.max_ack {
                    self.ack(STATUS_INVALID_PARAMETER, READMEM_ACK, id, &[]);
                } else if !Self::inside(&self.mapped, address, n) {
                    self.ack(STATUS_INVALID_ADDRESS, READMEM_ACK, id, &[]);
                } else {
                    let data = self.memory[address as usize..(address + n) as usize].to_vec();
                    self.ack(STATUS_SUCCESS, READMEM_ACK, id, &data);
                }
            }
            WRITEMEM_CMD if length >= 8 => {
                let data = &p[20..];
                let n = data.len() as u64;
                if !Self::inside(&self.mapped, address, n) {
                    self.ack(STATUS_INVALID_ADDRESS, WRITEMEM_ACK, id, &[]);
                } else if self.protected.iter().any(|r| address < r.end && address + n > r.start) {
                    self.ack(STATUS_WRITE_PROTECT, WRITEMEM_ACK, id, &[]);
                } else {
                    let data = data.to_vec();
                    self.put(address, &data);
                    self.settle();
                    let mut body = vec![0, 0];
                    body.extend_from_slice(&(n as u16).to_le_bytes());
                    self.ack(STATUS_SUCCESS, WRITEMEM_ACK, id, &body);
                }
            }
            _ => self.ack(STATUS_NOT_IMPLEMENTED, command + 1, id, &[]),
        }
    }
}

impl ControlEndpoint for FakeCamera {
    fn send(&mut self, packet: &[u8], _timeout: Duration) -> Result<(), EndpointError> {
        if !self.silent {
            self.command(packet);
        }
        Ok(())
    }

    fn receive(&mut self, buf: &mut [u8], _timeout: Duration) -> Result<usize, EndpointError> {
        let Some(ack) = self.acks.pop_front() else {
            return Err(EndpointError::Timeout);
        };
        if ack.len() > buf.len() {
            return Err(EndpointError::Failed("transfer overflow".into()));
        }
        buf[..ack.len()].copy_from_slice(&ack);
        Ok(ack.len())
    }
}
