//! USB3 Vision streaming: turns the bytes of a camera's bulk stream endpoint into frames.
//!
//! In: the bulk-IN transfers of one USB3 Vision (U3V) camera's streaming interface, in order, of
//! any sizes ([`U3vStream::push`]). Out: each complete, valid image block as a [`U3vFrame`]
//! (header fields plus the raw payload, convertible into an RGB8 buffer with
//! [`U3vFrame::to_rgb`]), or a [`RejectReason`] for each block that is not, counted in
//! [`U3vStats`]. Pure parsing: no USB here (the `usb` source reads the transfers, behind the cargo
//! feature `usb`), so it is always compiled and tested (`tests/u3v.rs`).
//!
//! # What is supported
//!
//! A U3V stream carries blocks, each a leader, a payload and a trailer. All fields are
//! little-endian; offsets are in bytes.
//!
//! Leader (`leader_size` bytes, at least 52 for an image):
//!
//! | offset | size | field |
//! | --- | --- | --- |
//! | 0 | 4 | magic `U3VL` = `0x4C563355` |
//! | 4 | 2 | reserved |
//! | 6 | 2 | leader_size |
//! | 8 | 8 | block_id |
//! | 16 | 2 | reserved |
//! | 18 | 2 | payload_type: only `0x0001` (image) is accepted |
//! | 20 | 8 | timestamp (device ticks) |
//! | 28 | 4 | pixel_format (PFNC code) |
//! | 32 | 4 | size_x |
//! | 36 | 4 | size_y |
//! | 40 | 4 | offset_x (reported, not used) |
//! | 44 | 4 | offset_y (reported, not used) |
//! | 48 | 2 | padding_x: bytes after each line |
//! | 50 | 2 | reserved |
//!
//! Payload: `size_y` lines of `size_x * bytes_per_pixel + padding_x` bytes.
//!
//! Trailer (`trailer_size` bytes, at least 28; 32 and more carry size_y):
//!
//! | offset | size | field |
//! | --- | --- | --- |
//! | 0 | 4 | magic `U3VT` = `0x54563355` |
//! | 4 | 2 | reserved |
//! | 6 | 2 | trailer_size |
//! | 8 | 8 | block_id: must equal the leader's |
//! | 16 | 2 | status: must be 0 (success); e.g. `0xA100` data discarded rejects the block |
//! | 18 | 2 | reserved |
//! | 20 | 8 | valid_payload_size: must equal the payload received and expected |
//! | 28 | 4 | size_y (image trailers of 32 bytes or more): must equal the leader's |
//!
//! Bytes of a leader or trailer beyond the fields above (e.g. a chunk layout id) are read and
//! ignored. Leaders and trailers longer than [`HEADER_MAX`] bytes are rejected.
//!
//! Pixel formats ([`PixelFormat`], PFNC codes): `Mono8` 0x01080001, `RGB8` 0x02180014, `BGR8`
//! 0x02180015, `BayerGR8` 0x01080008, `BayerRG8` 0x01080009, `BayerGB8` 0x0108000A, `BayerBG8`
//! 0x0108000B, `YUV422_8` 0x02100032 (Y U Y V), `YUV422_8_UYVY` 0x0210001F, `YCbCr422_8`
//! 0x0210003B (Y Cb Y Cr), `YCbCr422_8_CbYCrY` 0x02100043. The YUV/YCbCr ones are converted as
//! BT.601 full range (PFNC's YCbCr definition; the legacy YUV codes are taken the same way).
//! Not supported (the block is rejected as [`RejectReason::UnsupportedPixelFormat`]): packed and
//! 10/12/16-bit formats, planar formats, alpha formats. Not supported payload types (rejected as
//! [`RejectReason::UnsupportedPayloadType`]): chunk data (`0x4000`), image with extended chunks
//! (`0x4001`), GenDC (`0x1001`, `0x1002`).
//!
//! # Synchronisation and errors
//!
//! The parser looks for a leader magic anywhere in the byte stream (across transfer boundaries).
//! Garbage where a leader is expected is skipped and counted once per run of garbage
//! ([`RejectReason::WrongMagic`], bytes in [`U3vStats::bytes_skipped`]). A block whose leader does
//! not fit the sensor (size, format, payload type) is rejected and skipped up to the next leader.
//! The payload length comes from the leader; a camera sends its trailer in a bulk transfer of its
//! own, so a transfer that *starts* with a trailer magic and the current block id ends the payload
//! early (a truncated block, [`RejectReason::PayloadSizeMismatch`]) and one that starts with a
//! leader magic abandons the current block; both resynchronise at once. When the stream is cut
//! elsewhere (possible only with arbitrary transfer sizes), the missing trailer is noticed where it
//! was expected ([`RejectReason::WrongMagic`]) and the parser resynchronises on the next leader
//! magic it finds, which may cost the block after the broken one. Nothing panics on any input.
//!
//! Memory: the payload buffer is allocated once in [`U3vStream::new`] for the largest supported
//! format at the sensor's size (3 bytes a pixel plus [`MAX_PADDING_X`] a line); pushing transfers
//! and converting frames allocate nothing.

