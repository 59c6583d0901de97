//! The GenICam pixel formats a USB3 Vision camera's leaders name, and how each becomes RGB8.
//!
//! In: a leader's pixel-format code; a payload. Out: the format, or none we read; RGB8 pixels.

use super::*;

/// Supported PFNC pixel formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PixelFormat {
    Mono8,
    Rgb8,
    Bgr8,
    BayerGr8,
    BayerRg8,
    BayerGb8,
    BayerBg8,
    Yuv422_8,
    Yuv422_8Uyvy,
    YCbCr422_8,
    YCbCr422_8CbYCrY,
}

impl PixelFormat {
    /// Every supported format.
    pub const ALL: [PixelFormat; 11] = [
        PixelFormat::Mono8,
        PixelFormat::Rgb8,
        PixelFormat::Bgr8,
        PixelFormat::BayerGr8,
        PixelFormat::BayerRg8,
        PixelFormat::BayerGb8,
        PixelFormat::BayerBg8,
        PixelFormat::Yuv422_8,
        PixelFormat::Yuv422_8Uyvy,
        PixelFormat::YCbCr422_8,
        PixelFormat::YCbCr422_8CbYCrY,
    ];

    /// The PFNC code.
    pub fn pfnc(self) -> u32 {
        match self {
            PixelFormat::Mono8 => 0x0108_0001,
            PixelFormat::Rgb8 => 0x0218_0014,
            PixelFormat::Bgr8 => 0x0218_0015,
            PixelFormat::BayerGr8 => 0x0108_0008,
            PixelFormat::BayerRg8 => 0x0108_0009,
            PixelFormat::BayerGb8 => 0x0108_000A,
            PixelFormat::BayerBg8 => 0x0108_000B,
            PixelFormat::Yuv422_8 => 0x0210_0032,
            PixelFormat::Yuv422_8Uyvy => 0x0210_001F,
            PixelFormat::YCbCr422_8 => 0x0210_003B,
            PixelFormat::YCbCr422_8CbYCrY => 0x0210_0043,
        }
    }

    /// The supported format of a PFNC code, if any.
    pub fn from_pfnc(code: u32) -> Option<PixelFormat> {
        PixelFormat::ALL.into_iter().find(|f| f.pfnc() == code)
    }

    /// The PFNC name.
    pub fn name(self) -> &'static str {
        match self {
            PixelFormat::Mono8 => "Mono8",
            PixelFormat::Rgb8 => "RGB8",
            PixelFormat::Bgr8 => "BGR8",
            PixelFormat::BayerGr8 => "BayerGR8",
            PixelFormat::BayerRg8 => "BayerRG8",
            PixelFormat::BayerGb8 => "BayerGB8",
            PixelFormat::BayerBg8 => "BayerBG8",
            PixelFormat::Yuv422_8 => "YUV422_8",
            PixelFormat::Yuv422_8Uyvy => "YUV422_8_UYVY",
            PixelFormat::YCbCr422_8 => "YCbCr422_8",
            PixelFormat::YCbCr422_8CbYCrY => "YCbCr422_8_CbYCrY",
        }
    }

    /// Bytes of one pixel in the payload.
    pub fn bytes_per_pixel(self) -> usize {
        match self {
            PixelFormat::Mono8
            | PixelFormat::BayerGr8
            | PixelFormat::BayerRg8
            | PixelFormat::BayerGb8
            | PixelFormat::BayerBg8 => 1,
            PixelFormat::Yuv422_8
            | PixelFormat::Yuv422_8Uyvy
            | PixelFormat::YCbCr422_8
            | PixelFormat::YCbCr422_8CbYCrY => 2,
            PixelFormat::Rgb8 | PixelFormat::Bgr8 => 3,
        }
    }
}

impl fmt::Display for PixelFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}
