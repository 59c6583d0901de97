//! Why a USB3 Vision payload was refused: each reason one line, counted per kind in the
//! stream's statistics.
//!
//! In: nothing (plain data). Out: the reason and its words.

use super::*;

/// Why a block was not delivered.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RejectReason {
    /// Bytes that are neither a leader where one was expected nor a trailer where one was
    /// expected (counted once per run of garbage).
    WrongMagic,
    /// A leader or trailer whose size field is too small for its fields or above [`HEADER_MAX`].
    BadHeader,
    /// A payload type other than image (`0x0001`).
    UnsupportedPayloadType,
    /// A pixel format not in [`PixelFormat`].
    UnsupportedPixelFormat,
    /// size_x / size_y not the sensor's, or the trailer's size_y not the leader's.
    SizeMismatch,
    /// The payload received, the payload the leader implies and the trailer's
    /// valid_payload_size disagree (a truncated block, a missing trailer, a payload too large).
    PayloadSizeMismatch,
    /// The trailer's block id is not the leader's.
    BlockIdMismatch,
    /// The trailer reports a non-zero status.
    TrailerStatus,
}

impl RejectReason {
    /// Every reason, in the order of [`RejectReason::index`].
    pub const ALL: [RejectReason; 8] = [
        RejectReason::WrongMagic,
        RejectReason::BadHeader,
        RejectReason::UnsupportedPayloadType,
        RejectReason::UnsupportedPixelFormat,
        RejectReason::SizeMismatch,
        RejectReason::PayloadSizeMismatch,
        RejectReason::BlockIdMismatch,
        RejectReason::TrailerStatus,
    ];

    /// Position in [`RejectReason::ALL`].
    pub fn index(self) -> usize {
        self as usize
    }

    /// Short human-readable name.
    pub fn name(self) -> &'static str {
        match self {
            RejectReason::WrongMagic => "wrong magic",
            RejectReason::BadHeader => "bad leader/trailer size",
            RejectReason::UnsupportedPayloadType => "unsupported payload type",
            RejectReason::UnsupportedPixelFormat => "unsupported pixel format",
            RejectReason::SizeMismatch => "image size mismatch",
            RejectReason::PayloadSizeMismatch => "payload size mismatch",
            RejectReason::BlockIdMismatch => "block id mismatch",
            RejectReason::TrailerStatus => "trailer status error",
        }
    }

    /// The fault a source records for the sensor.
    pub fn fault(self) -> ImageFault {
        match self {
            RejectReason::UnsupportedPayloadType | RejectReason::UnsupportedPixelFormat => ImageFault::WrongFormat,
            RejectReason::SizeMismatch => ImageFault::WrongSize,
            RejectReason::TrailerStatus => ImageFault::Dropped,
            RejectReason::WrongMagic
            | RejectReason::BadHeader
            | RejectReason::PayloadSizeMismatch
            | RejectReason::BlockIdMismatch => ImageFault::Corrupt,
        }
    }
}

impl fmt::Display for RejectReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}