mod pixel;
mod reject;

use super::convert::{self, BayerPattern, ConvertError, YuvOrder, YuvRange};
use omnitrack_core::frame::ImageFault;
pub use pixel::PixelFormat;
pub use reject::RejectReason;
use std::fmt;

/// Leader magic `U3VL`, read little-endian.
pub const LEADER_MAGIC: u32 = 0x4C56_3355;
/// Trailer magic `U3VT`, read little-endian.
pub const TRAILER_MAGIC: u32 = 0x5456_3355;
/// Payload type of an image block.
pub const PAYLOAD_TYPE_IMAGE: u16 = 0x0001;
/// Size of an image leader with every field of the table above.
pub const IMAGE_LEADER_SIZE: usize = 52;
/// Smallest trailer accepted (through valid_payload_size).
pub const MIN_TRAILER_SIZE: usize = 28;
/// Size of an image trailer with size_y.
pub const IMAGE_TRAILER_SIZE: usize = 32;
/// Largest leader or trailer accepted.
pub const HEADER_MAX: usize = 1024;
/// Largest per-line padding the payload buffer has room for.
pub const MAX_PADDING_X: usize = 256;

/// The common first 16 bytes of a leader and a trailer.
const PREFIX: usize = 16;

/// What a stream parsed so far.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct U3vStats {
    /// Blocks delivered as frames.
    pub frames: u64,
    /// Rejections, indexed by [`RejectReason::index`].
    pub rejected: [u64; RejectReason::ALL.len()],
    /// Bytes skipped while looking for a leader (garbage and the rest of rejected blocks).
    pub bytes_skipped: u64,
    /// Status of the last trailer with a non-zero status.
    pub last_error_status: u16,
}

impl U3vStats {
    /// Rejections of one reason.
    pub fn rejected(&self, reason: RejectReason) -> u64 {
        self.rejected[reason.index()]
    }

    /// Rejections of every reason.
    pub fn total_rejected(&self) -> u64 {
        self.rejected.iter().sum()
    }
}

/// The header fields of a delivered image block.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameInfo {
    pub block_id: u64,
    /// Device timestamp (ticks of the camera's clock, nanoseconds on most cameras).
    pub timestamp: u64,
    pub format: PixelFormat,
    pub width: u32,
    pub height: u32,
    pub offset_x: u32,
    pub offset_y: u32,
    pub padding_x: u16,
}

/// A delivered frame: header fields and the raw payload, valid until the next push.
#[derive(Debug, Clone, Copy)]
pub struct U3vFrame<'a> {
    pub info: FrameInfo,
    pub payload: &'a [u8],
}

impl U3vFrame<'_> {
    /// Bytes from one line of the payload to the next.
    pub fn stride(&self) -> usize {
        self.info.width as usize * self.info.format.bytes_per_pixel() + self.info.padding_x as usize
    }

    /// Converts the payload into RGB8 `out` of `width * height * 3` bytes.
    pub fn to_rgb(&self, out: &mut [u8]) -> Result<(), ConvertError> {
        let (w, h, s, p) = (self.info.width, self.info.height, self.stride(), self.payload);
        match self.info.format {
            PixelFormat::Mono8 => convert::grey_to_rgb(p, w, h, s, out),
            PixelFormat::Rgb8 => convert::rgb_to_rgb(p, w, h, s, out),
            PixelFormat::Bgr8 => convert::bgr_to_rgb(p, w, h, s, out),
            PixelFormat::BayerGr8 => convert::bayer_to_rgb(p, w, h, s, BayerPattern::Grbg, out),
            PixelFormat::BayerRg8 => convert::bayer_to_rgb(p, w, h, s, BayerPattern::Rggb, out),
            PixelFormat::BayerGb8 => convert::bayer_to_rgb(p, w, h, s, BayerPattern::Gbrg, out),
            PixelFormat::BayerBg8 => convert::bayer_to_rgb(p, w, h, s, BayerPattern::Bggr, out),
            PixelFormat::Yuv422_8 | PixelFormat::YCbCr422_8 => {
                convert::yuv422_to_rgb(p, w, h, s, YuvOrder::Yuyv, YuvRange::Full, out)
            }
            PixelFormat::Yuv422_8Uyvy | PixelFormat::YCbCr422_8CbYCrY => {
                convert::yuv422_to_rgb(p, w, h, s, YuvOrder::Uyvy, YuvRange::Full, out)
            }
        }
    }
}

/// What [`U3vStream::push`] reports, in stream order.
#[derive(Debug, Clone, Copy)]
pub enum U3vEvent<'a> {
    /// A complete, valid image block.
    Frame(U3vFrame<'a>),
    /// A block (or a run of garbage) that was not delivered; `block_id` when a header named one.
    Rejected {
        reason: RejectReason,
        block_id: Option<u64>,
    },
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    /// Looking for a leader magic; `quiet` when skipping the rest of a block already rejected (no
    /// wrong-magic count), `counted` when this run of garbage was counted already.
    Seek { quiet: bool, counted: bool },
    /// Reading a leader whose magic was seen.
    Leader,
    /// Copying the payload.
    Payload,
    /// Reading the trailer.
    Trailer,
}

/// The streaming parser of one camera. See the module doc.
#[derive(Debug, Clone)]
pub struct U3vStream {
    width: u32,
    height: u32,
    state: State,
    /// The leader or trailer read so far.
    header: Box<[u8; HEADER_MAX]>,
    header_len: usize,
    /// The leader of the block being read.
    current: FrameInfo,
    payload: Box<[u8]>,
    received: usize,
    expected: usize,
    stats: U3vStats,
}

fn u16_at(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([b[at], b[at + 1]])
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

fn u64_at(b: &[u8], at: usize) -> u64 {
    let mut a = [0u8; 8];
    a.copy_from_slice(&b[at..at + 8]);
    u64::from_le_bytes(a)
}

impl U3vStream {
    /// A parser for a sensor of `width` × `height`; allocates its payload buffer once.
    pub fn new(width: u32, height: u32) -> U3vStream {
        let capacity = height as usize * (width as usize * 3 + MAX_PADDING_X);
        U3vStream {
            width,
            height,
            state: State::Seek {
                quiet: false,
                counted: false,
            },
            header: Box::new([0u8; HEADER_MAX]),
            header_len: 0,
            current: FrameInfo {
                block_id: 0,
                timestamp: 0,
                format: PixelFormat::Mono8,
                width: 0,
                height: 0,
                offset_x: 0,
                offset_y: 0,
                padding_x: 0,
            },
            payload: vec![0u8; capacity].into_boxed_slice(),
            received: 0,
            expected: 0,
            stats: U3vStats::default(),
        }
    }

    /// Counters so far.
    pub fn stats(&self) -> &U3vStats {
        &self.stats
    }

    /// Forgets any partly read block (e.g. after the device was reopened); counters stay.
    pub fn reset(&mut self) {
        self.state = State::Seek {
            quiet: true,
            counted: false,
        };
        self.header_len = 0;
        self.received = 0;
    }

    /// Feeds one bulk transfer (any length, including 0); `sink` gets every frame completed and
    /// every block rejected, in order. A frame's payload is valid only inside the call.
    pub fn push(&mut self, transfer: &[u8], mut sink: impl FnMut(U3vEvent<'_>)) {
        if self.state == State::Payload && transfer.len() >= PREFIX {
            let magic = u32_at(transfer, 0);
            let size = u16_at(transfer, 6) as usize;
            if magic == TRAILER_MAGIC
                && u64_at(transfer, 8) == self.current.block_id
                && (MIN_TRAILER_SIZE..=HEADER_MAX).contains(&size)
            {
                // The trailer came early: the payload was cut short.
                self.state = State::Trailer;
                self.header_len = 0;
            } else if magic == LEADER_MAGIC && (IMAGE_LEADER_SIZE..=HEADER_MAX).contains(&size) {
                // A new block began before this one ended.
                self.reject(
                    RejectReason::PayloadSizeMismatch,
                    Some(self.current.block_id),
                    &mut sink,
                );
                self.state = State::Seek {
                    quiet: false,
                    counted: false,
                };
                self.header_len = 0;
            }
        }
        self.consume(transfer, &mut sink);
    }

    fn reject(&mut self, reason: RejectReason, block_id: Option<u64>, sink: &mut impl FnMut(U3vEvent<'_>)) {
        self.stats.rejected[reason.index()] += 1;
        sink(U3vEvent::Rejected { reason, block_id });
    }

    /// Runs the state machine over `data`.
    fn consume(&mut self, data: &[u8], sink: &mut impl FnMut(U3vEvent<'_>)) {
        let mut i = 0;
        while i < data.len() {
            match self.state {
                State::Seek { quiet, counted } => {
                    if self.header_len == 0 {
                        let skip = data[i..].iter().position(|&b| b == b'U').unwrap_or(data.len() - i);
                        if skip > 0 {
                            self.skipped(skip, quiet, counted, sink);
                            i += skip;
                            continue;
                        }
                    }
                    let b = data[i];
                    i += 1;
                    if b == LEADER_MAGIC.to_le_bytes()[self.header_len] {
                        self.header[self.header_len] = b;
                        self.header_len += 1;
                        if self.header_len == 4 {
                            self.state = State::Leader;
                        }
                    } else {
                        // The partial magic and this byte are garbage, except a fresh 'U'.
                        let (garbage, restart) = if b == b'U' {
                            (self.header_len, 1)
                        } else {
                            (self.header_len + 1, 0)
                        };
                        self.header[0] = b'U';
                        self.header_len = restart;
                        self.skipped(garbage, quiet, counted, sink);
                    }
                }
                State::Leader => {
                    i += self.fill_header(&data[i..]);
                    if self.header_len < PREFIX {
                        continue;
                    }
                    let size = u16_at(&self.header[..], 6) as usize;
                    if !(IMAGE_LEADER_SIZE..=HEADER_MAX).contains(&size) {
                        self.bad_header(sink);
                        continue;
                    }
                    if self.header_len < size {
                        i += self.fill_header_to(&data[i..], size);
                        if self.header_len < size {
                            continue;
                        }
                    }
                    self.leader_done(sink);
                }
                State::Payload => {
                    let n = (self.expected - self.received).min(data.len() - i);
                    self.payload[self.received..self.received + n].copy_from_slice(&data[i..i + n]);
                    self.received += n;
                    i += n;
                    if self.received == self.expected {
                        self.state = State::Trailer;
                        self.header_len = 0;
                    }
                }
                State::Trailer => {
                    if self.header_len < 4 {
                        let b = data[i];
                        if b != TRAILER_MAGIC.to_le_bytes()[self.header_len] {
                            // No trailer where one belongs: reject the block and look again at
                            // these bytes as the start of the next leader.
                            self.reject(RejectReason::WrongMagic, Some(self.current.block_id), sink);
                            self.rescan(0, sink);
                            continue;
                        }
                        self.header[self.header_len] = b;
                        self.header_len += 1;
                        i += 1;
                        continue;
                    }
                    i += self.fill_header(&data[i..]);
                    if self.header_len < PREFIX {
                        continue;
                    }
                    let size = u16_at(&self.header[..], 6) as usize;
                    if !(MIN_TRAILER_SIZE..=HEADER_MAX).contains(&size) {
                        self.bad_header(sink);
                        continue;
                    }
                    if self.header_len < size {
                        i += self.fill_header_to(&data[i..], size);
                        if self.header_len < size {
                            continue;
                        }
                    }
                    self.trailer_done(size, sink);
                }
            }
        }
    }

    /// Counts skipped bytes; the first garbage of a run (outside a rejected block) is one
    /// wrong-magic rejection.
    fn skipped(&mut self, n: usize, quiet: bool, counted: bool, sink: &mut impl FnMut(U3vEvent<'_>)) {
        if n == 0 {
            return;
        }
        self.stats.bytes_skipped += n as u64;
        if !quiet && !counted {
            self.reject(RejectReason::WrongMagic, None, sink);
            self.state = State::Seek { quiet, counted: true };
        }
    }

    /// Copies bytes into the header up to its 16-byte prefix; returns how many were used.
    fn fill_header(&mut self, data: &[u8]) -> usize {
        self.fill_header_to(data, PREFIX)
    }

    fn fill_header_to(&mut self, data: &[u8], size: usize) -> usize {
        let n = size.saturating_sub(self.header_len).min(data.len());
        self.header[self.header_len..self.header_len + n].copy_from_slice(&data[..n]);
        self.header_len += n;
        n
    }

    /// A leader or trailer with an impossible size: reject, and search its bytes after the magic
    /// for the next leader.
    fn bad_header(&mut self, sink: &mut impl FnMut(U3vEvent<'_>)) {
        let block_id = u64_at(&self.header[..], 8);
        self.reject(RejectReason::BadHeader, Some(block_id), sink);
        self.rescan(1, sink);
    }

    /// Re-reads the header bytes from `from` in the seek state (so that a leader hidden in them
    /// is found). At most [`PREFIX`] bytes, on the stack.
    fn rescan(&mut self, from: usize, sink: &mut impl FnMut(U3vEvent<'_>)) {
        let mut copy = [0u8; PREFIX];
        let n = self.header_len.min(PREFIX).saturating_sub(from);
        copy[..n].copy_from_slice(&self.header[from..from + n]);
        self.header_len = 0;
        self.state = State::Seek {
            quiet: true,
            counted: true,
        };
        self.consume(&copy[..n], sink);
    }

    fn skip_block(&mut self) {
        self.header_len = 0;
        self.state = State::Seek {
            quiet: true,
            counted: false,
        };
    }

    fn leader_done(&mut self, sink: &mut impl FnMut(U3vEvent<'_>)) {
        let h = &self.header[..];
        let block_id = u64_at(h, 8);
        let payload_type = u16_at(h, 18);
        let code = u32_at(h, 28);
        let (size_x, size_y) = (u32_at(h, 32), u32_at(h, 36));
        let (offset_x, offset_y) = (u32_at(h, 40), u32_at(h, 44));
        let padding_x = u16_at(h, 48);
        let timestamp = u64_at(h, 20);
        let reason = if payload_type != PAYLOAD_TYPE_IMAGE {
            Some(RejectReason::UnsupportedPayloadType)
        } else if PixelFormat::from_pfnc(code).is_none() {
            Some(RejectReason::UnsupportedPixelFormat)
        } else if (size_x, size_y) != (self.width, self.height) {
            Some(RejectReason::SizeMismatch)
        } else if padding_x as usize > MAX_PADDING_X {
            Some(RejectReason::PayloadSizeMismatch)
        } else {
            None
        };
        if let Some(reason) = reason {
            self.reject(reason, Some(block_id), sink);
            self.skip_block();
            return;
        }
        let format = PixelFormat::from_pfnc(code).unwrap_or(PixelFormat::Mono8);
        self.current = FrameInfo {
            block_id,
            timestamp,
            format,
            width: size_x,
            height: size_y,
            offset_x,
            offset_y,
            padding_x,
        };
        self.expected = size_y as usize * (size_x as usize * format.bytes_per_pixel() + padding_x as usize);
        self.received = 0;
        self.header_len = 0;
        self.state = if self.expected == 0 {
            State::Trailer
        } else {
            State::Payload
        };
    }

    fn trailer_done(&mut self, size: usize, sink: &mut impl FnMut(U3vEvent<'_>)) {
        let h = &self.header[..];
        let block_id = u64_at(h, 8);
        let status = u16_at(h, 16);
        let valid_payload = u64_at(h, 20);
        let size_y = (size >= IMAGE_TRAILER_SIZE).then(|| u32_at(h, 28));
        let id = Some(self.current.block_id);
        self.header_len = 0;
        self.state = State::Seek {
            quiet: false,
            counted: false,
        };
        let reason = if block_id != self.current.block_id {
            Some(RejectReason::BlockIdMismatch)
        } else if status != 0 {
            self.stats.last_error_status = status;
            Some(RejectReason::TrailerStatus)
        } else if valid_payload != self.received as u64 || self.received != self.expected {
            Some(RejectReason::PayloadSizeMismatch)
        } else if size_y.is_some_and(|y| y != self.current.height) {
            Some(RejectReason::SizeMismatch)
        } else {
            None
        };
        match reason {
            Some(reason) => self.reject(reason, id, sink),
            None => {
                self.stats.frames += 1;
                sink(U3vEvent::Frame(U3vFrame {
                    info: self.current,
                    payload: &self.payload[..self.received],
                }));
            }
        }
    }
}
